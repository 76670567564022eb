//! Serving a recording as a reader: one client at a time gets a
//! [`ReplaySession`] over a [`Connection`]; a second
//! client is refused as a reader refuses it (a READER_EVENT_NOTIFICATION with
//! FailedClientInitiatedConnectionExists, then close).

use std::io;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::{Duration, Instant};

use llrp::enums::ConnectionAttemptStatus;
use llrp::message::ErrorMessage;
use llrp::params::LlrpStatus;
use llrp::{Inbound, Message, StatusCode};
use tokio::io::AsyncWriteExt;
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::watch;

use super::connection::{Connection, Io};
use crate::record::replay::{ReplayOptions, ReplaySession, Script};
use crate::record::writer::utc_now_us;

/// Bytes queued for the client before the session stops moving due frames to it.
const QUEUE_BYTES: usize = 256 * 1024;

/// Serves `script` on `listener` until `shutdown` turns true.
pub async fn serve(
    listener: TcpListener,
    script: Arc<Script>,
    options: ReplayOptions,
    mut shutdown: watch::Receiver<bool>,
) -> io::Result<()> {
    let (busy_tx, busy_rx) = watch::channel(false);
    let busy_tx = Arc::new(busy_tx);
    loop {
        tokio::select! {
            _ = shutdown.changed() => {
                if *shutdown.borrow() {
                    return Ok(());
                }
            }
            accepted = listener.accept() => {
                let (stream, peer) = match accepted {
                    Ok(a) => a,
                    Err(e) => {
                        tracing::warn!("accept failed: {e}");
                        tokio::time::sleep(Duration::from_millis(100)).await;
                        continue;
                    }
                };
                if *busy_rx.borrow() {
                    tracing::info!(%peer, "refusing a second client");
                    tokio::spawn(refuse(stream));
                    continue;
                }
                let _ = busy_tx.send(true);
                let script = Arc::clone(&script);
                let busy = Arc::clone(&busy_tx);
                let stop = shutdown.clone();
                tokio::spawn(async move {
                    tracing::info!(%peer, "replaying connection {} of the recording", script.conn());
                    match session(stream, peer, &script, options, stop).await {
                        Ok(()) => tracing::info!(%peer, "client disconnected"),
                        Err(e) => tracing::info!(%peer, "connection ended: {e}"),
                    }
                    let _ = busy.send(false);
                });
            }
        }
    }
}

/// One client's replay.
async fn session(
    stream: TcpStream,
    peer: SocketAddr,
    script: &Script,
    options: ReplayOptions,
    mut shutdown: watch::Receiver<bool>,
) -> io::Result<()> {
    let mut conn = Connection::new(stream);
    let start = Instant::now();
    let now = || start.elapsed().as_micros() as u64;
    let mut s = ReplaySession::new(script, options, now());
    loop {
        s.advance(now(), QUEUE_BYTES.saturating_sub(conn.queued()));
        let out = s.transmit();
        conn.queue_buf(&mut out.bytes);
        if out.close {
            let _ = tokio::time::timeout(Duration::from_secs(1), conn.shutdown()).await;
            return Ok(());
        }
        let wake = match s.deadline() {
            Some(d) if conn.queued() < QUEUE_BYTES => Some(tokio::time::Instant::from_std(
                start + Duration::from_micros(d),
            )),
            _ => None,
        };
        tokio::select! {
            _ = shutdown.changed() => {
                if *shutdown.borrow() {
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
            _ = sleep_until(wake) => {}
        }
    }
}

async fn sleep_until(at: Option<tokio::time::Instant>) {
    match at {
        Some(t) => tokio::time::sleep_until(t).await,
        None => std::future::pending().await,
    }
}

/// Refuses a second client as a reader does.
async fn refuse(mut stream: TcpStream) {
    let mut body = crate::net::proxy::connection_failed(utc_now_us());
    if let Some(e) = &mut body.reader_event_notification_data.connection_attempt_event {
        e.status = ConnectionAttemptStatus::FailedClientInitiatedConnectionExists;
    }
    let bytes = Message::new(0, body).to_bytes();
    let _ = tokio::time::timeout(Duration::from_millis(500), async {
        stream.write_all(&bytes).await?;
        stream.shutdown().await
    })
    .await;
}
