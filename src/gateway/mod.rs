//! The gateway's parts below its commands (`llrp-gateway proxy` and `replay`, whose arguments
//! and runners are `cli::proxy` and `cli::replay`): the proxies of a `--config` file
//! ([`GatewayConfig`], [`ProxyEntry`]), the regions' channel tables ([`Region`]), the proxy's
//! statistics in the log ([`log_stats`]), and the live localizer's feed from a proxy
//! ([`live`]).

use crate::reads::ReaderName;
use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::time::Duration;

use llrp::units::HopTable;
use serde::Deserialize;

use crate::net::proxy::Stats;
use crate::net::tls::{self, ServerFiles, Verify};

pub mod live;

pub use crate::net::LLRP_PORT;

/// A regulatory region's channel table.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
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
    /// Name in logs and on tapped reads (the rule of [`ReaderName`]).
    pub name: ReaderName,
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

/// Logs, every 10 s while frames flow, how many the proxy `name` has forwarded.
pub async fn log_stats(name: ReaderName, stats: std::sync::Arc<Stats>) {
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
