//! `llrp-gateway decode`: LLRP frames in (raw bytes or hex text), one JSON object per message out.

use std::io::Write;

use llrp::{FrameError, FrameSplitter, Message, Split};

/// Why decoding a stream of frames stopped.
#[derive(Debug, thiserror::Error)]
pub enum DecodeStreamError {
    /// The input was meant to be hex but is not.
    #[error("input is not valid hex: {0}")]
    Hex(#[from] llrp::raw::HexError),
    /// The stream cannot be split into frames at this offset.
    #[error("frame at offset {offset}: {source}")]
    Frame {
        /// Offset of the frame in the input.
        offset: usize,
        /// What is wrong with its header.
        source: FrameError,
    },
    /// The input ends inside a frame.
    #[error("truncated frame at offset {offset}: {missing} more byte(s) needed")]
    Truncated {
        /// Offset of the frame in the input.
        offset: usize,
        /// Bytes missing.
        missing: usize,
    },
    /// A frame could not be decoded.
    #[error("message {name} (id {id}) at offset {offset}: {kind} at offset {at} in {path} (LLRPStatus {status})")]
    Decode {
        /// Offset of the frame in the input.
        offset: usize,
        /// Message type name from the header.
        name: &'static str,
        /// Message ID from the header.
        id: u32,
        /// Absolute offset of the error in the input.
        at: usize,
        /// Parameter path of the error.
        path: String,
        /// What went wrong.
        kind: String,
        /// The status a reader would answer.
        status: llrp::StatusCode,
    },
    /// Re-encoding a decoded message did not give back its bytes.
    #[error("message {name} (id {id}) at offset {offset}: re-encoded bytes differ at message offset {diff} (input {input_len} bytes, re-encoded {output_len})")]
    Roundtrip {
        /// Offset of the frame in the input.
        offset: usize,
        /// Message name.
        name: &'static str,
        /// Message ID.
        id: u32,
        /// First differing offset inside the message.
        diff: usize,
        /// Length of the input frame.
        input_len: usize,
        /// Length of the re-encoded frame.
        output_len: usize,
    },
    /// Writing the output failed.
    #[error("writing output: {0}")]
    Io(#[from] std::io::Error),
}

/// How to read the input.
#[derive(Clone, Copy, Debug, Default)]
pub struct DecodeOptions {
    /// The input is hex text (whitespace allowed) rather than raw bytes.
    pub hex: bool,
    /// Re-encode every message and fail if the bytes differ.
    pub roundtrip: bool,
}

/// Decodes every frame of `input`, writing one JSON line per message to `out`.
///
/// Stops at the first bad frame, after writing every good message before it; returns the
/// number of messages written.
pub fn decode_stream(
    input: &[u8],
    opts: DecodeOptions,
    out: &mut impl Write,
) -> Result<usize, DecodeStreamError> {
    let owned;
    let bytes = if opts.hex {
        owned = llrp::raw::from_hex(&String::from_utf8_lossy(input))?;
        &owned[..]
    } else {
        input
    };
    let splitter = FrameSplitter::default();
    let mut offset = 0;
    let mut count = 0;
    while offset < bytes.len() {
        let rest = &bytes[offset..];
        let header = match splitter.split(rest) {
            Ok(Split::Frame(h)) => h,
            Ok(Split::Incomplete(missing)) => {
                return Err(DecodeStreamError::Truncated { offset, missing })
            }
            Err(source) => return Err(DecodeStreamError::Frame { offset, source }),
        };
        let frame = &rest[..header.length as usize];
        let msg = Message::decode(frame).map_err(|e| DecodeStreamError::Decode {
            offset,
            name: llrp::message::message_name(header.msg_type, frame),
            id: header.id,
            at: offset + e.offset,
            path: e.path_string(),
            kind: format!("{:?}", e.kind),
            status: e.status_code(),
        })?;
        if opts.roundtrip {
            let again = msg.to_bytes();
            if again[..] != *frame {
                let diff = again
                    .iter()
                    .zip(frame)
                    .position(|(a, b)| a != b)
                    .unwrap_or(again.len().min(frame.len()));
                return Err(DecodeStreamError::Roundtrip {
                    offset,
                    name: msg.name(),
                    id: msg.id,
                    diff,
                    input_len: frame.len(),
                    output_len: again.len(),
                });
            }
        }
        serde_json::to_writer(&mut *out, &msg).map_err(std::io::Error::from)?;
        out.write_all(b"\n")?;
        count += 1;
        offset += frame.len();
    }
    Ok(count)
}

#[cfg(test)]
mod tests {
    use super::*;

    const KEEPALIVE: &str = "043e0000000a00000007";

    #[test]
    fn prints_good_messages_then_fails_on_a_bad_one() {
        // KEEPALIVE, then DELETE_ROSPEC whose length says 13 but needs 14 for its u32.
        let input = format!("{KEEPALIVE}\n04150000000d00000001 000000");
        let mut out = Vec::new();
        let opts = DecodeOptions {
            hex: true,
            roundtrip: true,
        };
        let err = decode_stream(input.as_bytes(), opts, &mut out).unwrap_err();
        let text = String::from_utf8(out).unwrap();
        assert_eq!(text.lines().count(), 1);
        assert!(text.contains("\"KEEPALIVE\""), "{text}");
        let msg = err.to_string();
        assert!(msg.contains("DELETE_ROSPEC"), "{msg}");
        assert!(
            msg.contains("at offset 20 in DELETE_ROSPEC/ROSpecID"),
            "{msg}"
        );
    }

    #[test]
    fn reports_truncated_input() {
        let mut out = Vec::new();
        let err = decode_stream(
            &llrp::raw::from_hex(&KEEPALIVE[..12]).unwrap(),
            DecodeOptions::default(),
            &mut out,
        )
        .unwrap_err();
        assert!(
            matches!(
                err,
                DecodeStreamError::Truncated {
                    offset: 0,
                    missing: 4
                }
            ),
            "{err}"
        );
    }
}
