//! What a browser on the user's desktop may do with the API: pages of other origins cannot
//! write (the `Origin` and `Sec-Fetch-Site` checks), a host name that is not loopback's
//! cannot reach a loopback listener (DNS rebinding), and every response carries the headers
//! that keep the map page from being sniffed, framed or leaking its address
//! (`docs/http.md`, "What a browser can do").

use axum::extract::{Request, State};
use axum::http::{header, HeaderMap, HeaderName, HeaderValue, Method, StatusCode};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use base64::engine::general_purpose::STANDARD as BASE64;
use base64::Engine as _;

use super::{ApiError, AppState};

/// What browsers may do beyond the API's own origin.
#[derive(Clone, Debug, Default)]
pub struct BrowserRules {
    /// Check the `Host` header: true for a loopback listener (a name that is not loopback's
    /// is a DNS rebinding attempt). Beyond loopback the token guards every route instead.
    pub check_host: bool,
    /// Host names accepted beside loopback's (`--http-allowed-host`); a leading `.` takes
    /// the domain and its subdomains.
    pub allowed_hosts: Vec<String>,
    /// Origins whose pages may call the API, writes included (`--http-allowed-origin`,
    /// e.g. `http://dashboard.lan:3000`); they get CORS answers.
    pub allowed_origins: Vec<String>,
}

impl BrowserRules {
    /// Whether `host` (a `Host` header's value, port and all) names this server.
    pub fn host_allowed(&self, host: &str) -> bool {
        let name = host_name(host).to_ascii_lowercase();
        is_loopback_name(&name)
            || self.allowed_hosts.iter().any(|a| {
                let a = host_name(a).to_ascii_lowercase();
                match a.strip_prefix('.') {
                    Some(domain) => name == domain || name.ends_with(&format!(".{domain}")),
                    None => a == name,
                }
            })
    }

    /// Whether `origin` is one a flag names.
    pub fn origin_allowed(&self, origin: &str) -> bool {
        self.allowed_origins
            .iter()
            .any(|a| a.trim_end_matches('/').eq_ignore_ascii_case(origin))
    }
}

/// The host part of a `Host` value: without its port, an IPv6 literal with its brackets.
fn host_name(host: &str) -> &str {
    let host = host.trim();
    if host.starts_with('[') {
        return host.find(']').map_or(host, |end| &host[..=end]);
    }
    match host.rsplit_once(':') {
        Some((name, port)) if port.bytes().all(|b| b.is_ascii_digit()) => name,
        _ => host,
    }
}

/// `localhost`, a name under `.localhost` (RFC 6761 §6.3: always loopback), an IPv4 address in
/// 127.0.0.0/8, or `[::1]`.
fn is_loopback_name(name: &str) -> bool {
    name == "localhost"
        || name.ends_with(".localhost")
        || name == "[::1]"
        || name
            .parse::<std::net::Ipv4Addr>()
            .is_ok_and(|ip| ip.is_loopback())
}

/// Whether a request changes state: anything but GET, HEAD and OPTIONS.
fn is_write(method: &Method) -> bool {
    !matches!(*method, Method::GET | Method::HEAD | Method::OPTIONS)
}

/// The Host rule, then the cross-origin write rule; refused requests get 403 naming the rule
/// and the flag that lifts it.
pub(super) async fn browser_guard(
    State(state): State<AppState>,
    request: Request,
    next: Next,
) -> Response {
    let rules = &state.options.browser;
    let headers = request.headers();
    let host = headers.get(header::HOST).and_then(|v| v.to_str().ok());
    if rules.check_host {
        if let Some(host) = host.filter(|h| !rules.host_allowed(h)) {
            return ApiError::new(
                StatusCode::FORBIDDEN,
                format!(
                    "Host {host:?} is not this server's: a loopback listener answers only \
                     loopback names (localhost, 127.0.0.1, [::1]) and those given with \
                     --http-allowed-host"
                ),
            )
            .into_response();
        }
    }
    if is_write(request.method()) {
        if let Err(reason) = write_allowed(rules, headers, host) {
            tracing::warn!(
                "HTTP: refused {} {}: {reason}",
                request.method(),
                request.uri().path()
            );
            return ApiError::new(StatusCode::FORBIDDEN, reason).into_response();
        }
    }
    next.run(request).await
}

/// A write is allowed from the API's own origin, from an origin a flag names, or from a
/// client that is not a browser page (no `Origin`, no `Sec-Fetch-Site`).
fn write_allowed(
    rules: &BrowserRules,
    headers: &HeaderMap,
    host: Option<&str>,
) -> Result<(), String> {
    let origin = headers.get(header::ORIGIN).and_then(|v| v.to_str().ok());
    let site = headers
        .get(HeaderName::from_static("sec-fetch-site"))
        .and_then(|v| v.to_str().ok());
    let named = origin.is_some_and(|o| rules.origin_allowed(o));
    if let Some(site) = site {
        if !matches!(site, "same-origin" | "none") && !named {
            return Err(format!(
                "a write from another site's page (Sec-Fetch-Site: {site}) is refused: \
                 allow its origin with --http-allowed-origin"
            ));
        }
    }
    if let Some(origin) = origin {
        let own = host.is_some_and(|h| {
            origin.eq_ignore_ascii_case(&format!("http://{h}"))
                || origin.eq_ignore_ascii_case(&format!("https://{h}"))
        });
        if !own && !named {
            return Err(format!(
                "a write from the page of origin {origin:?} is refused: only this server's \
                 own pages and the origins given with --http-allowed-origin may write"
            ));
        }
    }
    Ok(())
}

/// The Content-Security-Policy of a page whose one inline script and one inline style are
/// those of `html` (allowed by their SHA-256): the event stream's worker from a blob,
/// requests to its own origin only, and no framing, plugins, forms or base URL.
pub(super) fn page_policy(html: &str) -> String {
    let hash = |open: &str, close: &str| {
        let body = html
            .split_once(open)
            .and_then(|(_, rest)| rest.split_once(close))
            .map_or("", |(body, _)| body);
        format!("'sha256-{}'", sha256_base64(body))
    };
    format!(
        "default-src 'none'; script-src {}; style-src {}; connect-src 'self'; \
         worker-src blob:; img-src 'self' data:; base-uri 'none'; form-action 'none'; \
         frame-ancestors 'none'",
        hash("<script>", "</script>"),
        hash("<style>", "</style>")
    )
}

/// The SHA-256 of `text`, base64 as CSP hash sources write it.
fn sha256_base64(text: &str) -> String {
    BASE64.encode(ring::digest::digest(&ring::digest::SHA256, text.as_bytes()).as_ref())
}

/// The API's answers are data, never a page to frame or run.
const API_CSP: &str = "default-src 'none'; frame-ancestors 'none'";

/// Adds the headers every response carries; the map page gets its own policy (set by its
/// handler), every other response [`API_CSP`].
pub(super) async fn security_headers(request: Request, next: Next) -> Response {
    let mut response = next.run(request).await;
    let h = response.headers_mut();
    h.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    h.insert(
        header::REFERRER_POLICY,
        HeaderValue::from_static("no-referrer"),
    );
    h.insert(header::X_FRAME_OPTIONS, HeaderValue::from_static("DENY"));
    if !h.contains_key(header::CONTENT_SECURITY_POLICY) {
        h.insert(
            header::CONTENT_SECURITY_POLICY,
            HeaderValue::from_static(API_CSP),
        );
    }
    response
}

/// The media types a JSON body may be sent as (`POST /api/poses`): none of them is one a
/// page can send across origins without a CORS preflight.
pub const JSON_TYPES: [&str; 3] = [
    "application/json",
    "application/x-ndjson",
    "application/jsonl",
];

/// Whether the request's `Content-Type` is one of [`JSON_TYPES`] (parameters such as
/// `charset` aside); else the 415 that says which to send.
pub(super) fn require_json(headers: &HeaderMap) -> Result<(), ApiError> {
    let given = headers
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok());
    let essence = given
        .and_then(|v| v.split(';').next())
        .map(|v| v.trim().to_ascii_lowercase());
    if essence.as_deref().is_some_and(|e| JSON_TYPES.contains(&e)) {
        return Ok(());
    }
    Err(ApiError::new(
        StatusCode::UNSUPPORTED_MEDIA_TYPE,
        format!(
            "send the body as Content-Type: application/json (or application/x-ndjson for \
             JSON Lines); got {}",
            given.map_or("no Content-Type".to_string(), |g| format!("{g:?}"))
        ),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn loopback_names_and_allowed_hosts_pass_others_do_not() {
        let rules = BrowserRules {
            check_host: true,
            allowed_hosts: vec!["robot.lan".into(), ".fleet.example:8080".into()],
            allowed_origins: vec![],
        };
        for ok in [
            "127.0.0.1:8080",
            "127.1.2.3",
            "localhost:8080",
            "LOCALHOST",
            "map.localhost:80",
            "[::1]:8080",
            "robot.lan:8080",
            "fleet.example",
            "a.fleet.example:1",
        ] {
            assert!(rules.host_allowed(ok), "{ok}");
        }
        for bad in [
            "attacker.example",
            "attacker.example:8080",
            "localhost.attacker.example",
            "128.0.0.1",
            "[::2]:8080",
            "notfleet.example",
            "robot.lan.attacker.example",
        ] {
            assert!(!rules.host_allowed(bad), "{bad}");
        }
    }

    #[test]
    fn writes_from_other_origins_are_refused_unless_named() {
        let rules = BrowserRules {
            check_host: true,
            allowed_hosts: vec![],
            allowed_origins: vec!["http://dash.lan:3000/".into()],
        };
        let headers = |pairs: &[(&'static str, &str)]| {
            let mut h = HeaderMap::new();
            for (k, v) in pairs {
                h.insert(*k, HeaderValue::from_str(v).expect("header value"));
            }
            h
        };
        let host = Some("127.0.0.1:8080");
        // Not a browser page: curl, a robot.
        assert!(write_allowed(&rules, &headers(&[]), host).is_ok());
        // The map's own origin.
        let own = headers(&[
            ("origin", "http://127.0.0.1:8080"),
            ("sec-fetch-site", "same-origin"),
        ]);
        assert!(write_allowed(&rules, &own, host).is_ok());
        // Another origin, by Origin or by Sec-Fetch-Site alone.
        let other = headers(&[("origin", "http://attacker.example")]);
        let e = write_allowed(&rules, &other, host).expect_err("cross-origin");
        assert!(
            e.contains("attacker.example") && e.contains("--http-allowed-origin"),
            "{e}"
        );
        let port = headers(&[("origin", "http://127.0.0.1:9999")]);
        assert!(
            write_allowed(&rules, &port, host).is_err(),
            "another port is another origin"
        );
        let null = headers(&[("origin", "null")]);
        assert!(write_allowed(&rules, &null, host).is_err());
        let site = headers(&[("sec-fetch-site", "cross-site")]);
        assert!(write_allowed(&rules, &site, host).is_err());
        let same_site = headers(&[("sec-fetch-site", "same-site")]);
        assert!(write_allowed(&rules, &same_site, host).is_err());
        // A named origin.
        let named = headers(&[
            ("origin", "http://dash.lan:3000"),
            ("sec-fetch-site", "cross-site"),
        ]);
        assert!(write_allowed(&rules, &named, host).is_ok());
    }

    #[test]
    fn json_bodies_need_a_json_content_type() {
        let with = |v: &str| {
            let mut h = HeaderMap::new();
            h.insert(
                header::CONTENT_TYPE,
                HeaderValue::from_str(v).expect("value"),
            );
            h
        };
        assert!(require_json(&with("application/json")).is_ok());
        assert!(require_json(&with("Application/JSON; charset=utf-8")).is_ok());
        assert!(require_json(&with("application/x-ndjson")).is_ok());
        for bad in [
            "text/plain",
            "application/x-www-form-urlencoded",
            "multipart/form-data",
        ] {
            let e = require_json(&with(bad)).expect_err(bad);
            assert_eq!(e.status, StatusCode::UNSUPPORTED_MEDIA_TYPE);
            assert!(e.message.contains(bad), "{}", e.message);
        }
        assert!(require_json(&HeaderMap::new())
            .expect_err("none")
            .message
            .contains("no Content-Type"));
    }

    #[test]
    fn the_page_policy_hashes_its_script_and_style() {
        let csp = page_policy("<style>a{}</style><p>x</p><script>go()</script>");
        assert!(
            csp.contains(&format!("script-src 'sha256-{}'", sha256_base64("go()"))),
            "{csp}"
        );
        assert!(
            csp.contains(&format!("style-src 'sha256-{}'", sha256_base64("a{}"))),
            "{csp}"
        );
        assert!(csp.contains("frame-ancestors 'none'") && !csp.contains("unsafe"));
        // The SHA-256 of "abc" (FIPS 180-2, appendix B.1), as base64.
        assert_eq!(
            sha256_base64("abc"),
            "ungWv48Bz+pBQUDeXa4iI7ADYaOWF3qctBD/YfIAFa0="
        );
    }
}
