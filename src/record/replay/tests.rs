//! Unit tests of the parent module.

use super::*;
use crate::record::format::{Header, Stamp};
use llrp::message::{
    EnableRospec, EnableRospecResponse, GetReaderConfig, GetReaderConfigResponse, GetRospecs,
    GetRospecsResponse, Keepalive,
};
use llrp::params::{FirstSeenTimestampUtc, TagReportData};

fn ok() -> LlrpStatus {
    LlrpStatus::new(StatusCode::M_Success, "")
}

fn report(id: u32, first_seen_utc: u64) -> Bytes {
    let data = TagReportData {
        first_seen_timestamp_utc: Some(FirstSeenTimestampUtc(first_seen_utc)),
        ..Default::default()
    };
    Message::new(
        id,
        RoAccessReport {
            tag_report_data: vec![data],
            ..Default::default()
        },
    )
    .to_bytes()
    .freeze()
}

fn frame(t_us: u64, dir: Direction, m: Message) -> Entry {
    Entry::Frame {
        at: Stamp { t_us, utc_us: t_us },
        conn: 1,
        dir,
        frame: m.to_bytes().freeze(),
        undecodable: None,
    }
}

/// The script of [`recording`].
pub(super) fn script_for_server() -> Script {
    Script::new(&recording(), None).expect("script")
}

/// A recording: greeting keepalive at 5 ms; GET_READER_CONFIG (id 7) answered; ENABLE_ROSPEC
/// (id 8) at 100 ms answered, then three reports 10, 20 and 30 ms after it.
fn recording() -> Recording {
    use Direction::*;
    let mut entries = vec![
        Entry::Marker {
            at: Stamp::default(),
            conn: 1,
            event: crate::record::Event::Connect,
            reason: "client".into(),
        },
        frame(5_000, FromReader, Message::new(900, Keepalive::default())),
        frame(
            50_000,
            ToReader,
            Message::new(7, GetReaderConfig::default()),
        ),
        frame(
            51_000,
            FromReader,
            Message::new(7, GetReaderConfigResponse::with_status(ok())),
        ),
        frame(100_000, ToReader, Message::new(8, EnableRospec::default())),
        frame(
            100_500,
            FromReader,
            Message::new(8, EnableRospecResponse::with_status(ok())),
        ),
    ];
    for (i, dt) in [10_000u64, 20_000, 30_000].iter().enumerate() {
        entries.push(Entry::Frame {
            at: Stamp {
                t_us: 100_000 + dt,
                utc_us: 0,
            },
            conn: 1,
            dir: FromReader,
            frame: report(901 + i as u32, 1_000_000 + dt),
            undecodable: None,
        });
    }
    Recording {
        header: Header::new("test", 0),
        entries,
        warnings: Vec::new(),
    }
}

fn frames(bytes: &[u8]) -> Vec<Message> {
    let mut rest = bytes;
    let mut out = Vec::new();
    while let Some(h) = FrameHeader::peek(rest) {
        let len = h.length as usize;
        out.push(Message::decode(&rest[..len]).expect("decodes"));
        rest = &rest[len..];
    }
    out
}

fn take(s: &mut ReplaySession) -> Vec<Message> {
    let out = std::mem::take(&mut s.transmit().bytes);
    frames(&out)
}

#[test]
fn the_greeting_then_answers_with_the_clients_ids_then_reports_at_their_offsets() {
    let script = Script::new(&recording(), None).expect("script");
    let opts = ReplayOptions {
        speed: Some(1.0),
        looped: false,
    };
    // The client connects at t = 1 s of its own clock.
    let t0 = 1_000_000;
    let mut s = ReplaySession::new(std::sync::Arc::new(script.clone()), opts, t0);
    s.advance(t0 + 4_999, usize::MAX);
    assert!(take(&mut s).is_empty(), "the greeting is due at 5 ms");
    s.advance(t0 + 5_000, usize::MAX);
    assert!(matches!(
        take(&mut s)[..],
        [Message {
            id: 900,
            body: MessageBody::Keepalive(_),
            ..
        }]
    ));
    let req = Message::new(42, GetReaderConfig::default()).to_bytes();
    s.receive(&req, t0 + 6_000);
    let got = take(&mut s);
    assert_eq!(got.len(), 1);
    assert_eq!(got[0].id, 42, "the client's ID, not the recorded 7");
    assert!(matches!(
        got[0].body,
        MessageBody::GetReaderConfigResponse(_)
    ));
    let enable = Message::new(43, EnableRospec::default()).to_bytes();
    let at = t0 + 200_000;
    s.receive(&enable, at);
    assert_eq!(take(&mut s)[0].id, 43);
    assert_eq!(s.deadline(), Some(at + 10_000));
    s.advance(at + 15_000, usize::MAX);
    let got = take(&mut s);
    assert_eq!(got.iter().map(|m| m.id).collect::<Vec<_>>(), vec![901]);
    s.advance(at + 30_000, usize::MAX);
    assert_eq!(
        take(&mut s).iter().map(|m| m.id).collect::<Vec<_>>(),
        vec![902, 903]
    );
    assert_eq!(s.deadline(), None);
    assert!(s.divergence().is_none());
}

#[test]
fn speed_divides_the_recorded_offsets() {
    let script = Script::new(&recording(), None).expect("script");
    let opts = ReplayOptions {
        speed: Some(4.0),
        looped: false,
    };
    let mut s = ReplaySession::new(std::sync::Arc::new(script.clone()), opts, 0);
    s.receive(&Message::new(1, EnableRospec::default()).to_bytes(), 1_000);
    take(&mut s);
    assert_eq!(s.deadline(), Some(1_250), "the greeting, 5 ms / 4");
    s.advance(1_250, usize::MAX);
    assert_eq!(take(&mut s).len(), 1);
    assert_eq!(
        s.deadline(),
        Some(1_000 + 2_500),
        "the first report, 10 ms / 4 on"
    );
    s.advance(1_000 + 7_500, usize::MAX);
    // All three reports (10, 20, 30 ms / 4) are due.
    assert_eq!(take(&mut s).len(), 3);
}

#[test]
fn a_request_the_recording_never_answered_gets_the_readers_error_and_is_logged_once() {
    let script = Script::new(&recording(), None).expect("script");
    let mut s = ReplaySession::new(
        std::sync::Arc::new(script.clone()),
        ReplayOptions {
            speed: None,
            looped: false,
        },
        0,
    );
    s.receive(&Message::new(5, GetRospecs::default()).to_bytes(), 0);
    s.receive(&Message::new(6, GetRospecs::default()).to_bytes(), 0);
    let got = take(&mut s);
    let statuses: Vec<_> = got
        .iter()
        .filter(|m| matches!(m.body, MessageBody::GetRospecsResponse(_)))
        .map(|m| (m.id, m.body.status().map(|s| s.status_code)))
        .collect();
    assert_eq!(
        statuses,
        vec![
            (5, Some(StatusCode::M_UnsupportedMessage)),
            (6, Some(StatusCode::M_UnsupportedMessage))
        ]
    );
    let first = s.divergence().expect("diverged");
    assert!(
        first.contains("GET_ROSPECS") && first.contains("#1"),
        "{first}"
    );
    let _ = GetRospecsResponse::default();
}

#[test]
fn close_connection_is_answered_and_ends_the_session() {
    let script = Script::new(&recording(), None).expect("script");
    let mut s = ReplaySession::new(
        std::sync::Arc::new(script.clone()),
        ReplayOptions {
            speed: None,
            looped: false,
        },
        0,
    );
    s.receive(&Message::new(77, CloseConnection::default()).to_bytes(), 0);
    assert!(s.closing());
    let got = take(&mut s);
    assert!(matches!(
        got[..],
        [Message {
            id: 77,
            body: MessageBody::CloseConnectionResponse(_),
            ..
        }]
    ));
    assert_eq!(s.deadline(), None, "nothing more is sent");
}

#[test]
fn a_loop_repeats_the_reports_with_timestamps_shifted_by_the_streams_length() {
    let script = Script::new(&recording(), None).expect("script");
    let opts = ReplayOptions {
        speed: Some(1.0),
        looped: true,
    };
    let mut s = ReplaySession::new(std::sync::Arc::new(script.clone()), opts, 0);
    s.receive(&Message::new(1, EnableRospec::default()).to_bytes(), 0);
    s.advance(30_000, usize::MAX);
    let first: Vec<_> = take(&mut s);
    assert_eq!(first.len(), 1 + 1 + 3, "greeting, response, three reports");
    // The stream (reports 10..30 ms, 10 ms apart) lasts 30 ms: round two is 30 ms later,
    // its first report at 40 ms.
    s.advance(30_000 + 9_999, usize::MAX);
    assert!(take(&mut s).is_empty());
    s.advance(30_000 + 40_000, usize::MAX);
    let again = take(&mut s);
    let seen: Vec<u64> = again
        .iter()
        .filter_map(|m| match &m.body {
            MessageBody::RoAccessReport(r) => r.tag_report_data[0]
                .first_seen_timestamp_utc
                .as_ref()
                .map(|t| t.0),
            _ => None,
        })
        .collect();
    assert_eq!(
        seen,
        vec![1_010_000 + 30_000, 1_020_000 + 30_000, 1_030_000 + 30_000]
    );
}

#[test]
fn by_default_a_port_probe_before_the_session_is_passed_over_and_listed_as_such() {
    use Direction::*;
    // Connection 1: a health check that got the reader's greeting and left; 2: the session.
    let mut rec = recording();
    for e in &mut rec.entries {
        if let Entry::Frame { conn, .. } | Entry::Marker { conn, .. } = e {
            *conn = 2;
        }
    }
    let probe = vec![
        Entry::Marker {
            at: Stamp::default(),
            conn: 1,
            event: crate::record::Event::Connect,
            reason: "client 10.0.0.9:40000".into(),
        },
        Entry::Frame {
            at: Stamp::default(),
            conn: 1,
            dir: FromReader,
            frame: Message::new(0, Keepalive::default()).to_bytes().freeze(),
            undecodable: None,
        },
        Entry::Marker {
            at: Stamp::default(),
            conn: 1,
            event: crate::record::Event::Disconnect,
            reason: "client closed".into(),
        },
    ];
    rec.entries.splice(0..0, probe);
    let script = Script::new(&rec, None).expect("script");
    assert_eq!(script.conn(), 2, "the connection with a session");
    assert_eq!(Script::new(&rec, Some(1)).expect("asked for").conn(), 1);
    let s = rec.summaries();
    assert_eq!(s.len(), 2);
    assert!(!s[0].has_session() && s[1].has_session(), "{s:?}");
    assert_eq!((s[1].to_reader, s[1].from_reader, s[1].reports), (2, 6, 3));
    assert_eq!(s[0].client.as_deref(), Some("client 10.0.0.9:40000"));
    assert_eq!(s[0].end.as_deref(), Some("client closed"));
}
