//! Faults injected over HTTP into a running `llrp-gateway sim`, seen by real clients over
//! TCP: the project's LLRP client sees an antenna unplugged and plugged back (AntennaEvent,
//! AntennaConnected), the report buffer held full (ReportBufferLevelWarningEvent, then
//! ReportBufferOverflowErrorEvent, then reports again) and its connection dropped (a reset,
//! no ConnectionCloseEvent); `llrp-gateway inventory` rides out a reboot (refused while the
//! reader boots, reconnected and reading after); the route's errors name the field and
//! `/metrics` counts every fault.

mod http_support;

use std::net::SocketAddr;
use std::time::{Duration, Instant};

use http_support::{request, Proc, PATIENCE};
use llrp::enums::*;
use llrp::message::*;
use llrp::params::*;
use llrp::{Message, MessageBody};
use llrp_gateway::net::client::{Client, ClientError};

/// Generous wait for one message.
const T: Duration = Duration::from_secs(10);

/// `POST /api/readers/{reader}/faults` with `body`: (status, body).
fn post_fault(http: SocketAddr, reader: &str, body: &str) -> (u16, String) {
    let r = request(
        http,
        "POST",
        &format!("/api/readers/{reader}/faults"),
        &[("Content-Type", "application/json")],
        body.as_bytes(),
    );
    (r.status, String::from_utf8_lossy(&r.body).into_owned())
}

/// Injects `body` into the S1 reader; it must be accepted.
fn inject(http: SocketAddr, body: &str) {
    let (status, text) = post_fault(http, "s1-reader", body);
    assert_eq!(status, 202, "{body}: {text}");
}

fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("a runtime")
}

/// The event data of a READER_EVENT_NOTIFICATION.
fn event(m: &Message) -> Option<&ReaderEventNotificationData> {
    match &m.body {
        MessageBody::ReaderEventNotification(n) => Some(&n.reader_event_notification_data),
        _ => None,
    }
}

/// The AntennaEvent of `m`, as (connected, antenna).
fn antenna_event(m: &Message) -> Option<(bool, u16)> {
    let a = event(m)?.antenna_event.as_ref()?;
    Some((
        a.event_type == AntennaEventType::AntennaConnected,
        a.antenna_id,
    ))
}

/// Turns on the notifications of `types`.
async fn enable_events(c: &mut Client, types: &[NotificationEventType]) {
    let set = SetReaderConfig {
        reader_event_notification_spec: Some(ReaderEventNotificationSpec {
            event_notification_state: (types.iter())
                .map(|&t| EventNotificationState {
                    event_type: t,
                    notification_state: true,
                    ..Default::default()
                })
                .collect(),
            ..Default::default()
        }),
        ..Default::default()
    };
    c.check(set, T).await.expect("SET_READER_CONFIG succeeds");
}

/// AntennaProperties.AntennaConnected of antenna 1.
async fn antenna_1_connected(c: &mut Client) -> bool {
    let get = GetReaderConfig {
        requested_data: ConfigRequest::AntennaProperties,
        antenna_id: 1,
        ..Default::default()
    };
    let r = c.check(get, T).await.expect("GET_READER_CONFIG succeeds");
    r.antenna_properties[0].antenna_connected
}

/// What a client sees of the buffer held full: the kinds of message in order, from the
/// warning on, up to and including the first report after the overflow.
async fn through_a_full_buffer(c: &mut Client) -> Vec<&'static str> {
    let mut seen = Vec::new();
    let until = Instant::now() + PATIENCE;
    while Instant::now() < until {
        let m = c.recv(T).await.expect("messages keep coming");
        let kind = match (&m.body, event(&m)) {
            (_, Some(e)) if e.report_buffer_level_warning_event.is_some() => "warning",
            (_, Some(e)) if e.report_buffer_overflow_error_event.is_some() => "overflow",
            (MessageBody::RoAccessReport(_), _) => "report",
            _ => continue,
        };
        if seen.is_empty() && kind == "report" {
            continue; // reports sent before the fault
        }
        if seen.last() != Some(&kind) {
            seen.push(kind);
        }
        if kind == "report" {
            return seen;
        }
    }
    panic!("reports never resumed: {seen:?}");
}

#[test]
fn a_client_sees_an_antenna_unplugged_a_full_buffer_and_its_connection_dropped() {
    let (mut sim, http) = Proc::sim(&[]);
    let llrp = sim.address("listening on ");
    let rt = runtime();
    rt.block_on(async {
        let mut c = Client::connect_reader(&llrp, T).await.expect("connects");
        c.answer_keepalives(true);
        enable_events(
            &mut c,
            &[
                NotificationEventType::AntennaEvent,
                NotificationEventType::ReportBufferFillWarning,
            ],
        )
        .await;

        inject(http, r#"{"fault": "antenna_disconnect", "antenna": 1}"#);
        let m = c.wait_for(|m| antenna_event(m).is_some(), T).await;
        assert_eq!(m.ok().as_ref().and_then(antenna_event), Some((false, 1)));
        assert!(!antenna_1_connected(&mut c).await);
        inject(http, r#"{"fault": "antenna_reconnect", "antenna": 1}"#);
        let m = c.wait_for(|m| antenna_event(m).is_some(), T).await;
        assert_eq!(m.ok().as_ref().and_then(antenna_event), Some((true, 1)));
        assert!(antenna_1_connected(&mut c).await);

        c.add_rospec(RoSpec::immediate(1, vec![0]), T)
            .await
            .expect("added");
        c.enable_rospec(1, T).await.expect("enabled");
        c.wait_for(|m| matches!(m.body, MessageBody::RoAccessReport(_)), T)
            .await
            .expect("reads");
        inject(http, r#"{"fault": "fill_report_buffer", "for_ms": 1500}"#);
        assert_eq!(
            through_a_full_buffer(&mut c).await,
            ["warning", "overflow", "report"],
            "warned, overflowed, then reports again once the buffer drains"
        );

        inject(http, r#"{"fault": "drop_connection"}"#);
        let end = loop {
            match c.recv(T).await {
                Ok(m) => assert!(!m.body.is_connection_close(), "no ConnectionCloseEvent"),
                Err(e) => break e,
            }
        };
        assert!(
            matches!(&end, ClientError::Io(e) if e.kind() == std::io::ErrorKind::ConnectionReset),
            "a reset: {end:?}"
        );
        // The reader is still there: a new connection is greeted at once.
        Client::connect_reader(&llrp, T).await.expect("reconnects");
    });
    let reasons = sim.lines_with("fault injected", 4);
    assert_eq!(reasons.len(), 4, "each fault is logged: {reasons:?}");
    assert!(
        !sim.lines_with("reports (", 1).is_empty(),
        "the lost reports are logged"
    );
    let metrics = request(http, "GET", "/metrics", &[], b"").text();
    for fault in [
        "antenna_disconnect",
        "antenna_reconnect",
        "fill_report_buffer",
        "drop_connection",
    ] {
        let line = format!("llrp_gateway_faults_total{{reader=\"s1-reader\",fault=\"{fault}\"}} 1");
        assert!(metrics.lines().any(|l| l == line), "{line}\n{metrics}");
    }
    assert!(sim.stop().success());
}

#[test]
fn the_faults_route_names_what_is_wrong() {
    let (mut sim, http) = Proc::sim(&[]);
    sim.address("listening on ");
    let cases = [
        (
            "s1-reader",
            r#"{"fault": "meltdown"}"#,
            400,
            "fault: unknown variant `meltdown`",
        ),
        (
            "s1-reader",
            r#"{"antenna": 1}"#,
            400,
            "fault: missing field `fault`",
        ),
        (
            "s1-reader",
            r#"{"fault": "antenna_disconnect", "antenna": 9}"#,
            400,
            "antenna: must be an antenna port in [1, 1], got 9",
        ),
        (
            "s1-reader",
            r#"{"fault": "delay_responses", "ms": 0}"#,
            400,
            "ms: must be in [1, 3600000] ms, got 0",
        ),
        (
            "s1-reader",
            r#"{"fault": "reboot", "boot": 1}"#,
            400,
            "boot: unknown field `boot`",
        ),
        (
            "s1-reader",
            r#"{"fault": "lose_keepalives", "count": "three"}"#,
            400,
            "count: invalid type",
        ),
        (
            "nobody",
            r#"{"fault": "drop_connection"}"#,
            404,
            "no reader named",
        ),
    ];
    for (reader, body, status, says) in cases {
        let (got, text) = post_fault(http, reader, body);
        assert_eq!(got, status, "{reader} {body}: {text}");
        assert!(text.contains(says), "{reader} {body}: {text}");
    }
    let r = request(
        http,
        "POST",
        "/api/readers/s1-reader/faults",
        &[("Content-Type", "text/plain")],
        br#"{"fault": "drop_connection"}"#,
    );
    assert_eq!(r.status, 415);
    let metrics = request(http, "GET", "/metrics", &[], b"").text();
    assert!(
        !metrics.contains("llrp_gateway_faults_total{"),
        "nothing refused is counted:\n{metrics}"
    );
    assert!(sim.stop().success());
}

/// Whole lines in the file so far (0 if it does not exist yet).
fn whole_lines(path: &std::path::Path) -> usize {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    text.matches('\n').count()
}

/// Waits (at most [`PATIENCE`]) until the reads file holds at least `n` whole lines.
fn wait_for_reads(path: &std::path::Path, n: usize) {
    let until = Instant::now() + PATIENCE;
    while whole_lines(path) < n {
        assert!(Instant::now() < until, "{n} reads did not arrive");
        std::thread::sleep(Duration::from_millis(50));
    }
}

#[test]
fn llrp_gateway_inventory_rides_out_a_reboot_refused_while_booting_then_reading_again() {
    let (mut sim, http) = Proc::sim(&[]);
    let llrp = sim.address("listening on ");
    let dir = tempfile::tempdir().expect("a temporary directory");
    let path = dir.path().join("reads.jsonl");
    let out = path.to_str().expect("UTF-8").to_string();
    let mut inv = Proc::spawn(&[
        "inventory",
        &llrp,
        "--retries",
        "forever",
        "--backoff-ms",
        "100",
        "--backoff-max-ms",
        "300",
        "--output",
        &out,
    ]);
    wait_for_reads(&path, 1);
    inject(http, r#"{"fault": "reboot", "boot_ms": 4000}"#);
    // The reader stops listening: a connection is refused (not accepted and left hanging).
    let until = Instant::now() + PATIENCE;
    loop {
        match std::net::TcpStream::connect(&llrp) {
            Err(e) if e.kind() == std::io::ErrorKind::ConnectionRefused => break,
            _ => assert!(Instant::now() < until, "never refused"),
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let lost = inv.lines_with("reconnecting in", 1);
    assert_eq!(lost.len(), 1, "the client noticed: {lost:?}");
    let before = whole_lines(&path);
    let started = inv.lines_with("inventory started", 2);
    assert_eq!(
        started.len(),
        2,
        "connected again after the boot: {started:?}"
    );
    wait_for_reads(&path, before + 1);
    assert_eq!(sim.lines_with("listening again", 1).len(), 1);
    let metrics = request(http, "GET", "/metrics", &[], b"").text();
    let line = "llrp_gateway_faults_total{reader=\"s1-reader\",fault=\"reboot\"} 1";
    assert!(metrics.lines().any(|l| l == line), "{metrics}");
    assert!(inv.stop().success());
    assert!(sim.stop().success());
}

/// The faults the test above does not inject, over HTTP into a running sim: a client still
/// gets its answer while responses are delayed, stays connected while keepalives are lost,
/// and hears of a reader exception; each fault is logged and counted on `/metrics`.
#[test]
fn delayed_responses_lost_keepalives_and_an_exception_are_seen_logged_and_counted() {
    let (mut sim, http) = Proc::sim(&[]);
    let llrp = sim.address("listening on ");
    let rt = runtime();
    rt.block_on(async {
        let mut c = Client::connect_reader(&llrp, T).await.expect("connects");
        c.answer_keepalives(true);
        enable_events(&mut c, &[NotificationEventType::ReaderExceptionEvent]).await;

        inject(
            http,
            r#"{"fault": "delay_responses", "ms": 300, "for_ms": 2000}"#,
        );
        c.check(GetReaderCapabilities::default(), T)
            .await
            .expect("answered, late");
        inject(http, r#"{"fault": "lose_keepalives", "count": 2}"#);
        inject(
            http,
            r#"{"fault": "reader_exception", "message": "RF synthesizer unlocked"}"#,
        );
        let m = c
            .wait_for(
                |m| event(m).is_some_and(|e| e.reader_exception_event.is_some()),
                T,
            )
            .await
            .expect("the exception event");
        let said = event(&m).and_then(|e| e.reader_exception_event.as_ref());
        assert_eq!(
            said.map(|e| e.message.as_str()),
            Some("RF synthesizer unlocked")
        );
        // Still connected: the reader answers.
        c.check(GetReaderCapabilities::default(), T)
            .await
            .expect("still connected");
    });
    let reasons = sim.lines_with("fault injected", 3);
    assert_eq!(reasons.len(), 3, "each fault is logged: {reasons:?}");
    let metrics = request(http, "GET", "/metrics", &[], b"").text();
    for fault in ["delay_responses", "lose_keepalives", "reader_exception"] {
        let line = format!("llrp_gateway_faults_total{{reader=\"s1-reader\",fault=\"{fault}\"}} 1");
        assert!(metrics.lines().any(|l| l == line), "{line}\n{metrics}");
    }
    assert!(sim.stop().success());
}
