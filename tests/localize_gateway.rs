//! The live localizer beside `replay` and `proxy` (`--http ADDR`): a replayed recording with
//! its pose file localizes as `localize` does offline; the proxy's tapped reads reach it.

mod http_support;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use http_support::{request, Proc};

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_llrp-gateway"))
}

fn fixture(name: &str) -> String {
    let p: PathBuf = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fixtures/localize")
        .join(name);
    p.to_str().expect("utf-8").to_string()
}

/// Polls `GET path` until `pred` holds on its JSON (at most 60 s); the last JSON.
fn poll(
    http: std::net::SocketAddr,
    path: &str,
    pred: impl Fn(&serde_json::Value) -> bool,
) -> serde_json::Value {
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        let v = request(http, "GET", path, &[], b"").json();
        if pred(&v) || Instant::now() > deadline {
            return v;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

#[test]
fn a_replayed_recording_localizes_live_as_localize_does_offline() {
    let rec = fixture("s1-report-per-read.jsonl");
    let poses = fixture("s1-report-per-read.poses.jsonl");
    let settings = fixture("s1-report-per-read.settings.json");
    let mut replay = Proc::spawn(&[
        "replay",
        &rec,
        "--listen",
        "127.0.0.1:0",
        "--speed",
        "max",
        "--http",
        "127.0.0.1:0",
        "--poses",
        &poses,
        "--localize-settings",
        &settings,
    ]);
    let http: std::net::SocketAddr = replay.address("live map on http://").parse().expect("addr");
    let llrp = replay.address("listening on ");
    // The client the recording was made with, asking what it asked then.
    let status = bin()
        .args(["inventory", &llrp, "--impinj", "--report-every", "1"])
        .args(["--seconds", "3"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .expect("inventory runs");
    assert!(status.success());
    // Every tag estimated: "converged", or "converging" where the covariance shows the
    // residuals' correlation along the pass (the recording's poses are the robot's own).
    let all_in = |v: &serde_json::Value| {
        v["tags"].as_array().is_some_and(|t| {
            t.len() == 10
                && t.iter()
                    .all(|t| t["state"] == "converged" || t["state"] == "converging")
        })
    };
    let live = poll(http, "/api/tags", all_in);
    assert!(all_in(&live), "{live}");
    let readers = request(http, "GET", "/api/readers", &[], b"").json();
    assert_eq!(readers["readers"][0]["name"], "s1-reader", "{readers}");

    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("offline.json");
    let ok = bin()
        .args(["localize", &rec, "--poses", &poses, "--settings", &settings])
        .arg("--output")
        .arg(&out)
        .stderr(Stdio::null())
        .status()
        .expect("localize runs")
        .success();
    assert!(ok);
    let offline: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).expect("written")).expect("JSON");
    for (a, b) in live["tags"]
        .as_array()
        .expect("live")
        .iter()
        .zip(offline["tags"].as_array().expect("offline"))
    {
        assert_eq!(a["epc"], b["epc"]);
        let d = ["x", "y"]
            .map(|k| a["estimate"][k].as_f64().expect("p") - b["estimate"][k].as_f64().expect("q"));
        assert!(d[0].hypot(d[1]) < 1e-3, "{a} vs {b}");
    }
}

#[test]
fn the_proxys_tapped_reads_reach_the_localizer() {
    let mut sim = Proc::spawn(&[
        "sim",
        "--no-http",
        "--listen",
        "127.0.0.1:0",
        "--speed",
        "8",
    ]);
    let upstream = sim.address("listening on ");
    let mut proxy = Proc::spawn(&[
        "proxy",
        "--upstream",
        &upstream,
        "--listen",
        "127.0.0.1:0",
        "--http",
        "127.0.0.1:0",
    ]);
    let http: std::net::SocketAddr = proxy.address("live map on http://").parse().expect("addr");
    let llrp = proxy.address("listening on ");
    let status = bin()
        .args(["inventory", &llrp, "--impinj", "--seconds", "2"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .expect("inventory runs");
    assert!(status.success());
    let readers = poll(http, "/api/readers", |v| {
        v["readers"][0]["reads"].as_u64().unwrap_or(0) > 0
    });
    assert_eq!(readers["readers"][0]["name"], "reader", "{readers}");
    assert!(
        readers["readers"][0]["reads"].as_u64().unwrap_or(0) > 0,
        "{readers}"
    );
    // No pose came: the reads are set aside as such, never guessed.
    let metrics = request(http, "GET", "/metrics", &[], b"").text();
    let count = |name: &str| -> u64 {
        metrics
            .lines()
            .find(|l| l.starts_with(name))
            .and_then(|l| l.split_whitespace().nth(1))
            .and_then(|v| v.parse().ok())
            .unwrap_or(0)
    };
    assert!(count("llrp_gateway_reads_total") > 0, "{metrics}");
    assert!(count("llrp_gateway_reads_set_aside_total") > 0, "{metrics}");
    let tags = request(http, "GET", "/api/tags", &[], b"").json();
    assert!(
        tags["tags"].as_array().is_some_and(
            |t| !t.is_empty() && t.iter().all(|t| t["state"] == "insufficient_geometry")
        ),
        "{tags}"
    );
}

#[test]
fn the_inventory_clients_reads_reach_its_localizer() {
    let rec = fixture("s1-report-per-read.jsonl");
    let poses = fixture("s1-report-per-read.poses.jsonl");
    let settings = fixture("s1-report-per-read.settings.json");
    // At 10× the recording's pace, not `max`: at `max` the client's localizer tap, which
    // drops rather than slow the client, dropped a fifth of the reads, and whether every tag
    // then converged was luck (the test waited for the replay's next round, 20 s on).
    let mut replay = Proc::spawn(&["replay", &rec, "--listen", "127.0.0.1:0", "--speed", "10"]);
    let llrp = replay.address("listening on ");
    let mut client = Proc::spawn(&[
        "inventory",
        &llrp,
        "--impinj",
        "--report-every",
        "1",
        "--seconds",
        "60",
        // The reader's name in the pose file and the settings.
        "--name",
        "s1-reader",
        "--http",
        "127.0.0.1:0",
        "--poses",
        &poses,
        "--localize-settings",
        &settings,
    ]);
    let http: std::net::SocketAddr = client.address("live map on http://").parse().expect("addr");
    // Every tag estimated: "converged", or "converging" where the covariance shows the
    // residuals' correlation along the pass (the recording's poses are the robot's own).
    let all_in = |v: &serde_json::Value| {
        v["tags"].as_array().is_some_and(|t| {
            t.len() == 10
                && t.iter()
                    .all(|t| t["state"] == "converged" || t["state"] == "converging")
        })
    };
    let tags = poll(http, "/api/tags", all_in);
    assert!(all_in(&tags), "{tags}");
}
