//! The simulated reader's TCP side: one task per simulated reader owns its [`Session`] and
//! moves bytes between it and the sockets. The task accepts connections (the session decides
//! who is refused), hands the session every frame a [`Connection`] reads, writes what the
//! session has to send, and otherwise sleeps until the session's next deadline.
//!
//! With TLS ([`serve_tls`]) each accepted connection's handshake runs in a task of its own
//! (at most [`MAX_HANDSHAKES`] at once, each within [`tls::HANDSHAKE_TIMEOUT`]); only a
//! finished handshake reaches the session, so a client that fails it (plain LLRP sent to the
//! TLS port, a certificate it refuses, silence) is logged and changes nothing for the reader.

use std::collections::VecDeque;
use std::io;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::{Duration, Instant};

use tokio::net::TcpListener;
use tokio::sync::{oneshot, watch};
use tokio::task::JoinSet;

use super::clock::{Clock, Speed};
use super::connection::{Connection, Io};
use super::report_buffer::{ReportBuffer, REPORT_BUFFER_BYTES};
use super::serve::{refuse, sleep_until, stopping, AcceptBackoff};
use super::stream::Stream;
use super::tls;
use crate::localize::live::{Input, Tap};
use crate::physics::pool::Pool;
use crate::reader::session::{Accepted, ClientId, Now, Session};
use crate::reader::Reader;
use crate::record::{Direction, Entry, Event, Recorder};
use llrp_gateway_vocab::feed::Inventory;
use prometheus_client::metrics::counter::Counter;

/// Sees the reader after each step (writes ground truth).
pub type Observer = Box<dyn FnMut(&Reader) + Send>;

/// `--speed max`: output is sent once this much is waiting...
const FLUSH_BYTES: usize = 64 * 1024;
/// ... or this long after the last send, so a slow scenario still streams.
const FLUSH_AFTER: Duration = Duration::from_millis(1);
/// `--speed max`: most output one turn makes (several flushes' worth, so that handing the
/// reader to its pool thread and back costs little per byte)...
const TURN_BYTES: usize = 8 * FLUSH_BYTES;
/// ... most steps, and longest time, one turn runs.
const STEPS_PER_TURN: usize = 64;
const TURN: Duration = Duration::from_millis(2);
/// How long a reader that closes a connection waits for its client to take the last bytes
/// (the ConnectionCloseEvent, a CLOSE_CONNECTION_RESPONSE).
const SHUTDOWN_FLUSH: Duration = Duration::from_millis(500);
/// How long a refused client gets to take its refusal.
const REFUSAL_WRITE: Duration = Duration::from_millis(200);
/// Most TLS handshakes under way at once; accepting waits while this many run.
pub const MAX_HANDSHAKES: usize = 16;

/// A simulated reader ready to serve: its session, clock and ground-truth observer.
pub struct SimReader {
    session: Session,
    clock: Arc<Clock>,
    observer: Option<Observer>,
    /// Where the reader's CPU-bound work (inventory physics, reports) runs.
    pool: Arc<Pool>,
    live: Option<LiveHook>,
}

/// How a served reader talks to the live localizer.
pub struct LiveHook {
    /// The reader's name in the localizer.
    pub name: String,
    /// The localizer's tap: every frame the reader sends its client is offered to it.
    pub tap: Tap,
    /// Told whether a client is connected (the simulator's own inventory runs while not).
    pub client: watch::Sender<bool>,
    /// Counts the frames the client sends the reader.
    pub frames_in: Counter,
}

impl SimReader {
    /// Wraps a reader's session and its clock; `observer` sees the reader after every step.
    /// Its inventory runs on the process's readers' pool.
    pub fn new(session: Session, clock: Arc<Clock>, observer: Option<Observer>) -> Self {
        SimReader {
            session,
            clock,
            observer,
            pool: Pool::readers(),
            live: None,
        }
    }

    /// Offers every frame sent to the client to the live localizer, and tells it (and the
    /// simulator's own inventory) whether a client is connected.
    pub fn with_live(mut self, hook: LiveHook) -> Self {
        self.live = Some(hook);
        self
    }

    /// Whether running the reader now may compute physics (an ROSpec runs or is due).
    fn busy(&self) -> bool {
        self.session.reader().inventorying() || self.session.deadline().sim_us.is_some()
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

/// Runs `f` on the reader: on the readers' pool when it may compute physics (so CPU-bound
/// work never runs on a tokio worker thread), here otherwise (a request to an idle reader, a
/// keepalive). Gives the reader back; an error if the pool lost it (a panic in the physics).
async fn work(
    mut sim: Box<SimReader>,
    f: impl FnOnce(&mut SimReader) + Send + 'static,
) -> io::Result<Box<SimReader>> {
    if !sim.busy() {
        f(&mut sim);
        return Ok(sim);
    }
    home(send_away(sim, f)).await
}

/// Starts `f` on the reader on the readers' pool (here if the pool has no thread); the reader
/// comes back through the receiver.
fn send_away(
    sim: Box<SimReader>,
    f: impl FnOnce(&mut SimReader) + Send + 'static,
) -> oneshot::Receiver<Box<SimReader>> {
    let pool = Arc::clone(&sim.pool);
    let (tx, rx) = oneshot::channel();
    let task = Box::new(move || {
        let mut sim = sim;
        f(&mut sim);
        let _ = tx.send(sim);
    });
    if let Err(task) = pool.run(task) {
        // No physics thread could be started: the work runs here after all.
        task();
    }
    rx
}

/// The reader back from the pool; an error if the pool lost it (a panic in the physics).
async fn home(away: oneshot::Receiver<Box<SimReader>>) -> io::Result<Box<SimReader>> {
    away.await
        .map_err(|_| io::Error::other("the simulated reader was lost in its physics"))
}

/// One `--speed max` turn: steps simulated time until a buffer's worth of output, the end of
/// the work, a close, or [`TURN`].
fn turn(sim: &mut SimReader) {
    let start = Instant::now();
    for _ in 0..STEPS_PER_TURN {
        let now = Now {
            sim_us: sim.clock.step(),
            wall_ms: sim.clock.wall_ms(),
        };
        sim.session.advance(now);
        sim.observe();
        if sim.session.pending() >= TURN_BYTES
            || sim.session.deadline().sim_us.is_none()
            || sim.session.transmit().is_some_and(|t| t.close)
            || start.elapsed() >= TURN
        {
            break;
        }
    }
}

/// The connected client's socket.
struct Client {
    id: ClientId,
    conn: Connection,
    peer: String,
    /// Its connection number in the recording.
    rec: u32,
    /// The reports waiting for it, bounded.
    buffer: ReportBuffer,
}

/// Records the frames of `bytes` (whole frames, as the session sends them) as sent by the
/// reader on connection `conn`.
async fn record_sent(recorder: &Option<Recorder>, conn: u32, bytes: &[u8]) {
    let Some(r) = recorder else { return };
    let at = r.now();
    // One copy of the whole output, each frame a slice of it, all in one batch.
    let all = bytes::Bytes::copy_from_slice(bytes);
    let mut entries = Vec::new();
    let mut start = 0;
    while let Some(h) = llrp::FrameHeader::peek(&all[start..]) {
        let len = (h.length as usize).clamp(llrp::frame::HEADER_LEN, all.len() - start);
        entries.push(Entry::Frame {
            at,
            conn,
            dir: Direction::FromReader,
            frame: all.slice(start..start + len),
            undecodable: None,
        });
        start += len;
    }
    if !entries.is_empty() {
        let _ = r.entries(entries).await;
    }
}

/// Records a marker on connection `conn`.
async fn record_marker(recorder: &Option<Recorder>, conn: u32, event: Event, reason: String) {
    if let Some(r) = recorder {
        let _ = r.marker(conn, event, reason).await;
    }
}

/// Serves `listener` until `shutdown` turns true; then the connected client gets the
/// ConnectionCloseEvent and is closed.
///
/// At `--speed max` the reader steps simulated time in turns on the readers' pool while this
/// task sends the previous turn's output, so the two overlap; a turn starts only while less
/// than a few flushes' worth wait to be sent, so a slow client slows simulated time down. Requests
/// that arrive during a turn are handled once it is back, in order.
pub async fn serve(
    listener: TcpListener,
    sim: SimReader,
    shutdown: watch::Receiver<bool>,
    recorder: Option<Recorder>,
) -> io::Result<()> {
    serve_tls(listener, None, sim, shutdown, recorder).await
}

/// [`serve`], over TLS when `tls` is given: every client does the TLS handshake first (see the
/// module's documentation).
pub async fn serve_tls(
    listener: TcpListener,
    tls: Option<tls::Acceptor>,
    sim: SimReader,
    mut shutdown: watch::Receiver<bool>,
    recorder: Option<Recorder>,
) -> io::Result<()> {
    let mut handshakes: JoinSet<(SocketAddr, io::Result<Stream>)> = JoinSet::new();
    let max = sim.clock.speed() == Speed::Max;
    // The reader is here, or away on the pool for a turn.
    let mut here: Option<Box<SimReader>> = Some(Box::new(sim));
    let mut away: Option<oneshot::Receiver<Box<SimReader>>> = None;
    let mut arrived: VecDeque<llrp::Inbound> = VecDeque::new();
    let mut client: Option<Client> = None;
    let mut flushed = Instant::now();
    let mut backoff = AcceptBackoff::default();
    let mut accept_after: Option<tokio::time::Instant> = None;
    let live = here.as_mut().and_then(|s| s.live.take());
    let mut told: Option<(bool, bool)> = None;
    loop {
        if let Some(mut sim) = here.take() {
            // Requests that came during a turn, in order.
            while let (Some(inbound), Some(c)) = (arrived.pop_front(), client.as_ref()) {
                let id = c.id;
                sim = work(sim, move |sim| {
                    let now = sim.now();
                    sim.session.receive(id, inbound, now);
                    sim.observe();
                })
                .await?;
            }
            if let Some(c) = &mut client {
                let now_utc_us = sim.session.reader().utc_us(sim.session.reader().now_us());
                let out = sim.session.transmit().map(|t| (t.bytes.split(), t.close));
                if let Some((raw, close)) = out {
                    // Reports past the report buffer are dropped, and the client told.
                    let admitted = c.buffer.admit(c.conn.queued(), raw);
                    let mut bytes = admitted.bytes;
                    if let Some(percent) = admitted.warn {
                        if let Some(m) = sim.session.reader_mut().buffer_warning_event(percent) {
                            m.encode(&mut bytes);
                        }
                    }
                    if admitted.overflow {
                        sim.session
                            .reader_mut()
                            .buffer_overflow_event()
                            .encode(&mut bytes);
                    }
                    record_sent(&recorder, c.rec, &bytes[..]).await;
                    if let Some(l) = &live {
                        l.tap.offer(Input::Frames {
                            reader: l.name.clone(),
                            bytes: bytes::Bytes::copy_from_slice(&bytes[..]),
                            now_utc_us,
                        });
                    }
                    c.conn.queue_buf(&mut bytes);
                    if close {
                        // What the session said last goes out, then the connection closes.
                        let _ = tokio::time::timeout(SHUTDOWN_FLUSH, c.conn.shutdown()).await;
                        sim.session.disconnect(c.id);
                        tracing::info!(peer = %c.peer, "client disconnected by the reader");
                        record_marker(
                            &recorder,
                            c.rec,
                            Event::Disconnect,
                            "the reader closed the connection".into(),
                        )
                        .await;
                        client = None;
                    }
                }
            }
            here = Some(sim);
        }
        // After the session's output, which may have closed the client (CLOSE_CONNECTION,
        // a keepalive timeout): told before waiting, not when something next wakes the loop.
        if let Some(l) = &live {
            tell_live(l, &client, here.as_deref(), &mut told);
        }
        let (deadline, wake) = match here.as_deref() {
            Some(sim) => {
                let d = sim.session.deadline();
                (d, sim.clock.wake_at(d).map(tokio::time::Instant::from_std))
            }
            None => Default::default(),
        };
        let streaming = max && client.is_some() && (away.is_some() || deadline.sim_us.is_some());
        let queued = client.as_ref().map_or(0, |c| c.conn.queued());
        let flush_now = queued > 0
            && (!streaming
                || away.is_some()
                || queued >= FLUSH_BYTES
                || flushed.elapsed() >= FLUSH_AFTER);
        let may_accept = here.is_some()
            && handshakes.len() < MAX_HANDSHAKES
            && accept_after.map_or(true, |t| t <= tokio::time::Instant::now());
        let may_turn = here.is_some() && streaming && queued < TURN_BYTES;
        tokio::select! {
            biased;
            changed = shutdown.changed() => {
                if stopping(changed, &shutdown) {
                    let mut sim = match (here.take(), away.take()) {
                        (Some(s), _) => s,
                        (None, Some(a)) => home(a).await?,
                        (None, None) => return Ok(()),
                    };
                    if let Some(mut c) = client.take() {
                        sim.session.shutdown();
                        if let Some(t) = sim.session.transmit() {
                            record_sent(&recorder, c.rec, &t.bytes[..]).await;
                            c.conn.queue_buf(t.bytes);
                        }
                        let _ = tokio::time::timeout(SHUTDOWN_FLUSH, c.conn.shutdown()).await;
                        sim.session.disconnect(c.id);
                        record_marker(&recorder, c.rec, Event::Disconnect, "the simulator stopped".into()).await;
                    }
                    return Ok(());
                }
            }
            back = returned(&mut away), if away.is_some() => {
                // (Polling the receiver by reference: a turn still running when another
                // branch wins is still there next time.)
                away = None;
                here = Some(back?);
            }
            r = client_io(&mut client, flush_now) => {
                let Some(c) = client.as_ref() else { continue };
                match r {
                    Ok(Io::Frame(inbound)) => {
                        if let Some(l) = &live {
                            l.frames_in.inc();
                        }
                        if let (Some(r), llrp::Inbound::Frame(f)) = (&recorder, &inbound) {
                            let _ = r.frame(r.now(), c.rec, Direction::ToReader, f.clone()).await;
                        }
                        arrived.push_back(inbound);
                    }
                    Ok(Io::Flushed) => flushed = Instant::now(),
                    Ok(Io::Closed) | Err(_) => {
                        if let Err(e) = &r {
                            tracing::info!(peer = %c.peer, "connection ended: {e}");
                        }
                        tracing::info!(peer = %c.peer, "client disconnected");
                        let reason = match &r {
                            Err(e) => format!("client connection failed: {e}"),
                            Ok(_) => "client closed".to_string(),
                        };
                        record_marker(&recorder, c.rec, Event::Disconnect, reason).await;
                        let id = c.id;
                        client = None;
                        arrived.clear();
                        let mut sim = match (here.take(), away.take()) {
                            (Some(s), _) => s,
                            (None, Some(a)) => home(a).await?,
                            (None, None) => continue,
                        };
                        sim.session.disconnect(id);
                        here = Some(sim);
                    }
                }
            }
            accepted = listener.accept(), if may_accept => {
                let Some(sim) = here.as_deref_mut() else { continue };
                match accepted {
                    Ok((stream, peer)) => {
                        backoff.succeeded();
                        match &tls {
                            Some(acceptor) => {
                                let acceptor = acceptor.clone();
                                handshakes.spawn(async move {
                                    (peer, acceptor.accept(stream).await.map(Stream::from))
                                });
                            }
                            None => {
                                admit(sim, &mut client, &recorder, Stream::from(stream), peer).await;
                            }
                        }
                    }
                    Err(e) => {
                        let pause = backoff.failed();
                        tracing::warn!("accept failed: {e}; pausing accepts for {pause:?}");
                        accept_after = Some(tokio::time::Instant::now() + pause);
                    }
                }
            }
            Some(done) = handshakes.join_next(), if here.is_some() && !handshakes.is_empty() => {
                let Some(sim) = here.as_deref_mut() else { continue };
                match done {
                    Ok((peer, Ok(stream))) => {
                        admit(sim, &mut client, &recorder, stream, peer).await;
                    }
                    Ok((peer, Err(e))) => {
                        tracing::warn!(%peer, "TLS handshake failed: {e}; the client is dropped, the reader carries on");
                    }
                    Err(e) => tracing::warn!("a TLS handshake task failed: {e}"),
                }
            }
            _ = sleep_until(accept_after), if !may_accept && here.is_some() => {
                accept_after = None;
            }
            _ = sleep_until(wake), if wake.is_some() && !may_turn => {
                if let Some(sim) = here.take() {
                    here = Some(
                        work(sim, |sim| {
                            let now = sim.now();
                            sim.session.advance(now);
                            sim.observe();
                        })
                        .await?,
                    );
                }
            }
            _ = std::future::ready(()), if may_turn && arrived.is_empty() => {
                if let Some(sim) = here.take() {
                    away = Some(send_away(sim, turn));
                }
            }
        }
    }
}

/// Tells the localizer (and the own inventory) whether a client is connected and whether it
/// inventories, when that changed (`told` holds what was told last).
fn tell_live(
    live: &LiveHook,
    client: &Option<Client>,
    sim: Option<&SimReader>,
    told: &mut Option<(bool, bool)>,
) {
    let connected = client.is_some();
    // While the reader is away on its turn it is inventorying.
    let inventorying = connected && sim.map_or(true, |s| s.session.reader().inventorying());
    if *told == Some((connected, inventorying)) {
        return;
    }
    *told = Some((connected, inventorying));
    live.client
        .send_if_modified(|c| std::mem::replace(c, connected) != connected);
    let peer = client.as_ref().map(|c| c.peer.clone());
    live.tap.links().update(&live.name, |l| {
        l.connected = connected;
        l.peer = peer;
        if connected {
            l.inventory = if inventorying {
                Inventory::Client
            } else {
                Inventory::Idle
            };
        } else if l.inventory == Inventory::Client {
            l.inventory = Inventory::Idle;
        }
    });
}

/// The reader back from its turn; pending forever when it is not away.
async fn returned(
    away: &mut Option<oneshot::Receiver<Box<SimReader>>>,
) -> io::Result<Box<SimReader>> {
    match away {
        Some(rx) => rx
            .await
            .map_err(|_| io::Error::other("the simulated reader was lost in its physics")),
        None => std::future::pending().await,
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

/// A new client (its TLS handshake done, if any): the session takes it, or refuses it when
/// another client is connected.
async fn admit(
    sim: &mut SimReader,
    client: &mut Option<Client>,
    recorder: &Option<Recorder>,
    stream: Stream,
    peer: SocketAddr,
) {
    let now = sim.now();
    let tls = if stream.is_tls() { " over TLS" } else { "" };
    match sim.session.connect(now) {
        Accepted::Client(id) => {
            tracing::info!(%peer, "client connected{tls}");
            let rec = recorder.as_ref().map_or(0, Recorder::next_conn);
            record_marker(recorder, rec, Event::Connect, format!("client {peer}{tls}")).await;
            *client = Some(Client {
                id,
                conn: Connection::from_stream(stream),
                peer: peer.to_string(),
                rec,
                buffer: ReportBuffer::new(REPORT_BUFFER_BYTES),
            });
        }
        Accepted::Refused(bytes) => {
            tracing::info!(%peer, "refusing a second client");
            let rec = recorder.as_ref().map_or(0, Recorder::next_conn);
            record_marker(recorder, rec, Event::Connect, format!("client {peer}{tls}")).await;
            record_sent(recorder, rec, &bytes).await;
            refuse(stream, &bytes, REFUSAL_WRITE).await;
            record_marker(
                recorder,
                rec,
                Event::Disconnect,
                "refused: another client is connected".into(),
            )
            .await;
        }
    }
}
