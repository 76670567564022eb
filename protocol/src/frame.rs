//! Message framing: the 10-byte header and splitting a byte stream into whole messages.

use bytes::{BufMut, Bytes, BytesMut};

use crate::error::FrameError;

/// Size of the LLRP message header in bytes.
pub const HEADER_LEN: usize = 10;

/// Default upper bound on a message's length field (4 MiB).
pub const DEFAULT_MAX_FRAME_LEN: u32 = 4 * 1024 * 1024;

/// LLRP 1.0.1 header version.
pub const VERSION_1_0_1: u8 = 1;
/// LLRP 1.1 header version.
pub const VERSION_1_1: u8 = 2;

/// The fixed 10-byte message header.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct FrameHeader {
    /// Protocol version (1 = LLRP 1.0.1, 2 = LLRP 1.1).
    pub version: u8,
    /// Message type, 0..=1023.
    pub msg_type: u16,
    /// Whole message length, header included.
    pub length: u32,
    /// Message ID; a response carries its request's ID.
    pub id: u32,
}

impl FrameHeader {
    /// Reads the header from the first 10 bytes, if present (no validation).
    pub fn peek(buf: &[u8]) -> Option<FrameHeader> {
        let h: &[u8; HEADER_LEN] = buf.get(..HEADER_LEN)?.try_into().ok()?;
        let first = u16::from_be_bytes([h[0], h[1]]);
        Some(FrameHeader {
            version: ((first >> 10) & 0x7) as u8,
            msg_type: first & 0x3FF,
            length: u32::from_be_bytes([h[2], h[3], h[4], h[5]]),
            id: u32::from_be_bytes([h[6], h[7], h[8], h[9]]),
        })
    }

    /// Writes the header.
    pub fn encode(&self, buf: &mut impl BufMut) {
        buf.put_u16((u16::from(self.version & 0x7) << 10) | (self.msg_type & 0x3FF));
        buf.put_u32(self.length);
        buf.put_u32(self.id);
    }
}

/// What the splitter found at the front of a buffer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Split {
    /// A whole message of `header.length` bytes is at the front of the buffer.
    Frame(FrameHeader),
    /// At least this many more bytes are needed before a message can be returned.
    Incomplete(usize),
}

/// Splits a byte stream into LLRP messages, enforcing length and version rules.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameSplitter {
    /// Largest accepted length field.
    pub max_len: u32,
}

impl Default for FrameSplitter {
    fn default() -> Self {
        FrameSplitter {
            max_len: DEFAULT_MAX_FRAME_LEN,
        }
    }
}

impl FrameSplitter {
    /// A splitter accepting messages up to `max_len` bytes.
    pub fn new(max_len: u32) -> Self {
        FrameSplitter { max_len }
    }

    /// Looks at the front of `buf`: a whole frame, how many bytes are missing, or an error.
    ///
    /// `TooShort` / `TooLong` are fatal for the stream; `UnsupportedVersion` carries the header
    /// so the caller can answer ERROR_MESSAGE and skip `length` bytes once they are buffered.
    pub fn split(&self, buf: &[u8]) -> Result<Split, FrameError> {
        let Some(header) = FrameHeader::peek(buf) else {
            return Ok(Split::Incomplete(HEADER_LEN - buf.len()));
        };
        if header.length < HEADER_LEN as u32 {
            return Err(FrameError::TooShort {
                len: header.length,
                msg_type: header.msg_type,
                id: header.id,
            });
        }
        if header.length > self.max_len {
            return Err(FrameError::TooLong {
                len: header.length,
                max: self.max_len,
                msg_type: header.msg_type,
                id: header.id,
            });
        }
        if header.version != VERSION_1_0_1 && header.version != VERSION_1_1 {
            return Err(FrameError::UnsupportedVersion(header));
        }
        let len = header.length as usize;
        if buf.len() < len {
            return Ok(Split::Incomplete(len - buf.len()));
        }
        Ok(Split::Frame(header))
    }
}

/// What a [`Deframer`] found in a byte stream.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Inbound {
    /// One whole frame, header included, byte for byte as received (any header version:
    /// whether the version is spoken is the receiver's decision, the length is sane).
    Frame(Bytes),
    /// A header whose length field cannot be right (below 10 or above the limit): the stream
    /// cannot be resynchronised, and the deframer yields this from now on.
    Unsynced(FrameError),
}

/// Turns a byte stream into whole frames: bytes are appended to its buffer as they arrive,
/// frames come out. The buffer holds at most one frame beyond what has been taken, so the
/// splitter's limit bounds it.
#[derive(Clone, Debug, Default)]
pub struct Deframer {
    buf: BytesMut,
    splitter: FrameSplitter,
    unsynced: Option<FrameError>,
}

impl Deframer {
    /// A deframer with the given limits.
    pub fn new(splitter: FrameSplitter) -> Self {
        Deframer {
            buf: BytesMut::new(),
            splitter,
            unsynced: None,
        }
    }

    /// The buffer to append received bytes to.
    pub fn buffer_mut(&mut self) -> &mut BytesMut {
        &mut self.buf
    }

    /// Bytes received but not yet returned as a frame.
    pub fn buffered(&self) -> usize {
        self.buf.len()
    }

    /// The next whole frame, or the error that ended the stream; `None` while more bytes are
    /// needed (the buffer then has room reserved for them).
    pub fn next_frame(&mut self) -> Option<Inbound> {
        if let Some(e) = &self.unsynced {
            return Some(Inbound::Unsynced(e.clone()));
        }
        let len = match self.splitter.split(&self.buf) {
            Ok(Split::Frame(h)) => h.length as usize,
            Ok(Split::Incomplete(more)) => {
                self.buf.reserve(more);
                return None;
            }
            Err(FrameError::UnsupportedVersion(h)) => {
                let len = h.length as usize;
                if self.buf.len() < len {
                    self.buf.reserve(len - self.buf.len());
                    return None;
                }
                len
            }
            Err(e) => {
                self.unsynced = Some(e.clone());
                self.buf.clear();
                return Some(Inbound::Unsynced(e));
            }
        };
        Some(Inbound::Frame(self.buf.split_to(len).freeze()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn keepalive(version: u8, len: u32) -> Vec<u8> {
        let mut v = Vec::new();
        FrameHeader {
            version,
            msg_type: 62,
            length: len,
            id: 7,
        }
        .encode(&mut v);
        v
    }

    #[test]
    fn keepalive_header_matches_spec_bytes() {
        assert_eq!(keepalive(1, 10), [0x04, 0x3E, 0, 0, 0, 10, 0, 0, 0, 7]);
    }

    #[test]
    fn reports_missing_bytes() {
        let s = FrameSplitter::default();
        let f = keepalive(1, 10);
        assert_eq!(s.split(&f[..3]), Ok(Split::Incomplete(7)));
        assert_eq!(s.split(&[]), Ok(Split::Incomplete(10)));
        let long = keepalive(1, 14);
        assert_eq!(s.split(&long), Ok(Split::Incomplete(4)));
        match s.split(&f) {
            Ok(Split::Frame(h)) => assert_eq!((h.msg_type, h.length, h.id), (62, 10, 7)),
            other => panic!("expected a frame, got {other:?}"),
        }
    }

    #[test]
    fn rejects_bad_lengths_and_versions() {
        let s = FrameSplitter::new(100);
        assert!(matches!(
            s.split(&keepalive(1, 9)),
            Err(FrameError::TooShort { len: 9, .. })
        ));
        assert!(matches!(
            s.split(&keepalive(1, 101)),
            Err(FrameError::TooLong {
                len: 101,
                max: 100,
                ..
            })
        ));
        assert!(s.split(&keepalive(2, 10)).is_ok());
        match s.split(&keepalive(3, 10)) {
            Err(FrameError::UnsupportedVersion(h)) => assert_eq!((h.version, h.id), (3, 7)),
            other => panic!("expected unsupported version, got {other:?}"),
        }
        assert!(matches!(
            s.split(&keepalive(0, 10)),
            Err(FrameError::UnsupportedVersion(_))
        ));
    }

    #[test]
    fn deframer_yields_whole_frames_of_any_version_then_stays_unsynced() {
        let mut d = Deframer::default();
        let a = keepalive(1, 10);
        let b = keepalive(5, 10);
        d.buffer_mut().extend_from_slice(&a[..4]);
        assert_eq!(d.next_frame(), None);
        d.buffer_mut().extend_from_slice(&a[4..]);
        d.buffer_mut().extend_from_slice(&b[..9]);
        assert_eq!(d.next_frame(), Some(Inbound::Frame(Bytes::from(a.clone()))));
        assert_eq!(d.next_frame(), None);
        d.buffer_mut().extend_from_slice(&b[9..]);
        assert_eq!(d.next_frame(), Some(Inbound::Frame(Bytes::from(b))));
        assert_eq!(d.buffered(), 0);
        d.buffer_mut().extend_from_slice(&keepalive(1, 4));
        d.buffer_mut().extend_from_slice(&a);
        for _ in 0..2 {
            assert!(matches!(
                d.next_frame(),
                Some(Inbound::Unsynced(FrameError::TooShort {
                    len: 4,
                    id: 7,
                    ..
                }))
            ));
        }
    }
}
