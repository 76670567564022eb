//! A localizer worker's `--mcap FILE` (docs/robotics.md): `sim --publish` → a real mosquitto
//! → `localize --subscribe URL --mcap FILE`, whose file holds the estimates it computed on
//! `/estimates/tags` and a scene of them on `/scene`, read by the independent readers of
//! `scripts/interop/mcap_check.py` (`LLRP_MCAP_PYTHON`).

mod broker_support;
mod http_support;
mod mcap_support;

use std::collections::BTreeSet;
use std::time::{Duration, Instant};

use broker_support::{publishing_sim, worker, Mosquitto};
use http_support::request;

/// Waits (a hang guard, not a measurement) until the worker at `http` has a position for
/// three tags at least; the EPCs it has a position for.
fn wait_for_estimates(http: std::net::SocketAddr) -> BTreeSet<String> {
    let until = Instant::now() + mcap_support::GUARD;
    loop {
        let tags = request(http, "GET", "/api/tags", &[], b"").json();
        let placed: BTreeSet<String> = (tags["tags"].as_array().expect("tags").iter())
            .filter(|t| t["state"] == "converged" || t["state"] == "converging")
            .map(|t| t["epc"].as_str().expect("epc").to_uppercase())
            .collect();
        if placed.len() >= 3 {
            return placed;
        }
        assert!(
            Instant::now() < until,
            "the worker has not placed them: {tags}"
        );
        std::thread::sleep(Duration::from_millis(200));
    }
}

#[test]
#[ignore = "needs mosquitto (./scripts/install-brokers) and the MCAP readers (LLRP_MCAP_PYTHON); ./scripts/test runs it"]
fn a_worker_s_mcap_file_holds_the_estimates_it_computed_and_their_scene() {
    let broker = Mosquitto::start("");
    let url = broker.url("x");
    let dir = tempfile::tempdir().expect("temp dir");
    let mcap = dir.path().join("worker.mcap");
    let (mut w, http) = worker(
        &url,
        &[
            "--client-id",
            "mcap-worker",
            "--mcap",
            mcap.to_str().expect("utf-8"),
        ],
    );
    let placed = {
        let _sim = publishing_sim(&url, &["--poses", "truth"]);
        wait_for_estimates(http)
    };
    assert!(w.stop().success(), "the worker stopped cleanly");
    let v = mcap_support::check(&mcap);
    let ch = mcap_support::channels(&v);
    assert_eq!(ch["/estimates/tags"].0, "llrp_gateway_msgs/msg/TagEstimate");
    assert_eq!(ch["/scene"].0, "foxglove_msgs/msg/SceneUpdate");
    for decoder in ["mcap_ros2", "rosbags"] {
        assert_eq!(v[decoder]["scenes"], v["mcap_ros2"]["scenes"], "{decoder}");
        assert_eq!(
            v[decoder]["estimates"], v["mcap_ros2"]["estimates"],
            "{decoder}"
        );
    }
    let estimates = v["mcap_ros2"]["estimates"].as_array().expect("estimates");
    let epcs: BTreeSet<String> = (estimates.iter())
        .map(|e| e["epc"].as_str().expect("epc").to_string())
        .collect();
    assert!(epcs.is_superset(&placed), "{epcs:?} vs {placed:?}");
    let scenes = v["mcap_ros2"]["scenes"].as_array().expect("scenes");
    let last = scenes.last().expect("a scene");
    let mut drawn = BTreeSet::new();
    for e in last["entities"].as_array().expect("entities") {
        let id = e["id"].as_str().expect("an id");
        let epc = id
            .strip_prefix("estimate/")
            .unwrap_or_else(|| panic!("a worker knows no truth, only estimates: {id}"));
        let center = &e["spheres"][0]["position"];
        let stamp = e["stamp_ns"].as_u64().expect("a stamp");
        (estimates.iter())
            .rfind(|m| {
                m["epc"] == epc
                    && m["position"] == *center
                    && m["log_time"].as_u64().is_some_and(|t| t <= stamp)
            })
            .unwrap_or_else(|| panic!("{id}: no estimate at {center} by {stamp}"));
        drawn.insert(epc.to_string());
    }
    assert!(drawn.is_superset(&placed), "{drawn:?} vs {placed:?}");
}
