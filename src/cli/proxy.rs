//! `llrp-gateway proxy`: one or more transparent proxies in front of real readers (from the
//! options, or from a `--config` file), each optionally recording its sessions, with the
//! localizer and publisher of [`super::live`] fed with the tapped reads, until Ctrl-C or
//! SIGTERM. The proxy itself is [`crate::net::proxy`], its config file [`crate::gateway`].

use crate::reads::ReaderName;
use std::path::PathBuf;
use std::time::Duration;

use tokio::sync::watch;
use tokio::task::JoinHandle;

use super::live::{start_sinks, LiveArgs, SinksError};
use super::root::Consumers;
use crate::foxglove::LiveServer;
use crate::gateway::{live, log_stats, ConfigError, GatewayConfig, ProxyEntry, Region};
use crate::net::proxy::{Proxy, ProxyConfig};
use crate::net::tls::{self, TlsError};
use crate::net::{with_port_or, LLRP_PORT};
use crate::record::mcap::{McapError, McapTee, McapThread};
use crate::record::{Discard, Header, RecordOptions, Recorder, RecorderTask};
use crate::stop::StopSignal;

/// Longest the proxy waits at a stop for its sessions to close.
const STOP_WAIT: Duration = Duration::from_secs(10);

/// Arguments of `llrp-gateway proxy`.
#[derive(clap::Args, Debug)]
pub struct ProxyArgs {
    /// The reader, `HOST[:PORT]` (port 5084 if none).
    #[arg(long, required_unless_present = "config", conflicts_with = "config")]
    pub upstream: Option<String>,
    /// Where clients connect.
    #[arg(long, default_value = "0.0.0.0:5084")]
    pub listen: String,
    /// Record every session to this file (JSON Lines, docs/recordings.md).
    #[arg(long)]
    pub record: Option<PathBuf>,
    /// Write every proxy's sessions to this MCAP file too: frames, tag reads, reader events
    /// (ROS 2 messages; docs/robotics.md). An existing file is refused.
    #[arg(long, value_name = "FILE")]
    pub mcap: Option<PathBuf>,
    /// Serve the same messages live to Foxglove on this address (its WebSocket protocol;
    /// docs/robotics.md "Live in Foxglove").
    #[arg(long, value_name = "ADDR")]
    pub foxglove: Option<String>,
    /// Start a numbered next recording file once a file would pass this many bytes.
    #[arg(long, value_name = "BYTES", value_parser = crate::cli::options::parser::<u64>("record-max-bytes"))]
    pub record_max_bytes: Option<u64>,
    /// Regulatory region of the reader (`fcc` or `etsi`), for channel frequencies of tapped
    /// reads until the reader's capabilities are seen.
    #[arg(long)]
    pub region: Option<super::args::RegionArg>,
    /// Most clients served at once (each with its own connection to the reader); one more
    /// gets a failed ConnectionAttemptEvent and is closed.
    #[arg(long, value_name = "N", default_value_t = crate::net::proxy::MAX_CLIENTS as u64, value_parser = crate::cli::options::parser::<u64>("max-clients"))]
    pub max_clients: u64,
    /// Longest wait for the reader to accept the connection, in milliseconds.
    #[arg(long, default_value = "5000", value_parser = crate::cli::options::parser::<u64>("connect-timeout-ms"))]
    pub connect_timeout_ms: u64,
    /// Clients connect with TLS: this certificate chain (PEM); see docs/tls.md.
    #[arg(
        long,
        value_name = "FILE",
        requires = "tls_key",
        conflicts_with = "config"
    )]
    pub tls_cert: Option<PathBuf>,
    /// The private key (PEM) of --tls-cert.
    #[arg(
        long,
        value_name = "FILE",
        requires = "tls_cert",
        conflicts_with = "config"
    )]
    pub tls_key: Option<PathBuf>,
    /// Reach the reader with TLS (LLRP over TLS, port 5085 on readers that offer it), with
    /// --upstream-ca or --upstream-insecure.
    #[arg(long, conflicts_with = "config")]
    pub upstream_tls: bool,
    /// With --upstream-tls: CA certificates (PEM) the reader's certificate must be issued by.
    #[arg(
        long,
        value_name = "FILE",
        requires = "upstream_tls",
        conflicts_with = "upstream_insecure"
    )]
    pub upstream_ca: Option<PathBuf>,
    /// With --upstream-tls: accept any reader certificate (encrypted, not authenticated).
    #[arg(long, requires = "upstream_tls")]
    pub upstream_insecure: bool,
    /// Several proxies from a JSON file: `{"proxies": [{"name", "upstream", "listen",
    /// "record", "region", "tls_cert", "tls_key", "upstream_tls", "upstream_ca",
    /// "upstream_insecure"}]}`.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// The live localizer and its HTTP API (`--http ADDR`).
    #[command(flatten)]
    pub live: LiveArgs,
}

/// Why `proxy` failed.
#[derive(Debug, thiserror::Error)]
pub enum ProxyCommandError {
    /// The `--config` file cannot be read or a field of it is wrong (the message names the
    /// file and the field).
    #[error("{0}")]
    Config(#[from] ConfigError),
    /// Neither `--upstream` nor `--config`.
    #[error("give --upstream HOST[:PORT] or --config FILE")]
    NoUpstream,
    /// `--upstream-tls` without saying which certificates to trust.
    #[error(
        "--upstream-tls needs --upstream-ca FILE (the CA, or the reader's own self-signed \
         certificate) or --upstream-insecure (accept any certificate)"
    )]
    UpstreamTrust,
    /// The async runtime could not be started.
    #[error("cannot start the async runtime: {0}")]
    Runtime(std::io::Error),
    /// The localizer, its API or the publisher could not be started.
    #[error("{0}")]
    Sinks(#[from] SinksError),
    /// A proxy's recording cannot be created.
    #[error("{}: cannot create the recording: {source}", path.display())]
    Recording {
        /// The recording.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A proxy's TLS settings cannot be used.
    #[error("'{name}': TLS: {source}")]
    Tls {
        /// The proxy.
        name: ReaderName,
        /// Why.
        source: Box<TlsError>,
    },
    /// A proxy's listening address cannot be bound.
    #[error("{name}: cannot listen on {listen}: {source}")]
    Listen {
        /// The proxy.
        name: ReaderName,
        /// Its listening address.
        listen: String,
        /// Why.
        source: std::io::Error,
    },
    /// The MCAP file cannot be created.
    #[error("cannot write the MCAP file: {0}")]
    Mcap(McapError),
    /// The Foxglove live view could not listen.
    #[error("{0}")]
    Live(#[from] crate::foxglove::LiveError),
    /// At the stop, recordings were not written whole (each failure, `; ` between them).
    #[error("{}", joined(.0))]
    Recordings(Vec<RecordingFailure>),
}

/// Why a recording was not written whole at the stop.
#[derive(Debug, thiserror::Error)]
pub enum RecordingFailure {
    /// Its writer had not finished a second after the sessions' deadline.
    #[error("a recording was not finished in time")]
    Late,
    /// Writing it failed.
    #[error("writing the recording failed: {0}")]
    Write(std::io::Error),
    /// Its writer's task failed.
    #[error("the recording's writer failed: {0}")]
    Writer(tokio::task::JoinError),
    /// The MCAP file was not written whole.
    #[error("the MCAP file: {0}")]
    Mcap(McapError),
}

/// The failures, `; ` between them.
fn joined(failures: &[RecordingFailure]) -> String {
    let all: Vec<String> = failures.iter().map(ToString::to_string).collect();
    all.join("; ")
}

/// Runs `llrp-gateway proxy` until Ctrl-C or SIGTERM.
pub fn run(args: ProxyArgs) -> Result<(), ProxyCommandError> {
    crate::stop::init_logging();
    let entries = entries(&args)?;
    if args.upstream_tls && args.upstream_ca.is_none() && !args.upstream_insecure {
        return Err(ProxyCommandError::UpstreamTrust);
    }
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(ProxyCommandError::Runtime)?;
    runtime.block_on(serve(args, entries))
}

/// The proxies to run: the `--config` file's, or the one of the options.
fn entries(args: &ProxyArgs) -> Result<Vec<ProxyEntry>, ProxyCommandError> {
    match (&args.config, &args.upstream) {
        (Some(path), _) => Ok(GatewayConfig::load(path)?.proxies),
        (None, Some(upstream)) => Ok(vec![ProxyEntry {
            // "reader" keeps the rule (not empty, no white space or control character).
            name: "reader".parse().expect("a reader name"),
            upstream: upstream.clone(),
            listen: args.listen.clone(),
            record: args.record.clone(),
            region: args.region.map(Region::from),
            tls_cert: args.tls_cert.clone(),
            tls_key: args.tls_key.clone(),
            upstream_tls: args.upstream_tls,
            upstream_ca: args.upstream_ca.clone(),
            upstream_insecure: args.upstream_insecure,
        }]),
        (None, None) => Err(ProxyCommandError::NoUpstream),
    }
}

/// The running proxies' tasks and their recordings' writers.
#[derive(Default)]
struct Running {
    tasks: Vec<JoinHandle<std::io::Result<()>>>,
    writers: Vec<RecorderTask>,
    /// The `--mcap` file's (or `--foxglove` live view's) writer, which every recorder hands
    /// its entries to, and the file's path.
    mcap: Option<(Option<PathBuf>, McapThread)>,
}

/// Starts the localizer and publisher and every proxy, and runs them until a stop signal.
async fn serve(args: ProxyArgs, entries: Vec<ProxyEntry>) -> Result<(), ProxyCommandError> {
    let stop = StopSignal::watch();
    let sinks = start_sinks(&args.live, "proxy").await?;
    let (stop_tx, stop_rx) = watch::channel(false);
    let mut running = Running::default();
    let live = match &args.foxglove {
        Some(addr) => Some(LiveServer::bind(addr).await?),
        None => None,
    };
    let tap = live.as_ref().map(LiveServer::tap);
    let mcap =
        McapThread::open(args.mcap.as_deref(), false, tap).map_err(ProxyCommandError::Mcap)?;
    let shared = sinks.live().map(|l| l.shared.clone());
    crate::mcap_estimates::by_wall_clock(shared.as_deref(), mcap.as_ref());
    running.mcap = mcap.map(|m| (args.mcap.clone(), m));
    for e in entries {
        start(&args, e, &sinks, &stop_rx, &mut running).await?;
    }
    stop.wait().await;
    eprintln!("llrp-gateway proxy: stopping: closing every session");
    let _ = stop_tx.send(true);
    let mcap = running.mcap.as_ref().map(|(_, m)| m);
    crate::mcap_estimates::last_scene(shared.as_deref(), mcap);
    let failures = running.finish().await;
    if let Some(live) = live {
        live.shutdown().await;
    }
    sinks.stop().await;
    eprintln!("llrp-gateway proxy: stopped");
    if failures.is_empty() {
        Ok(())
    } else {
        Err(ProxyCommandError::Recordings(failures))
    }
}

/// Starts the proxy `e`: its recording, its TLS, its tap into `sinks`, its listener.
async fn start(
    args: &ProxyArgs,
    e: ProxyEntry,
    sinks: &Consumers,
    stop: &watch::Receiver<bool>,
    running: &mut Running,
) -> Result<(), ProxyCommandError> {
    // LLRP over TLS is on port 5085 by convention.
    let port = if e.upstream_tls {
        tls::LLRP_TLS_PORT
    } else {
        LLRP_PORT
    };
    let upstream = with_port_or(&e.upstream, port);
    let tee = running.mcap.as_ref().map(|(_, m)| m.tee(&upstream));
    let recorder = recorder(args, &e, &upstream, tee, &mut running.writers)?;
    let (acceptor, connector) = match (e.acceptor(), e.connector()) {
        (Ok(a), Ok(c)) => (a, c),
        (Err(source), _) | (_, Err(source)) => {
            return Err(ProxyCommandError::Tls {
                name: e.name.clone(),
                source: Box::new(source),
            })
        }
    };
    let config = ProxyConfig {
        name: e.name.clone(),
        upstream: upstream.clone(),
        listen: e.listen.clone(),
        record: e.record.clone(),
        region: e.region.map(Region::hop_table),
        connect_timeout: Duration::from_millis(args.connect_timeout_ms),
        tls: acceptor,
        upstream_tls: connector,
    };
    // A tap only for the localizer or the publisher: decoding every read for nobody costs a
    // third of the throughput.
    let tap = sinks.tap().map(|t| {
        let (tap, rx) = crate::net::proxy::Tap::new(4096);
        tokio::spawn(live::forward(rx, tap.links(), t, sinks.keepalive_losses()));
        tap
    });
    let proxy = Proxy::bind(config, recorder, tap)
        .await
        .map_err(|source| ProxyCommandError::Listen {
            name: e.name.clone(),
            listen: e.listen.clone(),
            source,
        })?
        .with_max_clients(usize::try_from(args.max_clients).unwrap_or(usize::MAX));
    match proxy.local_addr() {
        Ok(addr) => eprintln!(
            "llrp-gateway proxy: '{}' listening on {addr}{}, forwarding to {upstream}{}{}",
            e.name,
            if e.tls_cert.is_some() { " (TLS)" } else { "" },
            if e.upstream_tls { " (TLS)" } else { "" },
            e.record
                .as_ref()
                .map(|p| format!(", recording to {}", p.display()))
                .unwrap_or_default()
        ),
        Err(err) => eprintln!("llrp-gateway proxy: '{}': {err}", e.name),
    }
    tokio::spawn(log_stats(e.name.clone(), proxy.stats()));
    running.tasks.push(tokio::spawn(proxy.run(stop.clone())));
    Ok(())
}

/// The recorder of the proxy `e` to `upstream`, if it records (to a file, or only to the
/// MCAP file through `mcap`); its writer goes to `writers`.
fn recorder(
    args: &ProxyArgs,
    e: &ProxyEntry,
    upstream: &str,
    mcap: Option<McapTee>,
    writers: &mut Vec<RecorderTask>,
) -> Result<Option<Recorder>, ProxyCommandError> {
    let options = RecordOptions {
        max_bytes: args.record_max_bytes,
        mcap,
    };
    let header = Header::new(upstream, 0);
    let (recorder, task) = match &e.record {
        Some(path) => Recorder::create(path, header, options).map_err(|source| {
            ProxyCommandError::Recording {
                path: path.clone(),
                source,
            }
        })?,
        None if options.mcap.is_some() => Recorder::start(Discard, header, options)
            .map_err(|e| ProxyCommandError::Mcap(McapError::Mcap { error: e.into() }))?,
        None => return Ok(None),
    };
    writers.push(task);
    Ok(Some(recorder))
}

impl Running {
    /// Waits for the sessions to close (at most [`STOP_WAIT`]), then for the recordings to be
    /// written out; what went wrong with them.
    async fn finish(self) -> Vec<RecordingFailure> {
        // Each session takes at most a few seconds to close (CLOSE_CONNECTION, then the
        // reader's close); past STOP_WAIT the process exits all the same.
        let deadline = tokio::time::Instant::now() + STOP_WAIT;
        for t in self.tasks {
            if tokio::time::timeout_at(deadline, t).await.is_err() {
                eprintln!("llrp-gateway proxy: a session did not close within {STOP_WAIT:?}");
                break;
            }
        }
        // The recorders end once the sessions holding them are gone.
        let mut failures = Vec::new();
        for w in self.writers {
            match tokio::time::timeout_at(deadline + Duration::from_secs(1), w).await {
                Err(_) => failures.push(RecordingFailure::Late),
                Ok(Ok(Ok(()))) => {}
                Ok(Ok(Err(e))) => failures.push(RecordingFailure::Write(e)),
                Ok(Err(e)) => failures.push(RecordingFailure::Writer(e)),
            }
        }
        // The MCAP file ends once every recorder has handed on its last entries.
        if let Some((path, mcap)) = self.mcap {
            let end = deadline + Duration::from_secs(2);
            let finished = tokio::time::timeout_at(end, mcap.finish_async()).await;
            match (finished.unwrap_or(Err(McapError::ThreadGone)), path) {
                (Ok(s), Some(path)) => eprintln!(
                    "llrp-gateway proxy: {} frames, {} tag reads, {} reader events: {} messages on {} channels in {}",
                    s.frames, s.reads, s.events, s.messages, s.channels, path.display()
                ),
                (Ok(_), None) => {}
                (Err(e), _) => failures.push(RecordingFailure::Mcap(e)),
            }
        }
        failures
    }
}
