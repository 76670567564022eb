//! Simulator throughput: tag reports per second an LLRP reader delivers over TCP to a raw-socket
//! client that only counts them.
//!
//! Usage: `sim_throughput ADDR N SECONDS [IDLE_MS]` (driven by `scripts/bench-sim`; `cargo bench`
//! alone, without arguments, prints the usage and does nothing).
//!
//! The client connects, waits for the READER_EVENT_NOTIFICATION greeting, sends ADD_ROSPEC
//! (ROSpecID 1, Immediate start, Null stop, one AISpec on antenna 0 = all with a Null stop
//! trigger, InventoryParameterSpec 1 for protocol 1, ROReportSpec "upon N tags or end of
//! ROSpec" with N and a selector of AntennaID, ChannelIndex, PeakRSSI, FirstSeen, LastSeen and
//! TagSeenCount), ENABLE_ROSPEC and START_ROSPEC, and counts the TagReportData of every
//! RO_ACCESS_REPORT with `llrp::reads::tag_reads` (frames found with `llrp::FrameSplitter`;
//! nothing is decoded into the typed tree on this path) from the moment ENABLE_ROSPEC is sent
//! until SECONDS have passed or, with IDLE_MS, until no report has arrived for IDLE_MS after the
//! first one (a scenario whose reads run out: the window then ends at the last report).
//!
//! START_ROSPEC: an Immediate ROSpec starts on ENABLE_ROSPEC by itself (LLRP), so a conforming
//! reader answers START_ROSPEC with an error when the spec already runs, or starts it if it has
//! not yet; llrpkit 0.3.0's emulator ignores the start trigger and only runs a spec after
//! START_ROSPEC. Sending it to every reader keeps the bytes on the wire identical; its status
//! is reported in the JSON (`start_rospec`) and does not affect the count.
//!
//! Output: one JSON line `{"reports": n, "seconds": s, "reports_per_sec": r, ...}` on stdout;
//! `ended` says whether the deadline or the idle rule ended the window.
//!
//! Two diagnostic modes time the same work without sockets, on S2 (`fixtures/scenarios/s2.json`)
//! until its robot has long stopped (250 s of simulated time), best and median of PASSES:
//! * `sim_throughput physics [PASSES]`: the channel model alone on one thread, the antennas in
//!   turn for the reader's dwell (25 ms) each, without phase and Doppler (as the ROSpec below
//!   asks);
//! * `sim_throughput inproc N [PASSES]`: the simulated reader driven in-process with the ROSpec
//!   below and report trigger N, its physics computed ahead on every core as under `sim`, every
//!   output encoded into a buffer.

use std::io::{self, Read, Write};
use std::net::TcpStream;
use std::process::ExitCode;
use std::sync::Arc;
use std::time::{Duration, Instant};

use bytes::BytesMut;
use llrp::enums::{ConnectionAttemptStatus, RoReportTriggerType};
use llrp::message::{
    AddRospec, AddRospecResponse, EnableRospec, EnableRospecResponse, MessageBody, MessageDef,
    RoAccessReport, StartRospec, StartRospecResponse,
};
use llrp::params::{LlrpStatus, RoReportSpec, RoSpec, TagReportContentSelector};
use llrp::{FrameSplitter, Message, Split};
use llrp_gateway::physics::{Model, Want};
use llrp_gateway::reader::{Output, Reader, ReaderProfile, ANTENNA_DWELL_US};
use llrp_gateway::scenario::Scenario;

/// How long the handshake may take before the client gives up.
const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(10);

/// Socket read timeout, so the measurement ends on time even if the reader stalls.
const READ_TIMEOUT: Duration = Duration::from_millis(100);

/// Initial receive buffer size (grown if a frame is bigger).
const BUF_LEN: usize = 4 << 20;

fn main() -> ExitCode {
    // `cargo bench` appends `--bench`; anything starting with `-` is ignored.
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with('-'))
        .collect();
    match args.first().map(String::as_str) {
        Some("physics") => return physics(args.get(1).map(String::as_str)),
        Some("inproc") => {
            return inproc(
                args.get(1).map(String::as_str),
                args.get(2).map(String::as_str),
            )
        }
        _ => {}
    }
    let (addr, n, seconds, idle_ms) = match args.as_slice() {
        [a, n, s] => (a, n, s, "0"),
        [a, n, s, i] => (a, n, s, i.as_str()),
        _ => {
            eprintln!(
                "usage: sim_throughput ADDR N SECONDS [IDLE_MS]  (run by scripts/bench-sim; \
                 nothing to do without a reader address)\n       sim_throughput physics [PASSES]\n       \
                 sim_throughput inproc N [PASSES]"
            );
            return ExitCode::SUCCESS;
        }
    };
    let (Ok(n), Ok(seconds), Ok(idle_ms)) = (
        n.parse::<u16>(),
        seconds.parse::<f64>(),
        idle_ms.parse::<u64>(),
    ) else {
        eprintln!("sim_throughput: N must be 0..=65535, SECONDS a number, IDLE_MS an integer");
        return ExitCode::FAILURE;
    };
    if !(seconds > 0.0 && seconds.is_finite()) {
        eprintln!("sim_throughput: SECONDS must be positive");
        return ExitCode::FAILURE;
    }
    let idle = (idle_ms > 0).then(|| Duration::from_millis(idle_ms));
    match run(addr, n, Duration::from_secs_f64(seconds), idle) {
        Ok(r) => {
            println!(
                "{{\"reports\": {}, \"seconds\": {:.6}, \"reports_per_sec\": {:.0}, \
                 \"frames\": {}, \"bytes\": {}, \"n\": {}, \"ended\": \"{}\", \
                 \"start_rospec\": \"{}\"}}",
                r.reports,
                r.seconds,
                r.reports as f64 / r.seconds,
                r.frames,
                r.bytes,
                n,
                r.ended,
                r.start_rospec
            );
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("sim_throughput: {addr}: {e}");
            ExitCode::FAILURE
        }
    }
}

/// Simulated time the in-process modes run S2 for, µs: past the end of its drive.
const S2_END_US: u64 = 250_000_000;

/// S2 as shipped.
fn s2() -> Result<Scenario, String> {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/fixtures/scenarios/s2.json");
    Scenario::load(std::path::Path::new(path)).map_err(|e| e.to_string())
}

/// PASSES as given (default 10, at least 1).
fn passes(arg: Option<&str>) -> Result<usize, String> {
    arg.map_or(Ok(10), |a| {
        a.parse::<usize>().map_err(|e| format!("PASSES: {e}"))
    })
    .map(|p| p.max(1))
}

/// Best and median of the timed passes, ms.
fn best_and_median(mut ms: Vec<f64>) -> (f64, f64) {
    ms.sort_by(f64::total_cmp);
    (ms[0], ms[ms.len() / 2])
}

/// `physics [PASSES]`: the channel model of an S2 pass on one thread.
fn physics(arg: Option<&str>) -> ExitCode {
    let (scenario, k) = match s2().and_then(|s| Ok((s, passes(arg)?))) {
        Ok(v) => v,
        Err(e) => {
            eprintln!("sim_throughput physics: {e}");
            return ExitCode::FAILURE;
        }
    };
    let want = Want {
        phase: false,
        doppler: false,
    };
    let (mut times, mut reads) = (Vec::new(), 0);
    for _ in 0..k {
        // A fresh model each pass: nothing cached from the last one.
        let model = Model::new(&scenario, 0);
        let antennas = u64::from(model.antenna_count().max(1));
        let start = Instant::now();
        reads = 0;
        let (mut t, mut slot) = (0, 0u64);
        while t < S2_END_US {
            let antenna = (slot % antennas) as u16 + 1;
            reads += model
                .inventory_with(
                    antenna,
                    t,
                    t + ANTENNA_DWELL_US,
                    None,
                    None,
                    want,
                    &Default::default(),
                )
                .len();
            t += ANTENNA_DWELL_US;
            slot += 1;
        }
        times.push(start.elapsed().as_secs_f64() * 1e3);
    }
    let (best, median) = best_and_median(times);
    println!(
        "{{\"mode\": \"physics\", \"reads\": {reads}, \"passes\": {k}, \"best_ms\": {best:.2}, \
         \"median_ms\": {median:.2}}}"
    );
    ExitCode::SUCCESS
}

/// `inproc N [PASSES]`: the simulated reader over an S2 pass without sockets.
fn inproc(n: Option<&str>, arg: Option<&str>) -> ExitCode {
    let parsed = n
        .ok_or_else(|| "N is missing".to_string())
        .and_then(|n| n.parse::<u16>().map_err(|e| format!("N: {e}")))
        .and_then(|n| Ok((n, s2()?, passes(arg)?)));
    let (n, scenario, k) = match parsed {
        Ok(v) => v,
        Err(e) => {
            eprintln!("sim_throughput inproc: {e}");
            return ExitCode::FAILURE;
        }
    };
    let (mut times, mut reports) = (Vec::new(), 0);
    for _ in 0..k {
        let model = Arc::new(Model::new(&scenario, 0));
        let profile = ReaderProfile::from_scenario(&scenario, 0, &model);
        let mut reader = Reader::new(profile, model, 1_700_000_000_000_000);
        let requests = [
            Message::new(
                1,
                AddRospec {
                    ro_spec: rospec(n),
                    ..Default::default()
                },
            ),
            Message::new(
                2,
                EnableRospec {
                    ro_spec_id: 1,
                    ..Default::default()
                },
            ),
        ];
        let _ = reader.connect(0, 0);
        for m in requests {
            let _ = reader.handle(m, 0, 0);
        }
        let mut out = BytesMut::with_capacity(128 * 1024);
        reports = 0;
        let start = Instant::now();
        let mut now = 0;
        while now < S2_END_US {
            // The steps `sim --speed max` takes.
            now += 100_000;
            for o in reader.advance(now, 0) {
                if let Output::Send(m) = o {
                    if let MessageBody::RoAccessReport(r) = &m.body {
                        reports += r.tag_report_data.len();
                    }
                    m.encode(&mut out);
                    if out.len() >= 64 * 1024 {
                        std::hint::black_box(&out);
                        out.clear();
                    }
                }
            }
        }
        times.push(start.elapsed().as_secs_f64() * 1e3);
    }
    let (best, median) = best_and_median(times);
    println!(
        "{{\"mode\": \"inproc\", \"n\": {n}, \"reports\": {reports}, \"passes\": {k}, \
         \"best_ms\": {best:.2}, \"median_ms\": {median:.2}, \"reports_per_sec_at_best\": {:.0}}}",
        reports as f64 / best * 1e3
    );
    ExitCode::SUCCESS
}

/// What one measurement saw.
struct Outcome {
    reports: u64,
    frames: u64,
    bytes: u64,
    seconds: f64,
    ended: &'static str,
    start_rospec: &'static str,
}

fn other(msg: String) -> io::Error {
    io::Error::other(msg)
}

/// A blocking LLRP connection with a receive buffer.
struct Conn {
    stream: TcpStream,
    buf: Vec<u8>,
    /// Bytes `start..end` of `buf` are received and not yet consumed.
    start: usize,
    end: usize,
    splitter: FrameSplitter,
    /// Whether RO_ACCESS_REPORTs are counted (from ENABLE_ROSPEC on).
    counting: bool,
    reports: u64,
    frames: u64,
    bytes: u64,
    /// When the last counted tag report arrived.
    last_report: Option<Instant>,
}

impl Conn {
    /// Reads more bytes; `Ok(false)` on a timeout.
    fn fill(&mut self) -> io::Result<bool> {
        if self.start > 0 && (self.end == self.buf.len() || self.start == self.end) {
            self.buf.copy_within(self.start..self.end, 0);
            self.end -= self.start;
            self.start = 0;
        }
        if self.end == self.buf.len() {
            let len = self.buf.len() * 2;
            self.buf.resize(len, 0);
        }
        match self.stream.read(&mut self.buf[self.end..]) {
            Ok(0) => Err(other("connection closed by the reader".into())),
            Ok(k) => {
                self.end += k;
                Ok(true)
            }
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                ) =>
            {
                Ok(false)
            }
            Err(e) if e.kind() == io::ErrorKind::Interrupted => Ok(true),
            Err(e) => Err(e),
        }
    }

    /// The next whole frame already received, as `(type, start, end)` in `buf`; counts it
    /// if it is an RO_ACCESS_REPORT and counting is on.
    fn next_frame(&mut self) -> io::Result<Option<(u16, usize, usize)>> {
        match self.splitter.split(&self.buf[self.start..self.end]) {
            Ok(Split::Frame(h)) => {
                let at = self.start;
                self.start += h.length as usize;
                if self.counting {
                    self.bytes += u64::from(h.length);
                    if h.msg_type == RoAccessReport::TYPE {
                        self.count(at, self.start)?;
                    }
                }
                Ok(Some((h.msg_type, at, self.start)))
            }
            Ok(Split::Incomplete(_)) => Ok(None),
            Err(e) => Err(other(format!("bad frame from the reader: {e}"))),
        }
    }

    /// Counts the TagReportData of the RO_ACCESS_REPORT at `buf[a..b]`.
    fn count(&mut self, a: usize, b: usize) -> io::Result<()> {
        self.frames += 1;
        let mut k = 0;
        let reads = llrp::reads::tag_reads(&self.buf[a..b])
            .map_err(|e| other(format!("bad RO_ACCESS_REPORT: {e}")))?;
        for r in reads {
            r.map_err(|e| other(format!("bad TagReportData: {e}")))?;
            k += 1;
        }
        if k > 0 {
            self.reports += k;
            self.last_report = Some(Instant::now());
        }
        Ok(())
    }

    fn send(&mut self, id: u32, body: impl Into<MessageBody>) -> io::Result<()> {
        let mut out = BytesMut::new();
        Message::new(id, body).encode(&mut out);
        self.stream.write_all(&out)
    }

    /// Waits for the first message of type `ty` (counting nothing) and decodes it.
    fn wait_for(&mut self, ty: u16, what: &str) -> io::Result<Message> {
        let deadline = Instant::now() + HANDSHAKE_TIMEOUT;
        loop {
            while let Some((t, a, b)) = self.next_frame()? {
                if t == ty {
                    return Message::decode(&self.buf[a..b])
                        .map_err(|e| other(format!("{what} does not decode: {e}")));
                }
            }
            if Instant::now() >= deadline {
                return Err(other(format!("no {what} within {HANDSHAKE_TIMEOUT:?}")));
            }
            self.fill()?;
        }
    }
}

/// The ROSpec the benchmark adds: all antennas, Immediate, no stop triggers, reports upon N
/// tags with antenna, channel, RSSI, timestamps and count.
fn rospec(n: u16) -> RoSpec {
    RoSpec::immediate(1, vec![0]).with_report(
        RoReportSpec::new(RoReportTriggerType::UponNTagsOrEndOfRoSpec, n).with_content(
            TagReportContentSelector {
                enable_antenna_id: true,
                enable_channel_index: true,
                enable_peak_rssi: true,
                enable_first_seen_timestamp: true,
                enable_last_seen_timestamp: true,
                enable_tag_seen_count: true,
                ..Default::default()
            },
        ),
    )
}

fn status_of(m: &Message) -> Option<&LlrpStatus> {
    m.body.status()
}

fn require_success(m: &Message, what: &str) -> io::Result<()> {
    match status_of(m) {
        Some(s) if s.is_success() => Ok(()),
        Some(s) => Err(other(format!(
            "{what} refused: status {} {}",
            s.status_code, s.error_description
        ))),
        None => Err(other(format!("{what}: unexpected {}", m.name()))),
    }
}

fn run(addr: &str, n: u16, duration: Duration, idle: Option<Duration>) -> io::Result<Outcome> {
    let stream = TcpStream::connect(addr)?;
    stream.set_nodelay(true)?;
    stream.set_read_timeout(Some(READ_TIMEOUT))?;
    let mut c = Conn {
        stream,
        buf: vec![0; BUF_LEN],
        start: 0,
        end: 0,
        splitter: FrameSplitter::default(),
        counting: false,
        reports: 0,
        frames: 0,
        bytes: 0,
        last_report: None,
    };
    // Greeting: READER_EVENT_NOTIFICATION with ConnectionAttemptEvent Success.
    let greeting = c.wait_for(63, "READER_EVENT_NOTIFICATION")?;
    match greeting.body.connection_attempt() {
        Some(ConnectionAttemptStatus::Success) => {}
        Some(s) => return Err(other(format!("connection refused (status {s:?})"))),
        None => return Err(other("greeting without ConnectionAttemptEvent".into())),
    }
    c.send(
        1,
        AddRospec {
            ro_spec: rospec(n),
            ..Default::default()
        },
    )?;
    require_success(
        &c.wait_for(AddRospecResponse::TYPE, "ADD_ROSPEC_RESPONSE")?,
        "ADD_ROSPEC",
    )?;
    // Measurement: from here (a reader may start an Immediate ROSpec at once) to the end.
    let t0 = Instant::now();
    c.counting = true;
    c.send(
        2,
        EnableRospec {
            ro_spec_id: 1,
            ..Default::default()
        },
    )?;
    require_success(
        &c.wait_for(EnableRospecResponse::TYPE, "ENABLE_ROSPEC_RESPONSE")?,
        "ENABLE_ROSPEC",
    )?;
    c.send(
        3,
        StartRospec {
            ro_spec_id: 1,
            ..Default::default()
        },
    )?;
    let started = c.wait_for(StartRospecResponse::TYPE, "START_ROSPEC_RESPONSE")?;
    let start_rospec = match status_of(&started) {
        Some(s) if s.is_success() => "started",
        // Only "already running" is acceptable; reports must flow either way.
        Some(_) => "refused (Immediate spec already running)",
        None => {
            return Err(other(format!(
                "START_ROSPEC: unexpected {}",
                started.name()
            )))
        }
    };

    let deadline = t0 + duration;
    let ended = loop {
        while c.next_frame()?.is_some() {}
        let now = Instant::now();
        if now >= deadline {
            break "deadline";
        }
        if let (Some(idle), Some(last)) = (idle, c.last_report) {
            if now.duration_since(last) >= idle {
                break "idle";
            }
        }
        c.fill()?;
    };
    let end = match (ended, c.last_report) {
        ("idle", Some(last)) => last,
        _ => Instant::now(),
    };
    let seconds = end.duration_since(t0).as_secs_f64();
    let reports = c.reports;
    if reports == 0 {
        return Err(other(format!(
            "no tag reports in {seconds:.1} s (START_ROSPEC: {start_rospec})"
        )));
    }
    Ok(Outcome {
        reports,
        frames: c.frames,
        bytes: c.bytes,
        seconds,
        ended,
        start_rospec,
    })
}
