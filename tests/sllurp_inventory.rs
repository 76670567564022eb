//! Unmodified `sllurp inventory` (sllurp 2.0.1 from the test venv) against the simulated
//! reader over loopback: the whole client sequence must succeed and the tags it prints must be
//! the scenario's, with channel indices from the region's table, Impinj values in range, and
//! peak RSSI falling 40 dB per decade of distance along an antenna's boresight.
//! Needs the venv; `./scripts/test` creates it and sets `LLRP_VENV`.

mod common;

use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use common::*;
use llrp_gateway::net::clock::Speed;
use llrp_gateway::scenario::Scenario;
use serde_json::Value;

fn venv() -> PathBuf {
    PathBuf::from(
        std::env::var("LLRP_VENV")
            .expect("LLRP_VENV must name the sllurp venv (set by ./scripts/test)"),
    )
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Longest a sllurp run may take to log the reports a test waits for (a hang guard, not a
/// measurement).
const SLLURP_GUARD: Duration = Duration::from_secs(60);

/// Runs `sllurp inventory ARGS` against `port` until it has logged `want` tag reports (lines
/// `saw tag(s)`), interrupts it like Ctrl-C, and returns the tag reports it logged (one Vec per
/// RO_ACCESS_REPORT) and its whole log.
fn run_sllurp(port: u16, args: &[&str], want: usize) -> (Vec<Vec<Value>>, String) {
    let dir = tempfile::tempdir().expect("temp dir");
    let log = dir.path().join("sllurp.log");
    let mut cmd = Command::new(venv().join("bin").join("sllurp"));
    cmd.arg("-l")
        .arg(&log)
        .arg("inventory")
        .arg("-p")
        .arg(port.to_string());
    cmd.args(args).arg("127.0.0.1");
    let mut child = cmd
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("sllurp starts");
    let guard = Instant::now() + SLLURP_GUARD;
    loop {
        let logged = std::fs::read_to_string(&log).unwrap_or_default();
        if logged.matches("saw tag(s)").count() >= want {
            break;
        }
        if child.try_wait().expect("wait").is_some() || Instant::now() > guard {
            break; // sllurp ended, or never got there: the assertions say what is missing
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    // Ctrl-C: sllurp deletes its AccessSpecs and ROSpecs, then disconnects.
    let _ = Command::new("kill")
        .arg("-INT")
        .arg(child.id().to_string())
        .status();
    let deadline = Instant::now() + Duration::from_secs(15);
    loop {
        if child.try_wait().expect("wait").is_some() {
            break;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            break;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let text = std::fs::read_to_string(&log).unwrap_or_default();
    let out = Command::new(venv().join("bin").join("python"))
        .arg(root().join("scripts/interop/sllurp_tags.py"))
        .arg(&log)
        .output()
        .expect("parser runs");
    assert!(
        out.status.success(),
        "parser failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let reports = String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str::<Vec<Value>>(l).expect("json report"))
        .collect();
    (reports, text)
}

fn epcs(s: &Scenario) -> Vec<String> {
    s.tags.iter().map(|t| t.epc.to_lowercase()).collect()
}

/// Checks every tag report against the scenario; returns the number of tags reported.
fn check_tags(s: &Scenario, reports: &[Vec<Value>], impinj: bool) -> usize {
    let known = epcs(s);
    let channels = s.readers[0].region.frequencies_khz().len() as u64;
    let now_us = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .expect("clock")
        .as_micros() as u64;
    let mut n = 0;
    for tag in reports.iter().flatten() {
        n += 1;
        let epc = tag["EPC-96"].as_str().expect("EPC-96");
        assert!(known.contains(&epc.to_string()), "unknown EPC {epc}");
        let ch = tag["ChannelIndex"].as_u64().expect("ChannelIndex");
        assert!(
            (1..=channels).contains(&ch),
            "channel {ch} outside 1..={channels}"
        );
        assert!(tag["TagSeenCount"].as_u64().expect("TagSeenCount") >= 1);
        let seen = tag["LastSeenTimestampUTC"]
            .as_u64()
            .expect("LastSeenTimestampUTC");
        assert!(
            seen <= now_us && seen + 120_000_000 > now_us,
            "timestamp {seen} is not recent UTC µs"
        );
        if impinj {
            let phase = tag["ImpinjRFPhaseAngle"]
                .as_u64()
                .expect("ImpinjRFPhaseAngle");
            assert!(phase < 4096);
            let rssi = tag["ImpinjPeakRSSI"].as_i64().expect("ImpinjPeakRSSI");
            assert!(
                (-10_000..=-1_000).contains(&rssi),
                "ImpinjPeakRSSI {rssi} cdBm"
            );
            assert!(tag.get("ImpinjRFDopplerFrequency").is_some());
        } else {
            assert!(tag.get("ImpinjRFPhaseAngle").is_none());
        }
    }
    n
}

async fn with_sim(
    args: &'static [&'static str],
    want: usize,
) -> (Scenario, Vec<Vec<Value>>, String) {
    with_scenario(s1(), args, want).await
}

/// As [`with_sim`], on scenario `s`.
async fn with_scenario(
    s: Scenario,
    args: &'static [&'static str],
    want: usize,
) -> (Scenario, Vec<Vec<Value>>, String) {
    let sim = start(&s, Speed::Factor(1.0)).await;
    let port = sim.addrs[0].port();
    let (reports, log) = tokio::task::spawn_blocking(move || run_sllurp(port, args, want))
        .await
        .expect("join");
    sim.shutdown().await;
    (s, reports, log)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "needs the sllurp venv; run by ./scripts/test"]
async fn impinj_reports_all_antennas_every_tag() {
    let (s, reports, log) = with_sim(
        &[
            "--impinj-reports",
            "--impinj-search-mode",
            "2",
            "-a",
            "0",
            "-n",
            "1",
        ],
        3,
    )
    .await;
    assert!(
        log.contains("Impinj"),
        "sllurp enabled the extensions:\n{log}"
    );
    assert!(
        reports.len() >= 2,
        "reports keep coming with -n 1 (got {}):\n{log}",
        reports.len()
    );
    assert!(check_tags(&s, &reports, true) >= 2);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "needs the sllurp venv; run by ./scripts/test"]
async fn plain_reports_one_antenna_every_tag() {
    let (s, reports, log) = with_sim(&["--impinj-search-mode", "2", "-a", "1", "-n", "1"], 3).await;
    assert!(reports.len() >= 2, "got {} reports:\n{log}", reports.len());
    assert!(check_tags(&s, &reports, false) >= 2);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "needs the sllurp venv; run by ./scripts/test"]
async fn default_reporting_with_a_duration() {
    // Report trigger "end of AISpec" with a 2 s AISpec: one aggregated report per run.
    let (s, reports, log) = with_sim(
        &[
            "--impinj-reports",
            "--impinj-search-mode",
            "2",
            "-a",
            "0",
            "-t",
            "2",
        ],
        1,
    )
    .await;
    assert!(
        !reports.is_empty(),
        "no report at the end of the AISpec:\n{log}"
    );
    let first = &reports[0];
    assert!(
        first
            .iter()
            .any(|t| t["TagSeenCount"].as_u64().unwrap_or(0) > 1),
        "reads aggregate per tag"
    );
    check_tags(&s, &reports, true);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "needs the sllurp venv; run by ./scripts/test"]
async fn default_reporting_one_antenna_short_duration() {
    // Without -n the reader reports at the end of the AISpec (N = 0): with -t 1 that is one
    // report after a second.
    let (s, reports, log) = with_sim(&["--impinj-search-mode", "2", "-a", "1", "-t", "1"], 1).await;
    assert!(
        !reports.is_empty(),
        "no report at the end of the AISpec:\n{log}"
    );
    check_tags(&s, &reports, false);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "needs the sllurp venv; run by ./scripts/test"]
async fn the_readme_command_shows_live_reads() {
    // The README's `sllurp inventory --impinj-reports --impinj-search-mode 2 -a 0 HOST`: Null
    // stop triggers and ROReportTrigger 1 with N = 0, session 2 dual target. Like an Impinj
    // reader, the simulator reports the running AISpec every second (the scenario's
    // report_interval_ms), aggregated per tag.
    let (s, reports, log) = with_sim(
        &["--impinj-reports", "--impinj-search-mode", "2", "-a", "0"],
        2,
    )
    .await;
    assert!(
        reports.len() >= 2,
        "a report every second while inventory runs (got {}):\n{log}",
        reports.len()
    );
    assert!(
        reports
            .iter()
            .flatten()
            .any(|t| t["TagSeenCount"].as_u64().unwrap_or(0) > 1),
        "reads aggregate per tag between reports"
    );
    assert!(check_tags(&s, &reports, true) >= 2);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "needs the sllurp venv; run by ./scripts/test"]
async fn sllurp_sees_rssi_fall_40_db_per_decade() {
    let (s, reports, log) = with_scenario(
        line_scenario(&[1.0, 2.0, 4.0]),
        &[
            "--impinj-reports",
            "--impinj-search-mode",
            "2",
            "-a",
            "1",
            "-n",
            "1",
        ],
        60,
    )
    .await;
    assert!(check_tags(&s, &reports, true) >= 3, "{log}");
    // ImpinjPeakRSSI (hundredths of dBm) of each tag as sllurp printed it.
    let mut by_epc: std::collections::BTreeMap<String, Vec<i64>> = Default::default();
    for tag in reports.iter().flatten() {
        let epc = tag["EPC-96"].as_str().expect("EPC-96").to_string();
        let rssi = tag["ImpinjPeakRSSI"].as_i64().expect("ImpinjPeakRSSI");
        by_epc.entry(epc).or_default().push(rssi);
    }
    let mean = |n: u8| {
        let v = &by_epc[&format!("e200000000000000000000{n:02x}")];
        v.iter().sum::<i64>() as f64 / v.len() as f64 / 100.0
    };
    assert_eq!(by_epc.len(), 3, "every tag read: {:?}", by_epc.keys());
    let (at1, at2, at4) = (mean(1), mean(2), mean(3));
    // Tags at 1, 2 and 4 m on the boresight of one fixed antenna, in free space, on one
    // channel, without noise: −40 dB per decade of distance, to the hundredth of a dB the reader
    // reports.
    for (near, far, ratio) in [(at1, at2, 2.0f64), (at2, at4, 2.0), (at1, at4, 4.0)] {
        let slope = near - far;
        assert!(
            (slope - 40.0 * ratio.log10()).abs() < 0.05,
            "{near:.2} dBm then {far:.2} dBm: {slope:.2} dB over a factor {ratio}"
        );
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "needs the sllurp venv; run by ./scripts/test"]
async fn sllurp_reads_a_128_bit_epc_through_epcdata() {
    let mut s = line_scenario(&[1.5, 2.5]);
    s.tags[0].epc = "E2000000000000000000000000000001".into();
    let long = s.tags[0].epc.to_lowercase();
    let short = s.tags[1].epc.to_lowercase();
    let s = Scenario::from_json(&serde_json::to_string(&s).expect("serialises"))
        .expect("a 128-bit EPC is valid");
    let (_, reports, log) =
        with_scenario(s, &["--impinj-search-mode", "2", "-a", "1", "-n", "1"], 40).await;
    // sllurp 2.0.1 names an EPCData's bytes "EPC", and an EPC-96 both "EPC" and "EPC-96".
    let mut seen = std::collections::BTreeSet::new();
    for tag in reports.iter().flatten() {
        let epc = tag["EPC"].as_str().expect("EPC").to_string();
        match tag.get("EPC-96").and_then(Value::as_str) {
            Some(e96) => assert_eq!((e96, epc.as_str()), (short.as_str(), short.as_str())),
            None => assert_eq!(epc, long, "{tag}"),
        }
        seen.insert(epc);
    }
    assert_eq!(seen.len(), 2, "both tags: {seen:?}\n{log}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "needs the sllurp venv; run by ./scripts/test"]
async fn single_target_in_session_2_reports_each_static_tag_once() {
    // sllurp's defaults (session 2, a report each second aggregated per tag) with Impinj's
    // single-target search: a tag read goes to B and stays there while it is powered, so the
    // first second's report counts each static tag once (dual target: about 200 times).
    let s = line_scenario(&[1.5, 2.0, 2.5]);
    let (_, reports, log) = with_scenario(s, &["--impinj-search-mode", "1", "-a", "1"], 1).await;
    let first = reports.first().expect("a report");
    let counts: std::collections::BTreeMap<String, u64> = first
        .iter()
        .map(|tag| {
            (
                tag["EPC-96"].as_str().expect("EPC-96").to_string(),
                tag["TagSeenCount"].as_u64().expect("TagSeenCount"),
            )
        })
        .collect();
    assert_eq!(counts.len(), 3, "every tag: {counts:?}\n{log}");
    // One TagReportData per tag (a reread on another channel would be another).
    assert_eq!(first.len(), 3, "{first:?}");
    assert!(counts.values().all(|&n| n == 1), "{counts:?}");
}

/// One static tag 1 m before one antenna, read as `reader_model` reads.
fn one_tag(reader_model: &str) -> Scenario {
    let json = format!(
        r#"{{
      "name": "one tag", "seed": 7, "reader_model": "{reader_model}",
      "world": {{ "min": [-2, -2, 0], "max": [3, 2, 2] }},
      "tags": [{{ "epc": "E20000000000000000000001", "position": [1.0, 0, 1.0] }}],
      "readers": [{{ "name": "r", "listen": "127.0.0.1:0", "region": "fcc",
        "antennas": [{{ "mount": {{ "type": "fixed", "pose": {{ "position": [0, 0, 1] }} }} }}] }}]
    }}"#
    );
    Scenario::from_json(&json).expect("one-tag scenario is valid")
}

/// Median time between the reads of sllurp's reports (LastSeenTimestampUTC, µs).
fn median_interval_us(reports: &[Vec<Value>]) -> f64 {
    let mut seen: Vec<u64> = reports
        .iter()
        .flatten()
        .filter_map(|t| t["LastSeenTimestampUTC"].as_u64())
        .collect();
    seen.sort_unstable();
    let mut gaps: Vec<f64> = seen.windows(2).map(|w| (w[1] - w[0]) as f64).collect();
    gaps.sort_by(f64::total_cmp);
    gaps.get(gaps.len() / 2).copied().unwrap_or(f64::NAN)
}

/// sllurp's `-n 1` ends each AISpec at its first tag. A real R420 then rereads one static tag
/// every 14.1 ms (docs/measurement.md "Reader models": the reader's setup of each AISpec);
/// the `impinj-r420` model does within 20 %, the `ideal` one several times faster.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "needs the sllurp venv; run by ./scripts/test"]
async fn an_aispec_per_tag_rereads_one_tag_at_the_real_readers_pace() {
    let (_, reports, log) =
        with_scenario(one_tag("impinj-r420"), &["-a", "1", "-n", "1"], 40).await;
    let r420 = median_interval_us(&reports);
    assert!(
        (0.8 * 14_100.0..1.2 * 14_100.0).contains(&r420),
        "impinj-r420: a read every {r420} µs:\n{log}"
    );
    let (_, reports, log) = with_scenario(one_tag("ideal"), &["-a", "1", "-n", "1"], 40).await;
    let ideal = median_interval_us(&reports);
    assert!(
        ideal < 0.5 * 14_100.0,
        "ideal: a read every {ideal} µs:\n{log}"
    );
}

/// Two tags before the first antenna of a reader presenting itself as a Zebra FX9600 (eight
/// antenna ports, Zebra's tables, no Impinj extensions).
fn zebra_scenario() -> Scenario {
    let antenna = |x: f64| {
        format!(r#"{{ "mount": {{ "type": "fixed", "pose": {{ "position": [{x}, 0, 1] }} }} }}"#)
    };
    let antennas: Vec<String> = (0..8).map(|k| antenna(-0.1 * f64::from(k))).collect();
    let json = format!(
        r#"{{
      "name": "zebra", "seed": 7,
      "world": {{ "min": [-2, -2, 0], "max": [3, 2, 2] }},
      "tags": [{{ "epc": "E20000000000000000000001", "position": [1.0, 0, 1.0] }},
               {{ "epc": "E20000000000000000000002", "position": [1.5, 0.2, 1.0] }}],
      "readers": [{{ "name": "fx", "listen": "127.0.0.1:0", "region": "fcc",
        "device": "zebra-fx9600", "antennas": [{}] }}]
    }}"#,
        antennas.join(",")
    );
    Scenario::from_json(&json).expect("Zebra scenario is valid")
}

/// A Zebra-targeted client's view: sllurp 2.0.1 without Impinj options inventories a
/// simulated Zebra FX9600 (its power table from index 0 to 200, its RF modes, vendor 161) and
/// gets the scenario's tags; asked for Impinj reports it stops, as against a real FX9600,
/// because IMPINJ_ENABLE_EXTENSIONS is answered with an ERROR_MESSAGE.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "needs the sllurp venv; run by ./scripts/test"]
async fn sllurp_inventories_a_zebra_fx9600() {
    let (s, reports, log) = with_scenario(zebra_scenario(), &["-a", "0", "-n", "1"], 3).await;
    assert!(reports.len() >= 2, "got {} reports:\n{log}", reports.len());
    assert!(check_tags(&s, &reports, false) >= 2, "{log}");
    let (_, reports, log) =
        with_scenario(zebra_scenario(), &["--impinj-reports", "-a", "1"], 1).await;
    assert!(
        reports.is_empty(),
        "no reads without the extensions:\n{log}"
    );
    assert!(
        log.contains("unexpected response ERROR_MESSAGE while enabling Impinj"),
        "sllurp says why it stopped:\n{log}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "needs the sllurp venv; run by ./scripts/test"]
async fn a_tag_filter_mask_reports_only_the_matching_tag() {
    // `--tag-filter-mask` sends a C1G2Filter on the EPC bank from 20h with no action
    // parameter (Select/Unselect): of three tags in the field only the masked one answers.
    let s = line_scenario(&[1.5, 2.0, 2.5]);
    let want = s.tags[1].epc.to_lowercase();
    let (_, reports, log) = with_scenario(
        s,
        &["--tag-filter-mask", "E20000000000000000000002", "-a", "1"],
        3,
    )
    .await;
    let seen: std::collections::BTreeSet<String> = reports
        .iter()
        .flatten()
        .map(|tag| tag["EPC-96"].as_str().expect("EPC-96").to_string())
        .collect();
    assert_eq!(seen.into_iter().collect::<Vec<_>>(), [want], "{log}");
    assert!(reports.len() >= 3, "{log}");
}
