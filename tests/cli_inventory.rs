//! `llrp-gateway inventory` from the command line, against the simulated reader (the `sim`
//! binary) and, when `LLRP_LLRPKIT` names it, llrpkit 0.3.0's `llrpkit emulate`: the reads
//! file, the CSV, antennas, keepalives, reconnection, errors.

use std::collections::{BTreeSet, HashSet};
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::mpsc::{self, Receiver};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use llrp::units::HopTable;
use llrp_gateway::reads::{read_jsonl, Read, CSV_HEADER};

/// Longest any wait below may take (a hang guard, not a measurement).
const GUARD: Duration = Duration::from_secs(60);

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_llrp-gateway"))
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn utc_now_us() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .expect("after 1970")
        .as_micros() as u64
}

/// A loopback port nothing listens on right now.
fn free_port() -> u16 {
    let l = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
    l.local_addr().expect("addr").port()
}

/// A child process whose stderr (and stdout) lines are collected as they come.
struct Proc {
    child: Child,
    lines: Receiver<String>,
    log: Arc<Mutex<String>>,
    out: Arc<Mutex<String>>,
    readers: Vec<std::thread::JoinHandle<()>>,
}

impl Proc {
    fn spawn(mut cmd: Command) -> Proc {
        let mut child = cmd
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("starts");
        let (tx, lines) = mpsc::channel();
        let log = Arc::new(Mutex::new(String::new()));
        let out = Arc::new(Mutex::new(String::new()));
        let mut readers = Vec::new();
        let stderr = child.stderr.take().expect("piped");
        let stdout = child.stdout.take().expect("piped");
        for (pipe, all, tx) in [
            (
                Box::new(stderr) as Box<dyn std::io::Read + Send>,
                log.clone(),
                Some(tx.clone()),
            ),
            (Box::new(stdout), out.clone(), Some(tx)),
        ] {
            readers.push(std::thread::spawn(move || {
                for line in BufReader::new(pipe).lines() {
                    let line = line.unwrap_or_default();
                    if let Some(tx) = &tx {
                        let _ = tx.send(line.clone());
                    }
                    let mut all = all.lock().expect("log lock");
                    all.push_str(&line);
                    all.push('\n');
                }
            }));
        }
        Proc {
            child,
            lines,
            log,
            out,
            readers,
        }
    }

    /// Waits (at most [`GUARD`]) for an output line containing `pattern`; returns it.
    fn wait_line(&self, pattern: &str) -> String {
        let until = Instant::now() + GUARD;
        loop {
            let left = until.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(l) if l.contains(pattern) => return l,
                Ok(_) => {}
                Err(_) => panic!(
                    "no line with {pattern:?}; log so far:\n{}",
                    self.log.lock().expect("log lock")
                ),
            }
        }
    }

    fn signal(&self, sig: &str) {
        let ok = Command::new("kill")
            .args([sig, &self.child.id().to_string()])
            .status()
            .expect("kill runs")
            .success();
        assert!(ok, "kill {sig} delivered");
    }

    /// Waits (at most [`GUARD`]) for the exit; returns the status, stdout and stderr.
    fn wait(mut self) -> (ExitStatus, String, String) {
        let until = Instant::now() + GUARD;
        let status = loop {
            if let Some(s) = self.child.try_wait().expect("wait") {
                break s;
            }
            if Instant::now() > until {
                let _ = self.child.kill();
                panic!(
                    "the process did not exit; log:\n{}",
                    self.log.lock().unwrap()
                );
            }
            std::thread::sleep(Duration::from_millis(20));
        };
        for r in self.readers.drain(..) {
            let _ = r.join();
        }
        let out = self.out.lock().expect("out lock").clone();
        let log = self.log.lock().expect("log lock").clone();
        (status, out, log)
    }

    /// SIGTERM, then [`Proc::wait`].
    fn terminate(self) -> (ExitStatus, String, String) {
        self.signal("-TERM");
        self.wait()
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        // A test that panicked leaves no process behind.
        if matches!(self.child.try_wait(), Ok(None)) {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// `llrp-gateway sim` on `addr` (with `scenario`, else the embedded S1), once it listens.
fn sim(scenario: Option<&Path>, addr: &str) -> Proc {
    let mut cmd = bin();
    cmd.args(["sim", "--no-http", "--listen", addr]);
    if let Some(s) = scenario {
        cmd.arg("--scenario").arg(s);
    }
    let p = Proc::spawn(cmd);
    p.wait_line("listening on");
    p
}

/// `llrp-gateway sim` on a free loopback port; returns it and its address.
fn sim_anywhere(scenario: Option<&Path>) -> (Proc, String) {
    let mut cmd = bin();
    cmd.args(["sim", "--no-http", "--listen", "127.0.0.1:0"]);
    if let Some(s) = scenario {
        cmd.arg("--scenario").arg(s);
    }
    let p = Proc::spawn(cmd);
    // The port the system gave, not one picked earlier that another process may take.
    let line = p.wait_line("listening on");
    let addr = line
        .split("listening on ")
        .nth(1)
        .and_then(|rest| rest.split_whitespace().next())
        .expect("an address after 'listening on'")
        .to_string();
    (p, addr)
}

/// Runs `llrp-gateway inventory ARGS` to its end (at most [`GUARD`]).
fn inventory(args: &[&str]) -> (ExitStatus, String, String) {
    let mut cmd = bin();
    cmd.arg("inventory").args(args);
    Proc::spawn(cmd).wait()
}

/// `inventory` with its output in `dir/name`; returns the status, stdout, stderr and path.
fn inventory_to(dir: &Path, name: &str, args: &[&str]) -> (ExitStatus, String, String, PathBuf) {
    let path = dir.join(name);
    let mut all: Vec<&str> = args.to_vec();
    let p = path.to_str().expect("utf-8 path").to_string();
    all.extend(["--output", &p]);
    let (status, out, err) = inventory(&all);
    (status, out, err, path)
}

fn reads_of(path: &Path) -> Vec<Read> {
    let f = std::fs::File::open(path).expect("the reads file exists");
    read_jsonl(BufReader::new(f)).expect("every line is a read")
}

/// A number on the summary line: the word just before `label` when the label starts with a
/// space (`" reads,"`), else the one just after it (`"connections: "`).
fn summary_number(text: &str, label: &str) -> u64 {
    let line = text
        .lines()
        .find(|l| l.contains("distinct EPCs"))
        .unwrap_or_else(|| panic!("no summary in:\n{text}"));
    let at = line
        .find(label)
        .unwrap_or_else(|| panic!("no {label:?} in {line}"));
    let word = if label.starts_with(' ') {
        line[..at].split_whitespace().last()
    } else {
        line[at + label.len()..]
            .split(|c: char| !c.is_ascii_digit())
            .next()
    };
    word.and_then(|w| w.parse().ok())
        .unwrap_or_else(|| panic!("no number at {label:?} in {line}"))
}

/// S1 with its reader in the FCC region, hopping over the 50-channel table.
fn fcc_s1(dir: &Path) -> PathBuf {
    let mut s: serde_json::Value =
        serde_json::from_str(include_str!("../fixtures/scenarios/s1.json")).expect("s1 parses");
    s["readers"][0]["region"] = serde_json::json!("fcc");
    s["readers"][0]
        .as_object_mut()
        .expect("a reader object")
        .remove("fixed_channel");
    let path = dir.join("s1-fcc.json");
    std::fs::write(&path, s.to_string()).expect("write");
    path
}

fn s1_epcs() -> HashSet<String> {
    let s: serde_json::Value =
        serde_json::from_str(include_str!("../fixtures/scenarios/s1.json")).expect("s1 parses");
    s["tags"]
        .as_array()
        .expect("tags")
        .iter()
        .map(|t| t["epc"].as_str().expect("epc").to_uppercase())
        .collect()
}

/// The checks every Impinj reads file passes: phase in [0, 2π), RSSI plausible, the channel's
/// frequency that of `table`, a timestamp within the run.
fn check_impinj_reads(reads: &[Read], table: &HopTable, from_us: u64, to_us: u64) {
    assert!(!reads.is_empty(), "reads arrived");
    for r in reads {
        let phase = r.phase_rad.expect("Impinj phase");
        assert!(
            (0.0..std::f64::consts::TAU).contains(&phase),
            "phase {phase}"
        );
        let rssi = r.rssi_dbm.expect("RSSI");
        assert!((-110.0..0.0).contains(&rssi), "RSSI {rssi} dBm");
        assert!(r.doppler_hz.is_some(), "Impinj Doppler: {r:?}");
        let ch = r.channel_index.expect("channel index");
        let want = table.frequency_khz(ch).map(|k| u64::from(k) * 1000);
        assert!(want.is_some(), "channel {ch} is in the reader's table");
        assert_eq!(r.channel_frequency_hz, want, "channel {ch}");
        assert!(
            (from_us..=to_us).contains(&r.t_us),
            "t_us {} is UTC µs within the run [{from_us}, {to_us}]",
            r.t_us
        );
        assert!(r.antenna >= 1, "an antenna port: {r:?}");
    }
}

#[test]
fn impinj_inventory_writes_a_reads_file_with_the_readers_hop_table() {
    let dir = tempfile::tempdir().expect("temp dir");
    let scenario = fcc_s1(dir.path());
    let (sim, addr) = sim_anywhere(Some(&scenario));
    let from = utc_now_us();
    let (status, out, err, path) = inventory_to(
        dir.path(),
        "reads.jsonl",
        &[&addr, "--seconds", "2", "--impinj"],
    );
    let to = utc_now_us();
    drop(sim);
    assert!(status.success(), "{err}");
    let reads = reads_of(&path);
    check_impinj_reads(&reads, &HopTable::fcc(), from, to);
    let channels: BTreeSet<_> = reads.iter().filter_map(|r| r.channel_index).collect();
    assert!(
        channels.len() > 1,
        "the reader hopped over several channels: {channels:?}"
    );
    let epcs: HashSet<String> = reads.iter().map(|r| r.epc.to_string()).collect();
    assert!(epcs.is_subset(&s1_epcs()), "{epcs:?}");
    assert!(reads
        .iter()
        .all(|r| r.reader.as_deref() == Some(addr.as_str())));
    assert_eq!(summary_number(&out, " reads,"), reads.len() as u64, "{out}");
    assert_eq!(
        summary_number(&out, " distinct EPCs"),
        epcs.len() as u64,
        "{out}"
    );
    assert!(out.contains("antenna 1: "), "per-antenna line: {out}");
    assert!(out.contains(" dBm"), "RSSI range: {out}");
    assert!(err.contains("hop table 1 (50 channels)"), "{err}");
}

#[test]
fn csv_output_has_the_header_and_a_row_per_read_with_a_name_that_needs_quotes() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (sim, addr) = sim_anywhere(None);
    // A comma and quotes in the reader's name: quoted as RFC 4180 says, so that a CSV
    // reader (the csv crate here, a spreadsheet elsewhere) gets the name back whole.
    let name = "dock \"7\", north";
    let (status, out, err, path) = inventory_to(
        dir.path(),
        "reads.csv",
        &[&addr, "--seconds", "1", "--name", name],
    );
    drop(sim);
    assert!(status.success(), "{err}");
    let text = std::fs::read_to_string(&path).expect("the CSV exists");
    assert_eq!(text.lines().next(), Some(CSV_HEADER));
    let mut csv = csv::Reader::from_reader(text.as_bytes());
    let rows: Vec<csv::StringRecord> = csv.records().map(|r| r.expect("valid CSV")).collect();
    assert!(!rows.is_empty(), "rows");
    let columns = CSV_HEADER.split(',').count();
    let etsi = HopTable::etsi();
    for row in &rows {
        assert_eq!(row.len(), columns, "{row:?}");
        assert!(s1_epcs().contains(&row[0]), "a scenario EPC: {row:?}");
        assert_eq!(&row[1], name, "the name, whole");
        assert_eq!(&row[2], "1", "S1's one antenna");
        assert_eq!(&row[5], "", "no Impinj phase without --impinj");
        let rssi: f64 = row[6].parse().expect("PeakRSSI");
        assert_eq!(rssi.fract(), 0.0, "PeakRSSI is whole dBm");
        // S1 is ETSI, fixed on channel 1: 865.7 MHz.
        assert_eq!(&row[7], "1");
        let khz = etsi.frequency_khz(1).expect("channel 1");
        assert_eq!(&row[8], (u64::from(khz) * 1000).to_string());
    }
    assert_eq!(summary_number(&out, " reads,"), rows.len() as u64, "{out}");
}

#[test]
fn antennas_restricts_the_antennas_read() {
    let dir = tempfile::tempdir().expect("temp dir");
    let s2 = root().join("fixtures/scenarios/s2.json");
    let (sim, addr) = sim_anywhere(Some(&s2));
    let antennas = |reads: &[Read]| -> BTreeSet<u16> { reads.iter().map(|r| r.antenna).collect() };
    let (status, _, err, all) = inventory_to(dir.path(), "all.jsonl", &[&addr, "--seconds", "2"]);
    assert!(status.success(), "{err}");
    let seen = antennas(&reads_of(&all));
    assert!(
        seen.iter().any(|a| ![1, 3].contains(a)),
        "without --antennas antennas other than 1 and 3 read too: {seen:?}"
    );
    let (status, out, err, some) = inventory_to(
        dir.path(),
        "some.jsonl",
        &[&addr, "--seconds", "2", "--antennas", "1,3"],
    );
    drop(sim);
    assert!(status.success(), "{err}");
    let seen = antennas(&reads_of(&some));
    assert!(!seen.is_empty(), "reads arrived");
    assert!(seen.is_subset(&BTreeSet::from([1, 3])), "{seen:?}");
    assert!(!out.contains("antenna 2:"), "{out}");
}

/// The simulator drops a client after three unanswered keepalives (`KEEPALIVE_MISSES`): at a
/// 100 ms interval, within half a second of a 2 s run. One connection all along, with the
/// keepalives answered, shows they were.
#[test]
fn keepalives_are_answered_so_the_reader_keeps_the_connection() {
    let (sim, addr) = sim_anywhere(None);
    let (status, out, err) = inventory(&[&addr, "--seconds", "2", "--keepalive-ms", "100"]);
    drop(sim);
    assert!(status.success(), "{err}");
    assert_eq!(summary_number(&out, "connections: "), 1, "{out}\n{err}");
    assert!(
        summary_number(&out, "keepalives answered: ") >= 5,
        "{out}\n{err}"
    );
    assert!(!err.contains("reconnecting"), "{err}");
}

#[test]
fn an_inventory_started_before_the_reader_listens_connects_once_it_does() {
    let dir = tempfile::tempdir().expect("temp dir");
    let addr = format!("127.0.0.1:{}", free_port());
    let path = dir.path().join("reads.jsonl");
    let mut cmd = bin();
    cmd.args([
        "inventory",
        &addr,
        "--retries",
        "forever",
        "--backoff-ms",
        "50",
    ])
    .args(["--backoff-max-ms", "200", "--output"])
    .arg(&path);
    let inv = Proc::spawn(cmd);
    inv.wait_line("retrying in");
    let sim = sim(None, &addr);
    inv.wait_line("inventory started");
    wait_for_reads(&path, 1);
    let (status, out, err) = inv.terminate();
    drop(sim);
    assert!(status.success(), "SIGTERM ends the run cleanly: {err}");
    assert!(err.contains("cannot connect to"), "{err}");
    assert_eq!(summary_number(&out, "connections: "), 1, "{out}");
    assert!(!reads_of(&path).is_empty());
}

#[test]
fn a_reader_that_goes_away_is_reconnected_when_it_is_back() {
    let dir = tempfile::tempdir().expect("temp dir");
    let addr = format!("127.0.0.1:{}", free_port());
    let path = dir.path().join("reads.jsonl");
    let first = sim(None, &addr);
    let mut cmd = bin();
    cmd.args([
        "inventory",
        &addr,
        "--retries",
        "forever",
        "--backoff-ms",
        "50",
    ])
    .args(["--backoff-max-ms", "200", "--output"])
    .arg(&path);
    let inv = Proc::spawn(cmd);
    wait_for_reads(&path, 1);
    // SIGTERM: the simulator sends its ConnectionCloseEvent and closes.
    let (ok, _, _) = first.terminate();
    assert!(ok.success());
    inv.wait_line("reconnecting in");
    let before = whole_lines(&path);
    let restarted = utc_now_us();
    let second = sim(None, &addr);
    inv.wait_line("inventory started");
    wait_for_reads(&path, before + 1);
    let (status, out, err) = inv.terminate();
    drop(second);
    assert!(status.success(), "{err}");
    assert!(err.contains("the reader closed the connection"), "{err}");
    assert_eq!(summary_number(&out, "connections: "), 2, "{out}\n{err}");
    let reads = reads_of(&path);
    assert!(
        reads[before..].iter().any(|r| r.t_us >= restarted),
        "reads from the restarted reader"
    );
}

/// Whole lines in the file so far (0 if it does not exist yet).
fn whole_lines(path: &Path) -> usize {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    text.matches('\n').count()
}

/// Waits (at most [`GUARD`]) until the reads file holds at least `n` whole lines.
fn wait_for_reads(path: &Path, n: usize) {
    let until = Instant::now() + GUARD;
    loop {
        if whole_lines(path) >= n {
            return;
        }
        assert!(
            Instant::now() < until,
            "{n} reads did not arrive in {path:?}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

#[test]
fn an_unreachable_reader_fails_after_the_retries_or_is_retried_when_asked() {
    let addr = format!("127.0.0.1:{}", free_port());
    let (status, _, err) = inventory(&[&addr, "--retries", "2", "--backoff-ms", "20"]);
    assert!(!status.success());
    assert_eq!(err.matches("retrying in").count(), 2, "{err}");
    assert!(err.contains("retry 2 of 2"), "{err}");
    assert!(
        err.contains(&format!("cannot connect to {addr} after 3 attempt(s)")),
        "{err}"
    );
    // `forever` keeps trying past any limit, until the run ends.
    let (status, _, err) = inventory(&[
        &addr,
        "--retries",
        "forever",
        "--backoff-ms",
        "10",
        "--backoff-max-ms",
        "20",
        "--seconds",
        "1",
    ]);
    assert!(!status.success(), "never connected");
    assert!(err.contains("(retry 6)"), "{err}");
    assert!(err.contains("no connection to"), "{err}");
}

#[test]
fn settings_the_reader_cannot_do_are_refused_with_the_reason() {
    let (sim, addr) = sim_anywhere(None);
    let (status, _, err) = inventory(&[&addr, "--seconds", "1", "--mode", "7"]);
    assert!(!status.success());
    assert!(
        err.contains("RF mode 7 is not in the reader's mode table (0, 1, 2, 3, 4, 5, 1000, 1002, 1003, 1004)"),
        "{err}"
    );
    let (status, _, err) = inventory(&[&addr, "--seconds", "1", "--antennas", "1,9"]);
    drop(sim);
    assert!(!status.success());
    assert!(
        // The simulated R420's four ports, whatever the scenario connects.
        err.contains("antenna 9: the reader has antennas 1..=4"),
        "{err}"
    );
    assert!(!err.contains("retrying"), "a refusal is not retried: {err}");
}

#[test]
fn gen2_session_mode_and_search_mode_are_accepted_by_the_simulator() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (sim, addr) = sim_anywhere(None);
    let (status, _, err, path) = inventory_to(
        dir.path(),
        "reads.jsonl",
        &[
            &addr,
            "--seconds",
            "1",
            "--impinj",
            "--session",
            "1",
            "--mode",
            "2",
            "--search-mode",
            "2",
        ],
    );
    drop(sim);
    assert!(status.success(), "{err}");
    assert!(!reads_of(&path).is_empty());
}

/// A report comes every N TagReportData, and the reader aggregates a tag's reads into one
/// (TagSeenCount): with two or three of S1's tags in view a report of 50 never fills, and its
/// reads come only in the report the reader sends when the ROSpec stops at the end.
#[test]
fn reads_not_yet_reported_arrive_when_the_inventory_stops() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (sim, addr) = sim_anywhere(None);
    let (status, out, err, path) = inventory_to(
        dir.path(),
        "reads.jsonl",
        &[&addr, "--seconds", "1", "--report-every", "50"],
    );
    drop(sim);
    assert!(status.success(), "{err}");
    let reads = reads_of(&path);
    assert!(!reads.is_empty(), "the end-of-ROSpec report's reads: {out}");
    assert!(reads.len() < 50, "one partial report: {}", reads.len());
    assert_eq!(summary_number(&out, " reads,"), reads.len() as u64, "{out}");
}

/// llrpkit 0.3.0's emulator: `./scripts/test` installs it (`scripts/venv-llrpkit.sh`) and names
/// its `llrpkit` command in `LLRP_LLRPKIT`.
#[test]
#[ignore = "needs llrpkit 0.3.0 (LLRP_LLRPKIT, set by ./scripts/test)"]
fn llrpkit_emulate_reads_arrive_with_its_own_hop_table() {
    let llrpkit = std::env::var("LLRP_LLRPKIT")
        .expect("LLRP_LLRPKIT must name the llrpkit command (set by ./scripts/test)");
    let mut cmd = Command::new(llrpkit);
    cmd.args(["emulate", "--port", "0", "--tags", "20", "--antennas", "4"])
        .args(["--rate", "200"])
        .env("PYTHONUNBUFFERED", "1");
    let emulator = Proc::spawn(cmd);
    let line = emulator.wait_line("reader on port");
    let port: u16 = line
        .split("port ")
        .nth(1)
        .and_then(|r| r.split_whitespace().next())
        .and_then(|p| p.parse().ok())
        .unwrap_or_else(|| panic!("a port in {line:?}"));
    let dir = tempfile::tempdir().expect("temp dir");
    let from = utc_now_us();
    let (status, out, err, path) = inventory_to(
        dir.path(),
        "reads.jsonl",
        &[
            &format!("127.0.0.1:{port}"),
            "--seconds",
            "2",
            "--impinj",
            "--antennas",
            "1,3",
            "--keepalive-ms",
            "300",
            "--session",
            "1",
            "--mode",
            "1002",
            "--search-mode",
            "2",
        ],
    );
    let to = utc_now_us();
    drop(emulator);
    assert!(status.success(), "{err}");
    let reads = reads_of(&path);
    // llrpkit advertises 902.75..927.25 MHz in ascending order, not the simulator's hop
    // order: the frequencies must come from what this reader said.
    let table = HopTable {
        id: 1,
        frequencies_khz: (0..50).map(|i| 902_750 + 500 * i).collect(),
    };
    assert_ne!(table, HopTable::fcc());
    check_impinj_reads(&reads, &table, from, to);
    let seen: BTreeSet<u16> = reads.iter().map(|r| r.antenna).collect();
    assert!(seen.is_subset(&BTreeSet::from([1, 3])), "{seen:?}");
    assert!(summary_number(&out, "keepalives answered: ") >= 1, "{out}");
    assert_eq!(summary_number(&out, "connections: "), 1, "{out}");
}

/// `--output /dev/null` (a name that says no format) needs `--format`, and then works.
#[test]
fn an_output_named_without_a_format_takes_it_from_format() {
    let (sim, addr) = sim_anywhere(None);
    let (status, _, err) = inventory(&[&addr, "--seconds", "0.5", "--output", "/dev/null"]);
    assert!(!status.success());
    assert!(err.contains("--format jsonl"), "{err}");
    let (status, out, err) = inventory(&[
        &addr,
        "--seconds",
        "1",
        "--output",
        "/dev/null",
        "--format",
        "csv",
    ]);
    drop(sim);
    assert!(status.success(), "{err}");
    assert!(summary_number(&out, " reads,") > 0, "{out}");
}
