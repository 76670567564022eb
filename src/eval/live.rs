//! `bench localize`'s live part: the run's reads offered to a live localizer in their own
//! time order (at a multiple of real time), its HTTP API on a loopback port (both started by
//! the command's composition root), and an event-stream subscriber over TCP; the latency of each estimate update is the time from
//! the offer of the read it rests on (its newest) to the update's arrival at the subscriber.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use tokio::io::{AsyncBufReadExt, AsyncWriteExt, BufReader};

use super::bench::Run;
use crate::localize::live::{Input, Live, Settings};

/// Latency percentiles of the live updates (s).
#[derive(Clone, Debug, PartialEq)]
pub struct Latency {
    /// Updates measured.
    pub updates: usize,
    /// Median.
    pub p50: f64,
    /// 99th percentile.
    pub p99: f64,
    /// Largest.
    pub max: f64,
    /// Reads the tap dropped.
    pub dropped: u64,
}

/// When each read was offered: (EPC, read time) -> the instant of its offer.
type Offered = Arc<Mutex<HashMap<(crate::reads::Epc, u64), Instant>>>;

/// Offers `run`'s reads (true poses first) at `speed` times real time to the localizer `live`,
/// whose HTTP API is on `http`, and measures each update's read-to-HTTP latency.
pub async fn measure(
    run: &Run,
    speed: f64,
    live: &Live,
    http: std::net::SocketAddr,
) -> Result<Latency, String> {
    offer_poses(run, live).await;
    let offered: Offered = Arc::default();
    let latencies: Arc<Mutex<Vec<f64>>> = Arc::default();
    let subscriber = subscribe(http, offered.clone(), latencies.clone()).await?;
    tokio::time::sleep(Duration::from_millis(100)).await;
    offer_reads(run, speed, live, &offered).await;
    tokio::time::sleep(Duration::from_millis(500)).await;
    let dropped = live.shared.metrics.dropped_taps.get();
    subscriber.abort();
    let v = latencies.lock().map_err(|e| e.to_string())?.clone();
    percentiles(v, dropped)
}

/// The localizer settings of `run`'s live measurement.
pub fn settings(run: &Run) -> Settings {
    Settings {
        geometry: run.settings.geometry.clone(),
        ambiguity: run.settings.ambiguity,
        ..Settings::default()
    }
}

/// Offers every pose of `run` first (a robot's feed that runs ahead of the reads).
async fn offer_poses(run: &Run, live: &Live) {
    for chunk in run.true_poses.samples().chunks(1024) {
        let mut input = Input::Poses(chunk.to_vec());
        while let Err(back) = live.tap.try_offer(input) {
            input = back;
            tokio::time::sleep(Duration::from_millis(1)).await;
        }
    }
}

/// Subscribes to the events at `addr`, pushing each update's latency since its read's offer.
async fn subscribe(
    addr: std::net::SocketAddr,
    offered: Offered,
    latencies: Arc<Mutex<Vec<f64>>>,
) -> Result<tokio::task::JoinHandle<()>, String> {
    let mut stream = tokio::net::TcpStream::connect(addr)
        .await
        .map_err(|e| e.to_string())?;
    stream
        .write_all(b"GET /api/events HTTP/1.1\r\nHost: bench\r\nAccept: text/event-stream\r\n\r\n")
        .await
        .map_err(|e| e.to_string())?;
    let (o, l) = (offered, latencies);
    Ok(tokio::spawn(async move {
        let mut lines = BufReader::new(stream).lines();
        while let Ok(Some(line)) = lines.next_line().await {
            let Some(data) = line.strip_prefix("data: ") else {
                continue;
            };
            let at = Instant::now();
            let Ok(v) = serde_json::from_str::<serde_json::Value>(data) else {
                continue;
            };
            let (Some(epc), Some(t)) = (v["epc"].as_str(), v["last_seen"].as_u64()) else {
                continue;
            };
            let sent = o
                .lock()
                .ok()
                .and_then(|m| m.get(&(crate::reads::Epc::parse(epc).ok()?, t)).copied());
            if let (Some(sent), Ok(mut l)) = (sent, l.lock()) {
                l.push(at.duration_since(sent).as_secs_f64());
            }
        }
    }))
}

/// Offers `run`'s reads one by one at their times divided by `speed`, noting each offer.
async fn offer_reads(run: &Run, speed: f64, live: &Live, offered: &Offered) {
    let start = Instant::now();
    let t0 = run.reads.first().map_or(0, |r| r.t_us);
    for r in &run.reads {
        let due = Duration::from_secs_f64((r.t_us - t0) as f64 / 1e6 / speed);
        if let Some(wait) = due.checked_sub(start.elapsed()) {
            tokio::time::sleep(wait).await;
        }
        if let Ok(mut m) = offered.lock() {
            m.insert((r.epc.clone(), r.t_us), Instant::now());
        }
        live.tap.offer(Input::Reads(vec![r.clone()]));
    }
}

/// The percentiles of latencies `v` (s); an error if there are none.
fn percentiles(mut v: Vec<f64>, dropped: u64) -> Result<Latency, String> {
    if v.is_empty() {
        return Err("no estimate update reached the subscriber".into());
    }
    v.sort_by(f64::total_cmp);
    let pick = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
    Ok(Latency {
        updates: v.len(),
        p50: pick(0.5),
        p99: pick(0.99),
        max: v[v.len() - 1],
        dropped,
    })
}
