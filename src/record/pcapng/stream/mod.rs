//! TCP streams of a capture: reassembly of each direction by sequence number (duplicates
//! and retransmissions dropped, out-of-order segments held until the gap fills), then
//! LLRP framing of each direction, and which end is the reader.

use std::collections::{BTreeMap, HashMap};
use std::net::SocketAddr;

use bytes::Bytes;
use llrp::MessageKind;

use super::packet::{InSegment, ACK, FIN, RST, SYN};

mod framer;
pub use framer::{known_frame, Framer};

/// The LLRP ports: 5084 (plain) and 5085 (TLS, as IANA lists it).
pub const LLRP_PORTS: [u16; 2] = [5084, 5085];

/// What reassembly and framing made of a direction's bytes.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Piece {
    /// One whole LLRP frame.
    Frame(Bytes),
    /// Bytes that are not LLRP frames.
    Bytes(Bytes),
}

/// One direction of a stream.
#[derive(Debug, Default)]
struct Half {
    /// Whether the sequence space is known (from a SYN or the first segment).
    started: bool,
    /// The absolute sequence number of the next byte expected, and its offset in the stream.
    next_seq: u32,
    next_off: u64,
    /// Segments beyond a gap, by stream offset, and their bytes (at most [`MAX_HELD`]).
    held: BTreeMap<u64, Vec<u8>>,
    held_bytes: usize,
    /// Where the FIN is, once seen.
    fin_at: Option<u64>,
    /// The FIN was reached: this direction is done.
    closed: bool,
    framer: Framer,
    /// The first frame this direction sent.
    first_frame: Option<Bytes>,
    /// Bytes that arrived again (retransmissions, duplicates).
    duplicate_bytes: usize,
    /// Gaps skipped at the out-of-order bound, the bytes the framers before the last one
    /// dropped at the stream's start, and those dropped after a gap.
    gaps: usize,
    skipped_at_start: usize,
    skipped_after_gaps: usize,
}

impl Half {
    /// Whether what decides the stream's kind and reader end is known for this direction:
    /// its first frame, or that it will never have one.
    fn settled(&self) -> bool {
        self.first_frame.is_some() || self.closed || self.framer.unsynced()
    }
}

/// The bytes of segments held beyond a gap in one direction before the gap is taken as
/// lost: 8 MiB, the most a receiver's window lets be in flight at window scale 7.
pub const MAX_HELD: usize = 8 << 20;

/// What a stream is, once decided: LLRP or not, and which end is the reader.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Role {
    /// Whether it carries LLRP ([`Stream::is_llrp`]).
    pub llrp: bool,
    /// Which end is the reader ([`Stream::reader_end`]).
    pub reader: usize,
}

/// What happened in a stream, in capture order.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Happening {
    /// The connection began (SYN, or the first packet of a stream caught mid-way).
    Open {
        /// Whether the handshake was seen.
        syn: bool,
    },
    /// End `end` sent this.
    Data {
        /// Which end sent it: index into [`Stream::ends`].
        end: usize,
        /// A frame or non-LLRP bytes.
        piece: Piece,
    },
    /// The connection ended.
    Close(Ending),
}

/// How a connection ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ending {
    /// This end sent the first FIN.
    Fin(usize),
    /// This end sent a RST.
    Reset(usize),
}

/// One event of a stream: the packet that caused it, and what.
#[derive(Clone, Debug)]
pub struct Event {
    /// Index of the packet in the capture (0-based) and the order within it.
    pub at: (usize, usize),
    /// UTC µs of the packet.
    pub utc_us: u64,
    /// What.
    pub what: Happening,
}

/// One TCP connection of a capture.
#[derive(Debug)]
pub struct Stream {
    /// Its two ends; end 0 sent the stream's first packet.
    pub ends: [SocketAddr; 2],
    halves: [Half; 2],
    /// Which end sent the SYN, and which the SYN-ACK.
    syn_from: Option<usize>,
    synack_from: Option<usize>,
    /// The SYN's sequence number (a different one on the same ports is a new connection).
    syn_seq: Option<u32>,
    first_data_from: Option<usize>,
    ended: bool,
    /// What happened, in order, since the importer last took the events.
    pub events: Vec<Event>,
    /// The packet of the last event and how many it had (the order within a packet).
    last_event: Option<(usize, usize)>,
    /// LLRP or not, and the reader's end, once decided ([`Stream::decide`]).
    pub role: Option<Role>,
    /// Payload bytes seen, both ways.
    pub payload_bytes: u64,
    /// Problems found at its end (gaps never filled, a frame cut).
    pub warnings: Vec<String>,
}

impl Stream {
    fn new(ends: [SocketAddr; 2]) -> Stream {
        Stream {
            ends,
            halves: Default::default(),
            syn_from: None,
            synack_from: None,
            syn_seq: None,
            first_data_from: None,
            ended: false,
            events: Vec::new(),
            last_event: None,
            role: None,
            payload_bytes: 0,
            warnings: Vec::new(),
        }
    }

    fn event(&mut self, packet: usize, utc_us: u64, what: Happening) {
        let n = match self.last_event {
            Some((p, n)) if p == packet => n + 1,
            _ => 0,
        };
        self.last_event = Some((packet, n));
        self.events.push(Event {
            at: (packet, n),
            utc_us,
            what,
        });
    }

    /// Takes one segment sent by end `end`.
    fn segment(&mut self, end: usize, seg: &InSegment<'_>, packet: usize, utc_us: u64) {
        if self.last_event.is_none() {
            let syn = seg.flags & SYN != 0;
            self.event(packet, utc_us, Happening::Open { syn });
        }
        let mut seq = seg.seq;
        if seg.flags & SYN != 0 {
            if seg.flags & ACK == 0 {
                self.syn_from = Some(end);
                self.syn_seq = Some(seg.seq);
            } else {
                self.synack_from = Some(end);
            }
            let h = &mut self.halves[end];
            if !h.started || (h.next_off == 0 && h.held.is_empty()) {
                h.started = true;
                h.next_seq = seg.seq.wrapping_add(1);
                h.next_off = 0;
                h.framer = Framer::new(false);
            }
            seq = seq.wrapping_add(1);
        }
        if !seg.payload.is_empty() {
            self.first_data_from.get_or_insert(end);
            self.payload_bytes += seg.payload.len() as u64;
            self.data(end, seq, seg.payload, packet, utc_us);
        }
        if seg.flags & FIN != 0 {
            let h = &mut self.halves[end];
            if h.started {
                let off = offset(h, seq.wrapping_add(seg.payload.len() as u32));
                h.fin_at = Some(off.max(0) as u64);
            }
        }
        self.check_fin(end, packet, utc_us);
        if seg.flags & RST != 0 && !self.ended {
            self.ended = true;
            self.event(packet, utc_us, Happening::Close(Ending::Reset(end)));
        }
    }

    /// Delivers payload at sequence number `seq` from `end`.
    fn data(&mut self, end: usize, seq: u32, payload: &[u8], packet: usize, utc_us: u64) {
        let h = &mut self.halves[end];
        if !h.started {
            // Caught mid-way: the first segment seen sets the sequence space.
            h.started = true;
            h.next_seq = seq;
            h.next_off = 0;
            h.framer = Framer::new(true);
        }
        let mut off = offset(h, seq);
        let mut bytes = payload;
        if off < 0 {
            let before = off.unsigned_abs() as usize;
            if before >= bytes.len() {
                h.duplicate_bytes += bytes.len();
                return;
            }
            bytes = &bytes[before..];
            off = 0;
        }
        let off = off as u64;
        let end_off = off + bytes.len() as u64;
        if end_off <= h.next_off {
            h.duplicate_bytes += bytes.len();
            return;
        }
        let mut out = Vec::new();
        if off > h.next_off {
            hold(h, off, bytes);
        } else {
            let fresh = &bytes[(h.next_off - off) as usize..];
            h.duplicate_bytes += bytes.len() - fresh.len();
            advance(h, fresh, &mut out);
        }
        drain_held(h, &mut out);
        while h.held_bytes > MAX_HELD {
            let Some((gap, held)) = skip_gap(h, &mut out) else {
                break;
            };
            self.warnings.push(format!(
                "{} <-> {}: {gap} bytes from {} were never captured; the {held} bytes after them \
                 passed the out-of-order bound ({} MiB), so the stream goes on after the gap, \
                 from its next LLRP header",
                self.ends[0],
                self.ends[1],
                self.ends[end],
                MAX_HELD >> 20
            ));
            drain_held(h, &mut out);
        }
        if h.first_frame.is_none() {
            // A copy: a view would keep the framer's whole buffer of that time alive.
            h.first_frame = out.iter().find_map(|p| match p {
                Piece::Frame(f) => Some(Bytes::copy_from_slice(f)),
                Piece::Bytes(_) => None,
            });
        }
        for piece in out {
            self.event(packet, utc_us, Happening::Data { end, piece });
        }
    }

    /// Marks `end` closed once its FIN is reached; the connection ends when both are.
    fn check_fin(&mut self, end: usize, packet: usize, utc_us: u64) {
        let h = &mut self.halves[end];
        if h.closed || h.fin_at != Some(h.next_off) {
            return;
        }
        h.closed = true;
        let other_closed = self.halves[1 - end].closed;
        if !self.ended && other_closed {
            self.ended = true;
            // The other end closed first.
            self.event(packet, utc_us, Happening::Close(Ending::Fin(1 - end)));
        }
    }

    /// At the end of the capture: what is left in the framers, gaps never filled, a
    /// connection closed by one end only.
    fn finish(&mut self, packet: usize, utc_us: u64) {
        let name = format!("{} <-> {}", self.ends[0], self.ends[1]);
        for end in 0..2 {
            let h = &mut self.halves[end];
            if let Some((&at, _)) = h.held.first_key_value() {
                let bytes: usize = h.held.values().map(Vec::len).sum();
                self.warnings.push(format!(
                    "{name}: {} bytes from {} were never captured; the {bytes} bytes after them are dropped",
                    at - h.next_off,
                    self.ends[end]
                ));
                h.held.clear();
                h.held_bytes = 0;
            }
            let (at_start, after_gaps) = if h.gaps == 0 {
                (h.framer.skipped, 0)
            } else {
                (h.skipped_at_start, h.skipped_after_gaps + h.framer.skipped)
            };
            if at_start > 0 {
                self.warnings.push(format!(
                    "{name}: the capture starts inside the stream; {at_start} bytes from {} before the first LLRP header are dropped",
                    self.ends[end]
                ));
            }
            if after_gaps > 0 {
                self.warnings.push(format!(
                    "{name}: {after_gaps} bytes from {} after its gaps, before the next LLRP header, are dropped",
                    self.ends[end]
                ));
            }
            if let Some(rest) = h.framer.finish() {
                self.warnings.push(format!(
                    "{name}: the stream from {} ends inside a frame; its last {} bytes are kept as bytes",
                    self.ends[end],
                    rest.len()
                ));
                self.event(
                    packet,
                    utc_us,
                    Happening::Data {
                        end,
                        piece: Piece::Bytes(rest),
                    },
                );
            }
        }
        if !self.ended {
            let closed: Vec<usize> = (0..2).filter(|&e| self.halves[e].closed).collect();
            if let [e] = closed[..] {
                self.ended = true;
                self.event(packet, utc_us, Happening::Close(Ending::Fin(e)));
            }
        }
    }

    /// Which end is the reader (index into [`Stream::ends`]), and the rule that decided:
    /// the end whose first frame is READER_EVENT_NOTIFICATION; else the end on an LLRP port
    /// (5084, 5085); else the end that accepted the SYN; else the end whose first frame is of
    /// a kind only readers send; else the end that sent the first byte.
    pub fn reader_end(&self) -> usize {
        let first = |e: usize| {
            self.halves[e]
                .first_frame
                .as_deref()
                .and_then(MessageKind::of_frame)
        };
        let one = |f: &dyn Fn(usize) -> bool| match (f(0), f(1)) {
            (true, false) => Some(0),
            (false, true) => Some(1),
            _ => None,
        };
        let notification = MessageKind::standard(63);
        one(&|e| first(e) == Some(notification))
            .or_else(|| one(&|e| LLRP_PORTS.contains(&self.ends[e].port())))
            .or(self.synack_from)
            .or(self.syn_from.map(|e| 1 - e))
            .or_else(|| one(&|e| first(e).is_some_and(|k| k.is_from_reader())))
            .or(self.first_data_from)
            .unwrap_or(1)
    }

    /// Whether the stream carries LLRP: one end is on an LLRP port, or a direction's first
    /// frame is a whole LLRP message of a known kind.
    pub fn is_llrp(&self) -> bool {
        self.ends.iter().any(|e| LLRP_PORTS.contains(&e.port()))
            || self
                .halves
                .iter()
                .any(|h| h.first_frame.as_deref().is_some_and(known_frame))
    }

    /// Whether the stream's kind and reader end can no longer change: it ended, or each
    /// direction has its first frame or will never have one.
    pub fn settled(&self) -> bool {
        self.ended || self.halves.iter().all(Half::settled)
    }

    /// Decides, once, whether the stream is LLRP and which end is the reader, from what is
    /// known now (the importer decides when [`Stream::settled`], at the end of the capture,
    /// or when the events waiting for the decision pass its bound).
    pub fn decide(&mut self) -> Role {
        if let Some(r) = self.role {
            return r;
        }
        let r = Role {
            llrp: self.is_llrp(),
            reader: self.reader_end(),
        };
        self.role = Some(r);
        r
    }

    /// Bytes that arrived twice (retransmissions), both ways.
    pub fn duplicate_bytes(&self) -> usize {
        self.halves.iter().map(|h| h.duplicate_bytes).sum()
    }
}

/// The stream offset of sequence number `seq` (negative: before the stream's start).
fn offset(h: &Half, seq: u32) -> i64 {
    h.next_off as i64 + i64::from(seq.wrapping_sub(h.next_seq) as i32)
}

/// Holds a segment at stream offset `off`, beyond a gap (the longer one if one is there).
fn hold(h: &mut Half, off: u64, bytes: &[u8]) {
    let held = h.held.entry(off).or_default();
    if held.len() < bytes.len() {
        h.held_bytes += bytes.len() - held.len();
        *held = bytes.to_vec();
    }
}

/// Delivers the held segments the stream has reached.
fn drain_held(h: &mut Half, out: &mut Vec<Piece>) {
    while let Some(first) = h.held.first_entry() {
        if *first.key() > h.next_off {
            break;
        }
        let (at, held) = first.remove_entry();
        h.held_bytes -= held.len();
        let skip = (h.next_off - at) as usize;
        if skip < held.len() {
            h.duplicate_bytes += skip;
            advance(h, &held[skip..], out);
        } else {
            h.duplicate_bytes += held.len();
        }
    }
}

/// Takes the gap before the first held segment as lost: the bytes of a frame cut by it are
/// kept as bytes and framing resumes at the next plausible header (a direction that is no
/// longer LLRP stays bytes). Returns the gap's length and the bytes held after it.
fn skip_gap(h: &mut Half, out: &mut Vec<Piece>) -> Option<(u64, usize)> {
    let (&at, _) = h.held.first_key_value()?;
    let gap = at - h.next_off;
    let held = h.held_bytes;
    if !h.framer.unsynced() {
        if let Some(rest) = h.framer.finish() {
            out.push(Piece::Bytes(rest));
        }
        if h.gaps == 0 {
            h.skipped_at_start = h.framer.skipped;
        } else {
            h.skipped_after_gaps += h.framer.skipped;
        }
        h.framer = Framer::new(true);
    }
    h.gaps += 1;
    h.next_off = at;
    // Sequence numbers are modulo 2^32.
    h.next_seq = h.next_seq.wrapping_add(gap as u32);
    Some((gap, held))
}

fn advance(h: &mut Half, bytes: &[u8], out: &mut Vec<Piece>) {
    h.next_off += bytes.len() as u64;
    // Sequence numbers are modulo 2^32.
    h.next_seq = h.next_seq.wrapping_add(bytes.len() as u32);
    h.framer.push(bytes, out);
}

/// Every TCP stream of a capture, in order of their first packet.
#[derive(Debug, Default)]
pub struct Streams {
    /// The streams.
    pub streams: Vec<Stream>,
    /// The open stream of each pair of ends (ordered).
    by_ends: HashMap<(SocketAddr, SocketAddr), usize>,
}

impl Streams {
    /// Takes one captured segment; returns the index of its stream.
    pub fn segment(&mut self, seg: &InSegment<'_>, packet: usize, utc_us: u64) -> usize {
        let key = if seg.src <= seg.dst {
            (seg.src, seg.dst)
        } else {
            (seg.dst, seg.src)
        };
        let fresh_syn = seg.flags & (SYN | ACK) == SYN;
        let index = match self.by_ends.get(&key) {
            // A new SYN on the ports of an ended connection, or with another initial
            // sequence number, starts a new connection.
            Some(&i)
                if !(fresh_syn
                    && (self.streams[i].ended
                        || self.streams[i].syn_seq.is_some_and(|s| s != seg.seq))) =>
            {
                i
            }
            _ => {
                self.streams.push(Stream::new([seg.src, seg.dst]));
                self.by_ends.insert(key, self.streams.len() - 1);
                self.streams.len() - 1
            }
        };
        let s = &mut self.streams[index];
        let end = usize::from(s.ends[0] != seg.src);
        s.segment(end, seg, packet, utc_us);
        index
    }

    /// Ends the capture: flushes what each stream holds (bytes left in a framer, gaps never
    /// filled) and closes streams that only one end closed.
    pub fn finish(&mut self, packet: usize, utc_us: u64) {
        for s in &mut self.streams {
            s.finish(packet, utc_us);
        }
    }
}

#[cfg(test)]
mod tests;
