//! Fleet scale through a real mosquitto (started here on a free loopback port): `sim
//! --publish` → broker → localizer workers (`localize --subscribe`), which publish their
//! estimates back, retained. NATS JetStream's MQTT interface: `fleet_nats.rs`.

mod broker_support;
mod http_support;

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use broker_support::agree::two_workers_agree;
use broker_support::{publishing_sim, worker, Mosquitto, Probe};
use http_support::{counter, request};

#[test]
#[ignore = "needs mosquitto (./scripts/install-brokers); ./scripts/test runs it"]
fn two_workers_on_disjoint_shards_give_the_estimates_of_one_worker_on_all() {
    let broker = Mosquitto::start("");
    two_workers_agree(&broker.url("site"), broker.port);
}

#[test]
#[ignore = "needs mosquitto (./scripts/install-brokers); ./scripts/test runs it"]
fn malformed_messages_are_counted_and_skipped_and_the_worker_goes_on() {
    let broker = Mosquitto::start("");
    let url = broker.url("m");
    let (_w, http) = worker(&url, &["--client-id", "m-worker"]);
    let probe = Probe::connect(broker.port, "m-probe", &[]);
    probe.publish("m/v1/reads/0", b"{not json");
    probe.publish(
        "m/v1/refs",
        br#"{"v": 2, "gateway": "g", "reader": "r", "seq": 1, "reads": []}"#,
    );
    probe.publish("m/v1/poses/r/1", br#"{"x": "north"}"#);
    let good = serde_json::json!({
        "v": 1, "gateway": "g", "reader": "r", "seq": 1,
        "reads": [{"epcHex": "300833B2DDD9014000000001", "antennaPort": 1, "phaseAngle": 90.0,
                   "frequency": 866300, "lastSeenTime": "2026-01-01T00:00:00Z",
                   "firstSeenUs": 1_000_000}]
    });
    let shard = llrp_gateway::fleet::schema::shard("300833B2DDD9014000000001", 16);
    probe.publish(&format!("m/v1/reads/{shard}"), good.to_string().as_bytes());
    let deadline = Instant::now() + Duration::from_secs(20);
    while counter(http, "mqtt_received") < 4.0 && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(50));
    }
    assert_eq!(counter(http, "mqtt_received"), 4.0);
    assert_eq!(counter(http, "mqtt_malformed"), 3.0);
    // The good read was taken in (and set aside: no pose for it yet).
    let deadline = Instant::now() + Duration::from_secs(20);
    while counter(http, "reads") < 1.0 && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(50));
    }
    assert_eq!(counter(http, "reads"), 1.0);
    assert_eq!(request(http, "GET", "/healthz", &[], b"").status, 200);
}

#[test]
#[ignore = "needs mosquitto (./scripts/install-brokers); ./scripts/test runs it"]
fn presence_events_tell_arrivals_moves_and_departures_with_positions() {
    let broker = Mosquitto::start("");
    let url = broker.url("p");
    let probe = Probe::connect(broker.port, "presence-probe", &["p/v1/presence/+"]);
    let _w = worker(
        &url,
        &["--presence-silence-s", "1", "--presence-move-m", "0.5"],
    );
    {
        let _sim = publishing_sim(&url, &["--poses", "truth"]);
        std::thread::sleep(Duration::from_secs(3));
    }
    // Silent for the second of silence after the simulator stopped: every tag departs.
    std::thread::sleep(Duration::from_secs(2));
    let mut by_tag: BTreeMap<String, Vec<serde_json::Value>> = BTreeMap::new();
    for (topic, payload, _) in probe.drain(Duration::from_secs(1)) {
        let v: serde_json::Value = serde_json::from_slice(&payload).expect("JSON");
        assert_eq!(
            topic,
            format!("p/v1/presence/{}", v["epc"].as_str().expect("epc"))
        );
        by_tag
            .entry(v["epc"].as_str().unwrap_or_default().into())
            .or_default()
            .push(v);
    }
    assert_eq!(by_tag.len(), 10, "{by_tag:?}");
    for (epc, events) in &by_tag {
        let kinds: Vec<&str> = events
            .iter()
            .map(|e| e["event"].as_str().unwrap_or(""))
            .collect();
        assert_eq!(kinds.first(), Some(&"arrived"), "{epc}: {kinds:?}");
        assert_eq!(kinds.last(), Some(&"departed"), "{epc}: {kinds:?}");
        // Each tag got a position once estimated, and the departure carries the latest.
        assert!(kinds.contains(&"moved"), "{epc}: {kinds:?}");
        let last = events.last().expect("departed");
        assert!(
            last["position"].is_array() && last["reader"] == "s1-reader",
            "{last}"
        );
    }
}

#[test]
#[ignore = "needs mosquitto (./scripts/install-brokers); ./scripts/test runs it"]
fn the_simulators_reads_carry_their_antennas_pose_and_its_messages_one_run() {
    let broker = Mosquitto::start("");
    let url = broker.url("s");
    let probe = Probe::connect(
        broker.port,
        "stamp-probe",
        &["s/v1/reads/+", "s/v1/status/+"],
    );
    {
        let _sim = publishing_sim(&url, &["--poses", "truth"]);
        std::thread::sleep(Duration::from_secs(2));
    }
    let (mut runs, mut xs) = (std::collections::BTreeSet::new(), Vec::new());
    for (topic, payload, _) in probe.drain(Duration::from_secs(1)) {
        let v: serde_json::Value = serde_json::from_slice(&payload).expect("JSON");
        if topic.starts_with("s/v1/status/gateway/") {
            continue;
        }
        runs.insert(v["run"].as_u64().expect("a run in every reader's message"));
        for r in v["reads"].as_array().into_iter().flatten() {
            let pose = &r["antennaPose"];
            assert!(
                ["x", "y", "z", "yaw_deg", "pitch_deg"]
                    .iter()
                    .all(|k| pose[k].is_f64()),
                "a read without its antenna's pose: {r}"
            );
            xs.push(pose["x"].as_f64().unwrap_or_default());
        }
    }
    assert!(xs.len() > 10, "{} reads", xs.len());
    // S1's antenna is on a robot: the pose is the one at each read, not one for all.
    let spread =
        xs.iter().copied().fold(f64::MIN, f64::max) - xs.iter().copied().fold(f64::MAX, f64::min);
    assert!(spread > 0.1, "the antenna moved {spread} m over the reads");
    assert_eq!(runs.len(), 1, "{runs:?}");
    assert!(
        runs.first().is_some_and(|&r| r > 1_700_000_000_000_000),
        "{runs:?}"
    );
}
