//! Unit tests of the parent module.

use super::*;
use llrp::message::KeepaliveAck;
use llrp::Message;

fn sample() -> (Header, Vec<Entry>) {
    let at = |t| Stamp {
        t_us: t,
        utc_us: 1_700_000_000_000_000 + t,
    };
    let frame = Message::new(7, KeepaliveAck::default()).to_bytes().freeze();
    let entries = vec![
        Entry::Marker {
            at: at(0),
            conn: 1,
            event: Event::Connect,
            reason: "client 127.0.0.1:5000".into(),
        },
        Entry::Frame {
            at: at(10),
            conn: 1,
            dir: Direction::ToReader,
            frame,
            undecodable: None,
        },
        Entry::Bytes {
            at: at(11),
            conn: 1,
            dir: Direction::FromReader,
            bytes: Bytes::from_static(b"GET / HTTP/1.1\r\n"),
        },
        Entry::Frame {
            at: at(11),
            conn: 1,
            dir: Direction::FromReader,
            frame: Bytes::from_static(&[0x04, 0x3e, 0, 0, 0, 12, 0, 0, 0, 9, 0xff, 0xff]),
            undecodable: Some("KEEPALIVE_ACK: 2 bytes after the message body".into()),
        },
        Entry::Reader {
            at: at(12),
            conn: 1,
            reader: ReaderInfo {
                manufacturer: Some(25882),
                ..ReaderInfo::default()
            },
        },
        Entry::Marker {
            at: at(20),
            conn: 1,
            event: Event::Disconnect,
            reason: "client closed".into(),
        },
    ];
    (
        Header::new("127.0.0.1:5084", 1_700_000_000_000_000),
        entries,
    )
}

fn encode(header: &Header, entries: &[Entry]) -> Vec<u8> {
    let mut out = Vec::new();
    encode_header(header, &mut out);
    for e in entries {
        encode_entry(e, &mut out);
    }
    out
}

#[test]
fn every_kind_of_line_round_trips() {
    let (header, entries) = sample();
    let text = encode(&header, &entries);
    let r = Recording::read(&text[..]).expect("reads");
    assert_eq!(r.header, header);
    assert_eq!(r.entries, entries);
    assert!(r.warnings.is_empty());
    assert_eq!(r.connections(), vec![1]);
    assert_eq!(r.frames(1).count(), 2);
}

#[test]
fn the_fast_frame_line_is_the_json_serde_writes() {
    let (_, entries) = sample();
    for e in &entries[1..3] {
        let mut fast = Vec::new();
        encode_entry(e, &mut fast);
        let (at, conn) = (e.at(), e.conn());
        let mut line = Line {
            t_us: at.t_us,
            utc_us: at.utc_us,
            conn,
            ..Line::default()
        };
        match e {
            Entry::Frame { dir, frame, .. } => {
                line.dir = Some(*dir);
                line.frame = Some(BASE64.encode(frame));
            }
            Entry::Bytes { dir, bytes, .. } => {
                line.dir = Some(*dir);
                line.bytes = Some(BASE64.encode(bytes));
            }
            _ => unreachable!("entries 1 and 2 are a frame and bytes"),
        }
        let mut serde = serde_json::to_vec(&line).expect("serialises");
        serde.push(b'\n');
        assert_eq!(String::from_utf8(fast), String::from_utf8(serde));
    }
}

#[test]
fn a_truncated_last_line_is_dropped_with_a_warning() {
    let (header, entries) = sample();
    let mut text = encode(&header, &entries);
    text.truncate(text.len() - 9); // cut into the last marker, its line end gone
    let r = Recording::read(&text[..]).expect("tolerated");
    assert_eq!(r.entries, entries[..entries.len() - 1]);
    assert_eq!(r.warnings.len(), 1, "{:?}", r.warnings);
    assert!(r.warnings[0].contains("truncated"), "{:?}", r.warnings);
}

#[test]
fn a_bad_line_in_the_middle_is_an_error_naming_line_and_field() {
    let (header, entries) = sample();
    let text = String::from_utf8(encode(&header, &entries)).expect("utf-8");
    let text = text.replacen("\"dir\":\"to_reader\"", "\"dir\":\"sideways\"", 1);
    match Recording::read(text.as_bytes()) {
        Err(RecordError::Line { line: 3, message }) => {
            assert!(message.starts_with("dir:"), "{message}")
        }
        other => panic!("expected a line-3 error, got {other:?}"),
    }
}

#[test]
fn another_format_version_is_refused_by_number() {
    let (mut header, entries) = sample();
    header.llrp_recording = 2;
    let e = Recording::read(&encode(&header, &entries)[..]).expect_err("version 2");
    assert!(
        matches!(&e, RecordError::Version { found } if found == "2"),
        "{e:?}"
    );
    assert!(e.to_string().contains("reads version 1"), "{e}");
    // A version beyond u64 is named as written, not taken for a missing one.
    let big = String::from_utf8(encode(&header, &entries))
        .expect("utf-8")
        .replacen(
            "\"llrp_recording\":2",
            "\"llrp_recording\":18446744073709551616",
            1,
        );
    let e = Recording::read(big.as_bytes()).expect_err("beyond u64");
    assert_eq!(
        e.to_string(),
        "recording format version 18446744073709551616 is not supported: this llrp-gateway reads version 1"
    );
    let e = Recording::read(&b"{\"llrp_recording\":\"1\"}\n"[..]).expect_err("a string");
    assert!(e.to_string().contains("is not a format version"), "{e}");
    let e = Recording::read(&b"{\"hello\":1}\n"[..]).expect_err("not a recording");
    assert!(e.to_string().contains("llrp_recording"), "{e}");
}

#[test]
fn a_frame_line_must_hold_exactly_one_frame() {
    let line = format!(
        "{{\"t_us\":1,\"utc_us\":1,\"conn\":1,\"dir\":\"to_reader\",\"frame\":\"{}\"}}\n",
        BASE64.encode([4u8, 62, 0, 0])
    );
    let mut text = Vec::new();
    encode_header(&Header::new("x", 0), &mut text);
    text.extend_from_slice(line.as_bytes());
    let e = Recording::read(&text[..]).expect_err("4 bytes");
    assert!(e.to_string().contains("line 2: frame:"), "{e}");
}
