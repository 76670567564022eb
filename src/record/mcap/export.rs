//! A recording as an MCAP file: every frame and non-frame byte run on its connection and
//! direction's channel, the reads and notifications decoded from the reader's frames, and the
//! connect and disconnect markers as reader events, each at its recorded UTC time.

use std::io::Write;

use super::{McapError, McapOut, Summary};
use crate::record::{Entry, Event, Recording};

/// Writes `recording` to `out` as an MCAP file; what it holds.
pub fn export<W: Write>(recording: &Recording, out: W) -> Result<(Summary, W), McapError> {
    let reader = recording
        .header
        .upstream
        .strip_prefix("sim:")
        .unwrap_or(&recording.header.upstream);
    let mut mcap = McapOut::new(out)?;
    for entry in &recording.entries {
        let ns = entry.at().utc_us.saturating_mul(1000);
        match entry {
            Entry::Frame {
                conn, dir, frame, ..
            } => mcap.frame(reader, *conn, *dir, true, ns, frame)?,
            Entry::Bytes {
                conn, dir, bytes, ..
            } => mcap.frame(reader, *conn, *dir, false, ns, bytes)?,
            Entry::Marker {
                conn,
                event,
                reason,
                ..
            } => {
                let kind = match event {
                    Event::Connect => "connect",
                    Event::Disconnect => "disconnect",
                };
                mcap.event(reader, *conn, kind, reason, ns, ns)?;
            }
            // What was learnt of the reader is in its frames (capabilities, configuration).
            Entry::Reader { .. } => {}
        }
    }
    mcap.finish()
}
