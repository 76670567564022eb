//! The simulated reader's TCP side: one listener per scenario reader, one client at a time
//! (a second one is refused the LLRP way), frames in, the reader state machine in the middle,
//! messages out.

use std::io;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use bytes::{Buf, BytesMut};
use llrp::params::LlrpStatus;
use llrp::{FrameError, FrameSplitter, Message, Split, StatusCode};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::tcp::OwnedWriteHalf;
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{mpsc, watch};

use super::clock::{Clock, Speed};
use crate::reader::{Output, Reader, CONNECTION_ANOTHER_ATTEMPTED, CONNECTION_CLIENT_EXISTS};

/// How often a connection runs the reader in real-time modes.
const TICK: Duration = Duration::from_millis(10);

/// Sees the reader after each step (writes ground truth).
pub type Observer = Box<dyn Fn(&Reader) + Send + Sync>;

/// A simulated reader ready to serve: the state machine, its clock and who is connected.
pub struct SimReader {
    reader: Mutex<Reader>,
    clock: Arc<Clock>,
    /// Channel to the connected client's task (to tell it another client tried).
    active: Mutex<Option<mpsc::UnboundedSender<u16>>>,
    /// Called with the simulated time reached after each step (ground-truth output).
    observer: Option<Observer>,
}

impl SimReader {
    /// Wraps a reader and its clock; `observer` sees the reader after every step.
    pub fn new(reader: Reader, clock: Arc<Clock>, observer: Option<Observer>) -> Arc<Self> {
        Arc::new(SimReader {
            reader: Mutex::new(reader),
            clock,
            active: Mutex::new(None),
            observer,
        })
    }

    fn reader(&self) -> MutexGuard<'_, Reader> {
        // A poisoned lock means a task panicked while holding it; the reader state is still
        // consistent enough to keep serving (each handler leaves it valid between calls).
        self.reader.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn active(&self) -> MutexGuard<'_, Option<mpsc::UnboundedSender<u16>>> {
        self.active.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn observe(&self, r: &Reader) {
        if let Some(f) = &self.observer {
            f(r);
        }
    }
}

/// Accepts clients on `listener` until `shutdown` turns true.
pub async fn serve(
    listener: TcpListener,
    sim: Arc<SimReader>,
    mut shutdown: watch::Receiver<bool>,
) -> io::Result<()> {
    loop {
        tokio::select! {
            accepted = listener.accept() => {
                let (stream, peer) = match accepted {
                    Ok(x) => x,
                    Err(e) => {
                        tracing::warn!("accept failed: {e}");
                        continue;
                    }
                };
                let _ = stream.set_nodelay(true);
                let busy = sim.active().as_ref().is_some_and(|tx| !tx.is_closed());
                if busy {
                    tracing::info!(%peer, "refusing a second client");
                    if let Some(tx) = sim.active().as_ref() {
                        let _ = tx.send(CONNECTION_ANOTHER_ATTEMPTED);
                    }
                    let msg = sim.reader().connection_event(CONNECTION_CLIENT_EXISTS);
                    tokio::spawn(refuse(stream, msg));
                    continue;
                }
                let (tx, rx) = mpsc::unbounded_channel();
                *sim.active() = Some(tx);
                tracing::info!(%peer, "client connected");
                let sim = sim.clone();
                let shutdown = shutdown.clone();
                tokio::spawn(async move {
                    if let Err(e) = connection(stream, sim.clone(), rx, shutdown).await {
                        tracing::info!(%peer, "connection ended: {e}");
                    }
                    sim.reader().disconnect();
                    *sim.active() = None;
                    tracing::info!(%peer, "client disconnected");
                });
            }
            _ = shutdown.changed() => {
                if *shutdown.borrow() {
                    return Ok(());
                }
            }
        }
    }
}

/// Tells a second client it is refused, then closes.
async fn refuse(mut stream: TcpStream, msg: Message) {
    let _ = stream.write_all(&msg.to_bytes()).await;
    let _ = stream.shutdown().await;
}

/// Encodes outputs into `buf`; returns false if the connection must close after it is sent.
fn encode_outputs(buf: &mut BytesMut, outputs: Vec<Output>) -> bool {
    for o in outputs {
        match o {
            Output::Send(m) => m.encode(buf),
            Output::Close => return false,
        }
    }
    true
}

/// Sends what `buf` holds; shuts the connection down if `open` is false. Returns `open`.
async fn flush(wr: &mut OwnedWriteHalf, buf: &mut BytesMut, open: bool) -> io::Result<bool> {
    if !buf.is_empty() {
        wr.write_all(buf).await?;
        buf.clear();
    }
    if !open {
        wr.shutdown().await?;
    }
    Ok(open)
}

/// ERROR_MESSAGE for a frame whose length field cannot be right.
fn bad_length(e: &FrameError) -> Message {
    let (id, text) = match e {
        FrameError::TooShort { id, .. } | FrameError::TooLong { id, .. } => (*id, e.to_string()),
        FrameError::UnsupportedVersion(h) => (h.id, e.to_string()),
    };
    Message::new(
        id,
        llrp::message::ErrorMessage {
            llrp_status: LlrpStatus::new(StatusCode::M_FieldError, text),
            ..Default::default()
        },
    )
}

/// Handles every whole frame at the front of `buf`; returns the outputs and whether the
/// stream is still in sync.
fn handle_frames(
    sim: &SimReader,
    buf: &mut BytesMut,
    splitter: &FrameSplitter,
) -> (Vec<Output>, bool) {
    let mut out = Vec::new();
    loop {
        match splitter.split(buf) {
            Ok(Split::Incomplete(_)) => return (out, true),
            Ok(Split::Frame(h)) => {
                let frame = buf.split_to(h.length as usize);
                let now = sim.clock.now_us();
                let wall = sim.clock.wall_ms();
                let mut r = sim.reader();
                match Message::decode(&frame) {
                    Ok(m) => {
                        tracing::debug!(message = m.name(), id = m.id, "request");
                        out.extend(r.handle(m, now, wall));
                    }
                    Err(e) => {
                        // A client's mistake: answered on the wire, logged quietly.
                        tracing::info!(
                            "malformed {}: {e}",
                            llrp::message::message_name(h.msg_type, &frame)
                        );
                        let reply = r.reject(&h, &frame, &e);
                        out.push(Output::Send(reply));
                    }
                }
                sim.observe(&r);
            }
            Err(FrameError::UnsupportedVersion(h)) => {
                if buf.len() < h.length as usize {
                    return (out, true);
                }
                buf.advance(h.length as usize);
                out.push(Output::Send(Reader::unsupported_version(&h)));
            }
            Err(e) => {
                tracing::info!("unrecoverable framing error: {e}");
                out.push(Output::Send(bad_length(&e)));
                out.push(Output::Close);
                return (out, false);
            }
        }
    }
}

/// `--speed max`: output is sent once this much is waiting...
const FLUSH_BYTES: usize = 64 * 1024;
/// ... or this long after the last send, so a slow scenario still streams.
const FLUSH_AFTER: Duration = Duration::from_millis(1);
/// `--speed max`: most steps, and longest time, run before the connection looks at its
/// socket again.
const STEPS_PER_TURN: usize = 64;
const TURN: Duration = Duration::from_millis(2);

/// Serves one client until it leaves, the reader closes it, or shutdown.
///
/// At `--speed max` the reader steps simulated time while it has work and the client keeps
/// up: steps run in turns of up to [`STEPS_PER_TURN`] (or [`TURN`]), their messages collect in one buffer
/// that is sent once it holds [`FLUSH_BYTES`] (or [`FLUSH_AFTER`] has passed), and the next
/// turn waits until the socket has taken it, so a slow client slows simulated time down and
/// the buffer never grows beyond one turn's output. Requests are read between turns and
/// answered at once.
async fn connection(
    stream: TcpStream,
    sim: Arc<SimReader>,
    mut notices: mpsc::UnboundedReceiver<u16>,
    mut shutdown: watch::Receiver<bool>,
) -> io::Result<()> {
    let (mut rd, mut wr) = stream.into_split();
    let splitter = FrameSplitter::default();
    let mut buf = BytesMut::with_capacity(64 * 1024);
    let mut out = BytesMut::with_capacity(2 * FLUSH_BYTES);
    let greeting = sim
        .reader()
        .connect(sim.clock.now_us(), sim.clock.wall_ms());
    let open = encode_outputs(&mut out, greeting);
    if !flush(&mut wr, &mut out, open).await? {
        return Ok(());
    }
    let max = sim.clock.speed() == Speed::Max;
    let mut tick = tokio::time::interval(TICK);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut flushed = Instant::now();
    loop {
        let busy = max && sim.reader().next_deadline_us().is_some();
        // Whether what `out` holds must go now.
        let urgent = tokio::select! {
            biased;
            r = rd.read_buf(&mut buf) => {
                match r {
                    Ok(0) => return Ok(()),
                    Ok(_) => {
                        let (outputs, in_sync) = handle_frames(&sim, &mut buf, &splitter);
                        let open = encode_outputs(&mut out, outputs);
                        if !in_sync || !open {
                            flush(&mut wr, &mut out, false).await?;
                            return Ok(());
                        }
                        true
                    }
                    Err(e) => return Err(e),
                }
            }
            Some(status) = notices.recv() => {
                let m = sim.reader().connection_event(status);
                m.encode(&mut out);
                true
            }
            _ = shutdown.changed() => {
                if *shutdown.borrow() {
                    return Ok(());
                }
                false
            }
            _ = std::future::ready(()), if busy => {
                let open = {
                    let mut r = sim.reader();
                    let mut open = true;
                    let turn = Instant::now();
                    for _ in 0..STEPS_PER_TURN {
                        let now = sim.clock.step();
                        let outputs = r.advance(now, sim.clock.wall_ms());
                        sim.observe(&r);
                        open = encode_outputs(&mut out, outputs);
                        if !open
                            || out.len() >= FLUSH_BYTES
                            || r.next_deadline_us().is_none()
                            || turn.elapsed() >= TURN
                        {
                            break;
                        }
                    }
                    open
                };
                if !open {
                    flush(&mut wr, &mut out, false).await?;
                    return Ok(());
                }
                out.len() >= FLUSH_BYTES || flushed.elapsed() >= FLUSH_AFTER
            }
            _ = tick.tick() => {
                let outputs = {
                    let now = sim.clock.now_us();
                    let mut r = sim.reader();
                    let outputs = r.advance(now, sim.clock.wall_ms());
                    sim.observe(&r);
                    outputs
                };
                if !encode_outputs(&mut out, outputs) {
                    flush(&mut wr, &mut out, false).await?;
                    return Ok(());
                }
                true
            }
        };
        if urgent || !busy {
            flush(&mut wr, &mut out, true).await?;
            flushed = Instant::now();
        }
        if busy {
            // `--speed max` always has work: give the other tasks on this thread a turn.
            tokio::task::yield_now().await;
        }
    }
}
