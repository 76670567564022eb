//! A localizer worker's `--mcap FILE` and `--foxglove ADDR` (docs/robotics.md): `sim
//! --publish` → a real mosquitto → `localize --subscribe URL`, whose file holds the estimates
//! it computed on `/estimates/tags` and a scene of them on `/scene`, read by the independent
//! readers of `scripts/interop/mcap_check.py` (`LLRP_MCAP_PYTHON`), and whose live view
//! streams the same two channels to the independent client
//! `scripts/interop/foxglove_client.py`.

mod broker_support;
mod http_support;
mod mcap_support;

use serde_json::Value;
use std::collections::BTreeSet;
use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use broker_support::{publishing_sim, worker, Mosquitto};
use http_support::request;

/// Waits (a hang guard, not a measurement) until the worker at `http` has a position for
/// three tags at least; the EPCs it has a position for.
fn wait_for_estimates(http: std::net::SocketAddr) -> BTreeSet<String> {
    let until = Instant::now() + mcap_support::GUARD;
    loop {
        let tags = request(http, "GET", "/api/tags", &[], b"").json();
        let placed: BTreeSet<String> = (tags["tags"].as_array().expect("tags").iter())
            .filter(|t| t["state"] == "converged" || t["state"] == "converging")
            .map(|t| t["epc"].as_str().expect("epc").to_uppercase())
            .collect();
        if placed.len() >= 3 {
            return placed;
        }
        assert!(
            Instant::now() < until,
            "the worker has not placed them: {tags}"
        );
        std::thread::sleep(Duration::from_millis(200));
    }
}

#[test]
#[ignore = "needs mosquitto (./scripts/install-brokers) and the MCAP readers (LLRP_MCAP_PYTHON); ./scripts/test runs it"]
fn a_worker_s_mcap_file_holds_the_estimates_it_computed_and_their_scene() {
    let broker = Mosquitto::start("");
    let url = broker.url("x");
    let dir = tempfile::tempdir().expect("temp dir");
    let mcap = dir.path().join("worker.mcap");
    let (mut w, http) = worker(
        &url,
        &[
            "--client-id",
            "mcap-worker",
            "--mcap",
            mcap.to_str().expect("utf-8"),
        ],
    );
    let placed = {
        let _sim = publishing_sim(&url, &["--poses", "truth"]);
        wait_for_estimates(http)
    };
    assert!(w.stop().success(), "the worker stopped cleanly");
    let v = mcap_support::check(&mcap);
    let ch = mcap_support::channels(&v);
    assert_eq!(ch["/estimates/tags"].0, "llrp_gateway_msgs/msg/TagEstimate");
    assert_eq!(ch["/scene"].0, "foxglove_msgs/msg/SceneUpdate");
    for decoder in ["mcap_ros2", "rosbags"] {
        assert_eq!(v[decoder]["scenes"], v["mcap_ros2"]["scenes"], "{decoder}");
        assert_eq!(
            v[decoder]["estimates"], v["mcap_ros2"]["estimates"],
            "{decoder}"
        );
    }
    let estimates = v["mcap_ros2"]["estimates"].as_array().expect("estimates");
    let epcs: BTreeSet<String> = (estimates.iter())
        .map(|e| e["epc"].as_str().expect("epc").to_string())
        .collect();
    assert!(epcs.is_superset(&placed), "{epcs:?} vs {placed:?}");
    let scenes = v["mcap_ros2"]["scenes"].as_array().expect("scenes");
    let last = scenes.last().expect("a scene");
    // The antenna poses the worker received over MQTT: on their topics, on /tf, and drawn
    // where one of them put the antenna.
    let pose_topic = "/llrp/s1_reader/antenna_1/pose";
    assert_eq!(ch[pose_topic].0, "foxglove_msgs/msg/PoseInFrame");
    let poses: Vec<&Value> = (v["mcap_ros2"]["poses"].as_array().expect("poses").iter())
        .filter(|p| p["topic"] == pose_topic)
        .collect();
    let tf = v["mcap_ros2"]["tf"].as_array().expect("tf");
    for p in &poses {
        let at = |m: &Value| ["x", "y", "z"].map(|k| m[k].as_f64());
        assert!(
            (tf.iter()).any(|t| t["child"] == "s1_reader/antenna_1" && at(t) == at(p)),
            "{p} is on /tf"
        );
    }
    let mut drawn = BTreeSet::new();
    for e in last["entities"].as_array().expect("entities") {
        let id = e["id"].as_str().expect("an id");
        if id == "antenna/s1_reader/antenna_1" {
            let arrow = &e["arrows"][0]["position"];
            assert!(
                (poses.iter()).any(|p| *arrow == serde_json::json!([p["x"], p["y"], p["z"]])),
                "the antenna is drawn where a pose put it: {arrow}"
            );
            continue;
        }
        if id.starts_with("antenna/") || id.starts_with("path/") {
            continue;
        }
        drawn.insert(mcap_support::drawn_estimate(e, estimates));
    }
    assert!(drawn.is_superset(&placed), "{drawn:?} vs {placed:?}");
}

#[test]
#[ignore = "needs mosquitto (./scripts/install-brokers) and the Foxglove client's venv (LLRP_MCAP_PYTHON); ./scripts/test runs it"]
fn a_worker_s_live_view_streams_its_estimates_and_their_scene() {
    let broker = Mosquitto::start("");
    let url = broker.url("f");
    let (mut w, _http) = worker(
        &url,
        &[
            "--client-id",
            "foxglove-worker",
            "--foxglove",
            "127.0.0.1:0",
        ],
    );
    let ws = w.address("Foxglove live view on ");
    let python = std::env::var("LLRP_MCAP_PYTHON").expect(
        "LLRP_MCAP_PYTHON must name the python of scripts/venv-mcap.sh (set by ./scripts/test)",
    );
    // No reads to wait for; done once a scene that draws an estimate has come. Its channels are advertised with
    // the worker's first estimate, so the client subscribes once the simulation runs.
    let mut client = Command::new(python)
        .arg(mcap_support::root().join("scripts/interop/foxglove_client.py"))
        .args([ws.as_str(), "0", "30", "estimate_scenes"])
        .stdout(Stdio::piped())
        .spawn()
        .expect("the client starts");
    let mut out = BufReader::new(client.stdout.take().expect("piped")).lines();
    let report: serde_json::Value = {
        let _sim = publishing_sim(&url, &["--poses", "truth"]);
        let ready = out.next().expect("a line").expect("utf-8");
        assert_eq!(ready, "READY", "the client subscribed");
        let line = out.next().expect("the client's report").expect("utf-8");
        serde_json::from_str(&line).expect("JSON")
    };
    assert!(client.wait().expect("the client ends").success());
    assert!(w.stop().success(), "the worker stopped cleanly");
    let channels: BTreeSet<(String, String)> = (report["channels"].as_array())
        .expect("channels")
        .iter()
        .map(|c| {
            assert_eq!(
                (c["encoding"].as_str(), c["schemaEncoding"].as_str()),
                (Some("cdr"), Some("ros2msg")),
                "{c}"
            );
            (
                c["topic"].as_str().expect("a topic").to_string(),
                c["schemaName"].as_str().expect("a schema").to_string(),
            )
        })
        .collect();
    let want: BTreeSet<(String, String)> = [
        ("/estimates/tags", "llrp_gateway_msgs/msg/TagEstimate"),
        ("/scene", "foxglove_msgs/msg/SceneUpdate"),
        (
            "/llrp/s1_reader/antenna_1/pose",
            "foxglove_msgs/msg/PoseInFrame",
        ),
        ("/tf", "tf2_msgs/msg/TFMessage"),
    ]
    .map(|(t, s)| (t.to_string(), s.to_string()))
    .into();
    assert_eq!(
        channels, want,
        "a worker streams its estimates, their scene and the antenna poses it received only"
    );
    assert!(
        report["counts"]["/estimates/tags"].as_u64() >= Some(1),
        "{report}"
    );
    assert!(report["estimate_scenes"].as_u64() >= Some(1), "{report}");
    let ids = report["scene_ids"].as_array().expect("ids");
    assert!(!ids.is_empty(), "{report}");
    for id in ids {
        let id = id.as_str().expect("an id");
        // The antenna the poses it received put there, or an estimate: no truth.
        assert!(
            id.starts_with("estimate/") || id.ends_with("s1_reader/antenna_1"),
            "a worker knows no truth: {id}"
        );
    }
}
