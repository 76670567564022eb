//! The simulator over loopback: every reader of a scenario listens, and the ground truth it
//! writes while a client inventories.

mod common;

use common::*;
use llrp::message::*;
use llrp::params::*;
use llrp_gateway::net::client::Client;
use llrp_gateway::net::clock::Speed;
use llrp_gateway::scenario::{Mount, PoseEstimate, PoseEstimateKind, Scenario};
use llrp_gateway::sim::{self, SimOptions};

/// ENABLE_ROSPEC `id`, which must succeed.
async fn enable(c: &mut Client, id: u32) {
    let enable = EnableRospec {
        ro_spec_id: id,
        ..Default::default()
    };
    assert_eq!(request_status(c, enable).await, StatusCode::M_Success);
}

async fn add(c: &mut Client, spec: RoSpec) {
    let code = request_status(
        c,
        AddRospec {
            ro_spec: spec,
            ..Default::default()
        },
    )
    .await;
    assert_eq!(code, StatusCode::M_Success);
}

#[tokio::test]
async fn ground_truth_is_written_as_jsonl() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("truth.jsonl");
    let scenario = s1();
    let opts = SimOptions {
        speed: Speed::Max,
        truth: Some(path.clone()),
        ..Default::default()
    };
    let sim = sim::start(&scenario, &opts).await.expect("starts");
    let mut c = connect(&sim).await;
    add(
        &mut c,
        rospec(
            1,
            vec![0],
            ro_null(),
            ai_null(),
            full_report(RoReportTriggerType::UponNTagsOrEndOfRoSpec, 1),
        ),
    )
    .await;
    enable(&mut c, 1).await;
    // Until the reads span a simulated second (ten ground-truth intervals).
    let span = |t: &[TagReportData]| {
        let last = t
            .iter()
            .filter_map(|r| r.last_seen_timestamp_utc.map(|s| s.0))
            .max();
        let first = t
            .iter()
            .filter_map(|r| r.first_seen_timestamp_utc.map(|s| s.0))
            .min();
        last.zip(first).map_or(0, |(l, f)| l - f)
    };
    let (tags, _) = collect_reports(&mut c, T, |t| span(t) >= 1_000_000).await;
    assert!(span(&tags) >= 1_000_000, "reads span a simulated second");
    c.close(T).await.expect("the reader closes too");
    sim.shutdown().await;
    let text = std::fs::read_to_string(&path).expect("truth written");
    let lines: Vec<serde_json::Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).expect("json line"))
        .collect();
    assert!(lines.len() >= 10, "{} lines", lines.len());
    let first = &lines[0];
    assert_eq!(first["t_us"], 0);
    let tags = first["tags"].as_array().expect("tags");
    assert_eq!(tags.len(), scenario.tags.len());
    for (t, spec) in tags.iter().zip(&scenario.tags) {
        assert_eq!(t["epc"].as_str(), Some(spec.epc.to_lowercase().as_str()));
        let p: Vec<f64> = serde_json::from_value(t["position"].clone()).expect("position");
        assert_eq!(p, spec.position.to_vec());
    }
    for w in lines.windows(2) {
        let dt = w[1]["t_us"].as_u64().expect("t") - w[0]["t_us"].as_u64().expect("t");
        assert_eq!(dt, 100_000);
    }
    // S1's antenna rides a robot: its true pose changes over time.
    let pos = |l: &serde_json::Value| l["antennas"][0]["pose"]["position"].clone();
    assert_ne!(pos(&lines[0]), pos(lines.last().expect("lines")));
}

/// The ground truth `sim` writes for `scenario` while one ROSpec of `span_ms` (simulated)
/// runs to its end, at `--speed max`.
async fn truth_of_one_rospec(scenario: &Scenario, span_ms: u32) -> Vec<serde_json::Value> {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("truth.jsonl");
    let opts = SimOptions {
        speed: Speed::Max,
        truth: Some(path.clone()),
        ..Default::default()
    };
    let sim = sim::start(scenario, &opts).await.expect("starts");
    let mut c = connect(&sim).await;
    let report = full_report(RoReportTriggerType::UponNTagsOrEndOfRoSpec, 0);
    add(
        &mut c,
        rospec(1, vec![0], ro_duration(span_ms), ai_null(), report),
    )
    .await;
    enable(&mut c, 1).await;
    // The ROSpec's report comes when it ends.
    let (tags, _) = collect_reports(&mut c, T, |t| !t.is_empty()).await;
    assert!(!tags.is_empty(), "the ROSpec reported at its end");
    c.close(T).await.expect("the reader closes too");
    sim.shutdown().await;
    let text = std::fs::read_to_string(&path).expect("truth written");
    text.lines()
        .map(|l| serde_json::from_str(l).expect("json line"))
        .collect()
}

/// Standard deviation of `v`.
fn std_dev(v: &[f64]) -> f64 {
    let mean = v.iter().sum::<f64>() / v.len() as f64;
    (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / v.len() as f64).sqrt()
}

#[tokio::test]
async fn ground_truth_carries_true_and_estimated_poses_with_the_pose_file_keys() {
    // S1's robot localized with a large, nearly white error (τ far below the 100 ms between
    // truth lines), so 20 s of truth give 200 nearly independent errors: σ within about 5 %.
    let (sigma, heading_deg) = (0.05, 2.0);
    let mut scenario = s1();
    let Mount::Robot { robot, .. } = &mut scenario.readers[0].antennas[0].mount else {
        panic!("S1's antenna rides a robot");
    };
    robot.pose_estimate = PoseEstimate {
        kind: PoseEstimateKind::Localized,
        position_sigma_m: sigma,
        heading_sigma_deg: heading_deg,
        correlation_s: 0.01,
    };
    let lines = truth_of_one_rospec(&scenario, 20_000).await;
    let last = lines.last().and_then(|l| l["t_us"].as_u64()).unwrap_or(0);
    assert!(last >= 19_900_000, "truth up to {last} µs");
    let mut keys = [
        "t_us",
        "reader",
        "antenna",
        "x",
        "y",
        "z",
        "yaw_deg",
        "pitch_deg",
    ];
    keys.sort_unstable();
    let mut errors: [Vec<f64>; 3] = Default::default();
    for line in &lines {
        for a in line["antennas"].as_array().expect("antennas") {
            for kind in ["true", "estimated"] {
                let pose = a[kind].as_object().expect("a pose object");
                let mut got: Vec<&str> = pose.keys().map(String::as_str).collect();
                got.sort_unstable();
                assert_eq!(got, keys, "{kind}");
                assert_eq!(pose["t_us"], line["t_us"]);
                assert_eq!(pose["reader"], line["reader"]);
                assert_eq!(pose["antenna"], a["antenna"]);
            }
            let (t, e) = (&a["true"], &a["estimated"]);
            let position: Vec<f64> =
                serde_json::from_value(a["pose"]["position"].clone()).expect("position");
            let at = |p: &serde_json::Value, k: &str| p[k].as_f64().expect("a number");
            assert_eq!([at(t, "x"), at(t, "y"), at(t, "z")].to_vec(), position);
            let yaw = at(&a["pose"], "yaw_rad").to_degrees();
            assert!((at(t, "yaw_deg") - yaw).abs() < 1e-9);
            assert_eq!(at(e, "z"), at(t, "z"));
            let dyaw = (at(e, "yaw_deg") - at(t, "yaw_deg") + 180.0).rem_euclid(360.0) - 180.0;
            errors[0].push(at(e, "x") - at(t, "x"));
            errors[1].push(at(e, "y") - at(t, "y"));
            errors[2].push(dyaw);
        }
    }
    assert!(errors[0].len() >= 200, "{} poses", errors[0].len());
    // The heading error swings the antenna's 0.2 m arm too: σ 7 mm beside 50 mm, +1 % on x.
    for (axis, want) in [sigma, sigma, heading_deg].into_iter().enumerate() {
        let got = std_dev(&errors[axis]);
        assert!(
            (got / want - 1.0).abs() < 0.2,
            "axis {axis}: σ {got} vs {want}"
        );
    }
}

#[tokio::test]
async fn every_reader_of_a_scenario_listens() {
    let mut scenario = s1();
    let mut second = scenario.readers[0].clone();
    second.name = "reader-2".parse().expect("a reader name");
    scenario.readers.push(second);
    let sim = start(&scenario, Speed::Factor(1.0)).await;
    assert_eq!(sim.addrs.len(), 2);
    assert_ne!(sim.addrs[0], sim.addrs[1]);
    for addr in &sim.addrs {
        let mut c = Client::connect(*addr).await.expect("connects");
        let m = c.recv(T).await.expect("greeting");
        assert_eq!(
            connection_status(&m),
            Some(ConnectionAttemptStatus::Success)
        );
    }
    sim.shutdown().await;
}

/// A client leaves its ROSpec running (as sllurp does when it is killed); the next client's
/// inventory (`ReadStream`, what `llrp-gateway inventory` runs) takes only its own reads:
/// every one with the antenna, phase and RSSI it asked for, none of the earlier ROSpec's
/// (whose reports carried no antenna and no Impinj phase).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_inventory_takes_no_read_of_a_rospec_an_earlier_client_left_running() {
    use llrp_gateway::net::client::{InventorySpec, ReadStream};
    let sim = start(&line_scenario(&[1.0, 1.5, 2.0]), Speed::Factor(1.0)).await;
    let mut first = connect(&sim).await;
    let bare = RoSpec::immediate(7, vec![0]).with_report(
        RoReportSpec::new(RoReportTriggerType::UponNTagsOrEndOfAiSpec, 1).with_content(
            TagReportContentSelector {
                enable_ro_spec_id: true,
                ..Default::default()
            },
        ),
    );
    add(&mut first, bare).await;
    enable(&mut first, 7).await;
    let (tags, _) = collect_reports(&mut first, T, |t| !t.is_empty()).await;
    assert!(!tags.is_empty(), "the first client's ROSpec reads");
    // Gone without a word: its ROSpec stays and keeps running on the next connection.
    drop(first);
    tokio::time::sleep(std::time::Duration::from_millis(200)).await;
    let second = Client::connect_reader(sim.addrs[0], T)
        .await
        .expect("connects");
    // The old ROSpec's reports pile up while the client is not yet set up.
    tokio::time::sleep(std::time::Duration::from_millis(300)).await;
    let spec = InventorySpec {
        impinj: true,
        ..InventorySpec::default()
    };
    let mut stream = ReadStream::start(second, &spec, None, T)
        .await
        .expect("the inventory starts");
    let mut reads = Vec::new();
    while reads.len() < 50 {
        stream
            .next(T, &mut reads)
            .await
            .expect("reports keep coming");
    }
    for r in &reads {
        assert!(
            r.antenna >= 1 && r.phase_rad.is_some() && r.rssi_dbm.is_some(),
            "a read this inventory did not ask for: {r:?}"
        );
    }
    assert!(
        stream.foreign_reads() > 0,
        "the earlier ROSpec's reports came (and were set aside)"
    );
    sim.shutdown().await;
}
