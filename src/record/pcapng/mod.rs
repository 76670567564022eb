//! Recordings to and from packet captures: a recording as a pcapng capture that Wireshark
//! dissects as LLRP ([`export()`], behind `llrp-gateway export`), and the LLRP streams of a
//! pcap or pcapng capture as a recording that replays ([`import()`], behind `llrp-gateway
//! import`; both commands' runners are in `cli::capture`). See `docs/recordings.md`.

pub mod capture;
pub mod export;
pub mod packet;
pub mod stream;

use pcap_file::PcapError;

pub use export::{export, ExportError, ExportOptions, ExportSummary, DEFAULT_MSS};

use super::format::{
    encode_entry, encode_header, Direction, Entry, Event, Header, Recording, Stamp,
};
use packet::Skip;
use stream::{Ending, Happening, Piece, Streams};

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
    #[error("malformed capture at byte {offset}: {source}")]
    Pcap {
        /// Where the bad block or packet starts.
        offset: usize,
        /// What pcap-file found.
        source: PcapError,
    },
    /// No packet has a link type this importer takes apart.
    #[error(
        "no packet of a supported link type (Ethernet, raw IP, Linux cooked, BSD loopback); the capture has link type {0}"
    )]
    LinkType(String),
    /// Nothing in the capture is an LLRP stream.
    #[error("no LLRP stream in the capture: {0}")]
    NoLlrp(String),
}

/// Turns the LLRP streams of a pcap or pcapng capture into a recording: one connection per
/// TCP stream, in order of their first packet; both directions reassembled and split into
/// frames; connect and disconnect markers from SYN, FIN and RST. Streams that are not LLRP
/// are skipped; what was skipped or tolerated is in the recording's `warnings`.
pub fn import(data: &[u8]) -> Result<Recording, ImportError> {
    let read = capture::read(data)?;
    let mut warnings = read.warnings;
    let packets = read.packets;
    let Some(first) = packets.first() else {
        return Err(no_packet(&warnings));
    };
    let start_us = first.utc_us;
    let streams = reassemble(&packets, &mut warnings)?;
    let llrp = llrp_entries(&streams, start_us, &mut warnings);
    let Some(upstream) = llrp.upstream else {
        let n = streams.streams.len();
        return Err(ImportError::NoLlrp(format!(
            "{n} TCP streams, none on port 5084 or 5085 nor starting with an LLRP message"
        )));
    };
    if llrp.readers.len() > 1 {
        let all: Vec<String> = llrp.readers.iter().map(|a| a.to_string()).collect();
        warnings.push(format!(
            "the capture has {} readers ({}): the recording's header names the first",
            llrp.readers.len(),
            all.join(", ")
        ));
    }
    let mut entries = llrp.entries;
    // Capture order: by packet, then by order within the packet (stable).
    entries.sort_by_key(|(at, _)| *at);
    Ok(Recording {
        header: Header::new(upstream.to_string(), start_us),
        entries: entries.into_iter().map(|(_, e)| e).collect(),
        warnings,
    })
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

/// The TCP streams of the (non-empty) `packets`, with warnings for what was skipped.
fn reassemble(
    packets: &[capture::Packet<'_>],
    warnings: &mut Vec<String>,
) -> Result<Streams, ImportError> {
    let mut unsupported: Vec<u32> = Vec::new();
    let (mut not_tcp, mut fragments, mut truncated) = (0, 0, 0);
    let mut streams = Streams::default();
    for (i, p) in packets.iter().enumerate() {
        let link = match p.link {
            Ok(l) => l,
            Err(t) => {
                if !unsupported.contains(&t) {
                    unsupported.push(t);
                }
                continue;
            }
        };
        match packet::parse(link, p.data) {
            Ok(seg) => streams.segment(&seg, i, p.utc_us),
            Err(Skip::NotTcp) => not_tcp += 1,
            Err(Skip::Fragment) => fragments += 1,
            Err(Skip::Truncated) => truncated += 1,
        }
    }
    let types = || {
        let t: Vec<String> = unsupported.iter().map(u32::to_string).collect();
        t.join(", ")
    };
    if !unsupported.is_empty() {
        if packets.iter().all(|p| p.link.is_err()) {
            return Err(ImportError::LinkType(types()));
        }
        warnings.push(format!(
            "packets of link type {} are skipped (not supported)",
            types()
        ));
    }
    if fragments > 0 {
        warnings.push(format!(
            "{fragments} IP fragments skipped (fragments are not reassembled)"
        ));
    }
    if truncated > 0 {
        warnings.push(format!(
            "{truncated} packets skipped: cut short (by the capture's snap length?) or with inconsistent headers"
        ));
    }
    let _ = not_tcp; // other protocols are of no interest, and not worth a warning
    let last = packets.len().saturating_sub(1);
    streams.finish(last, packets[last].utc_us);
    Ok(streams)
}

/// What a capture's LLRP streams give: entries by capture position and the readers.
struct LlrpStreams {
    /// Each entry with its (packet, order within the packet).
    entries: Vec<((usize, usize), Entry)>,
    /// The first LLRP stream's reader.
    upstream: Option<std::net::SocketAddr>,
    /// Every reader, in order of first appearance.
    readers: Vec<std::net::SocketAddr>,
}

/// The entries of every LLRP stream, one connection each, with warnings for what was skipped.
fn llrp_entries(streams: &Streams, start_us: u64, warnings: &mut Vec<String>) -> LlrpStreams {
    let mut entries: Vec<((usize, usize), Entry)> = Vec::new();
    let mut upstream: Option<std::net::SocketAddr> = None;
    let (mut conn, mut silent, mut readers) = (0u32, 0usize, Vec::new());
    for s in &streams.streams {
        if !s.is_llrp() {
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
        conn += 1;
        warnings.extend(s.warnings.iter().cloned());
        if s.duplicate_bytes() > 0 {
            warnings.push(format!(
                "{} <-> {}: {} bytes arrived twice (retransmissions) and were taken once",
                s.ends[0],
                s.ends[1],
                s.duplicate_bytes()
            ));
        }
        let reader_addr = s.ends[s.reader_end()];
        upstream.get_or_insert(reader_addr);
        if !readers.contains(&reader_addr) {
            readers.push(reader_addr);
        }
        stream_entries(s, conn, start_us, &mut entries);
    }
    if silent > 0 {
        warnings.push(format!(
            "{silent} TCP streams without payload, not on an LLRP port, skipped"
        ));
    }
    LlrpStreams {
        entries,
        upstream,
        readers,
    }
}

/// Appends the entries of LLRP stream `s` as connection `conn` to `entries`.
fn stream_entries(
    s: &stream::Stream,
    conn: u32,
    start_us: u64,
    entries: &mut Vec<((usize, usize), Entry)>,
) {
    let reader = s.reader_end();
    let client_addr = s.ends[1 - reader];
    let role = |end: usize| if end == reader { "reader" } else { "client" };
    for e in &s.events {
        let at = Stamp {
            t_us: e.utc_us.saturating_sub(start_us),
            utc_us: e.utc_us,
        };
        let dir = |end: usize| {
            if end == reader {
                Direction::FromReader
            } else {
                Direction::ToReader
            }
        };
        let entry = match &e.what {
            Happening::Open { syn } => Entry::Marker {
                at,
                conn,
                event: Event::Connect,
                reason: if *syn {
                    format!("client {client_addr}")
                } else {
                    format!("client {client_addr} (the capture starts after the handshake)")
                },
            },
            Happening::Data { end, piece } => match piece {
                Piece::Frame(frame) => Entry::Frame {
                    at,
                    conn,
                    dir: dir(*end),
                    frame: frame.clone(),
                    undecodable: None,
                },
                Piece::Bytes(bytes) => Entry::Bytes {
                    at,
                    conn,
                    dir: dir(*end),
                    bytes: bytes.clone(),
                },
            },
            Happening::Close(ending) => Entry::Marker {
                at,
                conn,
                event: Event::Disconnect,
                reason: match ending {
                    Ending::Fin(end) => format!("{} closed", role(*end)),
                    Ending::Reset(end) => format!("reset by the {}", role(*end)),
                },
            },
        };
        entries.push((e.at, entry));
    }
}

/// Writes `recording` (header and entries) to `out`.
pub fn write_recording(
    recording: &Recording,
    out: &mut impl std::io::Write,
) -> std::io::Result<()> {
    let mut buf = Vec::new();
    encode_header(&recording.header, &mut buf);
    for e in &recording.entries {
        encode_entry(e, &mut buf);
    }
    out.write_all(&buf)
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
