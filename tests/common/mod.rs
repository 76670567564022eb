//! Shared helpers for the loopback tests: start the simulator, build requests.
#![allow(dead_code)]

use std::time::Duration;

use llrp::message::*;
use llrp::params::*;
use llrp::Message;
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

/// Connects and checks the greeting (ConnectionAttemptEvent Success).
pub async fn connect(sim: &RunningSim) -> Client {
    let mut c = Client::connect(sim.addrs[0]).await.expect("connects");
    let m = c.recv(T).await.expect("greeting");
    assert_eq!(connection_status(&m), Some(0), "greeting: {m:?}");
    c
}

/// The ConnectionAttemptEvent status in a message, if it carries one.
pub fn connection_status(m: &Message) -> Option<u16> {
    match &m.body {
        MessageBody::ReaderEventNotification(n) => n
            .reader_event_notification_data
            .connection_attempt_event
            .as_ref()
            .map(|e| e.status),
        _ => None,
    }
}

/// The LLRPStatus of a response.
pub fn status(m: &Message) -> LlrpStatus {
    let s = match &m.body {
        MessageBody::AddRospecResponse(r) => &r.llrp_status,
        MessageBody::DeleteRospecResponse(r) => &r.llrp_status,
        MessageBody::StartRospecResponse(r) => &r.llrp_status,
        MessageBody::StopRospecResponse(r) => &r.llrp_status,
        MessageBody::EnableRospecResponse(r) => &r.llrp_status,
        MessageBody::DisableRospecResponse(r) => &r.llrp_status,
        MessageBody::GetRospecsResponse(r) => &r.llrp_status,
        MessageBody::AddAccessspecResponse(r) => &r.llrp_status,
        MessageBody::DeleteAccessspecResponse(r) => &r.llrp_status,
        MessageBody::EnableAccessspecResponse(r) => &r.llrp_status,
        MessageBody::DisableAccessspecResponse(r) => &r.llrp_status,
        MessageBody::GetReaderCapabilitiesResponse(r) => &r.llrp_status,
        MessageBody::GetReaderConfigResponse(r) => &r.llrp_status,
        MessageBody::SetReaderConfigResponse(r) => &r.llrp_status,
        MessageBody::CloseConnectionResponse(r) => &r.llrp_status,
        MessageBody::ErrorMessage(r) => &r.llrp_status,
        MessageBody::ImpinjEnableExtensionsResponse(r) => &r.llrp_status,
        MessageBody::GetSupportedVersionResponse(r) => &r.llrp_status,
        MessageBody::SetProtocolVersionResponse(r) => &r.llrp_status,
        other => panic!("no status in {}", other.name()),
    };
    s.clone()
}

/// Sends a request and returns its response's status code.
pub async fn request_status(c: &mut Client, body: impl Into<MessageBody>) -> u16 {
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
    RoSpec {
        ro_spec_id: id,
        priority: 0,
        current_state: 0,
        ro_boundary_spec: RoBoundarySpec {
            ro_spec_start_trigger: RoSpecStartTrigger {
                ro_spec_start_trigger_type: 1,
                ..Default::default()
            },
            ro_spec_stop_trigger: ro_stop,
            ..Default::default()
        },
        specs: vec![SpecParameter::AiSpec(AiSpec {
            antenna_ids: antennas,
            ai_spec_stop_trigger: ai_stop,
            inventory_parameter_specs: vec![InventoryParameterSpec {
                inventory_parameter_spec_id: 1,
                protocol_id: 1,
                ..Default::default()
            }],
            ..Default::default()
        })],
        ro_report_spec: Some(report),
        ..Default::default()
    }
}

/// A report spec with trigger `trigger`, N = `n`, every standard field and the Impinj ones.
pub fn full_report(trigger: u8, n: u16) -> RoReportSpec {
    RoReportSpec {
        ro_report_trigger: trigger,
        n,
        tag_report_content_selector: TagReportContentSelector {
            enable_ro_spec_id: true,
            enable_spec_index: true,
            enable_inventory_parameter_spec_id: true,
            enable_antenna_id: true,
            enable_channel_index: true,
            enable_peak_rssi: true,
            enable_first_seen_timestamp: true,
            enable_last_seen_timestamp: true,
            enable_tag_seen_count: true,
            enable_access_spec_id: true,
            ..Default::default()
        },
        custom: vec![Custom::ImpinjTagReportContentSelector(Box::new(
            ImpinjTagReportContentSelector {
                enable_rf_phase_angle: Some(ImpinjEnableRfPhaseAngle {
                    rf_phase_angle_mode: 1,
                    ..Default::default()
                }),
                enable_peak_rssi: Some(ImpinjEnablePeakRssi {
                    peak_rssi_mode: 1,
                    ..Default::default()
                }),
                enable_rf_doppler_frequency: Some(ImpinjEnableRfDopplerFrequency {
                    rf_doppler_frequency_mode: 1,
                    ..Default::default()
                }),
                ..Default::default()
            },
        ))],
        ..Default::default()
    }
}

/// A duration stop trigger for the ROSpec.
pub fn ro_duration(ms: u32) -> RoSpecStopTrigger {
    RoSpecStopTrigger {
        ro_spec_stop_trigger_type: 1,
        duration_trigger_value: ms,
        ..Default::default()
    }
}

/// A Null stop trigger for the ROSpec.
pub fn ro_null() -> RoSpecStopTrigger {
    RoSpecStopTrigger::default()
}

/// A duration stop trigger for the AISpec.
pub fn ai_duration(ms: u32) -> AiSpecStopTrigger {
    AiSpecStopTrigger {
        ai_spec_stop_trigger_type: 1,
        duration_trigger: ms,
        ..Default::default()
    }
}

/// A Null stop trigger for the AISpec.
pub fn ai_null() -> AiSpecStopTrigger {
    AiSpecStopTrigger::default()
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
  "readers": [{{
    "name": "r",
    "listen": "127.0.0.1:0",
    "region": "etsi",
    "fixed_channel": 1,
    "reads_per_second": 600,
    "antennas": [{{
      "mount": {{ "type": "fixed", "pose": {{ "position": [0, 0, 1], "yaw_deg": 0, "pitch_deg": 0 }} }},
      "gain_dbi": 6,
      "beamwidth_deg": 70,
      "tx_power_dbm": 30,
      "cable_loss_db": 1,
      "phase_offset_rad": [0, 0, 0, 0],
      "phase_sign": 1,
      "phase_noise_rad": 0,
      "rssi_noise": 0,
      "range_m": 7,
      "range_sigma": 0
    }}]
  }}]
}}"#,
        tags = tags.join(",")
    );
    Scenario::from_json(&json).expect("test scenario is valid")
}
