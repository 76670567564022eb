//! The subscriber of the MQTT benchmarks (scripts/bench-mqtt): counts the tag reads that
//! arrive on a topic filter of a broker, or measures the latency of published estimates.
//!
//! `mqtt_subscriber reads PORT FILTER FORMAT SECONDS` — from the first message on, counts for
//! SECONDS (or until nothing has come for 3 s) the reads in each message (FORMAT `batch`:
//! llrp-gateway's read batches, `llrpkit`: one read a message; parsed into their types) and
//! prints `{"reads", "messages", "seconds", "reads_per_s"}`, the rate over the span from the
//! first message to the last.
//!
//! `mqtt_subscriber latency PORT FILTER SECONDS` — for SECONDS, takes each estimate published
//! on FILTER (one element of `GET /api/tags`) and its age on arrival, the wall clock minus the
//! tag's newest read (`last_seen`, UTC µs; meaningful for a simulator at real time), and prints
//! `{"estimates", "p50_ms", "p99_ms", "max_ms"}`. With a second filter READS (read batches),
//! also the age of each read on arrival there, the wall clock minus its `firstSeenUs`:
//! `"reads"`, `"read_p50_ms"`, `"read_p99_ms"`.

use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use llrp_gateway::fleet::schema::ReadBatch;
use rumqttc::{Client, Event, MqttOptions, Packet, QoS};

/// One message of llrpkit's bridge (`{base}/tags`, its `tag_payload`).
#[derive(serde::Deserialize)]
#[allow(dead_code)]
struct LlrpkitRead {
    reader: String,
    epc: String,
    antenna: Option<u16>,
    rssi_dbm: Option<f64>,
    phase_deg: Option<f64>,
    doppler_hz: Option<f64>,
    channel: Option<u16>,
    at: f64,
}

fn utc_now_us() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as u64)
}

fn usage() -> ! {
    eprintln!(
        "usage: mqtt_subscriber reads PORT FILTER batch|llrpkit SECONDS\n       mqtt_subscriber latency PORT FILTER SECONDS [READS]"
    );
    std::process::exit(2)
}

fn connect(port: u16, filter: &str) -> rumqttc::Connection {
    connect_qos(port, filter, QoS::AtLeastOnce, "")
}

fn connect_qos(port: u16, filter: &str, qos: QoS, tag: &str) -> rumqttc::Connection {
    let mut o = MqttOptions::new(
        format!("bench-subscriber-{}{tag}", std::process::id()),
        rumqttc::Broker::tcp("127.0.0.1", port),
    );
    o.set_max_packet_size(1 << 22, 1 << 22);
    o.set_keep_alive(30);
    let (client, connection) = Client::builder(o).capacity(1000).build();
    if client.subscribe(filter, qos).is_err() {
        eprintln!("mqtt_subscriber: cannot subscribe");
        std::process::exit(1);
    }
    // The client lives as long as the connection needs it.
    std::mem::forget(client);
    connection
}

fn reads(port: u16, filter: &str, format: &str, seconds: f64) {
    let mut connection = connect(port, filter);
    let (mut reads, mut messages) = (0u64, 0u64);
    let mut started: Option<Instant> = None;
    let mut last = Instant::now();
    let window = Duration::from_secs_f64(seconds);
    // Gives up when nothing has come for a minute.
    let give_up = Instant::now() + Duration::from_secs(60);
    loop {
        let idle = started.is_some() && last.elapsed() >= Duration::from_secs(3);
        if idle || started.map_or(Instant::now() >= give_up, |t| t.elapsed() >= window) {
            break;
        }
        let p = match connection.recv_timeout(Duration::from_millis(100)) {
            Ok(Ok(Event::Incoming(Packet::Publish(p)))) => p,
            Ok(Ok(_)) | Err(_) => continue,
            Ok(Err(e)) => {
                eprintln!("mqtt_subscriber: {e}");
                std::thread::sleep(Duration::from_millis(100));
                continue;
            }
        };
        started.get_or_insert_with(Instant::now);
        // Parsed into the schema's types, as a consumer would.
        let n = match format {
            "batch" => serde_json::from_slice::<ReadBatch>(&p.payload).map(|b| b.reads.len()),
            _ => serde_json::from_slice::<LlrpkitRead>(&p.payload).map(|_| 1),
        };
        let Ok(n) = n else {
            continue;
        };
        messages += 1;
        reads += n as u64;
        last = Instant::now();
    }
    let s = started.map_or(0.0, |t| last.duration_since(t).as_secs_f64());
    println!(
        "{}",
        serde_json::json!({
            "reads": reads,
            "messages": messages,
            "seconds": s,
            "reads_per_s": if s > 0.0 { reads as f64 / s } else { 0.0 },
        })
    );
}

fn latency(port: u16, filter: &str, seconds: f64, reads_filter: Option<&str>) {
    let mut connection = connect(port, filter);
    // The reads on a connection of their own, at QoS 0: they never hold up the estimates.
    let sampler = reads_filter.map(|r| {
        let mut c = connect_qos(port, r, QoS::AtMostOnce, "-reads");
        let end = Instant::now() + Duration::from_secs_f64(seconds);
        std::thread::spawn(move || {
            let mut ages = Vec::new();
            while Instant::now() < end {
                let Ok(Ok(Event::Incoming(Packet::Publish(p)))) =
                    c.recv_timeout(Duration::from_millis(100))
                else {
                    continue;
                };
                if let Ok(b) = serde_json::from_slice::<ReadBatch>(&p.payload) {
                    let now = utc_now_us();
                    ages.extend(
                        b.reads
                            .iter()
                            .map(|r| now.saturating_sub(r.first_seen_us) as f64 / 1000.0),
                    );
                }
            }
            ages
        })
    });
    let end = Instant::now() + Duration::from_secs_f64(seconds);
    let mut ages: Vec<f64> = Vec::new();
    // With MQTT_SUBSCRIBER_AGES=FILE: every estimate's arrival (s from the start) and age (ms).
    let mut dump = std::env::var_os("MQTT_SUBSCRIBER_AGES")
        .and_then(|path| std::fs::File::create(path).ok())
        .map(std::io::BufWriter::new);
    let start = Instant::now();
    while Instant::now() < end {
        let Ok(Ok(Event::Incoming(Packet::Publish(p)))) =
            connection.recv_timeout(Duration::from_millis(100))
        else {
            continue;
        };
        // Retained estimates of an earlier run are old news.
        if p.retain {
            continue;
        }

        let Ok(v) = serde_json::from_slice::<serde_json::Value>(&p.payload) else {
            continue;
        };
        let Some(seen) = v["last_seen"].as_u64() else {
            continue;
        };
        let now = utc_now_us();
        let age = now.saturating_sub(seen) as f64 / 1000.0;
        if let Some(out) = dump.as_mut() {
            use std::io::Write;
            let epc = v["epc"].as_str().unwrap_or_default();
            let _ = writeln!(out, "{:.4}\t{age:.2}\t{epc}", start.elapsed().as_secs_f64());
        }
        ages.push(age);
    }
    ages.sort_by(f64::total_cmp);
    let mut read_ages = sampler.and_then(|s| s.join().ok()).unwrap_or_default();
    read_ages.sort_by(f64::total_cmp);
    let q = |v: &[f64], f: f64| {
        if v.is_empty() {
            0.0
        } else {
            v[((v.len() - 1) as f64 * f).round() as usize]
        }
    };
    println!(
        "{}",
        serde_json::json!({
            "estimates": ages.len(),
            "p50_ms": q(&ages, 0.5),
            "p99_ms": q(&ages, 0.99),
            "max_ms": ages.last().copied().unwrap_or(0.0),
            "reads": read_ages.len(),
            "read_p50_ms": q(&read_ages, 0.5),
            "read_p99_ms": q(&read_ages, 0.99),
        })
    );
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let port = |s: &str| s.parse::<u16>().unwrap_or_else(|_| usage());
    let secs = |s: &str| s.parse::<f64>().unwrap_or_else(|_| usage());
    match args
        .iter()
        .map(String::as_str)
        .collect::<Vec<_>>()
        .as_slice()
    {
        ["reads", p, filter, format @ ("batch" | "llrpkit"), s] => {
            reads(port(p), filter, format, secs(s))
        }
        ["latency", p, filter, s] => latency(port(p), filter, secs(s), None),
        ["latency", p, filter, s, reads] => latency(port(p), filter, secs(s), Some(reads)),
        _ => usage(),
    }
}
