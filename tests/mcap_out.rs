//! MCAP out (docs/robotics.md): `export RECORDING --mcap FILE` and `inventory --mcap FILE`,
//! each file read by independent readers (Foxglove's Python `mcap` with
//! `mcap-ros2-support`, and `rosbags`, through `scripts/interop/mcap_check.py` in the venv of
//! `scripts/venv-mcap.sh`, named by `LLRP_MCAP_PYTHON`): the channels and their schemas, the
//! message counts, the frames byte for byte, and the decoded reads against the JSON Lines
//! reads of the same run.

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use llrp_gateway::reads::{read_jsonl, Read};
use llrp_gateway::record::{Direction, Entry, Recording};
use serde_json::Value;

/// Longest any wait below may take (a hang guard, not a measurement).
const GUARD: Duration = Duration::from_secs(60);

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_llrp-gateway"))
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// What the two readers make of `mcap` (`scripts/interop/mcap_check.py`).
fn check(mcap: &Path) -> Value {
    let python = std::env::var("LLRP_MCAP_PYTHON").expect(
        "LLRP_MCAP_PYTHON must name the python of scripts/venv-mcap.sh (set by ./scripts/test)",
    );
    let out = Command::new(python)
        .arg(root().join("scripts/interop/mcap_check.py"))
        .arg(mcap)
        .output()
        .expect("the checker runs");
    assert!(
        out.status.success(),
        "the readers refused {}: {}",
        mcap.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("the checker prints JSON")
}

/// Runs `llrp-gateway ARGS` to its end; its standard error.
fn run(args: &[&str]) -> String {
    let out = bin().args(args).output().expect("runs");
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "llrp-gateway {args:?}: {err}");
    err
}

/// The frames of `recording`, each connection and direction's bytes concatenated in file
/// order (hex), by the topic the MCAP file gives them (the reader's token is `token`).
fn recorded_streams(recording: &Recording, token: &str) -> BTreeMap<String, String> {
    let mut streams = BTreeMap::<String, String>::new();
    for e in &recording.entries {
        let (conn, dir, bytes) = match e {
            Entry::Frame {
                conn, dir, frame, ..
            } => (conn, dir, frame),
            Entry::Bytes {
                conn, dir, bytes, ..
            } => (conn, dir, bytes),
            _ => continue,
        };
        let side = match dir {
            Direction::ToReader => "to_reader",
            Direction::FromReader => "from_reader",
        };
        let hex: String = bytes.iter().map(|b| format!("{b:02x}")).collect();
        streams
            .entry(format!("/llrp/{token}/conn_{conn}/{side}"))
            .or_default()
            .push_str(&hex);
    }
    streams
}

/// A read as the checker prints it (floats as their IEEE 754 bits), as a [`Read`].
fn read_of(v: &Value) -> Read {
    let float = |k: &str| v[k].as_u64().map(f64::from_bits);
    let int = |k: &str| v[k].as_u64();
    Read {
        epc: llrp_gateway::reads::Epc::parse(v["epc"].as_str().expect("epc")).expect("an EPC"),
        reader: v["reader"]
            .as_str()
            .filter(|s| !s.is_empty())
            .map(|s| llrp_gateway::reads::ReaderName::parse(s).expect("a reader name")),
        antenna: int("antenna").expect("antenna") as u16,
        t_us: int("t_us").expect("t_us"),
        phase_rad: float("phase_rad"),
        rssi_dbm: float("rssi_dbm"),
        channel_index: int("channel_index").map(|c| c as u16),
        channel_frequency_hz: int("channel_frequency_hz"),
        doppler_hz: float("doppler_hz"),
        antenna_pose: None,
        last_seen_us: int("last_seen_us"),
    }
}

/// The reads file at `path`, its float fields read from their text exactly (Rust's
/// correctly rounded `str::parse`; serde_json's own parser may be off by one unit in the last
/// place, which would hide or fake a difference of that size).
fn reads_file(path: &Path) -> Vec<Read> {
    let text = std::fs::read_to_string(path).expect("the reads file");
    let mut reads = read_jsonl(text.as_bytes()).expect("reads");
    for (read, line) in reads.iter_mut().zip(text.lines()) {
        let exact = |key: &str| {
            let at = line.find(&format!("\"{key}\":"))? + key.len() + 3;
            let value = &line[at..];
            let end = value.find([',', '}']).expect("a value's end");
            value[..end].parse::<f64>().ok()
        };
        read.phase_rad = exact("phase_rad");
        read.rssi_dbm = exact("rssi_dbm");
        read.doppler_hz = exact("doppler_hz");
    }
    reads
}

/// The reads of one decoder's output, sorted (MCAP readers return messages by time, the
/// reads file has them as they arrived; reads of one report share a time).
fn decoded_reads(decoded: &Value) -> Vec<Read> {
    let mut reads: Vec<Read> = decoded["reads"]
        .as_array()
        .expect("reads")
        .iter()
        .map(read_of)
        .collect();
    sort(&mut reads);
    reads
}

fn sort(reads: &mut [Read]) {
    reads.sort_by(|a, b| {
        (a.t_us, a.epc.as_str(), a.antenna, a.channel_index)
            .cmp(&(b.t_us, b.epc.as_str(), b.antenna, b.channel_index))
            .then(a.phase_rad.partial_cmp(&b.phase_rad).expect("no NaN"))
    });
}

/// The channels as `topic → (schema, count)`, each `ros2msg` and `cdr` with its QoS.
fn channels(v: &Value) -> BTreeMap<String, (String, u64)> {
    let mut out = BTreeMap::new();
    for c in v["channels"].as_array().expect("channels") {
        assert_eq!(c["schema_encoding"], "ros2msg", "{c}");
        assert_eq!(c["message_encoding"], "cdr", "{c}");
        assert!(
            c["qos"].as_str().is_some_and(|q| q.contains("reliability")),
            "offered_qos_profiles: {c}"
        );
        out.insert(
            c["topic"].as_str().expect("topic").to_string(),
            (
                c["schema"].as_str().expect("schema").to_string(),
                c["count"].as_u64().expect("count"),
            ),
        );
    }
    out
}

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

/// A child process killed if the test panics.
struct Proc(Child);

impl Drop for Proc {
    fn drop(&mut self) {
        if matches!(self.0.try_wait(), Ok(None)) {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
}

/// `llrp-gateway sim` on a free loopback port recording to `record`; it and its address.
fn sim_recording(record: &Path) -> (Proc, String) {
    let mut child = bin()
        .args(["sim", "--no-http", "--listen", "127.0.0.1:0", "--record"])
        .arg(record)
        .stderr(Stdio::piped())
        .stdout(Stdio::null())
        .spawn()
        .expect("sim starts");
    let mut lines = BufReader::new(child.stderr.take().expect("piped")).lines();
    let until = Instant::now() + GUARD;
    let addr = loop {
        assert!(Instant::now() < until, "sim did not listen");
        let line = lines.next().expect("a line").expect("utf-8");
        if let Some(rest) = line.split("listening on ").nth(1) {
            break rest
                .split_whitespace()
                .next()
                .expect("an address")
                .to_string();
        }
    };
    // Keep reading its log so that it never blocks on a full pipe.
    std::thread::spawn(move || for _ in lines {});
    (Proc(child), addr)
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
    assert_eq!(
        channels(&v),
        BTreeMap::from([(
            topic.clone(),
            (
                "llrp_gateway_msgs/msg/TagRead".to_string(),
                reads.len() as u64
            )
        )])
    );
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
