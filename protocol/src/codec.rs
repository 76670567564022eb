//! The encode/decode machinery every parameter and message shares: field codecs (nom to
//! read, `BufMut` to write), the parameter header, the sub-parameter walker that keeps
//! unknown parameters in place, and the matching encoder.

use bytes::{BufMut, BytesMut};
use nom::number::complete as num;

use crate::error::{DecodeError, ErrorKind, PathSeg};
use crate::raw::{Extra, RawParam};

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
        T::decode_param(i, h).map(Box::new)
    }
    fn encode_param(&self, buf: &mut BytesMut) {
        (**self).encode_param(buf)
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

/// Reads the sub-parameters of a message or parameter, one header at a time.
///
/// The generated decoders keep the current header in a local and assign each parameter to
/// the first slot (in spec order, at or after the current one) whose type it matches.
/// Parameters of unknown type, and Custom parameters where the container has no Custom
/// slot, are set aside as [`Extra`]s with their position, so encoding puts them back.
pub struct Walk<'a> {
    rest: &'a [u8],
    extras: Vec<Extra>,
    count: u16,
}

impl<'a> Walk<'a> {
    /// Starts walking the sub-parameters in `rest`.
    #[inline]
    pub fn new(rest: &'a [u8]) -> Self {
        Walk {
            rest,
            extras: Vec::new(),
            count: 0,
        }
    }

    /// Header of the next parameter, or `None` at the end.
    #[inline(always)]
    pub fn header(&self) -> Result<Option<ParamHeader>, DecodeError> {
        if self.rest.is_empty() {
            return Ok(None);
        }
        ParamHeader::read(self.rest).map(Some)
    }

    /// Whether a parameter no slot takes is kept as an [`Extra`] (unknown or vendor).
    #[inline]
    pub fn is_extra(h: &ParamHeader) -> bool {
        !h.tv() && (h.ty() == CUSTOM_TYPE || !crate::params::is_known_tlv(h.ty()))
    }

    /// Sets the current parameter aside as an [`Extra`].
    pub fn set_aside(&mut self, h: &ParamHeader) {
        let (this, rest) = self.rest.split_at(h.size());
        self.extras.push(Extra {
            at: self.count,
            param: RawParam::new(this.to_vec()),
        });
        self.rest = rest;
    }

    /// Decodes the current parameter as `T`.
    #[inline]
    pub fn take<T: Param>(&mut self, h: &ParamHeader) -> Result<T, DecodeError> {
        let (this, rest) = self.rest.split_at(h.size());
        let v = T::decode_param(this, h)?;
        self.rest = rest;
        self.count = self.count.saturating_add(1);
        Ok(v)
    }

    /// Decodes the current parameter as the first of a list of `T`, sizing the list from
    /// the bytes left (bounded, so hostile lengths cannot make it allocate much).
    #[inline]
    pub fn take_first<T: Param>(
        &mut self,
        h: &ParamHeader,
        v: &mut Vec<T>,
    ) -> Result<(), DecodeError> {
        let by_len = self.rest.len() / h.size().max(1);
        let by_mem = 4 * self.rest.len() / std::mem::size_of::<T>().max(1);
        v.reserve_exact(by_len.min(by_mem).max(1));
        v.push(self.take(h)?);
        Ok(())
    }

    /// A known parameter out of place here.
    #[cold]
    pub fn unexpected(&self, h: &ParamHeader) -> DecodeError {
        DecodeError::at(
            self.rest.as_ptr(),
            ErrorKind::UnexpectedParameter { ty: h.ty() },
        )
    }

    /// A second parameter where only one is allowed.
    #[cold]
    pub fn duplicate(&self, h: &ParamHeader) -> DecodeError {
        DecodeError::at(
            self.rest.as_ptr(),
            ErrorKind::DuplicateParameter { ty: h.ty() },
        )
    }

    /// A required parameter absent before the current position.
    #[cold]
    pub fn missing<T: Param>(&self) -> DecodeError {
        DecodeError::at(
            self.rest.as_ptr(),
            ErrorKind::MissingParameter {
                ty: T::TYPE,
                name: T::NAME,
            },
        )
    }

    /// Ends the walk, returning the parameters set aside.
    #[inline]
    pub fn finish(self) -> Vec<Extra> {
        self.extras
    }
}

/// Writes sub-parameters, putting each [`Extra`] back at its recorded position.
pub struct SubEnc<'b> {
    buf: &'b mut BytesMut,
    extras: &'b [Extra],
    next: usize,
    count: u16,
}

impl<'b> SubEnc<'b> {
    /// Starts writing into `buf`.
    pub fn new(buf: &'b mut BytesMut, extras: &'b [Extra]) -> Self {
        SubEnc {
            buf,
            extras,
            next: 0,
            count: 0,
        }
    }

    #[inline]
    fn flush(&mut self) {
        while let Some(e) = self.extras.get(self.next) {
            if e.at > self.count {
                break;
            }
            self.buf.put_slice(&e.param.bytes);
            self.next += 1;
        }
    }

    /// Appends one sub-parameter.
    #[inline]
    pub fn put<T: Param>(&mut self, p: &T) {
        if !self.extras.is_empty() {
            self.flush();
        }
        p.encode_param(self.buf);
        self.count = self.count.saturating_add(1);
    }

    /// Appends the extras that come after the last sub-parameter.
    pub fn finish(mut self) {
        self.flush();
        for e in &self.extras[self.next..] {
            self.buf.put_slice(&e.param.bytes);
        }
    }
}

/// Wraps an error from inside a field with the field's name and position.
#[inline]
pub(crate) fn in_field(name: &'static str, index: u16) -> impl FnOnce(DecodeError) -> DecodeError {
    move |e| e.within(PathSeg::Field { name, index })
}

/// A field-range check failure at `i`.
pub(crate) fn out_of_range(i: &[u8], name: &'static str, index: u16) -> DecodeError {
    DecodeError::at(i.as_ptr(), ErrorKind::OutOfRange).within(PathSeg::Field { name, index })
}
