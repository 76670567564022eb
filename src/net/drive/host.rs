//! What the serve loop needs of a session's owner ([`Host`]) and of the wire ([`Wire`]), and
//! its bounds ([`Limits`]).

use crate::reads::ReaderName;
use std::time::{Duration, Instant};

use bytes::BytesMut;
use llrp_gateway_vocab::feed::Tap;
use llrp_gateway_vocab::session::ServerSession;
use prometheus_client::metrics::counter::Counter;
use std::sync::Arc;
use tokio::sync::watch;

use crate::record::Recorder;

/// Work handed to a host's pool.
pub type Job = Box<dyn FnOnce() + Send>;

/// Runs a [`Job`] off the async threads, or gives it back when it cannot.
pub type Offload = Arc<dyn Fn(Job) -> Result<(), Job> + Send + Sync>;

/// The session's time.
pub type NowOf<H> = <<H as Host>::Session as ServerSession>::Now;

/// What the loop needs of a session's owner beyond the session.
pub trait Host: Send + 'static {
    /// The session served.
    type Session: ServerSession;

    /// The session, to drive it.
    fn session_mut(&mut self) -> &mut Self::Session;
    /// The session's time now.
    fn now(&self) -> NowOf<Self>;
    /// The instant the session's deadline falls due; `None`: never, or not by the clock
    /// (streaming steps it).
    fn wake_at(&self) -> Option<Instant>;
    /// The wall clock (UTC µs) the frames sent now are offered to the live feed with.
    fn utc_now_us(&self) -> u64;
    /// Whether the connected client has the session inventorying (for the live feed).
    fn inventorying(&self) -> bool;
    /// Called after each step the session takes.
    fn stepped(&mut self) {}
    /// Whether the next step may be heavy: it then runs through [`Host::offload`].
    fn heavy(&self) -> bool {
        false
    }
    /// Where heavy steps run; `None`: here.
    fn offload(&self) -> Option<Offload> {
        None
    }
    /// Whether the session streams now: steps back to back ([`Host::turn`]) as fast as the
    /// client takes output, rather than at its deadlines.
    fn streaming(&self) -> bool {
        false
    }
    /// One streaming turn: steps until about [`TURN_BYTES`](super::TURN_BYTES) of output or the turn's end.
    fn turn(&mut self) {}
    /// The client's report buffer (bytes queued past which reports are dropped), if any.
    fn report_buffer(&self) -> Option<usize> {
        None
    }
    /// Encodes into `out` the events of the report buffer: a warning at `warn` percent, an
    /// overflow.
    fn buffer_events(&mut self, warn: Option<u8>, overflow: bool, out: &mut BytesMut) {
        let _ = (warn, overflow, out);
    }
    /// Most bytes queued for the client before the session is run again on its deadline
    /// (`None`: no bound, the report buffer's choice).
    fn backlog(&self) -> Option<usize> {
        None
    }
    /// Notified when something outside the session gave it work (a GPI line toggled through
    /// the HTTP API): the loop then runs it at once. `None`: nothing outside does.
    fn nudge(&self) -> Option<Arc<tokio::sync::Notify>> {
        None
    }
    /// Whether the report buffer counts as full now, whatever is queued (a fault injected:
    /// as if the client had stopped reading).
    fn report_buffer_held_full(&self) -> bool {
        false
    }
    /// Whether the close the session asks for is a reset: the connection is dropped at once
    /// (TCP RST), what waits to be sent is lost.
    fn abrupt(&self) -> bool {
        false
    }
    /// Whether the server listens now: while not (a simulated reader rebooting), the loop
    /// closes its listener, so connections are refused, and binds it again after.
    fn listening(&self) -> bool {
        true
    }
}

/// The live localizer's view of a served session.
pub struct LiveHook {
    /// The reader's name in the localizer.
    pub name: ReaderName,
    /// The localizer's tap: every frame sent to the client is offered to it.
    pub tap: Tap,
    /// Told whether a client is connected (the simulator's own inventory runs while not).
    pub client: Option<watch::Sender<bool>>,
    /// Counts the frames the client sends.
    pub frames_in: Option<Counter>,
}

/// What sees the wire besides the client: the recorder and the live localizer.
#[derive(Default)]
pub struct Wire {
    /// Records every frame each way and the connections' markers.
    pub recorder: Option<Recorder>,
    /// The live localizer's tap and link state.
    pub live: Option<LiveHook>,
}

/// The loop's bounds.
#[derive(Clone, Copy, Debug)]
pub struct Limits {
    /// Most TLS handshakes under way at once; accepting waits while this many run.
    pub handshakes: usize,
    /// Most refusals being written at once; a connection refused beyond is closed at once.
    pub refusals: usize,
    /// How long a refused client gets to take its refusal.
    pub refusal_write: Duration,
    /// How long a closing client gets to take the session's last bytes.
    pub close_flush: Duration,
}
