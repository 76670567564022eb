//! Sockets: one framed [`connection::Connection`] for every LLRP socket, the simulated
//! reader's server, an LLRP client, and the simulated clock.

pub mod client;
pub mod clock;
pub mod connection;
pub mod proxy;
pub mod replay;
pub mod server;
