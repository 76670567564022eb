//! The HTTP server against clients that try to hold it open, over loopback: slowloris
//! headers, idle connections (fresh and kept alive), a body declared far over the limit, a
//! stalled body, more connections than the limit; and the order of 401 and 405 with a token.
//! The server under test has short limits (a second) so that each case ends quickly; the
//! binary's defaults are checked by one slowloris run against `sim`.

mod http_support;

use std::io::{BufRead, BufReader, ErrorKind, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::time::{Duration, Instant};

use http_support::{post_poses, request, Proc, Server, PATIENCE};
use llrp_gateway::http::{HttpOptions, ServerLimits};

fn limits() -> ServerLimits {
    ServerLimits {
        header_read: Duration::from_secs(1),
        body_read: Duration::from_secs(1),
        request: Duration::from_secs(5),
        max_connections: 16,
    }
}

fn server(limits: ServerLimits) -> Server {
    Server::start(HttpOptions {
        limits,
        ..HttpOptions::default()
    })
}

fn connect(addr: SocketAddr) -> TcpStream {
    let s = TcpStream::connect(addr).expect("connects");
    s.set_read_timeout(Some(Duration::from_millis(200)))
        .expect("timeout");
    s
}

/// Keeps `streams` busy with `feed` (a write a round, failures ignored) until the server has
/// closed every one of them; panics after [`PATIENCE`]. What each read before its end.
fn until_all_closed(
    streams: &mut [TcpStream],
    mut feed: impl FnMut(&mut TcpStream),
) -> Vec<Vec<u8>> {
    let deadline = Instant::now() + PATIENCE;
    let mut open = vec![true; streams.len()];
    let mut got = vec![Vec::new(); streams.len()];
    let mut buf = [0u8; 4096];
    while open.iter().any(|&o| o) {
        assert!(Instant::now() < deadline, "still open after {PATIENCE:?}");
        for (k, s) in streams.iter_mut().enumerate() {
            if !open[k] {
                continue;
            }
            feed(s);
            match s.read(&mut buf) {
                Ok(0) => open[k] = false,
                Ok(n) => got[k].extend_from_slice(&buf[..n]),
                Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {}
                Err(_) => open[k] = false,
            }
        }
    }
    got
}

/// The status code of the first response in `bytes`.
fn status_of(bytes: &[u8]) -> u16 {
    let text = String::from_utf8_lossy(bytes);
    text.split_whitespace()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("no status line in {text:?}"))
}

fn slowloris(addr: SocketAddr) {
    let mut streams: Vec<TcpStream> = (0..5).map(|_| connect(addr)).collect();
    for s in &mut streams {
        s.write_all(b"GET /api/tags HTTP/1.1\r\nHost: 127.0.0.1\r\n")
            .expect("a start");
    }
    // A header line now and then, never the blank line that ends the head.
    let mut n = 0u64;
    let got = until_all_closed(&mut streams, |s| {
        n += 1;
        let _ = s.write_all(format!("X-Slow-{n}: a\r\n").as_bytes());
    });
    for g in got {
        assert!(
            g.is_empty() || status_of(&g) == 408,
            "no answer but a 408: {}",
            String::from_utf8_lossy(&g)
        );
    }
}

#[test]
fn five_slowloris_connections_are_closed_after_the_header_read_timeout() {
    let s = server(limits());
    slowloris(s.addr);
    // The server still serves.
    assert_eq!(request(s.addr, "GET", "/healthz", &[], b"").status, 200);
}

#[test]
fn sims_own_http_server_closes_slowloris_connections_with_its_defaults() {
    let mut sim = Proc::spawn(&["sim", "--listen", "127.0.0.1:0", "--http", "127.0.0.1:0"]);
    let http: SocketAddr = sim.address("live map on http://").parse().expect("addr");
    slowloris(http);
    assert_eq!(request(http, "GET", "/healthz", &[], b"").status, 200);
}

#[test]
fn an_idle_connection_and_an_idle_keep_alive_connection_are_closed() {
    let s = server(limits());
    // One that never sends a byte, one that asked once and then kept the connection.
    let silent = connect(s.addr);
    let mut kept = connect(s.addr);
    kept.write_all(b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
        .expect("a request");
    let got = until_all_closed(&mut [silent, kept], |_| {});
    assert!(got[0].is_empty(), "{:?}", String::from_utf8_lossy(&got[0]));
    let answer = String::from_utf8_lossy(&got[1]);
    assert!(
        answer.starts_with("HTTP/1.1 200") && answer.ends_with("ok"),
        "the keep-alive request was answered, then the idle connection closed: {answer:?}"
    );
}

#[test]
fn a_body_declared_at_10_gb_gets_413_before_any_of_it_is_sent() {
    let s = server(limits());
    let mut c = TcpStream::connect(s.addr).expect("connects");
    c.set_read_timeout(Some(PATIENCE)).expect("timeout");
    c.write_all(
        b"POST /api/poses HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n\
          Content-Length: 10000000000\r\n\r\n",
    )
    .expect("the head only");
    let mut reader = BufReader::new(c);
    let mut line = String::new();
    reader
        .read_line(&mut line)
        .expect("an answer without a body sent");
    assert!(line.starts_with("HTTP/1.1 413"), "{line:?}");
    let mut rest = String::new();
    let _ = reader.read_to_string(&mut rest);
    assert!(
        rest.to_ascii_lowercase().contains("connection: close"),
        "{rest}"
    );
    assert!(
        rest.contains("10000000000") && rest.contains("limit"),
        "{rest}"
    );
}

#[test]
fn a_body_that_stalls_gets_408_and_the_connection_is_closed() {
    let s = server(limits());
    let mut c = connect(s.addr);
    c.write_all(
        b"POST /api/poses HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n\
          Content-Length: 100\r\n\r\n[{\"t_us\":",
    )
    .expect("a part of the body");
    let got = until_all_closed(&mut [c], |_| {});
    let answer = String::from_utf8_lossy(&got[0]);
    assert_eq!(status_of(&got[0]), 408, "{answer}");
    assert!(answer.contains("stalled"), "{answer}");
}

#[test]
fn connections_past_the_limit_get_503_and_a_freed_one_serves_again() {
    let s = server(ServerLimits {
        header_read: Duration::from_secs(120),
        max_connections: 3,
        ..limits()
    });
    let mut held: Vec<TcpStream> = (0..3).map(|_| connect(s.addr)).collect();
    // The held ones are accepted first (the listen queue is first in, first out).
    let over = request(s.addr, "GET", "/healthz", &[], b"");
    assert_eq!(over.status, 503, "{}", over.text());
    assert!(over.error().contains("limit is 3"), "{}", over.error());
    assert_eq!(over.header("retry-after"), Some("1"));
    // One leaves; its slot serves the next client once the server has seen it go.
    drop(held.pop());
    let deadline = Instant::now() + PATIENCE;
    loop {
        let r = request(s.addr, "GET", "/healthz", &[], b"");
        if r.status == 200 {
            break;
        }
        assert_eq!(r.status, 503, "{}", r.text());
        assert!(Instant::now() < deadline, "the freed slot never served");
        std::thread::sleep(Duration::from_millis(50));
    }
}

#[test]
fn with_a_token_an_unknown_method_gets_401_before_405_and_the_scheme_is_case_insensitive() {
    let s = Server::start(HttpOptions {
        token: Some("s3cret".into()),
        ..HttpOptions::default()
    });
    let r = request(s.addr, "DELETE", "/api/tags", &[], b"");
    assert_eq!(r.status, 401, "{}", r.text());
    let r = request(
        s.addr,
        "DELETE",
        "/api/tags",
        &[("Authorization", "Bearer s3cret")],
        b"",
    );
    assert_eq!(r.status, 405, "{}", r.text());
    let r = post_poses(s.addr, &[("Authorization", "bearer s3cret")], b"[]");
    // Past the token check: the body itself is judged (an empty array is no pose).
    assert_eq!(r.status, 400, "{}", r.text());
    let r = post_poses(s.addr, &[("Authorization", "Basic s3cret")], b"[]");
    assert_eq!(r.status, 401, "{}", r.text());
}
