//! sllurp 3.0.5's own clean close, through `llrp-gateway proxy`, twenty times each way
//! (issue 40 §5): `scripts/interop/sllurp3_session.py` runs sllurp's library (its `sllurp`
//! command is broken in the 3.0.x wheels) against a proxy in front of `llrp-gateway sim`.
//!
//! sllurp 3.0.5 closes without CLOSE_CONNECTION: DELETE_ACCESSSPEC, then on its response
//! DELETE_ROSPEC, then on that response it closes its socket; the proxy then sends the reader
//! CLOSE_CONNECTION on the client's behalf. Called from the application's thread, sllurp's
//! `disconnect()` races its own reader thread (it registers the callback that sends
//! DELETE_ROSPEC only after sending DELETE_ACCESSSPEC), and a session that loses the race never
//! closes, through the proxy or not (docs/gateway.md, "sllurp 3.0.5's close"). So: called from
//! sllurp's own thread every close must be clean; called from the application's thread every
//! close must be clean or that race, nothing else.
//!
//! `#[ignore]`d in a plain `cargo test`: it needs the venv `./scripts/test` makes
//! (`scripts/venv-sllurp3.sh`) and names in `LLRP_SLLURP3_PYTHON`.

mod http_support;

use std::path::PathBuf;
use std::process::Command;

use http_support::Proc;
use serde_json::Value;

fn python() -> PathBuf {
    PathBuf::from(
        std::env::var("LLRP_SLLURP3_PYTHON").expect(
            "LLRP_SLLURP3_PYTHON must name the sllurp 3.0.5 venv's python (./scripts/test)",
        ),
    )
}

/// Twenty sllurp sessions against `addr`, one after the other in one process, 0.2 s apart;
/// one JSON object each. (With no pause a session can reach the one-client reader while the
/// proxy is still closing the previous one's upstream connection on its behalf, and be refused
/// with FailedClientInitiatedConnectionExists: docs/gateway.md.)
fn sessions(addr: &str, extra: &[&str]) -> Vec<Value> {
    let (host, port) = addr.rsplit_once(':').expect("HOST:PORT");
    let script = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/scripts/interop/sllurp3_session.py"
    );
    let out = Command::new(python())
        .arg(script)
        .args([
            host,
            port,
            "--repeat",
            "20",
            "--timeout",
            "20",
            "--gap",
            "0.2",
        ])
        .args(extra)
        .output()
        .expect("sllurp runs");
    let text = String::from_utf8_lossy(&out.stdout);
    let runs: Vec<Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l}")))
        .collect();
    assert_eq!(
        runs.len(),
        20,
        "twenty sessions: {text}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    runs
}

#[test]
#[ignore = "needs sllurp 3.0.5 (LLRP_SLLURP3_PYTHON, set by ./scripts/test)"]
fn sllurp_3_closes_cleanly_through_the_proxy_twenty_times() {
    let mut sim = Proc::spawn(&[
        "sim",
        "--no-http",
        "--listen",
        "127.0.0.1:0",
        "--speed",
        "4",
    ]);
    let reader = sim.address("listening on ");
    let dir = tempfile::tempdir().expect("temp dir");
    let rec = dir.path().join("sllurp3.jsonl");
    let mut proxy = Proc::spawn(&[
        "proxy",
        "--no-http",
        "--upstream",
        &reader,
        "--listen",
        "127.0.0.1:0",
        "--record",
        rec.to_str().expect("utf-8"),
    ]);
    let addr = proxy.address("listening on ");
    // From sllurp's own thread: no race, so every close must be clean.
    for run in sessions(&addr, &["--disconnect-in-callback"]) {
        assert_eq!(run["clean"], true, "{run}");
        assert!(run["reports"].as_u64().is_some_and(|n| n >= 5), "{run}");
    }
    // From the application's thread, as most programs call it: clean, or sllurp's own race.
    for run in sessions(&addr, &[]) {
        assert!(
            run["clean"] == true || run["race"] == true,
            "a close that failed for another reason than sllurp's race: {run}"
        );
    }
    assert!(proxy.stop().success(), "the proxy exits cleanly");
    let _ = sim.stop();
    // Every session of the first twenty ended with the proxy's close on the client's behalf,
    // answered by the reader.
    let r = llrp_gateway::record::Recording::open(&rec).expect("the recording reads");
    let ends: Vec<&str> = r
        .entries
        .iter()
        .filter_map(|e| match e {
            llrp_gateway::record::Entry::Marker {
                event: llrp_gateway::record::Event::Disconnect,
                reason,
                ..
            } => Some(reason.as_str()),
            _ => None,
        })
        .collect();
    assert!(ends.len() >= 20, "{ends:?}");
    assert!(
        ends[..20]
            .iter()
            .all(|e| *e == "client closed; proxy sent CLOSE_CONNECTION and the reader closed"),
        "{ends:?}"
    );
}
