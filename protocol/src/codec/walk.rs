//! The sub-parameter walker that assigns each parameter to its slot and keeps unknown ones in
//! place, and the encoder that puts them back.

use bytes::BytesMut;

use super::*;
use crate::error::{DecodeError, ErrorKind, PathSeg};
use crate::raw::{Extra, RawParam};

/// Reads the sub-parameters of a message or parameter, one header at a time.
///
/// The generated decoders keep the current header in a local and assign each parameter to
/// the first slot (in spec order, at or after the current one) whose type it matches.
/// Parameters of unknown type, and Custom parameters where the container has no Custom
/// slot, are set aside as [`Extra`]s with their position, so encoding puts them back.
pub struct Walk<'a> {
    rest: &'a [u8],
    extras: Vec<Extra>,
    count: u32,
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
    count: u32,
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
