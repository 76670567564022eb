//! The request handlers other than the event stream, each with its OpenAPI operation.

use axum::body::Bytes;
use axum::extract::rejection::{BytesRejection, PathRejection};
use axum::extract::{Path, State};
use axum::http::{header, HeaderMap, HeaderValue, StatusCode};
use axum::response::{Html, IntoResponse, Response};
use axum::Json;
use serde::Serialize;
use serde_json::json;
use utoipa::openapi::security::{HttpAuthScheme, HttpBuilder, SecurityScheme};
use utoipa::openapi::{ComponentsBuilder, InfoBuilder, OpenApi, OpenApiBuilder};

use super::{ApiError, AppState};
use crate::localize::live::Input;
use crate::localize::shared::{Point, TagJson, TagsJson};
use crate::reads::Read;

/// The live map: one page, its script inline, nothing fetched from elsewhere.
const MAP_HTML: &str = include_str!("map.html");

/// The document's title and version, before the routes add their paths.
pub(super) fn base_document() -> OpenApi {
    OpenApiBuilder::new()
        .info(
            InfoBuilder::new()
                .title("llrp-gateway")
                .version(env!("CARGO_PKG_VERSION"))
                .description(Some(
                    "The live localizer's HTTP API: tag estimates, readers, ground truth \
                     (simulation), estimate events, pose input and metrics.",
                ))
                .build(),
        )
        .components(Some(
            ComponentsBuilder::new()
                .security_scheme(
                    "bearer",
                    SecurityScheme::Http(HttpBuilder::new().scheme(HttpAuthScheme::Bearer).build()),
                )
                .build(),
        ))
        .build()
}

#[utoipa::path(get, path = "/", tag = "map",
    responses((status = 200, description = "The live map page", content_type = "text/html")))]
pub(super) async fn map_page() -> Response {
    static POLICY: std::sync::OnceLock<HeaderValue> = std::sync::OnceLock::new();
    let policy = POLICY.get_or_init(|| {
        // The policy is ASCII (keywords and base64), so always a valid header value.
        HeaderValue::from_str(&super::guard::page_policy(MAP_HTML))
            .unwrap_or_else(|_| HeaderValue::from_static("default-src 'none'"))
    });
    (
        [(header::CONTENT_SECURITY_POLICY, policy.clone())],
        Html(MAP_HTML),
    )
        .into_response()
}

#[utoipa::path(get, path = "/healthz", tag = "ops",
    responses((status = 200, description = "Serving", body = String, content_type = "text/plain")))]
pub(super) async fn healthz() -> &'static str {
    "ok"
}

#[utoipa::path(get, path = "/metrics", tag = "ops",
    responses((status = 200, description = "Counters and histograms: OpenMetrics 1.0 text for a \
        client whose Accept asks for it (Prometheus does), else the Prometheus text format 0.0.4",
        content(
            (String = "application/openmetrics-text; version=1.0.0"),
            (String = "text/plain; version=0.0.4")))))]
pub(super) async fn metrics(State(state): State<AppState>, headers: HeaderMap) -> Response {
    // Several Accept headers are one list (RFC 9110, 5.3).
    let accept: Vec<&str> = headers
        .get_all(header::ACCEPT)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .collect();
    let format = crate::metrics::exposition::negotiate(
        Some(accept.join(",").as_str()).filter(|a| !a.is_empty()),
    );
    (
        [
            (header::CONTENT_TYPE, format.content_type()),
            (header::VARY, "Accept"),
        ],
        state.metrics.render_as(format),
    )
        .into_response()
}

#[utoipa::path(get, path = "/api/openapi.json", tag = "ops",
    responses((status = 200, description = "This document (OpenAPI 3)", content_type = "application/json")))]
pub(super) async fn openapi_json(State(state): State<AppState>) -> Response {
    (
        [(header::CONTENT_TYPE, "application/json")],
        state.openapi.as_str().to_owned(),
    )
        .into_response()
}

#[utoipa::path(get, path = "/api/tags", tag = "localizer",
    responses((status = 200, description = "Every tag's latest estimate, in EPC order",
        body = super::schema::Tags)))]
pub(super) async fn tags(State(state): State<AppState>) -> Json<TagsJson> {
    let tags = state.shared.tags().iter().map(TagJson::from).collect();
    Json(TagsJson { tags })
}

/// `GET /api/tags/{epc}`: the tag's estimate and its newest reads.
#[derive(Serialize)]
struct TagDetail {
    #[serde(flatten)]
    tag: TagJson,
    recent_reads: Vec<Read>,
}

#[utoipa::path(get, path = "/api/tags/{epc}", tag = "localizer",
    params(("epc" = String, Path, description = "EPC in hex, any case")),
    responses(
        (status = 200, description = "The tag's estimate and its newest reads (oldest first)",
            body = super::schema::TagDetail),
        (status = 400, description = "The EPC is not hex", body = super::schema::Error),
        (status = 404, description = "No such tag was read", body = super::schema::Error)))]
pub(super) async fn tag(
    State(state): State<AppState>,
    epc: Result<Path<String>, PathRejection>,
) -> Result<Response, ApiError> {
    let Path(epc) = epc.map_err(|r| ApiError::new(r.status(), r.body_text()))?;
    let epc = crate::reads::Epc::parse(&epc)
        .map_err(|e| ApiError::new(StatusCode::BAD_REQUEST, e.to_string()))?;
    let view = state
        .shared
        .tag(&epc)
        .ok_or_else(|| ApiError::new(StatusCode::NOT_FOUND, format!("no tag {epc} was read")))?;
    let detail = TagDetail {
        tag: TagJson::from(&view),
        recent_reads: view.recent.iter().cloned().collect(),
    };
    Ok(Json(detail).into_response())
}

#[utoipa::path(get, path = "/api/readers", tag = "localizer",
    responses((status = 200, description = "Every reader: connection, inventory, read rate, \
        antennas with their newest poses", body = super::schema::Readers)))]
pub(super) async fn readers(State(state): State<AppState>) -> Response {
    Json(json!({ "readers": state.shared.readers() })).into_response()
}

#[utoipa::path(get, path = "/api/truth", tag = "simulation",
    responses(
        (status = 200, description = "The simulation's true tag positions and antenna poses",
            body = super::schema::Truth),
        (status = 404, description = "Not a simulation", body = super::schema::Error)))]
pub(super) async fn truth(State(state): State<AppState>) -> Result<Response, ApiError> {
    let not_here = || ApiError::new(StatusCode::NOT_FOUND, "no ground truth: not a simulation");
    if !state.options.simulation {
        return Err(not_here());
    }
    let truth = state.shared.truth().ok_or_else(not_here)?;
    let tags: Vec<_> = truth
        .tags
        .iter()
        .map(|t| {
            json!({
                "epc": t.epc,
                "position": Point::from(t.position),
                "reference": t.reference,
            })
        })
        .collect();
    Ok(Json(json!({ "tags": tags, "antennas": truth.antennas })).into_response())
}

#[utoipa::path(post, path = "/api/poses", tag = "localizer",
    request_body(content = Vec<super::schema::Pose>, description = "One pose object, a JSON \
        array of them, or JSON Lines (one object a line), sent as application/json (or \
        application/x-ndjson, application/jsonl)"),
    responses(
        (status = 202, description = "Handed to the localizer", body = super::schema::Accepted),
        (status = 400, description = "A pose is bad: the message names its index, field and \
            reason; none of the body is taken", body = super::schema::Error),
        (status = 401, description = "A token is set and the request lacks it", body = super::schema::Error),
        (status = 403, description = "From another origin's page, or for a host name that is \
            not this server's", body = super::schema::Error),
        (status = 408, description = "The body stalled, or the request took too long", body = super::schema::Error),
        (status = 413, description = "The body is over the limit", body = super::schema::Error),
        (status = 415, description = "The body is not sent as JSON", body = super::schema::Error),
        (status = 503, description = "The localizer is behind: try again", body = super::schema::Error)),
    security((), ("bearer" = [])))]
pub(super) async fn post_poses(
    State(state): State<AppState>,
    headers: HeaderMap,
    body: Result<Bytes, BytesRejection>,
) -> Result<Response, ApiError> {
    super::guard::require_json(&headers)?;
    let body = body.map_err(|r| {
        if stalled(&r) {
            ApiError::new(
                StatusCode::REQUEST_TIMEOUT,
                "the body stalled: no part of it came within the body-read timeout",
            )
        } else {
            ApiError::new(r.status(), r.body_text())
        }
    })?;
    let poses = crate::localize::poses::parse_poses(&body)
        .map_err(|e| ApiError::new(StatusCode::BAD_REQUEST, e))?;
    let n = poses.len();
    if !state.tap.offer(Input::Poses(poses)) {
        return Err(ApiError::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "the localizer is behind: the poses were dropped, send them again",
        ));
    }
    Ok((StatusCode::ACCEPTED, Json(json!({ "accepted": n }))).into_response())
}

/// Whether reading a body failed because it stalled (tower-http's body timeout).
fn stalled(rejection: &BytesRejection) -> bool {
    let mut cause: Option<&(dyn std::error::Error + 'static)> = Some(rejection);
    while let Some(e) = cause {
        if e.is::<tower_http::timeout::TimeoutError>() {
            return true;
        }
        cause = e.source();
    }
    false
}
