//! Shared helpers of the MCAP tests: run the binary, read a file with the independent
//! readers (`scripts/interop/mcap_check.py`), compare reads.
#![allow(dead_code)]

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use llrp_gateway::reads::{read_jsonl, Read};
use llrp_gateway::record::{Direction, Entry, Recording};
use serde_json::Value;

/// Longest any wait below may take (a hang guard, not a measurement).
pub const GUARD: Duration = Duration::from_secs(60);

pub fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_llrp-gateway"))
}

pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// What the two readers make of `mcap` (`scripts/interop/mcap_check.py`).
pub fn check(mcap: &Path) -> Value {
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
pub fn run(args: &[&str]) -> String {
    let out = bin().args(args).output().expect("runs");
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "llrp-gateway {args:?}: {err}");
    err
}

/// The frames of `recording`, each connection and direction's bytes concatenated in file
/// order (hex), by the topic the MCAP file gives them (the reader's token is `token`).
pub fn recorded_streams(recording: &Recording, token: &str) -> BTreeMap<String, String> {
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
pub fn read_of(v: &Value) -> Read {
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
pub fn reads_file(path: &Path) -> Vec<Read> {
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
pub fn decoded_reads(decoded: &Value) -> Vec<Read> {
    let mut reads: Vec<Read> = decoded["reads"]
        .as_array()
        .expect("reads")
        .iter()
        .map(read_of)
        .collect();
    sort(&mut reads);
    reads
}

pub fn sort(reads: &mut [Read]) {
    reads.sort_by(|a, b| {
        (a.t_us, a.epc.as_str(), a.antenna, a.channel_index)
            .cmp(&(b.t_us, b.epc.as_str(), b.antenna, b.channel_index))
            .then(a.phase_rad.partial_cmp(&b.phase_rad).expect("no NaN"))
    });
}

/// The channels as `topic → (schema, count)`, each `ros2msg` and `cdr` with its QoS.
pub fn channels(v: &Value) -> BTreeMap<String, (String, u64)> {
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

/// A child process killed if the test panics.
pub struct Proc(pub Child);

impl Drop for Proc {
    fn drop(&mut self) {
        if matches!(self.0.try_wait(), Ok(None)) {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
}

/// `llrp-gateway sim` on a free loopback port recording to `record`; it and its address.
pub fn sim_recording(record: &Path) -> (Proc, String) {
    let record = record.to_str().expect("utf-8");
    spawn_listening(&[
        "sim",
        "--no-http",
        "--listen",
        "127.0.0.1:0",
        "--record",
        record,
    ])
}

/// `llrp-gateway ARGS`, a command that logs "listening on ADDR"; it and that address.
pub fn spawn_listening(args: &[&str]) -> (Proc, String) {
    let mut child = bin()
        .args(args)
        .stderr(Stdio::piped())
        .stdout(Stdio::null())
        .spawn()
        .expect("it starts");
    let mut lines = BufReader::new(child.stderr.take().expect("piped")).lines();
    let until = Instant::now() + GUARD;
    let addr = loop {
        assert!(Instant::now() < until, "{args:?} did not listen");
        let line = lines.next().expect("a line").expect("utf-8");
        if let Some(rest) = line.split("listening on ").nth(1) {
            break rest
                .split([' ', ','])
                .next()
                .expect("an address")
                .to_string();
        }
    };
    // Keep reading its log so that it never blocks on a full pipe.
    std::thread::spawn(move || for _ in lines {});
    (Proc(child), addr)
}

/// Stops `p` with SIGTERM (it finishes its files) and waits for it to exit successfully.
pub fn terminate(p: &mut Proc) {
    let killed = Command::new("kill")
        .args(["-TERM", &p.0.id().to_string()])
        .status()
        .expect("kill runs");
    assert!(killed.success());
    let until = Instant::now() + GUARD;
    loop {
        if let Some(status) = p.0.try_wait().expect("wait") {
            assert!(status.success(), "it exited with {status}");
            return;
        }
        assert!(Instant::now() < until, "it did not exit");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// `GET path` of the HTTP API at `addr` (`host:port`): the JSON body.
pub fn get_json(addr: &str, path: &str) -> Value {
    use std::io::{Read as _, Write as _};
    let mut s = std::net::TcpStream::connect(addr).expect("connects");
    write!(
        s,
        "GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n"
    )
    .expect("request");
    let mut text = String::new();
    s.read_to_string(&mut text).expect("response");
    let body = text.split("\r\n\r\n").nth(1).expect("a body");
    serde_json::from_str(body).unwrap_or_else(|e| panic!("{e}: {body}"))
}

/// The EPC of scene entity `e` (`estimate/EPC`), which must be drawn at the position of one
/// of `estimates` (TagEstimate messages as `mcap_check.py` prints them) logged by its stamp.
pub fn drawn_estimate(e: &Value, estimates: &[Value]) -> String {
    let id = e["id"].as_str().expect("an id");
    let epc = id
        .strip_prefix("estimate/")
        .unwrap_or_else(|| panic!("no truth here, only estimates: {id}"));
    let center = &e["spheres"][0]["position"];
    let stamp = e["stamp_ns"].as_u64().expect("a stamp");
    (estimates.iter())
        .rfind(|m| {
            m["epc"] == epc
                && m["position"] == *center
                && m["log_time"].as_u64().is_some_and(|t| t <= stamp)
        })
        .unwrap_or_else(|| panic!("{id}: no estimate at {center} by {stamp}"));
    epc.to_string()
}
