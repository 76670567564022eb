//! Proxy latency: how long an RO_ACCESS_REPORT takes from a reader's socket to its client's,
//! with both ends in this one process so that one monotonic clock stamps both sides.
//!
//! Usage: `proxy_latency LISTEN CONNECT[,CONNECT...] RATE SECONDS [WARMUP]` (driven by
//! `scripts/bench-proxy`; `cargo bench` alone, without arguments, prints the usage and does
//! nothing).
//!
//! * LISTEN: where the scripted reader listens (`127.0.0.1:PORT`).
//! * CONNECT: where a client connects: LISTEN itself (direct), or a proxy whose upstream is
//!   LISTEN (`llrp-gateway proxy --upstream LISTEN`). With several, one client per address,
//!   all at once, and the reader sends every frame to each of them, back to back (the order
//!   rotating from frame to frame): the paths are measured over the same moments, so a busy
//!   spell of the host falls on all of them alike.
//! * RATE: frames per second the reader sends, paced on absolute deadlines; 0 sends as fast as
//!   the path takes them (full load; meant for one CONNECT).
//! * SECONDS: how long the reader sends.
//! * WARMUP: frames sent first and left out of the statistics (default 100).
//!
//! The reader accepts one connection per client, sends a READER_EVENT_NOTIFICATION greeting
//! (ConnectionAttemptEvent Success), waits a moment, and then sends one frame after another:
//! an RO_ACCESS_REPORT of one TagReportData (EPC-96, AntennaID, PeakRSSI, ChannelIndex, first
//! and last seen UTC timestamps, TagSeenCount, ImpinjRFPhaseAngle and ImpinjPeakRSSI: the
//! fields an Impinj reader sends for sllurp's `--impinj-reports`), encoded once, with frame `i`
//! carrying message ID `i`. Just before each frame's `write`, it notes the frame's send time in
//! a table per connection indexed by ID. Each client reads as much as its socket holds at a
//! time, notes the receive time of that read for every whole frame in it (found with
//! `llrp::FrameSplitter`), and checks that each frame arrived once and byte for byte as sent
//! (apart from the ID). Latency is receive time minus send time, per frame.
//!
//! Output: one JSON line per CONNECT, in order, with the frame count, the achieved rate,
//! p50 / p99 / p99.9 / max of the latency in µs, and the frames lost, doubled or changed (all
//! three must be 0).

use std::io::{self, Read, Write};
use std::net::{Shutdown, TcpListener, TcpStream};
use std::process::ExitCode;
use std::thread;
use std::time::{Duration, Instant};

use llrp::message::ReaderEventNotification;
use llrp::{FrameSplitter, Message, Split};

/// Longest wait for the connection to come through (the proxy connects upstream only when
/// its client has connected).
const CONNECT_TIMEOUT: Duration = Duration::from_secs(10);

/// Pause between the greeting and the first frame, so that both connections are set up.
const SETTLE: Duration = Duration::from_millis(200);

/// Longest the client waits past the sending time for the last frames.
const DRAIN: Duration = Duration::from_secs(10);

/// Receive buffer size.
const BUF_LEN: usize = 1 << 20;

/// Where the message ID sits in an LLRP header.
const ID_AT: std::ops::Range<usize> = 6..10;

/// Not yet received.
const MISSING: u64 = u64::MAX;

fn main() -> ExitCode {
    // `cargo bench` appends `--bench`; anything starting with `-` is ignored.
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with('-'))
        .collect();
    let (listen, connect, rate, seconds, warmup) = match args.as_slice() {
        [l, c, r, s] => (l, c, r, s, "100"),
        [l, c, r, s, w] => (l, c, r, s, w.as_str()),
        _ => {
            eprintln!(
                "usage: proxy_latency LISTEN CONNECT[,CONNECT...] RATE SECONDS [WARMUP]  (run by \
                 scripts/bench-proxy; nothing to do without addresses)"
            );
            return ExitCode::SUCCESS;
        }
    };
    let (Ok(rate), Ok(seconds), Ok(warmup)) = (
        rate.parse::<f64>(),
        seconds.parse::<f64>(),
        warmup.parse::<usize>(),
    ) else {
        eprintln!("proxy_latency: RATE and SECONDS must be numbers, WARMUP an integer");
        return ExitCode::FAILURE;
    };
    if !(rate >= 0.0 && rate.is_finite() && seconds > 0.0 && seconds.is_finite()) {
        eprintln!("proxy_latency: RATE must be ≥ 0 and SECONDS positive");
        return ExitCode::FAILURE;
    }
    let plan = Plan {
        rate,
        duration: Duration::from_secs_f64(seconds),
        warmup,
    };
    let connect: Vec<&str> = connect.split(',').collect();
    match run(listen, &connect, &plan) {
        Ok(paths) => {
            let mut bad = false;
            for (r, addr) in paths.iter().zip(&connect) {
                println!("{}", r.json(&plan, addr));
                bad |= r.lost + r.doubled + r.changed > 0;
            }
            if bad {
                eprintln!("proxy_latency: frames were lost, doubled or changed");
                return ExitCode::FAILURE;
            }
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("proxy_latency: {e}");
            ExitCode::FAILURE
        }
    }
}

/// What to send.
struct Plan {
    /// Frames per second; 0 = as fast as possible.
    rate: f64,
    /// How long to send.
    duration: Duration,
    /// Frames left out of the statistics at the start.
    warmup: usize,
}

/// What one measurement saw.
struct Outcome {
    /// Frames counted (after the warm-up).
    frames: usize,
    /// Frames per second sent, over the counted frames.
    sent_per_sec: f64,
    /// Latencies of the counted frames, ns, sorted.
    latency_ns: Vec<u64>,
    /// Frames sent and never received.
    lost: usize,
    /// Frames received more than once.
    doubled: usize,
    /// Frames that differ from what was sent.
    changed: usize,
}

impl Outcome {
    /// The value at quantile `q` (nearest rank), µs.
    fn quantile_us(&self, q: f64) -> f64 {
        let v = &self.latency_ns;
        if v.is_empty() {
            return f64::NAN;
        }
        let rank = ((q * v.len() as f64).ceil() as usize).clamp(1, v.len());
        v[rank - 1] as f64 / 1e3
    }

    fn json(&self, plan: &Plan, addr: &str) -> String {
        format!(
            "{{\"connect\": \"{addr}\", \"rate\": {}, \"frames\": {}, \"sent_per_sec\": {:.0}, \"p50_us\": {:.1}, \
             \"p99_us\": {:.1}, \"p999_us\": {:.1}, \"max_us\": {:.1}, \"lost\": {}, \
             \"doubled\": {}, \"changed\": {}, \"warmup\": {}}}",
            plan.rate,
            self.frames,
            self.sent_per_sec,
            self.quantile_us(0.5),
            self.quantile_us(0.99),
            self.quantile_us(0.999),
            self.quantile_us(1.0),
            self.lost,
            self.doubled,
            self.changed,
            plan.warmup
        )
    }
}

fn other(msg: String) -> io::Error {
    io::Error::other(msg)
}

/// The greeting a reader sends on a new connection.
fn greeting() -> Vec<u8> {
    use llrp::enums::ConnectionAttemptStatus;
    use llrp::params::{
        ConnectionAttemptEvent, ReaderEventNotificationData, Timestamp, UtcTimestamp,
    };
    let body = ReaderEventNotification {
        reader_event_notification_data: ReaderEventNotificationData {
            timestamp: Timestamp::Utc(UtcTimestamp {
                microseconds: 1_763_900_000_000_000,
                ..Default::default()
            }),
            connection_attempt_event: Some(ConnectionAttemptEvent {
                status: ConnectionAttemptStatus::Success,
                ..Default::default()
            }),
            ..Default::default()
        },
        ..Default::default()
    };
    Message::new(0, body).to_bytes().to_vec()
}

/// The frame the reader sends (before its ID is set): one tag read as an Impinj reader
/// reports it.
fn report() -> Message {
    use llrp::impinj::{ImpinjPeakRssi, ImpinjRfPhaseAngle};
    use llrp::message::RoAccessReport;
    use llrp::params::{
        AntennaId, ChannelIndex, Custom, Epc, Epc96, FirstSeenTimestampUtc, LastSeenTimestampUtc,
        PeakRssi, TagReportData, TagSeenCount,
    };
    let seen_us = 1_763_900_000_000_000;
    let read = TagReportData {
        epc: Epc::Epc96(Epc96([
            0x30, 0x08, 0x33, 0xb2, 0xdd, 0xd9, 0x01, 0x40, 0x00, 0x00, 0x00, 0x2a,
        ])),
        antenna_id: Some(AntennaId(2)),
        peak_rssi: Some(PeakRssi(-52)),
        channel_index: Some(ChannelIndex(17)),
        first_seen_timestamp_utc: Some(FirstSeenTimestampUtc(seen_us)),
        last_seen_timestamp_utc: Some(LastSeenTimestampUtc(seen_us + 250)),
        tag_seen_count: Some(TagSeenCount(1)),
        custom: vec![
            Custom::ImpinjRfPhaseAngle(ImpinjRfPhaseAngle {
                phase_angle: 1234,
                ..Default::default()
            }),
            Custom::ImpinjPeakRssi(ImpinjPeakRssi {
                rssi: -5210,
                ..Default::default()
            }),
        ],
        ..Default::default()
    };
    Message::new(
        0,
        RoAccessReport {
            tag_report_data: vec![read],
            ..Default::default()
        },
    )
}

/// Accepts one connection on `listener` within [`CONNECT_TIMEOUT`].
fn accept(listener: &TcpListener) -> io::Result<TcpStream> {
    listener.set_nonblocking(true)?;
    let deadline = Instant::now() + CONNECT_TIMEOUT;
    loop {
        match listener.accept() {
            Ok((s, _)) => {
                s.set_nonblocking(false)?;
                return Ok(s);
            }
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                if Instant::now() >= deadline {
                    return Err(other("no upstream connection came to the reader".into()));
                }
                thread::sleep(Duration::from_millis(1));
            }
            Err(e) => return Err(e),
        }
    }
}

/// The scripted reader: greeting, then frames per `plan`, each frame on every connection
/// (in an order that rotates from frame to frame, so that no path is always first); returns,
/// per connection, each frame's send time (ns since `epoch`) indexed by message ID.
fn reader(
    mut conns: Vec<TcpStream>,
    plan: &Plan,
    template: &[u8],
    epoch: Instant,
) -> io::Result<Vec<Vec<u64>>> {
    for s in &mut conns {
        s.write_all(&greeting())?;
    }
    thread::sleep(SETTLE);
    let mut frame = template.to_vec();
    let expected = if plan.rate > 0.0 {
        (plan.rate * plan.duration.as_secs_f64()) as usize + plan.warmup + 1
    } else {
        1 << 20
    };
    let mut sent = vec![Vec::with_capacity(expected); conns.len()];
    let start = Instant::now();
    let end = start + plan.duration;
    let period = (plan.rate > 0.0).then(|| Duration::from_secs_f64(1.0 / plan.rate));
    let m = conns.len();
    let mut i: u32 = 0;
    loop {
        let now = Instant::now();
        if let Some(p) = period {
            let due = start + p * i;
            if due >= end {
                break;
            }
            if due > now {
                thread::sleep(due - now);
            }
        } else if now >= end {
            break;
        }
        frame[ID_AT].copy_from_slice(&i.to_be_bytes());
        for k in 0..m {
            let j = (i as usize + k) % m;
            sent[j].push(epoch.elapsed().as_nanos() as u64);
            conns[j].write_all(&frame)?;
        }
        i = i
            .checked_add(1)
            .ok_or_else(|| other("more frames than message IDs".into()))?;
    }
    // End of stream; then wait for the other side to close (the proxy passes the end on to
    // the client, whose close comes back the same way).
    for s in &conns {
        s.shutdown(Shutdown::Write)?;
    }
    let mut sink = [0u8; 4096];
    for s in &mut conns {
        s.set_read_timeout(Some(DRAIN))?;
        while matches!(s.read(&mut sink), Ok(k) if k > 0) {}
    }
    Ok(sent)
}

/// What the client saw: each frame's receive time (ns since `epoch`, [`MISSING`] if never)
/// indexed by message ID, and the frames doubled and changed.
struct Received {
    at: Vec<u64>,
    doubled: usize,
    changed: usize,
}

/// The client: waits for the greeting, then notes the receive time of every RO_ACCESS_REPORT
/// until the end of the stream.
fn client(
    mut s: TcpStream,
    template: &[u8],
    epoch: Instant,
    give_up: Instant,
) -> io::Result<Received> {
    s.set_read_timeout(Some(Duration::from_millis(100)))?;
    let report_type = llrp::FrameHeader::peek(template)
        .ok_or_else(|| other("template has no header".into()))?
        .msg_type;
    let splitter = FrameSplitter::default();
    let mut buf = vec![0u8; BUF_LEN];
    let (mut start, mut end) = (0usize, 0usize);
    let mut r = Received {
        at: Vec::with_capacity(1 << 16),
        doubled: 0,
        changed: 0,
    };
    loop {
        if start == end {
            start = 0;
            end = 0;
        } else if end == buf.len() {
            buf.copy_within(start..end, 0);
            end -= start;
            start = 0;
        }
        let k = match s.read(&mut buf[end..]) {
            Ok(0) => return Ok(r),
            Ok(k) => k,
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                ) =>
            {
                if Instant::now() >= give_up {
                    return Ok(r);
                }
                continue;
            }
            Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e),
        };
        let now = epoch.elapsed().as_nanos() as u64;
        end += k;
        loop {
            match splitter.split(&buf[start..end]) {
                Ok(Split::Frame(h)) => {
                    let f = &buf[start..start + h.length as usize];
                    start += h.length as usize;
                    if h.msg_type != report_type {
                        continue;
                    }
                    let id = h.id as usize;
                    if f.len() != template.len()
                        || f[..ID_AT.start] != template[..ID_AT.start]
                        || f[ID_AT.end..] != template[ID_AT.end..]
                    {
                        r.changed += 1;
                    }
                    if id >= r.at.len() {
                        r.at.resize((id + 1).max(r.at.len() * 2), MISSING);
                    }
                    if r.at[id] == MISSING {
                        r.at[id] = now;
                    } else {
                        r.doubled += 1;
                    }
                }
                Ok(Split::Incomplete(_)) => break,
                Err(e) => return Err(other(format!("bad frame: {e}"))),
            }
        }
    }
}

/// Sets up one connection per address in `connect` (each accepted by the reader before the
/// next is made, so the reader's connections are in the same order), runs the plan, and
/// returns what each path saw.
fn run(listen: &str, connect: &[&str], plan: &Plan) -> io::Result<Vec<Outcome>> {
    let template = report().to_bytes().to_vec();
    let listener = TcpListener::bind(listen)?;
    let epoch = Instant::now();
    let (mut clients, mut at_reader) = (Vec::new(), Vec::new());
    for addr in connect {
        let c = TcpStream::connect(addr)?;
        c.set_nodelay(true)?;
        clients.push(c);
        let r = accept(&listener)?;
        r.set_nodelay(true)?;
        at_reader.push(r);
    }
    let give_up = Instant::now() + SETTLE + plan.duration + DRAIN;
    let (sent, received) = thread::scope(|scope| {
        let t = &template;
        let rx: Vec<_> = clients
            .into_iter()
            .map(|c| scope.spawn(move || client(c, t, epoch, give_up)))
            .collect();
        let tx = scope.spawn(move || reader(at_reader, plan, t, epoch));
        let sent = tx
            .join()
            .map_err(|_| other("reader thread panicked".into()));
        let received: Vec<_> = rx
            .into_iter()
            .map(|h| h.join().map_err(|_| other("client thread panicked".into())))
            .collect();
        (sent, received)
    });
    let sent = sent??;
    sent.into_iter()
        .zip(received)
        .map(|(sent, received)| outcome(plan, &sent, &received??))
        .collect()
}

/// The statistics of one path.
fn outcome(plan: &Plan, sent: &[u64], received: &Received) -> io::Result<Outcome> {
    let counted = sent.len().saturating_sub(plan.warmup);
    if counted == 0 {
        return Err(other("no frame sent after the warm-up".into()));
    }
    let mut latency_ns = Vec::with_capacity(counted);
    let mut lost = 0;
    for (id, &t_sent) in sent.iter().enumerate() {
        match received.at.get(id).copied().unwrap_or(MISSING) {
            MISSING => lost += 1,
            t if id >= plan.warmup => latency_ns.push(t.saturating_sub(t_sent)),
            _ => {}
        }
    }
    latency_ns.sort_unstable();
    let first = sent.get(plan.warmup).copied().unwrap_or(0);
    let last = sent.last().copied().unwrap_or(first);
    let span = (last.saturating_sub(first)) as f64 / 1e9;
    Ok(Outcome {
        frames: counted,
        sent_per_sec: if span > 0.0 {
            (counted - 1) as f64 / span
        } else {
            0.0
        },
        latency_ns,
        lost,
        doubled: received.doubled,
        changed: received.changed,
    })
}
