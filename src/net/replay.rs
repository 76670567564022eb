//! Serving a recording as a reader: one client at a time gets a
//! [`ReplaySession`] over a [`Connection`]; a second
//! client is refused as a reader refuses it (a READER_EVENT_NOTIFICATION with
//! FailedClientInitiatedConnectionExists, then close).

use std::io;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use llrp::enums::ConnectionAttemptStatus;
use llrp::message::ErrorMessage;
use llrp::params::LlrpStatus;
use llrp::{Inbound, Message, StatusCode};
use tokio::net::TcpListener;
use tokio::sync::watch;

use super::connection::{Connection, Io};
use super::serve;
use super::tls::Acceptor;
use crate::localize::live::{Input, Tap};
use crate::record::replay::{ReplayOptions, ReplaySession, Script};
use crate::utc::now_us as utc_now_us;
use llrp_gateway_vocab::feed::Inventory;

/// Bytes queued for the client before the session stops moving due frames to it.
const QUEUE_BYTES: usize = 256 * 1024;

/// Connections held at once: the one client served and those being refused or in their TLS
/// handshake; one more is refused at once.
pub const MAX_CONNECTIONS: usize = 16;

/// How long a refused client gets to take its refusal.
const REFUSAL_WRITE: Duration = Duration::from_millis(500);

/// Serves `script` on `listener` until `shutdown` turns true; over TLS when `tls` is given.
pub async fn serve(
    listener: TcpListener,
    script: Arc<Script>,
    options: ReplayOptions,
    tls: Option<Acceptor>,
    shutdown: watch::Receiver<bool>,
) -> io::Result<()> {
    serve_tapped(listener, script, options, tls, shutdown, None).await
}

/// [`serve()`], offering every frame sent to the client to the live localizer's `tap` under the
/// reader name given with it.
pub async fn serve_tapped(
    listener: TcpListener,
    script: Arc<Script>,
    options: ReplayOptions,
    tls: Option<Acceptor>,
    shutdown: watch::Receiver<bool>,
    tap: Option<(String, Tap)>,
) -> io::Result<()> {
    // Whether a client is being served; taken once a client's TLS handshake (if any) is
    // done, so a client that never finishes one does not keep the next one out.
    let busy = Arc::new(AtomicBool::new(false));
    let plain = tls.is_none();
    serve::accept_loop(
        &listener,
        MAX_CONNECTIONS,
        shutdown.clone(),
        "replay",
        |stream, peer| {
            let script = Arc::clone(&script);
            let busy = Arc::clone(&busy);
            let stop = shutdown.clone();
            let tls = tls.clone();
            let tap = tap.clone();
            async move {
                let conn = match &tls {
                    None => Ok(Connection::new(stream)),
                    Some(a) => a.accept(stream).await.map(Connection::from_stream),
                };
                let conn = match conn {
                    Ok(c) => c,
                    Err(e) => {
                        tracing::warn!(%peer, "TLS handshake failed: {e}");
                        return;
                    }
                };
                let refused = busy
                    .compare_exchange(false, true, Ordering::AcqRel, Ordering::Acquire)
                    .is_err();
                if refused {
                    tracing::info!(%peer, "refusing a second client");
                    refuse(conn).await;
                    return;
                }
                // Frees the slot however the session ends (a panic included).
                let slot = Slot(&busy);
                tracing::info!(%peer, "replaying connection {} of the recording", script.conn());
                if let Some((name, t)) = &tap {
                    t.links().update(name, |l| {
                        l.connected = true;
                        l.peer = Some(peer.to_string());
                        l.inventory = Inventory::Client;
                    });
                }
                let result = session(conn, peer, &script, options, stop, tap.as_ref()).await;
                if let Some((name, t)) = &tap {
                    t.links().update(name, |l| {
                        l.connected = false;
                        l.peer = None;
                        l.inventory = Inventory::Idle;
                    });
                }
                match result {
                    Ok(()) => tracing::info!(%peer, "client disconnected"),
                    Err(e) => tracing::info!(%peer, "connection ended: {e}"),
                }
                drop(slot);
            }
        },
        // Over the limit, told as a second client is (a TLS client is closed: a refusal in
        // the clear means nothing to it before its handshake).
        move |stream, _| async move {
            if plain {
                serve::refuse(stream, &refusal(), REFUSAL_WRITE).await;
            }
        },
    )
    .await
}

/// One client's replay.
async fn session(
    mut conn: Connection,
    peer: SocketAddr,
    script: &Script,
    options: ReplayOptions,
    mut shutdown: watch::Receiver<bool>,
    tap: Option<&(String, Tap)>,
) -> io::Result<()> {
    let start = Instant::now();
    let now = || start.elapsed().as_micros() as u64;
    let mut s = ReplaySession::new(script, options, now());
    loop {
        s.advance(now(), QUEUE_BYTES.saturating_sub(conn.queued()));
        let out = s.transmit();
        if let (Some((name, t)), false) = (tap, out.bytes.is_empty()) {
            t.offer(Input::Frames {
                reader: name.clone(),
                bytes: bytes::Bytes::copy_from_slice(&out.bytes[..]),
                now_utc_us: utc_now_us(),
            });
        }
        conn.queue_buf(&mut out.bytes);
        if out.close {
            let _ = tokio::time::timeout(Duration::from_secs(1), conn.shutdown()).await;
            return Ok(());
        }
        let wake = match s.deadline() {
            // A time too far to represent is never.
            Some(d) if conn.queued() < QUEUE_BYTES => start
                .checked_add(Duration::from_micros(d))
                .map(tokio::time::Instant::from_std),
            _ => None,
        };
        tokio::select! {
            changed = shutdown.changed() => {
                if serve::stopping(changed, &shutdown) {
                    let _ = tokio::time::timeout(Duration::from_secs(1), conn.shutdown()).await;
                    return Ok(());
                }
            }
            io = conn.read_or_flush(conn.queued() > 0) => match io? {
                Io::Frame(Inbound::Frame(frame)) => s.receive(&frame, now()),
                Io::Frame(Inbound::Unsynced(e)) => {
                    // As a reader does: ERROR_MESSAGE, then close.
                    tracing::info!(%peer, "the client's stream is not LLRP: {e}");
                    let m = Message::new(
                        0,
                        ErrorMessage {
                            llrp_status: LlrpStatus::new(StatusCode::M_FieldError, e.to_string()),
                            ..Default::default()
                        },
                    );
                    conn.queue(&m);
                    let _ = tokio::time::timeout(Duration::from_secs(1), conn.shutdown()).await;
                    return Ok(());
                }
                Io::Closed => return Ok(()),
                Io::Flushed => {}
            },
            _ = serve::sleep_until(wake) => {}
        }
    }
}

/// What a reader tells a second client: a READER_EVENT_NOTIFICATION with
/// FailedClientInitiatedConnectionExists.
fn refusal() -> Vec<u8> {
    let mut body = crate::net::proxy::connection_failed(utc_now_us());
    if let Some(e) = &mut body.reader_event_notification_data.connection_attempt_event {
        e.status = ConnectionAttemptStatus::FailedClientInitiatedConnectionExists;
    }
    let mut bytes = bytes::BytesMut::new();
    Message::new(0, body).encode(&mut bytes);
    bytes.to_vec()
}

/// Refuses a second client as a reader does, then closes.
async fn refuse(mut conn: Connection) {
    conn.queue_bytes(&refusal());
    let _ = tokio::time::timeout(REFUSAL_WRITE, conn.shutdown()).await;
}

/// The replay's one client slot, held while a client is served.
struct Slot<'a>(&'a AtomicBool);

impl Drop for Slot<'_> {
    fn drop(&mut self) {
        self.0.store(false, Ordering::Release);
    }
}
