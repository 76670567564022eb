//! `llrp-gateway export` and `import`: a recording of a real session with the simulated
//! reader exported to pcapng and dissected by real tshark (Wireshark 4.0's LLRP dissector);
//! export → import giving back the same frames; a capture made by tshark itself imported.
//!
//! The tshark tests are `#[ignore]`d in a plain `cargo test` (`./scripts/test` runs them with
//! `--include-ignored` after `scripts/install-tshark`); they fail, naming the command to
//! run, if tshark is missing.

#[path = "common/reports.rs"]
mod reports;

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use bytes::Bytes;
use common::*;
use llrp::message::*;
use llrp::params::*;
use llrp::Message;
use llrp_gateway::net::client::{is_unsolicited, Client, ClientError};
use llrp_gateway::net::clock::Speed;
use llrp_gateway::record::format::{encode_entry, encode_header};
use llrp_gateway::record::pcapng;
use llrp_gateway::record::{Direction, Entry, Event, Header, Recording, Stamp};
use llrp_gateway::utc::now_us as utc_now_us;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_llrp-gateway"))
}

/// The recording's clock: monotonic offsets and UTC.
struct Clock {
    start: Instant,
    utc0: u64,
}

impl Clock {
    fn new() -> Clock {
        Clock {
            start: Instant::now(),
            utc0: utc_now_us(),
        }
    }

    fn now(&self) -> Stamp {
        let t_us = self.start.elapsed().as_micros() as u64;
        Stamp {
            t_us,
            utc_us: self.utc0 + t_us,
        }
    }
}

/// A client connection that records every frame it sends and receives, byte for byte.
struct Recorded<'a> {
    c: Client,
    conn: u32,
    clock: &'a Clock,
    entries: &'a mut Vec<Entry>,
    next_id: u32,
    /// Every frame, in order, with its direction (what the capture must show).
    frames: Vec<(Direction, Bytes)>,
}

impl<'a> Recorded<'a> {
    /// Connects, records the connect marker and the greeting.
    async fn open(
        addr: std::net::SocketAddr,
        conn: u32,
        clock: &'a Clock,
        entries: &'a mut Vec<Entry>,
    ) -> Recorded<'a> {
        let c = Client::connect(addr).await.expect("connects");
        entries.push(Entry::Marker {
            at: clock.now(),
            conn,
            event: Event::Connect,
            reason: format!("client for {addr}"),
        });
        let mut r = Recorded {
            c,
            conn,
            clock,
            entries,
            next_id: 1,
            frames: Vec::new(),
        };
        let hello = r.recv().await.expect("greeting");
        assert_eq!(hello.name(), "READER_EVENT_NOTIFICATION");
        r
    }

    fn record(&mut self, dir: Direction, frame: Bytes) {
        self.frames.push((dir, frame.clone()));
        self.entries.push(Entry::Frame {
            at: self.clock.now(),
            conn: self.conn,
            dir,
            frame,
            undecodable: None,
        });
    }

    async fn send(&mut self, body: impl Into<MessageBody>) -> u32 {
        let id = self.next_id;
        self.next_id += 1;
        let frame = Message::new(id, body).to_bytes().freeze();
        self.c.send_raw(&frame).await.expect("sends");
        self.record(Direction::ToReader, frame);
        id
    }

    async fn recv(&mut self) -> Result<Message, ClientError> {
        let frame = Bytes::from(self.c.recv_raw(T).await?);
        self.record(Direction::FromReader, frame.clone());
        Ok(Message::decode(&frame)?)
    }

    /// Sends a request and receives until its answer, recording the reports on the way.
    async fn request(&mut self, body: impl Into<MessageBody>) -> Message {
        let id = self.send(body).await;
        loop {
            let m = self.recv().await.expect("an answer");
            if m.id == id && !is_unsolicited(&m) {
                return m;
            }
        }
    }

    /// CLOSE_CONNECTION, then everything until the reader closes, then the marker.
    async fn close(mut self) -> Vec<(Direction, Bytes)> {
        let r = self.request(CloseConnection::default()).await;
        assert_eq!(r.name(), "CLOSE_CONNECTION_RESPONSE");
        loop {
            match self.recv().await {
                Ok(_) => continue,
                Err(ClientError::Closed) => break,
                Err(e) => panic!("until the reader closes: {e}"),
            }
        }
        self.entries.push(Entry::Marker {
            at: self.clock.now(),
            conn: self.conn,
            event: Event::Disconnect,
            reason: "reader closed".into(),
        });
        self.frames
    }
}

fn impinj_data(n: u32) -> Vec<Custom> {
    vec![Custom::ImpinjRequestedData(ImpinjRequestedData {
        requested_data: n,
        ..Default::default()
    })]
}

/// Scenario S2 (100 tags, 8 antennas) with its reader on an ephemeral port.
fn s2() -> llrp_gateway::scenario::Scenario {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/scenarios/s2.json");
    let mut s = llrp_gateway::scenario::Scenario::load(&path).expect("S2 loads");
    for r in &mut s.readers {
        r.listen = "127.0.0.1:0".into();
    }
    s
}

/// A recording of two sessions with the simulated reader (S2, as fast as the client takes
/// reports): capabilities and configuration with the Impinj extensions on (Identification
/// included), an inventory reporting phase, peak RSSI and Doppler, one report of every read
/// at the ROSpec's end (far larger than an MSS), then a short second connection.
async fn sim_recording() -> Recording {
    let sim = start(&s2(), Speed::Max).await;
    let r = session(sim.addrs[0]).await;
    sim.shutdown().await;
    r
}

/// The two sessions of [`sim_recording`] with the reader at `addr`.
async fn session(addr: std::net::SocketAddr) -> Recording {
    let clock = Clock::new();
    let mut entries = Vec::new();
    let mut s = Recorded::open(addr, 1, &clock, &mut entries).await;
    let r = s.request(ImpinjEnableExtensions::default()).await;
    assert_eq!(status(&r).status_code, StatusCode::M_Success);
    let caps = GetReaderCapabilities {
        custom: impinj_data(1000),
        ..Default::default()
    };
    assert_eq!(
        s.request(caps).await.name(),
        "GET_READER_CAPABILITIES_RESPONSE"
    );
    let cfg = GetReaderConfig {
        custom: impinj_data(2000),
        ..Default::default()
    };
    let r = s.request(cfg).await;
    let MessageBody::GetReaderConfigResponse(cfg) = &r.body else {
        panic!("{r:?}")
    };
    assert!(
        cfg.identification.is_some(),
        "the config has Identification"
    );
    // Every read held until the ROSpec ends: one large report.
    let spec = rospec(
        1,
        vec![0],
        ro_duration(5_000),
        ai_null(),
        full_report(RoReportTriggerType::UponNTagsOrEndOfRoSpec, 0),
    );
    let add = AddRospec {
        ro_spec: spec,
        ..Default::default()
    };
    assert_eq!(
        status(&s.request(add).await).status_code,
        StatusCode::M_Success
    );
    let enable = EnableRospec {
        ro_spec_id: 1,
        ..Default::default()
    };
    assert_eq!(
        status(&s.request(enable).await).status_code,
        StatusCode::M_Success
    );
    loop {
        let m = s.recv().await.expect("the report");
        if let MessageBody::RoAccessReport(r) = &m.body {
            assert!(!r.tag_report_data.is_empty(), "reads in the report");
            break;
        }
    }
    let delete = DeleteRospec::default();
    assert_eq!(
        status(&s.request(delete).await).status_code,
        StatusCode::M_Success
    );
    s.close().await;
    let mut s = Recorded::open(addr, 2, &clock, &mut entries).await;
    let cfg = GetReaderConfig {
        requested_data: ConfigRequest::Identification,
        ..Default::default()
    };
    assert_eq!(s.request(cfg).await.name(), "GET_READER_CONFIG_RESPONSE");
    s.close().await;
    Recording {
        header: Header::new(format!("sim:{addr}"), clock.utc0),
        entries,
        warnings: Vec::new(),
    }
}

fn write(recording: &Recording, path: &Path) {
    let mut text = Vec::new();
    encode_header(&recording.header, &mut text);
    for e in &recording.entries {
        encode_entry(e, &mut text);
    }
    std::fs::write(path, text).expect("write the recording");
}

/// One connection of a recording: its frames in order with their direction, and its
/// non-LLRP bytes to and from the reader.
struct Conn {
    frames: Vec<(Direction, Bytes)>,
    bytes: [Vec<u8>; 2],
}

/// The frames and bytes of each connection.
fn streams(r: &Recording) -> Vec<Conn> {
    r.connections()
        .into_iter()
        .map(|conn| {
            let frames = r.frames(conn).map(|(_, d, f)| (d, f.clone())).collect();
            let mut bytes = [Vec::new(), Vec::new()];
            for e in &r.entries {
                if let Entry::Bytes {
                    conn: c,
                    dir,
                    bytes: b,
                    ..
                } = e
                {
                    if *c == conn {
                        bytes[usize::from(*dir == Direction::FromReader)].extend_from_slice(b);
                    }
                }
            }
            Conn { frames, bytes }
        })
        .collect()
}

/// Runs tshark with `args`; fails naming the install script if it is missing.
fn tshark(args: &[&str]) -> String {
    let out = match Command::new("tshark").args(args).output() {
        Ok(o) => o,
        Err(e) => panic!("tshark cannot run ({e}): install it with scripts/install-tshark"),
    };
    assert!(
        out.status.success(),
        "tshark {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).expect("tshark prints UTF-8")
}

/// The Identification parameters and ImpinjRFDopplerFrequency parameters in `frames`, found
/// by decoding them with the codec: what Wireshark 4.0 may flag, and no more.
fn excusable(frames: &[Bytes]) -> (usize, usize) {
    let (mut identification, mut doppler) = (0, 0);
    for f in frames {
        match Message::decode(f).map(|m| m.body) {
            Ok(MessageBody::GetReaderConfigResponse(r)) => {
                identification += usize::from(r.identification.is_some());
            }
            Ok(MessageBody::RoAccessReport(r)) => {
                doppler += r
                    .tag_report_data
                    .iter()
                    .flat_map(|t| &t.custom)
                    .filter(|c| matches!(c, Custom::ImpinjRfDopplerFrequency(_)))
                    .count();
            }
            _ => {}
        }
    }
    (identification, doppler)
}

/// What tshark's verbose tree says of one expert item at warning or error level: its text
/// and the line of the tree item it hangs on.
#[derive(Debug)]
#[allow(dead_code)] // `frame` is there for the failure message
struct Expert {
    frame: usize,
    message: String,
    parent: String,
}

/// The expert items at warning or error level in tshark's `-V` output, each with the item it
/// hangs on (the nearest line above it that is indented less).
fn experts(verbose: &str) -> Vec<Expert> {
    let mut found = Vec::new();
    let mut frame = 0;
    let lines: Vec<&str> = verbose.lines().collect();
    for (i, line) in lines.iter().enumerate() {
        if let Some(rest) = line.strip_prefix("Frame ") {
            frame = rest
                .split(':')
                .next()
                .and_then(|n| n.trim().parse().ok())
                .unwrap_or(frame);
        }
        let text = line.trim_start();
        let Some(rest) = text.strip_prefix("[Expert Info (") else {
            continue;
        };
        if !(rest.starts_with("Warning/") || rest.starts_with("Error/")) {
            continue;
        }
        let indent = line.len() - text.len();
        let parent = lines[..i]
            .iter()
            .rev()
            .find(|l| l.len() - l.trim_start().len() < indent)
            .map_or("", |l| l.trim())
            .to_string();
        let message = rest
            .split_once("): ")
            .map_or(rest, |(_, m)| m)
            .trim_end_matches(']')
            .to_string();
        found.push(Expert {
            frame,
            message,
            parent,
        });
    }
    found
}

/// Whether an expert item is Wireshark 4.0's fault on a spec-conformant Identification: it
/// decodes IDType and the ReaderID but not the ReaderID's 2-byte count.
fn identification_fault(e: &Expert) -> bool {
    let numbers: Vec<usize> = e
        .message
        .split(|c: char| !c.is_ascii_digit())
        .filter_map(|n| n.parse().ok())
        .collect();
    e.parent == "TLV Parameter: Identification"
        && e.message.starts_with("Incorrect length of parameter:")
        && matches!(numbers[..], [decoded, claimed] if claimed == decoded + 2)
}

/// Whether an expert item is Wireshark 4.0's fault on ImpinjRFDopplerFrequency (Impinj
/// subtype 68, which it does not know: it decodes the 12-byte vendor header of the 14).
fn doppler_fault(e: &Expert) -> bool {
    e.parent == "TLV Parameter: Custom parameter (Impinj - Unknown Type: 68)"
        && e.message == "Incorrect length of parameter: 12 bytes decoded, but 14 bytes claimed."
}

/// Exports `recording` with the binary and checks what tshark makes of the capture: every
/// frame dissected as one LLRP message (type and ID in order), valid IPv4 and TCP checksums
/// on every packet, no TCP analysis flag, no malformed packet, no expert item at warning or
/// error level except Wireshark 4.0's two known faults, each exactly as often as the frames
/// hold the parameters it is about.
fn check_with_tshark(name: &str, recording: &Recording, dir: &Path) {
    // Bytes entries are not LLRP by definition: Wireshark would rightly call them malformed.
    let mut recording = recording.clone();
    recording
        .entries
        .retain(|e| !matches!(e, Entry::Bytes { .. }));
    let rec = dir.join(format!("{name}.jsonl"));
    let cap = dir.join(format!("{name}.pcapng"));
    write(&recording, &rec);
    let out = bin()
        .arg("export")
        .arg(&rec)
        .arg("--pcapng")
        .arg(&cap)
        .output()
        .expect("runs");
    assert!(
        out.status.success(),
        "{name}: export: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let cap = cap.to_str().expect("UTF-8 path");
    let common = [
        "-r",
        cap,
        "-2",
        "-o",
        "tcp.check_checksum:TRUE",
        "-o",
        "ip.check_checksum:TRUE",
        "-d",
        "tcp.port==5084,llrp",
    ];
    let run = |more: &[&str]| {
        let mut args = common.to_vec();
        args.extend_from_slice(more);
        tshark(&args)
    };
    let frames: Vec<Bytes> = recording
        .entries
        .iter()
        .filter_map(|e| match e {
            Entry::Frame { frame, .. } => Some(frame.clone()),
            _ => None,
        })
        .collect();
    let fields = run(&[
        "-T",
        "fields",
        "-E",
        "occurrence=a",
        "-E",
        "aggregator=,",
        "-e",
        "llrp.type",
        "-e",
        "llrp.id",
        "-e",
        "ip.checksum.status",
        "-e",
        "tcp.checksum.status",
    ]);
    let mut dissected = Vec::new();
    let mut packets = 0;
    for line in fields.lines() {
        packets += 1;
        let cols: Vec<&str> = line.split('\t').collect();
        assert_eq!(cols.len(), 4, "{name}: {line:?}");
        assert_eq!(
            (cols[2], cols[3]),
            ("1", "1"),
            "{name}: packet {packets}: IPv4 and TCP checksums good"
        );
        if cols[0].is_empty() {
            continue;
        }
        for (t, id) in cols[0].split(',').zip(cols[1].split(',')) {
            dissected.push((
                t.parse::<u16>().expect("type"),
                id.parse::<u32>().expect("id"),
            ));
        }
    }
    let expected: Vec<(u16, u32)> = frames
        .iter()
        .map(|f| {
            let h = llrp::FrameHeader::peek(f).expect("a frame has a header");
            (h.msg_type, h.id)
        })
        .collect();
    assert_eq!(
        dissected, expected,
        "{name}: every frame dissected as LLRP, in order"
    );
    // Wireshark marks the packet of every Malformed-group expert item with a hidden
    // `_ws.malformed`, the excused ones included; a dissector exception or a failed
    // reassembly has its own fields.
    for filter in [
        "tcp.analysis.flags",
        "_ws.malformed.expert",
        "_ws.malformed.reassembly",
        "_ws.malformed.dissector_bug",
    ] {
        let hits = run(&["-Y", filter, "-T", "fields", "-e", "frame.number"]);
        let hits: Vec<&str> = hits.lines().collect();
        assert!(hits.is_empty(), "{name}: packets with {filter}: {hits:?}");
    }
    let verbose = run(&["-V"]);
    assert!(
        !verbose.contains("[Malformed Packet"),
        "{name}: a packet tshark could not dissect"
    );
    let found = experts(&verbose);
    let (identification, doppler) = excusable(&frames);
    let not_ours = found
        .iter()
        .filter(|e| !identification_fault(e) && !doppler_fault(e))
        .collect::<Vec<_>>();
    assert!(
        not_ours.is_empty(),
        "{name}: expert items at warning or error level: {not_ours:#?}"
    );
    assert_eq!(
        found.iter().filter(|e| identification_fault(e)).count(),
        identification,
        "{name}: one Identification fault per Identification parameter"
    );
    assert_eq!(
        found.iter().filter(|e| doppler_fault(e)).count(),
        doppler,
        "{name}: one fault per ImpinjRFDopplerFrequency parameter"
    );
    eprintln!(
        "{name}: {} frames in {packets} packets dissected as LLRP; excused: {identification} Identification, {doppler} ImpinjRFDopplerFrequency",
        frames.len()
    );
}

/// The recordings shipped in `fixtures/sessions/`.
fn fixtures() -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/sessions");
    let mut found: Vec<PathBuf> = std::fs::read_dir(&dir)
        .map(|d| {
            d.filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|x| x == "jsonl"))
                .collect()
        })
        .unwrap_or_default();
    found.sort();
    found
}

#[tokio::test]
#[ignore = "needs tshark: scripts/install-tshark (./scripts/test runs it)"]
async fn tshark_dissects_every_exported_frame_as_llrp_with_only_the_known_faults() {
    let dir = tempfile::tempdir().expect("temp dir");
    let session = sim_recording().await;
    let (identification, doppler) = excusable(
        &session
            .entries
            .iter()
            .filter_map(|e| match e {
                Entry::Frame { frame, .. } => Some(frame.clone()),
                _ => None,
            })
            .collect::<Vec<_>>(),
    );
    assert!(identification >= 2 && doppler > 0, "the session has both");
    let largest = session
        .entries
        .iter()
        .filter_map(|e| match e {
            Entry::Frame { frame, .. } => Some(frame.len()),
            _ => None,
        })
        .max();
    assert!(
        largest > Some(2 * usize::from(pcapng::DEFAULT_MSS)),
        "a frame spans several segments: {largest:?}"
    );
    check_with_tshark("sim-session", &session, dir.path());
    let shipped = fixtures();
    assert!(shipped.len() >= 3, "the shipped fixtures: {shipped:?}");
    for path in shipped {
        let r = Recording::open(&path).expect("a shipped fixture reads");
        let name = path
            .file_stem()
            .expect("a name")
            .to_string_lossy()
            .to_string();
        check_with_tshark(&name, &r, dir.path());
    }
}

/// A third connection for the round trip: no connect or disconnect marker, a report far
/// larger than any MSS, then bytes that are not LLRP both ways.
fn add_synthetic(r: &mut Recording) {
    let at = r.entries.last().map(Entry::at).unwrap_or_default();
    let report = reports::many_reads(5000);
    let frames = [
        (
            Direction::ToReader,
            Message::new(9, GetReaderCapabilities::default()),
        ),
        (Direction::FromReader, Message::new(77, report)),
        (
            Direction::FromReader,
            Message::new(78, Keepalive::default()),
        ),
    ];
    for (dir, m) in frames {
        r.entries.push(Entry::Frame {
            at,
            conn: 3,
            dir,
            frame: m.to_bytes().freeze(),
            undecodable: None,
        });
    }
    let bytes = [
        (
            Direction::ToReader,
            &b"GET / HTTP/1.1\r\nHost: reader\r\n\r\n"[..],
        ),
        // A header whose length (4) is below the header's own 10 bytes.
        (
            Direction::FromReader,
            &[0x04, 0x3E, 0, 0, 0, 4, 0, 0, 0, 1, 0xFF][..],
        ),
        (Direction::ToReader, &b"more after the first"[..]),
    ];
    for (dir, b) in bytes {
        r.entries.push(Entry::Bytes {
            at,
            conn: 3,
            dir,
            bytes: Bytes::copy_from_slice(b),
        });
    }
}

fn run_ok(cmd: &mut Command) -> String {
    let out = cmd.output().expect("runs");
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(out.status.success(), "{cmd:?}: {err}");
    err
}

#[tokio::test]
async fn export_then_import_gives_back_the_same_frames_and_bytes() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut original = sim_recording().await;
    add_synthetic(&mut original);
    let rec = dir.path().join("original.jsonl");
    write(&original, &rec);
    let want = streams(&original);
    assert_eq!(want.len(), 3);
    for mss in ["536", "1460", "65495"] {
        let cap = dir.path().join(format!("mss-{mss}.pcapng"));
        let back = dir.path().join(format!("mss-{mss}.jsonl"));
        run_ok(
            bin()
                .arg("export")
                .arg(&rec)
                .arg("--pcapng")
                .arg(&cap)
                .args(["--mss", mss]),
        );
        let log = run_ok(bin().arg("import").arg(&cap).arg("--output").arg(&back));
        assert!(!log.contains("warning"), "MSS {mss}: {log}");
        let imported = Recording::open(&back).expect("the import reads back");
        assert_eq!(imported.header.upstream, "127.0.0.1:5084");
        assert_eq!(
            imported.header.start_utc_us,
            original.entries[0].at().utc_us
        );
        let got = streams(&imported);
        assert_eq!(
            got.len(),
            want.len(),
            "MSS {mss}: one connection per stream"
        );
        for (i, (g, w)) in got.iter().zip(&want).enumerate() {
            assert!(
                g.frames == w.frames,
                "MSS {mss}: conn {}: the same frames, in order and direction",
                i + 1
            );
            assert_eq!(
                g.bytes,
                w.bytes,
                "MSS {mss}: conn {}: the same bytes",
                i + 1
            );
        }
        // Every connection opens and closes, and the frames keep their times.
        for conn in imported.connections() {
            let markers: Vec<Event> = imported
                .entries
                .iter()
                .filter_map(|e| match e {
                    Entry::Marker { conn: c, event, .. } if *c == conn => Some(*event),
                    _ => None,
                })
                .collect();
            assert_eq!(markers, [Event::Connect, Event::Disconnect], "conn {conn}");
        }
        let times =
            |r: &Recording| -> Vec<u64> { r.frames(1).map(|(at, _, _)| at.utc_us).collect() };
        assert_eq!(
            times(&imported),
            times(&original),
            "MSS {mss}: packet times"
        );
    }
}

#[test]
fn export_refuses_a_bad_mss_and_import_names_a_file_that_is_no_capture() {
    let dir = tempfile::tempdir().expect("temp dir");
    let rec = dir.path().join("r.jsonl");
    write(
        &Recording {
            header: Header::new("x", 0),
            entries: Vec::new(),
            warnings: Vec::new(),
        },
        &rec,
    );
    let out = bin()
        .arg("export")
        .arg(&rec)
        .args(["--pcapng", "/dev/null", "--mss", "100"])
        .output()
        .expect("runs");
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("from 536 to 65495"));
    let out = bin()
        .arg("import")
        .arg(&rec)
        .arg("--output")
        .arg(dir.path().join("o.jsonl"))
        .output()
        .expect("runs");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("not a pcap or pcapng capture"), "{err}");
    assert!(err.contains("r.jsonl"), "names the file: {err}");
}

/// A running `tshark -i lo` writing a capture, stopped by its PID.
struct Capture {
    child: std::process::Child,
    path: PathBuf,
}

impl Capture {
    /// Starts capturing TCP port `port` on `interface` into `path`; returns once the capture
    /// holds a probe connection to a port of its own (tshark says "Capturing on" before its
    /// capture filter is in place), with a guard against a hang.
    fn start(interface: &str, port: u16, path: &Path) -> Capture {
        use std::io::{BufRead, BufReader};
        let probe = std::net::TcpListener::bind("127.0.0.1:0").expect("a probe port");
        let probe_port = probe.local_addr().expect("bound").port();
        let filter = format!("tcp port {port} or tcp port {probe_port}");
        let mut child = Command::new("tshark")
            .args(["-i", interface, "-f", &filter, "-w"])
            .arg(path)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap_or_else(|e| {
                panic!("tshark cannot run ({e}): install it with scripts/install-tshark")
            });
        let stderr = child.stderr.take().expect("piped");
        let log = std::thread::spawn(move || {
            let mut all = String::new();
            for line in BufReader::new(stderr).lines() {
                all.push_str(&line.unwrap_or_default());
                all.push('\n');
            }
            all
        });
        let seen = |path: &Path| {
            let Ok(data) = std::fs::read(path) else {
                return false;
            };
            let mut found = false;
            let _ = pcapng::capture::read_packets(&data[..], |p| {
                found |= p.link.is_ok_and(|l| {
                    matches!(pcapng::packet::parse(l, p.data),
                        Ok(pcapng::packet::Parsed::Segment(s)) if s.dst.port() == probe_port)
                });
                Ok(())
            });
            found
        };
        let guard = Instant::now() + std::time::Duration::from_secs(30);
        while !seen(path) {
            if let Some(status) = child.try_wait().expect("wait") {
                let log = log.join().unwrap_or_default();
                panic!("tshark exited ({status}) before capturing on {interface} (root or CAP_NET_RAW needed): {log}");
            }
            assert!(
                Instant::now() < guard,
                "tshark captured no probe within 30 s"
            );
            let _ = std::net::TcpStream::connect(("127.0.0.1", probe_port));
            std::thread::sleep(std::time::Duration::from_millis(50));
        }
        drop(probe);
        Capture {
            child,
            path: path.to_path_buf(),
        }
    }

    /// Waits (hang guard 20 s) until the capture holds `conns` closed connections, then
    /// stops tshark with SIGINT and returns the capture's bytes.
    async fn stop_when_closed(mut self, conns: usize) -> Vec<u8> {
        let closed = |data: &[u8]| {
            pcapng::import(data).is_ok_and(|r| {
                r.entries
                    .iter()
                    .filter(|e| {
                        matches!(
                            e,
                            Entry::Marker {
                                event: Event::Disconnect,
                                ..
                            }
                        )
                    })
                    .count()
                    >= conns
            })
        };
        let guard = Instant::now() + std::time::Duration::from_secs(20);
        while Instant::now() < guard {
            if std::fs::read(&self.path).is_ok_and(|d| closed(&d)) {
                break;
            }
            tokio::time::sleep(std::time::Duration::from_millis(50)).await;
        }
        let pid = self.child.id().to_string();
        let sent = Command::new("kill")
            .args(["-INT", &pid])
            .status()
            .expect("kill runs");
        assert!(sent.success(), "SIGINT to tshark");
        let status = self.child.wait().expect("tshark exits");
        assert!(
            status.success() || status.code().is_none(),
            "tshark: {status}"
        );
        std::fs::read(&self.path).expect("the capture file")
    }
}

#[tokio::test]
#[ignore = "needs tshark and a loopback capture (root): ./scripts/test runs it"]
async fn a_capture_by_tshark_on_loopback_imports_as_the_frames_the_client_saw() {
    live_capture("lo").await;
}

/// On `any`, libpcap writes Linux cooked (SLL) headers instead of Ethernet.
#[tokio::test]
#[ignore = "needs tshark and a capture on `any` (root): ./scripts/test runs it"]
async fn a_linux_cooked_capture_by_tshark_on_any_imports_as_the_frames_the_client_saw() {
    live_capture("any").await;
}

/// Captures a real session on `interface` with tshark and imports it.
async fn live_capture(interface: &str) {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("live.pcapng");
    let sim = start(&s2(), Speed::Max).await;
    let addr = sim.addrs[0];
    let capture = Capture::start(interface, addr.port(), &path);
    let client_side = session(addr).await;
    let data = capture.stop_when_closed(2).await;
    sim.shutdown().await;
    let imported = pcapng::import(&data).expect("the capture imports");
    eprintln!("import warnings: {:?}", imported.warnings);
    assert_eq!(
        imported.header.upstream,
        addr.to_string(),
        "the reader's side"
    );
    let got = streams(&imported);
    let want = streams(&client_side);
    assert_eq!(got.len(), 2, "two connections: {:?}", imported.warnings);
    // Each direction in order. Across directions the wire's order may differ from the
    // order the client logged them in: a report the reader sent while the client was
    // sending a request is on the wire first, but read after the request was sent.
    let way = |c: &Conn, d: Direction| -> Vec<Bytes> {
        c.frames
            .iter()
            .filter(|(x, _)| *x == d)
            .map(|(_, f)| f.clone())
            .collect()
    };
    for (i, (g, w)) in got.iter().zip(&want).enumerate() {
        assert_eq!(
            g.frames.len(),
            w.frames.len(),
            "conn {}: frame count",
            i + 1
        );
        for d in [Direction::ToReader, Direction::FromReader] {
            assert!(
                way(g, d) == way(w, d),
                "conn {}: the frames {d:?}, as the client sent or received them",
                i + 1
            );
        }
        assert!(
            g.bytes[0].is_empty() && g.bytes[1].is_empty(),
            "no stray bytes"
        );
    }
    // Through the command line too, and the same capture as legacy pcap (microseconds).
    let back = dir.path().join("live.jsonl");
    run_ok(bin().arg("import").arg(&path).arg("--output").arg(&back));
    assert_eq!(
        Recording::open(&back).expect("reads").entries,
        imported.entries
    );
    let pcap = dir.path().join("live.pcap");
    run_ok(
        Command::new("editcap")
            .args(["-F", "pcap"])
            .arg(&path)
            .arg(&pcap),
    );
    let legacy = pcapng::import(&std::fs::read(&pcap).expect("pcap")).expect("imports");
    let frames = |r: &Recording| -> Vec<Entry> {
        let mut e = r.entries.clone();
        e.retain(|e| matches!(e, Entry::Frame { .. }));
        e
    };
    assert_eq!(frames(&legacy), frames(&imported), "pcap and pcapng alike");
}
