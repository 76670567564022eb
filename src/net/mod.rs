//! Sockets: the simulated reader's LLRP server, an LLRP client, and the simulated clock.

pub mod client;
pub mod clock;
pub mod server;
