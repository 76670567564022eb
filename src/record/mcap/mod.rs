//! MCAP out: LLRP sessions, tag reads and reader events as an MCAP file of ROS 2 messages
//! (profile `ros2`, `ros2msg` schemas, CDR messages), which Foxglove, `ros2 bag play` and ROS 2
//! bag readers read. See `docs/robotics.md`.
//!
//! * [`McapOut`]: the file being written, from frames (each connection and direction its own
//!   channel, byte for byte; the reads and reader events decoded from them), reads and events;
//! * [`export()`]: a recording ([`crate::record::Recording`]) as an MCAP file;
//! * [`McapThread`]: an [`McapOut`] on a thread of its own, which running commands hand their
//!   data to (file IO never on an async worker);
//! * [`McapTap`]: every message written handed on as well (the live Foxglove view);
//! * the message set ([`msgs`]) and its CDR encoder ([`cdr`]); each tag's phase unwrapped
//!   per stream ([`phase`]).
//!
//! Times are UTC nanoseconds since the Unix epoch throughout: an MCAP message's log time is
//! when the gateway received it, its publish time the reader's own timestamp where it has one
//! (a read's first-seen time, a notification's UTCTimestamp), else the log time.

pub mod cdr;
pub mod cdr_read;
pub mod estimates;
mod export;
pub mod geo;
pub mod msgs;
pub mod phase;
pub mod read;
pub mod recording_in;
pub mod ros_in;
pub mod scene;
pub mod scene_msgs;
mod tap;
mod thread;
mod writer;

pub use export::export;
pub use tap::{McapTap, TapMessage, MESSAGE_ENCODING, SCHEMA_ENCODING};
pub use thread::{McapItem, McapSender, McapTee, McapThread};
pub use writer::McapOut;

/// Why an MCAP file could not be written.
#[derive(Debug, thiserror::Error)]
pub enum McapError {
    /// The MCAP writer failed (an IO error of the file, a record it refused).
    #[error("MCAP: {error}{}", cause(error))]
    Mcap {
        /// The writer's error.
        #[from]
        error: ::mcap::McapError,
    },
    /// The writer's thread is gone (it failed earlier, or panicked).
    #[error("the MCAP writer's thread ended early")]
    ThreadGone,
    /// The file cannot be created (the message names it).
    #[error("{0}")]
    File(#[from] crate::files::OutputError),
}

/// `: CAUSE` when the writer's error wraps one (its IO errors say only "I/O error").
fn cause(e: &::mcap::McapError) -> String {
    std::error::Error::source(e)
        .map(|s| format!(": {s}"))
        .unwrap_or_default()
}

/// What an MCAP file holds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Summary {
    /// Messages of every kind.
    pub messages: u64,
    /// Channels.
    pub channels: usize,
    /// LLRP frames (and non-frame byte runs).
    pub frames: u64,
    /// Tag reads.
    pub reads: u64,
    /// Reader events.
    pub events: u64,
    /// RO_ACCESS_REPORTs that did not decode (kept as frames, no reads from them).
    pub undecodable_reports: u64,
}

/// A reader's name as a ROS 2 topic name token (and frame id): letters, digits and single
/// underscores, not starting with a digit; every other run of characters becomes one `_`.
/// `127.0.0.1:5084` is `r_127_0_0_1_5084`, `dock 1` is `dock_1`, an empty name `reader`.
pub fn topic_token(name: &str) -> String {
    let mut t = String::with_capacity(name.len() + 2);
    for c in name.chars() {
        if c.is_ascii_alphanumeric() {
            t.push(c);
        } else if !t.is_empty() && !t.ends_with('_') {
            t.push('_');
        }
    }
    while t.ends_with('_') {
        t.pop();
    }
    if t.is_empty() {
        return "reader".into();
    }
    if t.starts_with(|c: char| c.is_ascii_digit()) {
        t.insert_str(0, "r_");
    }
    t
}

#[cfg(test)]
mod tests {
    use super::topic_token;

    #[test]
    fn a_reader_name_becomes_a_valid_topic_token() {
        assert_eq!(topic_token("127.0.0.1:5084"), "r_127_0_0_1_5084");
        assert_eq!(topic_token("dock 1"), "dock_1");
        assert_eq!(topic_token("s1-reader"), "s1_reader");
        assert_eq!(topic_token("__a__b__"), "a_b");
        assert_eq!(topic_token(""), "reader");
        assert_eq!(topic_token("€"), "reader");
    }
}
