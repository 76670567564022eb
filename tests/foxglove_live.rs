//! `sim --foxglove ADDR` (docs/robotics.md "Live in Foxglove") against an independent client
//! of Foxglove's WebSocket protocol, `scripts/interop/foxglove_client.py` (Python `websockets`
//! with `mcap-ros2-support`'s CDR decoder, in the venv of `scripts/venv-mcap.sh`:
//! `LLRP_MCAP_PYTHON`), and the layout file `docs/foxglove-layout.json` against the channels
//! the server advertises.

use std::collections::{BTreeMap, BTreeSet};
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Instant;

mod mcap_support;
use mcap_support::*;

/// `llrp-gateway sim ARGS`: it, its reader's LLRP address and its Foxglove address (from
/// its log).
fn spawn_sim(args: &[&str]) -> (Proc, String, String) {
    let mut child = bin()
        .arg("sim")
        .args(args)
        .stderr(Stdio::piped())
        .stdout(Stdio::null())
        .spawn()
        .expect("it starts");
    let mut lines = BufReader::new(child.stderr.take().expect("piped")).lines();
    let until = Instant::now() + GUARD;
    let (mut llrp, mut ws) = (None, None);
    while llrp.is_none() || ws.is_none() {
        assert!(Instant::now() < until, "sim {args:?} did not listen");
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
    let (mut sim, llrp, ws) = spawn_sim(&[
        "--no-http",
        "--listen",
        "127.0.0.1:0",
        "--foxglove",
        "127.0.0.1:0",
        "--mcap",
        &path("sim.mcap"),
    ]);
    let python = std::env::var("LLRP_MCAP_PYTHON").expect(
        "LLRP_MCAP_PYTHON must name the python of scripts/venv-mcap.sh (set by ./scripts/test)",
    );
    let mut client = Command::new(python)
        .arg(root().join("scripts/interop/foxglove_client.py"))
        .args([ws.as_str(), "20", "30"])
        .stdout(Stdio::piped())
        .spawn()
        .expect("the client starts");
    let mut out = BufReader::new(client.stdout.take().expect("piped")).lines();
    let ready = out.next().expect("a line").expect("utf-8");
    assert_eq!(ready, "READY", "the client subscribed");
    run(&[
        "inventory",
        &llrp,
        "--seconds",
        "2",
        "--impinj",
        "--output",
        &path("reads.jsonl"),
    ]);
    let line = out.next().expect("the client's report").expect("utf-8");
    let client = Proc(client);
    let v: serde_json::Value = serde_json::from_str(&line).expect("JSON");
    assert!(
        matches!(sim.0.try_wait(), Ok(None)),
        "the simulator still runs"
    );
    terminate(&mut sim);
    drop(client);

    // The handshake without the subprotocol is refused; every hostile request gets an
    // error status, and the clients after it are served.
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

    // The channels: ROS 2 ones, each also in the MCAP file with the same schema.
    let file = channels(&check(Path::new(&path("sim.mcap"))));
    let mut live = BTreeMap::new();
    for c in v["channels"].as_array().expect("channels") {
        assert_eq!(c["encoding"], "cdr", "{c}");
        assert_eq!(c["schemaEncoding"], "ros2msg", "{c}");
        let topic = c["topic"].as_str().expect("topic").to_string();
        let schema = c["schemaName"].as_str().expect("schema").to_string();
        assert_eq!(file.get(&topic).map(|c| &c.0), Some(&schema), "{topic}");
        assert!(live.insert(topic, schema).is_none(), "advertised once");
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
    ] {
        assert_eq!(live.get(topic).map(String::as_str), Some(schema), "{topic}");
    }
    for topic in layout_topics() {
        assert!(live.contains_key(&topic), "the layout's {topic} is served");
    }

    // The reads, decoded from CDR by the client: tags the inventory read, sane values.
    let epcs: BTreeSet<String> = reads_file(Path::new(&path("reads.jsonl")))
        .iter()
        .map(|r| r.epc.to_string())
        .collect();
    let reads = v["reads"].as_array().expect("reads");
    assert!(reads.len() >= 20, "{} reads arrived", reads.len());
    for r in reads {
        let epc = r["epc"].as_str().expect("epc");
        assert!(epcs.contains(epc), "{epc} is among {epcs:?}");
        let rssi = r["rssi_dbm"].as_f64().expect("a number");
        assert!((-100.0..=-20.0).contains(&rssi), "RSSI {rssi}");
        assert_eq!(r["reader"], "s1-reader");
        let antenna = r["antenna"].as_u64().expect("antenna");
        assert_eq!(r["frame_id"], format!("s1_reader/antenna_{antenna}"));
        assert!(r["log_time"].as_u64().expect("log time") > 0);
    }
    // The poses and transforms, the still tags' positions sent once at the start (a new
    // subscriber gets a channel's latest message), the reader's events.
    for key in ["poses", "tf", "tags", "events"] {
        assert!(v[key].as_u64().expect("a count") > 0, "{key}: {v}");
    }
    assert_eq!(v["bad_subscription_ids"], 0);
}
