//! Sockets: one framed [`connection::Connection`] for every LLRP socket (plain TCP or TLS,
//! [`stream::Stream`], [`tls`]), what every server shares ([`serve`]: the accept loop with its
//! connection limit, back-off and shutdown; [`drive`]: the loop that serves any sans-IO
//! session), the simulated reader's server, the replay, an LLRP client, the proxy, the
//! simulated clock, and the one back-off with jitter everything that retries uses ([`backoff`]).

pub mod backoff;
pub mod client;
pub mod clock;
pub mod connection;
pub mod drive;
pub mod proxy;
pub mod replay;
pub mod report_buffer;
pub mod serve;
pub mod server;
pub mod stream;
pub mod tls;

/// LLRP's TCP port (IANA).
pub const LLRP_PORT: u16 = 5084;

/// `HOST` → `HOST:PORT` with the given `port` (a bare IPv6 address in brackets);
/// `HOST:PORT` and `[v6]:PORT` unchanged.
pub fn with_port_or(addr: &str, port: u16) -> String {
    let has_port = match addr.rsplit_once(':') {
        Some((host, p)) => p.parse::<u16>().is_ok() && (!host.contains(':') || host.ends_with(']')),
        None => false,
    };
    if has_port {
        addr.to_string()
    } else if addr.contains(':') && !addr.starts_with('[') {
        format!("[{addr}]:{port}")
    } else {
        format!("{addr}:{port}")
    }
}
