//! Export: a recording as a pcapng capture that Wireshark dissects as LLRP. Each connection
//! of the recording is a TCP stream over loopback, with its handshake, its data in segments
//! of at most the MSS, an ACK from the receiver after each frame, and its FIN exchange.

use std::collections::HashMap;
use std::io::Write;
use std::net::Ipv4Addr;

use pcap_parser::{Linktype, OptionCode, PcapNGOption};

use super::packet::{ethernet_ipv4_tcp, OutSegment, TooLarge, ACK, FIN, PSH, SYN};
use super::write::{text, PcapNgOut, WriteError};
use super::{iso8601, READER_PORT};
use crate::record::format::{Direction, Entry, Event, Recording};

/// The MSS an export uses unless told otherwise: Ethernet's 1500-byte MTU less the IPv4 and
/// TCP headers, what a reader on a wired network sends.
pub const DEFAULT_MSS: u16 = 1460;

/// The smallest MSS accepted (IPv4's minimum, RFC 879).
pub const MIN_MSS: u16 = 536;

/// The largest MSS accepted: an IPv4 packet is at most 65535 bytes.
pub const MAX_MSS: u16 = 65495;

/// The window-scale shift both sides announce: a window of 65535 × 128 bytes, more than the
/// largest LLRP frame the codec takes (4 MiB), so a receiver's window never fills.
const WINDOW_SHIFT: u8 = 7;

/// Bytes a receiver lets arrive in one frame before it ACKs (it also ACKs after every frame).
const ACK_EVERY: usize = 1 << 20;

/// The first client port: connection `n` is `CLIENT_PORT_BASE + n % PORTS`.
const CLIENT_PORT_BASE: u16 = 40000;

/// Client ports in use before the next client address is taken.
const PORTS: u32 = 25000;

/// The reader's address in an export.
pub const READER_ADDR: Ipv4Addr = Ipv4Addr::new(127, 0, 0, 1);

/// How to export.
#[derive(Clone, Copy, Debug)]
pub struct ExportOptions {
    /// Largest TCP payload of one packet; a longer frame is split.
    pub mss: u16,
}

impl Default for ExportOptions {
    fn default() -> Self {
        ExportOptions { mss: DEFAULT_MSS }
    }
}

/// What an export wrote.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ExportSummary {
    /// TCP streams (one per connection and handshake).
    pub streams: usize,
    /// LLRP frames.
    pub frames: usize,
    /// `bytes` entries (non-LLRP payload).
    pub bytes_entries: usize,
    /// Packets written.
    pub packets: usize,
    /// Reader lines, which have no packet of their own.
    pub reader_lines: usize,
}

/// Why an export failed.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// The MSS is outside [`MIN_MSS`]..=[`MAX_MSS`].
    #[error("MSS {0} is out of range: {MIN_MSS}..={MAX_MSS}")]
    Mss(u16),
    /// Writing the capture failed.
    #[error("writing the capture: {0}")]
    Write(#[from] WriteError),
    /// A segment does not fit in a packet (it cannot happen with an MSS in range).
    #[error("{0}")]
    Packet(#[from] TooLarge),
}

/// The client's address and port of connection `conn`.
pub fn client_endpoint(conn: u32) -> (Ipv4Addr, u16) {
    let ip = Ipv4Addr::from(u32::from(Ipv4Addr::new(127, 0, 0, 2)) + conn / PORTS);
    // conn % PORTS < 25000, so the sum stays below 65535.
    (ip, CLIENT_PORT_BASE + (conn % PORTS) as u16)
}

/// Which end of a connection sends: 0 the client, 1 the reader.
const CLIENT: usize = 0;
const READER: usize = 1;

/// One connection's TCP stream while it is open.
struct Stream {
    conn: u32,
    ends: [(Ipv4Addr, u16); 2],
    /// Next sequence number each end sends.
    next: [u32; 2],
    /// IPv4 identification each end uses next.
    ip_id: [u16; 2],
    /// Bytes each end sent that the other has not ACKed yet.
    unacked: [usize; 2],
}

/// Writes packets, counting them.
struct Out<W: Write> {
    writer: PcapNgOut<W>,
    packets: usize,
    mss: u16,
}

impl<W: Write> Out<W> {
    /// Sends one segment from `end` of `s`; SYN and FIN count one sequence number.
    fn send(
        &mut self,
        s: &mut Stream,
        end: usize,
        flags: u8,
        payload: &[u8],
        utc_us: u64,
        comment: String,
    ) -> Result<(), ExportError> {
        let other = 1 - end;
        let syn_options = (flags & SYN != 0).then_some((self.mss, WINDOW_SHIFT));
        let data = ethernet_ipv4_tcp(&OutSegment {
            src: s.ends[end],
            dst: s.ends[other],
            seq: s.next[end],
            ack: s.next[other],
            flags,
            syn_options,
            window: u16::MAX,
            ip_id: s.ip_id[end],
            payload,
        })?;
        s.ip_id[end] = s.ip_id[end].wrapping_add(1);
        let used = payload.len() + usize::from(flags & (SYN | FIN) != 0);
        // Sequence numbers are modulo 2^32.
        s.next[end] = s.next[end].wrapping_add(used as u32);
        s.unacked[end] += payload.len();
        if flags & ACK != 0 {
            s.unacked[other] = 0;
        }
        self.packets += 1;
        // Nanoseconds (the interface's if_tsresol 9), to the year 2554.
        self.writer
            .packet(utc_us.saturating_mul(1000), &data, &comment)?;
        Ok(())
    }

    /// SYN, SYN-ACK, ACK.
    fn open(
        &mut self,
        conn: u32,
        generation: u32,
        utc_us: u64,
        why: &str,
    ) -> Result<Stream, ExportError> {
        // Deterministic initial sequence numbers, different per connection and end.
        let isn = conn.wrapping_mul(0x9E37_79B9) ^ generation.wrapping_mul(0x85EB_CA6B);
        let mut s = Stream {
            conn,
            ends: [client_endpoint(conn), (READER_ADDR, READER_PORT)],
            next: [isn, !isn],
            ip_id: [1, 1],
            unacked: [0, 0],
        };
        let at = iso8601(utc_us);
        self.send(
            &mut s,
            CLIENT,
            SYN,
            &[],
            utc_us,
            format!("{at} conn {conn} {why}"),
        )?;
        self.send(
            &mut s,
            READER,
            SYN | ACK,
            &[],
            utc_us,
            format!("{at} conn {conn} SYN-ACK"),
        )?;
        self.send(
            &mut s,
            CLIENT,
            ACK,
            &[],
            utc_us,
            format!("{at} conn {conn} ACK"),
        )?;
        Ok(s)
    }

    /// The payload of one entry from `end`, in MSS-sized segments, then the receiver's ACK.
    fn data(
        &mut self,
        s: &mut Stream,
        end: usize,
        bytes: &[u8],
        utc_us: u64,
        what: &str,
    ) -> Result<(), ExportError> {
        let at = iso8601(utc_us);
        let conn = s.conn;
        let dir = if end == CLIENT {
            "to_reader"
        } else {
            "from_reader"
        };
        let n = bytes.len().div_ceil(usize::from(self.mss));
        for (i, chunk) in bytes.chunks(usize::from(self.mss)).enumerate() {
            let flags = if i + 1 == n { PSH | ACK } else { ACK };
            let part = if n > 1 {
                format!(" (segment {} of {n})", i + 1)
            } else {
                String::new()
            };
            self.send(
                s,
                end,
                flags,
                chunk,
                utc_us,
                format!("{at} conn {conn} {dir} {what}{part}"),
            )?;
            if s.unacked[end] >= ACK_EVERY {
                self.send(
                    s,
                    1 - end,
                    ACK,
                    &[],
                    utc_us,
                    format!("{at} conn {conn} ACK"),
                )?;
            }
        }
        if s.unacked[end] > 0 {
            self.send(
                s,
                1 - end,
                ACK,
                &[],
                utc_us,
                format!("{at} conn {conn} ACK"),
            )?;
        }
        Ok(())
    }

    /// FIN from the client, FIN from the reader, last ACK.
    fn close(&mut self, mut s: Stream, utc_us: u64, why: &str) -> Result<(), ExportError> {
        let at = iso8601(utc_us);
        let conn = s.conn;
        self.send(
            &mut s,
            CLIENT,
            FIN | ACK,
            &[],
            utc_us,
            format!("{at} conn {conn} {why}"),
        )?;
        self.send(
            &mut s,
            READER,
            FIN | ACK,
            &[],
            utc_us,
            format!("{at} conn {conn} FIN"),
        )?;
        self.send(
            &mut s,
            CLIENT,
            ACK,
            &[],
            utc_us,
            format!("{at} conn {conn} ACK"),
        )?;
        Ok(())
    }
}

/// Writes `recording` as pcapng to `out`: see the module's description and
/// `docs/recordings.md`.
pub fn export(
    recording: &Recording,
    options: &ExportOptions,
    out: impl Write,
) -> Result<ExportSummary, ExportError> {
    if !(MIN_MSS..=MAX_MSS).contains(&options.mss) {
        return Err(ExportError::Mss(options.mss));
    }
    let mut writer = PcapNgOut::new(out, section_header(recording))?;
    writer.interface(Linktype::ETHERNET, 9, interface())?;
    let mut out = Out {
        writer,
        packets: 0,
        mss: options.mss,
    };
    // Where each connection's last entry is: its stream closes there if no marker does.
    let mut last = HashMap::new();
    for (i, e) in recording.entries.iter().enumerate() {
        last.insert(e.conn(), i);
    }
    let mut open: HashMap<u32, Stream> = HashMap::new();
    let mut generation: HashMap<u32, u32> = HashMap::new();
    let mut summary = ExportSummary::default();
    for (i, e) in recording.entries.iter().enumerate() {
        let (conn, utc_us) = (e.conn(), e.at().utc_us);
        if let Entry::Reader { .. } = e {
            summary.reader_lines += 1;
        }
        if starts_stream(e, &open) {
            let g = generation.entry(conn).or_insert(0);
            *g += 1;
            open.insert(conn, out.open(conn, *g, utc_us, &connect_reason(e))?);
            summary.streams += 1;
        }
        out.entry(e, &mut open, &mut summary)?;
        if last.get(&conn) == Some(&i) {
            if let Some(s) = open.remove(&conn) {
                out.close(
                    s,
                    utc_us,
                    "end of the recording's connection (no disconnect marker)",
                )?;
            }
        }
    }
    summary.packets = out.packets;
    Ok(summary)
}

/// The capture's section header options: the exporting program and what was recorded.
fn section_header(recording: &Recording) -> Vec<PcapNGOption<'static>> {
    let h = &recording.header;
    let mut about = format!(
        "llrp-gateway export of a recording of {}, started {}",
        h.upstream,
        iso8601(h.start_utc_us)
    );
    if let Some(s) = &h.scenario {
        about.push_str(&format!(" (scenario {s})"));
    }
    vec![
        text(
            OptionCode::ShbUserAppl,
            &format!("llrp-gateway {}", env!("CARGO_PKG_VERSION")),
        ),
        text(OptionCode::Comment, &about),
    ]
}

/// The options of the capture's one interface: Ethernet on loopback (nanosecond timestamps
/// are set by the caller).
fn interface() -> Vec<PcapNGOption<'static>> {
    vec![
        text(OptionCode::IfName, "lo"),
        text(
            OptionCode::IfDescription,
            "loopback, as exported by llrp-gateway: reader 127.0.0.1:5084",
        ),
    ]
}

/// Whether entry `e` opens a stream (none open; neither a reader line nor a disconnect).
fn starts_stream(e: &Entry, open: &HashMap<u32, Stream>) -> bool {
    !open.contains_key(&e.conn())
        && !matches!(e, Entry::Reader { .. })
        && !matches!(
            e,
            Entry::Marker {
                event: Event::Disconnect,
                ..
            }
        )
}

/// The comment on the SYN of a stream that entry `e` opens.
fn connect_reason(e: &Entry) -> String {
    match e {
        Entry::Marker { reason, .. } => format!("connect: {reason}"),
        _ => "connect (no connect marker in the recording)".to_string(),
    }
}

impl<W: Write> Out<W> {
    /// Writes the packets of entry `e` (payload or closing handshake) and counts it.
    fn entry(
        &mut self,
        e: &Entry,
        open: &mut HashMap<u32, Stream>,
        summary: &mut ExportSummary,
    ) -> Result<(), ExportError> {
        let (conn, utc_us) = (e.conn(), e.at().utc_us);
        match e {
            Entry::Frame { dir, frame, .. } => {
                let what = match (
                    llrp::FrameHeader::peek(frame),
                    llrp::MessageKind::of_frame(frame),
                ) {
                    (Some(h), Some(k)) => format!("{} id {}", k.name(), h.id),
                    _ => "frame".to_string(),
                };
                if let Some(s) = open.get_mut(&conn) {
                    self.data(s, end_of(*dir), frame, utc_us, &what)?;
                }
                summary.frames += 1;
            }
            Entry::Bytes { dir, bytes, .. } => {
                if let Some(s) = open.get_mut(&conn) {
                    let what = format!("{} bytes that are not LLRP", bytes.len());
                    self.data(s, end_of(*dir), bytes, utc_us, &what)?;
                }
                summary.bytes_entries += 1;
            }
            Entry::Marker {
                event: Event::Disconnect,
                reason,
                ..
            } => {
                if let Some(s) = open.remove(&conn) {
                    self.close(s, utc_us, &format!("disconnect: {reason}"))?;
                }
            }
            Entry::Marker { .. } | Entry::Reader { .. } => {}
        }
        Ok(())
    }
}

fn end_of(dir: Direction) -> usize {
    match dir {
        Direction::ToReader => CLIENT,
        Direction::FromReader => READER,
    }
}
