//! A client that stops reading gets a bounded report buffer, as from a reader: `llrp-gateway
//! sim` on a crowded dock door (300 tags, 4 antennas) at 100 times real time, a client whose
//! ROSpec reports every read, which then reads nothing for 6 s (10 simulated minutes). The
//! simulator's memory stays within the stated bound, and when the client reads again it finds
//! the ReportBufferLevelWarningEvent it enabled, the ReportBufferOverflowErrorEvent LLRP
//! defines, then reports again.

mod http_support;

use std::io::{Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};

use http_support::Proc;
use llrp::enums::RoReportTriggerType;
use llrp::message::*;
use llrp::params::*;
use llrp::Message;

/// The dock door of `fixtures/scenarios/dock-door.json` with 300 tags on its pallets.
fn crowded(dir: &std::path::Path) -> std::path::PathBuf {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/fixtures/scenarios/dock-door.json"
    );
    let mut s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).expect("reads")).expect("JSON");
    let tags: Vec<serde_json::Value> = (0..300)
        .map(|i| {
            serde_json::json!({
                "epc": format!("3034F8A2C0DE00000001{i:04X}"),
                "position": [1.5 + (i % 10) as f64 * 0.3, 1.5 + (i / 10 % 10) as f64 * 0.3, 0.3 + (i / 100) as f64 * 0.5],
            })
        })
        .collect();
    s["tags"] = serde_json::Value::Array(tags);
    let out = dir.join("crowded.json");
    std::fs::write(&out, serde_json::to_string(&s).expect("JSON")).expect("writes");
    out
}

fn read_message(s: &mut TcpStream) -> Message {
    let mut h = [0u8; 10];
    s.read_exact(&mut h).expect("a header");
    let len = u32::from_be_bytes([h[2], h[3], h[4], h[5]]) as usize;
    let mut frame = h.to_vec();
    frame.resize(len, 0);
    s.read_exact(&mut frame[10..]).expect("a body");
    Message::decode(&frame).expect("decodes")
}

fn request(s: &mut TcpStream, id: u32, body: impl Into<MessageBody>) {
    s.write_all(&Message::new(id, body).to_bytes())
        .expect("sends");
    loop {
        let m = read_message(s);
        if m.id == id && m.body.status().is_some() {
            assert_eq!(
                m.body.status().map(|st| st.status_code),
                Some(llrp::StatusCode::M_Success),
                "{m:?}"
            );
            return;
        }
    }
}

/// VmRSS of process `pid`, KiB.
fn rss_kib(pid: u32) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).expect("proc status");
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .expect("VmRSS")
}

/// The stated bound on what a stalled client may add to the simulator's memory: the 1 MiB
/// report buffer, with room for the allocator and the physics' own working set.
const BOUND_KIB: u64 = 24 * 1024;

#[test]
fn a_client_that_stops_reading_gets_a_bounded_buffer_and_the_overflow_event() {
    let dir = tempfile::tempdir().expect("temp dir");
    let scenario = crowded(dir.path());
    let mut sim = Proc::spawn(&[
        "sim",
        "--no-http",
        "--scenario",
        scenario.to_str().expect("utf-8"),
        "--listen",
        "127.0.0.1:0",
        "--speed",
        "100",
    ]);
    let addr = sim.address("listening on ");
    let mut s = TcpStream::connect(&addr).expect("connects");
    s.set_read_timeout(Some(Duration::from_secs(20)))
        .expect("timeout");
    let _ = read_message(&mut s);
    let warnings = SetReaderConfig {
        reader_event_notification_spec: Some(ReaderEventNotificationSpec {
            event_notification_state: vec![EventNotificationState {
                event_type: llrp::enums::NotificationEventType::ReportBufferFillWarning,
                notification_state: true,
                ..Default::default()
            }],
            ..Default::default()
        }),
        ..Default::default()
    };
    request(&mut s, 1, warnings);
    let spec = RoSpec::immediate(1, vec![0]).with_report(
        RoReportSpec::new(RoReportTriggerType::UponNTagsOrEndOfAiSpec, 1)
            .with_content(TagReportContentSelector::all()),
    );
    request(
        &mut s,
        2,
        AddRospec {
            ro_spec: spec,
            ..Default::default()
        },
    );
    request(
        &mut s,
        3,
        EnableRospec {
            ro_spec_id: 1,
            ..Default::default()
        },
    );
    // Reports flow; then the client reads nothing for 6 s.
    let mut reports = 0;
    while reports < 100 {
        if matches!(read_message(&mut s).body, MessageBody::RoAccessReport(_)) {
            reports += 1;
        }
    }
    let before = rss_kib(sim.pid());
    let mut most = before;
    let stall = Instant::now();
    while stall.elapsed() < Duration::from_secs(6) {
        std::thread::sleep(Duration::from_millis(250));
        most = most.max(rss_kib(sim.pid()));
    }
    assert!(
        most - before < BOUND_KIB,
        "the simulator grew by {} KiB while the client did not read (bound {BOUND_KIB} KiB)",
        most - before
    );
    // Reading again: the buffered reports, the warning (the client enabled it), then the
    // overflow event, then reports again.
    let deadline = Instant::now() + Duration::from_secs(60);
    let mut warned = false;
    let mut overflow = false;
    let mut after = 0;
    while after < 10 {
        assert!(Instant::now() < deadline, "no overflow event, then reports");
        let m = read_message(&mut s);
        match &m.body {
            MessageBody::ReaderEventNotification(n)
                if n.reader_event_notification_data
                    .report_buffer_overflow_error_event
                    .is_some() =>
            {
                assert!(warned, "the ReportBufferLevelWarningEvent came first");
                overflow = true
            }
            MessageBody::ReaderEventNotification(n)
                if n.reader_event_notification_data
                    .report_buffer_level_warning_event
                    .is_some() =>
            {
                warned = true
            }
            MessageBody::RoAccessReport(_) if overflow => after += 1,
            _ => {}
        }
    }
    drop(s);
    let _ = sim.stop();
}
