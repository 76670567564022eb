//! The localizer's pieces end to end on the default scenario S1, as a user would run them: the
//! simulator streams to the project's client over loopback and writes its ground truth; the
//! reads and the true antenna poses (the truth file, as a pose file) go through
//! `localize::ingest` and `localize::estimate` (Phase ReLock), and every tag's estimate is
//! compared with the truth.

mod common;

use std::io::BufRead;

use common::*;
use llrp_gateway::localize::estimate;
use llrp_gateway::localize::ingest::Ingest;
use llrp_gateway::localize::poses::{PoseSample, Poses};
use llrp_gateway::localize::series::Ambiguity;
use llrp_gateway::net::clock::Speed;
use llrp_gateway::reads::Read;
use llrp_gateway::sim::{self, SimOptions};

#[tokio::test]
async fn relock_localizes_every_s1_tag_from_the_stream_and_true_poses() {
    let dir = tempfile::tempdir().expect("temp dir");
    let truth = dir.path().join("truth.jsonl");
    // Clean reads: the pipeline's own accuracy (S1's `impinj-r420` reads give about 12 cm,
    // docs/benchmarks.md).
    let scenario = s1_ideal();
    let opts = SimOptions {
        speed: Speed::Max,
        truth: Some(truth.clone()),
        ..Default::default()
    };
    let sim = sim::start(&scenario, &opts).await.expect("starts");
    let mut c = connect(&sim).await;
    c.enable_impinj_extensions(T).await.expect("extensions");
    let spec = rospec(
        1,
        vec![0],
        ro_null(),
        ai_null(),
        full_report(RoReportTriggerType::UponNTagsOrEndOfAiSpec, 1),
    );
    c.add_rospec(spec, T).await.expect("ADD_ROSPEC");
    c.enable_rospec(1, T).await.expect("ENABLE_ROSPEC");
    // The robot drives 22 m at 0.5 m/s: until the reads span 46 s of simulated time.
    let span = |t: &[llrp::params::TagReportData]| {
        let ts: Vec<u64> = t
            .iter()
            .filter_map(|r| r.first_seen_timestamp_utc.map(|u| u.0))
            .collect();
        ts.iter()
            .max()
            .zip(ts.iter().min())
            .map_or(0, |(a, b)| a - b)
    };
    let (tags, _) = collect_reports(&mut c, T * 6, |t| span(t) >= 46_000_000).await;
    drop(c);
    sim.shutdown().await;
    assert!(
        span(&tags) >= 46_000_000,
        "only {} µs of reads",
        span(&tags)
    );

    // The truth file as a pose file (true poses), its simulated clock mapped to UTC.
    let mut poses = Poses::new();
    let mut positions: Vec<(String, [f64; 3])> = Vec::new();
    let file = std::fs::File::open(&truth).expect("truth written");
    for line in std::io::BufReader::new(file).lines() {
        let v: serde_json::Value = serde_json::from_str(&line.expect("a line")).expect("JSON");
        let offset = v["utc_us"].as_i64().expect("utc_us") - v["t_us"].as_i64().expect("t_us");
        poses.set_offset("s1-reader", offset);
        for a in v["antennas"].as_array().expect("antennas") {
            let p: PoseSample = serde_json::from_value(a["true"].clone()).expect("a pose record");
            poses.add(p);
        }
        if let Some(ts) = v["tags"].as_array().filter(|t| !t.is_empty()) {
            if positions.is_empty() {
                for t in ts {
                    let p = &t["position"];
                    let xyz = [0, 1, 2].map(|i| p[i].as_f64().expect("coordinate"));
                    positions.push((t["epc"].as_str().expect("epc").to_uppercase(), xyz));
                }
            }
        }
    }
    assert_eq!(positions.len(), 10);

    let mut ingest = Ingest::new(poses, Ambiguity::None, 1_000_000);
    for t in &tags {
        let read = Read {
            epc: llrp_gateway::reads::Epc::from_bytes(t.epc_bytes()),
            reader: Some("s1-reader".parse().expect("a reader name")),
            antenna: t.antenna_id.map_or(0, |a| a.0),
            t_us: t.first_seen_timestamp_utc.map_or(0, |u| u.0),
            phase_rad: t
                .impinj_phase_angle()
                .map(|p| f64::from(p) * std::f64::consts::TAU / 4096.0),
            rssi_dbm: None,
            channel_index: t.channel_index.map(|c| c.0),
            // S1 holds ETSI channel 1.
            channel_frequency_hz: Some(865_700_000),
            doppler_hz: None,
            antenna_pose: None,
            last_seen_us: None,
        };
        ingest.push(&read);
    }
    assert_eq!(ingest.set_aside().no_pose, 0, "{:?}", ingest.set_aside());

    // S1's antenna faces the racks (+y); tags and antenna at z = 0.5 m.
    let geometry = estimate::Geometry {
        tag_height_m: 0.5,
        phase_sign: 1.0,
        facing: [0.0, 1.0],
        reach_m: 4.0,
        references: Vec::new(),
        readers: Default::default(),
        pose_error: None,
        pose_corrections: None,
        tag_curvature_sigma_rad: 0.0,
    };
    let estimates = estimate::estimate_all(&ingest, estimate::Estimator::Relock, &geometry);
    assert_eq!(estimates.len(), 10);
    let mut errors = Vec::new();
    for (epc, truth) in &positions {
        let e = estimates
            .iter()
            .find(|e| &e.epc == epc)
            .unwrap_or_else(|| panic!("no estimate for {epc}"));
        let p = e
            .estimate
            .unwrap_or_else(|| panic!("{epc}: {:?} from {} phases", e.state, e.samples));
        assert_eq!(e.state, estimate::State::Converged, "{e:?}");
        errors.push((p[0] - truth[0]).hypot(p[1] - truth[1]));
    }
    let mean = errors.iter().sum::<f64>() / errors.len() as f64;
    let max = errors.iter().copied().fold(0.0, f64::max);
    // [G]'s anchor with AMCL poses: 15 mm mean, 39 mm max; with true poses a few mm.
    assert!(
        mean < 0.01 && max < 0.03,
        "mean {mean} m, max {max} m: {errors:?}"
    );
}
