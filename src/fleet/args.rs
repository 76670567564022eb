//! The `--publish` options of `sim`, `proxy` and `replay`.

use std::collections::BTreeSet;
use std::sync::Arc;
use std::time::Duration;

use super::metrics::MqttMetrics;
use super::publish::{PublishOptions, Publisher};
use super::schema::DEFAULT_SHARDS;
use super::url::BrokerUrl;

/// Publishing to an MQTT broker (docs/fleet.md).
#[derive(Clone, Debug, Default, PartialEq, clap::Args)]
pub struct PublishArgs {
    /// Publish reads, poses, reader events and statuses to this MQTT broker:
    /// `mqtt://[USER:PASS@]HOST[:PORT][/PREFIX]`.
    #[arg(long, value_name = "URL")]
    pub publish: Option<String>,
    /// Read shards: a tag's reads go to `PREFIX/v1/reads/{FNV-1a(EPC) % N}`.
    #[arg(long, value_name = "N", default_value_t = DEFAULT_SHARDS, value_parser = crate::options::parser::<u16>("shard-count"))]
    pub shard_count: u16,
    /// Messages held while the broker is away; beyond it they are dropped and counted.
    #[arg(long, value_name = "N", default_value_t = 10_000, value_parser = crate::options::parser::<usize>("publish-queue"))]
    pub publish_queue: usize,
    /// Batch each topic's reads over this window (ms); 0: a message per RO_ACCESS_REPORT.
    #[arg(long, value_name = "MS", default_value_t = 0, value_parser = crate::options::parser::<u64>("publish-window-ms"))]
    pub publish_window_ms: u64,
    /// This gateway's name on the broker (its status topic and MQTT client id).
    #[arg(long, value_name = "NAME", default_value = "llrp-gateway")]
    pub gateway_name: String,
    /// For `mqtts://`: the CA certificate (PEM) that signed the broker's.
    #[arg(long, value_name = "FILE")]
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

impl PublishArgs {
    /// The broker address as shown: its password hidden.
    pub fn shown(&self) -> String {
        self.publish
            .as_deref()
            .and_then(|u| BrokerUrl::parse(u).ok())
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
        let url = BrokerUrl::parse(url).map_err(|e| format!("--publish {e}"))?;
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
