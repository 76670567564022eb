//! Recordings to and from packet captures: a recording as a pcapng capture that Wireshark
//! dissects as LLRP ([`export()`], behind `llrp-gateway export`), and the LLRP streams of a
//! pcap or pcapng capture as a recording that replays ([`import()`], behind `llrp-gateway
//! import`; both commands' runners are in `cli::capture`). See `docs/recordings.md`.

pub mod capture;
pub mod defrag;
pub mod emit;
pub mod export;
pub mod packet;
pub mod stream;
pub mod write;

use std::io::Read;
use std::net::SocketAddr;

pub use emit::{JsonLines, Sink};
pub use export::{export, ExportError, ExportOptions, ExportSummary, DEFAULT_MSS};

use super::format::{Header, Recording};
use capture::Packet;
use defrag::Defrag;
use emit::Emitter;
use packet::{Parsed, Skip};
use stream::Streams;

/// The reader's TCP port in an export (LLRP's IANA port, which Wireshark dissects as LLRP).
pub const READER_PORT: u16 = 5084;

/// UTC µs since the Unix epoch as ISO-8601 with microseconds, e.g.
/// `2023-11-14T22:13:20.000010Z` ([`crate::utc::rfc3339_micros`]).
pub fn iso8601(utc_us: u64) -> String {
    crate::utc::rfc3339_micros(utc_us)
}

/// Why a capture cannot be imported.
#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    /// The file is neither pcap nor pcapng.
    #[error("not a pcap or pcapng capture: it starts with {start}{hint}")]
    NotACapture {
        /// Its first bytes in hex.
        start: String,
        /// What it might be instead.
        hint: &'static str,
    },
    /// The capture is malformed.
    #[error("malformed capture at byte {offset} (after packet {after}): {reason}")]
    Pcap {
        /// Where the bad block starts.
        offset: usize,
        /// The packets read before it.
        after: usize,
        /// What pcap-parser found.
        reason: String,
    },
    /// A packet cannot be read.
    #[error("packet {number}: {reason}")]
    Packet {
        /// Its number (1-based, as Wireshark counts).
        number: usize,
        /// Why.
        reason: String,
    },
    /// The capture file could not be read.
    #[error("reading the capture: {0}")]
    Read(String),
    /// The recording could not be written.
    #[error("writing the recording: {0}")]
    Write(#[source] std::io::Error),
    /// No packet has a link type this importer takes apart.
    #[error(
        "no packet of a supported link type (Ethernet, raw IP, Linux cooked, BSD loopback); the capture has link type {0}"
    )]
    LinkType(String),
    /// Nothing in the capture is an LLRP stream.
    #[error("no LLRP stream in the capture: {0}")]
    NoLlrp(String),
}

/// What an import wrote.
#[derive(Clone, Debug)]
pub struct ImportSummary {
    /// The reader of the first connection (the recording's `upstream`).
    pub upstream: SocketAddr,
    /// Connections written.
    pub connections: usize,
    /// Frames written.
    pub frames: usize,
    /// What was skipped or tolerated.
    pub warnings: Vec<String>,
}

/// Turns the LLRP streams of a pcap or pcapng capture held in memory into a recording (see
/// [`import_into`]).
pub fn import(data: &[u8]) -> Result<Recording, ImportError> {
    let mut recording = Recording {
        header: Header::new(String::new(), 0),
        entries: Vec::new(),
        warnings: Vec::new(),
    };
    let summary = import_into(data, &mut recording)?;
    recording.warnings = summary.warnings;
    Ok(recording)
}

/// Turns the LLRP streams of the pcap or pcapng capture `input` into a recording written to
/// `sink` as it goes, in bounded memory: one connection per TCP stream, in order of their
/// first packet; both directions reassembled and split into frames; connect and disconnect
/// markers from SYN, FIN and RST. Streams that are not LLRP are skipped; what was skipped
/// or tolerated is in the summary's `warnings`. On an error the sink may hold a part.
pub fn import_into<R: Read + Send, S: Sink>(
    input: R,
    sink: &mut S,
) -> Result<ImportSummary, ImportError> {
    let mut importer = Importer {
        streams: Streams::default(),
        defrag: Defrag::default(),
        emitter: Emitter::new(sink, 0),
        packets: 0,
        linked: 0,
        last_us: 0,
        unsupported: Vec::new(),
        truncated: 0,
    };
    let warnings = capture::read_packets(input, |p| importer.packet(p))?;
    importer.finish(warnings)
}

/// An import under way.
struct Importer<'s, S: Sink> {
    streams: Streams,
    defrag: Defrag,
    emitter: Emitter<'s, S>,
    /// Packets read, those of a supported link type, and the last one's time.
    packets: usize,
    linked: usize,
    last_us: u64,
    /// The unsupported link types seen.
    unsupported: Vec<u32>,
    /// Packets cut short or with inconsistent headers.
    truncated: usize,
}

impl<S: Sink> Importer<'_, S> {
    /// Takes one packet: its TCP segment (or, once whole, the packet its fragment completes)
    /// goes to its stream, and the recording is written as far as it is decided.
    fn packet(&mut self, p: &Packet<'_>) -> Result<(), ImportError> {
        if self.packets == 0 {
            self.emitter.start_us = p.utc_us;
        }
        let index = self.packets;
        self.packets += 1;
        self.last_us = p.utc_us;
        let link = match p.link {
            Ok(l) => l,
            Err(t) => {
                if !self.unsupported.contains(&t) {
                    self.unsupported.push(t);
                }
                return Ok(());
            }
        };
        self.linked += 1;
        let stream = match packet::parse(link, p.data) {
            // A TCP segment of a packet cut by the snap length (also one whose IPv4 length
            // is 0, which says nothing of where it ends) would be taken cut.
            Ok(_) if p.cut => None,
            Ok(Parsed::Segment(seg)) => Some(self.streams.segment(&seg, index, p.utc_us)),
            Ok(Parsed::Fragment(f)) => match self.defrag.add(&f, index) {
                None => return Ok(()),
                Some(whole) => packet::reassembled(f.key.src, f.key.dst, &whole)
                    .ok()
                    .map(|seg| self.streams.segment(&seg, index, p.utc_us)),
            },
            Err(Skip::NotTcp) => return Ok(()),
            Err(Skip::Truncated) => None,
        };
        let Some(stream) = stream else {
            self.truncated += 1;
            return Ok(());
        };
        self.emitter.take(&mut self.streams, stream);
        self.emitter
            .flush(&mut self.streams, false)
            .map_err(ImportError::Write)
    }

    /// At the end of the capture: what the streams still hold is written, and the warnings
    /// are gathered.
    fn finish(mut self, mut warnings: Vec<String>) -> Result<ImportSummary, ImportError> {
        if self.packets == 0 {
            return Err(no_packet(&warnings));
        }
        let types = self
            .unsupported
            .iter()
            .map(u32::to_string)
            .collect::<Vec<_>>()
            .join(", ");
        if self.linked == 0 {
            return Err(ImportError::LinkType(types));
        }
        self.defrag.finish();
        self.streams.finish(self.packets - 1, self.last_us);
        for i in 0..self.streams.streams.len() {
            self.emitter.take(&mut self.streams, i);
        }
        self.emitter
            .flush(&mut self.streams, true)
            .map_err(ImportError::Write)?;
        if !self.unsupported.is_empty() {
            warnings.push(format!(
                "packets of link type {types} are skipped (not supported)"
            ));
        }
        warnings.extend(self.defrag.warning());
        if self.truncated > 0 {
            warnings.push(format!(
                "{} packets skipped: cut short (by the capture's snap length?) or with inconsistent headers",
                self.truncated
            ));
        }
        stream_warnings(&mut self.streams, &mut warnings);
        let Some(upstream) = self.emitter.upstream else {
            let n = self.streams.streams.len();
            return Err(ImportError::NoLlrp(format!(
                "{n} TCP streams, none on port 5084 or 5085 nor starting with an LLRP message"
            )));
        };
        let readers = &self.emitter.readers;
        if readers.len() > 1 {
            let all: Vec<String> = readers.iter().map(|a| a.to_string()).collect();
            warnings.push(format!(
                "the capture has {} readers ({}): the recording's header names the first",
                readers.len(),
                all.join(", ")
            ));
        }
        Ok(ImportSummary {
            upstream,
            connections: self.emitter.connections(),
            frames: self.emitter.frames,
            warnings,
        })
    }
}

/// The error for a capture without a whole packet, with the capture's warnings.
fn no_packet(warnings: &[String]) -> ImportError {
    let why = if warnings.is_empty() {
        String::new()
    } else {
        format!(" ({})", warnings.join("; "))
    };
    ImportError::NoLlrp(format!("the capture holds no whole packet{why}"))
}

/// The warnings of each stream, in order: those skipped as not LLRP, and what each LLRP
/// stream tolerated (gaps, retransmissions, a start inside the stream).
fn stream_warnings(streams: &mut Streams, warnings: &mut Vec<String>) {
    let mut silent = 0usize;
    for s in &mut streams.streams {
        if !s.decide().llrp {
            if s.payload_bytes == 0 {
                silent += 1;
            } else {
                warnings.push(format!(
                    "skipped TCP stream {} <-> {} ({} bytes): not LLRP",
                    s.ends[0], s.ends[1], s.payload_bytes
                ));
            }
            continue;
        }
        warnings.extend(s.warnings.iter().cloned());
        if s.duplicate_bytes() > 0 {
            warnings.push(format!(
                "{} <-> {}: {} bytes arrived twice (retransmissions) and were taken once",
                s.ends[0],
                s.ends[1],
                s.duplicate_bytes()
            ));
        }
    }
    if silent > 0 {
        warnings.push(format!(
            "{silent} TCP streams without payload, not on an LLRP port, skipped"
        ));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn iso8601_of_known_instants() {
        assert_eq!(iso8601(0), "1970-01-01T00:00:00.000000Z");
        assert_eq!(
            iso8601(1_700_000_000_000_010),
            "2023-11-14T22:13:20.000010Z"
        );
        // A leap day, and the last microsecond of a century year that is not a leap year.
        assert_eq!(iso8601(951_782_400_000_000), "2000-02-29T00:00:00.000000Z");
        assert_eq!(
            iso8601(4_107_542_399_999_999),
            "2100-02-28T23:59:59.999999Z"
        );
    }

    #[test]
    fn bad_files_are_named_for_what_they_are() {
        let e = import(b"{\"llrp_recording\":1}\n").expect_err("JSON");
        assert!(
            e.to_string().contains("not a pcap or pcapng capture"),
            "{e}"
        );
        assert!(e.to_string().contains("recording?"), "{e}");
        let e = import(b"").expect_err("empty");
        assert!(e.to_string().contains("empty file"), "{e}");
        // A pcap header with link type 147 (user-defined), one packet.
        let mut pcap = vec![0xD4, 0xC3, 0xB2, 0xA1, 2, 0, 4, 0];
        pcap.extend_from_slice(&[0; 8]);
        pcap.extend_from_slice(&65535u32.to_le_bytes());
        pcap.extend_from_slice(&147u32.to_le_bytes());
        pcap.extend_from_slice(&[0; 8]);
        pcap.extend_from_slice(&4u32.to_le_bytes());
        pcap.extend_from_slice(&4u32.to_le_bytes());
        pcap.extend_from_slice(b"abcd");
        let e = import(&pcap).expect_err("link type");
        assert!(e.to_string().contains("link type 147"), "{e}");
        // The same, cut inside its packet: tolerated, then no LLRP.
        let e = import(&pcap[..pcap.len() - 2]).expect_err("cut");
        assert!(e.to_string().contains("no LLRP stream"), "{e}");
    }
}
