//! The recording an import writes as it goes. The streams' events wait in one queue, in
//! capture order, until their stream is known to be LLRP or not (and which end is the
//! reader); then the head of the queue is written, connection numbers given in order of the
//! streams' first packets. The queue is bounded ([`MAX_QUEUED`]): past it, the stream at its
//! head is decided with what is known so far.

use std::collections::{HashMap, VecDeque};
use std::net::SocketAddr;

use super::stream::{Ending, Event as StreamEvent, Happening, Piece, Role, Stream, Streams};
use crate::record::format::{Direction, Entry, Event, Header, Recording, Stamp};

/// Bytes of events waiting for their stream's decision, at most.
pub const MAX_QUEUED: usize = 16 << 20;

/// Where an import's recording goes: the header (once, before the first entry), then each
/// entry in order.
pub trait Sink {
    /// Takes the header.
    fn header(&mut self, header: &Header) -> std::io::Result<()>;
    /// Takes the next entry.
    fn entry(&mut self, entry: &Entry) -> std::io::Result<()>;
}

impl Sink for Recording {
    fn header(&mut self, header: &Header) -> std::io::Result<()> {
        self.header = header.clone();
        Ok(())
    }

    fn entry(&mut self, entry: &Entry) -> std::io::Result<()> {
        self.entries.push(entry.clone());
        Ok(())
    }
}

/// A recording written as JSON Lines to a `Write`.
pub struct JsonLines<W: std::io::Write>(pub W);

impl<W: std::io::Write> Sink for JsonLines<W> {
    fn header(&mut self, header: &Header) -> std::io::Result<()> {
        let mut buf = Vec::new();
        crate::record::format::encode_header(header, &mut buf);
        self.0.write_all(&buf)
    }

    fn entry(&mut self, entry: &Entry) -> std::io::Result<()> {
        let mut buf = Vec::new();
        crate::record::format::encode_entry(entry, &mut buf);
        self.0.write_all(&buf)
    }
}

/// The events waiting, and what was written.
pub struct Emitter<'s, S: Sink> {
    sink: &'s mut S,
    /// The capture's first packet's time: `t_us` 0.
    pub start_us: u64,
    queue: VecDeque<(usize, StreamEvent)>,
    queued_bytes: usize,
    /// Each LLRP stream's connection number, from its first entry written.
    conns: HashMap<usize, u32>,
    /// The first LLRP stream's reader (the recording's `upstream`).
    pub upstream: Option<SocketAddr>,
    /// Every reader, in order of first appearance.
    pub readers: Vec<SocketAddr>,
    /// Frames written.
    pub frames: usize,
}

/// The bytes an event holds (a frame's or bytes' length; a marker counts as a few).
fn weight(e: &StreamEvent) -> usize {
    match &e.what {
        Happening::Data {
            piece: Piece::Frame(b) | Piece::Bytes(b),
            ..
        } => b.len() + 64,
        _ => 64,
    }
}

impl<'s, S: Sink> Emitter<'s, S> {
    /// An emitter writing to `sink`, the capture starting at `start_us`.
    pub fn new(sink: &'s mut S, start_us: u64) -> Self {
        Emitter {
            sink,
            start_us,
            queue: VecDeque::new(),
            queued_bytes: 0,
            conns: HashMap::new(),
            upstream: None,
            readers: Vec::new(),
            frames: 0,
        }
    }

    /// Connections written.
    pub fn connections(&self) -> usize {
        self.conns.len()
    }

    /// Takes the new events of stream `index` (a stream found not to be LLRP drops them).
    pub fn take(&mut self, streams: &mut Streams, index: usize) {
        let s = &mut streams.streams[index];
        if s.role.is_some_and(|r| !r.llrp) {
            s.events.clear();
            return;
        }
        for e in s.events.drain(..) {
            self.queued_bytes += weight(&e);
            self.queue.push_back((index, e));
        }
    }

    /// Writes the head of the queue as far as its streams are decided; with `all` (the end
    /// of the capture) every stream is decided and the queue emptied.
    pub fn flush(&mut self, streams: &mut Streams, all: bool) -> std::io::Result<()> {
        while let Some((index, _)) = self.queue.front() {
            let s = &mut streams.streams[*index];
            let role = match s.role {
                Some(r) => r,
                None if all || s.settled() || self.queued_bytes > MAX_QUEUED => s.decide(),
                None => break,
            };
            let Some((index, e)) = self.queue.pop_front() else {
                break;
            };
            self.queued_bytes -= weight(&e);
            if role.llrp {
                self.write(&streams.streams[index], index, role, &e)?;
            }
        }
        Ok(())
    }

    /// Writes event `e` of LLRP stream `s` (the header first, before the first entry).
    fn write(
        &mut self,
        s: &Stream,
        index: usize,
        role: Role,
        e: &StreamEvent,
    ) -> std::io::Result<()> {
        let reader_addr = s.ends[role.reader];
        if self.upstream.is_none() {
            self.upstream = Some(reader_addr);
            let header = Header::new(reader_addr.to_string(), self.start_us);
            self.sink.header(&header)?;
        }
        let next = self.conns.len() as u32 + 1;
        let conn = *self.conns.entry(index).or_insert(next);
        if !self.readers.contains(&reader_addr) {
            self.readers.push(reader_addr);
        }
        let entry = entry(s, role, conn, self.start_us, e);
        self.frames += usize::from(matches!(entry, Entry::Frame { .. }));
        self.sink.entry(&entry)
    }
}

/// The recording's entry for event `e` of stream `s`, connection `conn`.
fn entry(s: &Stream, role: Role, conn: u32, start_us: u64, e: &StreamEvent) -> Entry {
    let reader = role.reader;
    let client_addr = s.ends[1 - reader];
    let name = |end: usize| if end == reader { "reader" } else { "client" };
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
    match &e.what {
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
                Ending::Fin(end) => format!("{} closed", name(*end)),
                Ending::Reset(end) => format!("reset by the {}", name(*end)),
            },
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::record::pcapng::packet::{InSegment, ACK, PSH, SYN};

    fn seg(seq: u32, flags: u8, payload: &[u8]) -> InSegment<'_> {
        InSegment {
            src: "10.1.1.1:51000".parse().expect("addr"),
            dst: "10.1.1.2:5084".parse().expect("addr"),
            seq,
            ack: 0,
            flags,
            payload,
        }
    }

    #[test]
    fn a_stream_that_never_settles_is_written_once_its_events_pass_the_bound() {
        // The client sends 1 MiB frames; the reader never answers, so the stream is not
        // settled (its reader end might still send a READER_EVENT_NOTIFICATION first).
        let mut frame = vec![0x04, 0x48];
        frame.extend_from_slice(&(1u32 << 20).to_be_bytes());
        frame.resize(1 << 20, 0);
        let mut recording = Recording {
            header: Header::new(String::new(), 0),
            entries: Vec::new(),
            warnings: Vec::new(),
        };
        let mut streams = Streams::default();
        let mut emitter = Emitter::new(&mut recording, 0);
        let mut seq = 100;
        let i = streams.segment(&seg(seq, SYN, &[]), 0, 0);
        seq += 1;
        let mut written_at = None;
        for packet in 1..=20 {
            streams.segment(&seg(seq, PSH | ACK, &frame), packet, 0);
            seq += frame.len() as u32;
            emitter.take(&mut streams, i);
            emitter.flush(&mut streams, false).expect("writes");
            if written_at.is_none() && emitter.frames > 0 {
                written_at = Some(packet);
            }
        }
        assert!(!streams.streams[i].settled());
        // 16 frames of 1 MiB and the connect marker are past the 16 MiB.
        assert_eq!(written_at, Some(16), "written once past 16 MiB waiting");
        assert_eq!(emitter.frames, 20, "and from then on as it comes");
        assert_eq!(
            emitter.upstream,
            Some("10.1.1.2:5084".parse().expect("addr"))
        );
    }
}
