//! Fleet benchmark client (run by `scripts/bench-sim --fleet N`): connects to every simulated
//! reader listed in a file, starts the same inventory on each, and for a number of seconds
//! counts what comes back and how far the reports' last reads lag behind the wall clock.
//! Prints one JSON line.
//!
//! Usage: `fleet ADDR_FILE SECONDS [N]`: ADDR_FILE has one `host:port` per line; N = 0 (the
//! default) runs sllurp's default ROSpec (ROReportTrigger 1 with N = 0: the reader reports
//! every report interval, aggregated per tag); N ≥ 1 reports every N tag reads.

use std::process::ExitCode;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use llrp::enums::{ConnectionAttemptStatus, RoReportTriggerType};
use llrp::message::{AddRospec, EnableRospec, MessageBody};
use llrp::params::{RoReportSpec, RoSpec, TagReportContentSelector};
use llrp::StatusCode;
use llrp_gateway::net::client::{Client, ClientError};

/// What one reader's connection saw.
#[derive(Default)]
struct Seen {
    /// RO_ACCESS_REPORT messages.
    messages: u64,
    /// TagReportData entries.
    tags: u64,
    /// Wall clock minus the last read of each report, ms.
    lags_ms: Vec<f64>,
}

fn now_utc_us() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as u64)
}

/// The inventory every reader runs.
fn rospec(n: u16) -> RoSpec {
    let trigger = if n == 0 {
        RoReportTriggerType::UponNTagsOrEndOfAiSpec
    } else {
        RoReportTriggerType::UponNTagsOrEndOfRoSpec
    };
    RoSpec::immediate(1, vec![0]).with_report(RoReportSpec::new(trigger, n).with_content(
        TagReportContentSelector {
            enable_antenna_id: true,
            enable_peak_rssi: true,
            enable_last_seen_timestamp: true,
            enable_tag_seen_count: true,
            ..Default::default()
        },
    ))
}

/// Connects to `addr`, starts the inventory, and counts reports until `until`.
async fn one(addr: String, n: u16, until: tokio::time::Instant) -> Result<Seen, String> {
    const T: Duration = Duration::from_secs(30);
    let fail = |what: &str, e: ClientError| format!("{addr}: {what}: {e}");
    let mut c = Client::connect(addr.as_str())
        .await
        .map_err(|e| fail("connect", e))?;
    let hello = c.recv(T).await.map_err(|e| fail("greeting", e))?;
    if hello.body.connection_attempt() != Some(ConnectionAttemptStatus::Success) {
        return Err(format!("{addr}: refused: {}", hello.name()));
    }
    let add = AddRospec {
        ro_spec: rospec(n),
        ..Default::default()
    };
    let r = c
        .transact(add, T)
        .await
        .map_err(|e| fail("ADD_ROSPEC", e))?;
    if r.llrp_status.status_code != StatusCode::M_Success {
        return Err(format!("{addr}: ADD_ROSPEC: {:?}", r.llrp_status));
    }
    let enable = EnableRospec {
        ro_spec_id: 1,
        ..Default::default()
    };
    let r = c
        .transact(enable, T)
        .await
        .map_err(|e| fail("ENABLE_ROSPEC", e))?;
    if r.llrp_status.status_code != StatusCode::M_Success {
        return Err(format!("{addr}: ENABLE_ROSPEC: {:?}", r.llrp_status));
    }
    let mut seen = Seen::default();
    loop {
        let left = until.saturating_duration_since(tokio::time::Instant::now());
        if left.is_zero() {
            break;
        }
        let m = match c.recv(left).await {
            Ok(m) => m,
            Err(ClientError::Timeout(_)) => break,
            Err(e) => return Err(fail("reports", e)),
        };
        if let MessageBody::RoAccessReport(r) = m.body {
            seen.messages += 1;
            seen.tags += r.tag_report_data.len() as u64;
            let last = r
                .tag_report_data
                .iter()
                .filter_map(|t| t.last_seen_timestamp_utc.map(|s| s.0))
                .max();
            if let Some(last) = last {
                seen.lags_ms
                    .push(now_utc_us().saturating_sub(last) as f64 / 1e3);
            }
        }
    }
    Ok(seen)
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let k = ((sorted.len() - 1) as f64 * p).round() as usize;
    sorted[k.min(sorted.len() - 1)]
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| a != "--bench")
        .collect();
    let (Some(file), Some(seconds)) = (args.first(), args.get(1)) else {
        eprintln!("usage: fleet ADDR_FILE SECONDS [N]");
        return ExitCode::FAILURE;
    };
    let seconds: f64 = match seconds.parse() {
        Ok(s) if s > 0.0 => s,
        _ => {
            eprintln!("fleet: SECONDS must be a positive number, got {seconds}");
            return ExitCode::FAILURE;
        }
    };
    let n: u16 = match args.get(2).map(|s| s.parse()) {
        None => 0,
        Some(Ok(n)) => n,
        Some(Err(e)) => {
            eprintln!("fleet: N: {e}");
            return ExitCode::FAILURE;
        }
    };
    let addrs: Vec<String> = match std::fs::read_to_string(file) {
        Ok(t) => t
            .lines()
            .map(str::trim)
            .filter(|l| !l.is_empty())
            .map(String::from)
            .collect(),
        Err(e) => {
            eprintln!("fleet: {file}: {e}");
            return ExitCode::FAILURE;
        }
    };
    let runtime = match tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
    {
        Ok(r) => r,
        Err(e) => {
            eprintln!("fleet: cannot start the async runtime: {e}");
            return ExitCode::FAILURE;
        }
    };
    let started = Instant::now();
    let results = runtime.block_on(async {
        let until = tokio::time::Instant::now() + Duration::from_secs_f64(seconds);
        let tasks: Vec<_> = addrs
            .iter()
            .map(|a| tokio::spawn(one(a.clone(), n, until)))
            .collect();
        let mut out = Vec::with_capacity(tasks.len());
        for t in tasks {
            out.push(t.await.map_err(|e| e.to_string()).and_then(|r| r));
        }
        out
    });
    let elapsed = started.elapsed().as_secs_f64();
    let mut errors = Vec::new();
    let (mut served, mut messages, mut tags, mut lags) = (0, 0, 0, Vec::new());
    for r in results {
        match r {
            Ok(s) => {
                served += usize::from(s.messages > 0);
                messages += s.messages;
                tags += s.tags;
                lags.extend(s.lags_ms);
            }
            Err(e) => errors.push(e),
        }
    }
    lags.sort_by(f64::total_cmp);
    println!(
        "{{\"readers\": {}, \"reporting\": {served}, \"errors\": {}, \"n\": {n}, \"seconds\": {elapsed:.1}, \
         \"messages\": {messages}, \"tag_reports\": {tags}, \"tag_reports_per_sec\": {:.0}, \
         \"lag_ms_p50\": {:.0}, \"lag_ms_p99\": {:.0}, \"lag_ms_max\": {:.0}}}",
        addrs.len(),
        errors.len(),
        tags as f64 / seconds,
        percentile(&lags, 0.5),
        percentile(&lags, 0.99),
        lags.last().copied().unwrap_or(f64::NAN),
    );
    for e in errors.iter().take(5) {
        eprintln!("fleet: {e}");
    }
    if errors.is_empty() {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}
