//! Replaying a recording as a reader, sans-IO: a [`Script`] is made once from one recorded
//! connection; each client gets a [`ReplaySession`] that takes its frames and the time, and
//! gives out the frames to send and when it next needs to run.
//!
//! - **Greeting**: the frames the reader sent before the first request, at their offsets
//!   from the connection's start.
//! - **Answers**: each request gets the recorded response to the same message type, in
//!   order (the n-th GET_READER_CONFIG gets the n-th recorded answer, the last one again
//!   when the client asks more often), with the message ID rewritten to the client's.
//! - **Streams**: reports, events and keepalives are tied to the request that preceded them
//!   in the recording (by type and occurrence) and follow the client's same request at
//!   their recorded offsets, divided by the speed.
//! - **Divergence**: a request the recording never answered gets the LLRP error a reader
//!   gives (the response type with M_UnsupportedMessage, or ERROR_MESSAGE), and the first
//!   divergence is logged once.
//! - **Loop**: the last stream that carries tag reports starts over when it ends, its
//!   timestamps shifted by the stream's length each time.

use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;

use bytes::{BufMut, Bytes, BytesMut};
use llrp::message::{
    CloseConnection, CloseConnectionResponse, ErrorMessage, MessageBody, RoAccessReport,
};
use llrp::params::{LlrpStatus, Timestamp};
use llrp::{FrameHeader, Message, MessageKind, Response, StatusCode};

use super::format::{Direction, Entry, Recording};

/// A frame to send at an offset (µs of recorded time) from its anchor.
#[derive(Clone, Debug)]
struct Timed {
    offset_us: u64,
    frame: Bytes,
}

/// Why a recording cannot be replayed.
#[derive(Debug, thiserror::Error)]
pub enum ScriptError {
    /// The recording has no connection with frames.
    #[error("the recording holds no frames")]
    Empty,
    /// The asked-for connection is not in the recording.
    #[error("connection {0} is not in the recording (it has {1:?})")]
    NoSuchConnection(u32, Vec<u32>),
}

/// What to replay: one recorded connection, organised by request.
#[derive(Clone, Debug)]
pub struct Script {
    conn: u32,
    greeting: Vec<Timed>,
    responses: HashMap<MessageKind, Vec<Bytes>>,
    streams: HashMap<(MessageKind, usize), Vec<Timed>>,
    /// The stream `--loop` repeats, and its period in recorded µs.
    looped: Option<((MessageKind, usize), u64)>,
}

/// Whether a client message gets an answer (all but KEEPALIVE_ACK and
/// ENABLE_EVENTS_AND_REPORTS; vendor messages the codec does not know are taken to be
/// requests).
fn answered(kind: MessageKind) -> bool {
    use llrp::message::{EnableEventsAndReports, KeepaliveAck};
    kind != KeepaliveAck::KIND && kind != EnableEventsAndReports::KIND
}

/// Whether a reader sends this kind on its own (not as an answer).
fn unsolicited(kind: MessageKind) -> bool {
    use llrp::message::{Keepalive, ReaderEventNotification};
    [
        RoAccessReport::KIND,
        ReaderEventNotification::KIND,
        Keepalive::KIND,
    ]
    .contains(&kind)
}

impl Script {
    /// The script of connection `conn` of `recording`; by default its first connection that
    /// carries an LLRP session (the client sent a frame and the reader answered), else its
    /// first connection whose reader sent a frame.
    pub fn new(recording: &Recording, conn: Option<u32>) -> Result<Script, ScriptError> {
        let conn = Script::pick_conn(recording, conn)?;
        let start = recording
            .entries
            .iter()
            .find(|e| e.conn() == conn)
            .map(|e| e.at().t_us)
            .unwrap_or(0);
        let mut script = Script {
            conn,
            greeting: Vec::new(),
            responses: HashMap::new(),
            streams: HashMap::new(),
            looped: None,
        };
        script.file_frames(recording, start);
        // Captures' timestamps can go backwards: each list in time order.
        script.greeting.sort_by_key(|t| t.offset_us);
        for frames in script.streams.values_mut() {
            frames.sort_by_key(|t| t.offset_us);
        }
        script.looped = script.loop_stream(recording);
        Ok(script)
    }

    /// The connection to replay: `conn` if the recording has it, else the default one.
    fn pick_conn(recording: &Recording, conn: Option<u32>) -> Result<u32, ScriptError> {
        let conns = recording.connections();
        Ok(match conn {
            Some(c) if conns.contains(&c) => c,
            Some(c) => return Err(ScriptError::NoSuchConnection(c, conns)),
            None => {
                let all = recording.summaries();
                all.iter()
                    .find(|s| s.has_session())
                    .or_else(|| all.iter().find(|s| s.from_reader > 0))
                    .ok_or(ScriptError::Empty)?
                    .conn
            }
        })
    }

    /// Files each frame of the connection as greeting, response or stream frame.
    fn file_frames(&mut self, recording: &Recording, start: u64) {
        let mut seen: HashMap<MessageKind, usize> = HashMap::new();
        // Requests waiting for their answer: message ID → kind.
        let mut open: HashMap<u32, MessageKind> = HashMap::new();
        let mut anchor: Option<((MessageKind, usize), u64)> = None;
        for e in &recording.entries {
            let Entry::Frame {
                at,
                conn: c,
                dir,
                frame,
                ..
            } = e
            else {
                continue;
            };
            if *c != self.conn {
                continue;
            }
            let (Some(kind), Some(h)) = (MessageKind::of_frame(frame), FrameHeader::peek(frame))
            else {
                continue;
            };
            match dir {
                Direction::ToReader => {
                    if !answered(kind) {
                        continue;
                    }
                    let n = seen.entry(kind).or_default();
                    anchor = Some(((kind, *n), at.t_us));
                    *n += 1;
                    open.insert(h.id, kind);
                }
                Direction::FromReader => {
                    if !unsolicited(kind) {
                        if let Some(req) = open.remove(&h.id) {
                            self.responses.entry(req).or_default().push(frame.clone());
                            continue;
                        }
                    }
                    match anchor {
                        None => self.greeting.push(Timed {
                            offset_us: at.t_us.saturating_sub(start),
                            frame: frame.clone(),
                        }),
                        Some((key, t0)) => self.streams.entry(key).or_default().push(Timed {
                            offset_us: at.t_us.saturating_sub(t0),
                            frame: frame.clone(),
                        }),
                    }
                }
            }
        }
    }

    /// The stream to loop and its period: the last one (by its anchor's place) with reports.
    fn loop_stream(&self, recording: &Recording) -> Option<((MessageKind, usize), u64)> {
        let mut best: Option<((MessageKind, usize), u64)> = None;
        let mut best_first = 0;
        for (key, frames) in &self.streams {
            let reports: Vec<&Timed> = frames
                .iter()
                .filter(|t| MessageKind::of_frame(&t.frame) == Some(RoAccessReport::KIND))
                .collect();
            let (Some(first), Some(last)) = (reports.first(), reports.last()) else {
                continue;
            };
            // Order by the anchor's place: the stream whose first report is latest.
            let first_abs = first.offset_us + anchor_time(recording, self.conn, key);
            if best.is_none() || first_abs > best_first {
                let gap = if reports.len() > 1 {
                    last.offset_us.saturating_sub(first.offset_us) / (reports.len() as u64 - 1)
                } else {
                    1_000
                };
                best = Some((
                    *key,
                    last.offset_us
                        .saturating_sub(first.offset_us)
                        .saturating_add(gap.max(1)),
                ));
                best_first = first_abs;
            }
        }
        best
    }

    /// The recorded connection this script replays.
    pub fn conn(&self) -> u32 {
        self.conn
    }

    /// Number of recorded responses (for logs).
    pub fn responses(&self) -> usize {
        self.responses.values().map(Vec::len).sum()
    }

    /// Number of recorded reports, events and keepalives (for logs).
    pub fn unsolicited(&self) -> usize {
        self.greeting.len() + self.streams.values().map(Vec::len).sum::<usize>()
    }
}

/// The recorded time of the request anchoring `key`.
fn anchor_time(recording: &Recording, conn: u32, key: &(MessageKind, usize)) -> u64 {
    let mut n = 0;
    for (at, dir, frame) in recording.frames(conn) {
        if dir == Direction::ToReader && MessageKind::of_frame(frame) == Some(key.0) {
            if n == key.1 {
                return at.t_us;
            }
            n += 1;
        }
    }
    0
}

/// How a replay runs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReplayOptions {
    /// Recorded offsets are divided by this; `None` sends every frame as soon as it is due
    /// by order (`--speed max`).
    pub speed: Option<f64>,
    /// Start the reports stream over when it ends.
    pub looped: bool,
}

/// What a session has to send.
#[derive(Debug, Default)]
pub struct Output {
    /// The bytes, whole frames.
    pub bytes: BytesMut,
    /// Close the connection once they are sent.
    pub close: bool,
}

/// One client's replay.
#[derive(Debug)]
pub struct ReplaySession {
    script: Arc<Script>,
    options: ReplayOptions,
    seen: HashMap<MessageKind, usize>,
    /// Frames due, by (due time µs, sequence) → frame.
    due: BTreeMap<(u64, u64), Bytes>,
    seq: u64,
    out: Output,
    /// The first divergence, once it happened.
    diverged: Option<String>,
    /// Loops of the looped stream so far, and when its first round started.
    rounds: u64,
    loop_started: Option<u64>,
}

impl ReplaySession {
    /// A session for a client that connected at `now_us` (any monotonic µs clock).
    pub fn new(script: Arc<Script>, options: ReplayOptions, now_us: u64) -> Self {
        let mut s = ReplaySession {
            script,
            options,
            seen: HashMap::new(),
            due: BTreeMap::new(),
            seq: 0,
            out: Output::default(),
            diverged: None,
            rounds: 0,
            loop_started: None,
        };
        let greeting = s.script.greeting.clone();
        s.schedule(now_us, &greeting, 0);
        s
    }

    fn scale(&self, offset_us: u64) -> u64 {
        match self.options.speed {
            Some(x) => (offset_us as f64 / x) as u64,
            None => 0,
        }
    }

    fn schedule(&mut self, now_us: u64, frames: &[Timed], shift_us: u64) {
        for t in frames {
            let frame = if shift_us == 0 {
                t.frame.clone()
            } else {
                shift_timestamps(&t.frame, shift_us)
            };
            self.due.insert(
                (now_us.saturating_add(self.scale(t.offset_us)), self.seq),
                frame,
            );
            self.seq += 1;
        }
    }

    /// The first divergence from the recording, if any.
    pub fn divergence(&self) -> Option<&str> {
        self.diverged.as_deref()
    }

    fn diverge(&mut self, what: String) {
        if self.diverged.is_none() {
            tracing::warn!("replay diverges from the recording: {what}");
            self.diverged = Some(what);
        }
    }

    /// Takes a frame from the client.
    pub fn receive(&mut self, frame: &[u8], now_us: u64) {
        let (Some(kind), Some(h)) = (MessageKind::of_frame(frame), FrameHeader::peek(frame)) else {
            return;
        };
        if !answered(kind) {
            return;
        }
        let n = {
            let c = self.seen.entry(kind).or_default();
            *c += 1;
            *c - 1
        };
        let script = Arc::clone(&self.script);
        let recorded = script
            .responses
            .get(&kind)
            .and_then(|r| r.get(n).or(r.last()));
        match recorded {
            Some(r) => {
                let mut bytes = r.to_vec();
                bytes[6..10].copy_from_slice(&h.id.to_be_bytes());
                self.out.bytes.put_slice(&bytes);
            }
            None if kind == CloseConnection::KIND => {
                let m = Message {
                    version: h.version,
                    id: h.id,
                    body: CloseConnectionResponse::with_status(LlrpStatus::new(
                        StatusCode::M_Success,
                        "",
                    ))
                    .into(),
                };
                m.encode(&mut self.out.bytes);
            }
            None => {
                self.diverge(format!(
                    "the client sent {} (its #{}) and the recording never answered one",
                    kind.name(),
                    n + 1
                ));
                let status = LlrpStatus::new(
                    StatusCode::M_UnsupportedMessage,
                    "not in the recording being replayed",
                );
                let body = kind.error_response(status.clone()).unwrap_or_else(|| {
                    ErrorMessage {
                        llrp_status: status,
                        ..Default::default()
                    }
                    .into()
                });
                Message {
                    version: h.version,
                    id: h.id,
                    body,
                }
                .encode(&mut self.out.bytes);
            }
        }
        if kind == CloseConnection::KIND {
            self.due.clear();
            self.out.close = true;
            return;
        }
        if let Some(frames) = self.script.streams.get(&(kind, n)) {
            let frames = frames.clone();
            self.schedule(now_us, &frames, 0);
            if self.script.looped.map(|(k, _)| k) == Some((kind, n)) {
                self.loop_started = Some(now_us);
            }
        }
    }

    /// Moves the frames due by `now_us` to the output, at most about `max_bytes` of them;
    /// with `--loop`, starts the looped stream over once it has run out.
    pub fn advance(&mut self, now_us: u64, max_bytes: usize) {
        while self.out.bytes.len() < max_bytes {
            let Some(entry) = self.due.first_entry() else {
                break;
            };
            if entry.key().0 > now_us {
                break;
            }
            let frame = entry.remove();
            self.out.bytes.put_slice(&frame);
        }
        if self.options.looped && self.due.is_empty() && !self.out.close {
            if let (Some(((kind, n), period)), Some(started)) =
                (self.script.looped, self.loop_started)
            {
                self.rounds += 1;
                // Round k runs k periods after the first, at the recorded offsets.
                let at = match self.options.speed {
                    Some(_) => {
                        started.saturating_add(self.scale(self.rounds.saturating_mul(period)))
                    }
                    None => now_us,
                };
                let frames = self
                    .script
                    .streams
                    .get(&(kind, n))
                    .cloned()
                    .unwrap_or_default();
                // Only the reports and events from the stream's first report on repeat.
                let first = frames
                    .iter()
                    .find(|t| MessageKind::of_frame(&t.frame) == Some(RoAccessReport::KIND))
                    .map_or(0, |t| t.offset_us);
                let again: Vec<Timed> = frames
                    .into_iter()
                    .filter(|t| t.offset_us >= first)
                    .collect();
                self.schedule(at, &again, self.rounds.saturating_mul(period));
            }
        }
    }

    /// What is waiting to be sent.
    pub fn transmit(&mut self) -> &mut Output {
        &mut self.out
    }

    /// When the next frame is due (µs), if any.
    pub fn deadline(&self) -> Option<u64> {
        self.due.keys().next().map(|k| k.0)
    }

    /// Whether the session has nothing more to send and was told to close.
    pub fn closing(&self) -> bool {
        self.out.close
    }
}

/// `frame` with its UTC and uptime timestamps moved `shift_us` later (tag reads' first and
/// last seen, an event's timestamp); unchanged if it does not decode.
pub fn shift_timestamps(frame: &[u8], shift_us: u64) -> Bytes {
    let Ok(mut m) = Message::decode(frame) else {
        return Bytes::copy_from_slice(frame);
    };
    match &mut m.body {
        MessageBody::RoAccessReport(r) => {
            for t in &mut r.tag_report_data {
                if let Some(x) = &mut t.first_seen_timestamp_utc {
                    x.0 = x.0.saturating_add(shift_us);
                }
                if let Some(x) = &mut t.first_seen_timestamp_uptime {
                    x.0 = x.0.saturating_add(shift_us);
                }
                if let Some(x) = &mut t.last_seen_timestamp_utc {
                    x.0 = x.0.saturating_add(shift_us);
                }
                if let Some(x) = &mut t.last_seen_timestamp_uptime {
                    x.0 = x.0.saturating_add(shift_us);
                }
            }
        }
        MessageBody::ReaderEventNotification(r) => {
            match &mut r.reader_event_notification_data.timestamp {
                Timestamp::Utc(t) => t.microseconds = t.microseconds.saturating_add(shift_us),
                Timestamp::Uptime(t) => t.microseconds = t.microseconds.saturating_add(shift_us),
            }
        }
        _ => return Bytes::copy_from_slice(frame),
    }
    m.to_bytes().freeze()
}

pub mod server;

#[cfg(test)]
mod tests;
