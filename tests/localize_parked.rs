//! The live localizer beside `sim` long after S1's drive has ended (the robot parked at its
//! end, reading the last tags thousands of times from one pose), with busy threads
//! competing for the cores: the estimates are what the drive's reads make them, whatever the
//! load (issue 40 §2).

mod http_support;

use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use http_support::{request, Proc};

/// Simulated time the test waits for: the drive ends near 44 s, so over 350 s parked.
const PARKED_UNTIL_US: u64 = 400_000_000;

#[test]
fn after_a_long_park_under_busy_threads_every_tag_converges_where_it_is() {
    let busy = Arc::new(AtomicBool::new(true));
    let hogs: Vec<_> = (0..3)
        .map(|_| {
            let busy = Arc::clone(&busy);
            std::thread::spawn(move || {
                let mut x = 0u64;
                while busy.load(Ordering::Relaxed) {
                    x = x.wrapping_mul(6364136223846793005).wrapping_add(1);
                    std::hint::black_box(x);
                }
            })
        })
        .collect();
    let mut sim = Proc::spawn(&[
        "sim",
        "--speed",
        "10",
        "--poses",
        "truth",
        "--listen",
        "127.0.0.1:0",
        "--http",
        "127.0.0.1:0",
    ]);
    let http: SocketAddr = sim.address("live map on http://").parse().expect("addr");
    let deadline = Instant::now() + Duration::from_secs(180);
    // The truth's times are on the reads' clock (UTC µs): simulated time is counted from the
    // first truth seen (a little after simulated time 0).
    let mut start: Option<u64> = None;
    let truth = loop {
        let t = request(http, "GET", "/api/truth", &[], b"").json();
        let at = t["antennas"][0]["t_us"].as_u64();
        let now = match (start, at) {
            (Some(s), Some(a)) => a.saturating_sub(s),
            (None, Some(a)) => {
                start = Some(a);
                0
            }
            _ => 0,
        };
        if now >= PARKED_UNTIL_US {
            break t;
        }
        assert!(
            Instant::now() < deadline,
            "simulated time stuck at {now} µs"
        );
        std::thread::sleep(Duration::from_millis(500));
    };
    let tags = request(http, "GET", "/api/tags", &[], b"").json();
    busy.store(false, Ordering::Relaxed);
    for h in hogs {
        h.join().expect("hog");
    }
    let tags = tags["tags"].as_array().expect("tags").clone();
    let mut converged = 0;
    for t in &tags {
        if t["state"] != "converged" {
            continue;
        }
        converged += 1;
        let epc = t["epc"].as_str().expect("epc");
        let truth = truth["tags"]
            .as_array()
            .expect("truth tags")
            .iter()
            .find(|x| x["epc"] == epc)
            .expect("a true position");
        let d = |k: &str| {
            t["estimate"][k].as_f64().expect("estimate")
                - truth["position"][k].as_f64().expect("truth")
        };
        let error_m = d("x").hypot(d("y"));
        assert!(
            error_m < 0.01,
            "{epc} converged {error_m} m from the truth: {t}"
        );
    }
    // Every tag was passed by the drive: each has the aperture to converge.
    assert_eq!(
        converged,
        10,
        "{converged} of {} converged: {tags:?}",
        tags.len()
    );
}
