//! Faults injected into the simulated readers over HTTP: `POST /api/readers/{reader}/faults`
//! with a body naming the fault and its parameters (`{"fault": "antenna_disconnect",
//! "antenna": 2}`, `{"fault": "reboot", "keep_state": false}`, …). The API names no
//! simulator: the command that runs the readers hands it a [`FaultControl`].

use std::sync::Arc;

use axum::body::Bytes;
use axum::extract::rejection::{BytesRejection, PathRejection};
use axum::extract::{Path, State};
use axum::http::{HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::{ApiError, AppState};

/// The simulated readers' faults, as the API reaches them.
pub trait FaultControl: Send + Sync + std::fmt::Debug {
    /// Injects `fault` into reader `reader` at once.
    fn inject(&self, reader: &str, fault: FaultRequest) -> Result<(), FaultError>;
}

/// Why a fault was refused.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum FaultError {
    /// No reader of that name.
    #[error("no reader named {0:?}")]
    NoReader(String),
    /// The reader refused it: the message starts with the field that is wrong.
    #[error("{0}")]
    Refused(String),
}

/// The body of `POST /api/readers/{reader}/faults`: the fault and its parameters. Times are
/// wall-clock ms.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(tag = "fault", rename_all = "snake_case", deny_unknown_fields)]
pub enum FaultRequest {
    /// Antenna port `antenna`'s cable pulled: AntennaEvent (disconnected), no reads on it,
    /// AntennaConnected false in GET_READER_CONFIG.
    AntennaDisconnect {
        /// Antenna port, 1-based.
        antenna: u16,
    },
    /// Antenna port `antenna`'s cable plugged back: AntennaEvent (connected), reads again.
    AntennaReconnect {
        /// Antenna port, 1-based.
        antenna: u16,
    },
    /// The reader drops the client's connection: a TCP reset, no ConnectionCloseEvent.
    DropConnection,
    /// The reader reboots: the connection closes, connections are refused for `boot_ms`,
    /// then it is back with its state lost (or kept).
    Reboot {
        /// Keep ROSpecs, AccessSpecs and configuration (default: the scenario reader's
        /// `persist_state`, false unless set).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        keep_state: Option<bool>,
        /// How long the reader is unreachable, ms (default 3000).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        boot_ms: Option<u64>,
    },
    /// The reader takes each request `ms` late, in order, for `for_ms`.
    DelayResponses {
        /// The delay, ms.
        ms: u64,
        /// How long, ms (default 10000).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        for_ms: Option<u64>,
    },
    /// The reader sends none of its next `count` KEEPALIVEs.
    LoseKeepalives {
        /// How many.
        count: u32,
    },
    /// The report buffer is full for `for_ms`, as if the client had stopped reading:
    /// ReportBufferLevelWarningEvent (if enabled), ReportBufferOverflowErrorEvent, reports lost.
    FillReportBuffer {
        /// How long, ms (default 10000).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        for_ms: Option<u64>,
    },
    /// A ReaderExceptionEvent with `message` (if enabled).
    ReaderException {
        /// The event's Message.
        message: String,
    },
}

/// The answer to a fault: what was handed to the reader.
#[derive(Serialize, ToSchema)]
pub struct FaultAccepted {
    /// The reader.
    pub reader: String,
    /// The fault as asked for.
    pub fault: FaultRequest,
}

/// The faults of the run, or the 404 of a run without simulated readers.
fn control(state: &AppState) -> Result<&Arc<dyn FaultControl>, ApiError> {
    state.options.faults.as_ref().ok_or_else(|| {
        ApiError::new(
            StatusCode::NOT_FOUND,
            "no faults: not a simulation (faults are injected on `llrp-gateway sim`)",
        )
    })
}

#[utoipa::path(post, path = "/api/readers/{reader}/faults", tag = "simulation",
    params(("reader" = String, Path, description = "The reader's name (percent-encoded)")),
    request_body(content = FaultRequest, description = "The fault, e.g. \
        `{\"fault\": \"antenna_disconnect\", \"antenna\": 2}`, `{\"fault\": \"reboot\"}`, \
        `{\"fault\": \"delay_responses\", \"ms\": 1500, \"for_ms\": 10000}`",
        content_type = "application/json"),
    responses(
        (status = 202, description = "Handed to the reader, which applies it at once (logged, \
            counted in /metrics' llrp_gateway_faults_total)", body = FaultAccepted),
        (status = 400, description = "The body is bad: the message names the field", body = super::schema::Error),
        (status = 401, description = "A token is set and the request lacks it", body = super::schema::Error),
        (status = 403, description = "From another origin's page, or for a host name that is \
            not this server's", body = super::schema::Error),
        (status = 404, description = "Not a simulation, or no reader of that name", body = super::schema::Error),
        (status = 415, description = "The body is not sent as JSON", body = super::schema::Error)),
    security((), ("bearer" = [])))]
pub(super) async fn post_fault(
    State(state): State<AppState>,
    path: Result<Path<String>, PathRejection>,
    headers: HeaderMap,
    body: Result<Bytes, BytesRejection>,
) -> Result<Response, ApiError> {
    let control = control(&state)?;
    let Path(reader) = path.map_err(|r| ApiError::new(r.status(), r.body_text()))?;
    super::guard::require_json(&headers)?;
    let body = body.map_err(|r| ApiError::new(r.status(), r.body_text()))?;
    let fault = parse_request(&body)?;
    control
        .inject(&reader, fault.clone())
        .map_err(|e| match e {
            FaultError::NoReader(_) => ApiError::new(StatusCode::NOT_FOUND, e.to_string()),
            FaultError::Refused(_) => ApiError::new(StatusCode::BAD_REQUEST, e.to_string()),
        })?;
    let accepted = FaultAccepted { reader, fault };
    Ok((StatusCode::ACCEPTED, Json(accepted)).into_response())
}

/// [`FaultRequest`] tagged from outside (`{"reboot": {...}}`): serde names the field of an
/// error in this form, where the internally tagged one only names the body.
#[derive(Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
#[allow(dead_code)] // read for its errors only
enum Tagged {
    AntennaDisconnect {
        antenna: u16,
    },
    AntennaReconnect {
        antenna: u16,
    },
    DropConnection {},
    Reboot {
        #[serde(default)]
        keep_state: Option<bool>,
        #[serde(default)]
        boot_ms: Option<u64>,
    },
    DelayResponses {
        ms: u64,
        #[serde(default)]
        for_ms: Option<u64>,
    },
    LoseKeepalives {
        count: u32,
    },
    FillReportBuffer {
        #[serde(default)]
        for_ms: Option<u64>,
    },
    ReaderException {
        message: String,
    },
}

/// The fault in `body`; a 400 naming the field that is wrong.
fn parse_request(body: &[u8]) -> Result<FaultRequest, ApiError> {
    let bad = |m: String| ApiError::new(StatusCode::BAD_REQUEST, m);
    let mut de = serde_json::Deserializer::from_slice(body);
    let value = serde_json::Value::deserialize(&mut de).map_err(|e| bad(format!("body: {e}")))?;
    de.end()
        .map_err(|e| bad(format!("body: one JSON object, then nothing: {e}")))?;
    let serde_json::Value::Object(mut fields) = value.clone() else {
        return Err(bad("body: must be a JSON object".into()));
    };
    let name = match fields.remove("fault") {
        Some(serde_json::Value::String(name)) => name,
        Some(other) => return Err(bad(format!("fault: must be a fault's name, got {other}"))),
        None => return Err(bad("fault: missing field `fault`".into())),
    };
    let tagged = serde_json::json!({ name: fields });
    serde_path_to_error::deserialize::<_, Tagged>(tagged).map_err(|e| {
        // The path starts with the fault's name: the field is what follows.
        let path = e.path().to_string();
        let inner = e.inner().to_string();
        // A field missing or unknown is named in serde's message, not in the path.
        let named = (inner.starts_with("missing field") || inner.starts_with("unknown field"))
            .then(|| inner.split('`').nth(1))
            .flatten();
        match (path.split_once('.'), named) {
            _ if path == "." => bad(format!("fault: {inner}")),
            (Some((_, field)), _) | (None, Some(field)) => bad(format!("{field}: {inner}")),
            (None, None) => bad(format!("body: {inner}")),
        }
    })?;
    // The same fields in the API's form: this cannot fail where the above did not, but if
    // it did the body is still the one to blame.
    serde_json::from_value(value).map_err(|e| bad(format!("body: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn error(body: &str) -> String {
        match parse_request(body.as_bytes()) {
            Ok(_) => panic!("{body} should be refused"),
            Err(e) => e.message,
        }
    }

    #[test]
    fn a_bad_body_names_the_field() {
        let e = error(r#"{"fault": "meltdown"}"#);
        assert!(e.starts_with("fault: unknown variant `meltdown`"), "{e}");
        let e = error(r#"{"fault": "antenna_disconnect"}"#);
        assert!(e.starts_with("antenna: missing field `antenna`"), "{e}");
        let e = error(r#"{"fault": "reboot", "boot_s": 3}"#);
        assert!(e.starts_with("boot_s: unknown field `boot_s`"), "{e}");
        let e = error(r#"{"fault": "lose_keepalives", "count": -1}"#);
        assert!(e.starts_with("count: invalid value: integer `-1`"), "{e}");
        let e = error(r#"{"antenna": 2}"#);
        assert!(e.starts_with("fault: missing field `fault`"), "{e}");
        let ok = parse_request(br#"{"fault": "delay_responses", "ms": 1500}"#).expect("valid");
        assert_eq!(
            ok,
            FaultRequest::DelayResponses {
                ms: 1500,
                for_ms: None
            }
        );
    }
}
