//! What an inventory is asked to do ([`InventoryOptions`], built by `cli::inventory` from the
//! command line), where its reads go ([`Output`]), how often it reconnects ([`Retries`]), and
//! the reader address with its default port ([`reader_address`]).

use crate::reads::ReaderName;
use std::path::PathBuf;

use crate::net::client::InventorySpec;
use crate::net::tls::Connector;

pub use crate::net::LLRP_PORT;

/// An inventory's settings.
pub struct InventoryOptions {
    /// The reader: HOST or HOST:PORT (port 5084, or 5085 over TLS, when none is given).
    pub reader: String,
    /// LLRP over TLS with this client.
    pub tls: Option<Connector>,
    /// The ROSpec and keepalives asked of the reader.
    pub spec: InventorySpec,
    /// Reader name written in each read.
    pub name: ReaderName,
    /// Stop after this many seconds (`None`: run until Ctrl-C or SIGTERM).
    pub seconds: Option<f64>,
    /// Where the reads go, its format settled (not [`Output::Unnamed`]).
    pub output: Option<Output>,
    /// Write the reads to this MCAP file too (ROS 2 messages; `docs/robotics.md`).
    pub mcap: Option<PathBuf>,
    /// Replace an existing output file.
    pub force: bool,
    /// Retries after failed connection attempts in a row.
    pub retries: Retries,
    /// First wait before a retry (ms); it doubles with each failure in a row.
    pub backoff_ms: u64,
    /// Longest wait before a retry (ms).
    pub backoff_max_ms: u64,
}

/// How many times a failed connection is retried.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Retries {
    /// At most this many retries after failures in a row.
    Limit(u32),
    /// Retry until stopped.
    Forever,
}

/// Where the reads go.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Output {
    /// JSON Lines (the reads file) to this file.
    Jsonl(PathBuf),
    /// CSV with a header row to this file.
    Csv(PathBuf),
    /// JSON Lines to standard output.
    Stdout,
    /// A file whose name says no format: `--format` must.
    Unnamed(PathBuf),
}

impl Output {
    /// The output's name in messages.
    pub fn shown(&self) -> String {
        match self {
            Output::Stdout => "standard output".into(),
            Output::Jsonl(p) | Output::Csv(p) | Output::Unnamed(p) => p.display().to_string(),
        }
    }
}

/// `HOST[:PORT]` as a socket address string: port 5084 when none is given.
pub fn reader_address(reader: &str) -> String {
    reader_address_on(reader, LLRP_PORT)
}

/// `HOST[:PORT]` as a socket address string: port `port` when none is given.
pub fn reader_address_on(reader: &str, port: u16) -> String {
    crate::net::with_port_or(reader, port)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_port_defaults_to_5084() {
        assert_eq!(reader_address("reader.local"), "reader.local:5084");
        assert_eq!(reader_address("reader.local:6000"), "reader.local:6000");
        assert_eq!(reader_address("10.1.2.3"), "10.1.2.3:5084");
        assert_eq!(reader_address("10.1.2.3:1"), "10.1.2.3:1");
        assert_eq!(reader_address("::1"), "[::1]:5084");
        assert_eq!(reader_address("[::1]:5000"), "[::1]:5000");
    }
}
