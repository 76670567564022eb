//! `llrp-gateway decode`: LLRP frames from a file or standard input, one JSON object per
//! message on standard output (the decoding itself: [`crate::decode`]).

use std::io::{Read, Write};
use std::path::Path;

use crate::decode::{decode_stream, DecodeOptions, DecodeStreamError};

/// Why `decode` failed.
#[derive(Debug, thiserror::Error)]
pub enum DecodeCommandError {
    /// The input could not be read.
    #[error("cannot read input: {0}")]
    Read(std::io::Error),
    /// A frame did not decode, or did not encode back to its bytes.
    #[error("{0}")]
    Decode(DecodeStreamError),
    /// Standard output could not be written.
    #[error("writing output: {0}")]
    Write(std::io::Error),
}

/// Decodes `file` (standard input when `None` or `-`).
pub fn run(file: Option<&Path>, options: DecodeOptions) -> Result<(), DecodeCommandError> {
    let mut input = Vec::new();
    match file {
        None => std::io::stdin().read_to_end(&mut input),
        Some(p) if p.as_os_str() == "-" => std::io::stdin().read_to_end(&mut input),
        Some(p) => std::fs::File::open(p).and_then(|mut f| f.read_to_end(&mut input)),
    }
    .map_err(DecodeCommandError::Read)?;
    let stdout = std::io::stdout();
    let mut out = std::io::BufWriter::new(stdout.lock());
    let result = decode_stream(&input, options, &mut out);
    let flushed = out.flush();
    result.map_err(DecodeCommandError::Decode)?;
    flushed.map_err(DecodeCommandError::Write)
}
