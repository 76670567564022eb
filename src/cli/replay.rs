//! `llrp-gateway replay`: a recording served as a reader until Ctrl-C or SIGTERM, with the
//! localizer and publisher of [`super::live`] fed with what is replayed. The replay session
//! is [`crate::record::replay`], its server [`crate::net::replay`].

use std::path::{Path, PathBuf};
use std::sync::Arc;

use tokio::sync::watch;

use super::live::{start_sinks, LiveArgs, SinksError};
use crate::foxglove::LiveServer;
use crate::net::clock::Speed;
use crate::net::tls::{Acceptor, ServerFiles, TlsError};
use crate::record::mcap::{McapError, McapThread};
use crate::record::replay::{ReplayOptions, Script, ScriptError};
use crate::record::{
    Discard, Header, RecordError, RecordOptions, Recorder, RecorderTask, Recording,
};
use crate::stop::StopSignal;

/// Arguments of `llrp-gateway replay`.
#[derive(clap::Args, Debug)]
pub struct ReplayArgs {
    /// The recording (JSON Lines, docs/recordings.md), or an MCAP file of its LLRP frames
    /// (`export --mcap`; docs/robotics.md).
    pub file: PathBuf,
    /// Where clients connect.
    #[arg(long, default_value = "0.0.0.0:5084")]
    pub listen: String,
    /// Recorded time per real time: a factor (1 = as recorded) or `max` (no waiting).
    #[arg(long, default_value = "1")]
    pub speed: Speed,
    /// Start the reports stream over when it ends, timestamps shifted.
    #[arg(long = "loop")]
    pub looped: bool,
    /// Replay this recorded connection (default: the first that carries an LLRP session,
    /// see `--list`).
    #[arg(long, value_parser = crate::cli::options::parser::<u32>("conn"))]
    pub conn: Option<u32>,
    /// List the recording's connections (what each holds, which one is replayed by
    /// default) and exit.
    #[arg(long)]
    pub list: bool,
    /// Serve LLRP over TLS with this certificate chain (PEM), as readers do on port 5085.
    #[arg(long, requires = "tls_key")]
    pub tls_cert: Option<PathBuf>,
    /// The private key (PEM) of `--tls-cert`.
    #[arg(long, requires = "tls_cert")]
    pub tls_key: Option<PathBuf>,
    /// Write the replayed sessions to this MCAP file: frames both ways, tag reads, reader
    /// events (ROS 2 messages; docs/robotics.md). An existing file is refused.
    #[arg(long, value_name = "FILE")]
    pub mcap: Option<PathBuf>,
    /// Serve the same messages live to Foxglove on this address (its WebSocket protocol;
    /// docs/robotics.md "Live in Foxglove").
    #[arg(long, value_name = "ADDR")]
    pub foxglove: Option<String>,
    /// The live localizer and its HTTP API (`--http ADDR`), fed with what is replayed.
    #[command(flatten)]
    pub live: LiveArgs,
}

/// Why `replay` failed.
#[derive(Debug, thiserror::Error)]
pub enum ReplayCommandError {
    /// The MCAP file cannot be replayed (the message names the file and why).
    #[error("{0}")]
    McapIn(#[from] crate::record::mcap::read::BagError),
    /// The recording cannot be read.
    #[error("{}: {source}", path.display())]
    Recording {
        /// The recording.
        path: PathBuf,
        /// Why.
        source: RecordError,
    },
    /// The recording has nothing to replay, or not the connection asked for.
    #[error("{}: {source}", path.display())]
    Script {
        /// The recording.
        path: PathBuf,
        /// Why.
        source: ScriptError,
    },
    /// `--tls-cert`/`--tls-key` cannot be used.
    #[error("{0}")]
    Tls(TlsError),
    /// The async runtime could not be started.
    #[error("cannot start the async runtime: {0}")]
    Runtime(std::io::Error),
    /// The listening address cannot be bound.
    #[error("cannot listen on {addr}: {source}")]
    Listen {
        /// `--listen`.
        addr: String,
        /// Why.
        source: std::io::Error,
    },
    /// The localizer, its API or the publisher could not be started.
    #[error("{0}")]
    Sinks(#[from] SinksError),
    /// The Foxglove live view could not listen.
    #[error("{0}")]
    Live(#[from] crate::foxglove::LiveError),
    /// The MCAP file cannot be written (or was not written whole).
    #[error("{}: {source}", path.display())]
    McapOut {
        /// `--mcap`.
        path: PathBuf,
        /// Why.
        source: McapError,
    },
}

/// Runs `llrp-gateway replay` (or, with `--list`, prints the recording's connections).
pub fn run(args: ReplayArgs) -> Result<(), ReplayCommandError> {
    crate::stop::init_logging();
    let recording = open(&args.file)?;
    if args.list {
        print!("{}", list(&recording));
        return Ok(());
    }
    let script =
        Script::new(&recording, args.conn).map_err(|source| ReplayCommandError::Script {
            path: args.file.clone(),
            source,
        })?;
    let tls = acceptor(&args)?;
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(ReplayCommandError::Runtime)?;
    runtime.block_on(async {
        let live = match &args.foxglove {
            Some(addr) => Some(LiveServer::bind(addr).await?),
            None => None,
        };
        let tap = live.as_ref().map(LiveServer::tap);
        let mcap = McapThread::open(args.mcap.as_deref(), false, tap).map_err(|source| {
            ReplayCommandError::McapOut {
                path: args.mcap.clone().unwrap_or_default(),
                source,
            }
        })?;
        let served = serve(&args, &recording, Arc::new(script), tls, mcap).await;
        if let Some(live) = live {
            live.shutdown().await;
        }
        served
    })
}

/// A recorder that hands the replayed sessions to `mcap` (nothing kept otherwise), named as
/// `export` names the recording's reader; none without `--mcap` or `--foxglove`.
fn mcap_recorder(
    recording: &Recording,
    mcap: Option<&McapThread>,
) -> std::io::Result<Option<(Recorder, RecorderTask)>> {
    let Some(mcap) = mcap else {
        return Ok(None);
    };
    let upstream = &recording.header.upstream;
    let reader = upstream.strip_prefix("sim:").unwrap_or(upstream);
    let options = RecordOptions {
        max_bytes: None,
        mcap: Some(mcap.tee(reader)),
    };
    Recorder::start(Discard, Header::new(upstream.clone(), 0), options).map(Some)
}

/// Finishes the MCAP output once its recorder has handed on everything; what the file
/// holds, said.
async fn finish_mcap(
    args: &ReplayArgs,
    mcap: Option<(McapThread, RecorderTask)>,
) -> Result<(), ReplayCommandError> {
    let Some((mcap, task)) = mcap else {
        return Ok(());
    };
    let error = |source| ReplayCommandError::McapOut {
        path: args.mcap.clone().unwrap_or_default(),
        source,
    };
    if let Ok(Err(e)) = task.await {
        tracing::warn!(error = %e, "the replay's recorder failed");
    }
    let s = mcap.finish_async().await.map_err(error)?;
    let Some(path) = &args.mcap else {
        return Ok(());
    };
    eprintln!(
        "llrp-gateway replay: {} frames, {} tag reads, {} reader events: {} messages on {} channels in {}",
        s.frames, s.reads, s.events, s.messages, s.channels, path.display()
    );
    Ok(())
}

/// The recording at `path`, its warnings said on standard error.
fn open(path: &Path) -> Result<Recording, ReplayCommandError> {
    if crate::record::mcap::read::is_mcap(path) {
        return Ok(crate::record::mcap::recording_in::recording(path)?);
    }
    let recording = Recording::open(path).map_err(|source| ReplayCommandError::Recording {
        path: path.to_owned(),
        source,
    })?;
    for w in &recording.warnings {
        eprintln!("llrp-gateway replay: {}: warning: {w}", path.display());
    }
    Ok(recording)
}

/// The TLS server of `--tls-cert` and `--tls-key`, if given.
fn acceptor(args: &ReplayArgs) -> Result<Option<Acceptor>, ReplayCommandError> {
    match args.tls_cert.clone().zip(args.tls_key.clone()) {
        Some((cert, key)) => ServerFiles { cert, key }
            .acceptor()
            .map(Some)
            .map_err(ReplayCommandError::Tls),
        None => Ok(None),
    }
}

/// Listens, starts the localizer and publisher, and serves `script` until a stop signal.
async fn serve(
    args: &ReplayArgs,
    recording: &Recording,
    script: Arc<Script>,
    tls: Option<Acceptor>,
    mcap: Option<McapThread>,
) -> Result<(), ReplayCommandError> {
    let stop = StopSignal::watch();
    let recorder =
        mcap_recorder(recording, mcap.as_ref()).map_err(|e| ReplayCommandError::McapOut {
            path: args.mcap.clone().unwrap_or_default(),
            source: McapError::Mcap { error: e.into() },
        })?;
    let (recorder, recorder_task) = recorder.unzip();
    let listener = tokio::net::TcpListener::bind(&args.listen)
        .await
        .map_err(|source| ReplayCommandError::Listen {
            addr: args.listen.clone(),
            source,
        })?;
    match listener.local_addr() {
        Ok(addr) => eprintln!(
            "llrp-gateway replay: {} (connection {}: {} responses, {} reports and events) listening on {addr}",
            args.file.display(),
            script.conn(),
            script.responses(),
            script.unsolicited()
        ),
        Err(e) => eprintln!("llrp-gateway replay: {e}"),
    }
    let sinks = start_sinks(&args.live, "replay").await?;
    let name = recording
        .header
        .reader_name()
        .map_err(|source| ReplayCommandError::Recording {
            path: args.file.clone(),
            source,
        })?;
    let tap = sinks.tap().map(|t| (name, t));
    let shared = sinks.live().map(|l| l.shared.clone());
    crate::mcap_estimates::by_wall_clock(shared.as_deref(), mcap.as_ref());
    let options = ReplayOptions {
        speed: match args.speed {
            Speed::Max => None,
            Speed::Factor(x) => Some(x),
        },
        looped: args.looped,
    };
    let (tx, rx) = watch::channel(false);
    let task = tokio::spawn(crate::net::replay::serve_tapped(
        listener, script, options, tls, rx, tap, recorder,
    ));
    stop.wait().await;
    let _ = tx.send(true);
    let _ = task.await;
    crate::mcap_estimates::last_scene(shared.as_deref(), mcap.as_ref());
    finish_mcap(args, mcap.zip(recorder_task)).await?;
    sinks.stop().await;
    eprintln!("llrp-gateway replay: stopped");
    Ok(())
}

/// The table `replay --list` prints: a line per connection, the default one marked.
fn list(recording: &Recording) -> String {
    use std::fmt::Write as _;
    let default = Script::new(recording, None).ok().map(|s| s.conn());
    let mut out =
        String::from("conn  start_s  client_frames  reader_frames  reports  client / end\n");
    for s in recording.summaries() {
        let start = s.start.map_or(0.0, |t| t.t_us as f64 / 1e6);
        let mark = if Some(s.conn) == default {
            "  (replayed by default)"
        } else if !s.has_session() {
            "  (no LLRP session)"
        } else {
            ""
        };
        let _ = writeln!(
            out,
            "{:>4}  {start:>7.3}  {:>13}  {:>13}  {:>7}  {} / {}{mark}",
            s.conn,
            s.to_reader,
            s.from_reader,
            s.reports,
            s.client.as_deref().unwrap_or("-"),
            s.end.as_deref().unwrap_or("-"),
        );
    }
    out
}
