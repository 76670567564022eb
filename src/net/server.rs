//! The simulated reader's TCP side: one task per simulated reader owns its [`Session`] and
//! moves bytes between it and the sockets. The task accepts connections (the session decides
//! who is refused), hands the session every frame a [`Connection`] reads, writes what the
//! session has to send, and otherwise sleeps until the session's next deadline.

use std::io;
use std::sync::Arc;
use std::time::{Duration, Instant};

use tokio::io::AsyncWriteExt;
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::watch;

use super::clock::{Clock, Speed};
use super::connection::{Connection, Io};
use crate::reader::session::{Accepted, ClientId, Now, Session};
use crate::reader::Reader;

/// Sees the reader after each step (writes ground truth).
pub type Observer = Box<dyn FnMut(&Reader) + Send>;

/// `--speed max`: output is sent once this much is waiting...
const FLUSH_BYTES: usize = 64 * 1024;
/// ... or this long after the last send, so a slow scenario still streams.
const FLUSH_AFTER: Duration = Duration::from_millis(1);
/// `--speed max`: most steps, and longest time, run before the task looks at its sockets
/// again.
const STEPS_PER_TURN: usize = 64;
const TURN: Duration = Duration::from_millis(2);
/// How long a reader that closes a connection waits for its client to take the last bytes
/// (the ConnectionCloseEvent, a CLOSE_CONNECTION_RESPONSE).
const SHUTDOWN_FLUSH: Duration = Duration::from_millis(500);
/// How long a refused client gets to take its refusal.
const REFUSAL_WRITE: Duration = Duration::from_millis(200);
/// First and longest pause after a failed accept (e.g. out of file descriptors).
const ACCEPT_BACKOFF_MIN: Duration = Duration::from_millis(10);
const ACCEPT_BACKOFF_MAX: Duration = Duration::from_secs(1);

/// A simulated reader ready to serve: its session, clock and ground-truth observer.
pub struct SimReader {
    session: Session,
    clock: Arc<Clock>,
    observer: Option<Observer>,
}

impl SimReader {
    /// Wraps a reader's session and its clock; `observer` sees the reader after every step.
    pub fn new(session: Session, clock: Arc<Clock>, observer: Option<Observer>) -> Self {
        SimReader {
            session,
            clock,
            observer,
        }
    }

    fn now(&self) -> Now {
        Now {
            sim_us: self.clock.now_us(),
            wall_ms: self.clock.wall_ms(),
        }
    }

    fn observe(&mut self) {
        if let Some(f) = &mut self.observer {
            f(self.session.reader());
        }
    }
}

/// The connected client's socket.
struct Client {
    id: ClientId,
    conn: Connection,
    peer: String,
}

/// Serves `listener` until `shutdown` turns true; then the connected client gets the
/// ConnectionCloseEvent and is closed.
pub async fn serve(
    listener: TcpListener,
    mut sim: SimReader,
    mut shutdown: watch::Receiver<bool>,
) -> io::Result<()> {
    let max = sim.clock.speed() == Speed::Max;
    let mut client: Option<Client> = None;
    let mut flushed = Instant::now();
    let mut backoff = ACCEPT_BACKOFF_MIN;
    let mut accept_after: Option<tokio::time::Instant> = None;
    loop {
        if let Some(c) = &mut client {
            if let Some(t) = sim.session.transmit() {
                c.conn.queue_buf(t.bytes);
                if t.close {
                    // What the session said last goes out, then the connection closes.
                    let _ = tokio::time::timeout(SHUTDOWN_FLUSH, c.conn.shutdown()).await;
                    sim.session.disconnect(c.id);
                    tracing::info!(peer = %c.peer, "client disconnected by the reader");
                    client = None;
                }
            }
        }
        let deadline = sim.session.deadline();
        let busy = max && client.is_some() && deadline.sim_us.is_some();
        let wake = sim
            .clock
            .wake_at(deadline)
            .map(tokio::time::Instant::from_std);
        let queued = client.as_ref().map_or(0, |c| c.conn.queued());
        let flush_now =
            queued > 0 && (!busy || queued >= FLUSH_BYTES || flushed.elapsed() >= FLUSH_AFTER);
        let may_accept = accept_after.map_or(true, |t| t <= tokio::time::Instant::now());
        tokio::select! {
            biased;
            _ = shutdown.changed() => {
                if *shutdown.borrow() {
                    if let Some(mut c) = client.take() {
                        sim.session.shutdown();
                        if let Some(t) = sim.session.transmit() {
                            c.conn.queue_buf(t.bytes);
                        }
                        let _ = tokio::time::timeout(SHUTDOWN_FLUSH, c.conn.shutdown()).await;
                        sim.session.disconnect(c.id);
                    }
                    return Ok(());
                }
            }
            r = client_io(&mut client, flush_now) => {
                let Some(c) = client.as_ref() else { continue };
                match r {
                    Ok(Io::Frame(inbound)) => {
                        let now = sim.now();
                        sim.session.receive(c.id, inbound, now);
                        sim.observe();
                    }
                    Ok(Io::Flushed) => flushed = Instant::now(),
                    Ok(Io::Closed) | Err(_) => {
                        if let Err(e) = &r {
                            tracing::info!(peer = %c.peer, "connection ended: {e}");
                        }
                        tracing::info!(peer = %c.peer, "client disconnected");
                        sim.session.disconnect(c.id);
                        client = None;
                    }
                }
            }
            accepted = listener.accept(), if may_accept => {
                match accepted {
                    Ok((stream, peer)) => {
                        backoff = ACCEPT_BACKOFF_MIN;
                        let now = sim.now();
                        match sim.session.connect(now) {
                            Accepted::Client(id) => {
                                tracing::info!(%peer, "client connected");
                                client = Some(Client {
                                    id,
                                    conn: Connection::new(stream),
                                    peer: peer.to_string(),
                                });
                            }
                            Accepted::Refused(bytes) => {
                                tracing::info!(%peer, "refusing a second client");
                                refuse(stream, &bytes).await;
                            }
                        }
                    }
                    Err(e) => {
                        tracing::warn!("accept failed: {e}; pausing accepts for {backoff:?}");
                        accept_after = Some(tokio::time::Instant::now() + backoff);
                        backoff = (backoff * 2).min(ACCEPT_BACKOFF_MAX);
                    }
                }
            }
            _ = sleep_until(accept_after), if !may_accept => {
                accept_after = None;
            }
            _ = sleep_until(wake), if wake.is_some() => {
                let now = sim.now();
                sim.session.advance(now);
                sim.observe();
            }
            _ = std::future::ready(()), if busy && queued < FLUSH_BYTES => {
                let turn = Instant::now();
                for _ in 0..STEPS_PER_TURN {
                    let now = Now { sim_us: sim.clock.step(), wall_ms: sim.clock.wall_ms() };
                    sim.session.advance(now);
                    sim.observe();
                    if sim.session.pending() >= FLUSH_BYTES
                        || sim.session.deadline().sim_us.is_none()
                        || sim.session.transmit().is_some_and(|t| t.close)
                        || turn.elapsed() >= TURN
                    {
                        break;
                    }
                }
                // `--speed max` always has work: give the other tasks on this thread a turn.
                tokio::task::yield_now().await;
            }
        }
    }
}

/// The connected client's next frame, or its write buffer sent (when `flush`); pending forever
/// without a client.
async fn client_io(client: &mut Option<Client>, flush: bool) -> io::Result<Io> {
    match client {
        Some(c) => c.conn.read_or_flush(flush).await,
        None => std::future::pending().await,
    }
}

async fn sleep_until(at: Option<tokio::time::Instant>) {
    match at {
        Some(t) => tokio::time::sleep_until(t).await,
        None => std::future::pending().await,
    }
}

/// Tells a second client it is refused, then closes (a client that does not read in time is
/// closed all the same).
async fn refuse(mut stream: TcpStream, bytes: &[u8]) {
    let _ = tokio::time::timeout(REFUSAL_WRITE, async {
        stream.write_all(bytes).await?;
        stream.shutdown().await
    })
    .await;
}
