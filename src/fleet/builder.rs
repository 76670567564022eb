//! The publishing thread: turns what the tap mirrors (LLRP frames, reads, poses, readers
//! coming) into messages for the outbox ([`super::publish`]).

use crate::reads::ReaderName;
use std::collections::{BTreeMap, HashMap};
use std::sync::atomic::Ordering;
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::sync::Arc;
use std::time::{Duration, Instant};

use super::json;
use super::publish::{lock, topic_level, Link, PublishOptions};
use super::schema::{self, TagRead, VERSION};
use crate::localize::live::Input;
use crate::localize::poses::PoseSample;
use crate::reads::Read;

/// LLRP's message type of READER_EVENT_NOTIFICATION.
const READER_EVENT_NOTIFICATION: u16 = 63;

/// Most reads in one batch message.
pub const MAX_BATCH_READS: usize = 1000;

/// Reads waiting for their batch's window to close, on one topic, already JSON.
#[derive(Default)]
struct Pending {
    /// The reads as [`json::tag_read`] writes them, comma-separated (kept between batches,
    /// so its room is made once).
    json: Vec<u8>,
    /// How many reads `json` holds.
    count: usize,
    /// When the first of them came.
    since: Option<Instant>,
}

impl Pending {
    fn push(&mut self, read: &TagRead, now: Instant) {
        if self.count == 0 {
            self.since = Some(now);
        } else {
            self.json.push(b',');
        }
        json::tag_read(&mut self.json, read);
        self.count += 1;
    }
}

/// Where a read waits: its shard's batch, or the reference tags' (`refs`).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Slot {
    Refs,
    Shard(usize),
}

/// One reader's pending batches.
struct ReaderPending {
    /// Per shard.
    shards: Vec<Pending>,
    /// The reference tags'.
    refs: Pending,
}

impl ReaderPending {
    fn new(shards: usize) -> ReaderPending {
        ReaderPending {
            shards: (0..shards).map(|_| Pending::default()).collect(),
            refs: Pending::default(),
        }
    }

    fn slot(&mut self, slot: Slot) -> Option<&mut Pending> {
        match slot {
            Slot::Refs => Some(&mut self.refs),
            Slot::Shard(s) => self.shards.get_mut(s),
        }
    }
}

/// The publishing thread: turns inputs into messages.
pub(super) struct Builder {
    opts: PublishOptions,
    link: Arc<Link>,
    decoders: crate::reads::Decoders,
    /// Reader time − robot time, per reader (poses go out in the reads' clock).
    offsets: HashMap<ReaderName, i64>,
    /// Per reader, per topic (under `v1/`), the last sequence number used.
    seqs: BTreeMap<String, BTreeMap<String, u64>>,
    /// Per reader: the reads waiting for their window.
    pending: HashMap<String, ReaderPending>,
    /// When the first pending window closes.
    next_due: Option<Instant>,
    /// `reads/{shard}` for every shard.
    shard_topics: Vec<String>,
    /// The reads' `lastSeenTime`s.
    clock: schema::Rfc3339Clock,
    /// Poses waiting for their window to close, per topic (under `v1/`).
    pending_poses: BTreeMap<String, (Vec<PoseSample>, Instant)>,
    /// JSON bytes a pose sample took in the last message: a message's buffer is made that
    /// big at once (grown as serde_json writes, it was copied a dozen times).
    pose_json_per: usize,
}

/// `value` as JSON into a buffer made for `items` of `per` bytes each; `per` becomes what
/// one took this time.
fn to_json(value: &impl serde::Serialize, items: usize, per: &mut usize) -> Vec<u8> {
    let mut out = Vec::with_capacity(items * *per + 256);
    // Reads and pose samples are plain values (finite numbers, strings): they always
    // serialize, and into a Vec nothing can fail.
    let _ = serde_json::to_writer(&mut out, value);
    *per = out.len() / items.max(1) + 16;
    out
}

impl Builder {
    pub(super) fn new(opts: PublishOptions, link: Arc<Link>) -> Builder {
        let shard_topics = (0..opts.shard_count.max(1))
            .map(|s| format!("reads/{s}"))
            .collect();
        Builder {
            opts,
            link,
            decoders: crate::reads::Decoders::default(),
            offsets: HashMap::new(),
            seqs: BTreeMap::new(),
            pending: HashMap::new(),
            next_due: None,
            shard_topics,
            clock: schema::Rfc3339Clock::default(),
            pending_poses: BTreeMap::new(),
            pose_json_per: 256,
        }
    }

    pub(super) fn run(mut self, rx: Receiver<Input>) {
        let tick = if self.opts.window.is_zero() {
            Duration::from_millis(100)
        } else {
            self.opts.window.min(Duration::from_millis(100))
        };
        loop {
            // Soon again while messages wait for a window.
            let wait = if self.link.outbox_empty() {
                tick
            } else {
                tick.min(Duration::from_millis(5))
            };
            match rx.recv_timeout(wait) {
                Ok(input) => self.take(input),
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => break,
            }
            self.flush(false);
            self.link.pump();
            if self.link.stopping.load(Ordering::Relaxed) {
                while let Ok(input) = rx.try_recv() {
                    self.take(input);
                }
                break;
            }
        }
        self.flush(true);
        let online: Vec<String> = std::mem::take(&mut *lock(&self.link.online))
            .into_iter()
            .collect();
        for r in online {
            let last = self.seqs.get(&r).cloned().unwrap_or_default();
            self.link.status(Some(&r), false, last);
        }
        self.link.status(None, false, BTreeMap::new());
        self.link.pump();
    }

    /// Takes one input from the tap: registers, decodes or publishes it.
    fn take(&mut self, input: Input) {
        match input {
            Input::Reader {
                name,
                hop_table,
                antennas,
                clock_offset_us,
                poses,
            } => {
                self.decoders.register(&name, hop_table, &antennas, poses);
                self.offsets.insert(name.clone(), clock_offset_us);
                self.came(&name);
            }
            Input::Frames {
                reader,
                bytes,
                now_utc_us,
            } => self.frames(&reader, &bytes, now_utc_us),
            Input::Reads(reads) => self.reads_of_readers(reads),
            Input::Poses(poses) => self.poses(poses),
            // A simulation's ground truth is not published.
            Input::Truth(_) => {}
            Input::Status { reader, online } => self.status(&reader, online),
            Input::Event { reader, data } => {
                self.came(&reader);
                self.event(&reader, &data);
            }
            Input::Keepalive {
                reader,
                lost,
                period_ms,
                silent_ms,
            } => {
                let link = schema::KeepaliveEvent {
                    state: if lost { "lost" } else { "restored" }.into(),
                    period_ms,
                    silent_ms,
                };
                self.event_of(&reader, "keepalive", &link);
            }
        }
    }

    /// Publishes the reads and events in the frames `bytes` of reader `reader`.
    fn frames(&mut self, reader: &ReaderName, bytes: &[u8], now_utc_us: u64) {
        self.came(reader);
        let decoder = self.decoders.of(reader);
        // The reads of each RO_ACCESS_REPORT apart: without a window, a message each;
        // with one, all in one list.
        let apart = self.opts.window.is_zero();
        let mut reports: Vec<Vec<Read>> = vec![Vec::new()];
        let mut events = Vec::new();
        for frame in crate::reads::frames(bytes) {
            let Ok(frame) = frame else {
                break;
            };
            let is_event = llrp::FrameHeader::peek(frame)
                .is_some_and(|h| h.msg_type == READER_EVENT_NOTIFICATION);
            if is_event {
                if let Ok(m) = llrp::Message::decode(frame) {
                    if let llrp::MessageBody::ReaderEventNotification(n) = m.body {
                        events.push(n.reader_event_notification_data);
                    }
                }
            } else if let Some(reads) = reports.last_mut() {
                let _ = decoder.frame(frame, now_utc_us, reads);
                if apart && !reads.is_empty() {
                    reports.push(Vec::new());
                }
            }
        }
        for reads in reports {
            self.reads(reader, reads);
        }
        for e in events {
            self.event(reader, &e);
        }
    }

    /// Reads of any readers published, reader by reader.
    fn reads_of_readers(&mut self, reads: Vec<Read>) {
        // The reads that name no reader are published under "".
        let mut by_reader: BTreeMap<String, Vec<Read>> = BTreeMap::new();
        for r in reads {
            let name = r.reader.as_deref().unwrap_or_default().to_owned();
            by_reader.entry(name).or_default().push(r);
        }
        for (reader, reads) in by_reader {
            self.reads(&reader, reads);
        }
    }

    /// Reader `reader` went online or offline: said once.
    fn status(&mut self, reader: &str, online: bool) {
        if online {
            self.came(reader);
        } else if lock(&self.link.online).remove(reader) {
            let last = self.seqs.get(reader).cloned().unwrap_or_default();
            self.link.status(Some(reader), false, last);
        }
    }

    /// Reader `reader` is online: announced the first time.
    fn came(&mut self, reader: &str) {
        if lock(&self.link.online).insert(reader.to_owned()) {
            self.link.status(Some(reader), true, BTreeMap::new());
        }
    }

    fn next_seq(&mut self, reader: &str, rest: &str) -> u64 {
        let n = self
            .seqs
            .entry(reader.to_owned())
            .or_default()
            .entry(rest.to_owned())
            .or_insert(0);
        *n += 1;
        *n
    }

    fn reads(&mut self, reader: &str, reads: Vec<Read>) {
        if reads.is_empty() {
            return;
        }
        self.came(reader);
        let now = Instant::now();
        // The reader's batches, out of the map while its reads go in.
        let (name, mut batches) = self.pending.remove_entry(reader).unwrap_or_else(|| {
            (
                reader.to_owned(),
                ReaderPending::new(self.shard_topics.len()),
            )
        });
        let mut touched: Vec<Slot> = Vec::new();
        for r in reads {
            let reference = self.opts.references.contains(r.epc.as_str());
            let shard = Slot::Shard(usize::from(schema::shard(&r.epc, self.opts.shard_count)));
            let t = TagRead::from_owned(r, &mut self.clock);
            for slot in [reference.then_some(Slot::Refs), Some(shard)]
                .into_iter()
                .flatten()
            {
                let Some(p) = batches.slot(slot) else {
                    continue;
                };
                p.push(&t, now);
                if p.count >= MAX_BATCH_READS {
                    self.send(&name, slot, p);
                } else if !touched.contains(&slot) {
                    touched.push(slot);
                }
            }
        }
        if self.opts.window.is_zero() {
            for slot in touched {
                if let Some(p) = batches.slot(slot) {
                    self.send(&name, slot, p);
                }
            }
        }
        self.pending.insert(name, batches);
        let due = now + self.opts.window;
        self.next_due = Some(self.next_due.map_or(due, |d| d.min(due)));
    }

    /// Sends the batches whose window has closed (all with `all`), poses too.
    fn flush(&mut self, all: bool) {
        self.flush_poses(all);
        let now = Instant::now();
        if !all && self.next_due.is_none_or(|d| now < d) {
            return;
        }
        let window = self.opts.window;
        let mut next: Option<Instant> = None;
        let readers: Vec<String> = self.pending.keys().cloned().collect();
        for reader in readers {
            let Some(mut batches) = self.pending.remove(&reader) else {
                continue;
            };
            let slots = (0..batches.shards.len())
                .map(Slot::Shard)
                .chain([Slot::Refs]);
            for slot in slots {
                let Some(p) = batches.slot(slot) else {
                    continue;
                };
                let Some(since) = p.since.filter(|_| p.count > 0) else {
                    continue;
                };
                if all || now.duration_since(since) >= window {
                    self.send(&reader, slot, p);
                } else {
                    let at = since + window;
                    next = Some(next.map_or(at, |n| n.min(at)));
                }
            }
            self.pending.insert(reader, batches);
        }
        self.next_due = next;
    }

    /// Publishes the reads `p` holds for `reader` on `slot`'s topic as one message.
    fn send(&mut self, reader: &str, slot: Slot, p: &mut Pending) {
        if p.count == 0 {
            return;
        }
        let rest = match slot {
            Slot::Refs => "refs".to_owned(),
            Slot::Shard(s) => match self.shard_topics.get(s) {
                Some(topic) => topic.clone(),
                None => return,
            },
        };
        let seq = self.next_seq(reader, &rest);
        let head = json::Head {
            v: VERSION,
            gateway: &self.opts.gateway,
            reader,
            run: self.opts.run,
            seq,
        };
        let payload = json::batch(&head, &p.json);
        let count = p.count as u64;
        p.json.clear();
        p.count = 0;
        p.since = None;
        self.link.publish(&rest, false, payload, count, true);
    }

    fn event(&mut self, reader: &str, data: &llrp::params::ReaderEventNotificationData) {
        self.event_of(reader, "event", data);
    }

    /// Publishes `value` as field `key` of a message on `events/{reader}`.
    fn event_of(&mut self, reader: &str, key: &str, value: &impl serde::Serialize) {
        let rest = format!("events/{}", topic_level(reader));
        let seq = self.next_seq(reader, &rest);
        let mut payload = serde_json::json!({
            "v": VERSION,
            "gateway": self.opts.gateway,
            "reader": reader,
            "run": self.opts.run,
            "seq": seq,
        });
        // An event of plain values always serializes.
        payload[key] = serde_json::to_value(value).unwrap_or_default();
        self.link
            .publish(&rest, false, payload.to_string().into_bytes(), 1, true);
    }

    fn poses(&mut self, poses: Vec<PoseSample>) {
        for mut p in poses {
            // In the reads' clock, as a worker files them.
            let reader = p.reader.as_deref().unwrap_or_default();
            let offset = self.offsets.get(reader).copied().unwrap_or(0);
            p.t_us = p.t_us.saturating_add_signed(offset);
            let rest = format!("poses/{}/{}", topic_level(reader), p.antenna);
            self.pending_poses
                .entry(rest)
                .or_insert_with(|| (Vec::new(), Instant::now()))
                .0
                .push(p);
        }
        // Batched over the window like the reads (a message per input without one).
        self.flush_poses(self.opts.window.is_zero());
    }

    /// Sends the pose batches whose window has closed (all with `all`) or that are full.
    fn flush_poses(&mut self, all: bool) {
        let due: Vec<String> = self
            .pending_poses
            .iter()
            .filter(|(_, (p, since))| {
                all || p.len() >= MAX_BATCH_READS || since.elapsed() >= self.opts.window
            })
            .map(|(k, _)| k.clone())
            .collect();
        for rest in due {
            let Some((poses, _)) = self.pending_poses.remove(&rest) else {
                continue;
            };
            let payload = to_json(&poses, poses.len(), &mut self.pose_json_per);
            self.link
                .publish(&rest, false, payload, poses.len() as u64, false);
        }
    }
}
