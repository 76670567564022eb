//! The fleet through NATS JetStream's MQTT interface (MQTT 3.1.1; nats-server started here on
//! a free loopback port). A test binary of its own, so it runs alone: under the load of
//! other tests in parallel, NATS redelivered a few batches out of order, and a tag's reads
//! filed out of order no longer agree to 1e-6 m between workers (docs/fleet.md).

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
