//! [`Discard`]: the sink of a recorder that keeps no file, whose entries only go on to an
//! MCAP file ([`super::RecordOptions::mcap`]).

use std::io;

use super::Sink;

/// A recording that keeps nothing: the sink of a [`super::Recorder`] whose entries only go on to an
/// MCAP file ([`super::RecordOptions::mcap`]).
#[derive(Clone, Copy, Debug, Default)]
pub struct Discard;

impl Sink for Discard {
    type Part = io::Sink;

    fn open(&mut self, _part: u32) -> io::Result<io::Sink> {
        Ok(io::sink())
    }

    fn sync(&mut self, _file: &mut io::Sink) -> io::Result<()> {
        Ok(())
    }

    fn name(&self, _part: u32) -> String {
        "(none)".into()
    }
}
