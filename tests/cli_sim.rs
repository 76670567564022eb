//! `llrp-gateway sim` from the command line: bad input gets a clear one-line error.

use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_llrp-gateway"))
}

#[test]
fn a_bad_scenario_file_names_the_field_and_the_reason() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("bad.json");
    let mut s: serde_json::Value =
        serde_json::from_str(include_str!("../fixtures/scenarios/s1.json")).expect("s1 parses");
    s["readers"][0]["antennas"][0]["beamwidth_deg"] = serde_json::json!(-5);
    std::fs::write(&path, s.to_string()).expect("write");
    let out = bin()
        .args(["sim", "--scenario"])
        .arg(&path)
        .output()
        .expect("runs");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("readers[0].antennas[0].beamwidth_deg"),
        "error names the field: {err}"
    );
    assert!(err.contains("-5"), "error gives the value: {err}");
}

#[test]
fn a_bad_speed_is_refused() {
    let out = bin()
        .args(["sim", "--speed", "fast"])
        .output()
        .expect("runs");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("positive number or `max`"), "{err}");
}

#[test]
fn an_unusable_listen_address_is_reported() {
    let out = bin()
        .args(["sim", "--listen", "256.0.0.1:5084"])
        .output()
        .expect("runs");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("cannot listen on 256.0.0.1:5084"), "{err}");
}

/// A running `llrp-gateway sim` child: its address and the thread collecting its stderr.
struct Running {
    child: std::process::Child,
    addr: String,
    log: std::thread::JoinHandle<String>,
    /// Every line of the log as it comes.
    lines: std::sync::mpsc::Receiver<String>,
}

/// Starts `llrp-gateway sim --no-http` with `args` on a free loopback port and waits for its
/// "listening on" line.
fn spawn_sim(args: &[&str]) -> Running {
    let mut all = vec!["--no-http"];
    all.extend_from_slice(args);
    spawn_sim_as(&all)
}

/// [`spawn_sim`] with exactly `args` (the HTTP API on by default).
fn spawn_sim_as(args: &[&str]) -> Running {
    use std::io::{BufRead, BufReader};
    use std::process::Stdio;

    let mut child = bin()
        .args(["sim", "--listen", "127.0.0.1:0"])
        .args(args)
        .stderr(Stdio::piped())
        .stdout(Stdio::null())
        .spawn()
        .expect("runs");
    let stderr = child.stderr.take().expect("piped");
    let (addr_tx, addr_rx) = std::sync::mpsc::channel();
    let (lines_tx, lines) = std::sync::mpsc::channel();
    let log = std::thread::spawn(move || {
        let mut all = String::new();
        for line in BufReader::new(stderr).lines() {
            let line = line.unwrap_or_default();
            let _ = lines_tx.send(line.clone());
            if let Some(at) = line.find("listening on ") {
                let _ = addr_tx.send(line[at + "listening on ".len()..].trim().to_string());
            }
            all.push_str(&line);
            all.push('\n');
        }
        all
    });
    let addr = addr_rx
        .recv_timeout(std::time::Duration::from_secs(20))
        .expect("the simulator listens");
    Running {
        child,
        addr,
        log,
        lines,
    }
}

impl Running {
    /// Sends SIGTERM and waits (at most 20 s, a hang guard) for the process to exit; returns
    /// whether it exited successfully and its log.
    fn terminate(mut self) -> (bool, String) {
        let pid = self.child.id().to_string();
        let sent = Command::new("kill")
            .args(["-TERM", &pid])
            .status()
            .expect("kill runs");
        assert!(sent.success(), "SIGTERM delivered");
        let guard = std::time::Instant::now() + std::time::Duration::from_secs(20);
        let status = loop {
            if let Some(s) = self.child.try_wait().expect("wait") {
                break s;
            }
            if std::time::Instant::now() > guard {
                let _ = self.child.kill();
                panic!("the simulator did not exit after SIGTERM");
            }
            std::thread::sleep(std::time::Duration::from_millis(20));
        };
        (status.success(), self.log.join().expect("log reader"))
    }
}

/// Failed accepts (here: out of file descriptors) pause accepting with a growing back-off
/// instead of spinning, and the reader serves again once descriptors are free.
#[test]
fn failed_accepts_back_off_and_the_reader_recovers() {
    use std::time::Duration;

    let sim = spawn_sim(&[]);
    let pid = sim.child.id().to_string();
    let fds = std::fs::read_dir(format!("/proc/{pid}/fd"))
        .expect("the simulator's descriptors")
        .count();
    // No descriptor left for an accepted connection (the soft limit; the hard one stays).
    let limit = |n: usize| {
        let ok = Command::new("prlimit")
            .args(["--pid", &pid, &format!("--nofile={n}:")])
            .status()
            .expect("prlimit runs")
            .success();
        assert!(ok, "prlimit --nofile={n}");
    };
    limit(fds);
    let mut s =
        std::net::TcpStream::connect(&sim.addr).expect("the kernel completes the handshake");
    s.set_read_timeout(Some(Duration::from_secs(20)))
        .expect("timeout");
    let mut failed = 0;
    while failed < 3 {
        let line = sim
            .lines
            .recv_timeout(Duration::from_secs(20))
            .expect("the simulator logs the failed accepts");
        failed += usize::from(line.contains("accept failed"));
    }
    limit(1024);
    let hello = read_message(&mut s).expect("the greeting once descriptors are free");
    assert_eq!(hello.name(), "READER_EVENT_NOTIFICATION");
    let (ok, log) = sim.terminate();
    assert!(ok, "{log}");
    let failures = log.matches("accept failed").count();
    // A loop that retried at once would log thousands; 10 ms about doubling to 1 s logs a
    // handful.
    assert!(
        (3..=50).contains(&failures),
        "{failures} failed accepts logged:\n{log}"
    );
    // The pauses (the shared back-off with jitter): 10-20 ms, then 20-40 ms, 40-80 ms, …
    let pauses: Vec<f64> = log
        .lines()
        .filter_map(|l| l.split("pausing accepts for ").nth(1))
        .map(|p| millis(p.trim()))
        .collect();
    assert!(pauses.len() >= 3, "{log}");
    assert!(
        pauses.iter().all(|p| (10.0..=1000.0).contains(p)),
        "{pauses:?}"
    );
    assert!(pauses[0] <= 20.0 && pauses[2] >= 40.0, "{pauses:?}");
    let growing = pauses.iter().take(6).collect::<Vec<_>>();
    assert!(growing.windows(2).all(|w| w[1] >= w[0]), "{pauses:?}");
}

/// A duration as `Debug` prints it (`17ms`, `1.5s`, `900µs`), in milliseconds.
fn millis(text: &str) -> f64 {
    let (number, scale) = if let Some(n) = text.strip_suffix("ms") {
        (n, 1.0)
    } else if let Some(n) = text.strip_suffix("µs") {
        (n, 1e-3)
    } else if let Some(n) = text.strip_suffix("ns") {
        (n, 1e-6)
    } else if let Some(n) = text.strip_suffix('s') {
        (n, 1e3)
    } else {
        panic!("not a duration: {text}")
    };
    number.parse::<f64>().expect("a number") * scale
}

/// The default HTTP address taken (here, or by anyone else): one line says so, and the
/// simulator serves LLRP all the same.
#[test]
fn a_taken_default_http_port_is_said_in_one_line_and_the_simulator_runs_on() {
    // Held for the test if free; if another process holds it, it is taken all the same.
    let _hold = std::net::TcpListener::bind("127.0.0.1:8080");
    let sim = spawn_sim_as(&[]);
    let mut s = std::net::TcpStream::connect(&sim.addr).expect("LLRP is served");
    s.set_read_timeout(Some(std::time::Duration::from_secs(20)))
        .expect("timeout");
    let hello = read_message(&mut s).expect("the greeting");
    assert_eq!(hello.name(), "READER_EVENT_NOTIFICATION");
    let (ok, log) = sim.terminate();
    assert!(ok, "{log}");
    let said: Vec<&str> = log.lines().filter(|l| l.contains("is taken")).collect();
    assert_eq!(said.len(), 1, "{log}");
    assert!(
        said[0].contains("127.0.0.1:8080") && said[0].contains("--http ADDR"),
        "{log}"
    );
}

/// An HTTP address the user chose must bind; beyond loopback it needs a token.
#[test]
fn a_chosen_http_address_that_cannot_serve_is_an_error() {
    let held = std::net::TcpListener::bind("127.0.0.1:0").expect("binds");
    let addr = held.local_addr().expect("bound").to_string();
    let out = bin()
        .args(["sim", "--listen", "127.0.0.1:0", "--http", &addr])
        .output()
        .expect("runs");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains(&format!("--http {addr}: cannot listen")),
        "{err}"
    );
    let out = bin()
        .args(["sim", "--listen", "127.0.0.1:0", "--http", "0.0.0.0:0"])
        .output()
        .expect("runs");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("--http 0.0.0.0:0") && err.contains("token"),
        "{err}"
    );
}

/// Reads one LLRP message from a blocking stream.
fn read_message(s: &mut std::net::TcpStream) -> std::io::Result<llrp::Message> {
    use std::io::Read;
    let mut h = [0u8; 10];
    s.read_exact(&mut h)?;
    let len = u32::from_be_bytes([h[2], h[3], h[4], h[5]]) as usize;
    let mut frame = h.to_vec();
    frame.resize(len.max(10), 0);
    s.read_exact(&mut frame[10..])?;
    llrp::Message::decode(&frame)
        .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidData, e.to_string()))
}

/// SIGTERM: the connected client gets the ConnectionCloseEvent a reader sends before it closes,
/// then end-of-stream; the ground truth written so far is on disk; the process exits 0.
#[test]
fn sigterm_tells_the_client_flushes_the_truth_and_exits() {
    use llrp::message::GetReaderCapabilities;
    use std::io::Write;
    use std::time::Duration;

    let dir = tempfile::tempdir().expect("temp dir");
    let truth = dir.path().join("truth.jsonl");
    let truth_arg = truth.to_str().expect("utf-8 path");
    let sim = spawn_sim(&["--truth", truth_arg]);
    let mut s = std::net::TcpStream::connect(&sim.addr).expect("connects");
    s.set_read_timeout(Some(Duration::from_secs(10)))
        .expect("timeout");
    let hello = read_message(&mut s).expect("greeting");
    assert_eq!(hello.name(), "READER_EVENT_NOTIFICATION");
    // A request makes the reader run (and write the first ground-truth line); its answer
    // proves the reader is serving.
    let req = llrp::Message::new(9, GetReaderCapabilities::default());
    s.write_all(&req.to_bytes()).expect("send");
    let caps = read_message(&mut s).expect("answer");
    assert_eq!(
        (caps.name(), caps.id),
        ("GET_READER_CAPABILITIES_RESPONSE", 9)
    );

    let pid = sim.child.id();
    let (ok, log) = sim.terminate();
    assert!(ok, "exit status 0 after SIGTERM (pid {pid}):\n{log}");
    let last = read_message(&mut s).expect("the reader says why it closes");
    assert!(last.body.is_connection_close(), "{last:?}");
    let mut rest = [0u8; 1];
    match std::io::Read::read(&mut s, &mut rest) {
        Ok(0) => {}
        Err(e) if e.kind() == std::io::ErrorKind::ConnectionReset => {}
        other => panic!("expected end-of-stream after the close event, got {other:?}"),
    }
    let text = std::fs::read_to_string(&truth).expect("truth file exists");
    let lines: Vec<&str> = text.lines().collect();
    assert!(
        !lines.is_empty(),
        "buffered ground truth flushed at shutdown"
    );
    for l in lines {
        let v: serde_json::Value = serde_json::from_str(l).expect("each line is JSON");
        assert!(v["t_us"].is_u64(), "{l}");
    }
}

/// Logs written to a file or a pipe carry no ANSI colour codes; `--log-format json` writes
/// one JSON object an event.
#[test]
fn logs_to_a_pipe_are_plain_text_and_json_on_request() {
    let sim = spawn_sim(&[]);
    let (ok, log) = sim.terminate();
    assert!(ok, "{log}");
    assert!(log.contains("simulated reader listening"), "{log}");
    assert!(
        !log.contains('\u{1b}'),
        "colour codes in a piped log:\n{log:?}"
    );

    let mut child = bin()
        .args([
            "--log-format",
            "json",
            "sim",
            "--listen",
            "127.0.0.1:0",
            "--no-http",
        ])
        .stderr(std::process::Stdio::piped())
        .stdout(std::process::Stdio::null())
        .spawn()
        .expect("runs");
    let stderr = child.stderr.take().expect("piped");
    let mut lines = std::io::BufRead::lines(std::io::BufReader::new(stderr));
    let event = lines
        .find_map(|l| {
            let l = l.ok()?;
            l.starts_with('{').then_some(l)
        })
        .expect("a JSON log line");
    let _ = child.kill();
    let _ = child.wait();
    let v: serde_json::Value = serde_json::from_str(&event).expect("the line is JSON");
    assert_eq!(v["level"], "INFO", "{event}");
    assert_eq!(
        v["fields"]["message"], "simulated reader listening",
        "{event}"
    );
}

/// The truth covers all simulated time, whoever drives the inventory: the reader's own
/// inventory before a client, the client's session, and the own inventory again after the
/// client left with CLOSE_CONNECTION; one line every 100 ms of simulated time, none missing
/// or twice, up to the stop.
#[test]
fn the_truth_covers_simulated_time_before_during_and_after_a_client() {
    use llrp::message::CloseConnection;
    use std::io::Write;
    use std::time::Duration;

    let dir = tempfile::tempdir().expect("temp dir");
    let truth = dir.path().join("truth.jsonl");
    let truth_arg = truth.to_str().expect("utf-8 path");
    let sim = spawn_sim_as(&[
        "--http",
        "127.0.0.1:0",
        "--speed",
        "10",
        "--truth",
        truth_arg,
    ]);
    // At ten times real time, a second is 10 s of simulated time.
    std::thread::sleep(Duration::from_secs(1));
    let mut s = std::net::TcpStream::connect(&sim.addr).expect("connects");
    s.set_read_timeout(Some(Duration::from_secs(10)))
        .expect("timeout");
    read_message(&mut s).expect("greeting");
    s.write_all(&llrp::Message::new(3, CloseConnection::default()).to_bytes())
        .expect("send");
    loop {
        let m = read_message(&mut s).expect("the close response");
        if m.name() == "CLOSE_CONNECTION_RESPONSE" {
            break;
        }
    }
    drop(s);
    std::thread::sleep(Duration::from_secs(1));
    let (ok, log) = sim.terminate();
    assert!(ok, "{log}");
    let text = std::fs::read_to_string(&truth).expect("truth file exists");
    let times: Vec<u64> = text
        .lines()
        .map(|l| {
            let v: serde_json::Value = serde_json::from_str(l).expect("each line is JSON");
            v["t_us"].as_u64().expect("t_us")
        })
        .collect();
    let expected: Vec<u64> = (0..times.len() as u64).map(|k| k * 100_000).collect();
    assert_eq!(times, expected, "one line every 100 ms of simulated time");
    // Two wall seconds passed at ten times real time.
    assert!(
        times.last().is_some_and(|&t| t >= 15_000_000),
        "the truth stops at {:?} µs",
        times.last()
    );
}

/// A client's malformed requests get LLRP answers, the connection carries on, and nothing is
/// logged at error level for them (the log is the binary's stderr at its default level).
#[test]
fn a_clients_mistakes_are_answered_and_not_logged_as_errors() {
    use std::io::{Read, Write};
    use std::net::TcpStream;
    use std::time::Duration;

    let sim = spawn_sim(&["--speed", "max"]);
    let mut s = TcpStream::connect(&sim.addr).expect("connects");
    s.set_read_timeout(Some(Duration::from_secs(10)))
        .expect("timeout");
    // Header: version 1 (or `ver`), type, length, message ID.
    let frame = |ver: u16, ty: u16, id: u32, body: &[u8]| {
        let mut f = Vec::new();
        f.extend_from_slice(&((ver << 10) | ty).to_be_bytes());
        f.extend_from_slice(&(10 + body.len() as u32).to_be_bytes());
        f.extend_from_slice(&id.to_be_bytes());
        f.extend_from_slice(body);
        f
    };
    // An unknown message type, an unsupported version, a truncated GET_READER_CONFIG, then a
    // good GET_READER_CAPABILITIES.
    for f in [
        frame(1, 999, 1, &[]),
        frame(3, 1, 2, &[0]),
        frame(1, 2, 3, &[0, 0]),
        frame(1, 1, 4, &[0]),
    ] {
        s.write_all(&f).expect("send");
    }
    let mut answered = Vec::new();
    while !answered.iter().any(|&(ty, id)| (ty, id) == (11, 4)) {
        let mut h = [0u8; 10];
        s.read_exact(&mut h).expect("a message from the reader");
        let ty = u16::from_be_bytes([h[0], h[1]]) & 0x3FF;
        let len = u32::from_be_bytes([h[2], h[3], h[4], h[5]]) as usize;
        let id = u32::from_be_bytes([h[6], h[7], h[8], h[9]]);
        let mut body = vec![0u8; len.saturating_sub(10)];
        s.read_exact(&mut body).expect("its body");
        answered.push((ty, id));
    }
    // ERROR_MESSAGE (100) for the unknown type and the bad version, the response type (12)
    // for the truncated request.
    for want in [(100, 1), (100, 2), (12, 3)] {
        assert!(answered.contains(&want), "{want:?} not in {answered:?}");
    }
    drop(s);
    // The log is complete once the process has exited.
    let (ok, log) = sim.terminate();
    assert!(ok, "{log}");
    assert!(log.contains("listening on"), "{log}");
    assert!(
        !log.contains("ERROR"),
        "a client's mistake logged as an error:\n{log}"
    );
}

/// The phase codes (ImpinjRFPhaseAngle, 4096 a turn) of an `inventory --impinj` client's reads
/// from `sim` on S1 at `--speed max` with `extra` arguments.
fn phase_codes(extra: &[&str]) -> Vec<u32> {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("reads.jsonl");
    let mut args = vec!["--speed", "max"];
    args.extend_from_slice(extra);
    let sim = spawn_sim(&args);
    let status = bin()
        .args([
            "inventory",
            &sim.addr,
            "--impinj",
            "--seconds",
            "2",
            "--output",
        ])
        .arg(&out)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .status()
        .expect("inventory runs");
    assert!(status.success());
    let (_, _) = sim.terminate();
    std::fs::read_to_string(&out)
        .expect("reads written")
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter_map(|r| r["phase_rad"].as_f64())
        .map(|p| (p / std::f64::consts::TAU * 4096.0).round() as u32)
        .collect()
}

#[test]
fn a_reader_model_on_the_command_line_reads_as_that_reader() {
    // impinj-r420 (S1's own model) reports every fourth code of the 12-bit phase field, as a
    // real R420 does; the ideal model uses them all.
    let r420 = phase_codes(&[]);
    assert!(r420.len() > 100, "{} reads", r420.len());
    assert!(r420.iter().all(|c| c % 4 == 0), "{:?}", &r420[..20]);
    let ideal = phase_codes(&["--reader-model", "ideal"]);
    assert!(ideal.len() > 100, "{} reads", ideal.len());
    assert!(ideal.iter().any(|c| c % 4 != 0));
    // An unknown model is named with the known ones.
    let out = bin()
        .args(["sim", "--no-http", "--reader-model", "acme-9000"])
        .output()
        .expect("runs");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("unknown reader model `acme-9000`") && err.contains("impinj-r420"),
        "{err}"
    );
}
