//! Recordings of LLRP sessions: the versioned JSON Lines format ([`mod@format`]), the writer the
//! proxy and the simulated reader record through, on a thread of its own ([`mod@writer`]).

mod discard;
pub mod format;
pub mod mcap;
pub mod pcapng;
pub mod replay;
pub mod writer;

pub use discard::Discard;
pub use format::{Direction, Entry, Event, Header, ReaderInfo, RecordError, Recording, Stamp};
pub use writer::{Files, RecordOptions, Recorder, RecorderTask, Sink};
