//! The live localizer beside `sim` long after S1's drive has ended (the robot parked at its
//! end, reading the last tags thousands of times from one pose), with busy threads
//! competing for the cores: the estimates are what the drive's reads make them, whatever the
//! load; and on the robot's own poses, ellipses that hold the truth (issue 40 §2).

mod http_support;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use http_support::{request, Proc};

/// Simulated time the test waits for: the drive ends near 44 s, so over 350 s parked.
const PARKED_UNTIL_US: u64 = 400_000_000;

/// Runs `sim --speed SPEED --poses POSES --reader-model MODEL` until `until_us` of simulated
/// time, `hogs` busy threads beside it; the truth and the tags then.
fn run_sim(
    poses: &str,
    model: &str,
    speed: &str,
    until_us: u64,
    hogs: usize,
) -> (serde_json::Value, Vec<serde_json::Value>) {
    let busy = Arc::new(AtomicBool::new(true));
    let hogs: Vec<_> = (0..hogs)
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
    let (_sim, http) = Proc::sim(&["--speed", speed, "--poses", poses, "--reader-model", model]);
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
        if now >= until_us {
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
    (truth, tags["tags"].as_array().expect("tags").clone())
}

/// `tag`'s true position in `truth` (x, y).
fn true_xy(truth: &serde_json::Value, tag: &serde_json::Value) -> (f64, f64) {
    let p = &truth["tags"]
        .as_array()
        .expect("truth tags")
        .iter()
        .find(|x| x["epc"] == tag["epc"])
        .expect("a true position")["position"];
    (p["x"].as_f64().expect("x"), p["y"].as_f64().expect("y"))
}

#[test]
fn after_a_long_park_under_busy_threads_every_tag_converges_where_it_is() {
    // Clean reads: on S1's own `impinj-r420` reads no tag's σ reaches the 1 cm of `converged`.
    let (truth, tags) = run_sim("truth", "ideal", "10", PARKED_UNTIL_US, 3);
    let mut converged = 0;
    for t in &tags {
        if t["state"] != "converged" {
            continue;
        }
        converged += 1;
        let epc = t["epc"].as_str().expect("epc");
        let (x, y) = true_xy(&truth, t);
        let error_m = (t["estimate"]["x"].as_f64().expect("x") - x)
            .hypot(t["estimate"]["y"].as_f64().expect("y") - y);
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

/// On the robot's own poses (S1's localization stack, σ 15 mm, 0.5°, correlated over 2 s, which
/// `sim` refines from the tags' phases as it goes) with reader model `model`, the drive and
/// some parking after it: every truth inside its 99.9 % ellipse, a converged tag within 3 cm;
/// the tags inside their 95 % ellipse, the mean error (m) and the tags.
fn own_poses(model: &str) -> (usize, f64, Vec<serde_json::Value>) {
    let (truth, tags) = run_sim("estimated", model, "20", 200_000_000, 0);
    let (mut estimated, mut inside95, mut sum_m) = (0, 0, 0.0);
    for t in &tags {
        let Some(c) = t["covariance"].as_array() else {
            continue;
        };
        estimated += 1;
        let c: Vec<f64> = c.iter().map(|v| v.as_f64().expect("a number")).collect();
        let (x, y) = true_xy(&truth, t);
        let (dx, dy) = (
            x - t["estimate"]["x"].as_f64().expect("x"),
            y - t["estimate"]["y"].as_f64().expect("y"),
        );
        let det = c[0] * c[4] - c[1] * c[3];
        let m2 = (c[4] * dx * dx - (c[1] + c[3]) * dx * dy + c[0] * dy * dy) / det;
        // χ²(2): 5.99 at 95 %, 13.8 at 99.9 %.
        assert!(m2 <= 13.8, "truth {m2:.1} (Mahalanobis²) outside: {t}");
        inside95 += usize::from(m2 <= 5.99);
        let error_m = dx.hypot(dy);
        sum_m += error_m;
        assert!(
            t["state"] != "converged" || error_m < 0.03,
            "converged {error_m} m away: {t}"
        );
    }
    assert_eq!(estimated, 10, "{tags:?}");
    (inside95, sum_m / 10.0, tags)
}

#[test]
fn on_the_robots_own_poses_and_clean_reads_the_live_default_is_within_g_15_mm_and_its_ellipses_hold(
) {
    let (inside95, mean_m, tags) = own_poses("ideal");
    assert!(
        inside95 >= 9,
        "{inside95} of 10 inside their 95 % ellipse: {tags:?}"
    );
    // [G]'s 15 mm (issue 40 §2): 10.4–10.9 mm (2026-12-07) with straight tracks and resting
    // antennas (docs/localize.md), under load as well; 17.8 mm before them, 31 mm on the poses
    // as reported without refinement.
    assert!(mean_m < 0.015, "mean error {mean_m} m: {tags:?}");
}

#[test]
fn on_reads_as_hardware_gives_them_the_live_defaults_ellipses_hold_their_tags() {
    // S1's own reader model, `impinj-r420`: about 12 cm mean since each tag has its own phase
    // curvature (2026-12-08; 29 mm before), which the ellipses must own up to (the tags'
    // curvature share, the phase error smooth in the direction read from, and the poses'
    // stated error; docs/localize.md).
    let (inside95, mean_m, tags) = own_poses("impinj-r420");
    assert!(
        inside95 >= 9,
        "{inside95} of 10 inside their 95 % ellipse (mean {mean_m} m): {tags:?}"
    );
}
