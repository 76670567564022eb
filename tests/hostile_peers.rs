//! Hostile peers against the real binaries: frames whose LLRPStatus nests ParameterErrors as
//! deep as a TLV allows (about 8,000 levels in 64 KiB), sent by a client to `sim` and by a
//! reader through `proxy` (recording and tap on), then replayed with the live localizer and
//! fed to `decode`. Each process answers with LLRP errors or forwards the bytes, and lives on.

mod http_support;

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::process::{Command, Stdio};
use std::time::Duration;

use http_support::{request, Proc};
use llrp::enums::ConnectionAttemptStatus;
use llrp::message::{MessageBody, MessageDef};
use llrp::sample::{nested_status_frame, MAX_FITTING_NESTING};
use llrp::{FrameHeader, Message, StatusCode};

const PATIENCE: Duration = Duration::from_secs(30);

/// Reads one whole LLRP frame, or `None` at the end of the stream.
fn read_frame(s: &mut TcpStream) -> Option<Vec<u8>> {
    let mut f = vec![0u8; 10];
    s.read_exact(&mut f).ok()?;
    let h = FrameHeader::peek(&f)?;
    f.resize(h.length as usize, 0);
    s.read_exact(&mut f[10..]).ok()?;
    Some(f)
}

fn connect(addr: &str) -> TcpStream {
    let s = TcpStream::connect(addr).expect("connects");
    s.set_read_timeout(Some(PATIENCE)).expect("timeout");
    s
}

fn request_frame(id: u32, body: impl Into<MessageBody>) -> Vec<u8> {
    Message::new(id, body).to_bytes().to_vec()
}

/// A reader that greets each client, then answers every request with its response type
/// carrying the deepest ParameterError chain that fits, followed by an ERROR_MESSAGE just as
/// deep; CLOSE_CONNECTION gets such a CLOSE_CONNECTION_RESPONSE and the close. Returns, per
/// connection, every byte it sent.
fn hostile_reader(listener: TcpListener, connections: usize) -> Vec<Vec<u8>> {
    (0..connections)
        .map(|_| {
            let (mut s, _) = listener.accept().expect("accept");
            s.set_read_timeout(Some(PATIENCE)).expect("timeout");
            let mut greeting = llrp_gateway::net::proxy::connection_failed(1_700_000_000_000_000);
            if let Some(e) = greeting
                .reader_event_notification_data
                .connection_attempt_event
                .as_mut()
            {
                e.status = ConnectionAttemptStatus::Success;
            }
            let mut sent = request_frame(0, greeting);
            s.write_all(&sent).expect("greeting");
            while let Some(f) = read_frame(&mut s) {
                let h = FrameHeader::peek(&f).expect("header");
                let close = h.msg_type == llrp::message::CloseConnection::TYPE;
                let answer_type = if close { 4 } else { h.msg_type + 10 };
                let mut out = nested_status_frame(answer_type, h.id, MAX_FITTING_NESTING);
                if !close {
                    out.extend(nested_status_frame(100, h.id + 1000, MAX_FITTING_NESTING));
                }
                s.write_all(&out).expect("answer");
                sent.extend(out);
                if close {
                    break;
                }
            }
            sent
        })
        .collect()
}

/// Sends the requests, then CLOSE_CONNECTION, and returns every byte received until the end.
fn session(addr: &str) -> Vec<u8> {
    let mut s = connect(addr);
    let mut got = read_frame(&mut s).expect("greeting");
    let requests = [
        request_frame(1, llrp::message::GetReaderCapabilities::default()),
        request_frame(2, llrp::message::GetReaderConfig::default()),
        request_frame(3, llrp::message::CloseConnection::default()),
    ];
    for r in &requests {
        s.write_all(r).expect("request");
    }
    s.read_to_end(&mut got).expect("to the end");
    got
}

#[test]
fn a_client_nesting_parameter_errors_8000_deep_gets_an_llrp_error_and_sim_serves_on() {
    let mut sim = Proc::spawn(&["sim", "--no-http", "--listen", "127.0.0.1:0"]);
    let addr = sim.address("listening on ");
    let mut s = connect(&addr);
    read_frame(&mut s).expect("greeting");
    s.write_all(&nested_status_frame(100, 0x4242, MAX_FITTING_NESTING))
        .expect("send");
    let answer = read_frame(&mut s).expect("an answer");
    let m = Message::decode(&answer).expect("the answer decodes");
    assert_eq!((m.name(), m.id), ("ERROR_MESSAGE", 0x4242));
    let MessageBody::ErrorMessage(e) = &m.body else {
        unreachable!("checked by name");
    };
    assert_eq!(e.llrp_status.status_code, StatusCode::M_ParameterError);
    assert!(
        e.llrp_status.error_description.contains("nested more than"),
        "{}",
        e.llrp_status.error_description
    );
    // The same connection is still served.
    s.write_all(&request_frame(
        5,
        llrp::message::GetReaderCapabilities::default(),
    ))
    .expect("send");
    let caps = Message::decode(&read_frame(&mut s).expect("answer")).expect("decodes");
    assert_eq!(caps.name(), "GET_READER_CAPABILITIES_RESPONSE");
    assert!(sim.running(), "sim is alive");
}

#[test]
fn a_reader_nesting_parameter_errors_8000_deep_kills_neither_proxy_nor_replay_nor_decode() {
    let listener = TcpListener::bind("127.0.0.1:0").expect("bind");
    let upstream = listener.local_addr().expect("bound").to_string();
    let reader = std::thread::spawn(move || hostile_reader(listener, 2));
    let dir = tempfile::tempdir().expect("temp dir");
    let rec = dir.path().join("hostile.jsonl");
    let rec_arg = rec.to_str().expect("utf-8");
    let mut proxy = Proc::spawn(&[
        "proxy",
        "--upstream",
        &upstream,
        "--listen",
        "127.0.0.1:0",
        "--record",
        rec_arg,
        "--http",
        "127.0.0.1:0",
    ]);
    let http: std::net::SocketAddr = proxy.address("live map on http://").parse().expect("addr");
    let llrp_addr = proxy.address("listening on ");
    // Two sessions in turn: the first must not take the proxy (or the tap) down.
    let first = session(&llrp_addr);
    let second = session(&llrp_addr);
    let sent = reader.join().expect("reader");
    assert_eq!(first, sent[0], "the first client got every byte unchanged");
    assert_eq!(
        second, sent[1],
        "the second client got every byte unchanged"
    );
    assert!(proxy.running(), "the proxy is alive");
    assert_eq!(request(http, "GET", "/api/readers", &[], b"").status, 200);
    let status = proxy.stop();
    assert!(status.success(), "the proxy exits cleanly: {status:?}");

    // The recording kept the frames byte for byte.
    let r = llrp_gateway::record::Recording::open(&rec).expect("the recording reads");
    let deep = r
        .entries
        .iter()
        .filter(|e| {
            matches!(e, llrp_gateway::record::Entry::Frame { frame, .. } if frame.len() > 60_000)
        })
        .count();
    assert_eq!(deep, 10, "every deep frame of both sessions is recorded");
    // Each is marked undecodable with the codec's reason, and only they are.
    let marked: Vec<(usize, &str)> = r
        .entries
        .iter()
        .filter_map(|e| match e {
            llrp_gateway::record::Entry::Frame {
                frame,
                undecodable: Some(why),
                ..
            } => Some((frame.len(), why.as_str())),
            _ => None,
        })
        .collect();
    assert_eq!(marked.len(), 10, "{marked:?}");
    assert!(
        marked
            .iter()
            .all(|(len, why)| *len > 60_000 && why.contains("nested more than")),
        "{marked:?}"
    );

    // Replayed with the live localizer reading the frames.
    let mut replay = Proc::spawn(&[
        "replay",
        rec_arg,
        "--listen",
        "127.0.0.1:0",
        "--http",
        "127.0.0.1:0",
    ]);
    let http: std::net::SocketAddr = replay.address("live map on http://").parse().expect("addr");
    let addr = replay.address("listening on ");
    let replayed = session(&addr);
    // Each request's recorded answer (capabilities, configuration, close) is replayed.
    assert!(
        replayed.len() > 3 * 60_000,
        "the deep answers were replayed"
    );
    assert!(replay.running(), "replay is alive");
    assert_eq!(request(http, "GET", "/api/readers", &[], b"").status, 200);

    // `decode` names the fault and exits with an error, not a crash.
    let hex = llrp::raw::to_hex(&nested_status_frame(12, 1, MAX_FITTING_NESTING));
    let mut child = Command::new(env!("CARGO_BIN_EXE_llrp-gateway"))
        .args(["decode", "--hex"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("decode runs");
    child
        .stdin
        .take()
        .expect("piped")
        .write_all(hex.as_bytes())
        .expect("hex in");
    let out = child.wait_with_output().expect("decode ends");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("TooDeep { ty: 289, limit: 64 }") && stderr.contains("ParameterError×65"),
        "{stderr}"
    );
}
