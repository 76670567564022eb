//! `--publish` beside the gateway: the proxy's reads, events and statuses reach the broker
//! as the simulator's do, and a replayed recording published to a real mosquitto, with its
//! poses published as a robot would, localizes at a worker as `localize` does offline.

mod broker_support;
mod http_support;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use broker_support::{worker, Mosquitto, Probe};
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

/// `proxy --upstream UPSTREAM --publish URL` and `extra` on a free port, once it listens; its
/// LLRP address.
fn publishing_proxy(upstream: &str, url: &str, extra: &[&str]) -> (Proc, String) {
    let mut args = vec![
        "proxy",
        "--upstream",
        upstream,
        "--listen",
        "127.0.0.1:0",
        "--publish",
        url,
    ];
    args.extend_from_slice(extra);
    let mut proxy = Proc::spawn(&args);
    let llrp = proxy.address("listening on ");
    (proxy, llrp)
}

#[test]
#[ignore = "needs mosquitto (./scripts/install-brokers); ./scripts/test runs it"]
fn the_proxy_publishes_its_readers_reads_events_and_statuses() {
    let broker = Mosquitto::start("");
    let probe = Probe::connect(
        broker.port,
        "proxy-probe",
        &["g/v1/reads/+", "g/v1/events/+", "g/v1/status/+"],
    );
    let mut sim = Proc::spawn(&[
        "sim",
        "--no-http",
        "--listen",
        "127.0.0.1:0",
        "--speed",
        "8",
    ]);
    let upstream = sim.address("listening on ");
    let (proxy, llrp) =
        publishing_proxy(&upstream, &broker.url("g"), &["--gateway-name", "edge-1"]);
    let status = bin()
        .args(["inventory", &llrp, "--impinj", "--seconds", "2"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .expect("inventory runs");
    assert!(status.success());
    drop(proxy);
    let messages = probe.drain(Duration::from_secs(2));
    let json = |p: &[u8]| serde_json::from_slice::<serde_json::Value>(p).expect("JSON");
    let batches: Vec<_> = messages
        .iter()
        .filter(|m| m.0.starts_with("g/v1/reads/"))
        .map(|m| json(&m.1))
        .collect();
    assert!(!batches.is_empty(), "no read batches");
    for b in &batches {
        assert_eq!(
            (b["reader"].as_str(), b["gateway"].as_str()),
            (Some("reader"), Some("edge-1"))
        );
        let r = &b["reads"][0];
        assert!(
            r["epcHex"].is_string() && r["phaseAngle"].is_number(),
            "{b}"
        );
        assert!(r["frequency"].as_u64().is_some_and(|k| k > 800_000), "{b}");
    }
    let events: Vec<_> = messages
        .iter()
        .filter(|m| m.0 == "g/v1/events/reader")
        .map(|m| json(&m.1))
        .collect();
    assert!(
        events
            .iter()
            .any(|e| !e["event"]["connection_attempt_event"].is_null()),
        "{events:?}"
    );
    let statuses: Vec<String> = messages
        .iter()
        .filter(|m| m.0 == "g/v1/status/reader")
        .map(|m| {
            json(&m.1)["status"]
                .as_str()
                .unwrap_or_default()
                .to_string()
        })
        .collect();
    assert_eq!(
        statuses.first().map(String::as_str),
        Some("online"),
        "{statuses:?}"
    );
    assert_eq!(
        statuses.last().map(String::as_str),
        Some("offline"),
        "{statuses:?}"
    );
}

#[test]
#[ignore = "needs mosquitto (./scripts/install-brokers); ./scripts/test runs it"]
fn the_inventory_client_publishes_what_it_reads() {
    let broker = Mosquitto::start("");
    let probe = Probe::connect(broker.port, "inventory-probe", &["i/v1/reads/+"]);
    let mut sim = Proc::spawn(&[
        "sim",
        "--no-http",
        "--listen",
        "127.0.0.1:0",
        "--speed",
        "8",
    ]);
    let llrp = sim.address("listening on ");
    let dir = tempfile::tempdir().expect("temp dir");
    let file = dir.path().join("reads.jsonl");
    let status = bin()
        .args([
            "inventory",
            &llrp,
            "--impinj",
            "--seconds",
            "2",
            "--name",
            "dock",
        ])
        .args(["--publish", &broker.url("i"), "--output"])
        .arg(&file)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .expect("inventory runs");
    assert!(status.success());
    let published: usize = probe
        .drain(Duration::from_secs(2))
        .iter()
        .map(|m| serde_json::from_slice::<serde_json::Value>(&m.1).expect("JSON"))
        .inspect(|b| assert_eq!(b["reader"], "dock", "{b}"))
        .map(|b| b["reads"].as_array().map_or(0, Vec::len))
        .sum();
    let written = std::fs::read_to_string(&file)
        .expect("reads file")
        .lines()
        .count();
    assert!(written > 0);
    assert_eq!(published, written, "every read written is published");
}

#[test]
#[ignore = "needs mosquitto (./scripts/install-brokers); ./scripts/test runs it"]
fn a_replay_published_with_a_robots_poses_localizes_at_a_worker_as_offline() {
    let rec = fixture("s1-report-per-read.jsonl");
    let poses = fixture("s1-report-per-read.poses.jsonl");
    let settings = fixture("s1-report-per-read.settings.json");
    let broker = Mosquitto::start("");
    let url = broker.url("g");
    let (_worker, http) = worker(&url, &["--settings", &settings]);
    // The robot publishes its poses (the pose file's keys, in its own clock).
    let robot = Probe::connect(broker.port, "robot", &[]);
    let text = std::fs::read_to_string(&poses).expect("pose file");
    let lines: Vec<serde_json::Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).expect("pose"))
        .collect();
    for chunk in lines.chunks(100) {
        let body = serde_json::to_vec(chunk).expect("JSON");
        robot.publish_acked("g/v1/poses/s1-reader/1", &body);
    }
    let mut replay = Proc::spawn(&[
        "replay",
        &rec,
        "--listen",
        "127.0.0.1:0",
        "--speed",
        "max",
        "--publish",
        &url,
    ]);
    let llrp = replay.address("listening on ");
    let status = bin()
        .args(["inventory", &llrp, "--impinj", "--report-every", "1"])
        .args(["--seconds", "3"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .expect("inventory runs");
    assert!(status.success());
    let deadline = Instant::now() + Duration::from_secs(60);
    let live = loop {
        let v = request(http, "GET", "/api/tags", &[], b"").json();
        let done = v["tags"]
            .as_array()
            .is_some_and(|t| t.len() == 10 && t.iter().all(|t| t["state"] == "converged"));
        if done || Instant::now() > deadline {
            break v;
        }
        std::thread::sleep(Duration::from_millis(100));
    };
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
    let tags = live["tags"].as_array().expect("tags");
    assert_eq!(tags.len(), 10, "{live}");
    for (a, b) in tags
        .iter()
        .zip(offline["tags"].as_array().expect("offline"))
    {
        assert_eq!(a["epc"], b["epc"]);
        let d = ["x", "y"]
            .map(|k| a["estimate"][k].as_f64().expect("p") - b["estimate"][k].as_f64().expect("q"));
        assert!(d[0].hypot(d[1]) < 1e-3, "{a} vs {b}");
    }
}

/// Sends SIGCONT to a process stopped with SIGSTOP when dropped (also when the test fails).
struct Stopped(u32);

impl Stopped {
    fn stop(pid: u32) -> Stopped {
        let ok = Command::new("kill")
            .args(["-STOP", &pid.to_string()])
            .status()
            .expect("kill runs")
            .success();
        assert!(ok, "SIGSTOP to {pid}");
        Stopped(pid)
    }
}

impl Drop for Stopped {
    fn drop(&mut self) {
        let _ = Command::new("kill")
            .args(["-CONT", &self.0.to_string()])
            .status();
    }
}

#[test]
#[ignore = "needs mosquitto (./scripts/install-brokers); ./scripts/test runs it"]
fn a_proxied_readers_keepalive_loss_and_return_are_published() {
    let broker = Mosquitto::start("");
    let probe = Probe::connect(broker.port, "keepalive-probe", &["k/v1/events/+"]);
    let mut sim = Proc::spawn(&["sim", "--no-http", "--listen", "127.0.0.1:0"]);
    let upstream = sim.address("listening on ");
    let (_proxy, llrp) = publishing_proxy(&upstream, &broker.url("k"), &[]);
    // KEEPALIVEs every 200 ms; the client itself gives up on the reader only after 5.6 s.
    let mut client = bin()
        .args([
            "inventory",
            &llrp,
            "--keepalive-ms",
            "200",
            "--seconds",
            "6",
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("inventory runs");
    std::thread::sleep(Duration::from_millis(1500));
    // The reader hangs for 1.5 s (over three periods) with its connection open, then goes on.
    {
        let _hung = Stopped::stop(sim.pid());
        std::thread::sleep(Duration::from_millis(1500));
    }
    assert!(client.wait().expect("inventory ends").success());
    let keepalive: Vec<serde_json::Value> = probe
        .drain(Duration::from_secs(2))
        .iter()
        .filter(|m| m.0 == "k/v1/events/reader")
        .map(|m| serde_json::from_slice::<serde_json::Value>(&m.1).expect("JSON"))
        .filter(|e| !e["keepalive"].is_null())
        .collect();
    let states: Vec<&str> = keepalive
        .iter()
        .map(|e| e["keepalive"]["state"].as_str().unwrap_or_default())
        .collect();
    assert_eq!(states, ["lost", "restored"], "{keepalive:?}");
    for e in &keepalive {
        assert_eq!(e["keepalive"]["periodMs"], 200, "{e}");
        assert!(e["keepalive"]["silentMs"].as_u64() >= Some(600), "{e}");
        assert_eq!(
            (e["reader"].as_str(), e["v"].as_u64()),
            (Some("reader"), Some(1))
        );
    }
    assert!(
        keepalive[1]["keepalive"]["silentMs"].as_u64() >= Some(1400),
        "restored after the whole hang: {}",
        keepalive[1]
    );
}
