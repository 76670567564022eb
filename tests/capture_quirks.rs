//! `llrp-gateway import` of what real captures hold and a hand-written parser refused: a
//! capture on the sending host with TCP segmentation offload (an IPv4 total length of 0),
//! IPv6 with an Authentication Header between it and TCP, and IP fragments (reassembled,
//! counted and reported; those of a packet never completed dropped, and reported).

#[path = "common/reports.rs"]
mod reports;

use std::net::{IpAddr, Ipv4Addr, Ipv6Addr};
use std::process::Command;

use bytes::Bytes;
use etherparse::PacketBuilder;
use llrp::message::*;
use llrp::Message;
use llrp_gateway::record::pcapng;
use llrp_gateway::record::{Direction, Entry, Event, Recording};

const CLIENT_PORT: u16 = 40001;
const READER_PORT: u16 = 5084;
const SYN: u8 = 0x02;
const FIN: u8 = 0x01;
const ACK: u8 = 0x10;
const PSH: u8 = 0x08;

/// One side of the session: who sends, and the next sequence number.
struct Side {
    addr: IpAddr,
    port: u16,
    seq: u32,
}

/// A TCP session between a client and a reader, as Ethernet frames.
struct Session {
    ends: [Side; 2],
}

impl Session {
    fn new(client: IpAddr, reader: IpAddr) -> Session {
        let side = |addr, port, seq| Side { addr, port, seq };
        Session {
            ends: [
                side(client, CLIENT_PORT, 1000),
                side(reader, READER_PORT, 900_000),
            ],
        }
    }

    /// The frame of a segment from end `from` (0 the client), with etherparse's builder.
    fn segment(&mut self, from: usize, flags: u8, payload: &[u8]) -> Vec<u8> {
        let ack = self.ends[1 - from].seq;
        let (src, dst) = (&self.ends[from], &self.ends[1 - from]);
        let eth = PacketBuilder::ethernet2([0; 6], [0; 6]);
        let ip = match (src.addr, dst.addr) {
            (IpAddr::V4(s), IpAddr::V4(d)) => eth.ipv4(s.octets(), d.octets(), 64),
            (IpAddr::V6(s), IpAddr::V6(d)) => eth.ipv6(s.octets(), d.octets(), 64),
            _ => panic!("one IP version"),
        };
        let mut tcp = ip.tcp(src.port, dst.port, src.seq, 65535);
        if flags & SYN != 0 {
            tcp = tcp.syn();
        }
        if flags & FIN != 0 {
            tcp = tcp.fin();
        }
        if flags & PSH != 0 {
            tcp = tcp.psh();
        }
        if flags & ACK != 0 {
            tcp = tcp.ack(ack);
        }
        let mut out = Vec::new();
        tcp.write(&mut out, payload).expect("builds");
        let used = payload.len() + usize::from(flags & (SYN | FIN) != 0);
        self.ends[from].seq = self.ends[from].seq.wrapping_add(used as u32);
        out
    }

    fn handshake(&mut self) -> Vec<Vec<u8>> {
        vec![
            self.segment(0, SYN, &[]),
            self.segment(1, SYN | ACK, &[]),
            self.segment(0, ACK, &[]),
        ]
    }

    fn close(&mut self) -> Vec<Vec<u8>> {
        vec![
            self.segment(0, FIN | ACK, &[]),
            self.segment(1, FIN | ACK, &[]),
            self.segment(0, ACK, &[]),
        ]
    }
}

/// The session's frames: a request, a report far larger than an MSS, a keepalive.
fn frames() -> Vec<(Direction, Bytes)> {
    let report = reports::many_reads(1000);
    vec![
        (
            Direction::ToReader,
            Message::new(1, GetReaderCapabilities::default())
                .to_bytes()
                .freeze(),
        ),
        (
            Direction::FromReader,
            Message::new(2, report).to_bytes().freeze(),
        ),
        (
            Direction::FromReader,
            Message::new(3, Keepalive::default()).to_bytes().freeze(),
        ),
    ]
}

/// The session's packets: handshake, each frame in one segment (given to `shape`, which
/// may turn a packet into several or change it), close.
fn session(
    client: IpAddr,
    reader: IpAddr,
    shape: impl Fn(Vec<u8>) -> Vec<Vec<u8>>,
) -> Vec<Vec<u8>> {
    let mut s = Session::new(client, reader);
    let mut packets = s.handshake();
    for (dir, frame) in frames() {
        let from = usize::from(dir == Direction::FromReader);
        packets.extend(shape(s.segment(from, PSH | ACK, &frame)));
    }
    packets.extend(s.close());
    packets
}

/// A classic pcap (microseconds, Ethernet) of `packets`, 1 ms apart.
fn pcap(packets: &[Vec<u8>]) -> Vec<u8> {
    let mut f = vec![0xD4, 0xC3, 0xB2, 0xA1, 2, 0, 4, 0];
    f.extend_from_slice(&[0; 8]);
    f.extend_from_slice(&262_144u32.to_le_bytes());
    f.extend_from_slice(&1u32.to_le_bytes());
    for (i, p) in packets.iter().enumerate() {
        f.extend_from_slice(&1_700_000_000u32.to_le_bytes());
        f.extend_from_slice(&(i as u32 * 1000).to_le_bytes());
        f.extend_from_slice(&(p.len() as u32).to_le_bytes());
        f.extend_from_slice(&(p.len() as u32).to_le_bytes());
        f.extend_from_slice(p);
    }
    f
}

fn frames_of(r: &Recording) -> Vec<(Direction, Bytes)> {
    r.frames(1).map(|(_, d, f)| (d, f.clone())).collect()
}

/// Imports `packets` with the library and with the command; checks the frames come back
/// whole, and returns the command's standard error.
fn import_both_ways(name: &str, packets: &[Vec<u8>]) -> (Recording, String) {
    let data = pcap(packets);
    let r = pcapng::import(&data).expect("imports");
    assert_eq!(frames_of(&r), frames(), "{name}: the frames, whole");
    let markers: Vec<Event> = r
        .entries
        .iter()
        .filter_map(|e| match e {
            Entry::Marker { event, .. } => Some(*event),
            _ => None,
        })
        .collect();
    assert_eq!(markers, [Event::Connect, Event::Disconnect], "{name}");
    let dir = tempfile::tempdir().expect("temp dir");
    let (cap, out) = (dir.path().join("in.pcap"), dir.path().join("out.jsonl"));
    std::fs::write(&cap, &data).expect("writes");
    let o = Command::new(env!("CARGO_BIN_EXE_llrp-gateway"))
        .arg("import")
        .arg(&cap)
        .arg("--output")
        .arg(&out)
        .output()
        .expect("runs");
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    assert!(o.status.success(), "{name}: {err}");
    let back = Recording::open(&out).expect("reads back");
    assert_eq!(
        back.entries, r.entries,
        "{name}: the command writes the same"
    );
    (r, err)
}

#[test]
fn a_capture_with_tcp_segmentation_offload_imports_whole() {
    let (c, r) = (
        Ipv4Addr::new(10, 0, 0, 7).into(),
        Ipv4Addr::new(10, 0, 0, 5).into(),
    );
    let packets = session(c, r, |mut p| {
        // The sending host's capture: one segment far larger than the MTU, IPv4 length 0.
        if p.len() > 1514 {
            p[16..18].copy_from_slice(&[0, 0]);
        }
        vec![p]
    });
    assert!(packets
        .iter()
        .any(|p| p.len() > 1514 && p[16..18] == [0, 0]));
    let (r, err) = import_both_ways("TSO", &packets);
    assert!(r.warnings.is_empty(), "{:?}", r.warnings);
    assert!(!err.contains("warning"), "{err}");
    assert_eq!(r.header.upstream, "10.0.0.5:5084");
}

/// `p` (Ethernet, IPv6, TCP) with an Authentication Header (RFC 4302) before its TCP.
fn with_authentication_header(p: Vec<u8>) -> Vec<Vec<u8>> {
    // Next header TCP, length 4 (24 bytes), reserved, SPI, sequence number, 12-byte ICV.
    let mut ah = vec![6, 4, 0, 0, 0, 0, 0x10, 0x01, 0, 0, 0, 9];
    ah.extend_from_slice(&[0xAA; 12]);
    let mut out = p[..54].to_vec();
    let len = u16::from_be_bytes([p[18], p[19]]) + ah.len() as u16;
    out[18..20].copy_from_slice(&len.to_be_bytes());
    out[20] = 51; // next header: AH
    out.extend_from_slice(&ah);
    out.extend_from_slice(&p[54..]);
    vec![out]
}

#[test]
fn ipv6_with_an_authentication_header_imports() {
    let c = "fd00::7".parse::<Ipv6Addr>().expect("addr").into();
    let r = "fd00::5".parse::<Ipv6Addr>().expect("addr").into();
    let packets = session(c, r, with_authentication_header);
    let (r, err) = import_both_ways("IPv6 AH", &packets);
    assert!(r.warnings.is_empty(), "{:?}", r.warnings);
    assert!(!err.contains("warning"), "{err}");
    assert_eq!(r.header.upstream, "[fd00::5]:5084");
}

/// `p` (Ethernet, IPv4 without options, TCP) as IPv4 fragments of at most 1480 bytes of
/// payload, the last first (as some stacks send them).
fn fragments(p: &[u8], id: u16) -> Vec<Vec<u8>> {
    let payload = &p[34..];
    let mut out: Vec<Vec<u8>> = payload
        .chunks(1480)
        .enumerate()
        .map(|(i, chunk)| {
            let mut f = p[..34].to_vec();
            f[16..18].copy_from_slice(&((20 + chunk.len()) as u16).to_be_bytes());
            f[18..20].copy_from_slice(&id.to_be_bytes());
            let more = if (i + 1) * 1480 < payload.len() {
                0x2000
            } else {
                0
            };
            f[20..22].copy_from_slice(&(more | (i * 1480 / 8) as u16).to_be_bytes());
            f.extend_from_slice(chunk);
            f
        })
        .collect();
    out.rotate_right(1);
    out
}

#[test]
fn ip_fragments_are_reassembled_counted_and_reported() {
    let (c, r) = (
        Ipv4Addr::new(10, 0, 0, 7).into(),
        Ipv4Addr::new(10, 0, 0, 5).into(),
    );
    let mut packets = session(c, r, |p| {
        if p.len() > 1514 {
            fragments(&p, 77)
        } else {
            vec![p]
        }
    });
    let n = packets.len() - 8; // the handshake, the request and keepalive, the close
    assert!(n > 10, "the report is in {n} fragments");
    // The first two fragments again, of a packet (another identification) that never
    // completes. (Packet 4 is the report's last fragment: sent first.)
    let lost: Vec<Vec<u8>> = packets[5..7]
        .iter()
        .map(|f| {
            let mut f = f.clone();
            f[18..20].copy_from_slice(&78u16.to_be_bytes());
            f
        })
        .collect();
    packets.extend(lost);
    let (r, err) = import_both_ways("fragments", &packets);
    let want = format!(
        "{} IP fragments of TCP packets, reassembled into 1 packets; 2 fragments of packets never completed (or past the reassembly bounds) are dropped",
        n + 2
    );
    assert_eq!(r.warnings, std::slice::from_ref(&want));
    assert!(err.contains(&want), "{err}");
}
