//! The `--publish` options of `sim`, `proxy` and `replay`.

use std::collections::BTreeSet;
use std::sync::Arc;
use std::time::Duration;

use super::metrics::MqttMetrics;
use super::publish::{PublishOptions, Publisher};
use super::url::{BrokerAddress, BrokerUrl};
use crate::secret::Secret;

/// Publishing to an MQTT broker (docs/fleet.md; the command line's `--publish` options).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PublishConfig {
    /// Publish reads, poses, reader events and statuses to this MQTT broker:
    /// `mqtt://[USER[:PASS]@]HOST[:PORT][/PREFIX]` (shown without its password).
    pub publish: Option<BrokerAddress>,
    /// The broker's password given apart from the URL (`--mqtt-password`, its file or its
    /// environment variable), for a URL that names the user only.
    pub password: Option<Secret>,
    /// Read shards: a tag's reads go to `PREFIX/v1/reads/{FNV-1a(EPC) % N}`.
    pub shard_count: u16,
    /// Messages held while the broker is away; beyond it they are dropped and counted.
    pub publish_queue: usize,
    /// Batch each topic's reads over this window (ms); 0: a message per RO_ACCESS_REPORT.
    pub publish_window_ms: u64,
    /// This gateway's name on the broker (its status topic and MQTT client id).
    pub gateway_name: String,
    /// For `mqtts://`: the CA certificate (PEM) that signed the broker's.
    pub mqtt_ca: Option<std::path::PathBuf>,
}

/// The TLS settings of `--mqtt-ca FILE`.
pub fn tls_config(
    ca: Option<&std::path::Path>,
) -> Result<Option<Arc<tokio_rustls::rustls::ClientConfig>>, String> {
    ca.map(|p| {
        crate::net::tls::client_config(&crate::net::tls::Verify::Ca(p.to_owned()))
            .map_err(|e| format!("--mqtt-ca {}: {e}", p.display()))
    })
    .transpose()
}

impl PublishConfig {
    /// The broker address as shown: its password hidden.
    pub fn shown(&self) -> String {
        self.publish
            .as_ref()
            .and_then(|u| BrokerUrl::parse(u.as_str()).ok())
            .map(|u| u.clone().with_password(self.password.clone()).unwrap_or(u))
            .map(|u| u.to_string())
            .unwrap_or_default()
    }

    /// Starts the publisher when `--publish` was given, counting in `metrics`; `references`
    /// are the reference tags' EPCs.
    pub fn start(
        &self,
        metrics: MqttMetrics,
        references: BTreeSet<String>,
    ) -> Result<Option<Publisher>, String> {
        let Some(url) = &self.publish else {
            return Ok(None);
        };
        let url = BrokerUrl::parse(url.as_str())
            .and_then(|u| u.with_password(self.password.clone()))
            .map_err(|e| format!("--publish {e}"))?;
        let mut opts = PublishOptions::new(url, &self.gateway_name);
        opts.shard_count = self.shard_count;
        opts.queue = self.publish_queue;
        opts.window = Duration::from_millis(self.publish_window_ms);
        opts.references = references;
        opts.tls = tls_config(self.mqtt_ca.as_deref())?;
        Publisher::start(opts, metrics)
            .map(Some)
            .map_err(|e| format!("--publish: {e}"))
    }
}
