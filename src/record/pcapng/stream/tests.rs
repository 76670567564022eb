//! Unit tests of the parent module.

use super::*;
use llrp::message::{Keepalive, KeepaliveAck};
use llrp::Message;

fn frame(id: u32) -> Vec<u8> {
    Message::new(id, KeepaliveAck::default())
        .to_bytes()
        .to_vec()
}

fn seg<'a>(from_client: bool, seq: u32, flags: u8, payload: &'a [u8]) -> InSegment<'a> {
    let (c, r) = ("10.1.1.1:51000", "10.1.1.2:6000");
    let (src, dst) = if from_client { (c, r) } else { (r, c) };
    InSegment {
        src: src.parse().expect("addr"),
        dst: dst.parse().expect("addr"),
        seq,
        ack: 0,
        flags,
        payload,
    }
}

fn frames_of(s: &Stream, end: usize) -> Vec<Bytes> {
    s.events
        .iter()
        .filter_map(|e| match &e.what {
            Happening::Data {
                end: x,
                piece: Piece::Frame(f),
            } if *x == end => Some(f.clone()),
            _ => None,
        })
        .collect()
}

#[test]
fn out_of_order_duplicate_and_wrapping_segments_reassemble() {
    let mut wire = Vec::new();
    for id in 1..=5 {
        wire.extend_from_slice(&frame(id));
    }
    let isn = u32::MAX - 20; // the sequence numbers wrap inside the stream
    let mut st = Streams::default();
    st.segment(&seg(true, isn, SYN, &[]), 0, 0);
    st.segment(&seg(false, 500, SYN | ACK, &[]), 1, 0);
    let start = isn.wrapping_add(1);
    let at = |o: usize| start.wrapping_add(o as u32);
    // Pieces of 7 bytes: the third before the second, the first twice, one overlapping.
    st.segment(&seg(true, at(0), ACK, &wire[0..7]), 2, 1);
    st.segment(&seg(true, at(14), ACK, &wire[14..21]), 3, 2);
    st.segment(&seg(true, at(0), ACK, &wire[0..7]), 4, 3);
    st.segment(&seg(true, at(7), ACK, &wire[7..14]), 5, 4);
    st.segment(&seg(true, at(10), ACK, &wire[10..30]), 6, 5);
    st.segment(&seg(true, at(30), ACK | FIN, &wire[30..]), 7, 6);
    st.segment(&seg(false, 501, ACK | FIN, &[]), 8, 7);
    st.finish(9, 8);
    let s = &st.streams[0];
    let got = frames_of(s, 0);
    assert_eq!(got.len(), 5);
    assert_eq!(got.concat(), wire);
    assert_eq!(s.duplicate_bytes(), 7 + 11);
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    // The client's FIN came first; the close is the last event.
    assert_eq!(
        s.events.last().map(|e| &e.what),
        Some(&Happening::Close(Ending::Fin(0)))
    );
    // Not on port 5084 and the reader sent nothing: the SYN-ACK decides.
    assert_eq!(s.reader_end(), 1);
}

#[test]
fn a_gap_never_filled_is_reported_and_a_reset_ends_the_stream() {
    let f = frame(1);
    let mut st = Streams::default();
    st.segment(&seg(true, 100, SYN, &[]), 0, 0);
    st.segment(&seg(true, 101, ACK, &f), 1, 0);
    st.segment(&seg(true, 101 + 30, ACK, &f), 2, 0);
    st.segment(&seg(false, 9, RST, &[]), 3, 0);
    st.finish(4, 0);
    let s = &st.streams[0];
    assert_eq!(frames_of(s, 0).len(), 1);
    assert_eq!(s.warnings.len(), 1, "{:?}", s.warnings);
    assert!(s.warnings[0].contains("20 bytes from 10.1.1.1:51000 were never captured"));
    assert!(s
        .events
        .iter()
        .any(|e| e.what == Happening::Close(Ending::Reset(1))));
}

#[test]
fn the_end_that_sends_reader_event_notification_first_is_the_reader() {
    // A reader-initiated connection: the reader connects out, to the client's port 5084.
    let hello = Message::new(1, llrp::message::ReaderEventNotification::default()).to_bytes();
    let ka = Message::new(2, Keepalive::default()).to_bytes();
    let mut st = Streams::default();
    let r = "10.1.1.2:40000".parse().expect("addr");
    let c = "10.1.1.1:5084".parse().expect("addr");
    let s = |src, dst, seq, flags, payload| InSegment {
        src,
        dst,
        seq,
        ack: 0,
        flags,
        payload,
    };
    st.segment(&s(r, c, 1, SYN, &[]), 0, 0);
    st.segment(&s(c, r, 1, SYN | ACK, &[]), 1, 0);
    st.segment(&s(r, c, 2, ACK, &hello), 2, 0);
    st.segment(&s(r, c, 2 + hello.len() as u32, ACK, &ka), 3, 0);
    st.finish(4, 0);
    assert_eq!(st.streams[0].ends[st.streams[0].reader_end()], r);
    assert!(st.streams[0].is_llrp());
}

#[test]
fn a_stream_caught_mid_way_resynchronises_at_the_first_header() {
    let mut wire = frame(1);
    wire.extend_from_slice(&frame(2));
    let mut st = Streams::default();
    // The first 4 bytes were sent before the capture started.
    st.segment(&seg(true, 1004, ACK, &wire[4..12]), 0, 0);
    st.segment(&seg(true, 1012, ACK, &wire[12..]), 1, 0);
    st.finish(2, 0);
    let s = &st.streams[0];
    assert_eq!(frames_of(s, 0), vec![Bytes::from(frame(2))]);
    assert_eq!(s.events[0].what, Happening::Open { syn: false });
    assert!(
        s.warnings.iter().any(|w| w.contains("6 bytes")),
        "{:?}",
        s.warnings
    );
}

#[test]
fn after_a_bad_length_everything_is_bytes() {
    let mut f = Framer::new(false);
    let mut out = Vec::new();
    f.push(&frame(1), &mut out);
    f.push(b"GET / HTTP/1.1\r\n", &mut out);
    f.push(b"Host: x\r\n", &mut out);
    assert_eq!(
        out,
        vec![
            Piece::Frame(Bytes::from(frame(1))),
            Piece::Bytes(Bytes::from_static(b"GET / HTTP/1.1\r\n")),
            Piece::Bytes(Bytes::from_static(b"Host: x\r\n")),
        ]
    );
    assert_eq!(f.finish(), None);
}

/// A KEEPALIVE_ACK header claiming `len` bytes, then filler: a whole frame to the splitter.
fn big_frame(id: u32, len: usize) -> Vec<u8> {
    let mut f = vec![0x04, 0x48];
    f.extend_from_slice(&(len as u32).to_be_bytes());
    f.extend_from_slice(&id.to_be_bytes());
    f.resize(len, 0x5A);
    f
}

#[test]
fn the_events_of_one_packet_are_numbered_in_order() {
    let mut wire = Vec::new();
    for id in 1..=4 {
        wire.extend_from_slice(&frame(id));
    }
    let mut st = Streams::default();
    st.segment(&seg(true, 100, SYN, &[]), 0, 0);
    st.segment(&seg(true, 101, ACK, &wire), 1, 0);
    let at: Vec<(usize, usize)> = st.streams[0].events.iter().map(|e| e.at).collect();
    assert_eq!(at, [(0, 0), (1, 0), (1, 1), (1, 2), (1, 3)]);
}

#[test]
fn a_gap_past_the_out_of_order_bound_is_reported_and_the_stream_goes_on_after_it() {
    const MIB: usize = 1 << 20;
    let lost = frame(1);
    let mut st = Streams::default();
    st.segment(&seg(true, 100, SYN, &[]), 0, 0);
    // The first frame is never captured; 9 frames of 1 MiB follow it.
    let mut seq = 101 + lost.len() as u32;
    for i in 0..9 {
        let f = big_frame(i + 2, MIB);
        st.segment(&seg(true, seq, ACK, &f), 1 + i as usize, 0);
        seq = seq.wrapping_add(f.len() as u32);
    }
    let s = &st.streams[0];
    assert_eq!(frames_of(s, 0).len(), 9, "delivered once past the bound");
    assert_eq!(s.warnings.len(), 1, "{:?}", s.warnings);
    assert!(
        s.warnings[0].contains("10 bytes from 10.1.1.1:51000 were never captured")
            && s.warnings[0].contains("out-of-order bound (8 MiB)"),
        "{:?}",
        s.warnings
    );
    st.finish(10, 0);
    assert_eq!(st.streams[0].warnings.len(), 1, "nothing else dropped");
}
