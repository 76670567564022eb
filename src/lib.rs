//! llrp-gateway: a simulated LLRP reader backed by a physics model of a scenario, and an LLRP
//! client and frame decoder. The LLRP codec lives in the `llrp` crate (`protocol/`).

pub mod alloc;
pub mod cli;
pub mod decode;
pub mod eval;
pub mod files;
pub mod fleet;
pub mod foxglove;
pub mod gateway;
pub mod http;
pub mod inventory;
pub mod mcap_estimates;
pub mod metrics;
pub mod net;
pub mod realism;
pub mod record;
pub mod secret;
pub mod sim;
pub mod stop;

pub use llrp_gateway_localize as localize;
pub use llrp_gateway_sim::{physics, reader, scenario};
pub use llrp_gateway_vocab::{reads, utc};
