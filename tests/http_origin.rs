//! What a browser page can do with the HTTP API, tried with raw requests against the real
//! server over loopback: a host name that is not loopback's is refused (DNS rebinding), a write
//! from another origin's page is refused whatever its content type, a JSON body must say it is
//! JSON, the origins a flag names get CORS answers, and every response carries the security
//! headers (the map page its own Content-Security-Policy). `tests/http_browser.rs` tries the
//! same from a page in headless Chromium.

mod http_support;

use http_support::{post_poses, request, Server};
use llrp_gateway::http::{BrowserRules, HttpOptions};

fn pose_body() -> &'static [u8] {
    br#"{"t_us": 1000, "reader": "robot", "antenna": 1, "x": 1, "y": 2, "z": 0.5, "yaw_deg": 90}"#
}

fn accepted_poses(server: &Server) -> u64 {
    server
        .live
        .shared
        .metrics
        .render()
        .lines()
        .find_map(|l| l.strip_prefix("llrp_gateway_poses_total "))
        .and_then(|n| n.parse().ok())
        .expect("llrp_gateway_poses_total")
}

#[test]
fn a_host_name_that_is_not_loopback_is_refused_and_loopback_names_pass() {
    let server = Server::start(HttpOptions::default());
    let port = server.addr.port().to_string();
    for host in [
        "attacker.example".to_string(),
        format!("attacker.example:{port}"),
        format!("localhost.attacker.example:{port}"),
        "10.0.0.5".to_string(),
    ] {
        let r = request(server.addr, "GET", "/api/tags", &[("Host", &host)], b"");
        assert_eq!(r.status, 403, "Host {host}: {}", r.text());
        assert!(
            r.error().contains("--http-allowed-host"),
            "the refusal names the remedy: {}",
            r.text()
        );
    }
    for host in [
        format!("127.0.0.1:{port}"),
        format!("localhost:{port}"),
        format!("[::1]:{port}"),
        "map.localhost".to_string(),
    ] {
        let r = request(server.addr, "GET", "/api/tags", &[("Host", &host)], b"");
        assert_eq!(r.status, 200, "Host {host}: {}", r.text());
    }
    // A rebinding page cannot write either.
    let r = post_poses(server.addr, &[("Host", "attacker.example")], pose_body());
    assert_eq!(r.status, 403);
    assert_eq!(accepted_poses(&server), 0);
}

#[test]
fn a_host_the_flag_names_is_served() {
    let server = Server::start(HttpOptions {
        browser: BrowserRules {
            check_host: true,
            allowed_hosts: vec!["robot.lan".into(), ".fleet.example".into()],
            allowed_origins: vec![],
        },
        ..HttpOptions::default()
    });
    for (host, status) in [
        ("robot.lan:8080", 200),
        ("cell-3.fleet.example", 200),
        ("fleet.example", 200),
        ("robot.lan.attacker.example", 403),
    ] {
        let r = request(server.addr, "GET", "/healthz", &[("Host", host)], b"");
        assert_eq!(r.status, status, "Host {host}");
    }
}

#[test]
fn a_write_from_another_origins_page_is_refused_whatever_its_content_type() {
    let server = Server::start(HttpOptions::default());
    let own = format!("http://{}", server.addr);
    // What a page of another origin can send without a preflight: a "simple" request.
    for (origin, site, ty) in [
        (Some("http://attacker.example"), None, "text/plain"),
        (
            Some("http://attacker.example"),
            Some("cross-site"),
            "application/json",
        ),
        (Some("null"), None, "application/json"),
        (None, Some("cross-site"), "application/json"),
        (None, Some("same-site"), "application/json"),
        (
            Some("http://127.0.0.1:1"),
            Some("same-site"),
            "application/json",
        ),
    ] {
        let mut headers = vec![("Content-Type", ty)];
        if let Some(o) = origin {
            headers.push(("Origin", o));
        }
        if let Some(s) = site {
            headers.push(("Sec-Fetch-Site", s));
        }
        let r = post_poses(server.addr, &headers, pose_body());
        assert_eq!(r.status, 403, "{headers:?}: {}", r.text());
    }
    assert_eq!(
        accepted_poses(&server),
        0,
        "no refused write reached the localizer"
    );
    // A form or a text/plain fetch from the API's own origin is still no JSON.
    let r = post_poses(
        server.addr,
        &[("Origin", &own), ("Content-Type", "text/plain")],
        pose_body(),
    );
    assert_eq!(r.status, 415, "{}", r.text());
    assert!(r.error().contains("application/json"), "{}", r.text());
    let r = post_poses(
        server.addr,
        &[("Content-Type", "application/x-www-form-urlencoded")],
        pose_body(),
    );
    assert_eq!(r.status, 415);
    assert_eq!(accepted_poses(&server), 0);
    // The API's own page, and a client that is no page (curl, a robot), may write.
    let r = post_poses(
        server.addr,
        &[("Origin", &own), ("Sec-Fetch-Site", "same-origin")],
        pose_body(),
    );
    assert_eq!(r.status, 202, "{}", r.text());
    let r = post_poses(
        server.addr,
        &[("Content-Type", "application/x-ndjson")],
        pose_body(),
    );
    assert_eq!(r.status, 202, "{}", r.text());
}

#[test]
fn an_origin_the_flag_names_gets_cors_answers_and_may_write() {
    let dash = "http://dashboard.lan:3000";
    let server = Server::start(HttpOptions {
        browser: BrowserRules {
            check_host: true,
            allowed_hosts: vec![],
            allowed_origins: vec![dash.into()],
        },
        ..HttpOptions::default()
    });
    let preflight = request(
        server.addr,
        "OPTIONS",
        "/api/poses",
        &[
            ("Origin", dash),
            ("Access-Control-Request-Method", "POST"),
            ("Access-Control-Request-Headers", "content-type"),
        ],
        b"",
    );
    assert!(preflight.status < 300, "{}", preflight.status);
    assert_eq!(preflight.header("access-control-allow-origin"), Some(dash));
    let r = post_poses(
        server.addr,
        &[("Origin", dash), ("Sec-Fetch-Site", "cross-site")],
        pose_body(),
    );
    assert_eq!(r.status, 202, "{}", r.text());
    assert_eq!(r.header("access-control-allow-origin"), Some(dash));
    // Any other origin gets no CORS answer and no write.
    let other = request(
        server.addr,
        "OPTIONS",
        "/api/poses",
        &[
            ("Origin", "http://attacker.example"),
            ("Access-Control-Request-Method", "POST"),
        ],
        b"",
    );
    assert_eq!(other.header("access-control-allow-origin"), None);
    let r = post_poses(
        server.addr,
        &[("Origin", "http://attacker.example")],
        pose_body(),
    );
    assert_eq!(r.status, 403);
}

#[test]
fn every_response_carries_the_security_headers_and_the_map_its_policy() {
    let server = Server::start(HttpOptions::default());
    for path in ["/", "/api/tags", "/healthz", "/no/such/route"] {
        let r = request(server.addr, "GET", path, &[], b"");
        assert_eq!(
            r.header("x-content-type-options"),
            Some("nosniff"),
            "{path}"
        );
        assert_eq!(r.header("referrer-policy"), Some("no-referrer"), "{path}");
        assert_eq!(r.header("x-frame-options"), Some("DENY"), "{path}");
        let csp = r.header("content-security-policy").unwrap_or_default();
        assert!(csp.contains("frame-ancestors 'none'"), "{path}: {csp}");
    }
    let page = request(server.addr, "GET", "/", &[], b"");
    let csp = page
        .header("content-security-policy")
        .expect("the map's policy");
    assert!(
        csp.contains("script-src 'sha256-") && !csp.contains("unsafe"),
        "no inline script runs but the page's own: {csp}"
    );
}
