//! Message framing: the 10-byte header and splitting a byte stream into whole messages.

use bytes::BufMut;

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
}
