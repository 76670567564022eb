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
