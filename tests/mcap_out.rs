//! MCAP out (docs/robotics.md): `export RECORDING --mcap FILE` and `inventory --mcap FILE`,
//! each file read by independent readers (Foxglove's Python `mcap` with
//! `mcap-ros2-support`, and `rosbags`, through `scripts/interop/mcap_check.py` in the venv of
//! `scripts/venv-mcap.sh`, named by `LLRP_MCAP_PYTHON`): the channels and their schemas, the
//! message counts, the frames byte for byte, and the decoded reads against the JSON Lines
//! reads of the same run.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use llrp_gateway::record::{Direction, Entry, Recording};
use serde_json::Value;

mod mcap_support;
use mcap_support::*;

#[test]
#[ignore = "needs the MCAP readers (LLRP_MCAP_PYTHON: scripts/venv-mcap.sh, set by ./scripts/test)"]
fn an_exported_recording_holds_its_streams_byte_for_byte_its_reads_and_its_events() {
    let dir = tempfile::tempdir().expect("temp dir");
    let input = root().join("fixtures/sessions/s1-sllurp-impinj.jsonl");
    let out = dir.path().join("s1.mcap");
    run(&[
        "export",
        input.to_str().expect("utf-8"),
        "--mcap",
        out.to_str().expect("utf-8"),
    ]);
    let recording = Recording::open(&input).expect("the fixture reads");
    let v = check(&out);
    assert_eq!(v["header"]["profile"], "ros2");
    let streams = recorded_streams(&recording, "s1_reader");
    let chans = channels(&v);
    for decoder in ["mcap_ros2", "rosbags"] {
        let d = &v[decoder];
        let frames: BTreeMap<String, String> =
            serde_json::from_value(d["frames"].clone()).expect("frames");
        assert_eq!(frames, streams, "{decoder}: every stream byte for byte");
        assert_eq!(
            d["count"].as_u64(),
            Some(chans.values().map(|c| c.1).sum()),
            "{decoder}: every message of the summary decodes"
        );
    }
    // The reads: those of a decoder fed the recording's frames from the reader.
    let mut expected = Vec::new();
    let mut decoder = llrp_gateway::reads::ReadDecoder::new(recording.header.reader_name().ok());
    for (at, dir, frame) in recording.frames(1) {
        if dir == Direction::FromReader {
            decoder
                .frame(frame, at.utc_us, &mut expected)
                .expect("decodes");
        }
    }
    sort(&mut expected);
    assert!(!expected.is_empty());
    for decoder in ["mcap_ros2", "rosbags"] {
        assert_eq!(decoded_reads(&v[decoder]), expected, "{decoder}");
    }
    assert_eq!(
        chans.get("/llrp/s1_reader/reads"),
        Some(&(
            "llrp_gateway_msgs/msg/TagRead".to_string(),
            expected.len() as u64
        ))
    );
    // The markers (connect, disconnect) and the READER_EVENT_NOTIFICATIONs, each also a log
    // line; a notification's stamp and publish time are the reader's timestamp.
    let markers = recording
        .entries
        .iter()
        .filter(|e| matches!(e, Entry::Marker { .. }))
        .count();
    let events = v["mcap_ros2"]["events"].as_array().expect("events");
    let notifications: Vec<&Value> = events
        .iter()
        .filter(|e| e["kind"] == "notification")
        .collect();
    assert_eq!(events.len() - notifications.len(), markers);
    assert!(!notifications.is_empty());
    for n in notifications {
        let detail: Value =
            serde_json::from_str(n["detail"].as_str().expect("text")).expect("JSON");
        let us = detail["timestamp"]["Utc"]["microseconds"]
            .as_u64()
            .expect("UTC stamp");
        assert_eq!(n["publish_time"].as_u64(), Some(us * 1000), "{n}");
        assert_eq!(n["stamp_ns"].as_u64(), Some(us * 1000), "{n}");
    }
    assert_eq!(
        v["mcap_ros2"]["logs"].as_array().map(Vec::len),
        Some(events.len())
    );
}

#[test]
#[ignore = "needs the MCAP readers (LLRP_MCAP_PYTHON: scripts/venv-mcap.sh, set by ./scripts/test)"]
fn inventory_and_the_export_of_its_recorded_session_give_the_reads_file_s_reads() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = |name: &str| dir.path().join(name).to_str().expect("utf-8").to_string();
    let (mut sim, addr) = sim_recording(Path::new(&path("session.jsonl")));
    run(&[
        "inventory",
        &addr,
        "--seconds",
        "2",
        "--impinj",
        "--output",
        &path("reads.jsonl"),
        "--mcap",
        &path("inventory.mcap"),
    ]);
    // SIGTERM: the simulator ends its recording cleanly.
    let killed = Command::new("kill")
        .args(["-TERM", &sim.0.id().to_string()])
        .status()
        .expect("kill runs");
    assert!(killed.success());
    let until = Instant::now() + GUARD;
    while sim.0.try_wait().expect("wait").is_none() {
        assert!(Instant::now() < until, "sim did not exit");
        std::thread::sleep(Duration::from_millis(20));
    }
    run(&[
        "export",
        &path("session.jsonl"),
        "--mcap",
        &path("session.mcap"),
    ]);
    let mut reads = reads_file(Path::new(&path("reads.jsonl")));
    assert!(reads.len() > 10, "the inventory read tags: {}", reads.len());
    sort(&mut reads);

    // The inventory's own file: its reads, as written to the reads file, with times.
    let v = check(Path::new(&path("inventory.mcap")));
    let token = llrp_gateway::record::mcap::topic_token(&addr);
    let topic = format!("/llrp/{token}/reads");
    // Each read with a phase also as its phase unwrapped.
    let phased = reads.iter().filter(|r| r.phase_rad.is_some()).count() as u64;
    let mut want = BTreeMap::from([(
        topic.clone(),
        (
            "llrp_gateway_msgs/msg/TagRead".to_string(),
            reads.len() as u64,
        ),
    )]);
    if phased > 0 {
        want.insert(
            format!("/llrp/{token}/phase_unwrapped"),
            ("llrp_gateway_msgs/msg/TagPhase".to_string(), phased),
        );
    }
    assert_eq!(channels(&v), want);
    for decoder in ["mcap_ros2", "rosbags"] {
        let mut got = decoded_reads(&v[decoder]);
        // The reads file does not carry the last-seen time.
        got.iter_mut().for_each(|r| r.last_seen_us = None);
        assert_eq!(got, reads, "{decoder}");
    }
    for r in v["mcap_ros2"]["reads"].as_array().expect("reads") {
        // Publish time and stamp: the reader's first-seen time; log time: when it arrived.
        let t_ns = r["t_us"].as_u64().expect("t_us") * 1000;
        assert_eq!(r["publish_time"].as_u64(), Some(t_ns), "{r}");
        assert!(
            r["log_time"].as_u64() >= Some(t_ns),
            "received after read: {r}"
        );
    }

    // The export of the simulator's recording of the same session: the same reads, named
    // after the simulated reader.
    let v = check(Path::new(&path("session.mcap")));
    for decoder in ["mcap_ros2", "rosbags"] {
        let mut got = decoded_reads(&v[decoder]);
        for r in &mut got {
            assert_eq!(r.reader.as_deref(), Some("s1-reader"));
            r.reader = reads[0].reader.clone();
            r.last_seen_us = None;
        }
        assert_eq!(got, reads, "{decoder}");
    }
}

#[test]
#[ignore = "needs the MCAP readers (LLRP_MCAP_PYTHON: scripts/venv-mcap.sh, set by ./scripts/test)"]
fn an_exported_recording_s_unwrapped_phases_differ_from_the_read_phases_by_whole_turns_and_never_jump(
) {
    use std::collections::HashMap;
    use std::f64::consts::{PI, TAU};
    let dir = tempfile::tempdir().expect("temp dir");
    let input = root().join("fixtures/sessions/s1-sllurp-impinj.jsonl");
    let out = dir.path().join("s1.mcap");
    run(&[
        "export",
        input.to_str().expect("utf-8"),
        "--mcap",
        out.to_str().expect("utf-8"),
    ]);
    let v = check(&out);
    let chans = channels(&v);
    let topic = "/llrp/s1_reader/phase_unwrapped";
    let reads = v["mcap_ros2"]["reads"].as_array().expect("reads");
    let with_phase = reads.iter().filter(|r| !r["phase_rad"].is_null()).count();
    assert!(with_phase > 0, "the fixture's reads carry a phase");
    assert_eq!(
        chans.get(topic),
        Some(&(
            "llrp_gateway_msgs/msg/TagPhase".to_string(),
            with_phase as u64
        ))
    );
    let sorted = |d: &str| {
        let mut p: Vec<String> = (v[d]["phases"].as_array().expect("phases").iter())
            .map(Value::to_string)
            .collect();
        p.sort();
        p
    };
    assert_eq!(sorted("rosbags"), sorted("mcap_ros2"));
    // In file order (the order the reads were received), per stream.
    let phases = v["mcap_ros2"]["phases"].as_array().expect("phases");
    let mut last: HashMap<(String, u64, u64, u64), f64> = HashMap::new();
    let mut wrapped = 0;
    for p in phases {
        assert_eq!(p["topic"], topic);
        let raw = p["phase_rad"].as_f64().expect("a phase");
        let unwrapped = p["phase_unwrapped_rad"].as_f64().expect("unwrapped");
        let turns = (unwrapped - raw) / TAU;
        assert!((turns - turns.round()).abs() < 1e-9, "{p}");
        if turns.round() != 0.0 {
            wrapped += 1;
        }
        let key = (
            p["epc"].as_str().expect("epc").to_string(),
            p["antenna"].as_u64().expect("antenna"),
            p["channel_index"].as_u64().expect("channel"),
            p["channel_frequency_hz"].as_u64().expect("frequency"),
        );
        if let Some(previous) = last.insert(key, unwrapped) {
            assert!(
                (unwrapped - previous).abs() <= PI + 1e-12,
                "{p} after {previous}"
            );
        }
    }
    assert!(
        wrapped > 0,
        "some stream crossed 2π: the unwrapping was put to the test"
    );
}
