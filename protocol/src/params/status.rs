//! LLRPStatus and its error detail parameters.

use crate::error::StatusCode;

llrp_struct! {
    /// Outcome of a request: a status code, a description and optional detail.
    pub struct LlrpStatus: tlv [287] "LLRPStatus" {
        status_code "StatusCode": StatusCode,
        error_description "ErrorDescription": String,
    } {
        field_error: opt FieldError,
        parameter_error: opt ParameterError,
    }
}

llrp_struct! {
    /// Which field of a message or parameter was in error, and why.
    pub struct FieldError: tlv [288] "FieldError" {
        field_num "FieldNum": u16,
        error_code "ErrorCode": StatusCode,
    } {}
}

llrp_struct! {
    /// Which parameter was in error, and why; nests down to the innermost one.
    pub struct ParameterError: tlv [289] "ParameterError" {
        parameter_type "ParameterType": u16,
        error_code "ErrorCode": StatusCode,
    } {
        field_error: opt FieldError,
        parameter_error: opt Box<ParameterError>,
    }
}

impl LlrpStatus {
    /// A status with this code and description and no detail.
    pub fn new(code: StatusCode, description: impl Into<String>) -> Self {
        LlrpStatus {
            status_code: code,
            error_description: description.into(),
            ..Default::default()
        }
    }

    /// M_Success with an empty description.
    pub fn success() -> Self {
        Self::new(StatusCode::M_Success, "")
    }

    /// The status code.
    pub fn code(&self) -> StatusCode {
        self.status_code
    }

    /// True for M_Success.
    pub fn is_success(&self) -> bool {
        self.status_code == StatusCode::M_Success
    }
}

impl ParameterError {
    /// Error detail for parameter type `ty`.
    pub fn new(ty: u16, code: StatusCode) -> Self {
        ParameterError {
            parameter_type: ty,
            error_code: code,
            ..Default::default()
        }
    }
}
