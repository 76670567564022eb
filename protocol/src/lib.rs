//! `llrp`: a sans-IO codec for the EPCglobal Low Level Reader Protocol (LLRP 1.0.1 and 1.1)
//! with Impinj extensions.
//!
//! * [`FrameSplitter`] finds whole messages in a byte stream; [`Deframer`] buffers a stream
//!   and yields them.
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
//! * [`MessageKind`] names a message type; each [`Request`] knows its [`Response`], and
//!   [`MessageKind::error_response`] builds the answer a reader gives a refused request.
//! * [`build`] has constructors for ROSpecs, their triggers and report specs.
//! * [`units`] converts phase, RSSI, Doppler and channel indices to physical values.
//!
//! No I/O, no async runtime, no global state.
//!
//! # Encode a message, find it in a byte stream, decode it
//!
//! ```
//! use bytes::BytesMut;
//! use llrp::message::{MessageBody, StartRospec};
//! use llrp::params::LlrpStatus;
//! use llrp::{FrameSplitter, Message, Request, Response, Split};
//!
//! let mut wire = BytesMut::new();
//! Message::new(7, StartRospec { ro_spec_id: 1, ..Default::default() }).encode(&mut wire);
//! assert_eq!(&wire[..], &[0x04, 0x16, 0, 0, 0, 14, 0, 0, 0, 7, 0, 0, 0, 1]);
//!
//! // A stream may hold half a message: the splitter says how much is missing.
//! let splitter = FrameSplitter::default();
//! assert_eq!(splitter.split(&wire[..6]), Ok(Split::Incomplete(4)));
//! let Ok(Split::Frame(header)) = splitter.split(&wire) else { panic!("a whole frame") };
//! let m = Message::decode(&wire[..header.length as usize]).expect("valid frame");
//! assert_eq!((m.name(), m.id), ("START_ROSPEC", 7));
//! assert!(matches!(m.body, MessageBody::StartRospec(ref s) if s.ro_spec_id == 1));
//! // The request knows the type of its answer.
//! let answer = <StartRospec as Request>::Response::with_status(LlrpStatus::success());
//! assert_eq!(m.body.kind().response(), Some(MessageBody::from(answer).kind()));
//! ```
//!
//! # Walk the tag reads of an RO_ACCESS_REPORT
//!
//! ```
//! use llrp::message::RoAccessReport;
//! use llrp::params::{AntennaId, Epc, Epc96, PeakRssi, TagReportData};
//! use llrp::{units, Message};
//!
//! let read = TagReportData {
//!     epc: Epc::Epc96(Epc96([0x30, 0x08, 0x33, 0xB2, 0xDD, 0xD9, 0x01, 0x40, 0, 0, 0, 1])),
//!     antenna_id: Some(AntennaId(2)),
//!     peak_rssi: Some(PeakRssi(units::dbm_to_peak_rssi(-61.25))),
//!     ..Default::default()
//! };
//! let report = RoAccessReport { tag_report_data: vec![read], ..Default::default() };
//! let frame = Message::new(1, report).to_bytes();
//!
//! // In place, without allocating: one flat TagRead per TagReportData.
//! for r in llrp::reads::tag_reads(&frame).expect("an RO_ACCESS_REPORT") {
//!     let r = r.expect("well-formed TagReportData");
//!     assert_eq!(r.epc.len(), 12);
//!     assert_eq!((r.antenna_id, r.peak_rssi), (Some(2), Some(-61)));
//! }
//! ```
#![warn(missing_docs)]

#[macro_use]
mod macros;

pub mod build;
pub mod codec;
#[macro_use]
pub mod enums;
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
pub use frame::{Deframer, FrameHeader, FrameSplitter, Inbound, Split};
pub use message::{Message, MessageBody, MessageKind, Request, Response};
