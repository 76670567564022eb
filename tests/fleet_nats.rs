//! The fleet through NATS JetStream's MQTT interface (MQTT 3.1.1; nats-server started here on
//! a free loopback port, `ack_wait` 1 s). A test binary of its own, so it runs alone: beside
//! the mosquitto tests NATS held back about a thousand batches in 16,000 for its redelivery,
//! and workers under that load drifted apart (docs/fleet.md).

mod broker_support;
mod http_support;

use broker_support::agree::two_workers_agree;
use broker_support::Nats;

#[test]
#[ignore = "needs nats-server (./scripts/install-brokers); ./scripts/test runs it"]
fn the_same_through_nats_jetstream_mqtt() {
    let broker = Nats::start();
    two_workers_agree(&broker.url("site"), broker.port);
}
