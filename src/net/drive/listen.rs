//! The loop's listener: closed while the session does not listen (a simulated reader
//! rebooting, so connections are refused), bound again after.

use std::io;
use std::net::SocketAddr;

use tokio::net::TcpListener;

use super::{Driver, Host};

impl<H: Host> Driver<H> {
    /// Closes the listener while the session does not listen (a reader rebooting: connections
    /// are refused), and binds its address again once it does (retried while that fails).
    pub(super) async fn sync_listener(
        &mut self,
        listener: &mut Option<TcpListener>,
        addr: SocketAddr,
    ) {
        let Some(h) = self.here.as_deref() else {
            return;
        };
        let listening = h.listening();
        if !listening && listener.is_some() {
            *listener = None;
            tracing::info!(%addr, "not listening: connections are refused");
        } else if listening && listener.is_none() && self.accept_after.is_none() {
            match TcpListener::bind(addr).await {
                Ok(l) => {
                    *listener = Some(l);
                    tracing::info!(%addr, "listening again");
                }
                Err(e) => {
                    let pause = self.backoff.failed();
                    tracing::warn!(%addr, "cannot listen again: {e}; retrying in {pause:?}");
                    self.accept_after = Some(tokio::time::Instant::now() + pause);
                }
            }
        }
    }
}

/// The next connection on `listener`; pending forever while there is none (not listening).
pub(super) async fn accept(
    listener: &Option<TcpListener>,
) -> io::Result<(tokio::net::TcpStream, SocketAddr)> {
    match listener {
        Some(l) => l.accept().await,
        None => std::future::pending().await,
    }
}
