//! MCAP out of running commands (docs/robotics.md): `proxy --mcap FILE`, `replay --mcap
//! FILE` and `sim --mcap FILE`, each file read by the independent readers of
//! `scripts/interop/mcap_check.py` (`LLRP_MCAP_PYTHON`, see `tests/mcap_out.rs`) and compared
//! with what the same run wrote otherwise: the recording's export, the client's reads file,
//! the simulator's ground truth.

use std::collections::BTreeMap;
use std::path::Path;

mod mcap_support;
use mcap_support::*;

/// What a decoder made of a file, without what only one reader gives (rosbags has no
/// publish time).
fn decoded(v: &serde_json::Value, decoder: &str) -> serde_json::Value {
    let mut d = v[decoder].clone();
    for key in ["reads", "events"] {
        for m in d[key].as_array_mut().expect("an array") {
            m.as_object_mut().expect("an object").remove("publish_time");
        }
    }
    d
}

#[test]
#[ignore = "needs the MCAP readers (LLRP_MCAP_PYTHON: scripts/venv-mcap.sh, set by ./scripts/test)"]
fn a_proxy_s_mcap_file_is_the_export_of_its_recording_and_holds_the_client_s_reads() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = |name: &str| dir.path().join(name).to_str().expect("utf-8").to_string();
    let (mut sim, sim_addr) = sim_recording(Path::new(&path("sim.jsonl")));
    let (mut proxy, proxy_addr) = spawn_listening(&[
        "proxy",
        "--upstream",
        &sim_addr,
        "--listen",
        "127.0.0.1:0",
        "--record",
        &path("proxy.jsonl"),
        "--mcap",
        &path("proxy.mcap"),
    ]);
    run(&[
        "inventory",
        &proxy_addr,
        "--seconds",
        "2",
        "--impinj",
        "--output",
        &path("reads.jsonl"),
    ]);
    terminate(&mut proxy);
    terminate(&mut sim);
    run(&[
        "export",
        &path("proxy.jsonl"),
        "--mcap",
        &path("export.mcap"),
    ]);
    let live = check(Path::new(&path("proxy.mcap")));
    let exported = check(Path::new(&path("export.mcap")));

    // The same channels, counts, frames, reads and events as the export of the recording,
    // for both readers (publish times included, where the reader gives them).
    let token = llrp_gateway::record::mcap::topic_token(&sim_addr);
    let ch = channels(&live);
    assert_eq!(ch, channels(&exported));
    for topic in ["reads", "events", "conn_1/to_reader", "conn_1/from_reader"] {
        assert!(
            ch.contains_key(&format!("/llrp/{token}/{topic}")),
            "{topic}: {ch:?}"
        );
    }
    assert_eq!(live["mcap_ros2"], exported["mcap_ros2"]);
    assert_eq!(decoded(&live, "rosbags"), decoded(&exported, "rosbags"));
    let recording = llrp_gateway::record::Recording::open(Path::new(&path("proxy.jsonl")))
        .expect("the recording");
    let streams = recorded_streams(&recording, &token);
    assert_eq!(
        live["mcap_ros2"]["frames"],
        serde_json::to_value(&streams).expect("json")
    );

    // The reads are the client's, value for value.
    let mut reads = reads_file(Path::new(&path("reads.jsonl")));
    assert!(reads.len() > 10, "the inventory read tags: {}", reads.len());
    sort(&mut reads);
    for decoder in ["mcap_ros2", "rosbags"] {
        let mut got = decoded_reads(&live[decoder]);
        for r in &mut got {
            r.reader = reads[0].reader.clone();
            r.last_seen_us = None;
        }
        assert_eq!(got, reads, "{decoder}");
    }
    let kinds: BTreeMap<String, usize> = live["mcap_ros2"]["events"]
        .as_array()
        .expect("events")
        .iter()
        .fold(BTreeMap::new(), |mut m, e| {
            *m.entry(e["kind"].as_str().expect("kind").to_string())
                .or_default() += 1;
            m
        });
    assert_eq!(kinds.get("connect"), Some(&1), "{kinds:?}");
    assert_eq!(kinds.get("disconnect"), Some(&1), "{kinds:?}");
}

#[test]
#[ignore = "needs the MCAP readers (LLRP_MCAP_PYTHON: scripts/venv-mcap.sh, set by ./scripts/test)"]
fn a_replay_s_mcap_file_holds_the_replayed_session_and_the_client_s_reads() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = |name: &str| dir.path().join(name).to_str().expect("utf-8").to_string();
    // A recording of `inventory --impinj --report-every 1`, which the same client replays.
    let fixture = root().join("fixtures/localize/s1-report-per-read.jsonl");
    let (mut replay, addr) = spawn_listening(&[
        "replay",
        fixture.to_str().expect("utf-8"),
        "--listen",
        "127.0.0.1:0",
        "--speed",
        "max",
        "--mcap",
        &path("replay.mcap"),
    ]);
    run(&[
        "inventory",
        &addr,
        "--seconds",
        "2",
        "--impinj",
        "--report-every",
        "1",
        "--output",
        &path("reads.jsonl"),
    ]);
    terminate(&mut replay);
    let v = check(Path::new(&path("replay.mcap")));
    let recording = llrp_gateway::record::Recording::open(&fixture).expect("the fixture");
    let reader = recording.header.upstream.trim_start_matches("sim:");
    let token = llrp_gateway::record::mcap::topic_token(reader);
    let ch = channels(&v);
    for topic in ["reads", "events", "conn_1/to_reader", "conn_1/from_reader"] {
        assert!(
            ch.contains_key(&format!("/llrp/{token}/{topic}")),
            "{topic}: {ch:?}"
        );
    }
    let mut reads = reads_file(Path::new(&path("reads.jsonl")));
    assert!(!reads.is_empty(), "the inventory read tags");
    sort(&mut reads);
    for decoder in ["mcap_ros2", "rosbags"] {
        let mut got = decoded_reads(&v[decoder]);
        for r in &mut got {
            assert_eq!(r.reader.as_deref(), Some(reader));
            r.reader = reads[0].reader.clone();
            r.last_seen_us = None;
        }
        assert_eq!(got, reads, "{decoder}");
        assert_eq!(
            v[decoder]["count"].as_u64(),
            Some(ch.values().map(|(_, n)| n).sum::<u64>()),
            "{decoder}: every message the summary counts decodes"
        );
    }
}

/// The values of `v`'s field `key` as `f64`.
fn f(v: &serde_json::Value, key: &str) -> f64 {
    v[key].as_f64().unwrap_or_else(|| panic!("{key} in {v}"))
}

/// The boresight (+x of the antenna frame) of a message's quaternion.
fn boresight(m: &serde_json::Value) -> [f64; 3] {
    let (x, y, z, w) = (f(m, "qx"), f(m, "qy"), f(m, "qz"), f(m, "qw"));
    [
        1.0 - 2.0 * (y * y + z * z),
        2.0 * (x * y + w * z),
        2.0 * (x * z - w * y),
    ]
}

/// The transform `parent` then `child` (each x, y, z and a quaternion), as one.
fn compose(parent: &serde_json::Value, child: &serde_json::Value) -> serde_json::Value {
    use nalgebra::{Quaternion, UnitQuaternion, Vector3};
    let q = |m: &serde_json::Value| {
        UnitQuaternion::from_quaternion(Quaternion::new(
            f(m, "qw"),
            f(m, "qx"),
            f(m, "qy"),
            f(m, "qz"),
        ))
    };
    let t = |m: &serde_json::Value| Vector3::new(f(m, "x"), f(m, "y"), f(m, "z"));
    let (r, p) = (q(parent) * q(child), t(parent) + q(parent) * t(child));
    serde_json::json!({"x": p.x, "y": p.y, "z": p.z, "qx": r.i, "qy": r.j, "qz": r.k, "qw": r.w})
}

/// Asserts that `m` (x, y, z and a quaternion) is `pose` of the truth file (`position`,
/// `yaw_rad`, `pitch_rad`).
fn assert_pose(m: &serde_json::Value, position: &serde_json::Value, yaw: f64, pitch: f64) {
    for (i, k) in ["x", "y", "z"].iter().enumerate() {
        let want = position[i].as_f64().expect("a coordinate");
        assert!((f(m, k) - want).abs() < 1e-9, "{k}: {m} vs {position}");
    }
    let b = boresight(m);
    let want = [
        yaw.cos() * pitch.cos(),
        yaw.sin() * pitch.cos(),
        pitch.sin(),
    ];
    for (g, w) in b.iter().zip(want) {
        assert!((g - w).abs() < 1e-9, "boresight {b:?} vs {want:?}: {m}");
    }
}

#[test]
#[ignore = "needs the MCAP readers (LLRP_MCAP_PYTHON: scripts/venv-mcap.sh, set by ./scripts/test)"]
fn a_simulation_s_mcap_file_holds_its_sessions_its_antenna_poses_and_its_ground_truth() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = |name: &str| dir.path().join(name).to_str().expect("utf-8").to_string();
    let (mut sim, addr) = spawn_listening(&[
        "sim",
        "--no-http",
        "--listen",
        "127.0.0.1:0",
        "--record",
        &path("sim.jsonl"),
        "--truth",
        &path("truth.jsonl"),
        "--mcap",
        &path("sim.mcap"),
    ]);
    run(&[
        "inventory",
        &addr,
        "--seconds",
        "2",
        "--impinj",
        "--output",
        &path("reads.jsonl"),
    ]);
    terminate(&mut sim);
    run(&["export", &path("sim.jsonl"), "--mcap", &path("export.mcap")]);
    let v = check(Path::new(&path("sim.mcap")));
    let exported = check(Path::new(&path("export.mcap")));

    // The sessions: what the export of the simulator's recording holds.
    let ch = channels(&v);
    for (topic, c) in channels(&exported) {
        assert_eq!(ch.get(&topic), Some(&c), "{topic}");
    }
    for key in ["reads", "frames", "events", "logs"] {
        assert_eq!(v["mcap_ros2"][key], exported["mcap_ros2"][key], "{key}");
    }
    let mut reads = reads_file(Path::new(&path("reads.jsonl")));
    assert!(reads.len() > 10, "the inventory read tags: {}", reads.len());
    sort(&mut reads);
    for decoder in ["mcap_ros2", "rosbags"] {
        let mut got = decoded_reads(&v[decoder]);
        for r in &mut got {
            assert_eq!(r.reader.as_deref(), Some("s1-reader"));
            r.reader = reads[0].reader.clone();
            r.last_seen_us = None;
        }
        assert_eq!(got, reads, "{decoder}");
        for key in ["poses", "tf", "tags"] {
            assert_eq!(v[decoder][key], v["mcap_ros2"][key], "{decoder}: {key}");
        }
    }

    // Poses and truth: one instant per line of the truth file, value for value.
    assert_truth(&v["mcap_ros2"], Path::new(&path("truth.jsonl")));
}

/// Asserts that the poses, transforms and tag positions `d` decoded are, instant for
/// instant, those of the truth file at `truth`.
fn assert_truth(d: &serde_json::Value, truth: &Path) {
    let truth: Vec<serde_json::Value> = std::fs::read_to_string(truth)
        .expect("the truth file")
        .lines()
        .map(|l| serde_json::from_str(l).expect("a truth line"))
        .collect();
    assert!(truth.len() > 5, "truth lines: {}", truth.len());
    let by_topic = |topic: &str| -> Vec<serde_json::Value> {
        (d["poses"].as_array().expect("poses").iter())
            .filter(|p| p["topic"] == topic)
            .cloned()
            .collect()
    };
    let tf = d["tf"].as_array().expect("tf");
    let tags = d["tags"].as_array().expect("tags");
    let antennas = truth[0]["antennas"].as_array().expect("antennas").len();
    // S1's one robot carries every antenna: its frame at each instant, then theirs.
    let robots: Vec<_> = tf.iter().filter(|t| t["child"] == "robot_1").collect();
    assert_eq!(robots.len(), truth.len());
    assert_eq!(tf.len(), truth.len() * (antennas + 1));
    let tag_total: usize = truth
        .iter()
        .map(|l| l["tags"].as_array().expect("tags").len())
        .sum();
    assert_eq!(tags.len(), tag_total);
    for a in 0..antennas {
        let port = truth[0]["antennas"][a]["antenna"].as_u64().expect("a port");
        let true_poses = by_topic(&format!("/truth/s1_reader/antenna_{port}/pose"));
        let reported = by_topic(&format!("/llrp/s1_reader/antenna_{port}/pose"));
        let frames: Vec<_> = (tf.iter())
            .filter(|t| t["child"] == format!("s1_reader/antenna_{port}"))
            .collect();
        assert_eq!(true_poses.len(), truth.len(), "antenna {port}");
        assert_eq!(reported.len(), truth.len(), "antenna {port}");
        assert_eq!(frames.len(), truth.len(), "antenna {port}");
        for (i, line) in truth.iter().enumerate() {
            let ns = line["utc_us"].as_u64().expect("utc_us") * 1000;
            let ant = &line["antennas"][a];
            let p = &ant["pose"];
            assert_eq!(true_poses[i]["stamp_ns"].as_u64(), Some(ns));
            assert_eq!(true_poses[i]["frame_id"], "map");
            assert_pose(
                &true_poses[i],
                &p["position"],
                f(p, "yaw_rad"),
                f(p, "pitch_rad"),
            );
            let e = &ant["estimated"];
            let position = serde_json::json!([f(e, "x"), f(e, "y"), f(e, "z")]);
            let (yaw, pitch) = (f(e, "yaw_deg").to_radians(), f(e, "pitch_deg").to_radians());
            assert_pose(&reported[i], &position, yaw, pitch);
            assert_eq!(frames[i]["parent"], "robot_1");
            assert_eq!(frames[i]["stamp_ns"].as_u64(), Some(ns));
            assert_eq!(robots[i]["parent"], "map");
            assert_eq!(robots[i]["stamp_ns"].as_u64(), Some(ns));
            assert_pose(&compose(robots[i], frames[i]), &position, yaw, pitch);
        }
    }
    let first = &truth[0]["tags"][0];
    let t0 = &tags[0];
    assert_eq!(
        t0["epc"].as_str().map(str::to_lowercase).as_deref(),
        first["epc"].as_str()
    );
    assert_eq!(
        t0["stamp_ns"].as_u64(),
        truth[0]["utc_us"].as_u64().map(|u| u * 1000)
    );
    assert_pose_position(t0, &first["position"]);
}

/// Asserts that `m`'s x, y, z are `position`.
fn assert_pose_position(m: &serde_json::Value, position: &serde_json::Value) {
    for (i, k) in ["x", "y", "z"].iter().enumerate() {
        let want = position[i].as_f64().expect("a coordinate");
        assert!((f(m, k) - want).abs() < 1e-12, "{k}: {m} vs {position}");
    }
}
