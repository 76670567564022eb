//! `llrp-gateway proxy` from the command line: several readers from one `--config`, each
//! recorded; rotation; the unreachable reader's one log line; bad config files; SIGTERM.

use std::collections::HashMap;
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

use llrp::enums::CapabilitiesRequest;
use llrp::enums::ConnectionAttemptStatus;
use llrp::message::GetReaderCapabilities;
use llrp_gateway::net::client::Client;
use llrp_gateway::record::{Entry, Event, Recording};

const T: Duration = Duration::from_secs(10);

/// A running child of the binary with its stderr lines.
struct Running {
    child: Child,
    lines: mpsc::Receiver<String>,
    log: Vec<String>,
}

fn spawn(args: &[&str]) -> Running {
    let mut child = Command::new(env!("CARGO_BIN_EXE_llrp-gateway"))
        .args(args)
        .stderr(Stdio::piped())
        .stdout(Stdio::null())
        .spawn()
        .expect("runs");
    let stderr = child.stderr.take().expect("piped");
    let (tx, lines) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            let _ = tx.send(line);
        }
    });
    Running {
        child,
        lines,
        log: Vec::new(),
    }
}

impl Running {
    /// Waits for `n` "listening on" lines; returns the addresses by the name before them.
    fn listening(&mut self, n: usize) -> HashMap<String, String> {
        let mut out = HashMap::new();
        while out.len() < n {
            let line = self
                .lines
                .recv_timeout(Duration::from_secs(30))
                .unwrap_or_else(|_| panic!("{n} listening lines; log so far: {:?}", self.log));
            self.log.push(line.clone());
            if let Some((head, rest)) = line.split_once("listening on ") {
                let addr = rest
                    .split([',', ' '])
                    .next()
                    .unwrap_or_default()
                    .to_string();
                let name = head.split('\'').nth(1).unwrap_or("").to_string();
                out.insert(name, addr);
            }
        }
        out
    }

    /// SIGTERM, then the exit status (a hang guard of 20 s) and the whole log.
    fn terminate(mut self) -> (bool, Vec<String>) {
        let pid = self.child.id().to_string();
        Command::new("kill")
            .args(["-TERM", &pid])
            .status()
            .expect("kill");
        let guard = std::time::Instant::now() + Duration::from_secs(20);
        let status = loop {
            if let Some(s) = self.child.try_wait().expect("wait") {
                break s;
            }
            assert!(std::time::Instant::now() < guard, "no exit after SIGTERM");
            std::thread::sleep(Duration::from_millis(20));
        };
        while let Ok(l) = self.lines.recv_timeout(Duration::from_millis(500)) {
            self.log.push(l);
        }
        (status.success(), self.log)
    }
}

fn sim() -> (Running, String) {
    let mut s = spawn(&["sim", "--no-http", "--listen", "127.0.0.1:0"]);
    let addr = s.listening(1).into_values().next().expect("an address");
    (s, addr)
}

async fn session(addr: &str) {
    let mut c = Client::connect(addr).await.expect("connects");
    let m = c.recv(T).await.expect("greeting");
    assert_eq!(
        m.body.connection_attempt(),
        Some(ConnectionAttemptStatus::Success)
    );
    c.transact(
        GetReaderCapabilities {
            requested_data: CapabilitiesRequest::All,
            ..Default::default()
        },
        T,
    )
    .await
    .expect("capabilities");
    c.request(llrp::message::CloseConnection::default(), T)
        .await
        .expect("closed");
    c.until_closed(T).await.expect("closed");
}

fn check_recording(path: &Path, upstream: &str) {
    let r = Recording::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!(r.header.upstream, upstream);
    let frames = r
        .entries
        .iter()
        .filter(|e| matches!(e, Entry::Frame { .. }))
        .count();
    assert!(frames >= 5, "{}: {frames} frames", path.display());
    let events: Vec<Event> = r
        .entries
        .iter()
        .filter_map(|e| match e {
            Entry::Marker { event, .. } => Some(*event),
            _ => None,
        })
        .collect();
    assert_eq!(events, vec![Event::Connect, Event::Disconnect]);
}

#[tokio::test]
async fn one_process_proxies_several_readers_from_a_config_and_records_each() {
    let (sim_a, a) = sim();
    let (sim_b, b) = sim();
    let dir = tempfile::tempdir().expect("temp dir");
    let config = dir.path().join("gateway.json");
    let text = serde_json::json!({"proxies": [
        {"name": "dock", "upstream": a, "listen": "127.0.0.1:0", "record": "dock.jsonl"},
        {"name": "aisle", "upstream": b, "listen": "127.0.0.1:0", "record": "aisle.jsonl", "region": "etsi"},
    ]});
    std::fs::write(&config, text.to_string()).expect("write");
    let mut proxy = spawn(&["proxy", "--config", config.to_str().expect("utf-8")]);
    let addrs = proxy.listening(2);
    session(&addrs["dock"]).await;
    session(&addrs["aisle"]).await;
    let (ok, log) = proxy.terminate();
    assert!(ok, "{log:?}");
    check_recording(&dir.path().join("dock.jsonl"), &a);
    check_recording(&dir.path().join("aisle.jsonl"), &b);
    sim_a.terminate();
    sim_b.terminate();
}

#[tokio::test]
async fn past_record_max_bytes_the_recording_goes_on_in_numbered_files() {
    let (sim, a) = sim();
    let dir = tempfile::tempdir().expect("temp dir");
    let rec = dir.path().join("rec.jsonl");
    let mut proxy = spawn(&[
        "proxy",
        "--upstream",
        &a,
        "--listen",
        "127.0.0.1:0",
        "--record",
        rec.to_str().expect("utf-8"),
        "--record-max-bytes",
        "600",
    ]);
    let addr = proxy.listening(1).into_values().next().expect("address");
    session(&addr).await;
    let (ok, log) = proxy.terminate();
    assert!(ok, "{log:?}");
    let mut parts = 0;
    let mut frames = 0;
    loop {
        let p = llrp_gateway::record::writer::part_path(&rec, parts);
        if !p.exists() {
            break;
        }
        let r = Recording::open(&p).expect("each part reads");
        assert_eq!(r.header.part, parts);
        frames += r
            .entries
            .iter()
            .filter(|e| matches!(e, Entry::Frame { .. }))
            .count();
        parts += 1;
    }
    assert!(parts >= 2, "one file only");
    assert!(frames >= 5);
    sim.terminate();
}

#[tokio::test]
async fn an_unreachable_reader_is_one_clear_log_line_and_a_failed_connection_attempt() {
    let gone = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
    let dead = gone.local_addr().expect("bound").to_string();
    drop(gone);
    let mut proxy = spawn(&["proxy", "--upstream", &dead, "--listen", "127.0.0.1:0"]);
    let addr = proxy.listening(1).into_values().next().expect("address");
    let mut c = Client::connect(&addr).await.expect("the proxy accepts");
    let m = c.recv(T).await.expect("notification");
    assert_eq!(
        m.body.connection_attempt(),
        Some(ConnectionAttemptStatus::FailedOtherReason)
    );
    c.until_closed(T).await.expect("closed");
    let (ok, log) = proxy.terminate();
    assert!(ok);
    let lines: Vec<&String> = log.iter().filter(|l| l.contains(&dead)).collect();
    let unreachable: Vec<&&String> = lines.iter().filter(|l| l.contains("unreachable")).collect();
    assert_eq!(unreachable.len(), 1, "{log:#?}");
}

#[test]
fn a_bad_config_names_the_field_and_the_reason() {
    let dir = tempfile::tempdir().expect("temp dir");
    let config = dir.path().join("gateway.json");
    std::fs::write(
        &config,
        r#"{"proxies": [{"name": "dock", "upstream": 5084, "listen": "127.0.0.1:0"}]}"#,
    )
    .expect("write");
    let out = Command::new(env!("CARGO_BIN_EXE_llrp-gateway"))
        .args(["proxy", "--config"])
        .arg(&config)
        .output()
        .expect("runs");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("proxies[0].upstream"), "{err}");
    assert!(err.contains("expected a string"), "{err}");
}
