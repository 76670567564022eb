//! The transparent proxy over loopback: byte-exact forwarding both ways (undecodable frames
//! and non-LLRP bytes included), recording, the tap, and the faults (upstream unreachable,
//! upstream gone mid-session, client gone, slow client).

mod common;

use std::net::SocketAddr;
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use common::*;
use llrp::impinj::*;
use llrp::message::MessageDef;
use llrp::message::*;
use llrp::{FrameHeader, Message};
use llrp_gateway::net::clock::Speed;
use llrp_gateway::net::proxy::{Proxy, ProxyConfig, Tap, Tapped};
use llrp_gateway::record::{Direction, Entry, Event, Header, RecordOptions, Recorder, Recording};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{mpsc, watch};

/// A running proxy and how to stop it.
struct Running {
    addr: SocketAddr,
    stop: watch::Sender<bool>,
    task: tokio::task::JoinHandle<std::io::Result<()>>,
    recording: Option<llrp_gateway::record::RecorderTask>,
}

impl Running {
    /// Stops the proxy and waits until the recording (if any) is on disk.
    async fn stop(self) {
        let _ = self.stop.send(true);
        self.task.await.expect("joined").expect("proxy ran");
        if let Some(r) = self.recording {
            r.await.expect("joined").expect("recording written");
        }
    }
}

async fn proxy(upstream: &str, record: Option<&Path>, tap: Option<Tap>) -> Running {
    let (recorder, recording) = match record {
        Some(p) => {
            let (r, t) = Recorder::create(p, Header::new(upstream, 0), RecordOptions::default())
                .expect("recording");
            (Some(r), Some(t))
        }
        None => (None, None),
    };
    let config = ProxyConfig {
        name: "test".parse().expect("a reader name"),
        upstream: upstream.into(),
        listen: "127.0.0.1:0".into(),
        record: record.map(Path::to_owned),
        region: None,
        connect_timeout: Duration::from_secs(5),
        tls: None,
        upstream_tls: None,
    };
    let p = Proxy::bind(config, recorder, tap).await.expect("binds");
    let addr = p.local_addr().expect("bound");
    let (stop, rx) = watch::channel(false);
    let task = tokio::spawn(p.run(rx));
    Running {
        addr,
        stop,
        task,
        recording,
    }
}

/// Bytes logged by a [`relay`], per direction.
#[derive(Default)]
struct Log {
    /// From the side that connected to the relay, towards the target.
    forward: Mutex<Vec<u8>>,
    /// From the target back.
    back: Mutex<Vec<u8>>,
}

/// A plain TCP relay that logs every byte: the test's own view of one hop.
async fn relay(target: SocketAddr) -> (SocketAddr, Arc<Log>, tokio::task::JoinHandle<()>) {
    let l = TcpListener::bind("127.0.0.1:0").await.expect("bind");
    let addr = l.local_addr().expect("bound");
    let log = Arc::new(Log::default());
    let log2 = Arc::clone(&log);
    let task = tokio::spawn(async move {
        let (a, _) = l.accept().await.expect("accept");
        let b = TcpStream::connect(target).await.expect("connect target");
        let (mut ar, mut aw) = a.into_split();
        let (mut br, mut bw) = b.into_split();
        let l1 = Arc::clone(&log2);
        let fwd = async move {
            let mut buf = vec![0u8; 16384];
            loop {
                let n = ar.read(&mut buf).await.unwrap_or(0);
                if n == 0 || bw.write_all(&buf[..n]).await.is_err() {
                    let _ = bw.shutdown().await;
                    return;
                }
                l1.forward
                    .lock()
                    .expect("lock")
                    .extend_from_slice(&buf[..n]);
            }
        };
        let back = async move {
            let mut buf = vec![0u8; 16384];
            loop {
                let n = br.read(&mut buf).await.unwrap_or(0);
                if n == 0 || aw.write_all(&buf[..n]).await.is_err() {
                    let _ = aw.shutdown().await;
                    return;
                }
                log2.back.lock().expect("lock").extend_from_slice(&buf[..n]);
            }
        };
        tokio::join!(fwd, back);
    });
    (addr, log, task)
}

/// The bytes of one direction of a recorded connection, frames and non-LLRP bytes in order.
fn recorded_stream(r: &Recording, conn: u32, dir: Direction) -> Vec<u8> {
    let mut out = Vec::new();
    for e in &r.entries {
        match e {
            Entry::Frame {
                conn: c,
                dir: d,
                frame,
                ..
            } if *c == conn && *d == dir => out.extend_from_slice(frame),
            Entry::Bytes {
                conn: c,
                dir: d,
                bytes,
                ..
            } if *c == conn && *d == dir => out.extend_from_slice(bytes),
            _ => {}
        }
    }
    out
}

fn markers(r: &Recording) -> Vec<(Event, String)> {
    r.entries
        .iter()
        .filter_map(|e| match e {
            Entry::Marker { event, reason, .. } => Some((*event, reason.clone())),
            _ => None,
        })
        .collect()
}

fn frame(id: u32, body: impl Into<MessageBody>) -> Vec<u8> {
    Message::new(id, body).to_bytes().to_vec()
}

#[tokio::test]
async fn every_byte_is_forwarded_unchanged_both_ways_even_when_it_is_not_llrp() {
    // What the client sends: a request, a frame with a valid header and a body the codec
    // cannot decode, then bytes that are not LLRP at all.
    let mut from_client = frame(1, GetReaderCapabilities::default());
    let mut bad = frame(2, GetReaderConfig::default());
    bad.extend_from_slice(&[0xde, 0xad]);
    let len = bad.len() as u32;
    bad[2..6].copy_from_slice(&len.to_be_bytes());
    from_client.extend_from_slice(&bad);
    from_client.extend_from_slice(b"GET / HTTP/1.1\r\nHost: reader\r\n\r\n");
    // What the reader sends: its greeting, an answer, then garbage.
    let mut from_reader = frame(
        0,
        llrp_gateway::net::proxy::connection_failed(1_700_000_000_000_000),
    );
    from_reader.extend_from_slice(&frame(1, KeepaliveAck::default()));
    from_reader.extend_from_slice(&[0x00, 0x00, 0xff, 0xff, b'n', b'o', b't', 0x00, 0x01, 0x02]);

    let reader = TcpListener::bind("127.0.0.1:0").await.expect("bind");
    let upstream = reader.local_addr().expect("bound").to_string();
    let expect_in = from_client.len();
    let script = from_reader.clone();
    let reader_task = tokio::spawn(async move {
        let (mut s, _) = reader.accept().await.expect("accept");
        s.write_all(&script[..20]).await.expect("greeting part");
        let mut got = vec![0u8; expect_in];
        s.read_exact(&mut got)
            .await
            .expect("everything the client sent");
        s.write_all(&script[20..]).await.expect("the rest");
        s.shutdown().await.expect("close");
        got
    });
    let dir = tempfile::tempdir().expect("temp dir");
    let rec = dir.path().join("rec.jsonl");
    let p = proxy(&upstream, Some(&rec), None).await;

    let mut c = TcpStream::connect(p.addr).await.expect("connect");
    c.write_all(&from_client).await.expect("send");
    let mut got = Vec::new();
    c.read_to_end(&mut got).await.expect("read to the end");
    let reader_got = reader_task.await.expect("reader");
    assert_eq!(
        reader_got, from_client,
        "the reader got what the client sent"
    );
    assert_eq!(got, from_reader, "the client got what the reader sent");
    p.stop().await;

    let r = Recording::open(&rec).expect("recording reads");
    assert_eq!(recorded_stream(&r, 1, Direction::ToReader), from_client);
    assert_eq!(recorded_stream(&r, 1, Direction::FromReader), from_reader);
    assert!(
        r.entries.iter().any(|e| matches!(e, Entry::Bytes { .. })),
        "the non-LLRP bytes are recorded as bytes"
    );
    let m = markers(&r);
    assert_eq!(m.first().map(|m| m.0), Some(Event::Connect));
    assert_eq!(m.last().map(|m| m.0), Some(Event::Disconnect));
    assert!(
        m.last().expect("marker").1.contains("upstream closed"),
        "{m:?}"
    );
}

#[tokio::test]
async fn a_simulated_inventory_passes_byte_for_byte_and_is_recorded_and_tapped() {
    let sim = start(&s1(), Speed::Factor(1.0)).await;
    // client → relay A → proxy → relay B → simulated reader: A and B log what each side of the
    // proxy saw.
    let (b_addr, b_log, b_task) = relay(sim.addrs[0]).await;
    let dir = tempfile::tempdir().expect("temp dir");
    let rec = dir.path().join("rec.jsonl");
    let (tap, mut tapped) = Tap::new(100_000);
    let p = proxy(&b_addr.to_string(), Some(&rec), Some(tap.clone())).await;
    let (a_addr, a_log, a_task) = relay(p.addr).await;

    let mut c = llrp_gateway::net::client::Client::connect(a_addr)
        .await
        .expect("connects");
    let greeting = c.recv(T).await.expect("greeting");
    assert_eq!(
        connection_status(&greeting),
        Some(ConnectionAttemptStatus::Success)
    );
    let caps = c
        .transact(
            GetReaderCapabilities {
                requested_data: CapabilitiesRequest::All,
                ..Default::default()
            },
            T,
        )
        .await
        .expect("capabilities");
    assert!(caps.regulatory_capabilities.is_some());
    c.request(ImpinjEnableExtensions::default(), T)
        .await
        .expect("Impinj extensions");
    start_inventory(&mut c).await;
    let (tags, _) = collect_reports(&mut c, Duration::from_secs(20), |t| t.len() >= 50).await;
    assert!(tags.len() >= 50, "only {} reads", tags.len());
    c.request(CloseConnection::default(), T)
        .await
        .expect("close response");
    c.until_closed(T).await.expect("closed");
    drop(c);
    a_task.await.expect("relay A");
    b_task.await.expect("relay B");
    p.stop().await;
    sim.shutdown().await;

    let a_fwd = a_log.forward.lock().expect("lock").clone();
    let a_back = a_log.back.lock().expect("lock").clone();
    let b_fwd = b_log.forward.lock().expect("lock").clone();
    let b_back = b_log.back.lock().expect("lock").clone();
    assert!(!a_back.is_empty());
    assert_eq!(a_fwd, b_fwd, "the reader got exactly what the client sent");
    assert_eq!(
        a_back, b_back,
        "the client got exactly what the reader sent"
    );

    let r = Recording::open(&rec).expect("recording reads");
    assert!(r.warnings.is_empty(), "{:?}", r.warnings);
    assert_eq!(recorded_stream(&r, 1, Direction::ToReader), b_fwd);
    assert_eq!(recorded_stream(&r, 1, Direction::FromReader), b_back);
    let info = r.entries.iter().find_map(|e| match e {
        Entry::Reader { reader, .. } => Some(reader.clone()),
        _ => None,
    });
    let info = info.expect("the reader's identity is recorded once seen");
    assert!(
        info.manufacturer.is_some() && info.firmware.is_some(),
        "{info:?}"
    );
    let last = markers(&r).pop().expect("a marker");
    assert_eq!(last.0, Event::Disconnect);

    // Every read the client got was tapped, with the frequency from the reader's own table.
    let mut reads = Vec::new();
    while let Ok(t) = tapped.try_recv() {
        if let Tapped::Reads(r) = t {
            reads.extend(r);
        }
    }
    assert_eq!(tap.dropped(), 0);
    let received: usize = b_back_reads(&b_back);
    assert_eq!(reads.len(), received);
    // S1 is an ETSI reader: the table is whatever its capabilities said.
    let regulatory = caps.regulatory_capabilities.as_ref().expect("regulatory");
    let table = llrp::units::HopTable::from_capabilities(regulatory, 1).expect("a table");
    for read in &reads {
        let ch = read.channel_index.expect("channel index");
        assert_eq!(
            read.channel_frequency_hz,
            table.frequency_khz(ch).map(|k| u64::from(k) * 1000)
        );
        assert!(read.phase_rad.is_some() && read.rssi_dbm.is_some());
        assert_eq!(read.reader.as_deref(), Some("test"));
    }
}

/// Number of TagReportData in the RO_ACCESS_REPORTs of a byte stream.
fn b_back_reads(stream: &[u8]) -> usize {
    let mut rest = stream;
    let mut n = 0;
    while let Some(h) = FrameHeader::peek(rest) {
        let len = h.length as usize;
        if let Ok(it) = llrp::reads::tag_reads(&rest[..len]) {
            n += it.count();
        }
        rest = &rest[len..];
    }
    n
}

#[tokio::test]
async fn an_unreachable_upstream_gets_the_client_a_failed_connection_attempt_then_a_close() {
    // A port nobody listens on: bind, note it, close.
    let gone = TcpListener::bind("127.0.0.1:0").await.expect("bind");
    let upstream = gone.local_addr().expect("bound").to_string();
    drop(gone);
    let dir = tempfile::tempdir().expect("temp dir");
    let rec = dir.path().join("rec.jsonl");
    let p = proxy(&upstream, Some(&rec), None).await;
    let mut c = llrp_gateway::net::client::Client::connect(p.addr)
        .await
        .expect("the proxy accepts");
    let m = c.recv(T).await.expect("a notification");
    assert_eq!(
        connection_status(&m),
        Some(ConnectionAttemptStatus::FailedOtherReason),
        "{m:?}"
    );
    c.until_closed(T).await.expect("then closed");
    p.stop().await;
    let r = Recording::open(&rec).expect("reads");
    let m = markers(&r);
    assert_eq!(m.len(), 2, "{m:?}");
    assert_eq!(m[1].0, Event::Disconnect);
    assert!(m[1].1.contains("unreachable"), "{m:?}");
}

#[tokio::test]
async fn when_the_client_leaves_the_proxy_sends_close_connection_so_the_reader_is_free() {
    let reader = TcpListener::bind("127.0.0.1:0").await.expect("bind");
    let upstream = reader.local_addr().expect("bound").to_string();
    let reader_task = tokio::spawn(reader_answering_close(reader));
    let dir = tempfile::tempdir().expect("temp dir");
    let rec = dir.path().join("rec.jsonl");
    let p = proxy(&upstream, Some(&rec), None).await;
    let mut c = TcpStream::connect(p.addr).await.expect("connect");
    let mut greeting = [0u8; 10];
    c.read_exact(&mut greeting).await.expect("greeting");
    drop(c);
    assert!(
        reader_task.await.expect("reader"),
        "the reader got CLOSE_CONNECTION"
    );
    p.stop().await;
    let r = Recording::open(&rec).expect("reads");
    let last = markers(&r).pop().expect("marker");
    assert!(
        last.1.contains("client closed") && last.1.contains("reader closed"),
        "{last:?}"
    );
    let sent = recorded_stream(&r, 1, Direction::ToReader);
    assert_eq!(
        FrameHeader::peek(&sent).map(|h| h.msg_type),
        Some(CloseConnection::TYPE),
        "the proxy's CLOSE_CONNECTION is in the recording"
    );
}

#[tokio::test]
async fn after_a_client_leaves_the_simulated_reader_takes_the_next_one() {
    let sim = start(&s1(), Speed::Factor(1.0)).await;
    let p = proxy(&sim.addrs[0].to_string(), None, None).await;
    for i in 0..3 {
        // The previous client's session may still be closing when the next one connects
        // (the reader then refuses it, as it should): try again until the reader is free.
        let mut welcomed = false;
        for _ in 0..100 {
            let mut c = llrp_gateway::net::client::Client::connect(p.addr)
                .await
                .expect("connects");
            let m = c.recv(T).await.expect("greeting");
            if connection_status(&m) == Some(ConnectionAttemptStatus::Success) {
                welcomed = true;
                // Dropped without CLOSE_CONNECTION; the proxy frees the reader.
                drop(c);
                break;
            }
            c.until_closed(T).await.expect("a refused client is closed");
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        assert!(welcomed, "client {i} never got the reader");
    }
    p.stop().await;
    sim.shutdown().await;
}

#[tokio::test]
async fn a_second_client_is_refused_by_the_reader_itself_not_the_proxy() {
    let sim = start(&s1(), Speed::Factor(1.0)).await;
    let p = proxy(&sim.addrs[0].to_string(), None, None).await;
    let mut first = llrp_gateway::net::client::Client::connect(p.addr)
        .await
        .expect("connects");
    let m = first.recv(T).await.expect("greeting");
    assert_eq!(
        connection_status(&m),
        Some(ConnectionAttemptStatus::Success)
    );
    let mut second = llrp_gateway::net::client::Client::connect(p.addr)
        .await
        .expect("connects");
    let m = second.recv(T).await.expect("refusal");
    assert_eq!(
        connection_status(&m),
        Some(ConnectionAttemptStatus::FailedClientInitiatedConnectionExists)
    );
    second.until_closed(T).await.expect("closed");
    let m = first.recv(T).await.expect("told");
    assert_eq!(
        connection_status(&m),
        Some(ConnectionAttemptStatus::AnotherConnectionAttempted)
    );
    p.stop().await;
    sim.shutdown().await;
}

#[tokio::test]
async fn when_the_upstream_drops_mid_session_the_client_is_closed_and_the_recording_says_why() {
    let reader = TcpListener::bind("127.0.0.1:0").await.expect("bind");
    let upstream = reader.local_addr().expect("bound").to_string();
    tokio::spawn(async move {
        let (mut s, _) = reader.accept().await.expect("accept");
        s.write_all(&frame(0, KeepaliveAck::default()))
            .await
            .expect("greeting");
        let mut buf = [0u8; 10];
        let _ = s.read_exact(&mut buf).await;
        // Gone without a word, in the middle of the session.
    });
    let dir = tempfile::tempdir().expect("temp dir");
    let rec = dir.path().join("rec.jsonl");
    let p = proxy(&upstream, Some(&rec), None).await;
    let mut c = llrp_gateway::net::client::Client::connect(p.addr)
        .await
        .expect("connects");
    c.recv(T).await.expect("greeting");
    c.send(Keepalive::default()).await.expect("send");
    c.until_closed(T)
        .await
        .expect("the proxy closes the client");
    p.stop().await;
    let r = Recording::open(&rec).expect("reads");
    let last = markers(&r).pop().expect("marker");
    assert_eq!(last.0, Event::Disconnect);
    assert!(
        last.1
            .contains("upstream closed the connection mid-session"),
        "{last:?}"
    );
}

/// Largest TCP send plus receive buffers the kernel may give one loopback hop.
fn socket_buffers_max() -> u64 {
    let max = |f: &str| -> u64 {
        std::fs::read_to_string(f)
            .ok()
            .and_then(|s| s.split_whitespace().last().and_then(|v| v.parse().ok()))
            .unwrap_or(8 << 20)
    };
    max("/proc/sys/net/ipv4/tcp_wmem") + max("/proc/sys/net/ipv4/tcp_rmem")
}

#[tokio::test]
async fn a_slow_client_slows_the_reading_from_the_reader_and_nothing_piles_up() {
    // The reader sends as fast as it can: frames of 60 KiB, far more than every buffer on
    // the way (two hops of socket buffers and the proxy's chunk).
    let hop = socket_buffers_max();
    let frame_len = 60 * 1024;
    let total = 4 * (2 * hop + (8 << 20));
    let frames = total / frame_len;
    let mut one = vec![0u8; frame_len as usize];
    FrameHeader {
        version: 1,
        msg_type: 1023,
        length: frame_len as u32,
        id: 0,
    }
    .encode(&mut &mut one[..10]);
    let reader = TcpListener::bind("127.0.0.1:0").await.expect("bind");
    let upstream = reader.local_addr().expect("bound").to_string();
    let written = Arc::new(AtomicU64::new(0));
    let w = Arc::clone(&written);
    let one2 = one.clone();
    tokio::spawn(async move {
        let (mut s, _) = reader.accept().await.expect("accept");
        for i in 0..frames {
            let mut f = one2.clone();
            f[6..10].copy_from_slice(&(i as u32).to_be_bytes());
            if s.write_all(&f).await.is_err() {
                return;
            }
            w.fetch_add(frame_len, Ordering::Relaxed);
        }
        let _ = s.shutdown().await;
    });
    let p = proxy(&upstream, None, None).await;
    let mut c = TcpStream::connect(p.addr).await.expect("connect");
    // The client reads nothing until the reader can write no more: no progress over three
    // samples in a row (a machine busy elsewhere may pause the reader for one).
    let mut last = u64::MAX;
    let mut still = 0;
    while still < 3 {
        tokio::time::sleep(Duration::from_millis(300)).await;
        let now = written.load(Ordering::Relaxed);
        still = if now == last { still + 1 } else { 0 };
        last = now;
    }
    let bound = 2 * hop + (1 << 20);
    assert!(
        last < total && last <= bound,
        "the reader wrote {last} bytes to a client that reads nothing (bound {bound}, total {total})"
    );
    // Then it reads everything, unchanged and in order.
    let mut got = Vec::with_capacity(total as usize);
    c.read_to_end(&mut got).await.expect("read");
    assert_eq!(got.len() as u64, frames * frame_len);
    for (i, f) in got.chunks(frame_len as usize).enumerate() {
        assert_eq!(&f[6..10], &(i as u32).to_be_bytes(), "frame {i} in order");
        assert_eq!(&f[10..], &one[10..]);
    }
    p.stop().await;
}

#[tokio::test]
async fn an_overloaded_tap_drops_and_counts_while_forwarding_loses_nothing() {
    let sim = start(&s1(), Speed::Factor(1.0)).await;
    // Room for one item, and nobody taking it; relays on both sides log what each saw.
    let (tap, mut tapped): (Tap, mpsc::Receiver<Tapped>) = Tap::new(1);
    let (b_addr, b_log, b_task) = relay(sim.addrs[0]).await;
    let p = proxy(&b_addr.to_string(), None, Some(tap.clone())).await;
    let (a_addr, a_log, a_task) = relay(p.addr).await;
    let mut c = llrp_gateway::net::client::Client::connect(a_addr)
        .await
        .expect("connects");
    c.recv(T).await.expect("greeting");
    start_inventory(&mut c).await;
    let (tags, _) = collect_reports(&mut c, Duration::from_secs(20), |t| t.len() >= 30).await;
    assert!(tags.len() >= 30);
    c.request(CloseConnection::default(), T)
        .await
        .expect("closed");
    c.until_closed(T).await.expect("closed");
    drop(c);
    a_task.await.expect("relay A");
    b_task.await.expect("relay B");
    p.stop().await;
    sim.shutdown().await;
    let back = b_log.back.lock().expect("lock").clone();
    assert_eq!(
        *a_log.back.lock().expect("lock"),
        back,
        "the client got every byte"
    );
    assert_eq!(
        *a_log.forward.lock().expect("lock"),
        *b_log.forward.lock().expect("lock"),
        "the reader got every byte"
    );
    let (mut items, mut kept) = (0, 0);
    while let Ok(t) = tapped.try_recv() {
        items += 1;
        kept += match t {
            Tapped::Reads(r) => r.len() as u64,
            Tapped::Event { .. } => 1,
        };
    }
    assert_eq!(items, 1, "the one slot is full");
    // Every read and every notification (the greeting too) the reader sent was offered.
    let offered = b_back_reads(&back) as u64 + count_kind(&back, ReaderEventNotification::TYPE);
    assert!(offered > tags.len() as u64);
    assert_eq!(
        tap.dropped() + kept,
        offered,
        "dropped {} kept {kept} offered {offered}",
        tap.dropped()
    );
    assert!(tap.dropped() > 0);
}

#[tokio::test]
async fn the_simulated_reader_records_its_sessions_as_the_proxy_does() {
    let dir = tempfile::tempdir().expect("temp dir");
    let rec = dir.path().join("sim.jsonl");
    let sim = llrp_gateway::sim::start(
        &s1(),
        &llrp_gateway::sim::SimOptions {
            record: Some(rec.clone()),
            ..Default::default()
        },
    )
    .await
    .expect("starts");
    let (addr, log, task) = relay(sim.addrs[0]).await;
    let mut c = llrp_gateway::net::client::Client::connect(addr)
        .await
        .expect("connects");
    c.recv(T).await.expect("greeting");
    c.request(ImpinjEnableExtensions::default(), T)
        .await
        .expect("extensions");
    start_inventory(&mut c).await;
    let (tags, _) = collect_reports(&mut c, Duration::from_secs(20), |t| t.len() >= 10).await;
    assert!(tags.len() >= 10);
    c.request(CloseConnection::default(), T)
        .await
        .expect("closed");
    c.until_closed(T).await.expect("closed");
    drop(c);
    task.await.expect("relay");
    sim.shutdown().await;
    let r = Recording::open(&rec).expect("reads");
    assert_eq!(r.header.upstream, "sim:s1-reader");
    assert_eq!(r.header.scenario.as_deref(), Some("s1"));
    assert_eq!(
        recorded_stream(&r, 1, Direction::ToReader),
        log.forward.lock().expect("lock").clone()
    );
    assert_eq!(
        recorded_stream(&r, 1, Direction::FromReader),
        log.back.lock().expect("lock").clone()
    );
    let m = markers(&r);
    assert_eq!(m.first().map(|m| m.0), Some(Event::Connect));
    assert_eq!(m.last().map(|m| m.0), Some(Event::Disconnect));
}

#[tokio::test]
async fn at_shutdown_each_reader_gets_close_connection_and_each_client_is_closed() {
    let reader = TcpListener::bind("127.0.0.1:0").await.expect("bind");
    let upstream = reader.local_addr().expect("bound").to_string();
    let reader_task = tokio::spawn(reader_answering_close(reader));
    let dir = tempfile::tempdir().expect("temp dir");
    let rec = dir.path().join("rec.jsonl");
    let p = proxy(&upstream, Some(&rec), None).await;
    let mut c = llrp_gateway::net::client::Client::connect(p.addr)
        .await
        .expect("connects");
    c.recv(T).await.expect("greeting");
    // The proxy stops while the session is open.
    let _ = p.stop.send(true);
    c.until_closed(T).await.expect("the client is closed");
    assert!(
        reader_task.await.expect("reader"),
        "the reader got CLOSE_CONNECTION"
    );
    p.task.await.expect("joined").expect("proxy ran");
    p.recording
        .expect("recording")
        .await
        .expect("joined")
        .expect("written");
    let r = Recording::open(&rec).expect("reads");
    let last = markers(&r).pop().expect("marker");
    assert!(
        last.1.contains("proxy shutting down") && last.1.contains("reader closed"),
        "{last:?}"
    );
}

/// A scripted reader: greets, then sends a KEEPALIVE every 10 ms, answers CLOSE_CONNECTION
/// and closes; gives back every byte it received.
async fn chatty_reader(listener: TcpListener) -> Vec<u8> {
    let (s, _) = listener.accept().await.expect("accept");
    let (mut rd, mut wr) = s.into_split();
    let writer = tokio::spawn(async move {
        let _ = wr.write_all(&frame(0, KeepaliveAck::default())).await;
        for i in 1.. {
            tokio::time::sleep(Duration::from_millis(10)).await;
            if wr.write_all(&frame(i, Keepalive::default())).await.is_err() {
                return wr;
            }
        }
        wr
    });
    let mut got = Vec::new();
    let mut buf = [0u8; 4096];
    loop {
        match rd.read(&mut buf).await {
            Ok(0) | Err(_) => break,
            Ok(n) => got.extend_from_slice(&buf[..n]),
        }
        if let Some(h) = FrameHeader::peek(&got) {
            if h.msg_type == CloseConnection::TYPE && got.len() >= h.length as usize {
                break;
            }
        }
    }
    writer.abort();
    got
}

#[tokio::test]
async fn a_client_that_resets_still_gets_the_reader_close_connection() {
    // Which side of the proxy notices the reset first varies: several rounds.
    for round in 0..5 {
        let reader = TcpListener::bind("127.0.0.1:0").await.expect("bind");
        let upstream = reader.local_addr().expect("bound").to_string();
        let reader_task = tokio::spawn(chatty_reader(reader));
        let p = proxy(&upstream, None, None).await;
        let mut c = TcpStream::connect(p.addr).await.expect("connect");
        let mut greeting = [0u8; 10];
        c.read_exact(&mut greeting).await.expect("greeting");
        // Closing with SO_LINGER 0 sends a reset, not a FIN.
        #[allow(deprecated)]
        c.set_linger(Some(Duration::ZERO)).expect("linger");
        drop(c);
        let got = reader_task.await.expect("reader");
        assert_eq!(
            FrameHeader::peek(&got).map(|h| h.msg_type),
            Some(CloseConnection::TYPE),
            "round {round}: the reader got {got:?}"
        );
        p.stop().await;
    }
}

#[tokio::test]
async fn a_client_gone_inside_a_frame_gets_no_close_connection_spliced_into_it() {
    let reader = TcpListener::bind("127.0.0.1:0").await.expect("bind");
    let upstream = reader.local_addr().expect("bound").to_string();
    let reader_task = tokio::spawn(async move {
        let (mut s, _) = reader.accept().await.expect("accept");
        s.write_all(&frame(0, KeepaliveAck::default()))
            .await
            .expect("greeting");
        let mut got = Vec::new();
        let _ = s.read_to_end(&mut got).await;
        got
    });
    let dir = tempfile::tempdir().expect("temp dir");
    let rec = dir.path().join("rec.jsonl");
    let p = proxy(&upstream, Some(&rec), None).await;
    let mut c = TcpStream::connect(p.addr).await.expect("connect");
    let mut greeting = [0u8; 10];
    c.read_exact(&mut greeting).await.expect("greeting");
    let whole = frame(7, GetReaderConfig::default());
    let half = &whole[..whole.len() - 3];
    c.write_all(half).await.expect("send");
    c.shutdown().await.expect("close");
    let got = reader_task.await.expect("reader");
    assert_eq!(
        got, half,
        "the reader got the cut frame and nothing after it"
    );
    p.stop().await;
    let r = Recording::open(&rec).expect("reads");
    assert_eq!(recorded_stream(&r, 1, Direction::ToReader), half);
    let last = markers(&r).pop().expect("marker");
    assert!(last.1.contains("inside a frame"), "{last:?}");
}

/// Number of frames of message type `msg_type` in a byte stream.
fn count_kind(stream: &[u8], msg_type: u16) -> u64 {
    let mut rest = stream;
    let mut n = 0;
    while let Some(h) = FrameHeader::peek(rest) {
        n += u64::from(h.msg_type == msg_type);
        rest = &rest[h.length as usize..];
    }
    n
}

/// Adds and enables an ROSpec on every antenna reporting each read, with every field and the
/// Impinj ones; both must succeed.
async fn start_inventory(c: &mut llrp_gateway::net::client::Client) {
    let spec = rospec(
        1,
        vec![0],
        ro_null(),
        ai_null(),
        full_report(RoReportTriggerType::UponNTagsOrEndOfAiSpec, 1),
    );
    let add = AddRospec {
        ro_spec: spec,
        ..Default::default()
    };
    assert_eq!(request_status(c, add).await, StatusCode::M_Success);
    let enable = EnableRospec {
        ro_spec_id: 1,
        ..Default::default()
    };
    assert_eq!(request_status(c, enable).await, StatusCode::M_Success);
}

/// A scripted reader: greets, takes whatever comes until CLOSE_CONNECTION, answers it and
/// closes; whether CLOSE_CONNECTION came.
async fn reader_answering_close(listener: TcpListener) -> bool {
    let (s, _) = listener.accept().await.expect("accept");
    let mut conn = llrp_gateway::net::connection::Connection::new(s);
    conn.write_message(&Message::new(0, KeepaliveAck::default()))
        .await
        .expect("greeting");
    while let Ok(Some(llrp::Inbound::Frame(f))) = conn.read_frame().await {
        let m = Message::decode(&f).expect("decodes");
        if let MessageBody::CloseConnection(_) = m.body {
            conn.write_message(&Message::new(m.id, CloseConnectionResponse::default()))
                .await
                .expect("answer");
            conn.shutdown().await.expect("close");
            return true;
        }
    }
    false
}

#[tokio::test]
async fn a_client_over_the_limit_is_told_and_closed_and_a_freed_place_is_taken_again() {
    // A reader that greets each connection and counts them.
    let reader = TcpListener::bind("127.0.0.1:0").await.expect("bind");
    let upstream = reader.local_addr().expect("bound").to_string();
    let (seen_tx, mut seen) = mpsc::unbounded_channel();
    tokio::spawn(async move {
        let mut held = Vec::new();
        while let Ok((s, _)) = reader.accept().await {
            let mut conn = llrp_gateway::net::connection::Connection::new(s);
            let _ = conn
                .write_message(&Message::new(0, KeepaliveAck::default()))
                .await;
            held.push(conn);
            let _ = seen_tx.send(held.len());
        }
    });
    let config = ProxyConfig {
        name: "limited".parse().expect("a reader name"),
        upstream,
        listen: "127.0.0.1:0".into(),
        record: None,
        region: None,
        connect_timeout: Duration::from_secs(5),
        tls: None,
        upstream_tls: None,
    };
    let p = Proxy::bind(config, None, None)
        .await
        .expect("binds")
        .with_max_clients(1);
    let addr = p.local_addr().expect("bound");
    let (stop, rx) = watch::channel(false);
    let task = tokio::spawn(p.run(rx));
    // The first client holds the one place: the reader has its connection.
    let first = TcpStream::connect(addr).await.expect("connect");
    assert_eq!(seen.recv().await, Some(1));
    // The second is told as when the reader cannot be reached, and closed; the reader never
    // hears of it.
    let mut second = llrp_gateway::net::client::Client::connect(addr)
        .await
        .expect("the proxy accepts");
    let m = second.recv(T).await.expect("a notification");
    assert_eq!(
        connection_status(&m),
        Some(ConnectionAttemptStatus::FailedOtherReason),
        "{m:?}"
    );
    second.until_closed(T).await.expect("then closed");
    // Once the first leaves, a new client reaches the reader (after the proxy has seen the
    // first go: until then it is told as the second was).
    drop(first);
    let mut reached = false;
    for _ in 0..1000 {
        let mut c = TcpStream::connect(addr).await.expect("connect");
        let mut greeting = [0u8; 10];
        let _ = c.read(&mut greeting).await;
        if FrameHeader::peek(&greeting).map(|h| h.msg_type) == Some(KeepaliveAck::TYPE) {
            reached = true;
            break;
        }
        tokio::time::sleep(Duration::from_millis(2)).await;
    }
    assert!(reached, "a freed place is taken again");
    assert_eq!(seen.recv().await, Some(2));
    stop.send(true).expect("the proxy listens");
    task.await.expect("joined").expect("proxy ran");
}
