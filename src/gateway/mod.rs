//! The gateway's commands: `llrp-gateway proxy` (one or more transparent proxies in front of
//! real readers, each optionally recording its sessions) and `llrp-gateway replay` (a
//! recording served as a reader), each until Ctrl-C or SIGTERM.

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Duration;

use llrp::units::HopTable;
use serde::Deserialize;
use tokio::sync::watch;

use crate::net::proxy::{Proxy, ProxyConfig, Stats};
use crate::net::tls::{self, ServerFiles, Verify};
use crate::record::{Header, RecordOptions, Recorder};
use crate::stop::StopSignal;

pub mod live;
mod replay;

pub use replay::{run_replay, ReplayArgs};

/// Longest the proxy waits at a stop for its sessions to close.
const STOP_WAIT: Duration = Duration::from_secs(10);

pub use crate::net::LLRP_PORT;

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
    /// Start a numbered next recording file once a file would pass this many bytes.
    #[arg(long, value_name = "BYTES", value_parser = crate::options::parser::<u64>("record-max-bytes"))]
    pub record_max_bytes: Option<u64>,
    /// Regulatory region of the reader (`fcc` or `etsi`), for channel frequencies of tapped
    /// reads until the reader's capabilities are seen.
    #[arg(long)]
    pub region: Option<Region>,
    /// Most clients served at once (each with its own connection to the reader); one more
    /// gets a failed ConnectionAttemptEvent and is closed.
    #[arg(long, value_name = "N", default_value_t = crate::net::proxy::MAX_CLIENTS as u64, value_parser = crate::options::parser::<u64>("max-clients"))]
    pub max_clients: u64,
    /// Longest wait for the reader to accept the connection, in milliseconds.
    #[arg(long, default_value = "5000", value_parser = crate::options::parser::<u64>("connect-timeout-ms"))]
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
    pub live: live::LiveArgs,
}

/// A regulatory region's channel table.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Region {
    /// FCC Part 15, 50 channels (902.75..927.25 MHz).
    Fcc,
    /// ETSI EN 302 208, 4 channels (865.7..867.5 MHz).
    Etsi,
}

impl Region {
    /// The region's hop table.
    pub fn hop_table(self) -> HopTable {
        match self {
            Region::Fcc => HopTable::fcc(),
            Region::Etsi => HopTable::etsi(),
        }
    }
}

/// One proxy in a `--config` file.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProxyEntry {
    /// Name in logs and on tapped reads.
    pub name: String,
    /// The reader, `HOST[:PORT]`.
    pub upstream: String,
    /// Where clients connect.
    pub listen: String,
    /// Record to this file (relative to the config file's folder).
    #[serde(default)]
    pub record: Option<PathBuf>,
    /// The reader's region (`fcc`, `etsi`).
    #[serde(default)]
    pub region: Option<Region>,
    /// Clients connect with TLS: this certificate chain (PEM; relative to the config file's
    /// folder), with `tls_key`.
    #[serde(default)]
    pub tls_cert: Option<PathBuf>,
    /// The private key (PEM) of `tls_cert`.
    #[serde(default)]
    pub tls_key: Option<PathBuf>,
    /// Reach the reader with TLS, with `upstream_ca` or `upstream_insecure`.
    #[serde(default)]
    pub upstream_tls: bool,
    /// CA certificates (PEM) the reader's certificate must be issued by.
    #[serde(default)]
    pub upstream_ca: Option<PathBuf>,
    /// Accept any reader certificate.
    #[serde(default)]
    pub upstream_insecure: bool,
}

impl ProxyEntry {
    /// The TLS settings checked together: the field that is wrong, and why.
    fn check_tls(&self) -> Result<(), (&'static str, &'static str)> {
        match (&self.tls_cert, &self.tls_key) {
            (Some(_), None) => return Err(("tls_key", "tls_cert needs tls_key")),
            (None, Some(_)) => return Err(("tls_cert", "tls_key needs tls_cert")),
            _ => {}
        }
        match (self.upstream_tls, &self.upstream_ca, self.upstream_insecure) {
            (true, None, false) => Err((
                "upstream_tls",
                "needs upstream_ca (a PEM file) or upstream_insecure: true",
            )),
            (true, Some(_), true) => Err((
                "upstream_insecure",
                "upstream_ca and upstream_insecure exclude each other",
            )),
            (false, Some(_), _) => Err(("upstream_ca", "needs upstream_tls: true")),
            (false, None, true) => Err(("upstream_insecure", "needs upstream_tls: true")),
            _ => Ok(()),
        }
    }

    /// The server side of `tls_cert`/`tls_key`, if set.
    pub fn acceptor(&self) -> Result<Option<tls::Acceptor>, tls::TlsError> {
        match (&self.tls_cert, &self.tls_key) {
            (Some(cert), Some(key)) => ServerFiles {
                cert: cert.clone(),
                key: key.clone(),
            }
            .acceptor()
            .map(Some),
            _ => Ok(None),
        }
    }

    /// The client side of `upstream_tls`, if set (`upstream_insecure` logs a warning).
    pub fn connector(&self) -> Result<Option<tls::Connector>, tls::TlsError> {
        if !self.upstream_tls {
            return Ok(None);
        }
        let verify = match &self.upstream_ca {
            Some(ca) => Verify::Ca(ca.clone()),
            None => Verify::Insecure,
        };
        tls::Connector::new(&verify, None).map(Some)
    }
}

/// A `--config` file.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GatewayConfig {
    /// The proxies.
    pub proxies: Vec<ProxyEntry>,
}

/// A config file that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// It cannot be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A field is wrong.
    #[error("{path}: {field}: {message}")]
    Field {
        /// The file.
        path: PathBuf,
        /// JSON path of the field.
        field: String,
        /// What is wrong.
        message: String,
    },
}

impl GatewayConfig {
    /// Reads and checks a config file: names unique, listen addresses unique, at least one
    /// proxy; relative record paths are taken from the file's folder.
    pub fn load(path: &Path) -> Result<GatewayConfig, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Io {
            path: path.to_owned(),
            source,
        })?;
        let field = |field: String, message: String| ConfigError::Field {
            path: path.to_owned(),
            field,
            message,
        };
        let mut de = serde_json::Deserializer::from_str(&text);
        let mut config: GatewayConfig = serde_path_to_error::deserialize(&mut de)
            .map_err(|e| field(e.path().to_string(), e.inner().to_string()))?;
        if config.proxies.is_empty() {
            return Err(field("proxies".into(), "no proxy given".into()));
        }
        let (mut names, mut listens, mut records) =
            (HashSet::new(), HashSet::new(), HashSet::new());
        let dir = path.parent().unwrap_or(Path::new("."));
        for (i, p) in config.proxies.iter_mut().enumerate() {
            if !names.insert(p.name.clone()) {
                return Err(field(
                    format!("proxies[{i}].name"),
                    format!("'{}' is used twice", p.name),
                ));
            }
            // Port 0 (any free port) may be given to several.
            if !p.listen.ends_with(":0") && !listens.insert(p.listen.clone()) {
                return Err(field(
                    format!("proxies[{i}].listen"),
                    format!("{} is used twice", p.listen),
                ));
            }
            if let Some(r) = &p.record {
                if !records.insert(dir.join(r)) {
                    return Err(field(
                        format!("proxies[{i}].record"),
                        format!("{} is used twice", r.display()),
                    ));
                }
            }
            if p.upstream.trim().is_empty() {
                return Err(field(format!("proxies[{i}].upstream"), "empty".into()));
            }
            if let Err((name, message)) = p.check_tls() {
                return Err(field(format!("proxies[{i}].{name}"), message.into()));
            }
            for f in [
                &mut p.record,
                &mut p.tls_cert,
                &mut p.tls_key,
                &mut p.upstream_ca,
            ]
            .into_iter()
            .flatten()
            {
                if f.is_relative() {
                    *f = dir.join(&*f);
                }
            }
        }
        Ok(config)
    }
}

/// `HOST` → `HOST:5084`; `HOST:PORT` and `[v6]:PORT` unchanged.
pub fn with_default_port(addr: &str) -> String {
    with_port_or(addr, LLRP_PORT)
}

pub use crate::net::with_port_or;

/// Runs `llrp-gateway proxy`.
pub fn run(args: ProxyArgs) -> ExitCode {
    crate::stop::init_logging();
    let entries = match (&args.config, &args.upstream) {
        (Some(path), _) => match GatewayConfig::load(path) {
            Ok(c) => c.proxies,
            Err(e) => {
                eprintln!("llrp-gateway proxy: {e}");
                return ExitCode::FAILURE;
            }
        },
        (None, Some(upstream)) => vec![ProxyEntry {
            name: "reader".into(),
            upstream: upstream.clone(),
            listen: args.listen.clone(),
            record: args.record.clone(),
            region: args.region,
            tls_cert: args.tls_cert.clone(),
            tls_key: args.tls_key.clone(),
            upstream_tls: args.upstream_tls,
            upstream_ca: args.upstream_ca.clone(),
            upstream_insecure: args.upstream_insecure,
        }],
        (None, None) => {
            eprintln!("llrp-gateway proxy: give --upstream HOST[:PORT] or --config FILE");
            return ExitCode::FAILURE;
        }
    };
    if args.upstream_tls && args.upstream_ca.is_none() && !args.upstream_insecure {
        eprintln!(
            "llrp-gateway proxy: --upstream-tls needs --upstream-ca FILE (the CA, or the \
             reader's own self-signed certificate) or --upstream-insecure (accept any certificate)"
        );
        return ExitCode::FAILURE;
    }
    let runtime = match tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
    {
        Ok(r) => r,
        Err(e) => {
            eprintln!("llrp-gateway proxy: cannot start the async runtime: {e}");
            return ExitCode::FAILURE;
        }
    };
    let options = RecordOptions {
        max_bytes: args.record_max_bytes,
    };
    let timeout = Duration::from_millis(args.connect_timeout_ms);
    runtime.block_on(async move {
        let stop = StopSignal::watch();
        let sinks = match live::start_sinks(&args.live, "proxy").await {
            Ok(l) => l,
            Err(e) => {
                eprintln!("llrp-gateway proxy: {e}");
                return ExitCode::FAILURE;
            }
        };
        let (stop_tx, stop_rx) = watch::channel(false);
        let mut tasks = Vec::new();
        let mut writers = Vec::new();
        for e in entries {
            // LLRP over TLS is on port 5085 by convention.
            let port = if e.upstream_tls {
                tls::LLRP_TLS_PORT
            } else {
                LLRP_PORT
            };
            let upstream = with_port_or(&e.upstream, port);
            let recorder = match &e.record {
                Some(path) => {
                    match Recorder::create(path, Header::new(&upstream, 0), options.clone()) {
                        Ok((r, task)) => {
                            writers.push(task);
                            Some(r)
                        }
                        Err(err) => {
                            eprintln!(
                                "llrp-gateway proxy: {}: cannot create the recording: {err}",
                                path.display()
                            );
                            return ExitCode::FAILURE;
                        }
                    }
                }
                None => None,
            };
            let tls = match (e.acceptor(), e.connector()) {
                (Ok(a), Ok(c)) => (a, c),
                (Err(err), _) | (_, Err(err)) => {
                    eprintln!("llrp-gateway proxy: '{}': TLS: {err}", e.name);
                    return ExitCode::FAILURE;
                }
            };
            let upstream_shown = upstream.clone();
            let config = ProxyConfig {
                name: e.name.clone(),
                upstream,
                listen: e.listen.clone(),
                record: e.record.clone(),
                region: e.region.map(Region::hop_table),
                connect_timeout: timeout,
                tls: tls.0,
                upstream_tls: tls.1,
            };
            // A tap only for the localizer or the publisher: decoding every read for nobody
            // costs a third of the throughput.
            let tap = sinks.tap().map(|t| {
                let (tap, rx) = crate::net::proxy::Tap::new(4096);
                tokio::spawn(live::forward(rx, tap.links(), t, sinks.keepalive_losses()));
                tap
            });
            let proxy = match Proxy::bind(config, recorder, tap).await {
                Ok(p) => {
                    p.with_max_clients(usize::try_from(args.max_clients).unwrap_or(usize::MAX))
                }
                Err(err) => {
                    eprintln!(
                        "llrp-gateway proxy: {}: cannot listen on {}: {err}",
                        e.name, e.listen
                    );
                    return ExitCode::FAILURE;
                }
            };
            match proxy.local_addr() {
                Ok(addr) => eprintln!(
                    "llrp-gateway proxy: '{}' listening on {addr}{}, forwarding to {}{}{}",
                    e.name,
                    if e.tls_cert.is_some() { " (TLS)" } else { "" },
                    upstream_shown,
                    if e.upstream_tls { " (TLS)" } else { "" },
                    e.record
                        .as_ref()
                        .map(|p| format!(", recording to {}", p.display()))
                        .unwrap_or_default()
                ),
                Err(err) => eprintln!("llrp-gateway proxy: '{}': {err}", e.name),
            }
            tokio::spawn(log_stats(e.name.clone(), proxy.stats()));
            tasks.push(tokio::spawn(proxy.run(stop_rx.clone())));
        }
        stop.wait().await;
        eprintln!("llrp-gateway proxy: stopping: closing every session");
        let _ = stop_tx.send(true);
        // Each session takes at most a few seconds to close (CLOSE_CONNECTION, then the
        // reader's close); past STOP_WAIT the process exits all the same.
        let deadline = tokio::time::Instant::now() + STOP_WAIT;
        for t in tasks {
            if tokio::time::timeout_at(deadline, t).await.is_err() {
                eprintln!("llrp-gateway proxy: a session did not close within {STOP_WAIT:?}");
                break;
            }
        }
        // The recorders end once the sessions holding them are gone.
        let mut failed = false;
        for w in writers {
            let Ok(w) = tokio::time::timeout_at(deadline + Duration::from_secs(1), w).await else {
                eprintln!("llrp-gateway proxy: a recording was not finished in time");
                failed = true;
                continue;
            };
            match w {
                Ok(Ok(())) => {}
                Ok(Err(e)) => {
                    eprintln!("llrp-gateway proxy: writing the recording failed: {e}");
                    failed = true;
                }
                Err(e) => {
                    eprintln!("llrp-gateway proxy: the recording's writer failed: {e}");
                    failed = true;
                }
            }
        }
        sinks.stop().await;
        eprintln!("llrp-gateway proxy: stopped");
        if failed {
            ExitCode::FAILURE
        } else {
            ExitCode::SUCCESS
        }
    })
}

/// Logs, every 10 s while frames flow, how many the proxy `name` has forwarded.
async fn log_stats(name: String, stats: std::sync::Arc<Stats>) {
    use std::sync::atomic::Ordering::Relaxed;
    let mut last = 0u64;
    let mut tick = tokio::time::interval(Duration::from_secs(10));
    tick.tick().await;
    loop {
        tick.tick().await;
        let now = stats.frames_from_reader.load(Relaxed);
        if now != last {
            let bad = (
                stats.undecodable_to_reader.load(Relaxed),
                stats.undecodable_from_reader.load(Relaxed),
            );
            tracing::info!(
                proxy = %name,
                "{} sessions, {} frames to the reader, {now} from it ({}/s){}",
                stats.sessions.load(Relaxed),
                stats.frames_to_reader.load(Relaxed),
                (now - last) / 10,
                if bad == (0, 0) {
                    String::new()
                } else {
                    format!("; undecodable: {} to the reader, {} from it", bad.0, bad.1)
                }
            );
            last = now;
        }
    }
}

#[cfg(test)]
mod tests;
