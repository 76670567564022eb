//! The fleet's central check, shared by the brokers' test binaries: sim → broker → one worker
//! on all shards and two on halves, whose estimates must agree.

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::time::{Duration, Instant};

use super::{publishing_sim, worker, Probe};
use crate::http_support::{counter, request};

/// EPC → (samples, [x, y, z]) of every located tag of `GET /api/tags`.
pub fn located(http: SocketAddr) -> BTreeMap<String, (u64, [f64; 3])> {
    let v = request(http, "GET", "/api/tags", &[], b"").json();
    let mut out = BTreeMap::new();
    for t in v["tags"].as_array().cloned().unwrap_or_default() {
        let e = &t["estimate"];
        if let (Some(x), Some(y), Some(z)) = (e["x"].as_f64(), e["y"].as_f64(), e["z"].as_f64()) {
            let epc = t["epc"].as_str().unwrap_or_default().to_string();
            out.insert(epc, (t["samples"].as_u64().unwrap_or(0), [x, y, z]));
        }
    }
    out
}

pub fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// sim → the broker at `url` (MQTT on `port`) → one worker on all shards and two on halves.
pub fn two_workers_agree(url: &str, port: u16) {
    let url = url.to_string();
    let (_all, all_http) = worker(&url, &["--shards", "0-15", "--client-id", "all"]);
    let (_low, low_http) = worker(&url, &["--shards", "0-7", "--client-id", "low"]);
    let (_high, high_http) = worker(&url, &["--shards", "8-15", "--client-id", "high"]);
    // (Not `status/#`: NATS 2.9's MQTT interface gives a `#` subscription nothing retained,
    // nats-server issues 4760 and 4919.)
    let status = [Probe::connect(
        port,
        "status-probe",
        &["site/v1/status/+", "site/v1/status/gateway/+"],
    )];
    {
        let _sim = publishing_sim(&url, &["--poses", "truth", "--gateway-name", "gw1"]);
        // S1's 46 s drive at 20× real time, and a margin short enough that no tag reaches
        // the workers' bound of 4,096 phases (the robot parks by the last tag): what thinning
        // keeps depends on the order reads came in, and the broker may redeliver out of order.
        std::thread::sleep(Duration::from_secs(3));
        // Dropped: SIGTERM, and a clean exit publishes the offline statuses.
    }
    let statuses: BTreeMap<String, serde_json::Value> = status
        .iter()
        .flat_map(|p| p.drain(Duration::from_secs(2)))
        .map(|(t, p, _)| (t, serde_json::from_slice(&p).expect("status JSON")))
        .collect();
    let reader = &statuses["site/v1/status/s1-reader"];
    assert_eq!(reader["status"], "offline", "{statuses:?}");
    let gateway = statuses.get("site/v1/status/gateway/gw1");
    assert_eq!(
        gateway.map(|g| g["status"].clone()),
        Some("offline".into()),
        "{statuses:?}"
    );
    let last_seq = reader["lastSeq"].as_object().expect("lastSeq").clone();
    assert!(
        last_seq.keys().any(|k| k.starts_with("reads/")),
        "{last_seq:?}"
    );

    // Each worker has taken every message and estimated every tag once the two sides agree.
    let deadline = Instant::now() + Duration::from_secs(60);
    let (one, two) = loop {
        let one = located(all_http);
        let mut two = located(low_http);
        two.extend(located(high_http));
        let agree = one.len() == 10
            && one.keys().eq(two.keys())
            && one.iter().all(|(epc, (n, p))| {
                let (m, q) = two[epc];
                *n == m && distance(*p, q) <= 1e-6
            });
        if agree || Instant::now() > deadline {
            break (one, two);
        }
        std::thread::sleep(Duration::from_millis(200));
    };
    let diagnosis: Vec<String> = [all_http, low_http, high_http]
        .iter()
        .map(|&h| {
            [
                "mqtt_received",
                "mqtt_gaps",
                "mqtt_duplicates",
                "mqtt_reordered",
                "mqtt_filed_late",
                "reads",
                "reads_set_aside",
                "poses",
            ]
            .map(|n| format!("{n} {}", counter(h, n)))
            .join(", ")
        })
        .collect();
    eprintln!("workers (all, low, high): {diagnosis:#?}");
    let most = one.values().map(|(n, _)| *n).max().unwrap_or(0);
    eprintln!("most phases a tag: {most}");
    assert_eq!(one.len(), 10, "one worker located {one:?}");
    for (epc, (n, p)) in &one {
        let (m, q) = two
            .get(epc)
            .copied()
            .unwrap_or_else(|| panic!("{epc} not in {two:?}"));
        assert_eq!(*n, m, "{epc}: samples");
        assert!(distance(*p, q) <= 1e-6, "{epc}: {p:?} vs {q:?}");
    }
    // Disjoint: every tag is estimated by exactly one of the two.
    assert_eq!(located(low_http).len() + located(high_http).len(), 10);
    for http in [all_http, low_http, high_http] {
        assert_eq!(counter(http, "mqtt_gaps"), 0.0);
        assert_eq!(counter(http, "mqtt_malformed"), 0.0);
        assert!(counter(http, "mqtt_received") > 0.0);
    }
    // The estimates are on the broker, retained, for a subscriber that comes later.
    let late = Probe::connect(port, "late", &["site/v1/estimates/+"]);
    let retained: Vec<_> = late.drain(Duration::from_secs(2));
    assert_eq!(retained.len(), 10, "{} retained estimates", retained.len());
    for (topic, payload, retain) in retained {
        assert!(retain, "{topic}");
        let v: serde_json::Value = serde_json::from_slice(&payload).expect("JSON");
        let epc = v["epc"].as_str().expect("epc");
        assert_eq!(topic, format!("site/v1/estimates/{epc}"));
        let e = &v["estimate"];
        let p = [e["x"].as_f64(), e["y"].as_f64(), e["z"].as_f64()].map(|c| c.expect("x, y, z"));
        assert!(distance(p, one[epc].1) <= 1e-6, "{epc}: {p:?}");
    }
}
