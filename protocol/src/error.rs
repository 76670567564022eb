//! Decode errors and their mapping to the LLRPStatus a reader answers with.

use std::fmt;

use crate::params::{FieldError, LlrpStatus, ParameterError};

llrp_enum! {
    /// LLRPStatus status codes (LLRP 1.0.1 §16.2.8.1 plus 1.1's M_UnexpectedMessage).
    #[allow(non_camel_case_types, missing_docs)]
    pub enum StatusCode: u16 {
        M_Success = 0,
        M_ParameterError = 100,
        M_FieldError = 101,
        M_UnexpectedParameter = 102,
        M_MissingParameter = 103,
        M_DuplicateParameter = 104,
        M_OverflowParameter = 105,
        M_OverflowField = 106,
        M_UnknownParameter = 107,
        M_UnknownField = 108,
        M_UnsupportedMessage = 109,
        M_UnsupportedVersion = 110,
        M_UnsupportedParameter = 111,
        M_UnexpectedMessage = 112,
        P_ParameterError = 200,
        P_FieldError = 201,
        P_UnexpectedParameter = 202,
        P_MissingParameter = 203,
        P_DuplicateParameter = 204,
        P_OverflowParameter = 205,
        P_OverflowField = 206,
        P_UnknownParameter = 207,
        P_UnknownField = 208,
        P_UnsupportedParameter = 209,
        A_Invalid = 300,
        A_OutOfRange = 301,
        R_DeviceError = 401,
    }
}

impl StatusCode {
    /// The code's wire value.
    pub const fn code(self) -> u16 {
        self.value()
    }

    /// The code with this wire value, if the specification defines it.
    pub fn from_code(code: u16) -> Option<Self> {
        Some(Self::from_value(code)).filter(|c| c.is_known())
    }
}

impl fmt::Display for StatusCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Debug::fmt(self, f)
    }
}

/// One step of the path from the message to the place of an error.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum PathSeg {
    /// The message, with its type number.
    Message {
        /// Spec name, e.g. `ADD_ROSPEC`.
        name: &'static str,
        /// Message type number.
        ty: u16,
    },
    /// A parameter, with its type number.
    Param {
        /// Spec name, e.g. `AISpec`.
        name: &'static str,
        /// Parameter type number.
        ty: u16,
    },
    /// A field of the enclosing message or parameter.
    Field {
        /// Spec name, e.g. `AntennaIDs`.
        name: &'static str,
        /// Position of the field in its message or parameter, from 0.
        index: u16,
    },
}

impl PathSeg {
    /// Spec name of this step.
    pub fn name(&self) -> &'static str {
        match self {
            PathSeg::Message { name, .. }
            | PathSeg::Param { name, .. }
            | PathSeg::Field { name, .. } => name,
        }
    }
}

/// What went wrong while decoding.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ErrorKind {
    /// A field runs past the end of its message or parameter.
    Truncated,
    /// A field holds a value outside its allowed range.
    OutOfRange,
    /// A field holds an invalid value (e.g. text that is not UTF-8).
    Invalid,
    /// A TLV parameter's length is below 4 or runs past its container.
    BadParameterLength {
        /// Parameter type.
        ty: u16,
        /// Length field value.
        len: u16,
    },
    /// A parameter of a known type appears where the spec does not allow it.
    UnexpectedParameter {
        /// Parameter type.
        ty: u16,
    },
    /// A required parameter is absent.
    MissingParameter {
        /// Type of the missing parameter.
        ty: u16,
        /// Spec name of the missing parameter.
        name: &'static str,
    },
    /// A parameter allowed once appears twice.
    DuplicateParameter {
        /// Parameter type.
        ty: u16,
    },
    /// A TV parameter of unknown type (its length cannot be known).
    UnknownParameter {
        /// TV type.
        ty: u16,
    },
    /// Bytes left over after a message's or parameter's last sub-parameter.
    TrailingBytes,
    /// The message header's version is neither 1 nor 2.
    UnsupportedVersion {
        /// Version found.
        version: u8,
    },
    /// The message length field disagrees with the bytes given.
    BadMessageLength {
        /// Length field value.
        len: u32,
    },
    /// Parameters of a self-containing type nested deeper than
    /// [`MAX_NESTING`](crate::codec::MAX_NESTING).
    TooDeep {
        /// Type of the parameter one level too deep.
        ty: u16,
        /// The limit.
        limit: u32,
    },
}

/// A message that could not be decoded: where, what and the LLRPStatus it deserves.
///
/// Boxed so that decode results stay small on the hot path; the fields of
/// [`DecodeErrorDetail`] read through it (`e.offset`, `e.path`, `e.kind`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DecodeError(Box<DecodeErrorDetail>);

/// The contents of a [`DecodeError`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DecodeErrorDetail {
    /// Byte offset from the start of the frame.
    pub offset: usize,
    /// Message, parameters and (last) field leading to the error.
    pub path: Vec<PathSeg>,
    /// What went wrong.
    pub kind: ErrorKind,
}

impl std::ops::Deref for DecodeError {
    type Target = DecodeErrorDetail;
    fn deref(&self) -> &DecodeErrorDetail {
        &self.0
    }
}

impl std::ops::DerefMut for DecodeError {
    fn deref_mut(&mut self) -> &mut DecodeErrorDetail {
        &mut self.0
    }
}

impl DecodeError {
    /// An error at absolute address `at` (made relative to the frame by `Message::decode`).
    #[cold]
    pub(crate) fn at(at: *const u8, kind: ErrorKind) -> Self {
        DecodeError(Box::new(DecodeErrorDetail {
            offset: at as usize,
            path: Vec::new(),
            kind,
        }))
    }

    /// Prepends a step to the path (errors are built from the inside out).
    pub(crate) fn within(mut self, seg: PathSeg) -> Self {
        self.path.insert(0, seg);
        self
    }

    /// The path as `ADD_ROSPEC/ROSpec/AISpec/AntennaIDs`; a step repeated more than twice in
    /// a row is written once with its count (`ParameterError×65`).
    pub fn path_string(&self) -> String {
        let mut out = String::new();
        let mut steps = self.path.iter().map(PathSeg::name).peekable();
        while let Some(name) = steps.next() {
            let mut run = 1;
            while steps.peek() == Some(&name) {
                steps.next();
                run += 1;
            }
            for k in 0..if run > 2 { 1 } else { run } {
                if !out.is_empty() || k > 0 {
                    out.push('/');
                }
                out.push_str(name);
            }
            if run > 2 {
                out.push_str(&format!("×{run}"));
            }
        }
        out
    }

    /// The status code a reader answers this error with (top level of [`Self::to_status`]).
    pub fn status_code(&self) -> StatusCode {
        self.to_status().code()
    }

    /// The LLRPStatus a reader answers with, with FieldError / ParameterError detail.
    pub fn to_status(&self) -> LlrpStatus {
        let description = self.to_string();
        if let ErrorKind::UnsupportedVersion { .. } = self.kind {
            return LlrpStatus::new(StatusCode::M_UnsupportedVersion, description);
        }
        let mut params = self.status_params();
        let field = self.path.iter().rev().find_map(|s| match s {
            PathSeg::Field { index, .. } => Some(*index),
            _ => None,
        });
        let field_code = match self.kind {
            ErrorKind::OutOfRange => StatusCode::A_OutOfRange,
            _ => StatusCode::A_Invalid,
        };
        // The error is either about a field of the innermost container, or about a
        // sub-parameter of it (identified by type).
        let (sub_ty, m_code, p_code) = self.kind.status_codes();
        // An LLRPStatus holds at most 1 + MAX_NESTING ParameterErrors (what the decoder takes):
        // a deeper path is cut, its innermost kept parameter reported as P_ParameterError
        // without the detail below it (the description still names the whole path).
        let most = crate::codec::MAX_NESTING as usize + 1;
        let cut = params.len() + usize::from(sub_ty.is_some()) > most;
        if cut {
            params.truncate(most);
        }
        let sub_ty = sub_ty.filter(|_| !cut);
        let field = field.filter(|_| !cut);
        let field_error = match (sub_ty, field) {
            (None, Some(index)) => Some(FieldError {
                field_num: index,
                error_code: field_code,
                ..Default::default()
            }),
            _ => None,
        };
        let inner = sub_ty.map(|ty| ParameterError::new(ty, p_code));
        let detail_below = sub_ty.is_some() || cut;
        let (field_error, parameter_error) = nest(&params, field_error, inner, detail_below);
        let code = match (params.is_empty(), sub_ty) {
            (false, _) => StatusCode::M_ParameterError,
            (true, Some(_)) => m_code,
            (true, None) => StatusCode::M_FieldError,
        };
        let mut status = LlrpStatus::new(code, description);
        status.field_error = field_error;
        status.parameter_error = parameter_error;
        status
    }

    /// The parameter types along the path, outermost first, as the status echoes them.
    fn status_params(&self) -> Vec<u16> {
        let mut params: Vec<u16> = self
            .path
            .iter()
            .filter_map(|s| match s {
                PathSeg::Param { ty, .. } => Some(*ty),
                _ => None,
            })
            .collect();
        if let ErrorKind::TooDeep { ty, .. } = self.kind {
            // The detail stops at the first parameter of the self-nested run, holding the
            // run as one ParameterError of its type: echoing the whole path would answer
            // with a chain deeper than any decoder takes.
            if let Some(first) = params.iter().position(|&p| p == ty) {
                params.truncate(first + 1);
            }
        }
        params
    }
}

/// Wraps the innermost detail (a field error, or a sub-parameter's error) in one
/// ParameterError per enclosing parameter, innermost last in `params`. The innermost
/// enclosing one is a P_FieldError unless there is detail below it (`detail_below`). Gives
/// what the status itself holds: its FieldError (when no parameter encloses it) and the
/// outermost ParameterError.
fn nest(
    params: &[u16],
    mut field_error: Option<FieldError>,
    mut inner: Option<ParameterError>,
    detail_below: bool,
) -> (Option<FieldError>, Option<ParameterError>) {
    for (depth, ty) in params.iter().enumerate().rev() {
        let innermost = depth == params.len() - 1;
        let code = if innermost && !detail_below {
            StatusCode::P_FieldError
        } else {
            StatusCode::P_ParameterError
        };
        let mut pe = ParameterError::new(*ty, code);
        pe.field_error = field_error.take();
        pe.parameter_error = inner.take().map(Box::new);
        inner = Some(pe);
    }
    (field_error, inner)
}

impl ErrorKind {
    /// For an error about a sub-parameter: its type, and the message- and parameter-level
    /// codes; for an error about a field: no type, M_FieldError and P_FieldError.
    fn status_codes(&self) -> (Option<u16>, StatusCode, StatusCode) {
        use StatusCode as S;
        match *self {
            ErrorKind::UnexpectedParameter { ty } => {
                (Some(ty), S::M_UnexpectedParameter, S::P_UnexpectedParameter)
            }
            ErrorKind::MissingParameter { ty, .. } => {
                (Some(ty), S::M_MissingParameter, S::P_MissingParameter)
            }
            ErrorKind::DuplicateParameter { ty } => {
                (Some(ty), S::M_DuplicateParameter, S::P_DuplicateParameter)
            }
            ErrorKind::UnknownParameter { ty } => {
                (Some(ty), S::M_UnknownParameter, S::P_UnknownParameter)
            }
            ErrorKind::BadParameterLength { ty, .. } | ErrorKind::TooDeep { ty, .. } => {
                (Some(ty), S::M_ParameterError, S::P_ParameterError)
            }
            _ => (None, S::M_FieldError, S::P_FieldError),
        }
    }
}

impl fmt::Display for DecodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let what = match &self.kind {
            ErrorKind::Truncated => "field runs past the end of its container".to_string(),
            ErrorKind::OutOfRange => "field value out of range".to_string(),
            ErrorKind::Invalid => "invalid field value".to_string(),
            ErrorKind::BadParameterLength { ty, len } => {
                format!("parameter type {ty} has bad length {len}")
            }
            ErrorKind::UnexpectedParameter { ty } => format!("unexpected parameter type {ty}"),
            ErrorKind::MissingParameter { ty, name } => {
                format!("missing parameter {name} (type {ty})")
            }
            ErrorKind::DuplicateParameter { ty } => format!("duplicate parameter type {ty}"),
            ErrorKind::UnknownParameter { ty } => format!("unknown TV parameter type {ty}"),
            ErrorKind::TrailingBytes => "trailing bytes after the last parameter".to_string(),
            ErrorKind::UnsupportedVersion { version } => {
                format!("unsupported protocol version {version}")
            }
            ErrorKind::BadMessageLength { len } => format!("bad message length {len}"),
            ErrorKind::TooDeep { ty, limit } => {
                format!("parameter type {ty} nested more than {limit} deep")
            }
        };
        write!(
            f,
            "{what} at offset {} in {}",
            self.offset,
            self.path_string()
        )
    }
}

impl std::error::Error for DecodeError {}

/// Why a byte stream could not be split into frames.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum FrameError {
    /// Length field below the 10-byte header size: the stream cannot be resynchronised.
    #[error("message length {len} is below the 10-byte header (type {msg_type}, id {id})")]
    TooShort {
        /// Length field value.
        len: u32,
        /// Message type from the header.
        msg_type: u16,
        /// Message ID from the header.
        id: u32,
    },
    /// Length field above the configured maximum.
    #[error("message length {len} exceeds the maximum {max} (type {msg_type}, id {id})")]
    TooLong {
        /// Length field value.
        len: u32,
        /// Configured maximum.
        max: u32,
        /// Message type from the header.
        msg_type: u16,
        /// Message ID from the header.
        id: u32,
    },
    /// Version other than 1 (LLRP 1.0.1) or 2 (LLRP 1.1); the frame can be skipped.
    #[error("unsupported LLRP version {} (type {}, id {})", .0.version, .0.msg_type, .0.id)]
    UnsupportedVersion(crate::frame::FrameHeader),
}
