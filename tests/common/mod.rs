//! Shared helpers for the loopback tests: start the simulator, build requests.
#![allow(dead_code)]

pub mod virtual_reader;

use std::time::Duration;

pub use llrp::enums::*;
use llrp::message::*;
use llrp::params::*;
use llrp::Message;
pub use llrp::StatusCode;
use llrp_gateway::net::client::Client;
use llrp_gateway::net::clock::Speed;
use llrp_gateway::scenario::Scenario;
use llrp_gateway::sim::{self, RunningSim, SimOptions};

/// Generous wait for one response over loopback.
pub const T: Duration = Duration::from_secs(10);

/// The embedded default scenario with its readers on ephemeral ports.
pub fn s1() -> Scenario {
    let mut s = Scenario::default_s1();
    for r in &mut s.readers {
        r.listen = "127.0.0.1:0".into();
    }
    s
}

/// [`s1`] on the `ideal` reader model (S1's own is `impinj-r420`): clean reads, for what the
/// localizer's pipeline does when the phase holds no hardware error.
#[allow(dead_code)]
pub fn s1_ideal() -> Scenario {
    let mut s = Scenario::default_s1_with(Some("ideal")).expect("the embedded S1 is valid");
    for r in &mut s.readers {
        r.listen = "127.0.0.1:0".into();
    }
    s
}

/// Starts the simulator for `scenario` at `speed`.
pub async fn start(scenario: &Scenario, speed: Speed) -> RunningSim {
    sim::start(
        scenario,
        &SimOptions {
            speed,
            ..Default::default()
        },
    )
    .await
    .expect("simulator starts")
}

/// Connects and checks the greeting (ConnectionAttemptEvent Success): the client's own
/// handshake.
pub async fn connect(sim: &RunningSim) -> Client {
    Client::connect_reader(sim.addrs[0], T)
        .await
        .expect("connects and is greeted with Success")
}

/// The ConnectionAttemptEvent status in a message, if it carries one.
pub fn connection_status(m: &Message) -> Option<ConnectionAttemptStatus> {
    m.body.connection_attempt()
}

/// The LLRPStatus of a response (or ERROR_MESSAGE).
pub fn status(m: &Message) -> LlrpStatus {
    match m.body.status() {
        Some(s) => s.clone(),
        None => panic!("no status in {}", m.name()),
    }
}

/// Sends a request and returns its response's status code.
pub async fn request_status(c: &mut Client, body: impl Into<MessageBody>) -> StatusCode {
    let r = c.request(body, T).await.expect("response");
    status(&r).status_code
}

/// An ROSpec like sllurp's: Immediate start, the given stop triggers and report spec.
pub fn rospec(
    id: u32,
    antennas: Vec<u16>,
    ro_stop: RoSpecStopTrigger,
    ai_stop: AiSpecStopTrigger,
    report: RoReportSpec,
) -> RoSpec {
    RoSpec::immediate(id, antennas)
        .with_stop(ro_stop)
        .with_ai_stop(ai_stop)
        .with_report(report)
}

/// A report spec with trigger `trigger`, N = `n`, every standard field and the Impinj ones.
pub fn full_report(trigger: RoReportTriggerType, n: u16) -> RoReportSpec {
    RoReportSpec::new(trigger, n)
        .with_content(TagReportContentSelector::all())
        .with_impinj(true, true, true)
}

/// A duration stop trigger for the ROSpec.
pub fn ro_duration(ms: u32) -> RoSpecStopTrigger {
    RoSpecStopTrigger::duration(ms)
}

/// A Null stop trigger for the ROSpec.
pub fn ro_null() -> RoSpecStopTrigger {
    RoSpecStopTrigger::null()
}

/// A duration stop trigger for the AISpec.
pub fn ai_duration(ms: u32) -> AiSpecStopTrigger {
    AiSpecStopTrigger::duration(ms)
}

/// A Null stop trigger for the AISpec.
pub fn ai_null() -> AiSpecStopTrigger {
    AiSpecStopTrigger::null()
}

/// Collects the TagReportData of every RO_ACCESS_REPORT until `pred` says stop or `limit`
/// passes; other messages are returned separately.
pub async fn collect_reports(
    c: &mut Client,
    limit: Duration,
    mut done: impl FnMut(&[TagReportData]) -> bool,
) -> (Vec<TagReportData>, Vec<Message>) {
    let deadline = tokio::time::Instant::now() + limit;
    let mut tags = Vec::new();
    let mut others = Vec::new();
    while !done(&tags) {
        let left = deadline.saturating_duration_since(tokio::time::Instant::now());
        if left.is_zero() {
            break;
        }
        match c.recv(left).await {
            Ok(m) => match m.body {
                MessageBody::RoAccessReport(r) => tags.extend(r.tag_report_data),
                _ => others.push(m),
            },
            Err(_) => break,
        }
    }
    (tags, others)
}

/// One fixed antenna at the origin looking along +x, noise-free, on ETSI channel 1, and tags
/// on the boresight at the given distances (EPCs E200…01, E200…02, … in that order).
pub fn line_scenario(distances: &[f64]) -> Scenario {
    let tags: Vec<String> = distances
        .iter()
        .enumerate()
        .map(|(i, d)| {
            format!(
                r#"{{"epc": "E200000000000000000000{:02X}", "position": [{d}, 0, 1]}}"#,
                i + 1
            )
        })
        .collect();
    let json = format!(
        r#"{{
  "name": "line",
  "seed": 5,
  "world": {{ "min": [-5, -5, 0], "max": [60, 5, 3] }},
  "tags": [{tags}],
  "tag_variation": {{ "sensitivity_sigma_db": 0, "backscatter_sigma_db": 0 }},
  "readers": [{{
    "name": "r",
    "listen": "127.0.0.1:0",
    "region": "etsi",
    "fixed_channel": 1,
    "antennas": [{{
      "mount": {{ "type": "fixed", "pose": {{ "position": [0, 0, 1], "yaw_deg": 0, "pitch_deg": 0 }} }},
      "gain_dbi": 6,
      "beamwidth_deg": 70,
      "tx_power_dbm": 30,
      "cable_loss_db": 1,
      "phase_offset_rad": [0, 0, 0, 0],
      "phase_sign": 1,
      "phase_noise_rad": 0,
      "rssi_sigma_db": 0,
      "rssi_resolution_db": 0,
      "doppler_sigma_hz": 0,
      "range_m": 7,
      "range_sigma": 0
    }}]
  }}]
}}"#,
        tags = tags.join(",")
    );
    Scenario::from_json(&json).expect("test scenario is valid")
}
