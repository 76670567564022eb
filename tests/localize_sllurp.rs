//! The README's tour step: unmodified `sllurp inventory` (sllurp 2.0.1, which turns AntennaID
//! off) against `sim` with its live localizer. The reads of sllurp's session reach the
//! localizer with their antenna's pose instead of being set aside for want of one.
//! Needs the venv; `./scripts/test` creates it and sets `LLRP_VENV`.

mod http_support;

use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use http_support::{counter, first_reader, Proc};

#[test]
#[ignore = "needs the sllurp venv; run by ./scripts/test"]
fn sllurps_reads_without_antenna_ids_are_filed_on_the_readers_one_antenna() {
    let venv = PathBuf::from(
        std::env::var("LLRP_VENV").expect("LLRP_VENV must name the sllurp venv (./scripts/test)"),
    );
    let (mut sim, http) = Proc::sim(&["--speed", "4"]);
    let llrp: SocketAddr = sim.address("listening on ").parse().expect("addr");
    let reader = || first_reader(http);
    // The README's command, until the reader serves it and the localizer has taken in reads
    // of its session (a hang guard, not a measurement).
    let mut sllurp = Command::new(venv.join("bin").join("sllurp"))
        .args(["inventory", "--impinj-reports", "--impinj-search-mode", "2"])
        .args(["-a", "0", "-p", &llrp.port().to_string(), "127.0.0.1"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("sllurp starts");
    let guard = Instant::now() + Duration::from_secs(60);
    let mut start: Option<u64> = None;
    let taken = loop {
        let r = reader();
        let reads = r["reads"].as_u64().unwrap_or(0);
        if r["inventory"] == "client" {
            let first = *start.get_or_insert(reads);
            // A few of its reports, a second apart.
            if reads >= first + 12 {
                break reads - first;
            }
        }
        assert!(Instant::now() < guard, "sllurp's session fed nothing: {r}");
        std::thread::sleep(Duration::from_millis(200));
    };
    // Ctrl-C, as the README says.
    let _ = Command::new("kill")
        .args(["-INT", &sllurp.id().to_string()])
        .status();
    let _ = sllurp.wait();
    let aside = counter(http, "reads_set_aside");
    sim.stop();
    assert!(taken >= 12);
    // Before: every read of the session was set aside, on antenna 0 with no pose.
    assert_eq!(aside, 0.0, "reads set aside");
}
