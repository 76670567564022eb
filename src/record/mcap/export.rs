//! A recording as an MCAP file: every frame and non-frame byte run on its connection and
//! direction's channel, the reads and notifications decoded from the reader's frames, and the
//! connect and disconnect markers as reader events, each at its recorded UTC time.

use std::io::Write;

use super::{McapError, McapOut, Summary};
use crate::record::Recording;

/// Writes `recording` to `out` as an MCAP file; what it holds.
pub fn export<W: Write>(recording: &Recording, out: W) -> Result<(Summary, W), McapError> {
    let reader = recording
        .header
        .upstream
        .strip_prefix("sim:")
        .unwrap_or(&recording.header.upstream);
    let mut mcap = McapOut::new(out)?;
    for entry in &recording.entries {
        mcap.entry(reader, entry)?;
    }
    mcap.finish()
}
