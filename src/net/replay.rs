//! Serving a recording as a reader: the sans-IO [`ReplayServer`] (one client at a time gets a
//! replay session of the script; a second is refused as a reader refuses it) served by the
//! loop every session shares ([`drive`]), on the wall clock.

use crate::reads::ReaderName;
use std::io;
use std::sync::Arc;
use std::time::{Duration, Instant};

use tokio::net::TcpListener;
use tokio::sync::watch;

use super::drive::{drive, Host, Limits, LiveHook, Wire};
use super::tls::Acceptor;
use crate::record::replay::server::{ReplayNow, ReplayServer, BACKLOG_BYTES};
use crate::record::replay::{ReplayOptions, Script};
use crate::record::Recorder;
use crate::utc::now_us as utc_now_us;
use llrp_gateway_vocab::feed::Tap;
use llrp_gateway_vocab::session::ServerSession;

/// Connections held at once besides the client: TLS handshakes under way, and as many
/// refusals being written; one more is refused (or, past the refusals, closed) at once.
pub const MAX_CONNECTIONS: usize = 16;

/// How long a refused client gets to take its refusal, and a closing one its last bytes.
const REFUSAL_WRITE: Duration = Duration::from_millis(500);
const CLOSE_FLUSH: Duration = Duration::from_secs(1);

/// The replay on the wall clock.
struct ReplayHost {
    server: ReplayServer,
    start: Instant,
}

impl Host for ReplayHost {
    type Session = ReplayServer;

    fn session_mut(&mut self) -> &mut ReplayServer {
        &mut self.server
    }

    fn now(&self) -> ReplayNow {
        ReplayNow {
            us: self.start.elapsed().as_micros() as u64,
            utc_us: utc_now_us(),
        }
    }

    fn wake_at(&self) -> Option<Instant> {
        // A time too far to represent is never.
        let d = self.server.deadline()?;
        self.start.checked_add(Duration::from_micros(d))
    }

    fn utc_now_us(&self) -> u64 {
        utc_now_us()
    }

    fn inventorying(&self) -> bool {
        // A replayed client is told the recorded reports: it inventories while connected.
        self.server.connected()
    }

    fn backlog(&self) -> Option<usize> {
        Some(BACKLOG_BYTES)
    }
}

/// Serves `script` on `listener` until `shutdown` turns true; over TLS when `tls` is given.
pub async fn serve(
    listener: TcpListener,
    script: Arc<Script>,
    options: ReplayOptions,
    tls: Option<Acceptor>,
    shutdown: watch::Receiver<bool>,
) -> io::Result<()> {
    serve_tapped(listener, script, options, tls, shutdown, None, None).await
}

/// [`serve()`], offering every frame sent to the client to the live localizer's `tap` under the
/// reader name given with it, and recording the sessions with `recorder`.
pub async fn serve_tapped(
    listener: TcpListener,
    script: Arc<Script>,
    options: ReplayOptions,
    tls: Option<Acceptor>,
    shutdown: watch::Receiver<bool>,
    tap: Option<(ReaderName, Tap)>,
    recorder: Option<Recorder>,
) -> io::Result<()> {
    tracing::info!("replaying connection {} of the recording", script.conn());
    let host = ReplayHost {
        server: ReplayServer::new(script, options),
        start: Instant::now(),
    };
    let wire = Wire {
        recorder,
        live: tap.map(|(name, tap)| LiveHook {
            name,
            tap,
            client: None,
            frames_in: None,
        }),
    };
    let limits = Limits {
        handshakes: MAX_CONNECTIONS,
        refusals: MAX_CONNECTIONS,
        refusal_write: REFUSAL_WRITE,
        close_flush: CLOSE_FLUSH,
    };
    drive(listener, tls, host, wire, limits, shutdown).await
}
