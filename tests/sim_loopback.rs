//! The simulator over loopback: every reader of a scenario listens, and the ground truth it
//! writes while a client inventories.

mod common;

use common::*;
use llrp::message::*;
use llrp::params::*;
use llrp_gateway::net::client::Client;
use llrp_gateway::net::clock::Speed;
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

#[tokio::test]
async fn every_reader_of_a_scenario_listens() {
    let mut scenario = s1();
    let mut second = scenario.readers[0].clone();
    second.name = "reader-2".into();
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
