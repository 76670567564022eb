//! Sockets: one framed [`connection::Connection`] for every LLRP socket (plain TCP or TLS,
//! [`stream::Stream`], [`tls`]), the simulated reader's server, an LLRP client, the proxy, and
//! the simulated clock.

pub mod client;
pub mod clock;
pub mod connection;
pub mod proxy;
pub mod replay;
pub mod server;
pub mod stream;
pub mod tls;
