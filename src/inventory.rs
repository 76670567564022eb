//! `llrp-gateway inventory HOST[:PORT]`: an LLRP inventory against any reader (the simulated
//! one, or real hardware), built on the crate's client ([`crate::net::client`]).
//!
//! It connects and waits for the reader's greeting, reads its capabilities (the hop table the
//! reads' frequencies come from), asks for periodic keepalives (answered as they come),
//! optionally enables the Impinj extensions, adds, enables and starts one ROSpec, and writes
//! every tag read to a reads file (JSON Lines, the project's format, or CSV). A lost
//! connection is re-established with a capped exponential back-off; at the end (after
//! `--seconds`, or on Ctrl-C / SIGTERM) the ROSpec is stopped and deleted and the connection
//! closed with CLOSE_CONNECTION. On a terminal it shows a live line per antenna; it always
//! prints a summary. See `docs/client.md`.

use std::collections::{BTreeMap, HashSet};
use std::fs::File;
use std::io::{self, IsTerminal, Write};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::net::client::{Backoff, Client, ClientError, InventorySpec, ReadStream};
use crate::net::tls::{self, Connector, TlsError, Verify};
use crate::reads::{self, Read};

/// The LLRP port a reader listens on when HOST has none.
pub const LLRP_PORT: u16 = 5084;

/// How long one request (or the connection and greeting) may take.
const REQUEST_TIMEOUT: Duration = Duration::from_secs(10);

/// How long the clean close at the end may take.
const CLOSE_TIMEOUT: Duration = Duration::from_secs(5);

/// How often the live lines are redrawn and the output flushed; also the longest the loop
/// waits before looking at the clock and the stop signal again.
const TICK: Duration = Duration::from_millis(250);

/// How often the live lines change.
const LIVE_EVERY: Duration = Duration::from_secs(1);

/// Command-line options of `llrp-gateway inventory`.
#[derive(Clone, Debug, PartialEq, clap::Args)]
pub struct InventoryArgs {
    /// The reader: HOST or HOST:PORT (port 5084 when none is given); IPv6 as `[ADDR]:PORT`.
    pub reader: String,
    /// Stop after this many seconds (default: run until Ctrl-C or SIGTERM).
    #[arg(long, value_parser = parse_seconds)]
    pub seconds: Option<f64>,
    /// Antenna ports to inventory, comma-separated (default: all the reader has).
    #[arg(long, value_delimiter = ',', value_parser = clap::value_parser!(u16).range(1..))]
    pub antennas: Vec<u16>,
    /// Enable the Impinj extensions and ask for Impinj RF phase, peak RSSI and Doppler.
    #[arg(long)]
    pub impinj: bool,
    /// The reader sends a report every N tag entries (a reader may fold a tag's repeated
    /// reads into one entry; reads not yet reported come when the inventory stops).
    #[arg(long, value_name = "N", default_value_t = 1, value_parser = clap::value_parser!(u16).range(1..))]
    pub report_every: u16,
    /// Gen2 session, 0-3 (default: the reader's).
    #[arg(long, value_parser = clap::value_parser!(u8).range(0..=3))]
    pub session: Option<u8>,
    /// Impinj inventory search mode (0 reader selected, 1 single target, 2 dual target,
    /// 3 single target with suppression, ...; default: the reader's).
    #[arg(long, value_name = "M")]
    pub search_mode: Option<u16>,
    /// RF mode: a ModeIdentifier of the reader's RF mode table (default: the reader's).
    #[arg(long, value_name = "ID")]
    pub mode: Option<u16>,
    /// Write the reads here: a `.jsonl` file (the reads file), a `.csv` file, or `-` for
    /// JSON Lines on standard output.
    #[arg(long, value_parser = parse_output)]
    pub output: Option<Output>,
    /// Reader name written in each read (default: the reader address as given).
    #[arg(long)]
    pub name: Option<String>,
    /// Keepalive interval asked of the reader, ms (0: none). A reader silent for three
    /// intervals and 5 s more is taken for lost and reconnected.
    #[arg(long, value_name = "MS", default_value_t = 5000)]
    pub keepalive_ms: u32,
    /// Retries after failed connection attempts in a row: a number, or `forever`.
    #[arg(long, default_value = "5", value_parser = parse_retries)]
    pub retries: Retries,
    /// First wait before a retry, ms; it doubles with each failure in a row.
    #[arg(long, value_name = "MS", default_value_t = 500)]
    pub backoff_ms: u64,
    /// Longest wait before a retry, ms.
    #[arg(long, value_name = "MS", default_value_t = 30_000)]
    pub backoff_max_ms: u64,
    /// LLRP over TLS (port 5085 when HOST has none), with --tls-ca or --tls-insecure.
    #[arg(long)]
    pub tls: bool,
    /// With --tls: CA certificates (PEM) the reader's certificate must be issued by.
    #[arg(
        long,
        value_name = "FILE",
        requires = "tls",
        conflicts_with = "tls_insecure"
    )]
    pub tls_ca: Option<PathBuf>,
    /// With --tls: accept any reader certificate (encrypted, but not authenticated).
    #[arg(long, requires = "tls")]
    pub tls_insecure: bool,
    /// With --tls: the name the reader's certificate must carry (default: HOST).
    #[arg(long, value_name = "NAME", requires = "tls")]
    pub tls_server_name: Option<String>,
}

/// How many times a failed connection is retried.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Retries {
    /// At most this many retries after failures in a row.
    Limit(u32),
    /// Retry until stopped.
    Forever,
}

/// Where the reads go.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Output {
    /// JSON Lines (the reads file) to this file.
    Jsonl(PathBuf),
    /// CSV with a header row to this file.
    Csv(PathBuf),
    /// JSON Lines to standard output.
    Stdout,
}

fn parse_seconds(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v > 0.0 && v.is_finite() && v < 1e9 => Ok(v),
        _ => Err(format!("`{s}` is not a positive number of seconds")),
    }
}

fn parse_retries(s: &str) -> Result<Retries, String> {
    if s == "forever" {
        return Ok(Retries::Forever);
    }
    s.parse::<u32>()
        .map(Retries::Limit)
        .map_err(|_| format!("`{s}` is neither a number of retries nor `forever`"))
}

fn parse_output(s: &str) -> Result<Output, String> {
    if s == "-" {
        return Ok(Output::Stdout);
    }
    let path = PathBuf::from(s);
    match path.extension().and_then(|e| e.to_str()) {
        Some("jsonl") | Some("ndjson") => Ok(Output::Jsonl(path)),
        Some("csv") => Ok(Output::Csv(path)),
        _ => Err(format!(
            "`{s}`: the file name must end in .jsonl (reads file) or .csv, or be `-`"
        )),
    }
}

/// `HOST[:PORT]` as a socket address string: port 5084 when none is given.
pub fn reader_address(reader: &str) -> String {
    reader_address_on(reader, LLRP_PORT)
}

/// `HOST[:PORT]` as a socket address string: port `port` when none is given.
pub fn reader_address_on(reader: &str, port: u16) -> String {
    if reader.parse::<std::net::SocketAddr>().is_ok() {
        return reader.to_string();
    }
    if let Ok(ip) = reader.parse::<std::net::IpAddr>() {
        return std::net::SocketAddr::new(ip, port).to_string();
    }
    match reader.rsplit_once(':') {
        Some((host, p)) if !host.contains(':') && p.parse::<u16>().is_ok() => reader.to_string(),
        _ => format!("{reader}:{port}"),
    }
}

/// The TLS client of `--tls`, if asked for: `--tls-ca` or (logged) `--tls-insecure`.
fn connector(args: &InventoryArgs) -> Result<Option<Connector>, InventoryError> {
    if !args.tls {
        return Ok(None);
    }
    let verify = match (&args.tls_ca, args.tls_insecure) {
        (Some(ca), _) => Verify::Ca(ca.clone()),
        (None, true) => {
            eprintln!(
                "llrp-gateway inventory: warning: --tls-insecure: the reader's certificate is \
                 not checked (the connection is encrypted, not authenticated)"
            );
            Verify::Insecure
        }
        (None, false) => return Err(InventoryError::TlsTrust),
    };
    Ok(Some(Connector::new(
        &verify,
        args.tls_server_name.as_deref(),
    )?))
}

/// Why an inventory ended in failure.
#[derive(Debug, thiserror::Error)]
pub enum InventoryError {
    /// Every allowed connection attempt failed.
    #[error("cannot connect to {addr} after {attempts} attempt(s): {source}")]
    GaveUp {
        /// The reader address.
        addr: String,
        /// Attempts made in a row.
        attempts: u32,
        /// The last failure.
        source: ClientError,
    },
    /// The reader refused the inventory (a rejected request, or a setting it cannot do).
    #[error("{addr}: {source}")]
    Rejected {
        /// The reader address.
        addr: String,
        /// What the reader said.
        source: ClientError,
    },
    /// The TLS settings cannot be used.
    #[error("TLS: {0}")]
    Tls(#[from] TlsError),
    /// `--tls` without saying which certificates to trust.
    #[error("--tls needs --tls-ca FILE (the CA, or the reader's own self-signed certificate) or --tls-insecure (accept any certificate)")]
    TlsTrust,
    /// The run ended (time, or a stop signal) before any connection was made.
    #[error("no connection to {0} before the end of the run")]
    NeverConnected(String),
    /// The output could not be written.
    #[error("writing the reads to {path}: {source}")]
    Output {
        /// Where the reads go.
        path: String,
        /// The I/O error.
        source: io::Error,
    },
}

/// Reads seen on one antenna.
#[derive(Clone, Debug, Default)]
struct AntennaStats {
    reads: u64,
    /// Reads since the last live line.
    recent: u64,
    rssi: Option<(f64, f64)>,
}

/// What the run saw.
#[derive(Debug)]
struct Stats {
    reads: u64,
    epcs: HashSet<String>,
    antennas: BTreeMap<u16, AntennaStats>,
    /// When the first inventory started.
    started: Option<Instant>,
    connections: u32,
    keepalives: u64,
    bad_reports: u64,
}

impl Stats {
    fn new() -> Self {
        Stats {
            reads: 0,
            epcs: HashSet::new(),
            antennas: BTreeMap::new(),
            started: None,
            connections: 0,
            keepalives: 0,
            bad_reports: 0,
        }
    }

    fn add(&mut self, r: &Read) {
        self.reads += 1;
        if !self.epcs.contains(&r.epc) {
            self.epcs.insert(r.epc.clone());
        }
        let a = self.antennas.entry(r.antenna).or_default();
        a.reads += 1;
        a.recent += 1;
        if let Some(v) = r.rssi_dbm {
            a.rssi = Some(a.rssi.map_or((v, v), |(lo, hi)| (lo.min(v), hi.max(v))));
        }
    }

    fn seconds(&self, now: Instant) -> f64 {
        self.started
            .map_or(0.0, |s| now.duration_since(s).as_secs_f64())
    }

    /// The summary: a totals line and a line per antenna.
    fn summary(&self, addr: &str, now: Instant) -> String {
        let secs = self.seconds(now);
        let rate = if secs > 0.0 {
            self.reads as f64 / secs
        } else {
            0.0
        };
        let mut s = format!(
            "llrp-gateway inventory: {addr}: {} reads, {} distinct EPCs in {secs:.1} s \
             ({rate:.1} reads/s); connections: {}, keepalives answered: {}",
            self.reads,
            self.epcs.len(),
            self.connections,
            self.keepalives
        );
        if self.bad_reports > 0 {
            s.push_str(&format!(
                ", undecodable reports skipped: {}",
                self.bad_reports
            ));
        }
        s.push('\n');
        for (id, a) in &self.antennas {
            s.push_str(&format!(
                "  antenna {id}: {} reads, RSSI {}\n",
                a.reads,
                rssi_range(a.rssi)
            ));
        }
        s
    }
}

fn rssi_range(r: Option<(f64, f64)>) -> String {
    match r {
        Some((lo, hi)) => format!("{lo:.1}..{hi:.1} dBm"),
        None => "none reported".into(),
    }
}

/// Bytes of whole lines buffered before they are written out.
const SINK_BUFFER: usize = 64 * 1024;

/// The reads' destination, open. Lines are buffered here and written out whole (when the
/// buffer fills, and at each flush), so the file never ends in a partial line between
/// writes: a reader following it live only ever sees whole reads.
struct Sink {
    out: Option<Box<dyn Write>>,
    csv: bool,
    buf: Vec<u8>,
}

impl Sink {
    fn open(output: &Option<Output>) -> io::Result<Sink> {
        let (out, csv): (Option<Box<dyn Write>>, bool) = match output {
            None => (None, false),
            Some(Output::Stdout) => (Some(Box::new(io::stdout())), false),
            Some(Output::Jsonl(p)) => (Some(Box::new(File::create(p)?)), false),
            Some(Output::Csv(p)) => (Some(Box::new(File::create(p)?)), true),
        };
        let mut sink = Sink {
            out,
            csv,
            buf: Vec::with_capacity(SINK_BUFFER),
        };
        if csv {
            sink.buf.extend_from_slice(reads::CSV_HEADER.as_bytes());
            sink.buf.push(b'\n');
            sink.flush()?;
        }
        Ok(sink)
    }

    fn write(&mut self, r: &Read) -> io::Result<()> {
        if self.out.is_none() {
            return Ok(());
        }
        if self.csv {
            self.buf.extend_from_slice(r.csv_row().as_bytes());
            self.buf.push(b'\n');
        } else {
            reads::write_jsonl(&mut self.buf, r)?;
        }
        if self.buf.len() >= SINK_BUFFER {
            self.flush()?;
        }
        Ok(())
    }

    fn flush(&mut self) -> io::Result<()> {
        if let Some(out) = &mut self.out {
            out.write_all(&self.buf)?;
            out.flush()?;
        }
        self.buf.clear();
        Ok(())
    }
}

/// Log lines on stderr, and on a terminal the live lines below them.
struct Screen {
    live: bool,
    /// Live lines currently drawn.
    drawn: usize,
    last_live: Instant,
}

impl Screen {
    fn new() -> Self {
        Screen {
            live: io::stderr().is_terminal(),
            drawn: 0,
            last_live: Instant::now(),
        }
    }

    fn clear(&mut self) {
        if self.drawn > 0 {
            let mut e = io::stderr().lock();
            // Up over the live lines, clearing each; best effort on a terminal.
            for _ in 0..self.drawn {
                let _ = write!(e, "\x1b[1A\x1b[2K");
            }
            let _ = e.flush();
            self.drawn = 0;
        }
    }

    fn log(&mut self, line: &str) {
        self.clear();
        eprintln!("llrp-gateway inventory: {line}");
    }

    /// Redraws the live lines once a second (a terminal only).
    fn tick(&mut self, stats: &mut Stats, now: Instant) {
        let dt = now.duration_since(self.last_live);
        if dt < LIVE_EVERY {
            return;
        }
        self.last_live = now;
        let dt = dt.as_secs_f64();
        let mut lines = Vec::new();
        for (id, a) in &mut stats.antennas {
            lines.push(format!(
                "antenna {id}: {} reads, {:.1} reads/s, RSSI {}",
                a.reads,
                a.recent as f64 / dt,
                rssi_range(a.rssi)
            ));
            a.recent = 0;
        }
        if !self.live {
            return;
        }
        self.clear();
        let mut e = io::stderr().lock();
        if lines.is_empty() {
            lines.push("no reads yet".into());
        }
        for l in &lines {
            let _ = writeln!(e, "{l}");
        }
        let _ = e.flush();
        self.drawn = lines.len();
    }
}

/// Set once Ctrl-C or SIGTERM arrives.
fn watch_stop_signals() -> Arc<AtomicBool> {
    let flag = Arc::new(AtomicBool::new(false));
    let set = flag.clone();
    tokio::spawn(async move {
        #[cfg(unix)]
        {
            use tokio::signal::unix::{signal, SignalKind};
            match signal(SignalKind::terminate()) {
                Ok(mut term) => {
                    tokio::select! {
                        _ = tokio::signal::ctrl_c() => {}
                        _ = term.recv() => {}
                    }
                }
                Err(_) => {
                    let _ = tokio::signal::ctrl_c().await;
                }
            }
        }
        #[cfg(not(unix))]
        let _ = tokio::signal::ctrl_c().await;
        set.store(true, Ordering::SeqCst);
    });
    flag
}

/// Sleeps `d`, waking early at `deadline` or when `stop` is set; whether to go on.
async fn pause(d: Duration, deadline: Option<Instant>, stop: &AtomicBool) -> bool {
    let until = Instant::now() + d;
    loop {
        let now = Instant::now();
        if stop.load(Ordering::SeqCst) || deadline.is_some_and(|t| now >= t) {
            return false;
        }
        if now >= until {
            return true;
        }
        tokio::time::sleep((until - now).min(TICK)).await;
    }
}

/// Runs `llrp-gateway inventory` and reports the outcome as the process's exit code.
pub fn run(args: InventoryArgs) -> ExitCode {
    let runtime = match tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
    {
        Ok(r) => r,
        Err(e) => {
            eprintln!("llrp-gateway inventory: cannot start the async runtime: {e}");
            return ExitCode::FAILURE;
        }
    };
    match runtime.block_on(inventory(&args)) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("llrp-gateway inventory: {e}");
            ExitCode::FAILURE
        }
    }
}

/// The inventory itself: connects (and reconnects) until the end of the run, writes the reads,
/// prints the summary.
pub async fn inventory(args: &InventoryArgs) -> Result<(), InventoryError> {
    let tls = connector(args)?;
    let addr = if args.tls {
        reader_address_on(&args.reader, tls::LLRP_TLS_PORT)
    } else {
        reader_address(&args.reader)
    };
    let spec = InventorySpec {
        antennas: args.antennas.clone(),
        impinj: args.impinj,
        report_every: args.report_every,
        session: args.session,
        search_mode: args.search_mode,
        mode: args.mode,
        keepalive_ms: args.keepalive_ms,
        ..InventorySpec::default()
    };
    let name = Some(args.name.clone().unwrap_or_else(|| args.reader.clone()));
    let output_name = match &args.output {
        None => String::new(),
        Some(Output::Stdout) => "standard output".into(),
        Some(Output::Jsonl(p)) | Some(Output::Csv(p)) => p.display().to_string(),
    };
    let output_error = |source| InventoryError::Output {
        path: output_name.clone(),
        source,
    };
    let mut sink = Sink::open(&args.output).map_err(output_error)?;
    let stop = watch_stop_signals();
    let deadline = args
        .seconds
        .map(|s| Instant::now() + Duration::from_secs_f64(s));
    let retries = match args.retries {
        Retries::Limit(n) => Some(n),
        Retries::Forever => None,
    };
    let mut backoff = Backoff::new(
        Duration::from_millis(args.backoff_ms),
        Duration::from_millis(args.backoff_max_ms),
        retries,
    );
    // Silence for this long means the reader is gone (only when keepalives are on: without
    // them an idle reader sends nothing).
    let dead_after = (args.keepalive_ms > 0)
        .then(|| Duration::from_millis(u64::from(args.keepalive_ms) * 3) + Duration::from_secs(5));
    let mut stats = Stats::new();
    let mut screen = Screen::new();
    let mut batch = Vec::new();
    let mut last_flush = Instant::now();
    let over = |stop: &AtomicBool| {
        stop.load(Ordering::SeqCst) || deadline.is_some_and(|t| Instant::now() >= t)
    };

    'connections: while !over(&stop) {
        // Connect and set up, giving up early at the end of the run.
        let setup = async {
            let client = Client::connect_reader_with(&addr, tls.as_ref(), REQUEST_TIMEOUT).await?;
            ReadStream::start(client, &spec, name.clone(), REQUEST_TIMEOUT).await
        };
        let watch_end = async {
            while !over(&stop) {
                tokio::time::sleep(TICK).await;
            }
        };
        let result = tokio::select! {
            r = setup => r,
            () = watch_end => break 'connections,
        };
        let mut stream = match result {
            Ok(s) => s,
            Err(e) if e.is_transient() => match backoff.next_delay() {
                Some(d) => {
                    screen.log(&format!(
                        "cannot connect to {addr}: {e}; retrying in {d:?} ({})",
                        attempt_of(&backoff)
                    ));
                    pause(d, deadline, &stop).await;
                    continue;
                }
                None => {
                    return Err(InventoryError::GaveUp {
                        addr,
                        attempts: backoff.failures(),
                        source: e,
                    })
                }
            },
            Err(e) => return Err(InventoryError::Rejected { addr, source: e }),
        };
        backoff.reset();
        stats.connections += 1;
        stats.started.get_or_insert_with(Instant::now);
        let table = match stream.hop_table() {
            Some(t) => format!(
                "hop table {} ({} channels) from the reader's capabilities",
                t.id,
                t.frequencies_khz.len()
            ),
            None => "no hop table in the reader's capabilities: frequencies unknown".into(),
        };
        let via = if tls.is_some() { " over TLS" } else { "" };
        screen.log(&format!(
            "connected to {addr}{via}, inventory started; {table}"
        ));
        let mut last_heard = Instant::now();
        let mut keepalives = 0;
        loop {
            let now = Instant::now();
            if over(&stop) {
                stats.keepalives += stream.keepalives_answered();
                stats.bad_reports += stream.bad_reports();
                let closed = stream.finish(CLOSE_TIMEOUT, &mut batch).await;
                for r in batch.drain(..) {
                    sink.write(&r).map_err(output_error)?;
                    stats.add(&r);
                }
                if let Err(e) = closed {
                    screen.log(&format!("closing the connection: {e}"));
                }
                break 'connections;
            }
            let wait = deadline.map_or(TICK, |t| t.saturating_duration_since(now).min(TICK));
            match stream.next(wait, &mut batch).await {
                Ok(()) => last_heard = Instant::now(),
                Err(ClientError::Timeout(_)) => {}
                Err(e) => {
                    stats.keepalives += stream.keepalives_answered();
                    stats.bad_reports += stream.bad_reports();
                    let why = match e {
                        ClientError::Closed => "the reader closed the connection".to_string(),
                        e => format!("connection lost: {e}"),
                    };
                    lost(&mut screen, &mut backoff, &why, deadline, &stop, &addr).await?;
                    continue 'connections;
                }
            }
            if stream.keepalives_answered() != keepalives {
                keepalives = stream.keepalives_answered();
                last_heard = Instant::now();
            }
            for r in batch.drain(..) {
                sink.write(&r).map_err(output_error)?;
                stats.add(&r);
            }
            let now = Instant::now();
            if let Some(d) = dead_after {
                if now.duration_since(last_heard) > d {
                    stats.keepalives += stream.keepalives_answered();
                    stats.bad_reports += stream.bad_reports();
                    let why = format!(
                        "nothing from the reader for {:.1} s (keepalives every {} ms)",
                        d.as_secs_f64(),
                        args.keepalive_ms
                    );
                    drop(stream);
                    lost(&mut screen, &mut backoff, &why, deadline, &stop, &addr).await?;
                    continue 'connections;
                }
            }
            screen.tick(&mut stats, now);
            if now.duration_since(last_flush) >= TICK {
                sink.flush().map_err(output_error)?;
                last_flush = now;
            }
        }
    }
    sink.flush().map_err(output_error)?;
    screen.clear();
    if stats.connections == 0 {
        return Err(InventoryError::NeverConnected(addr));
    }
    let summary = stats.summary(&addr, Instant::now());
    if args.output == Some(Output::Stdout) {
        eprint!("{summary}");
    } else {
        print!("{summary}");
        let _ = io::stdout().flush();
    }
    Ok(())
}

/// "retry k of N" (or "retry k").
fn attempt_of(b: &Backoff) -> String {
    match b.retries() {
        Some(n) => format!("retry {} of {n}", b.failures()),
        None => format!("retry {}", b.failures()),
    }
}

/// After a lost connection: logs why and waits out the back-off before the next attempt.
async fn lost(
    screen: &mut Screen,
    backoff: &mut Backoff,
    why: &str,
    deadline: Option<Instant>,
    stop: &AtomicBool,
    addr: &str,
) -> Result<(), InventoryError> {
    match backoff.next_delay() {
        Some(d) => {
            screen.log(&format!(
                "{why}; reconnecting in {d:?} ({})",
                attempt_of(backoff)
            ));
            pause(d, deadline, stop).await;
            Ok(())
        }
        None => Err(InventoryError::GaveUp {
            addr: addr.to_string(),
            attempts: backoff.failures(),
            source: ClientError::Closed,
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        args: InventoryArgs,
    }

    fn parse(args: &[&str]) -> Result<InventoryArgs, clap::Error> {
        Cli::try_parse_from(std::iter::once("inventory").chain(args.iter().copied()))
            .map(|c| c.args)
    }

    #[test]
    fn the_antenna_list_is_comma_separated_and_one_based() {
        let a = parse(&["reader", "--antennas", "1,2,8"]).expect("parses");
        assert_eq!(a.antennas, [1, 2, 8]);
        assert!(parse(&["reader"]).expect("parses").antennas.is_empty());
        assert!(parse(&["reader", "--antennas", "0"]).is_err(), "antenna 0");
        assert!(
            parse(&["reader", "--antennas", "1,x"]).is_err(),
            "not a number"
        );
    }

    #[test]
    fn the_session_is_zero_to_three() {
        for s in 0..=3u8 {
            let a = parse(&["r", "--session", &s.to_string()]).expect("parses");
            assert_eq!(a.session, Some(s));
        }
        let e = parse(&["r", "--session", "4"]).expect_err("session 4");
        assert!(e.to_string().contains("0..=3"), "{e}");
    }

    #[test]
    fn every_option_parses_and_bad_values_are_refused() {
        let a = parse(&[
            "10.0.0.7:5085",
            "--seconds",
            "2.5",
            "--impinj",
            "--report-every",
            "10",
            "--search-mode",
            "2",
            "--mode",
            "1002",
            "--output",
            "reads.csv",
            "--retries",
            "forever",
            "--keepalive-ms",
            "0",
        ])
        .expect("parses");
        assert_eq!(a.seconds, Some(2.5));
        assert!(a.impinj);
        assert_eq!(a.report_every, 10);
        assert_eq!(a.search_mode, Some(2));
        assert_eq!(a.mode, Some(1002));
        assert_eq!(a.output, Some(Output::Csv("reads.csv".into())));
        assert_eq!(a.retries, Retries::Forever);
        assert_eq!(a.keepalive_ms, 0);
        let d = parse(&["r"]).expect("parses");
        assert_eq!(d.retries, Retries::Limit(5));
        assert_eq!(d.output, None);
        assert_eq!(
            parse(&["r", "--output", "x.jsonl"]).expect("parses").output,
            Some(Output::Jsonl("x.jsonl".into()))
        );
        assert_eq!(
            parse(&["r", "--output", "-"]).expect("parses").output,
            Some(Output::Stdout)
        );
        for bad in [
            &["r", "--seconds", "0"][..],
            &["r", "--seconds", "-1"],
            &["r", "--seconds", "soon"],
            &["r", "--output", "reads.txt"],
            &["r", "--report-every", "0"],
            &["r", "--retries", "many"],
        ] {
            assert!(parse(bad).is_err(), "{bad:?} is refused");
        }
    }

    #[test]
    fn the_port_defaults_to_5084() {
        assert_eq!(reader_address("reader.local"), "reader.local:5084");
        assert_eq!(reader_address("reader.local:6000"), "reader.local:6000");
        assert_eq!(reader_address("10.1.2.3"), "10.1.2.3:5084");
        assert_eq!(reader_address("10.1.2.3:1"), "10.1.2.3:1");
        assert_eq!(reader_address("::1"), "[::1]:5084");
        assert_eq!(reader_address("[::1]:5000"), "[::1]:5000");
    }

    #[test]
    fn the_summary_has_totals_and_each_antennas_rssi_range() {
        let mut s = Stats::new();
        let read = |epc: &str, antenna, rssi| Read {
            epc: epc.into(),
            reader: None,
            antenna,
            t_us: 0,
            phase_rad: None,
            rssi_dbm: rssi,
            channel_index: None,
            channel_frequency_hz: None,
            doppler_hz: None,
            antenna_pose: None,
            last_seen_us: None,
        };
        s.add(&read("AA", 1, Some(-60.0)));
        s.add(&read("AA", 1, Some(-50.5)));
        s.add(&read("BB", 2, None));
        s.connections = 1;
        let text = s.summary("r:5084", Instant::now());
        assert!(text.contains("3 reads, 2 distinct EPCs"), "{text}");
        assert!(
            text.contains("antenna 1: 2 reads, RSSI -60.0..-50.5 dBm"),
            "{text}"
        );
        assert!(
            text.contains("antenna 2: 1 reads, RSSI none reported"),
            "{text}"
        );
    }
}
