//! [`McapTap`]: where every message an [`McapOut`] writes is also handed, as it is written
//! (the live Foxglove view, [`crate::foxglove`]). The tap sits at the one place where a
//! message's topic, schema and CDR bytes come together, so a live view carries exactly the
//! channels, schemas and messages of the MCAP file, whichever part of the file made them.

use std::io::Sink;
use std::path::Path;

use super::msgs::MsgType;
use super::{McapError, McapOut, McapThread};

/// The schema encoding of every channel.
pub const SCHEMA_ENCODING: &str = "ros2msg";
/// The message encoding of every channel.
pub const MESSAGE_ENCODING: &str = "cdr";

/// One message as written: its channel (topic, type) and its data.
#[derive(Clone, Copy, Debug)]
pub struct TapMessage<'a> {
    /// The channel's topic.
    pub topic: &'a str,
    /// Its type: the schema's name and text ([`SCHEMA_ENCODING`]).
    pub ty: MsgType,
    /// The MCAP log time (reception), UTC ns.
    pub log_ns: u64,
    /// The MCAP publish time (the reader's own time where it has one), UTC ns.
    pub publish_ns: u64,
    /// The message, [`MESSAGE_ENCODING`].
    pub data: &'a [u8],
}

/// Receives every message an [`McapOut`] writes; it runs on the writer's thread, so it must
/// not block.
pub trait McapTap: Send {
    /// One message, handed on before it is written to the file.
    fn message(&mut self, m: &TapMessage<'_>);
}

impl McapOut<Sink> {
    /// An MCAP output with no file, for its tap alone: unchunked and uncompressed, into
    /// `std::io::sink()`, so nothing is kept or compressed for a file no one reads.
    pub fn tap_only(tap: Box<dyn McapTap>) -> Result<McapOut<Sink>, McapError> {
        let writer = ::mcap::WriteOptions::new()
            .profile("ros2")
            .use_chunks(false)
            .compression(None)
            .disable_seeking(true)
            .create(::mcap::write::NoSeek::new(std::io::sink()))?;
        Ok(McapOut::with_writer(writer).with_tap(tap))
    }
}

impl McapThread {
    /// The writer of a running command's MCAP output: to the file at `path` (created as
    /// [`McapThread::create`] does) and/or to `tap`; none when neither is given.
    pub fn open(
        path: Option<&Path>,
        force: bool,
        tap: Option<Box<dyn McapTap>>,
    ) -> Result<Option<McapThread>, McapError> {
        match (path, tap) {
            (Some(path), tap) => {
                let file = crate::files::create_stream(path, &[], force)?;
                let mut out = McapOut::new(std::io::BufWriter::new(file))?;
                if let Some(tap) = tap {
                    out = out.with_tap(tap);
                }
                McapThread::start_out(out).map(Some)
            }
            (None, Some(tap)) => McapThread::start_out(McapOut::tap_only(tap)?).map(Some),
            (None, None) => Ok(None),
        }
    }
}

#[cfg(test)]
mod tests {
    use std::sync::{Arc, Mutex};

    use super::*;

    /// A message's topic, schema name, log time and data.
    type Kept = (String, String, u64, Vec<u8>);

    /// Keeps every message.
    struct Keep(Arc<Mutex<Vec<Kept>>>);

    impl McapTap for Keep {
        fn message(&mut self, m: &TapMessage<'_>) {
            let mut v = self.0.lock().expect("not poisoned");
            v.push((
                m.topic.into(),
                m.ty.name().into(),
                m.log_ns,
                m.data.to_vec(),
            ));
        }
    }

    #[test]
    fn the_tap_sees_every_message_of_the_file_with_its_channel_and_bytes() {
        let seen = Arc::new(Mutex::new(Vec::new()));
        let mut out = McapOut::new(Vec::new())
            .expect("starts")
            .with_tap(Box::new(Keep(seen.clone())));
        out.event("dock 1", 1, "connect", "", 5_000, 5_000)
            .expect("written");
        out.event("dock 2", 1, "disconnect", "gone", 7_000, 6_000)
            .expect("written");
        let (_, file) = out.finish().expect("finished");

        let in_file: Vec<Kept> = ::mcap::MessageStream::new(&file)
            .expect("a file")
            .map(|m| {
                let m = m.expect("a message");
                let schema = m.channel.schema.as_ref().expect("a schema");
                let name = schema.name.clone();
                (m.channel.topic.clone(), name, m.log_time, m.data.to_vec())
            })
            .collect();
        let seen = seen.lock().expect("not poisoned").clone();
        assert_eq!(seen.len(), 4, "two events, each also on /log: {seen:?}");
        assert_eq!(seen, in_file);
    }

    #[test]
    fn a_tap_only_output_hands_on_every_message() {
        let seen = Arc::new(Mutex::new(Vec::new()));
        let mut out = McapOut::tap_only(Box::new(Keep(seen.clone()))).expect("starts");
        out.event("r", 3, "connect", "", 1, 1).expect("written");
        let (summary, _) = out.finish().expect("finished");
        let topics: Vec<String> = seen
            .lock()
            .expect("ok")
            .iter()
            .map(|m| m.0.clone())
            .collect();
        assert_eq!(topics, ["/llrp/r/events", "/log"]);
        assert_eq!(summary.messages, 2);
    }
}
