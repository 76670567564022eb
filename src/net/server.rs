//! The simulated reader's TCP side: one task per simulated reader serves its [`Session`]
//! through the loop every session shares ([`drive`]); this module is the reader's
//! [`Host`]: its clock (simulated and wall time), its physics on the readers' pool, its
//! `--speed max` turns and its report buffer.
//!
//! With TLS ([`serve_tls`]) each accepted connection's handshake runs in a task of its own
//! (at most [`MAX_HANDSHAKES`] at once, each within [`tls::HANDSHAKE_TIMEOUT`]); only a
//! finished handshake reaches the session, so a client that fails it (plain LLRP sent to the
//! TLS port, a certificate it refuses, silence) is logged and changes nothing for the reader.

use std::io;
use std::sync::Arc;
use std::time::{Duration, Instant};

use bytes::BytesMut;
use tokio::net::TcpListener;
use tokio::sync::watch;

use super::clock::{Clock, Speed};
use super::drive::{drive, Host, Limits, Offload, Wire, TURN_BYTES};
use super::report_buffer::REPORT_BUFFER_BYTES;
use super::tls;
use crate::physics::pool::Pool;
use crate::reader::session::{Now, ServerSession, Session};
use crate::reader::Reader;
use crate::record::Recorder;

pub use super::drive::LiveHook;

/// Sees the reader after each step (writes ground truth).
pub type Observer = Box<dyn FnMut(&Reader) + Send>;

/// `--speed max`: most steps, and longest time, one turn runs (at most [`TURN_BYTES`] of
/// output).
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
    /// Woken when the reader's GPI lines are toggled or a fault is injected from outside.
    nudge: Arc<tokio::sync::Notify>,
}

impl SimReader {
    /// Wraps a reader's session and its clock; `observer` sees the reader after every step.
    /// Its inventory runs on the process's readers' pool.
    pub fn new(session: Session, clock: Arc<Clock>, observer: Option<Observer>) -> Self {
        let nudge = Arc::new(tokio::sync::Notify::new());
        let wake = Arc::clone(&nudge);
        // A toggle queued on the reader's GPIO panel wakes its serve loop (notify_one keeps
        // a permit, so one that comes while the loop is busy is not lost).
        session
            .reader()
            .gpio_panel()
            .on_change(move || wake.notify_one());
        // So does a fault injected.
        let wake = Arc::clone(&nudge);
        session.fault_panel().on_change(move || wake.notify_one());
        SimReader {
            session,
            clock,
            observer,
            pool: Pool::readers(),
            live: None,
            nudge,
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
}

impl Host for SimReader {
    type Session = Session;

    fn session_mut(&mut self) -> &mut Session {
        &mut self.session
    }

    fn now(&self) -> Now {
        Now {
            sim_us: self.clock.now_us(),
            wall_ms: self.clock.wall_ms(),
        }
    }

    fn wake_at(&self) -> Option<Instant> {
        self.clock.wake_at(self.session.deadline())
    }

    fn utc_now_us(&self) -> u64 {
        let reader = self.session.reader();
        reader.utc_us(reader.now_us())
    }

    fn inventorying(&self) -> bool {
        self.session.reader().inventorying()
    }

    fn stepped(&mut self) {
        if let Some(f) = &mut self.observer {
            f(self.session.reader());
        }
    }

    /// Whether running the reader now may compute physics (an ROSpec runs or is due).
    fn heavy(&self) -> bool {
        self.busy()
    }

    fn offload(&self) -> Option<Offload> {
        let pool = Arc::clone(&self.pool);
        Some(Arc::new(move |job| pool.run(job)))
    }

    fn streaming(&self) -> bool {
        self.clock.speed() == Speed::Max && self.session.deadline().sim_us.is_some()
    }

    fn turn(&mut self) {
        turn(self)
    }

    fn report_buffer(&self) -> Option<usize> {
        Some(REPORT_BUFFER_BYTES)
    }

    fn nudge(&self) -> Option<Arc<tokio::sync::Notify>> {
        Some(Arc::clone(&self.nudge))
    }

    fn report_buffer_held_full(&self) -> bool {
        (self.session.reader()).report_buffer_held_full(self.clock.wall_ms())
    }

    fn abrupt(&self) -> bool {
        self.session.abrupt()
    }

    fn listening(&self) -> bool {
        self.session.listening()
    }

    fn buffer_events(&mut self, warn: Option<u8>, overflow: bool, out: &mut BytesMut) {
        let reader = self.session.reader_mut();
        if let Some(m) = warn.and_then(|percent| reader.buffer_warning_event(percent)) {
            m.encode(out);
        }
        if overflow {
            reader.buffer_overflow_event().encode(out);
        }
    }
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
        sim.stepped();
        if sim.session.pending() >= TURN_BYTES
            || sim.session.deadline().sim_us.is_none()
            || sim.session.transmit().is_some_and(|t| t.close)
            || start.elapsed() >= TURN
        {
            break;
        }
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
    mut sim: SimReader,
    shutdown: watch::Receiver<bool>,
    recorder: Option<Recorder>,
) -> io::Result<()> {
    let wire = Wire {
        recorder,
        live: sim.live.take(),
    };
    let limits = Limits {
        handshakes: MAX_HANDSHAKES,
        refusals: MAX_HANDSHAKES,
        refusal_write: REFUSAL_WRITE,
        close_flush: SHUTDOWN_FLUSH,
    };
    drive(listener, tls, sim, wire, limits, shutdown).await
}
