//! Field codecs: integers, counted arrays, strings, bit strings, enumerated fields, and the
//! sub-byte fields packed with their neighbours.

use bytes::{BufMut, BytesMut};
use nom::number::complete as num;

use crate::error::{DecodeError, ErrorKind};

/// Result of decoding a field: the rest of the input and the value.
pub type FieldResult<'a, T> = Result<(&'a [u8], T), DecodeError>;

/// A nom error at `i` turned into a truncation error.
fn truncated(i: &[u8]) -> DecodeError {
    DecodeError::at(i.as_ptr(), ErrorKind::Truncated)
}

/// A byte-aligned field type (integers, variable-length arrays, strings).
pub trait Field: Sized {
    /// Reads the field from the front of `i`.
    fn decode_field(i: &[u8]) -> FieldResult<'_, Self>;
    /// Appends the field.
    fn encode_field(&self, buf: &mut BytesMut);
}

macro_rules! int_field {
    ($($t:ty => $p:ident, $put:ident;)*) => {$(
        impl Field for $t {
            #[inline]
            fn decode_field(i: &[u8]) -> FieldResult<'_, Self> {
                num::$p::<_, nom::error::Error<&[u8]>>(i).map_err(|_| truncated(i))
            }
            #[inline]
            fn encode_field(&self, buf: &mut BytesMut) {
                buf.$put(*self);
            }
        }
    )*};
}

int_field! {
    u8 => be_u8, put_u8;
    u16 => be_u16, put_u16;
    u32 => be_u32, put_u32;
    u64 => be_u64, put_u64;
    i8 => be_i8, put_i8;
    i16 => be_i16, put_i16;
}

/// A field with a numeric value that a range check (`; in LO..=HI` in `llrp_struct!`) and
/// random generation work on: the integers, and the enumerated field types.
pub trait Ranged: Sized {
    /// The integer on the wire.
    type Raw: PartialOrd + Copy;
    /// The value on the wire.
    fn raw(&self) -> Self::Raw;
    /// The field with this wire value.
    fn from_raw(v: Self::Raw) -> Self;
}

macro_rules! int_ranged {
    ($($t:ty),*) => {$(
        impl Ranged for $t {
            type Raw = $t;
            #[inline]
            fn raw(&self) -> $t {
                *self
            }
            #[inline]
            fn from_raw(v: $t) -> Self {
                v
            }
        }
    )*};
}

int_ranged!(u8, u16, u32);

/// Reads a u16 element count and checks `count * size` bytes follow (no allocation before).
fn counted(i: &[u8], size: usize) -> FieldResult<'_, usize> {
    let (rest, n) = u16::decode_field(i)?;
    if rest.len() < usize::from(n) * size {
        return Err(truncated(i));
    }
    Ok((rest, usize::from(n)))
}

/// Appends a u16 count; counts above 65535 cannot be encoded and are capped.
fn put_count(buf: &mut BytesMut, n: usize) {
    debug_assert!(
        n <= usize::from(u16::MAX),
        "LLRP arrays hold at most 65535 elements"
    );
    buf.put_u16(u16::try_from(n).unwrap_or(u16::MAX));
}

impl Field for Vec<u8> {
    fn decode_field(i: &[u8]) -> FieldResult<'_, Self> {
        let (rest, n) = counted(i, 1)?;
        Ok((&rest[n..], rest[..n].to_vec()))
    }
    fn encode_field(&self, buf: &mut BytesMut) {
        put_count(buf, self.len());
        buf.put_slice(self);
    }
}

impl Field for Vec<u16> {
    fn decode_field(i: &[u8]) -> FieldResult<'_, Self> {
        let (rest, n) = counted(i, 2)?;
        let v = rest[..n * 2]
            .chunks_exact(2)
            .map(|c| u16::from_be_bytes([c[0], c[1]]))
            .collect();
        Ok((&rest[n * 2..], v))
    }
    fn encode_field(&self, buf: &mut BytesMut) {
        put_count(buf, self.len());
        for v in self {
            buf.put_u16(*v);
        }
    }
}

impl Field for Vec<u32> {
    fn decode_field(i: &[u8]) -> FieldResult<'_, Self> {
        let (rest, n) = counted(i, 4)?;
        let v = rest[..n * 4]
            .chunks_exact(4)
            .map(|c| u32::from_be_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        Ok((&rest[n * 4..], v))
    }
    fn encode_field(&self, buf: &mut BytesMut) {
        put_count(buf, self.len());
        for v in self {
            buf.put_u32(*v);
        }
    }
}

/// `utf8v`: u16 byte count and UTF-8 text.
impl Field for String {
    fn decode_field(i: &[u8]) -> FieldResult<'_, Self> {
        let (rest, n) = counted(i, 1)?;
        let s = std::str::from_utf8(&rest[..n])
            .map_err(|_| DecodeError::at(i.as_ptr(), ErrorKind::Invalid))?;
        Ok((&rest[n..], s.to_owned()))
    }
    fn encode_field(&self, buf: &mut BytesMut) {
        put_count(buf, self.len());
        buf.put_slice(self.as_bytes());
    }
}

/// 96 bits (the EPC-96 TV value).
impl Field for [u8; 12] {
    fn decode_field(i: &[u8]) -> FieldResult<'_, Self> {
        match i.get(..12) {
            Some(b) => {
                let mut a = [0u8; 12];
                a.copy_from_slice(b);
                Ok((&i[12..], a))
            }
            None => Err(truncated(i)),
        }
    }
    fn encode_field(&self, buf: &mut BytesMut) {
        buf.put_slice(self);
    }
}

/// `u1v`: a bit string, u16 bit count then ceil(bits / 8) bytes (e.g. an EPC or a tag mask).
#[derive(Clone, Debug, Default, PartialEq, Eq, Hash)]
pub struct BitVec {
    /// Number of meaningful bits.
    pub bits: u16,
    /// ceil(bits / 8) bytes, most significant bit first.
    pub bytes: Vec<u8>,
}

impl BitVec {
    /// A bit string of whole bytes.
    pub fn from_bytes(bytes: &[u8]) -> Self {
        BitVec {
            bits: u16::try_from(bytes.len() * 8).unwrap_or(u16::MAX),
            bytes: bytes.to_vec(),
        }
    }
}

impl Field for BitVec {
    fn decode_field(i: &[u8]) -> FieldResult<'_, Self> {
        let (rest, bits) = u16::decode_field(i)?;
        let n = usize::from(bits).div_ceil(8);
        match rest.get(..n) {
            Some(b) => Ok((
                &rest[n..],
                BitVec {
                    bits,
                    bytes: b.to_vec(),
                },
            )),
            None => Err(truncated(i)),
        }
    }
    fn encode_field(&self, buf: &mut BytesMut) {
        buf.put_u16(self.bits);
        buf.put_slice(&self.bytes);
    }
}

/// A field narrower than a byte, packed with its neighbours (flags, 2-bit enums).
pub trait BitField: Sized + Copy {
    /// Builds the value from the low bits of `v`.
    fn from_bits(v: u32) -> Self;
    /// The value as bits.
    fn to_bits(self) -> u32;
}

impl BitField for bool {
    fn from_bits(v: u32) -> Self {
        v != 0
    }
    fn to_bits(self) -> u32 {
        u32::from(self)
    }
}

impl BitField for u8 {
    fn from_bits(v: u32) -> Self {
        v as u8
    }
    fn to_bits(self) -> u32 {
        u32::from(self)
    }
}

/// Reads `width` bits at bit offset `*bit` of `i` (nom's bit parser), advancing both.
#[inline]
pub(crate) fn take_bits<'a>(i: &'a [u8], bit: &mut usize, width: usize) -> FieldResult<'a, u32> {
    let r: nom::IResult<(&[u8], usize), u32> = nom::bits::complete::take(width)((i, *bit));
    match r {
        Ok(((rest, b), v)) => {
            *bit = b;
            Ok((rest, v))
        }
        Err(_) => Err(truncated(i)),
    }
}

/// Accumulates sub-byte fields and writes each byte once it is full.
#[derive(Default)]
pub(crate) struct BitWriter {
    acc: u32,
    n: u32,
}

impl BitWriter {
    /// Appends the low `width` bits of `v`.
    #[inline]
    pub(crate) fn push(&mut self, buf: &mut BytesMut, width: u32, v: u32) {
        let mask = if width >= 32 {
            u32::MAX
        } else {
            (1 << width) - 1
        };
        self.acc = (self.acc << width) | (v & mask);
        self.n += width;
        while self.n >= 8 {
            self.n -= 8;
            buf.put_u8((self.acc >> self.n) as u8);
        }
        self.acc &= (1u32 << self.n) - 1;
    }
}
