//! The HTTP API of the live localizer (issue 18) and the live map page it serves: the tags'
//! estimates, the readers, the simulation's truth, an event stream of estimate updates, pose
//! input, Prometheus metrics and an OpenAPI document generated from the handlers
//! (`docs/http.md` lists the routes and their shapes).
//!
//! Every route is declared once, in [`api`]; the router and the OpenAPI document both come
//! from it. Errors are JSON `{"error": "..."}`, unknown routes included.

use std::net::SocketAddr;
use std::sync::Arc;

use axum::extract::{DefaultBodyLimit, Request, State};
use axum::http::{header, HeaderValue, Method, StatusCode};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use axum::Json;
use subtle::ConstantTimeEq;
use tokio::sync::watch;
use tower_http::timeout::RequestBodyTimeoutLayer;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use crate::localize::live::Tap;
use crate::localize::shared::Shared;
use crate::metrics::Metrics;
use crate::secret::Secret;

mod events;
pub mod faults;
pub mod gpio;
pub mod guard;
mod handlers;
pub mod launch;
pub mod schema;
mod serve;

pub use guard::BrowserRules;
pub use serve::{serve, ServerLimits};

/// Default largest request body (`POST /api/poses`): 1 MiB.
pub const DEFAULT_BODY_LIMIT: usize = 1 << 20;

/// How the API is served.
#[derive(Clone, Debug)]
pub struct HttpOptions {
    /// Bearer token; with one, write routes (POST) need `Authorization: Bearer <token>`
    /// (shown as `***`).
    pub token: Option<Secret>,
    /// Every route needs the token, reads too (a listener beyond loopback: see
    /// [`require_token_everywhere`]).
    pub token_everywhere: bool,
    /// A simulation: `GET /api/truth` is served (404 otherwise).
    pub simulation: bool,
    /// Largest request body (bytes); larger ones get 413 (at once when declared).
    pub body_limit: usize,
    /// Timeouts and the connection limit.
    pub limits: ServerLimits,
    /// What browser pages of other origins and other host names may do.
    pub browser: BrowserRules,
    /// The process's metrics, served by `GET /metrics`; `None`: the localizer's alone.
    pub metrics: Option<Arc<Metrics>>,
    /// The simulated readers' GPIO (`GET /api/gpio`, `POST /api/readers/{reader}/gpi/{port}`;
    /// 404 without).
    pub gpio: Option<Arc<dyn gpio::GpioControl>>,
    /// The simulated readers' faults (`POST /api/readers/{reader}/faults`; 404 without).
    pub faults: Option<Arc<dyn faults::FaultControl>>,
}

impl Default for HttpOptions {
    fn default() -> Self {
        HttpOptions {
            token: None,
            token_everywhere: false,
            simulation: false,
            body_limit: DEFAULT_BODY_LIMIT,
            limits: ServerLimits::default(),
            browser: BrowserRules {
                check_host: true,
                ..BrowserRules::default()
            },
            metrics: None,
            gpio: None,
            faults: None,
        }
    }
}

/// What the handlers share: the localizer's published state, its tap and the options.
#[derive(Clone, Debug)]
pub struct AppState {
    /// The localizer's published state.
    pub shared: Arc<Shared>,
    /// Where posted poses go.
    pub tap: Tap,
    /// How the API is served.
    pub options: Arc<HttpOptions>,
    /// What `GET /metrics` serves.
    pub metrics: Arc<Metrics>,
    /// The OpenAPI document, serialised once.
    openapi: Arc<String>,
    /// Estimate updates for the event stream, from the localizer's [`Shared::on_publish`].
    events: tokio::sync::broadcast::Sender<Arc<crate::localize::shared::TagView>>,
}

/// Whether a listener on `addr` must require the token on every route: it is not loopback.
pub fn require_token_everywhere(addr: &SocketAddr) -> bool {
    !addr.ip().is_loopback()
}

/// Refuses a listener beyond loopback without a token (the message says why).
pub fn check_bind(addr: &SocketAddr, token: &Option<Secret>) -> Result<(), String> {
    let has_token = token.as_ref().is_some_and(|t| !t.is_empty());
    if require_token_everywhere(addr) && !has_token {
        return Err(format!(
            "refusing to serve the HTTP API on {addr} without a token: \
             bind a loopback address or set a token"
        ));
    }
    Ok(())
}

/// Every route of the API, with its OpenAPI operation: the one list the router and the
/// document are made from.
pub fn api() -> OpenApiRouter<AppState> {
    OpenApiRouter::with_openapi(handlers::base_document())
        .routes(routes!(handlers::map_page))
        .routes(routes!(handlers::healthz))
        .routes(routes!(handlers::metrics))
        .routes(routes!(handlers::openapi_json))
        .routes(routes!(handlers::tags))
        .routes(routes!(handlers::tag))
        .routes(routes!(handlers::readers))
        .routes(routes!(handlers::truth))
        .routes(routes!(events::events))
        .routes(routes!(handlers::post_poses))
        .routes(routes!(gpio::get_gpio))
        .routes(routes!(gpio::post_gpi))
        .routes(routes!(faults::post_fault))
}

/// The OpenAPI 3 document of [`api`].
pub fn openapi() -> utoipa::openapi::OpenApi {
    api().into_openapi()
}

/// The API's router over `shared` and `tap`.
pub fn router(shared: Arc<Shared>, tap: Tap, options: HttpOptions) -> axum::Router {
    let (routes, document) = api().split_for_parts();
    // A document of plain strings and maps always serialises.
    let openapi = document.to_pretty_json().unwrap_or_else(|_| "{}".into());
    let body_limit = options.body_limit;
    let body_read = options.limits.body_read;
    let cors = cors(&options.browser);
    let (events, _) = tokio::sync::broadcast::channel(crate::localize::shared::EVENT_BUFFER);
    let tx = events.clone();
    // No subscriber is not an error.
    shared.on_publish(move |view| drop(tx.send(Arc::clone(view))));
    let metrics = options
        .metrics
        .clone()
        .unwrap_or_else(|| Metrics::of_localizer(&shared));
    let state = AppState {
        shared,
        metrics,
        events,
        tap,
        options: Arc::new(options),
        openapi: Arc::new(openapi),
    };
    let app = routes
        .fallback(no_route)
        .method_not_allowed_fallback(no_method)
        .layer(DefaultBodyLimit::max(body_limit))
        .layer(RequestBodyTimeoutLayer::new(body_read))
        .layer(middleware::from_fn_with_state(state.clone(), deadline))
        .layer(middleware::from_fn_with_state(
            state.clone(),
            declared_length,
        ))
        .layer(middleware::from_fn_with_state(state.clone(), authorize))
        .layer(middleware::from_fn_with_state(
            state.clone(),
            guard::browser_guard,
        ))
        .layer(middleware::from_fn(guard::security_headers));
    let app = match cors {
        Some(cors) => app.layer(cors),
        None => app,
    };
    app.with_state(state)
}

/// CORS answers (preflights included) for the origins `--http-allowed-origin` names, and for
/// no other: a page of another origin can then neither read the API nor send it JSON.
fn cors(rules: &BrowserRules) -> Option<tower_http::cors::CorsLayer> {
    use tower_http::cors::{AllowOrigin, CorsLayer};
    let origins: Vec<HeaderValue> = rules
        .allowed_origins
        .iter()
        .filter_map(|o| HeaderValue::from_str(o.trim_end_matches('/')).ok())
        .collect();
    if origins.is_empty() {
        return None;
    }
    Some(
        CorsLayer::new()
            .allow_origin(AllowOrigin::list(origins))
            .allow_methods([Method::GET, Method::POST])
            .allow_headers([header::CONTENT_TYPE, header::AUTHORIZATION])
            .max_age(std::time::Duration::from_secs(600)),
    )
}

/// The route that streams for as long as the client listens, so has no deadline.
const STREAM_ROUTE: &str = "/api/events";

/// A request that takes longer than [`ServerLimits::request`] from its header to its answer
/// gets 408 and the connection is closed (the event stream excepted).
async fn deadline(State(state): State<AppState>, request: Request, next: Next) -> Response {
    if request.uri().path() == STREAM_ROUTE {
        return next.run(request).await;
    }
    let limit = state.options.limits.request;
    match tokio::time::timeout(limit, next.run(request)).await {
        Ok(response) => response,
        Err(_) => closing(ApiError::new(
            StatusCode::REQUEST_TIMEOUT,
            format!("the request took over {} s", limit.as_secs_f64()),
        )),
    }
}

/// A body declared (Content-Length) over the limit gets 413 before any of it is read, and the
/// connection is closed.
async fn declared_length(State(state): State<AppState>, request: Request, next: Next) -> Response {
    let limit = state.options.body_limit;
    let declared = request
        .headers()
        .get(header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.trim().parse::<u64>().ok());
    match declared {
        Some(n) if n > limit as u64 => closing(ApiError::new(
            StatusCode::PAYLOAD_TOO_LARGE,
            format!("the body declares {n} bytes: the limit is {limit}"),
        )),
        _ => next.run(request).await,
    }
}

/// `error` as a response that also closes the connection (its request was not read whole).
fn closing(error: ApiError) -> Response {
    let mut response = error.into_response();
    response
        .headers_mut()
        .insert(header::CONNECTION, HeaderValue::from_static("close"));
    response
}

/// Tells long-lived responses (the event stream) that the server is shutting down.
#[derive(Clone, Debug)]
pub(crate) struct Closing(pub(crate) watch::Receiver<bool>);

/// An error as the API answers it: a status and `{"error": message}`.
#[derive(Debug)]
pub struct ApiError {
    /// The HTTP status.
    pub status: StatusCode,
    /// What went wrong.
    pub message: String,
}

impl ApiError {
    /// An error of `status` saying `message`.
    pub fn new(status: StatusCode, message: impl Into<String>) -> ApiError {
        ApiError {
            status,
            message: message.into(),
        }
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        (
            self.status,
            Json(serde_json::json!({ "error": self.message })),
        )
            .into_response()
    }
}

async fn no_route(method: Method, uri: axum::http::Uri) -> ApiError {
    ApiError::new(
        StatusCode::NOT_FOUND,
        format!("no route {method} {}", uri.path()),
    )
}

async fn no_method(method: Method, uri: axum::http::Uri) -> ApiError {
    ApiError::new(
        StatusCode::METHOD_NOT_ALLOWED,
        format!("{} does not take {method}", uri.path()),
    )
}

/// The token rule: writes need it when there is one; with `token_everywhere`, reads too.
async fn authorize(State(state): State<AppState>, request: Request, next: Next) -> Response {
    let Some(token) = state.options.token.as_ref().map(Secret::expose) else {
        return next.run(request).await;
    };
    let write = !matches!(*request.method(), Method::GET | Method::HEAD);
    if !write && !state.options.token_everywhere {
        return next.run(request).await;
    }
    let given = request
        .headers()
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(bearer);
    let reason = match given {
        None => "this route needs the header Authorization: Bearer <token>",
        Some(g) if !bool::from(g.as_bytes().ct_eq(token.as_bytes())) => "wrong bearer token",
        Some(_) => return next.run(request).await,
    };
    let mut response = ApiError::new(StatusCode::UNAUTHORIZED, reason).into_response();
    response
        .headers_mut()
        .insert(header::WWW_AUTHENTICATE, HeaderValue::from_static("Bearer"));
    response
}

/// The credentials of an `Authorization` value in the Bearer scheme, whose name is
/// case-insensitive (RFC 9110 §11.1).
fn bearer(value: &str) -> Option<&str> {
    let (scheme, credentials) = value.trim().split_once(' ')?;
    scheme
        .eq_ignore_ascii_case("bearer")
        .then(|| credentials.trim())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn beyond_loopback_needs_a_token() {
        let lo: SocketAddr = "127.0.0.1:8080".parse().expect("address");
        let lo6: SocketAddr = "[::1]:8080".parse().expect("address");
        let any: SocketAddr = "0.0.0.0:8080".parse().expect("address");
        assert!(!require_token_everywhere(&lo) && !require_token_everywhere(&lo6));
        assert!(require_token_everywhere(&any));
        assert!(check_bind(&lo, &None).is_ok());
        let e = check_bind(&any, &None).expect_err("no token");
        assert!(e.contains("0.0.0.0:8080") && e.contains("token"), "{e}");
        assert!(
            check_bind(&any, &Some(Secret::new(""))).is_err(),
            "empty token"
        );
        assert!(check_bind(&any, &Some("s3cret".into())).is_ok());
    }

    #[test]
    fn the_bearer_scheme_is_case_insensitive_and_other_schemes_are_not_taken() {
        assert_eq!(bearer("Bearer s3cret"), Some("s3cret"));
        assert_eq!(bearer("bearer s3cret"), Some("s3cret"));
        assert_eq!(bearer("BEARER  s3cret "), Some("s3cret"));
        assert_eq!(bearer("Basic s3cret"), None);
        assert_eq!(bearer("Bearers3cret"), None);
    }
}
