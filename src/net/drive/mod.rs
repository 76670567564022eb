//! One loop that serves any sans-IO [`ServerSession`] on a listener: the simulated reader's
//! and the replay's. The loop owns the session (through its [`Host`]) and every connection:
//! it accepts (with the back-off of [`serve`](super::serve)), runs TLS handshakes in tasks of
//! their own (at most [`Limits::handshakes`] at once; only a finished one reaches the
//! session), hands the session each new connection and every frame its client sends, writes
//! what the session has to send, refuses whom the session refuses in tracked tasks (at most
//! [`Limits::refusals`] at once; beyond, a connection is closed at once), and otherwise sleeps
//! until the session's next deadline. At the stop the client is told as the session says,
//! closed, and the loop's tasks are drained.
//!
//! What differs between sessions is the host's: its clock, whether a step may be heavy (then
//! it runs off the async threads, on the host's pool), whether it streams (`--speed max`:
//! steps back to back, overlapped with sending), its report buffer, and the live feed's view
//! of who inventories. What every server wants from its wire is here once ([`Wire`]): the
//! recorder and the live localizer's tap.

use std::collections::VecDeque;
use std::io;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::{Duration, Instant};

use tokio::net::TcpListener;
use tokio::sync::{oneshot, watch, Semaphore};
use tokio::task::JoinSet;

use super::backoff::Backoff;
use super::connection::{Connection, Io};
use super::report_buffer::ReportBuffer;
use super::serve::{accept_backoff, refuse, sleep_until, stopping, DRAIN};
use super::stream::Stream;
use super::tls;
use crate::record::{Direction, Entry, Event, Recorder};
use llrp_gateway_vocab::feed::{Input, Inventory};
use llrp_gateway_vocab::session::{Accepted, ClientId, ServerSession};

mod host;
mod listen;

pub use host::{Host, Job, Limits, LiveHook, NowOf, Offload, Wire};

/// Streaming: output is sent once this much is waiting...
const FLUSH_BYTES: usize = 64 * 1024;
/// ... or this long after the last send, so a slow stream still flows.
const FLUSH_AFTER: Duration = Duration::from_millis(1);
/// Streaming: a turn starts only while less than this waits to be sent (several flushes'
/// worth, so that handing the session to its pool thread and back costs little per byte).
pub const TURN_BYTES: usize = 8 * FLUSH_BYTES;

/// The connected client's socket.
struct Client {
    id: ClientId,
    conn: Connection,
    peer: String,
    /// Its connection number in the recording.
    rec: u32,
    /// The reports waiting for it, bounded (when the host has a report buffer).
    buffer: Option<ReportBuffer>,
}

/// The loop's state: the host (here, or away on its pool for a step) and the connections.
struct Driver<H: Host> {
    here: Option<Box<H>>,
    away: Option<oneshot::Receiver<Box<H>>>,
    offload: Option<Offload>,
    /// Frames the client sent while the host was away, in order.
    arrived: VecDeque<llrp::Inbound>,
    client: Option<Client>,
    wire: Wire,
    limits: Limits,
    flushed: Instant,
    backoff: Backoff,
    accept_after: Option<tokio::time::Instant>,
    handshakes: JoinSet<(SocketAddr, io::Result<Stream>)>,
    refusals: JoinSet<()>,
    refusal_slots: Arc<Semaphore>,
    /// What the live feed was told last: (connected, inventorying).
    told: Option<(bool, bool)>,
    /// Notified when the session has work from outside ([`Host::nudge`]).
    nudge: Option<Arc<tokio::sync::Notify>>,
}

/// Serves `host`'s session on `listener` until `shutdown` asks to stop; over TLS when `tls`
/// is given (see the module's documentation).
pub async fn drive<H: Host>(
    listener: TcpListener,
    tls: Option<tls::Acceptor>,
    host: H,
    wire: Wire,
    limits: Limits,
    mut shutdown: watch::Receiver<bool>,
) -> io::Result<()> {
    let offload = host.offload();
    let nudge = host.nudge();
    let mut d = Driver {
        nudge,
        here: Some(Box::new(host)),
        away: None,
        offload,
        arrived: VecDeque::new(),
        client: None,
        wire,
        limits,
        flushed: Instant::now(),
        backoff: accept_backoff(),
        accept_after: None,
        handshakes: JoinSet::new(),
        refusals: JoinSet::new(),
        refusal_slots: Arc::new(Semaphore::new(limits.refusals.max(1))),
        told: None,
    };
    let result = d.run(listener, tls.as_ref(), &mut shutdown).await;
    d.drain().await;
    result
}

impl<H: Host> Driver<H> {
    async fn run(
        &mut self,
        listener: TcpListener,
        tls: Option<&tls::Acceptor>,
        shutdown: &mut watch::Receiver<bool>,
    ) -> io::Result<()> {
        let addr = listener.local_addr()?;
        let mut listener = Some(listener);
        loop {
            self.deliver().await?;
            // After the session's output, which may have closed the client: told before
            // waiting, not when something next wakes the loop.
            self.tell_live();
            self.sync_listener(&mut listener, addr).await;
            let (wake, streaming) = match self.here.as_deref() {
                Some(h) => (
                    h.wake_at().map(tokio::time::Instant::from_std),
                    h.streaming(),
                ),
                None => (None, false),
            };
            let streaming = self.client.is_some() && (self.away.is_some() || streaming);
            let queued = self.client.as_ref().map_or(0, |c| c.conn.queued());
            let flush_now = queued > 0
                && (!streaming
                    || self.away.is_some()
                    || queued >= FLUSH_BYTES
                    || self.flushed.elapsed() >= FLUSH_AFTER);
            let here = self.here.is_some();
            let may_accept = here
                && self.handshakes.len() < self.limits.handshakes
                && self
                    .accept_after
                    .is_none_or(|t| t <= tokio::time::Instant::now());
            let may_turn = here && streaming && queued < TURN_BYTES;
            let backlogged = self
                .here
                .as_deref()
                .and_then(Host::backlog)
                .is_some_and(|b| queued >= b);
            tokio::select! {
                biased;
                changed = shutdown.changed() => {
                    if stopping(changed, shutdown) {
                        return self.stop().await;
                    }
                }
                back = returned(&mut self.away), if self.away.is_some() => {
                    // (Polling the receiver by reference: a turn still running when another
                    // branch wins is still there next time.)
                    self.away = None;
                    self.here = Some(back?);
                }
                r = client_io(&mut self.client, flush_now) => self.client_io(r).await?,
                accepted = listen::accept(&listener), if may_accept => self.accepted(accepted, tls).await,
                Some(done) = self.handshakes.join_next(), if here && !self.handshakes.is_empty() => {
                    match done {
                        Ok((peer, Ok(stream))) => self.admit(stream, peer).await,
                        Ok((peer, Err(e))) => tracing::warn!(%peer, "TLS handshake failed: {e}; the client is dropped, the server carries on"),
                        Err(e) => tracing::warn!("a TLS handshake task failed: {e}"),
                    }
                }
                Some(_) = self.refusals.join_next(), if !self.refusals.is_empty() => {}
                _ = sleep_until(self.accept_after), if !may_accept && here => {
                    self.accept_after = None;
                }
                _ = nudged(&self.nudge), if here && self.nudge.is_some() => {
                    self.step(|h| {
                        let now = h.now();
                        h.session_mut().advance(now);
                        h.stepped();
                    })
                    .await?;
                }
                _ = sleep_until(wake), if wake.is_some() && !may_turn && !backlogged => {
                    self.step(|h| {
                        let now = h.now();
                        h.session_mut().advance(now);
                        h.stepped();
                    })
                    .await?;
                }
                _ = std::future::ready(()), if may_turn && self.arrived.is_empty() => {
                    if let Some(h) = self.here.take() {
                        self.away = Some(send_away(h, self.offload.clone(), |h: &mut H| h.turn()));
                    }
                }
            }
        }
    }

    /// Runs `f` on the host: through its offload when the step may be heavy (so CPU-bound
    /// work never runs on a tokio worker thread), here otherwise.
    async fn step(&mut self, f: impl FnOnce(&mut H) + Send + 'static) -> io::Result<()> {
        let Some(mut h) = self.here.take() else {
            return Ok(());
        };
        if h.heavy() {
            h = home(send_away(h, self.offload.clone(), f)).await?;
        } else {
            f(&mut h);
        }
        self.here = Some(h);
        Ok(())
    }

    /// The host being here: hands the session what the client sent meanwhile, then sends
    /// the client what the session has (closing when it says so).
    async fn deliver(&mut self) -> io::Result<()> {
        if self.here.is_none() {
            return Ok(());
        }
        while let (Some(inbound), Some(id)) =
            (self.arrived.pop_front(), self.client.as_ref().map(|c| c.id))
        {
            self.step(move |h| {
                let now = h.now();
                h.session_mut().receive(id, inbound, now);
                h.stepped();
            })
            .await?;
        }
        let (Some(h), Some(c)) = (self.here.as_deref_mut(), self.client.as_mut()) else {
            return Ok(());
        };
        let utc_us = h.utc_now_us();
        let Some((raw, close)) = h
            .session_mut()
            .transmit()
            .map(|t| (t.bytes.split(), t.close))
        else {
            return Ok(());
        };
        let mut bytes = match &mut c.buffer {
            // Reports past the report buffer are dropped, and the client told.
            Some(buffer) => {
                let held_full = h.report_buffer_held_full();
                let admitted = buffer.admit(c.conn.queued(), raw, held_full);
                let mut bytes = admitted.bytes;
                if admitted.warn.is_some() || admitted.overflow {
                    h.buffer_events(admitted.warn, admitted.overflow, &mut bytes);
                }
                bytes
            }
            None => raw,
        };
        record_sent(&self.wire.recorder, c.rec, &bytes[..]).await;
        if close && h.abrupt() {
            // The connection dropped (a fault injected): a reset, nothing more sent.
            h.session_mut().disconnect(c.id);
            tracing::info!(peer = %c.peer, "connection dropped by the reader (reset)");
            let rec = c.rec;
            if let Some(c) = self.client.take() {
                c.conn.reset();
            }
            let reason = "the reader dropped the connection (reset)".to_string();
            record_marker(&self.wire.recorder, rec, Event::Disconnect, reason).await;
            return Ok(());
        }
        if let (Some(l), false) = (&self.wire.live, bytes.is_empty()) {
            l.tap.offer(Input::Frames {
                reader: l.name.clone(),
                bytes: bytes::Bytes::copy_from_slice(&bytes[..]),
                now_utc_us: utc_us,
            });
        }
        c.conn.queue_buf(&mut bytes);
        if close {
            // What the session said last goes out, then the connection closes.
            let _ = tokio::time::timeout(self.limits.close_flush, c.conn.shutdown()).await;
            h.session_mut().disconnect(c.id);
            tracing::info!(peer = %c.peer, "client disconnected by the reader");
            let rec = c.rec;
            self.client = None;
            let reason = "the reader closed the connection".to_string();
            record_marker(&self.wire.recorder, rec, Event::Disconnect, reason).await;
        }
        Ok(())
    }

    /// The stop: the client is told as the session says, and closed.
    async fn stop(&mut self) -> io::Result<()> {
        let mut h = match (self.here.take(), self.away.take()) {
            (Some(h), _) => h,
            (None, Some(a)) => home(a).await?,
            (None, None) => return Ok(()),
        };
        if let Some(mut c) = self.client.take() {
            h.session_mut().shutdown();
            if let Some(t) = h.session_mut().transmit() {
                record_sent(&self.wire.recorder, c.rec, &t.bytes[..]).await;
                c.conn.queue_buf(t.bytes);
            }
            let _ = tokio::time::timeout(self.limits.close_flush, c.conn.shutdown()).await;
            h.session_mut().disconnect(c.id);
            let reason = "the simulator stopped".to_string();
            record_marker(&self.wire.recorder, c.rec, Event::Disconnect, reason).await;
            self.told = None;
        }
        self.here = Some(h);
        self.tell_live();
        Ok(())
    }

    /// What the client's socket gave: a frame (kept for the session, in order), its output
    /// sent, or its end.
    async fn client_io(&mut self, r: io::Result<Io>) -> io::Result<()> {
        let Some(c) = self.client.as_ref() else {
            return Ok(());
        };
        match r {
            Ok(Io::Frame(inbound)) => {
                if let Some(n) = self.wire.live.as_ref().and_then(|l| l.frames_in.as_ref()) {
                    n.inc();
                }
                if let (Some(r), llrp::Inbound::Frame(f)) = (&self.wire.recorder, &inbound) {
                    let _ = r
                        .frame(r.now(), c.rec, Direction::ToReader, f.clone())
                        .await;
                }
                self.arrived.push_back(inbound);
            }
            Ok(Io::Flushed) => self.flushed = Instant::now(),
            Ok(Io::Closed) | Err(_) => {
                let reason = match &r {
                    Err(e) => {
                        tracing::info!(peer = %c.peer, "connection ended: {e}");
                        format!("client connection failed: {e}")
                    }
                    Ok(_) => "client closed".to_string(),
                };
                tracing::info!(peer = %c.peer, "client disconnected");
                record_marker(&self.wire.recorder, c.rec, Event::Disconnect, reason).await;
                let id = c.id;
                self.client = None;
                self.arrived.clear();
                let mut h = match (self.here.take(), self.away.take()) {
                    (Some(h), _) => h,
                    (None, Some(a)) => home(a).await?,
                    (None, None) => return Ok(()),
                };
                h.session_mut().disconnect(id);
                self.here = Some(h);
            }
        }
        Ok(())
    }

    /// A connection accepted (or an accept failed: accepts pause, longer each time).
    async fn accepted(
        &mut self,
        accepted: io::Result<(tokio::net::TcpStream, SocketAddr)>,
        tls: Option<&tls::Acceptor>,
    ) {
        match accepted {
            Ok((stream, peer)) => {
                self.backoff.reset();
                match tls {
                    Some(acceptor) => {
                        let acceptor = acceptor.clone();
                        self.handshakes.spawn(async move {
                            (peer, acceptor.accept(stream).await.map(Stream::from))
                        });
                    }
                    None => self.admit(Stream::from(stream), peer).await,
                }
            }
            Err(e) => {
                let pause = self.backoff.failed();
                tracing::warn!("accept failed: {e}; pausing accepts for {pause:?}");
                self.accept_after = Some(tokio::time::Instant::now() + pause);
            }
        }
    }

    /// A new connection (its TLS handshake done, if any): the session takes it, or refuses
    /// it (in a task of its own, bounded).
    async fn admit(&mut self, stream: Stream, peer: SocketAddr) {
        let Some(h) = self.here.as_deref_mut() else {
            return;
        };
        let now = h.now();
        let tls = if stream.is_tls() { " over TLS" } else { "" };
        let recorder = &self.wire.recorder;
        let rec = recorder.as_ref().map_or(0, Recorder::next_conn);
        record_marker(recorder, rec, Event::Connect, format!("client {peer}{tls}")).await;
        match h.session_mut().connect(now) {
            Accepted::Client(id) => {
                tracing::info!(%peer, "client connected{tls}");
                self.client = Some(Client {
                    id,
                    conn: Connection::from_stream(stream),
                    peer: peer.to_string(),
                    rec,
                    buffer: h.report_buffer().map(ReportBuffer::new),
                });
            }
            Accepted::Refused(bytes) => {
                record_sent(recorder, rec, &bytes).await;
                let reason = "refused: another client is connected".to_string();
                record_marker(recorder, rec, Event::Disconnect, reason).await;
                match Arc::clone(&self.refusal_slots).try_acquire_owned() {
                    Ok(slot) => {
                        tracing::info!(%peer, "refusing a second client");
                        let within = self.limits.refusal_write;
                        self.refusals.spawn(async move {
                            refuse(stream, &bytes, within).await;
                            drop(slot);
                        });
                    }
                    Err(_) => tracing::warn!(
                        %peer,
                        "a second client closed unanswered: {} refusals under way",
                        self.limits.refusals
                    ),
                }
            }
        }
    }

    /// Tells the live feed (and the own inventory) whether a client is connected and whether
    /// it inventories, when that changed.
    fn tell_live(&mut self) {
        let Some(live) = &self.wire.live else {
            return;
        };
        let connected = self.client.is_some();
        // While the host is away on its turn it is inventorying.
        let inventorying = connected && self.here.as_deref().is_none_or(Host::inventorying);
        if self.told == Some((connected, inventorying)) {
            return;
        }
        self.told = Some((connected, inventorying));
        if let Some(c) = &live.client {
            c.send_if_modified(|c| std::mem::replace(c, connected) != connected);
        }
        let peer = self.client.as_ref().map(|c| c.peer.clone());
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

    /// Waits up to [`DRAIN`] for the refusals and handshakes under way, then aborts them.
    async fn drain(&mut self) {
        self.handshakes.abort_all();
        let refusals = &mut self.refusals;
        let drained = tokio::time::timeout(DRAIN, async {
            while refusals.join_next().await.is_some() {}
        })
        .await;
        if drained.is_err() {
            self.refusals.shutdown().await;
        }
    }
}

/// Starts `f` on the host through `offload` (here if there is none, or it cannot take the
/// job); the host comes back through the receiver.
fn send_away<H: Host>(
    h: Box<H>,
    offload: Option<Offload>,
    f: impl FnOnce(&mut H) + Send + 'static,
) -> oneshot::Receiver<Box<H>> {
    let (tx, rx) = oneshot::channel();
    let job: Job = Box::new(move || {
        let mut h = h;
        f(&mut h);
        let _ = tx.send(h);
    });
    match offload {
        Some(run) => {
            if let Err(job) = run(job) {
                // No thread could take it: the work runs here after all.
                job();
            }
        }
        None => job(),
    }
    rx
}

/// The host back from its pool; an error if the pool lost it (a panic in its work).
async fn home<H>(away: oneshot::Receiver<Box<H>>) -> io::Result<Box<H>> {
    away.await
        .map_err(|_| io::Error::other("the served session was lost in its work"))
}

/// The host back from its turn; pending forever when it is not away.
async fn returned<H>(away: &mut Option<oneshot::Receiver<Box<H>>>) -> io::Result<Box<H>> {
    match away {
        Some(rx) => rx
            .await
            .map_err(|_| io::Error::other("the served session was lost in its work")),
        None => std::future::pending().await,
    }
}

/// The next notification of `nudge`; pending forever without one.
async fn nudged(nudge: &Option<Arc<tokio::sync::Notify>>) {
    match nudge {
        Some(n) => n.notified().await,
        None => std::future::pending().await,
    }
}

/// The connected client's next frame, or its write buffer sent (when `flush`); pending
/// forever without a client.
async fn client_io(client: &mut Option<Client>, flush: bool) -> io::Result<Io> {
    match client {
        Some(c) => c.conn.read_or_flush(flush).await,
        None => std::future::pending().await,
    }
}

/// Records the frames of `bytes` (whole frames, as a session sends them) as sent by the
/// server on connection `conn`.
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

#[cfg(test)]
mod tests;
