//! A client process killed with SIGKILL in the middle of its inventory (no CLOSE_CONNECTION,
//! the kernel closes its socket) hands the reader back as any other leaving does: `sim` shows
//! it not connected and its own inventory resumes (issue 46 §1).

mod http_support;

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use http_support::{first_reader, Proc};

/// Longest the test waits for each state (a hang guard, not a measurement).
const GUARD: Duration = Duration::from_secs(60);

#[test]
fn a_client_killed_with_sigkill_hands_the_reader_back_to_its_own_inventory() {
    let (mut sim, http) = Proc::sim(&["--speed", "4"]);
    let llrp = sim.address("listening on ");
    let reader = || first_reader(http);
    let until = |what: &str, pred: &dyn Fn(&serde_json::Value) -> bool| {
        let deadline = Instant::now() + GUARD;
        loop {
            let r = reader();
            if pred(&r) {
                return r;
            }
            assert!(Instant::now() < deadline, "{what}: {r}");
            std::thread::sleep(Duration::from_millis(100));
        }
    };
    until("the own inventory never ran", &|r| {
        r["inventory"] == "self" && r["reads"].as_u64() > Some(0)
    });
    let mut client = Command::new(env!("CARGO_BIN_EXE_llrp-gateway"))
        .args(["inventory", &llrp, "--seconds", "600", "--impinj"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("the client starts");
    until("the client's inventory is not shown", &|r| {
        r["connected"] == true && r["inventory"] == "client"
    });
    // SIGKILL: no goodbye from the client.
    client.kill().expect("SIGKILL");
    let _ = client.wait();
    let gone = until("the reader still shows the killed client", &|r| {
        r["connected"] == false && r["peer"].is_null()
    });
    let before = gone["reads"].as_u64().unwrap_or(0);
    until("the own inventory did not resume", &|r| {
        r["inventory"] == "self" && r["reads"].as_u64() > Some(before)
    });
    sim.stop();
}
