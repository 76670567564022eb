//! The process's metrics: each subsystem keeps its own (the localizer's
//! `localize::shared::Metrics`, the MQTT publisher's or worker's
//! [`crate::fleet::metrics::MqttMetrics`], the LLRP links' [`LinkMetrics`]), and the command
//! registers those it runs in one [`Metrics`], which `GET /metrics` serves in the format the
//! client asks for ([`exposition`]).

pub mod exposition;

use std::sync::{Arc, Mutex};

use prometheus_client::metrics::counter::Counter;
use prometheus_client::registry::Registry;

/// Every metric name starts with this (`llrp_gateway_reads_total`, …).
pub const PREFIX: &str = "llrp_gateway";

/// One registry for the process.
pub struct Metrics(Mutex<Registry>);

impl std::fmt::Debug for Metrics {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Metrics(..)")
    }
}

impl Metrics {
    /// An empty registry.
    pub fn new() -> Arc<Metrics> {
        Arc::new(Metrics(Mutex::new(Registry::with_prefix(PREFIX))))
    }

    /// A registry holding the localizer's metrics alone (an API over a localizer and nothing
    /// else).
    pub fn of_localizer(shared: &crate::localize::shared::Shared) -> Arc<Metrics> {
        let m = Metrics::new();
        m.register(|r| shared.metrics.register(r));
        m
    }

    /// Registers a subsystem's metrics: `add` is given the registry.
    pub fn register(&self, add: impl FnOnce(&mut Registry)) {
        // A panic while registering leaves the registry as it was: still worth serving.
        add(&mut self.0.lock().unwrap_or_else(|e| e.into_inner()));
    }

    /// Everything registered, in the OpenMetrics text format (prometheus-client's).
    pub fn render(&self) -> String {
        let mut out = String::new();
        let registry = self.0.lock().unwrap_or_else(|e| e.into_inner());
        // Writing into a String cannot fail.
        let _ = prometheus_client::encoding::text::encode(&mut out, &registry);
        out
    }

    /// Everything registered, in `format`.
    pub fn render_as(&self, format: exposition::Format) -> String {
        match format {
            exposition::Format::OpenMetrics => self.render(),
            exposition::Format::Classic => exposition::classic(&self.render()),
        }
    }
}

/// Counters of the LLRP links the simulated readers and the proxy keep.
#[derive(Clone, Debug, Default)]
pub struct LinkMetrics {
    /// LLRP frames clients sent to the simulated readers.
    pub frames_in: Counter,
    /// Proxied readers' keepalive links taken for lost (no KEEPALIVE for three periods).
    pub keepalive_losses: Counter,
}

impl LinkMetrics {
    /// Registers the counters in `registry`.
    pub fn register(&self, registry: &mut Registry) {
        registry.register(
            "frames_in",
            "LLRP frames clients sent to the readers",
            self.frames_in.clone(),
        );
        registry.register(
            "keepalive_losses",
            "Proxied readers' keepalive links taken for lost",
            self.keepalive_losses.clone(),
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn what_each_subsystem_registers_is_served_once_under_the_prefix() {
        let shared = crate::localize::shared::Shared::new();
        let links = LinkMetrics::default();
        let mqtt = crate::fleet::metrics::MqttMetrics::default();
        let m = Metrics::of_localizer(&shared);
        m.register(|r| links.register(r));
        m.register(|r| mqtt.register(r));
        links.frames_in.inc_by(3);
        mqtt.gaps.inc();
        shared.metrics.reads.inc_by(7);
        let text = m.render();
        for line in [
            "llrp_gateway_frames_in_total 3",
            "llrp_gateway_mqtt_gaps_total 1",
            "llrp_gateway_reads_total 7",
            "llrp_gateway_keepalive_losses_total 0",
        ] {
            assert_eq!(
                text.lines().filter(|l| *l == line).count(),
                1,
                "{line}\n{text}"
            );
        }
    }
}
