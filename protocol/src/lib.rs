//! `llrp`: a sans-IO codec for the EPCglobal Low Level Reader Protocol (LLRP 1.0.1 and 1.1)
//! with Impinj extensions.
//!
//! * [`FrameSplitter`] finds whole messages in a byte stream.
//! * [`Message::decode`] turns one message into typed structs (nom underneath);
//!   [`Message::encode`] writes it back (`bytes::BufMut`).
//! * Parameters the codec does not type, and vendor parameters, are kept byte for byte in
//!   their original position ([`raw::Extra`], [`params::RawCustom`]), so decode → encode is
//!   lossless.
//! * [`reads::tag_reads`] walks the tag reads of an RO_ACCESS_REPORT in place, without
//!   allocating, for consumers that only need the reads.
//! * A [`DecodeError`] carries the byte offset, the parameter path and the LLRPStatus a reader
//!   would answer with ([`DecodeError::to_status`]).
//!
//! No I/O, no async runtime, no global state.
#![warn(missing_docs)]

#[macro_use]
mod macros;

pub mod codec;
pub mod error;
pub mod frame;
pub mod impinj;
pub mod message;
pub mod params;
pub mod raw;
pub mod reads;
#[cfg(feature = "arbitrary")]
pub mod sample;
pub mod units;

pub use error::{DecodeError, DecodeErrorDetail, ErrorKind, FrameError, PathSeg, StatusCode};
pub use frame::{FrameHeader, FrameSplitter, Split};
pub use message::{Message, MessageBody};
