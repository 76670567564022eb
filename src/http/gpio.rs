//! The simulated readers' GPIO over HTTP: `GET /api/gpio` (every reader's GPI and GPO
//! states) and `POST /api/readers/{reader}/gpi/{port}` (set a GPI line high or low, or pulse
//! it: a photo-eye seeing an object). The API names no simulator: the command that runs the
//! readers hands it a [`GpioControl`].

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

/// Longest pulse the API takes, ms (one hour of simulated time).
pub const MAX_PULSE_MS: u64 = 3_600_000;

/// The readers' GPIO, as the API reaches it.
pub trait GpioControl: Send + Sync + std::fmt::Debug {
    /// Every reader's GPIO as it last knew it, in the readers' order.
    fn readers(&self) -> Vec<ReaderGpio>;
    /// Sets GPI `port` of reader `reader` as `change` says.
    fn change(&self, reader: &str, port: u16, change: GpiChange) -> Result<(), GpioError>;
}

/// A change of a GPI line asked for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GpiChange {
    /// The level (true: high).
    pub high: bool,
    /// Back to the other level after this many ms of simulated time; `None`: stays.
    pub pulse_ms: Option<u64>,
}

/// Why a change was refused.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum GpioError {
    /// No reader of that name.
    #[error("no reader named {0:?}")]
    NoReader(String),
    /// The reader refused it (a port it lacks); the message says why.
    #[error("{0}")]
    Refused(String),
}

/// A GPIO level.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum Level {
    /// Logic 1.
    High,
    /// Logic 0.
    Low,
}

impl Level {
    /// The level of `high`.
    pub fn of(high: bool) -> Level {
        if high {
            Level::High
        } else {
            Level::Low
        }
    }
}

/// One GPI port.
#[derive(Clone, Debug, PartialEq, Serialize, ToSchema)]
pub struct GpiJson {
    /// GPI port, 1-based.
    pub port: u16,
    /// Its level.
    pub state: Level,
    /// Whether the LLRP client left it enabled (GPIPortCurrentState.Config): a disabled port
    /// raises no GPIEvent and fires no trigger.
    pub enabled: bool,
}

/// One GPO port.
#[derive(Clone, Debug, PartialEq, Serialize, ToSchema)]
pub struct GpoJson {
    /// GPO port, 1-based.
    pub port: u16,
    /// The level the LLRP client last wrote (GPOWriteData), low at first.
    pub state: Level,
}

/// One reader's GPIO.
#[derive(Clone, Debug, PartialEq, Serialize, ToSchema)]
pub struct ReaderGpio {
    /// The reader's name.
    pub reader: String,
    /// Its GPI ports.
    pub gpis: Vec<GpiJson>,
    /// Its GPO ports.
    pub gpos: Vec<GpoJson>,
}

/// `GET /api/gpio`.
#[derive(Serialize, ToSchema)]
pub struct GpioJson {
    /// Every simulated reader, in the scenario's order.
    pub readers: Vec<ReaderGpio>,
}

/// The body of `POST /api/readers/{reader}/gpi/{port}`.
#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct GpiRequest {
    /// The level to set.
    pub state: Level,
    /// Set the level for this many ms of simulated time, then the other (1 to 3,600,000); a
    /// pulse. Without it the level stays.
    #[serde(default)]
    pub pulse_ms: Option<u64>,
}

/// The answer to a change: what was handed to the reader.
#[derive(Serialize, ToSchema)]
pub struct GpiAccepted {
    /// The reader.
    pub reader: String,
    /// The GPI port.
    pub port: u16,
    /// The level set.
    pub state: Level,
    /// The pulse's width, ms, if a pulse.
    #[schema(required = true)]
    pub pulse_ms: Option<u64>,
}

/// The GPIO of the run, or the 404 of a run without simulated readers.
fn control(state: &AppState) -> Result<&Arc<dyn GpioControl>, ApiError> {
    state.options.gpio.as_ref().ok_or_else(|| {
        ApiError::new(
            StatusCode::NOT_FOUND,
            "no GPIO: not a simulation (GPI lines are toggled on `llrp-gateway sim`)",
        )
    })
}

#[utoipa::path(get, path = "/api/gpio", tag = "simulation",
    responses(
        (status = 200, description = "Every simulated reader's GPI and GPO ports as it last \
            knew them", body = GpioJson),
        (status = 404, description = "Not a simulation", body = super::schema::Error)))]
pub(super) async fn get_gpio(State(state): State<AppState>) -> Result<Response, ApiError> {
    let readers = control(&state)?.readers();
    Ok(Json(GpioJson { readers }).into_response())
}

#[utoipa::path(post, path = "/api/readers/{reader}/gpi/{port}", tag = "simulation",
    params(
        ("reader" = String, Path, description = "The reader's name (percent-encoded)"),
        ("port" = u16, Path, description = "GPI port, 1-based")),
    request_body(content = GpiRequest, description = "`{\"state\": \"high\"}`, or a pulse: \
        `{\"state\": \"high\", \"pulse_ms\": 300}`", content_type = "application/json"),
    responses(
        (status = 202, description = "Handed to the reader, which applies it on its clock \
            at once (GPIEvent, GPI triggers)", body = GpiAccepted),
        (status = 400, description = "The body or the port is bad: the message names the \
            field", body = super::schema::Error),
        (status = 401, description = "A token is set and the request lacks it", body = super::schema::Error),
        (status = 403, description = "From another origin's page, or for a host name that is \
            not this server's", body = super::schema::Error),
        (status = 404, description = "Not a simulation, or no reader of that name", body = super::schema::Error),
        (status = 415, description = "The body is not sent as JSON", body = super::schema::Error)),
    security((), ("bearer" = [])))]
pub(super) async fn post_gpi(
    State(state): State<AppState>,
    path: Result<Path<(String, String)>, PathRejection>,
    headers: HeaderMap,
    body: Result<Bytes, BytesRejection>,
) -> Result<Response, ApiError> {
    let control = control(&state)?;
    let Path((reader, port)) = path.map_err(|r| ApiError::new(r.status(), r.body_text()))?;
    let port: u16 = port.parse().map_err(|_| {
        ApiError::new(
            StatusCode::BAD_REQUEST,
            format!("port: must be a GPI port number (1, 2, ...), got {port:?}"),
        )
    })?;
    super::guard::require_json(&headers)?;
    let body = body.map_err(|r| ApiError::new(r.status(), r.body_text()))?;
    let request = parse_request(&body)?;
    let change = GpiChange {
        high: request.state == Level::High,
        pulse_ms: request.pulse_ms,
    };
    control.change(&reader, port, change).map_err(|e| match e {
        GpioError::NoReader(_) => ApiError::new(StatusCode::NOT_FOUND, e.to_string()),
        GpioError::Refused(_) => ApiError::new(StatusCode::BAD_REQUEST, format!("port: {e}")),
    })?;
    let accepted = GpiAccepted {
        reader,
        port,
        state: request.state,
        pulse_ms: request.pulse_ms,
    };
    Ok((StatusCode::ACCEPTED, Json(accepted)).into_response())
}

/// The request in `body`; a 400 naming the field that is wrong.
fn parse_request(body: &[u8]) -> Result<GpiRequest, ApiError> {
    let bad = |m: String| ApiError::new(StatusCode::BAD_REQUEST, m);
    let mut de = serde_json::Deserializer::from_slice(body);
    let request: GpiRequest = serde_path_to_error::deserialize(&mut de).map_err(|e| {
        let path = e.path().to_string();
        if path == "." {
            bad(format!("body: {}", e.inner()))
        } else {
            bad(format!("{path}: {}", e.inner()))
        }
    })?;
    de.end()
        .map_err(|e| bad(format!("body: one JSON object, then nothing: {e}")))?;
    if let Some(ms) = request.pulse_ms {
        if ms == 0 || ms > MAX_PULSE_MS {
            return Err(bad(format!(
                "pulse_ms: must be in [1, {MAX_PULSE_MS}], got {ms}"
            )));
        }
    }
    Ok(request)
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
        assert!(error(r#"{"state": "up"}"#).starts_with("state: unknown variant `up`"));
        assert!(error(r#"{"state": "high", "pulse_ms": -1}"#).starts_with("pulse_ms: "));
        assert!(error(r#"{"state": "high", "pulse_ms": 0}"#).starts_with("pulse_ms: must be"));
        let unknown = error(r#"{"level": "high"}"#);
        assert!(
            unknown.starts_with("level: unknown field `level`"),
            "{unknown}"
        );
        assert!(error(r#"{}"#).contains("missing field `state`"));
        let ok = parse_request(br#"{"state": "low", "pulse_ms": 250}"#).expect("valid");
        assert_eq!((ok.state, ok.pulse_ms), (Level::Low, Some(250)));
    }
}
