//! sllurp's own library (3.0.5, unmodified, from the test venv) writing and reading tag memory
//! on the simulated reader over loopback, as an encoding station does: a C1G2Write of two
//! words of user memory on one connection, and a C1G2Read on a later one that gives them back.
//! `scripts/interop/sllurp3_access.py` does what `sllurp access -w` / `-r` does, because no
//! sllurp release has that command working (docs/testing.md). Needs the venv;
//! `./scripts/test` creates it and sets `LLRP_SLLURP3_PYTHON`.

mod common;

use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::*;
use llrp_gateway::net::clock::Speed;
use serde_json::Value;

/// Runs the access script against `port` with `args`; gives the JSON line it printed.
fn access(port: u16, args: &[&str]) -> Value {
    let python = std::env::var("LLRP_SLLURP3_PYTHON")
        .expect("LLRP_SLLURP3_PYTHON must name sllurp 3.0.5's python (set by ./scripts/test)");
    let script =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scripts/interop/sllurp3_access.py");
    let mut child = Command::new(python)
        .arg(script)
        .args(["127.0.0.1", &port.to_string()])
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the script runs");
    // A hang guard, not a measurement: the script gives up after 20 s and 10 s of close.
    let guard = Instant::now() + Duration::from_secs(90);
    while child.try_wait().expect("wait").is_none() {
        if Instant::now() > guard {
            let _ = child.kill();
            break;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let out = child.wait_with_output().expect("the script's output");
    let text = String::from_utf8_lossy(&out.stdout);
    serde_json::from_str(text.trim())
        .unwrap_or_else(|e| panic!("{e}: {text}\n{}", String::from_utf8_lossy(&out.stderr)))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "needs the sllurp 3.0.5 venv; run by ./scripts/test"]
async fn sllurp_writes_user_memory_and_reads_it_back_on_a_later_connection() {
    let s = line_scenario(&[1.0]);
    let sim = start(&s, Speed::Factor(1.0)).await;
    let port = sim.addrs[0].port();
    let (write, read) = tokio::task::spawn_blocking(move || {
        let write = access(port, &["--write", "BEEFCAFE", "--mb", "3"]);
        let read = access(port, &["--read", "3", "--mb", "3"]);
        (write, read)
    })
    .await
    .expect("join");
    sim.shutdown().await;
    assert_eq!(write["result"]["Result"], 0, "{write}");
    assert_eq!(write["result"]["NumWordsWritten"], 2, "{write}");
    assert_eq!(read["result"]["Result"], 0, "{read}");
    // The two words written, then the third word of the chip's (zeroed) user memory.
    assert_eq!(read["result"]["ReadData"], "beefcafe0000", "{read}");
}
