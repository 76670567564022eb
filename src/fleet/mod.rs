//! Fleet scale over MQTT (docs/fleet.md): readers and gateways publish reads, poses, events
//! and statuses to a broker ([`publish`]); localizer workers subscribe to the read shards
//! they own and publish estimates ([`worker`]). The messages are in [`schema`], broker
//! addresses in [`url`].

pub mod args;
mod builder;
mod json;
pub mod metrics;
pub mod presence;
pub mod publish;
pub mod schema;
pub mod seq;
pub mod url;
pub mod worker;
