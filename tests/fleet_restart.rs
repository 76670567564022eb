//! Restarting any part of the fleet: the broker (persistence on) in the middle of a
//! simulator's stream, and a localizer worker killed and started again with its session.
//! Real mosquitto, loopback only.

mod broker_support;
mod http_support;

use std::net::SocketAddr;
use std::time::{Duration, Instant};

use broker_support::{worker, Mosquitto, Probe};
use http_support::{counter, request, Proc};

/// What a broker restart did to a stream.
struct Outcome {
    /// Messages the simulator counted as dropped.
    dropped: f64,
    /// Sequence numbers missing at a subscriber that saw the stream from its start.
    missing: u64,
    /// The worker's count of gaps.
    gaps: f64,
    /// Messages the simulator published.
    published: f64,
}

/// Runs `sim --publish` through a broker restart with an outbox of `queue` messages.
fn through_a_broker_restart(queue: &str) -> Outcome {
    let mut broker = Mosquitto::start_with(|port, dir| {
        format!(
            "listener {port} 127.0.0.1\nallow_anonymous true\npersistence true\n\
             persistence_location {}/\n",
            dir.display()
        )
    });
    let url = broker.url("r");
    let (_w, http) = worker(&url, &["--client-id", "restart-worker"]);
    // Every sequenced message, from the start, across the restart.
    let probe = Probe::connect_persistent(
        broker.port,
        "restart-probe",
        &[
            "r/v1/reads/+",
            "r/v1/refs",
            "r/v1/events/+",
            "r/v1/status/+",
        ],
    );
    let mut sim = Proc::spawn(&[
        "sim",
        "--http",
        "127.0.0.1:0",
        "--listen",
        "127.0.0.1:0",
        "--speed",
        "20",
        "--publish",
        &url,
        "--publish-queue",
        queue,
    ]);
    let sim_http: SocketAddr = sim.address("live map on http://").parse().expect("address");
    sim.address("listening on ");
    // Reads flow, then the broker goes away for a second and comes back.
    let deadline = Instant::now() + Duration::from_secs(20);
    while counter(http, "mqtt_received") < 100.0 {
        assert!(Instant::now() < deadline, "no reads before the restart");
        std::thread::sleep(Duration::from_millis(20));
    }
    broker.stop();
    std::thread::sleep(Duration::from_secs(1));
    broker.restart();
    // The stream goes on after the return, so every loss is a gap between two messages.
    let resumed = counter(sim_http, "mqtt_published");
    let deadline = Instant::now() + Duration::from_secs(30);
    while counter(sim_http, "mqtt_published") < resumed + 2000.0 {
        assert!(Instant::now() < deadline, "the publisher did not resume");
        std::thread::sleep(Duration::from_millis(50));
    }
    let dropped = counter(sim_http, "mqtt_dropped_messages");
    let published = counter(sim_http, "mqtt_published");
    drop(sim);
    // The reader's clean offline (after every read message) closes the worker's count.
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        let readers = request(http, "GET", "/api/readers", &[], b"").json();
        let offline = readers["readers"].as_array().is_some_and(|r| {
            r.iter()
                .any(|r| r["name"] == "s1-reader" && r["connected"] == false)
        });
        if offline {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "no offline status at the worker: {readers}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    // The worker saw the broker go, too.
    assert!(counter(http, "mqtt_disconnects") >= 1.0);
    // What the probe saw against the reader's last sequence numbers.
    let mut seen: std::collections::BTreeMap<String, std::collections::BTreeSet<u64>> =
        Default::default();
    let mut last = None;
    for (topic, payload, _) in probe.drain(Duration::from_secs(2)) {
        let v: serde_json::Value = serde_json::from_slice(&payload).expect("JSON");
        let rest = topic.trim_start_matches("r/v1/").to_string();
        if rest.starts_with("status/") {
            if v["status"] == "offline" {
                last = Some(v["lastSeq"].clone());
            }
        } else {
            let seq = v["seq"].as_u64().expect("seq");
            seen.entry(rest).or_default().insert(seq);
        }
    }
    let last = last.expect("the reader's offline status");
    let missing = last
        .as_object()
        .expect("lastSeq")
        .iter()
        .filter(|(rest, _)| !rest.starts_with("status"))
        .map(|(rest, n)| {
            let n = n.as_u64().expect("a number");
            let got = seen.get(rest).map_or(0, |s| s.range(1..=n).count() as u64);
            n - got
        })
        .sum();
    // The worker counts what is still missing once the close's grace has passed, at its
    // connection's next event (a keep-alive ping at least every 5 s).
    let settled = Instant::now() + llrp_gateway::fleet::seq::CLOSE_GRACE + Duration::from_secs(6);
    while counter(http, "mqtt_gaps") == 0.0 && Instant::now() < settled {
        std::thread::sleep(Duration::from_millis(100));
    }
    Outcome {
        dropped,
        missing,
        gaps: counter(http, "mqtt_gaps"),
        published,
    }
}

#[test]
#[ignore = "needs mosquitto (./scripts/install-brokers); ./scripts/test runs it"]
fn a_broker_restart_within_the_queue_bound_loses_no_sequence_number() {
    let o = through_a_broker_restart("100000");
    assert!(o.published > 2000.0);
    assert_eq!(o.dropped, 0.0, "the publisher dropped messages");
    assert_eq!(o.missing, 0, "sequence numbers missing at the probe");
    assert_eq!(o.gaps, 0.0, "the worker is missing messages");
}

#[test]
#[ignore = "needs mosquitto (./scripts/install-brokers); ./scripts/test runs it"]
fn overflow_beyond_the_queue_is_counted_exactly() {
    let o = through_a_broker_restart("200");
    assert!(
        o.dropped > 0.0,
        "a second at 20x should overflow 200 messages"
    );
    assert_eq!(
        o.missing as f64, o.dropped,
        "every message dropped is missing at the probe, and no other"
    );
    // The worker counts what it can tell: jumps after its first message of a topic.
    assert!(
        o.gaps > 0.0 && o.gaps <= o.dropped,
        "worker gaps {}",
        o.gaps
    );
}

#[test]
#[ignore = "needs mosquitto (./scripts/install-brokers); ./scripts/test runs it"]
fn a_worker_killed_and_restarted_gets_what_was_published_meanwhile() {
    let broker = Mosquitto::start("");
    let url = broker.url("k");
    let probe = Probe::connect(broker.port, "k-probe", &[]);
    let epc = |i: u64| format!("300833B2DDD9014000{i:06X}");
    let mut seqs = std::collections::BTreeMap::new();
    let mut publish = |i: u64| {
        let e = epc(i);
        let topic = format!("k/v1/reads/{}", llrp_gateway::fleet::schema::shard(&e, 16));
        let seq = seqs.entry(topic.clone()).or_insert(0u64);
        *seq += 1;
        let b = serde_json::json!({
            "v": 1, "gateway": "probe", "reader": "r", "seq": *seq,
            "reads": [{"epcHex": e, "antennaPort": 1, "phaseAngle": 10.0, "frequency": 866300,
                       "lastSeenTime": "2026-01-01T00:00:00Z", "firstSeenUs": 1_000_000 + i,
                       "antennaPose": {"x": 0.0, "y": 0.0, "z": 1.0}}]
        });
        probe.publish_acked(&topic, b.to_string().as_bytes());
    };
    let (mut first, http) = worker(&url, &["--client-id", "k-worker"]);
    for i in 1..=50 {
        publish(i);
    }
    let deadline = Instant::now() + Duration::from_secs(20);
    while counter(http, "mqtt_received") < 50.0 {
        assert!(
            Instant::now() < deadline,
            "the first worker did not take 50"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    first.kill_hard();
    // Published while no worker runs: the broker keeps them in the worker's session.
    for i in 51..=100 {
        publish(i);
    }
    let (_second, http) = worker(&url, &["--client-id", "k-worker"]);
    let deadline = Instant::now() + Duration::from_secs(20);
    for i in 51..=100 {
        while request(http, "GET", &format!("/api/tags/{}", epc(i)), &[], b"").status != 200 {
            assert!(
                Instant::now() < deadline,
                "tag {i} never reached the restarted worker"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }
    assert_eq!(counter(http, "mqtt_gaps"), 0.0);
    assert!(counter(http, "mqtt_received") >= 50.0);
}
