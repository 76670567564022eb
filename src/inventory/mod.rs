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
//!
//! Here: the run itself; the command line ([`InventoryArgs`]), the statistics and the screen,
//! and the reads' sink are in submodules.

use std::io::{self, Write};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::net::client::{Backoff, Client, ClientError, InventorySpec, ReadStream};
use crate::net::tls::{self, Connector, TlsError, Verify};

mod args;
mod display;
mod sink;

pub use args::{
    reader_address, reader_address_on, Format, InventoryArgs, Output, Retries, LLRP_PORT,
};
use display::{Screen, Stats};
use sink::Sink;

/// How long one request (or the connection and greeting) may take.
const REQUEST_TIMEOUT: Duration = Duration::from_secs(10);

/// How long the clean close at the end may take.
const CLOSE_TIMEOUT: Duration = Duration::from_secs(5);

/// How often the live lines are redrawn and the output flushed; also the longest the loop
/// waits before looking at the clock and the stop signal again.
const TICK: Duration = Duration::from_millis(250);

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
    /// The localizer or its HTTP API could not start.
    #[error("{0}")]
    Localizer(String),
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
pub fn run(mut args: InventoryArgs) -> ExitCode {
    match args.resolved_output() {
        Ok(out) => args.output = out,
        Err(e) => {
            eprintln!("llrp-gateway inventory: {e}");
            return ExitCode::FAILURE;
        }
    }
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
        Some(Output::Jsonl(p)) | Some(Output::Csv(p)) | Some(Output::Unnamed(p)) => {
            p.display().to_string()
        }
    };
    let output_error = |source| InventoryError::Output {
        path: output_name.clone(),
        source,
    };
    let mut sink = Sink::open(&args.output, args.force).map_err(output_error)?;
    let sinks = crate::cli::live::start_sinks(&args.live, "inventory")
        .await
        .map_err(|e| InventoryError::Localizer(e.to_string()))?;
    let tap = sinks.tap();
    // The reads of a batch go to the localizer and the MQTT publisher too (if any), then to
    // the file.
    let share = |batch: &[crate::reads::Read]| {
        if let (Some(t), false) = (&tap, batch.is_empty()) {
            t.offer(crate::localize::live::Input::Reads(batch.to_vec()));
        }
    };
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
                stats.foreign_reads += stream.foreign_reads();
                let closed = stream.finish(CLOSE_TIMEOUT, &mut batch).await;
                share(&batch);
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
                    stats.foreign_reads += stream.foreign_reads();
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
            share(&batch);
            for r in batch.drain(..) {
                sink.write(&r).map_err(output_error)?;
                stats.add(&r);
            }
            let now = Instant::now();
            if let Some(d) = dead_after {
                if now.duration_since(last_heard) > d {
                    stats.keepalives += stream.keepalives_answered();
                    stats.bad_reports += stream.bad_reports();
                    stats.foreign_reads += stream.foreign_reads();
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
    drop(tap);
    sinks.stop().await;
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
