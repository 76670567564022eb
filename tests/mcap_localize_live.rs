//! `replay --http ADDR --mcap FILE` and `proxy --http ADDR --mcap FILE` (docs/robotics.md):
//! the live localizer's estimates of a replayed recording on `/estimates/tags` and a scene of
//! them on `/scene`, with no truth, read by the independent readers of
//! `scripts/interop/mcap_check.py` (`LLRP_MCAP_PYTHON`) and compared with what the HTTP API
//! said.

use std::collections::BTreeSet;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::process::Stdio;
use std::time::{Duration, Instant};

use serde_json::Value;

mod mcap_support;
use mcap_support::*;

fn fixture(name: &str) -> String {
    let p = root().join("fixtures/localize").join(name);
    p.to_str().expect("utf-8").to_string()
}

/// `llrp-gateway ARGS` with the S1 recording's poses and settings, its localizer's HTTP API
/// on a free loopback port, writing `mcap`; it, its LLRP and its HTTP address.
fn localizing(args: &[&str], mcap: &str) -> (Proc, String, String) {
    let mut child = bin()
        .args(args)
        .args(["--http", "127.0.0.1:0", "--poses"])
        .arg(fixture("s1-report-per-read.poses.jsonl"))
        .arg("--localize-settings")
        .arg(fixture("s1-report-per-read.settings.json"))
        .args(["--mcap", mcap])
        .stderr(Stdio::piped())
        .stdout(Stdio::null())
        .spawn()
        .expect("it starts");
    let mut lines = BufReader::new(child.stderr.take().expect("piped")).lines();
    let until = Instant::now() + GUARD;
    let (mut http, mut llrp) = (None, None);
    while http.is_none() || llrp.is_none() {
        assert!(Instant::now() < until, "{args:?} did not listen");
        let line = lines.next().expect("a line").expect("utf-8");
        if let Some(rest) = line.split("live map on http://").nth(1) {
            http = Some(rest.trim_end_matches('/').to_string());
        }
        if let Some(rest) = line.split("listening on ").nth(1) {
            llrp = Some(
                rest.split([' ', ','])
                    .next()
                    .expect("an address")
                    .to_string(),
            );
        }
    }
    std::thread::spawn(move || for _ in lines {});
    let (llrp, http) = (llrp.expect("LLRP"), http.expect("HTTP"));
    (Proc(child), llrp, http)
}

/// `POST path` of `body` (JSON) to the HTTP API at `addr`; its status must be 202.
fn post(addr: &str, path: &str, body: &str) {
    let mut s = TcpStream::connect(addr).expect("connects");
    write!(
        s,
        "POST {path} HTTP/1.1\r\nHost: {addr}\r\nContent-Type: application/json\r\n\
         Content-Length: {}\r\nConnection: close\r\n\r\n{body}",
        body.len()
    )
    .expect("request");
    let mut text = String::new();
    s.read_to_string(&mut text).expect("response");
    assert!(text.starts_with("HTTP/1.1 202"), "{text}");
}

/// Waits (a hang guard) until the API shows `reader`'s antenna 2 at `x`: the localizer has
/// taken the poses posted.
fn wait_for_poses(http: &str, reader: &str, x: f64) {
    let until = Instant::now() + GUARD;
    loop {
        let readers = get_json(http, "/api/readers");
        let found = (readers["readers"].as_array().into_iter().flatten())
            .filter(|r| r["name"] == reader)
            .flat_map(|r| r["antennas"].as_array().into_iter().flatten())
            .any(|a| a["antenna"] == 2 && a["pose"]["x"].as_f64() == Some(x));
        if found {
            return;
        }
        assert!(
            Instant::now() < until,
            "the poses were not taken: {readers}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// The poses posted of `robot-a`'s antenna 2 (at `written` x, each y 1.5, z 0.75, facing
/// +y), as both readers decode them: on its pose topic and on `/tf` from `map`, the one at
/// `skipped` on neither; and its antenna drawn in the last scene at the newest.
fn assert_posted_poses(mcap: &std::path::Path, written: &[f64], skipped: f64) {
    let v = check(mcap);
    let ch = channels(&v);
    let topic = "/llrp/robot_a/antenna_2/pose";
    assert_eq!(ch[topic].0, "foxglove_msgs/msg/PoseInFrame");
    assert_eq!(ch["/tf"].0, "tf2_msgs/msg/TFMessage");
    let half = std::f64::consts::FRAC_1_SQRT_2;
    for decoder in ["mcap_ros2", "rosbags"] {
        let poses: Vec<&Value> = (v[decoder]["poses"].as_array().expect("poses").iter())
            .filter(|p| p["topic"] == topic)
            .collect();
        let xs: Vec<f64> = poses.iter().map(|p| p["x"].as_f64().expect("x")).collect();
        assert_eq!(xs, written, "{decoder}: {poses:?}");
        for p in &poses {
            assert_eq!(p["frame_id"], "map", "{decoder}");
            assert_eq!((p["y"].as_f64(), p["z"].as_f64()), (Some(1.5), Some(0.75)));
            assert!((p["qz"].as_f64().expect("qz") - half).abs() < 1e-12, "{p}");
            assert!((p["qw"].as_f64().expect("qw") - half).abs() < 1e-12, "{p}");
        }
        let tf: Vec<f64> = (v[decoder]["tf"].as_array().expect("tf").iter())
            .filter(|t| t["child"] == "robot_a/antenna_2")
            .inspect(|t| assert_eq!(t["parent"], "map", "{decoder}"))
            .map(|t| t["x"].as_f64().expect("x"))
            .collect();
        assert_eq!(tf, written, "{decoder}");
        assert!(!xs.contains(&skipped) && !tf.contains(&skipped));
    }
    let scenes = v["mcap_ros2"]["scenes"].as_array().expect("scenes");
    let last = scenes.last().expect("a scene");
    let antenna = (last["entities"].as_array().expect("entities").iter())
        .find(|e| e["id"] == "antenna/robot_a/antenna_2")
        .unwrap_or_else(|| panic!("the posted antenna is not drawn: {last}"));
    let newest = written.last().expect("a pose written");
    assert_eq!(antenna["arrows"][0]["position"][0].as_f64(), Some(*newest));
}

/// Waits (a hang guard, not a measurement) until the localizer has a position for `want` of
/// the recording's ten tags; their EPCs.
fn wait_for_estimates(http: &str, want: usize) -> BTreeSet<String> {
    let until = Instant::now() + 3 * GUARD;
    loop {
        let tags = get_json(http, "/api/tags");
        let placed: BTreeSet<String> = (tags["tags"].as_array().expect("tags").iter())
            .filter(|t| t["state"] == "converged" || t["state"] == "converging")
            .map(|t| t["epc"].as_str().expect("epc").to_uppercase())
            .collect();
        if placed.len() >= want {
            return placed;
        }
        assert!(
            Instant::now() < until,
            "the localizer has not placed them: {tags}"
        );
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// The client the recording was made with, asking what it asked then, of `llrp`.
fn inventory(llrp: &str) {
    run(&[
        "inventory",
        llrp,
        "--impinj",
        "--report-every",
        "1",
        "--seconds",
        "3",
    ]);
}

#[test]
#[ignore = "needs the MCAP readers (LLRP_MCAP_PYTHON: scripts/venv-mcap.sh, set by ./scripts/test)"]
fn a_replay_that_localizes_writes_its_estimates_and_their_scene_without_truth() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mcap = dir.path().join("replay.mcap");
    let recording = fixture("s1-report-per-read.jsonl");
    let args = [
        "replay",
        &recording,
        "--listen",
        "127.0.0.1:0",
        "--speed",
        "max",
    ];
    let (mut replay, llrp, http) = localizing(&args, mcap.to_str().expect("utf-8"));
    inventory(&llrp);
    let placed = wait_for_estimates(&http, 10);
    // A robot's antenna, posted as a robot would: 100 ms of its clock apart at most one
    // is written, so the second is not.
    let posted = [(1_000_000, 2.5), (1_050_000, 2.75), (1_200_000, 3.25)];
    let body: Vec<Value> = (posted.iter())
        .map(|(t, x)| {
            serde_json::json!({"t_us": t, "reader": "robot-a", "antenna": 2, "x": x,
                "y": 1.5, "z": 0.75, "yaw_deg": 90.0, "pitch_deg": 0.0})
        })
        .collect();
    post(&http, "/api/poses", &Value::Array(body).to_string());
    wait_for_poses(&http, "robot-a", 3.25);
    terminate(&mut replay);
    assert_estimates_and_scene(&mcap, &placed);
    assert_posted_poses(&mcap, &[2.5, 3.25], 2.75);
}

#[test]
#[ignore = "needs the MCAP readers (LLRP_MCAP_PYTHON: scripts/venv-mcap.sh, set by ./scripts/test)"]
fn a_proxy_that_localizes_writes_its_estimates_and_their_scene_without_truth() {
    let dir = tempfile::tempdir().expect("temp dir");
    let recording = fixture("s1-report-per-read.jsonl");
    let (mut replay, upstream) = spawn_listening(&[
        "replay",
        &recording,
        "--listen",
        "127.0.0.1:0",
        "--speed",
        "max",
    ]);
    // The proxy names its reader as the recording and the pose file do.
    let config = dir.path().join("gateway.json");
    let proxies = serde_json::json!({"proxies": [
        {"name": "s1-reader", "upstream": upstream, "listen": "127.0.0.1:0"}
    ]});
    std::fs::write(&config, proxies.to_string()).expect("the config");
    let mcap = dir.path().join("proxy.mcap");
    let args = ["proxy", "--config", config.to_str().expect("utf-8")];
    let (mut proxy, llrp, http) = localizing(&args, mcap.to_str().expect("utf-8"));
    inventory(&llrp);
    // Any tag: in a debug build the proxy relays as fast as the MCAP writer compresses
    // (about 1,000 frames/s here), and under load not every tag has been placed by the hang
    // guard (noted on issue 44); what is checked is that those placed are in the file.
    let placed = wait_for_estimates(&http, 1);
    terminate(&mut proxy);
    terminate(&mut replay);
    assert_estimates_and_scene(&mcap, &placed);
}

/// Both readers decode `mcap`'s estimates and scenes alike; every tag of `placed` has
/// estimates, and the last scene holds estimates only (no truth), each placed tag's drawn at
/// the position of one of its estimates logged by then.
fn assert_estimates_and_scene(mcap: &std::path::Path, placed: &BTreeSet<String>) {
    let v = check(mcap);
    let ch = channels(&v);
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
    assert!(epcs.is_superset(placed), "{epcs:?} vs {placed:?}");
    let scenes = v["mcap_ros2"]["scenes"].as_array().expect("scenes");
    let last = scenes.last().expect("a scene");
    let mut drawn = BTreeSet::new();
    for e in last["entities"].as_array().expect("entities") {
        let id = e["id"].as_str().expect("an id");
        // The antennas of the poses received are drawn too (the pose file's, here).
        if id.starts_with("antenna/") || id.starts_with("path/") {
            continue;
        }
        drawn.insert(drawn_estimate(e, estimates));
    }
    assert!(drawn.is_superset(placed), "{drawn:?} vs {placed:?}");
}
