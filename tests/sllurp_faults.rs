//! A fault as an unmodified third-party client sees it: `sllurp inventory --reconnect`
//! (sllurp 2.0.1 from the test venv) against `llrp-gateway sim` over loopback, the reader
//! dropping the connection (`POST /api/readers/{reader}/faults`, `drop_connection`) in the
//! middle of the inventory. sllurp logs the reset, reconnects by its own logic, sets the
//! reader up again and logs tags again, the scenario's. Needs the venv (`LLRP_VENV`, set by
//! `./scripts/test`).

mod http_support;

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use http_support::{request, Proc, PATIENCE};
use llrp_gateway::scenario::Scenario;

fn sllurp() -> PathBuf {
    let venv = std::env::var("LLRP_VENV")
        .expect("LLRP_VENV must name the sllurp venv (set by ./scripts/test)");
    PathBuf::from(venv).join("bin").join("sllurp")
}

/// sllurp's log so far ("" before it exists).
fn log(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_default()
}

/// Waits (at most [`PATIENCE`]) until `ready` holds of sllurp's log, or sllurp ends; the
/// log then.
fn wait_for(child: &mut Child, path: &Path, ready: impl Fn(&str) -> bool) -> String {
    let until = Instant::now() + PATIENCE;
    loop {
        let text = log(path);
        if ready(&text) || Instant::now() > until || child.try_wait().ok().flatten().is_some() {
            return text;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Interrupts sllurp as Ctrl-C does and waits for it (killed after 15 s).
fn stop(child: &mut Child) {
    let _ = Command::new("kill")
        .arg("-INT")
        .arg(child.id().to_string())
        .status();
    let until = Instant::now() + Duration::from_secs(15);
    while child.try_wait().ok().flatten().is_none() {
        if Instant::now() > until {
            let _ = child.kill();
            let _ = child.wait();
            return;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// The EPCs (lower-case hex) in sllurp's `saw tag(s)` lines of `text`.
fn epcs(text: &str) -> Vec<String> {
    text.split("'EPC-96': b'")
        .skip(1)
        .filter_map(|rest| rest.split('\'').next())
        .map(str::to_string)
        .collect()
}

fn drop_connection(http: SocketAddr) {
    let r = request(
        http,
        "POST",
        "/api/readers/s1-reader/faults",
        &[("Content-Type", "application/json")],
        br#"{"fault": "drop_connection"}"#,
    );
    assert_eq!(r.status, 202, "{}", r.text());
}

#[test]
fn sllurp_reconnects_by_itself_after_the_reader_drops_it_and_reads_again() {
    let (mut sim, http) = Proc::sim(&[]);
    let llrp = sim.address("listening on ");
    let port = llrp.rsplit(':').next().expect("host:port").to_string();
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("sllurp.log");
    let mut child = Command::new(sllurp())
        .arg("-l")
        .arg(&path)
        .args(["inventory", "--reconnect", "-p", &port, "127.0.0.1"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("sllurp starts");

    let before = wait_for(&mut child, &path, |t| t.matches("saw tag(s)").count() >= 2);
    assert!(
        before.matches("saw tag(s)").count() >= 2,
        "sllurp reads before the fault:\n{before}"
    );
    drop_connection(http);
    // sllurp sees the reset, reconnects, starts its inventory again and logs tags again.
    let again = |t: &str| {
        t.split_once("Lost connection detected")
            .is_some_and(|(_, after)| {
                after
                    .split_once("starting inventory")
                    .is_some_and(|(_, then)| then.contains("saw tag(s)"))
            })
    };
    let text = wait_for(&mut child, &path, again);
    let running = child.try_wait().ok().flatten().is_none();
    stop(&mut child);
    assert!(running, "sllurp kept running:\n{text}");
    let (_, after) = text
        .split_once("Lost connection detected")
        .unwrap_or_else(|| panic!("sllurp noticed the lost connection:\n{text}"));
    assert!(
        after.contains("connected to 127.0.0.1"),
        "sllurp reconnected:\n{after}"
    );
    let (_, reads) = after
        .split_once("starting inventory")
        .unwrap_or_else(|| panic!("sllurp started its inventory again:\n{after}"));
    let seen = epcs(reads);
    assert!(!seen.is_empty(), "tags after the reconnect:\n{reads}");
    // They are the scenario's tags (the sim runs the default S1).
    let known: Vec<String> = Scenario::default_s1()
        .tags
        .iter()
        .map(|t| t.epc.to_lowercase())
        .collect();
    assert!(seen.iter().all(|e| known.contains(e)), "{seen:?}");
    assert_eq!(sim.lines_with("fault injected", 1).len(), 1);
    assert!(sim.stop().success());
}
