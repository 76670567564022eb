//! `sim --foxglove ADDR` (docs/robotics.md "Live in Foxglove") against an independent client
//! of Foxglove's WebSocket protocol, `scripts/interop/foxglove_client.py` (Python `websockets`
//! with `mcap-ros2-support`'s CDR decoder, in the venv of `scripts/venv-mcap.sh`:
//! `LLRP_MCAP_PYTHON`), and the layout file `docs/foxglove-layout.json` against the channels
//! the server advertises.

use std::collections::{BTreeMap, BTreeSet};
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{ChildStdout, Command, Stdio};
use std::time::Instant;

mod mcap_support;
use mcap_support::*;

/// `llrp-gateway ARGS`: it, its LLRP address and its Foxglove address (from its log).
fn spawn_live(args: &[&str]) -> (Proc, String, String) {
    let mut child = bin()
        .args(args)
        .stderr(Stdio::piped())
        .stdout(Stdio::null())
        .spawn()
        .expect("it starts");
    let mut lines = BufReader::new(child.stderr.take().expect("piped")).lines();
    let until = Instant::now() + GUARD;
    let (mut llrp, mut ws) = (None, None);
    while llrp.is_none() || ws.is_none() {
        assert!(Instant::now() < until, "{args:?} did not listen");
        let line = lines.next().expect("a line").expect("utf-8");
        if let Some(rest) = line.split("listening on ").nth(1) {
            llrp = rest.split([' ', ',']).next().map(str::to_string);
        }
        if let Some(rest) = line.split("Foxglove live view on ").nth(1) {
            ws = rest.split(' ').next().map(str::to_string);
        }
    }
    std::thread::spawn(move || for _ in lines {});
    (Proc(child), llrp.expect("set"), ws.expect("set"))
}

/// `scripts/interop/foxglove_client.py WS 20 30 NEED` once it has subscribed (its first
/// line, `READY`), and its output's next lines.
fn live_client(ws: &str, need: &str) -> (Proc, std::io::Lines<BufReader<ChildStdout>>) {
    let python = std::env::var("LLRP_MCAP_PYTHON").expect(
        "LLRP_MCAP_PYTHON must name the python of scripts/venv-mcap.sh (set by ./scripts/test)",
    );
    let mut client = Command::new(python)
        .arg(root().join("scripts/interop/foxglove_client.py"))
        .args([ws, "20", "30", need])
        .stdout(Stdio::piped())
        .spawn()
        .expect("the client starts");
    let mut out = BufReader::new(client.stdout.take().expect("piped")).lines();
    let ready = out.next().expect("a line").expect("utf-8");
    assert_eq!(ready, "READY", "the client subscribed");
    (Proc(client), out)
}

/// The client's report (its line after `READY`).
fn report(out: &mut std::io::Lines<BufReader<ChildStdout>>) -> serde_json::Value {
    let line = out.next().expect("the client's report").expect("utf-8");
    serde_json::from_str(&line).expect("JSON")
}

/// Asserts what every run's client saw: the refused handshake, an error status for each
/// hostile request, server info; the channels (each `cdr`/`ros2msg`, once), by topic.
fn assert_served(v: &serde_json::Value) -> BTreeMap<String, String> {
    assert_eq!(v["refused_status"], 400);
    let hostile = v["hostile_status"].as_array().expect("statuses");
    let expected = ["not JSON", "setParameters", "no channel 999999", "binary"];
    assert_eq!(hostile.len(), expected.len(), "{hostile:?}");
    for (s, e) in hostile.iter().zip(expected) {
        assert_eq!(s["level"], 2, "{s}");
        assert!(s["message"].as_str().expect("a message").contains(e), "{s}");
    }
    assert_eq!(v["server_info"]["op"], "serverInfo");
    assert!(v["server_info"]["capabilities"].is_array());
    let mut live = BTreeMap::new();
    for c in v["channels"].as_array().expect("channels") {
        assert_eq!(c["encoding"], "cdr", "{c}");
        assert_eq!(c["schemaEncoding"], "ros2msg", "{c}");
        let topic = c["topic"].as_str().expect("topic").to_string();
        let schema = c["schemaName"].as_str().expect("schema").to_string();
        assert!(live.insert(topic, schema).is_none(), "advertised once");
    }
    assert_eq!(v["bad_subscription_ids"], 0);
    live
}

/// Asserts that the client decoded at least 20 reads, each of a tag the inventory read
/// (`reads`, its reads file), with a sane RSSI, reader `reader` and its antenna's frame;
/// the reads' topics.
fn assert_reads(v: &serde_json::Value, reads: &Path, reader: &str) -> BTreeSet<String> {
    let epcs: BTreeSet<String> = reads_file(reads)
        .iter()
        .map(|r| r.epc.to_string())
        .collect();
    let decoded = v["reads"].as_array().expect("reads");
    assert!(decoded.len() >= 20, "{} reads arrived", decoded.len());
    let token = llrp_gateway::record::mcap::topic_token(reader);
    let mut topics = BTreeSet::new();
    for r in decoded {
        let epc = r["epc"].as_str().expect("epc");
        assert!(epcs.contains(epc), "{epc} is among {epcs:?}");
        let rssi = r["rssi_dbm"].as_f64().expect("a number");
        assert!((-100.0..=-20.0).contains(&rssi), "RSSI {rssi}");
        assert_eq!(r["reader"], reader);
        let antenna = r["antenna"].as_u64().expect("antenna");
        assert_eq!(r["frame_id"], format!("{token}/antenna_{antenna}"));
        assert!(r["log_time"].as_u64().expect("log time") > 0);
        topics.insert(r["topic"].as_str().expect("topic").to_string());
    }
    topics
}

/// Every topic `docs/foxglove-layout.json` names: the 3D panel's topics, the plots' message
/// paths (up to the filter or field), the raw messages' and log panels' topics.
fn layout_topics() -> BTreeSet<String> {
    let text = std::fs::read_to_string(root().join("docs/foxglove-layout.json")).expect("read");
    let layout: serde_json::Value = serde_json::from_str(&text).expect("the layout is JSON");
    let mut topics = BTreeSet::new();
    let panels = layout["configById"].as_object().expect("configById");
    for (id, config) in panels {
        assert!(
            layout["layout"].to_string().contains(&format!("\"{id}\"")),
            "panel {id} is placed in the layout"
        );
        if let Some(t) = config["topics"].as_object() {
            topics.extend(t.keys().cloned());
        }
        for p in config["paths"].as_array().into_iter().flatten() {
            let path = p["value"].as_str().expect("a message path");
            topics.insert(path.split(['{', '.']).next().expect("a topic").to_string());
        }
        for key in ["topicPath", "topicToRender"] {
            if let Some(t) = config[key].as_str() {
                topics.insert(t.to_string());
            }
        }
    }
    topics
}

#[test]
#[ignore = "needs the Python client's venv (LLRP_MCAP_PYTHON: scripts/venv-mcap.sh, set by ./scripts/test)"]
fn a_foxglove_client_gets_the_simulation_s_channels_and_reads_live_and_a_hostile_one_breaks_nothing(
) {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = |name: &str| dir.path().join(name).to_str().expect("utf-8").to_string();
    let (mut sim, llrp, ws) = spawn_live(&[
        "sim",
        "--no-http",
        "--listen",
        "127.0.0.1:0",
        "--foxglove",
        "127.0.0.1:0",
        "--mcap",
        &path("sim.mcap"),
    ]);
    let (client, mut out) = live_client(&ws, "poses,tf,tags,events,scenes");
    run(&[
        "inventory",
        &llrp,
        "--seconds",
        "2",
        "--impinj",
        "--output",
        &path("reads.jsonl"),
    ]);
    let v = report(&mut out);
    assert!(
        matches!(sim.0.try_wait(), Ok(None)),
        "the simulator still runs"
    );
    terminate(&mut sim);
    drop(client);
    let live = assert_served(&v);

    // The channels, each also in the MCAP file with the same schema.
    let in_file = check(Path::new(&path("sim.mcap")));
    let file = channels(&in_file);
    for (topic, schema) in &live {
        assert_eq!(file.get(topic).map(|c| &c.0), Some(schema), "{topic}");
    }
    for (topic, schema) in [
        ("/llrp/s1_reader/reads", "llrp_gateway_msgs/msg/TagRead"),
        (
            "/llrp/s1_reader/events",
            "llrp_gateway_msgs/msg/ReaderEvent",
        ),
        (
            "/llrp/s1_reader/antenna_1/pose",
            "foxglove_msgs/msg/PoseInFrame",
        ),
        ("/tf", "tf2_msgs/msg/TFMessage"),
        ("/truth/tags", "llrp_gateway_msgs/msg/TagPosition"),
        ("/log", "foxglove_msgs/msg/Log"),
        ("/scene", "foxglove_msgs/msg/SceneUpdate"),
    ] {
        assert_eq!(live.get(topic).map(String::as_str), Some(schema), "{topic}");
    }
    for topic in layout_topics() {
        assert!(live.contains_key(&topic), "the layout's {topic} is served");
    }

    // The reads, decoded from CDR by the client: tags the inventory read, sane values.
    let topics = assert_reads(&v, Path::new(&path("reads.jsonl")), "s1-reader");
    assert_eq!(
        topics,
        BTreeSet::from(["/llrp/s1_reader/reads".to_string()])
    );
    // Each is a read of the file: the same EPC, RSSI and log time.
    let key = |r: &serde_json::Value| {
        let rssi = r["rssi_dbm"].as_f64().expect("an RSSI");
        (r["epc"].to_string(), rssi.to_bits(), r["log_time"].as_u64())
    };
    let file_reads: BTreeSet<_> = (in_file["mcap_ros2"]["reads"].as_array().expect("reads"))
        .iter()
        .map(|r| {
            let bits = r["rssi_dbm"].as_u64().expect("the RSSI's bits");
            (r["epc"].to_string(), bits, r["log_time"].as_u64())
        })
        .collect();
    for r in v["reads"].as_array().expect("reads") {
        assert!(file_reads.contains(&key(r)), "{r} is in the MCAP file");
    }
    // The poses and transforms, the still tags' positions sent once at the start (a new
    // subscriber gets a channel's latest message), the reader's events.
    for key in ["poses", "tf", "tags", "events", "scenes"] {
        assert!(v[key].as_u64().expect("a count") > 0, "{key}: {v}");
    }
    // The scene, decoded by the client: the world, the antenna and each tag of the file's
    // ground truth.
    let ids: BTreeSet<String> = (v["scene_ids"].as_array().expect("ids").iter())
        .map(|i| i.as_str().expect("an id").to_string())
        .collect();
    let mut want = BTreeSet::from([
        "world/bounds".to_string(),
        "antenna/s1_reader/antenna_1".to_string(),
    ]);
    for t in in_file["mcap_ros2"]["tags"].as_array().expect("tags") {
        let epc = t["epc"].as_str().expect("an EPC").to_uppercase();
        want.insert(format!("truth/tag/{epc}"));
    }
    assert!(want.len() > 2, "{want:?}");
    assert!(ids.is_superset(&want), "{ids:?} vs {want:?}");
}

#[test]
#[ignore = "needs the Python client's venv (LLRP_MCAP_PYTHON: scripts/venv-mcap.sh, set by ./scripts/test)"]
fn a_proxy_without_mcap_serves_the_relayed_reads_and_events_live() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = |name: &str| dir.path().join(name).to_str().expect("utf-8").to_string();
    let (mut sim, sim_addr) = sim_recording(Path::new(&path("sim.jsonl")));
    let (mut proxy, proxy_addr, ws) = spawn_live(&[
        "proxy",
        "--upstream",
        &sim_addr,
        "--listen",
        "127.0.0.1:0",
        "--foxglove",
        "127.0.0.1:0",
    ]);
    let (client, mut out) = live_client(&ws, "events");
    run(&[
        "inventory",
        &proxy_addr,
        "--seconds",
        "2",
        "--impinj",
        "--output",
        &path("reads.jsonl"),
    ]);
    let v = report(&mut out);
    terminate(&mut proxy);
    terminate(&mut sim);
    drop(client);
    let live = assert_served(&v);
    let token = llrp_gateway::record::mcap::topic_token(&sim_addr);
    let reads = format!("/llrp/{token}/reads");
    assert_eq!(
        live.get(&reads).map(String::as_str),
        Some("llrp_gateway_msgs/msg/TagRead")
    );
    assert_eq!(
        assert_reads(&v, Path::new(&path("reads.jsonl")), &sim_addr),
        BTreeSet::from([reads])
    );
    assert!(v["events"].as_u64().expect("a count") > 0, "{v}");
}

#[test]
#[ignore = "needs the Python client's venv (LLRP_MCAP_PYTHON: scripts/venv-mcap.sh, set by ./scripts/test)"]
fn a_replay_serves_the_replayed_session_s_reads_live() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = |name: &str| dir.path().join(name).to_str().expect("utf-8").to_string();
    let fixture = root().join("fixtures/localize/s1-report-per-read.jsonl");
    let (mut replay, addr, ws) = spawn_live(&[
        "replay",
        fixture.to_str().expect("utf-8"),
        "--listen",
        "127.0.0.1:0",
        "--speed",
        "max",
        "--foxglove",
        "127.0.0.1:0",
    ]);
    let (client, mut out) = live_client(&ws, "");
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
    let v = report(&mut out);
    terminate(&mut replay);
    drop(client);
    assert_served(&v);
    let recording = llrp_gateway::record::Recording::open(&fixture).expect("the fixture");
    let reader = recording.header.upstream.trim_start_matches("sim:");
    let token = llrp_gateway::record::mcap::topic_token(reader);
    assert_eq!(
        assert_reads(&v, Path::new(&path("reads.jsonl")), reader),
        BTreeSet::from([format!("/llrp/{token}/reads")])
    );
}

#[test]
fn an_address_the_live_view_cannot_listen_on_is_said_and_nothing_is_written() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mcap = dir.path().join("out.mcap");
    let mcap = mcap.to_str().expect("utf-8");
    let taken = std::net::TcpListener::bind("127.0.0.1:0").expect("binds");
    let taken = taken.local_addr().expect("an address").to_string();
    let fixture = root().join("fixtures/localize/s1-report-per-read.jsonl");
    let fixture = fixture.to_str().expect("utf-8");
    let sim = ["sim", "--no-http", "--listen", "127.0.0.1:0"];
    let proxy = [
        "proxy",
        "--upstream",
        "127.0.0.1:9",
        "--listen",
        "127.0.0.1:0",
    ];
    let replay = ["replay", fixture, "--listen", "127.0.0.1:0"];
    for command in [&sim[..], &proxy[..], &replay[..]] {
        for (addr, why) in [
            ("not-an-address", "invalid socket address"),
            (taken.as_str(), "in use"),
        ] {
            let out = bin()
                .args(command)
                .args(["--foxglove", addr, "--mcap", mcap])
                .output()
                .expect("runs");
            let err = String::from_utf8_lossy(&out.stderr);
            assert_eq!(out.status.code(), Some(1), "{command:?} {addr}: {err}");
            let says = format!(
                "llrp-gateway {}: Foxglove WebSocket server: cannot listen on {addr}: ",
                command[0]
            );
            let last = err.lines().last().unwrap_or_default();
            assert!(last.starts_with(&says), "{last}");
            assert!(last.contains(why), "{last}");
            assert!(!Path::new(mcap).exists(), "{command:?}: no MCAP file");
        }
    }
}
