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
//! Here: the run itself ([`Inventory`]); its settings ([`InventoryOptions`]), the statistics
//! and the screen, and the reads' sink are in submodules. The command line (its options, the
//! localizer and publisher beside the run, the error said at the exit) is `cli::inventory`.

use std::io::{self, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::localize::live::{Input, Tap};
use crate::net::client::{Backoff, Client, ClientError, ReadStream};
use crate::net::tls;
use crate::reads::Read;
use crate::record::mcap::{McapError, McapItem, McapThread};

mod display;
mod options;
mod sink;

use display::{Screen, Stats};
pub use options::{
    reader_address, reader_address_on, InventoryOptions, Output, Retries, LLRP_PORT,
};
use sink::Sink;

/// How long one request (or the connection and greeting) may take.
const REQUEST_TIMEOUT: Duration = Duration::from_secs(10);

/// How long the clean close at the end may take.
const CLOSE_TIMEOUT: Duration = Duration::from_secs(5);

/// How often the live lines are redrawn and the output flushed; also the longest the loop
/// waits before looking at the clock and the stop signal again.
const TICK: Duration = Duration::from_millis(250);

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
    /// The run ended (time, or a stop signal) before any connection was made.
    #[error("no connection to {0} before the end of the run")]
    NeverConnected(String),
    /// The MCAP file cannot be written there (it exists, or the file system refused).
    #[error("{0}")]
    McapFile(crate::files::OutputError),
    /// The MCAP file could not be written.
    #[error("writing the reads to {}: {source}", path.display())]
    Mcap {
        /// The MCAP file.
        path: std::path::PathBuf,
        /// Why.
        source: McapError,
    },
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

/// An inventory whose output is open, ready to run.
pub struct Inventory {
    opts: InventoryOptions,
    sink: Sink,
    mcap: Option<McapThread>,
}

/// An inventory that ran to its end: what its summary is made of.
pub struct Ended {
    /// The MCAP file's writer, still to be finished ([`Ended::finish_mcap`]).
    mcap: Option<(std::path::PathBuf, McapThread)>,
    addr: String,
    stats: Stats,
    screen: Screen,
    to_stdout: bool,
}

/// What a connection attempt came to.
enum Attempt {
    /// Connected, the inventory started.
    Connected(Box<ReadStream>),
    /// Failed; the back-off is waited out: try again.
    Retry,
    /// The run ended first.
    End,
}

/// How a connection's session ended.
enum Session {
    /// The run is over (time, or a stop signal); the connection was closed cleanly.
    End,
    /// The connection was lost; the back-off is waited out: reconnect.
    Lost,
}

/// The state of a run: its settings, where the reads go, the back-off, the statistics.
struct Run {
    opts: InventoryOptions,
    addr: String,
    sink: Sink,
    mcap: Option<McapThread>,
    tap: Option<Tap>,
    stop: Arc<AtomicBool>,
    deadline: Option<Instant>,
    backoff: Backoff,
    /// Silence for this long means the reader is gone (only when keepalives are on: without
    /// them an idle reader sends nothing).
    dead_after: Option<Duration>,
    stats: Stats,
    screen: Screen,
    batch: Vec<Read>,
    last_flush: Instant,
}

impl Inventory {
    /// Opens the output (an existing file is refused unless `force`).
    pub fn open(opts: InventoryOptions) -> Result<Inventory, InventoryError> {
        let sink =
            Sink::open(&opts.output, opts.force).map_err(|source| output_error(&opts, source))?;
        let mcap = match &opts.mcap {
            None => None,
            Some(path) => Some(open_mcap(path, opts.force)?),
        };
        Ok(Inventory { opts, sink, mcap })
    }

    /// Connects (and reconnects) until the end of the run, writing the reads and offering
    /// them to `tap` (the localizer, the MQTT publisher) when given.
    pub async fn run(self, tap: Option<Tap>) -> Result<Ended, InventoryError> {
        let mut run = Run::new(self, tap);
        while !run.over() {
            let stream = match run.connect().await? {
                Attempt::Connected(s) => s,
                Attempt::Retry => continue,
                Attempt::End => break,
            };
            run.connected(&stream);
            match run.session(stream).await? {
                Session::End => break,
                Session::Lost => continue,
            }
        }
        run.sink.flush().map_err(|e| run.output_error(e))?;
        Ok(Ended {
            mcap: run.opts.mcap.clone().zip(run.mcap),
            to_stdout: run.opts.output == Some(Output::Stdout),
            addr: run.addr,
            stats: run.stats,
            screen: run.screen,
        })
    }
}

impl Ended {
    /// Finishes the MCAP file, if any (on a blocking thread: it waits for the writer).
    pub async fn finish_mcap(&mut self) -> Result<(), InventoryError> {
        let Some((path, mcap)) = self.mcap.take() else {
            return Ok(());
        };
        let finished = tokio::task::spawn_blocking(move || mcap.finish())
            .await
            .unwrap_or(Err(McapError::ThreadGone));
        finished
            .map(|_| ())
            .map_err(|source| InventoryError::Mcap { path, source })
    }

    /// Clears the live lines and prints the summary (on standard error when the reads went to
    /// standard output); an error if no connection was ever made.
    pub fn report(mut self) -> Result<(), InventoryError> {
        self.screen.clear();
        if self.stats.connections == 0 {
            return Err(InventoryError::NeverConnected(self.addr));
        }
        let summary = self.stats.summary(&self.addr, Instant::now());
        if self.to_stdout {
            eprint!("{summary}");
        } else {
            print!("{summary}");
            let _ = io::stdout().flush();
        }
        Ok(())
    }
}

/// Opens the MCAP file at `path` (an existing file is refused unless `force`) and starts
/// its writer.
fn open_mcap(path: &std::path::Path, force: bool) -> Result<McapThread, InventoryError> {
    let mcap_error = |source| InventoryError::Mcap {
        path: path.to_owned(),
        source,
    };
    let file = crate::files::create_stream(path, &[], force).map_err(InventoryError::McapFile)?;
    McapThread::start(io::BufWriter::new(file)).map_err(mcap_error)
}

/// The output's I/O error, naming the output.
fn output_error(opts: &InventoryOptions, source: io::Error) -> InventoryError {
    InventoryError::Output {
        path: opts.output.as_ref().map(Output::shown).unwrap_or_default(),
        source,
    }
}

impl Run {
    fn new(inventory: Inventory, tap: Option<Tap>) -> Run {
        let Inventory { opts, sink, mcap } = inventory;
        let addr = if opts.tls.is_some() {
            reader_address_on(&opts.reader, tls::LLRP_TLS_PORT)
        } else {
            reader_address(&opts.reader)
        };
        let retries = match opts.retries {
            Retries::Limit(n) => Some(n),
            Retries::Forever => None,
        };
        let backoff = Backoff::new(
            Duration::from_millis(opts.backoff_ms),
            Duration::from_millis(opts.backoff_max_ms),
            retries,
        );
        let keepalive_ms = opts.spec.keepalive_ms;
        Run {
            addr,
            sink,
            mcap,
            tap,
            stop: watch_stop_signals(),
            deadline: opts
                .seconds
                .map(|s| Instant::now() + Duration::from_secs_f64(s)),
            backoff,
            dead_after: (keepalive_ms > 0).then(|| {
                Duration::from_millis(u64::from(keepalive_ms) * 3) + Duration::from_secs(5)
            }),
            stats: Stats::new(),
            screen: Screen::new(),
            batch: Vec::new(),
            last_flush: Instant::now(),
            opts,
        }
    }

    /// The run's time is up, or a stop signal came.
    fn over(&self) -> bool {
        self.stop.load(Ordering::SeqCst) || self.deadline.is_some_and(|t| Instant::now() >= t)
    }

    fn output_error(&self, source: io::Error) -> InventoryError {
        output_error(&self.opts, source)
    }

    /// Connects and sets up, giving up early at the end of the run; a transient failure waits
    /// out the back-off.
    async fn connect(&mut self) -> Result<Attempt, InventoryError> {
        let setup = async {
            let client =
                Client::connect_reader_with(&self.addr, self.opts.tls.as_ref(), REQUEST_TIMEOUT)
                    .await?;
            let name = Some(self.opts.name.clone());
            ReadStream::start(client, &self.opts.spec, name, REQUEST_TIMEOUT).await
        };
        let watch_end = async {
            while !self.over() {
                tokio::time::sleep(TICK).await;
            }
        };
        let result = tokio::select! {
            r = setup => r,
            () = watch_end => return Ok(Attempt::End),
        };
        let addr = &self.addr;
        match result {
            Ok(s) => Ok(Attempt::Connected(Box::new(s))),
            Err(e) if e.is_transient() => match self.backoff.next_delay() {
                Some(d) => {
                    self.screen.log(&format!(
                        "cannot connect to {addr}: {e}; retrying in {d:?} ({})",
                        attempt_of(&self.backoff)
                    ));
                    pause(d, self.deadline, &self.stop).await;
                    Ok(Attempt::Retry)
                }
                None => Err(InventoryError::GaveUp {
                    addr: addr.clone(),
                    attempts: self.backoff.failures(),
                    source: e,
                }),
            },
            Err(e) => Err(InventoryError::Rejected {
                addr: addr.clone(),
                source: e,
            }),
        }
    }

    /// Counts the new connection and says it on the screen.
    fn connected(&mut self, stream: &ReadStream) {
        self.backoff.reset();
        self.stats.connections += 1;
        self.stats.started.get_or_insert_with(Instant::now);
        let table = match stream.hop_table() {
            Some(t) => format!(
                "hop table {} ({} channels) from the reader's capabilities",
                t.id,
                t.frequencies_khz.len()
            ),
            None => "no hop table in the reader's capabilities: frequencies unknown".into(),
        };
        let via = if self.opts.tls.is_some() {
            " over TLS"
        } else {
            ""
        };
        self.screen.log(&format!(
            "connected to {}{via}, inventory started; {table}",
            self.addr
        ));
    }

    /// Takes the reads of `stream` until the run is over (then closes it cleanly) or the
    /// connection is lost (then waits out the back-off).
    async fn session(&mut self, mut stream: Box<ReadStream>) -> Result<Session, InventoryError> {
        let mut last_heard = Instant::now();
        let mut keepalives = 0;
        loop {
            let now = Instant::now();
            if self.over() {
                self.close(*stream).await?;
                return Ok(Session::End);
            }
            let wait = self
                .deadline
                .map_or(TICK, |t| t.saturating_duration_since(now).min(TICK));
            match stream.next(wait, &mut self.batch).await {
                Ok(()) => last_heard = Instant::now(),
                Err(ClientError::Timeout(_)) => {}
                Err(e) => {
                    self.count(&stream);
                    let why = match e {
                        ClientError::Closed => "the reader closed the connection".to_string(),
                        e => format!("connection lost: {e}"),
                    };
                    self.lost(&why).await?;
                    return Ok(Session::Lost);
                }
            }
            if stream.keepalives_answered() != keepalives {
                keepalives = stream.keepalives_answered();
                last_heard = Instant::now();
            }
            self.drain().await?;
            let now = Instant::now();
            if let Some(why) = self.silent(now, last_heard) {
                self.count(&stream);
                drop(stream);
                self.lost(&why).await?;
                return Ok(Session::Lost);
            }
            self.screen.tick(&mut self.stats, now);
            if now.duration_since(self.last_flush) >= TICK {
                self.sink.flush().map_err(|e| self.output_error(e))?;
                self.last_flush = now;
            }
        }
    }

    /// Why the reader is taken for gone, if it has been silent too long.
    fn silent(&self, now: Instant, last_heard: Instant) -> Option<String> {
        let d = self.dead_after?;
        (now.duration_since(last_heard) > d).then(|| {
            format!(
                "nothing from the reader for {:.1} s (keepalives every {} ms)",
                d.as_secs_f64(),
                self.opts.spec.keepalive_ms
            )
        })
    }

    /// At the end of the run: stops the inventory and closes the connection, taking the last
    /// reads.
    async fn close(&mut self, stream: ReadStream) -> Result<(), InventoryError> {
        self.count(&stream);
        let closed = stream.finish(CLOSE_TIMEOUT, &mut self.batch).await;
        self.drain().await?;
        if let Err(e) = closed {
            self.screen.log(&format!("closing the connection: {e}"));
        }
        Ok(())
    }

    /// Adds the counters of a connection that ends to the statistics.
    fn count(&mut self, stream: &ReadStream) {
        self.stats.keepalives += stream.keepalives_answered();
        self.stats.bad_reports += stream.bad_reports();
        self.stats.foreign_reads += stream.foreign_reads();
    }

    /// The batch's reads to the localizer and the MQTT publisher (if any), the MCAP file's
    /// writer (if any), then to the output and the statistics.
    async fn drain(&mut self) -> Result<(), InventoryError> {
        if let (Some(t), false) = (&self.tap, self.batch.is_empty()) {
            t.offer(Input::Reads(self.batch.to_vec()));
        }
        if let (Some(m), false) = (&self.mcap, self.batch.is_empty()) {
            let item = McapItem::Reads {
                received_us: crate::utc::now_us(),
                reads: self.batch.to_vec(),
            };
            if let Err(source) = m.send(item).await {
                return Err(InventoryError::Mcap {
                    path: self.opts.mcap.clone().unwrap_or_default(),
                    source,
                });
            }
        }
        for r in self.batch.drain(..) {
            if let Err(e) = self.sink.write(&r) {
                return Err(output_error(&self.opts, e));
            }
            self.stats.add(&r);
        }
        Ok(())
    }

    /// After a lost connection: logs why and waits out the back-off before the next attempt.
    async fn lost(&mut self, why: &str) -> Result<(), InventoryError> {
        match self.backoff.next_delay() {
            Some(d) => {
                self.screen.log(&format!(
                    "{why}; reconnecting in {d:?} ({})",
                    attempt_of(&self.backoff)
                ));
                pause(d, self.deadline, &self.stop).await;
                Ok(())
            }
            None => Err(InventoryError::GaveUp {
                addr: self.addr.clone(),
                attempts: self.backoff.failures(),
                source: ClientError::Closed,
            }),
        }
    }
}

/// "retry k of N" (or "retry k").
fn attempt_of(b: &Backoff) -> String {
    match b.retries() {
        Some(n) => format!("retry {} of {n}", b.failures()),
        None => format!("retry {}", b.failures()),
    }
}
