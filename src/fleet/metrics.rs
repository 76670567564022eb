//! The MQTT publisher's and workers' counters, which the command registers beside the other
//! subsystems' ([`crate::metrics::Metrics`]).

use prometheus_client::metrics::counter::Counter;
use prometheus_client::registry::Registry;

/// Counters of MQTT publishing and receiving (`/metrics`' `mqtt_*`).
#[derive(Clone, Debug, Default)]
pub struct MqttMetrics {
    /// Messages handed to the broker connection.
    pub published: Counter,
    /// Reads, poses and messages the publisher dropped (its tap or its queue full).
    pub dropped: Counter,
    /// Messages the publisher dropped (its queue full, or lost with a broker session): each
    /// leaves a gap in its topic's sequence numbers.
    pub dropped_messages: Counter,
    /// Messages a worker took in.
    pub received: Counter,
    /// Messages skipped: not JSON of the schema, or on a topic not ours.
    pub malformed: Counter,
    /// Messages missing by sequence number, as a worker counts them.
    pub gaps: Counter,
    /// Messages received again (QoS 1 redelivery), as a worker counts them.
    pub duplicates: Counter,
    /// Read batches a worker held because they came ahead of a missing one.
    pub reordered: Counter,
    /// Read batches a worker filed behind later ones (they came after their gap was skipped).
    pub filed_late: Counter,
    /// Connections to the broker lost.
    pub disconnects: Counter,
}

impl MqttMetrics {
    /// Registers the counters in `registry` (as `mqtt_published`, …).
    pub fn register(&self, registry: &mut Registry) {
        let counters = [
            (
                "mqtt_published",
                "MQTT messages handed to the broker connection",
                &self.published,
            ),
            (
                "mqtt_dropped",
                "Reads, poses and messages the MQTT publisher dropped",
                &self.dropped,
            ),
            (
                "mqtt_dropped_messages",
                "MQTT messages the publisher dropped",
                &self.dropped_messages,
            ),
            ("mqtt_received", "MQTT messages taken in", &self.received),
            (
                "mqtt_malformed",
                "MQTT messages skipped as malformed or foreign",
                &self.malformed,
            ),
            (
                "mqtt_gaps",
                "MQTT messages missing by sequence number",
                &self.gaps,
            ),
            (
                "mqtt_duplicates",
                "MQTT messages received again",
                &self.duplicates,
            ),
            (
                "mqtt_reordered",
                "MQTT read batches held for an earlier missing one",
                &self.reordered,
            ),
            (
                "mqtt_filed_late",
                "MQTT read batches filed behind later ones",
                &self.filed_late,
            ),
            (
                "mqtt_disconnects",
                "Connections to the MQTT broker lost",
                &self.disconnects,
            ),
        ];
        // (The counters are handles: the clones registered count with the fields.)
        for (name, help, counter) in counters {
            registry.register(name, help, counter.clone());
        }
    }
}
