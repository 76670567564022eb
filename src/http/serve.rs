//! Serving the router: an accept loop with a connection limit, hyper's HTTP/1 connections with
//! a timer (so its header-read timeout fires, on the first request and between keep-alive
//! requests), and a graceful shutdown.
//!
//! `axum::serve` builds hyper's connections without a timer, so their header-read timeout never
//! fires, and it caps nothing: five slowloris connections, idle connections and a stalled
//! upload were all held open for as long as their peers liked. Here the limits are
//! [`ServerLimits`]; the per-request ones (body stall, whole-request deadline, a declared
//! body over the limit) are layers of the router ([`super::router`]).

use std::future::Future;
use std::io;
use std::sync::Arc;
use std::time::Duration;

use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::server::graceful::GracefulShutdown;
use hyper_util::service::TowerToHyperService;
use tokio::io::AsyncWriteExt;
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{watch, Semaphore};

use super::Closing;

/// How long and how many: the server's bounds on what a client can hold.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ServerLimits {
    /// Longest wait for a request's whole header, from the connection's start or from the end
    /// of the previous response (so an idle keep-alive connection is closed after it too).
    pub header_read: Duration,
    /// Longest a request body may stall between two of its chunks.
    pub body_read: Duration,
    /// Longest a request may take from its header to its answer (not the event stream).
    pub request: Duration,
    /// Most connections served at once; one more is answered 503 and closed.
    pub max_connections: usize,
}

impl Default for ServerLimits {
    fn default() -> Self {
        ServerLimits {
            header_read: Duration::from_secs(10),
            body_read: Duration::from_secs(10),
            request: Duration::from_secs(30),
            max_connections: 128,
        }
    }
}

/// How long a refused connection's 503 may take to leave.
const REFUSAL_WRITE: Duration = Duration::from_secs(1);

/// Serves `router` on `listener` within `limits` until `shutdown` resolves; then open event
/// streams end, requests under way finish (connections are given 2 s), and it returns.
pub async fn serve(
    listener: TcpListener,
    router: axum::Router,
    limits: ServerLimits,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> io::Result<()> {
    let (closing_tx, closing_rx) = watch::channel(false);
    let router = router.layer(axum::Extension(Closing(closing_rx)));
    let permits = Arc::new(Semaphore::new(limits.max_connections));
    let graceful = GracefulShutdown::new();
    let mut builder = hyper::server::conn::http1::Builder::new();
    builder
        .timer(TokioTimer::new())
        .header_read_timeout(limits.header_read);
    let builder = Arc::new(builder);
    tokio::pin!(shutdown);
    loop {
        let (stream, peer) = tokio::select! {
            () = &mut shutdown => break,
            accepted = listener.accept() => match accepted {
                Ok(a) => a,
                Err(e) => {
                    // Out of descriptors or a connection reset before it was taken: the
                    // listener itself is fine; wait a moment rather than spin.
                    tracing::warn!("HTTP accept failed: {e}");
                    tokio::time::sleep(Duration::from_millis(50)).await;
                    continue;
                }
            },
        };
        let Ok(permit) = Arc::clone(&permits).try_acquire_owned() else {
            tracing::info!(%peer, limit = limits.max_connections, "HTTP connection refused: at the limit");
            tokio::spawn(refuse(stream, limits.max_connections));
            continue;
        };
        let _ = stream.set_nodelay(true);
        let service = TowerToHyperService::new(router.clone());
        let conn = builder.serve_connection(TokioIo::new(stream), service);
        let conn = graceful.watch(conn);
        tokio::spawn(async move {
            if let Err(e) = conn.await {
                tracing::debug!(%peer, "HTTP connection ended: {e}");
            }
            drop(permit);
        });
    }
    drop(listener);
    let _ = closing_tx.send(true);
    if tokio::time::timeout(Duration::from_secs(2), graceful.shutdown())
        .await
        .is_err()
    {
        tracing::debug!("HTTP connections still open after 2 s: dropped");
    }
    Ok(())
}

/// Answers a connection over the limit with 503 and closes it.
async fn refuse(mut stream: TcpStream, limit: usize) {
    let body = format!(r#"{{"error":"too many connections: the limit is {limit}, try again"}}"#);
    let head = format!(
        "HTTP/1.1 503 Service Unavailable\r\ncontent-type: application/json\r\n\
         retry-after: 1\r\nconnection: close\r\ncontent-length: {}\r\n\r\n",
        body.len()
    );
    let write = async {
        stream.write_all(head.as_bytes()).await?;
        stream.write_all(body.as_bytes()).await?;
        stream.shutdown().await
    };
    let _ = tokio::time::timeout(REFUSAL_WRITE, write).await;
}
