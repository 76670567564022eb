//! The publishing thread: turns what the tap mirrors (LLRP frames, reads, poses, readers
//! coming) into messages for the outbox ([`super::publish`]).

use std::collections::{BTreeMap, HashMap};
use std::sync::atomic::Ordering;
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::sync::Arc;
use std::time::{Duration, Instant};

use super::publish::{lock, topic_level, Link, PublishOptions};
use super::schema::{self, TagRead, VERSION};
use crate::localize::live::Input;
use crate::localize::poses::PoseSample;
use crate::reads::Read;

/// A [`ReadBatch`](super::schema::ReadBatch) serialized without copying its reads.
#[derive(serde::Serialize)]
struct BatchRef<'a> {
    v: u32,
    gateway: &'a str,
    reader: &'a str,
    run: u64,
    seq: u64,
    reads: &'a [TagRead],
}

/// LLRP's message type of READER_EVENT_NOTIFICATION.
const READER_EVENT_NOTIFICATION: u16 = 63;

/// Most reads in one batch message.
pub const MAX_BATCH_READS: usize = 1000;

/// Reads waiting for their batch's window to close, per topic.
struct Pending {
    reads: Vec<TagRead>,
    since: Instant,
}

/// The publishing thread: turns inputs into messages.
pub(super) struct Builder {
    opts: PublishOptions,
    link: Arc<Link>,
    decoders: crate::reads::Decoders,
    /// Reader time − robot time, per reader (poses go out in the reads' clock).
    offsets: HashMap<String, i64>,
    /// Per reader, per topic (under `v1/`), the last sequence number used.
    seqs: BTreeMap<String, BTreeMap<String, u64>>,
    /// Per reader, per topic (under `v1/`): the reads waiting for their window.
    pending: HashMap<String, HashMap<String, Pending>>,
    /// When the first pending window closes.
    next_due: Option<Instant>,
    /// `reads/{shard}` for every shard.
    shard_topics: Vec<String>,
    /// Poses waiting for their window to close, per topic (under `v1/`).
    pending_poses: BTreeMap<String, (Vec<PoseSample>, Instant)>,
    /// JSON bytes a read and a pose sample took in the last message of each: a message's
    /// buffer is made that big at once (grown as serde_json writes, it was copied a dozen
    /// times).
    json_per: [usize; 2],
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
            pending_poses: BTreeMap::new(),
            json_per: [512, 256],
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

    fn take(&mut self, input: Input) {
        match input {
            Input::Reader {
                name,
                hop_table,
                clock_offset_us,
                poses,
                ..
            } => {
                self.decoders.register(&name, hop_table, poses);
                self.offsets.insert(name.clone(), clock_offset_us);
                self.came(&name);
            }
            Input::Frames {
                reader,
                bytes,
                now_utc_us,
            } => {
                self.came(&reader);
                let decoder = self.decoders.of(&reader);
                // The reads of each RO_ACCESS_REPORT apart: without a window, a message each;
                // with one, all in one list.
                let apart = self.opts.window.is_zero();
                let mut reports: Vec<Vec<Read>> = vec![Vec::new()];
                let mut events = Vec::new();
                for frame in crate::reads::frames(&bytes) {
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
                    self.reads(&reader, reads);
                }
                for e in events {
                    self.event(&reader, &e);
                }
            }
            Input::Reads(reads) => {
                let mut by_reader: BTreeMap<String, Vec<Read>> = BTreeMap::new();
                for r in reads {
                    let name = r.reader.clone().unwrap_or_default();
                    by_reader.entry(name).or_default().push(r);
                }
                for (reader, reads) in by_reader {
                    self.reads(&reader, reads);
                }
            }
            Input::Poses(poses) => self.poses(poses),
            Input::Status { reader, online } => {
                if online {
                    self.came(&reader);
                } else if lock(&self.link.online).remove(&reader) {
                    let last = self.seqs.get(&reader).cloned().unwrap_or_default();
                    self.link.status(Some(&reader), false, last);
                }
            }
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
        let window = self.opts.window;
        if !self.pending.contains_key(reader) {
            self.pending.insert(reader.to_owned(), HashMap::new());
        }
        let Some(topics) = self.pending.get_mut(reader) else {
            return;
        };
        let mut touched: Vec<usize> = Vec::new();
        let mut refs = false;
        let mut add = |topic: &str, read: TagRead| {
            let p = match topics.get_mut(topic) {
                Some(p) => p,
                None => topics.entry(topic.to_owned()).or_insert(Pending {
                    reads: Vec::new(),
                    since: now,
                }),
            };
            if p.reads.is_empty() {
                p.since = now;
            }
            p.reads.push(read);
        };
        for r in reads {
            let reference = self.opts.references.contains(&r.epc);
            let shard = usize::from(schema::shard(&r.epc, self.opts.shard_count));
            let t = TagRead::from_owned(r);
            if reference {
                add("refs", t.clone());
                refs = true;
            }
            if let Some(topic) = self.shard_topics.get(shard) {
                add(topic, t);
                if !touched.contains(&shard) {
                    touched.push(shard);
                }
            }
        }
        let mut send: Vec<String> = Vec::new();
        let full = |p: Option<&Pending>| p.is_some_and(|p| p.reads.len() >= MAX_BATCH_READS);
        if refs && (window.is_zero() || full(topics.get("refs"))) {
            send.push("refs".into());
        }
        for topic in touched.into_iter().filter_map(|s| self.shard_topics.get(s)) {
            if window.is_zero() || full(topics.get(topic.as_str())) {
                send.push(topic.clone());
            }
        }
        let due = now + window;
        self.next_due = Some(self.next_due.map_or(due, |d| d.min(due)));
        for topic in send {
            self.send(reader, &topic);
        }
    }

    /// Sends the batches whose window has closed (all with `all`), poses too.
    fn flush(&mut self, all: bool) {
        self.flush_poses(all);
        let now = Instant::now();
        if !all && self.next_due.map_or(true, |d| now < d) {
            return;
        }
        let window = self.opts.window;
        let mut due: Vec<(String, String)> = Vec::new();
        let mut next: Option<Instant> = None;
        for (reader, topics) in &self.pending {
            for (topic, p) in topics {
                if p.reads.is_empty() {
                    continue;
                }
                if all || now.duration_since(p.since) >= window {
                    due.push((reader.clone(), topic.clone()));
                } else {
                    let at = p.since + window;
                    next = Some(next.map_or(at, |n| n.min(at)));
                }
            }
        }
        self.next_due = next;
        for (reader, topic) in due {
            self.send(&reader, &topic);
        }
    }

    /// Publishes what waits for `reader` on `rest`, in messages of at most
    /// [`MAX_BATCH_READS`] reads.
    fn send(&mut self, reader: &str, rest: &str) {
        let Some(p) = self.pending.get_mut(reader).and_then(|t| t.get_mut(rest)) else {
            return;
        };
        // The next window's reads go into a list as long as this one's (grown from empty,
        // it was copied a dozen times a window).
        let room = p.reads.len();
        let reads = std::mem::replace(&mut p.reads, Vec::with_capacity(room));
        for chunk in reads.chunks(MAX_BATCH_READS) {
            let seq = self.next_seq(reader, rest);
            let batch = BatchRef {
                v: VERSION,
                gateway: &self.opts.gateway,
                reader,
                run: self.opts.run,
                seq,
                reads: chunk,
            };
            let payload = to_json(&batch, chunk.len(), &mut self.json_per[0]);
            self.link
                .publish(rest, false, payload, chunk.len() as u64, true);
        }
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
            let offset = self.offsets.get(&p.reader).copied().unwrap_or(0);
            p.t_us = p.t_us.saturating_add_signed(offset);
            let rest = format!("poses/{}/{}", topic_level(&p.reader), p.antenna);
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
            let payload = to_json(&poses, poses.len(), &mut self.json_per[1]);
            self.link
                .publish(&rest, false, payload, poses.len() as u64, false);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_batch_serialized_by_reference_parses_as_the_schemas_batch() {
        let read = crate::reads::Read {
            epc: "E2801160600002049ACB0065".into(),
            reader: Some("r1".into()),
            antenna: 2,
            t_us: 1_764_633_600_000_001,
            phase_rad: Some(0.5),
            rssi_dbm: Some(-60.0),
            channel_index: Some(1),
            channel_frequency_hz: Some(865_700_000),
            doppler_hz: None,
            antenna_pose: None,
            last_seen_us: None,
        };
        let reads = [TagRead::from_read(&read)];
        let json = serde_json::to_vec(&BatchRef {
            v: VERSION,
            gateway: "gw",
            reader: "r1",
            run: 1_764_633_000_000_000,
            seq: 7,
            reads: &reads,
        })
        .expect("serializes");
        let b: schema::ReadBatch = serde_json::from_slice(&json).expect("the schema's batch");
        assert_eq!(
            (b.v, b.gateway.as_str(), b.reader.as_str(), b.run, b.seq),
            (1, "gw", "r1", 1_764_633_000_000_000, 7)
        );
        assert_eq!(b.reads, reads);
    }
}
