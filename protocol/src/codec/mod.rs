//! The encode/decode machinery every parameter and message shares: field codecs (nom to
//! read, `BufMut` to write), the parameter header, the sub-parameter walker that keeps
//! unknown parameters in place, and the matching encoder.

use bytes::{BufMut, BytesMut};

use crate::error::{DecodeError, ErrorKind};

mod fields;
mod walk;

pub use fields::*;
pub use walk::*;

/// Header of a parameter as found on the wire.
///
/// Held as two whole words (read through accessors) so that the decoder's many copies of
/// the pending header never mix narrow stores with wide loads.
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct ParamHeader {
    /// Bit 62: TV; bits 32..48: type; bits 0..32: whole encoded length.
    word: u64,
    /// Vendor (high half) and subtype (low half) of a Custom parameter.
    custom: u64,
}

impl ParamHeader {
    /// A header with these parts (vendor and subtype are 0 except for Custom parameters).
    #[inline(always)]
    pub fn new(tv: bool, ty: u16, len: usize, vendor: u32, subtype: u32) -> Self {
        ParamHeader {
            word: u64::from(tv) << 62 | u64::from(ty) << 32 | (len as u64 & 0xFFFF_FFFF),
            custom: u64::from(vendor) << 32 | u64::from(subtype),
        }
    }

    /// True for a TV parameter (1-byte header, fixed size).
    #[inline(always)]
    pub fn tv(&self) -> bool {
        self.word & 1 << 62 != 0
    }

    /// Type: 1..=127 for TV, up to 1023 for TLV.
    #[inline(always)]
    pub fn ty(&self) -> u16 {
        (self.word >> 32) as u16
    }

    /// Whole encoded length, header included.
    #[inline(always)]
    pub fn size(&self) -> usize {
        (self.word & 0xFFFF_FFFF) as usize
    }

    /// Vendor ID of a Custom parameter (TLV 1023), else 0.
    #[inline(always)]
    pub fn vendor(&self) -> u32 {
        (self.custom >> 32) as u32
    }

    /// Subtype of a Custom parameter, else 0.
    #[inline(always)]
    pub fn subtype(&self) -> u32 {
        self.custom as u32
    }
}

impl std::fmt::Debug for ParamHeader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ParamHeader")
            .field("tv", &self.tv())
            .field("ty", &self.ty())
            .field("size", &self.size())
            .field("vendor", &self.vendor())
            .field("subtype", &self.subtype())
            .finish()
    }
}

/// TLV type of a Custom (vendor) parameter.
pub const CUSTOM_TYPE: u16 = 1023;

/// Value length of each TV type (LLRP 1.0.1 Table 5 plus 1.1's 19 and 20).
pub fn tv_value_len(ty: u8) -> Option<usize> {
    Some(match ty {
        1 => 2,
        2..=5 => 8,
        6 => 1,
        7 | 8 => 2,
        9 => 4,
        10..=12 => 2,
        13 => 12,
        14 | 15 => 2,
        16 => 4,
        17 => 2,
        18 => 4,
        19 | 20 => 2,
        _ => return None,
    })
}

impl ParamHeader {
    /// Reads and checks a parameter header at the front of `i` (which must not be empty).
    #[inline(always)]
    pub fn read(i: &[u8]) -> Result<ParamHeader, DecodeError> {
        let b0 = i[0];
        if b0 & 0x80 != 0 {
            let ty = b0 & 0x7F;
            let Some(n) = tv_value_len(ty) else {
                return Err(DecodeError::at(
                    i.as_ptr(),
                    ErrorKind::UnknownParameter { ty: ty.into() },
                ));
            };
            if i.len() < 1 + n {
                // A TV parameter that runs past its container is treated like a TLV whose
                // length does: a parameter error, not a field error of the container.
                return Err(DecodeError::at(
                    i.as_ptr(),
                    ErrorKind::BadParameterLength {
                        ty: ty.into(),
                        len: u16::try_from(i.len()).unwrap_or(u16::MAX),
                    },
                ));
            }
            return Ok(ParamHeader::new(true, ty.into(), 1 + n, 0, 0));
        }
        if i.len() < 4 {
            return Err(DecodeError::at(i.as_ptr(), ErrorKind::Truncated));
        }
        let ty = u16::from_be_bytes([i[0], i[1]]) & 0x3FF;
        let len = u16::from_be_bytes([i[2], i[3]]);
        let min = if ty == CUSTOM_TYPE { 12 } else { 4 };
        if usize::from(len) < min || usize::from(len) > i.len() {
            return Err(DecodeError::at(
                i.as_ptr(),
                ErrorKind::BadParameterLength { ty, len },
            ));
        }
        let (vendor, subtype) = if ty == CUSTOM_TYPE {
            (
                u32::from_be_bytes([i[4], i[5], i[6], i[7]]),
                u32::from_be_bytes([i[8], i[9], i[10], i[11]]),
            )
        } else {
            (0, 0)
        };
        Ok(ParamHeader::new(
            false,
            ty,
            usize::from(len),
            vendor,
            subtype,
        ))
    }
}

/// A parameter type: TLV, TV or vendor Custom.
pub trait Param: Sized {
    /// Spec name, e.g. `ROSpec`.
    const NAME: &'static str;
    /// Type number (TV type, TLV type, or 1023 for vendor parameters).
    const TYPE: u16;
    /// Whether a parameter with this header decodes as `Self`.
    fn matches(h: &ParamHeader) -> bool;
    /// Decodes from `i`, which holds exactly the whole parameter described by `h`.
    fn decode_param(i: &[u8], h: &ParamHeader) -> Result<Self, DecodeError>;
    /// Appends the whole parameter, header included.
    fn encode_param(&self, buf: &mut BytesMut);
}

impl<T: Param> Param for Box<T> {
    const NAME: &'static str = T::NAME;
    const TYPE: u16 = T::TYPE;
    fn matches(h: &ParamHeader) -> bool {
        T::matches(h)
    }
    fn decode_param(i: &[u8], h: &ParamHeader) -> Result<Self, DecodeError> {
        // A boxed slot is the only way a parameter can contain itself (ParameterError), so
        // it is the only place where nesting is not bounded by the spec's grammar.
        let _level = Nesting::enter(i, h)?;
        T::decode_param(i, h).map(Box::new)
    }
    fn encode_param(&self, buf: &mut BytesMut) {
        (**self).encode_param(buf)
    }
}

/// How many parameters of a self-containing type (a ParameterError in a ParameterError, …)
/// the decoder accepts nested in one another.
///
/// The spec's grammar bounds every other nesting; a ParameterError chain mirrors the path to
/// an error, which no real message makes deeper than about ten. Anything deeper is refused
/// with [`ErrorKind::TooDeep`], so that decoding (and every recursive walk over a decoded
/// value: encoding, JSON, drop) stays within a few kilobytes of stack.
pub const MAX_NESTING: u32 = 64;

std::thread_local! {
    /// Boxed (self-containing) parameters being decoded on this thread, outermost first.
    static NESTING: std::cell::Cell<u32> = const { std::cell::Cell::new(0) };
}

/// One level of self-containing nesting, released when dropped (also on error).
struct Nesting;

impl Nesting {
    /// Enters one more level, or refuses past [`MAX_NESTING`].
    fn enter(i: &[u8], h: &ParamHeader) -> Result<Nesting, DecodeError> {
        NESTING.with(|n| {
            let depth = n.get();
            if depth >= MAX_NESTING {
                return Err(DecodeError::at(
                    i.as_ptr(),
                    ErrorKind::TooDeep {
                        ty: h.ty(),
                        limit: MAX_NESTING,
                    },
                ));
            }
            n.set(depth + 1);
            Ok(Nesting)
        })
    }
}

impl Drop for Nesting {
    fn drop(&mut self) {
        NESTING.with(|n| n.set(n.get().saturating_sub(1)));
    }
}

/// The fields and sub-parameters of a TLV parameter or a message, without its header.
pub trait Body: Sized {
    /// Decodes from exactly the body bytes.
    fn decode_body(i: &[u8]) -> Result<Self, DecodeError>;
    /// Appends the body.
    fn encode_body(&self, buf: &mut BytesMut);
}

/// Writes a TLV header with a placeholder length; returns where to patch it.
#[inline]
pub(crate) fn begin_tlv(buf: &mut BytesMut, ty: u16) -> usize {
    let start = buf.len();
    buf.put_u16(ty & 0x3FF);
    buf.put_u16(0);
    start
}

/// Patches the length of the TLV started at `start`.
#[inline]
pub(crate) fn end_tlv(buf: &mut BytesMut, start: usize) {
    let len = buf.len() - start;
    debug_assert!(
        len <= usize::from(u16::MAX),
        "TLV parameter over 65535 bytes"
    );
    let len = u16::try_from(len).unwrap_or(u16::MAX);
    buf[start + 2..start + 4].copy_from_slice(&len.to_be_bytes());
}

/// Whether a sub-parameter slot is empty (serde skips empty slots).
pub trait Absent {
    /// True for `None` and empty lists.
    fn is_absent(&self) -> bool;
}

impl<T> Absent for Option<T> {
    fn is_absent(&self) -> bool {
        self.is_none()
    }
}

impl<T> Absent for Vec<T> {
    fn is_absent(&self) -> bool {
        self.is_empty()
    }
}

impl<T: Absent> Absent for Box<T> {
    fn is_absent(&self) -> bool {
        (**self).is_absent()
    }
}
