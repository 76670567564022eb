//! One direction's bytes as LLRP frames: the codec's frame splitter, resynchronising on the
//! first plausible header when the capture starts inside the stream.

use bytes::{Bytes, BytesMut};
use llrp::{FrameError, FrameHeader, FrameSplitter, MessageKind, Split};

use super::Piece;

/// Splits one direction's byte stream into frames with the codec's [`FrameSplitter`]; after
/// a length field that cannot be right everything is [`Piece::Bytes`], as a recording has it.
#[derive(Debug, Default)]
pub struct Framer {
    buf: BytesMut,
    unsynced: bool,
    /// Looking for the first frame boundary (the capture began after the handshake).
    hunting: bool,
    /// Bytes dropped while hunting.
    pub skipped: usize,
}

impl Framer {
    /// A framer for a stream that starts with a frame (`hunting` false) or somewhere inside
    /// one (`hunting` true: bytes before the first plausible LLRP header are dropped).
    pub fn new(hunting: bool) -> Framer {
        Framer {
            hunting,
            ..Framer::default()
        }
    }

    /// Takes the next bytes of the stream; appends what they complete to `out`.
    pub fn push(&mut self, data: &[u8], out: &mut Vec<Piece>) {
        if self.unsynced {
            out.push(Piece::Bytes(Bytes::copy_from_slice(data)));
            return;
        }
        self.buf.extend_from_slice(data);
        if self.hunting {
            self.hunt();
        }
        let splitter = FrameSplitter::default();
        loop {
            let len = match splitter.split(&self.buf) {
                Ok(Split::Frame(h)) => h.length as usize,
                Ok(Split::Incomplete(_)) => return,
                // A version the codec does not speak is still a whole frame of sane length.
                Err(FrameError::UnsupportedVersion(h)) if self.buf.len() >= h.length as usize => {
                    h.length as usize
                }
                Err(FrameError::UnsupportedVersion(_)) => return,
                Err(_) => {
                    self.unsynced = true;
                    out.push(Piece::Bytes(self.buf.split().freeze()));
                    return;
                }
            };
            out.push(Piece::Frame(self.buf.split_to(len).freeze()));
        }
    }

    /// Drops the bytes before the first offset where a plausible LLRP header starts (version
    /// 1 or 2, a sane length, a message type the codec names or CUSTOM_MESSAGE).
    fn hunt(&mut self) {
        let found = (0..self.buf.len().saturating_sub(llrp::frame::HEADER_LEN - 1))
            .find(|&i| plausible(&self.buf[i..]));
        let drop = match found {
            Some(i) => {
                self.hunting = false;
                i
            }
            None => self.buf.len().saturating_sub(llrp::frame::HEADER_LEN - 1),
        };
        self.skipped += drop;
        let _ = self.buf.split_to(drop);
    }

    /// Whether a length field that cannot be right was seen: everything after it is bytes.
    pub fn unsynced(&self) -> bool {
        self.unsynced
    }

    /// Bytes left that make no whole frame (at the end of the stream).
    pub fn finish(&mut self) -> Option<Bytes> {
        (!self.buf.is_empty()).then(|| self.buf.split().freeze())
    }
}

/// Whether `b` starts with a header that could begin an LLRP frame.
fn plausible(b: &[u8]) -> bool {
    let (Some(h), Some(k)) = (FrameHeader::peek(b), MessageKind::of_frame(b)) else {
        return false;
    };
    (1..=2).contains(&h.version)
        && (10..=llrp::frame::DEFAULT_MAX_FRAME_LEN).contains(&h.length)
        && (k.msg_type == llrp::message::CUSTOM_MESSAGE_TYPE || k.name() != "UNKNOWN")
}

/// Whether a frame is of a message kind the codec names (or a vendor message) and version.
pub fn known_frame(frame: &[u8]) -> bool {
    plausible(frame)
}
