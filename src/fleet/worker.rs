//! A localizer worker (`localize --subscribe`): takes the read shards it owns, the reference
//! reads and the poses from the broker with a persistent session, feeds them to the live
//! localizer it is given (the command's composition root starts it), and publishes each
//! estimate, retained, to `PREFIX/v1/estimates/{epc}`.
//!
//! Messages are acknowledged only once the localizer has taken them, so reads published
//! while the worker is down, or taken but not yet filed when it dies, come again from its
//! session. Readers' statuses set their `connected` in `GET /api/readers` (a gateway's
//! `offline` clears its readers'); a reader's clean `offline` carries its last sequence
//! numbers, so messages missing at the end of a topic count as gaps too. A batch late into a
//! gap is filed (a broker may redeliver out of order, as NATS JetStream does); a missing
//! number counts as a gap once it is far behind or the reader's clean `offline` closes the
//! topic; a batch already seen is counted as a duplicate and skipped ([`super::seq`]). A
//! batch that comes ahead of a missing one is held until the gap fills or
//! [`super::seq::HOLD`] passes, so each topic's batches are filed in sequence order whatever
//! order the broker delivers them in. A held batch is acknowledged as it is held (a broker
//! may deliver the missing one only once those before it are acknowledged): a worker killed
//! while holding loses what it held, at most [`super::seq::MAX_HELD`] batches a topic. A malformed message or one on a topic not
//! ours is counted and skipped.

use crate::reads::ReaderName;
use std::collections::{BTreeSet, HashMap};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use rumqttc::{Client, Connection, Event, Packet, Publish, QoS};

use super::metrics::MqttMetrics;
use super::presence::{Presence, PresenceEvent};
use super::publish::{mqtt_options, reconnect_backoff, refusal, topic_level, PublishError};
use super::schema::{self, ReadBatch, VERSION};
use super::seq::{Seq, Step};
use super::url::BrokerUrl;
use crate::localize::live::{Input, Tap};
use crate::localize::shared::{Shared, TagJson};

/// How a worker runs.
#[derive(Clone, Debug)]
pub struct WorkerOptions {
    /// The broker.
    pub url: BrokerUrl,
    /// The shards this worker owns.
    pub shards: BTreeSet<u16>,
    /// How many shards the publishers split the reads into.
    pub shard_count: u16,
    /// The MQTT client id, which names its persistent session.
    pub client_id: String,
    /// TLS settings for `mqtts://`.
    pub tls: Option<Arc<tokio_rustls::rustls::ClientConfig>>,
    /// A tag has departed after this long without a read (wall-clock time at the worker).
    pub presence_silence: Duration,
    /// A `moved` event when the estimate moves more than this (m).
    pub presence_move_m: f64,
}

/// A running worker: it feeds a localizer it is given and publishes its estimates.
pub struct Worker {
    client: Client,
    stopping: Arc<AtomicBool>,
    connection: Option<JoinHandle<()>>,
    estimates: Option<JoinHandle<()>>,
}

/// The shards of a `--shards` list such as `0-7` or `0,3,8-11`, each below `count`.
pub fn parse_shards(list: &str, count: u16) -> Result<BTreeSet<u16>, String> {
    let mut out = BTreeSet::new();
    for part in list.split(',').map(str::trim) {
        let (lo, hi) = match part.split_once('-') {
            Some((a, b)) => (a.trim(), b.trim()),
            None => (part, part),
        };
        let num = |s: &str| {
            s.parse::<u16>()
                .map_err(|_| format!("--shards {list}: '{s}' is not a shard number"))
        };
        let (lo, hi) = (num(lo)?, num(hi)?);
        if lo > hi {
            return Err(format!("--shards {list}: {lo}-{hi} is an empty range"));
        }
        if hi >= count {
            return Err(format!(
                "--shards {list}: shard {hi} is not below --shard-count {count}"
            ));
        }
        out.extend(lo..=hi);
    }
    Ok(out)
}

impl Worker {
    /// Starts the localizer, connects and subscribes (waiting up to 5 s for the broker to
    /// acknowledge the subscriptions: a refusal of the connection is an error, an
    /// unreachable broker is retried in the background).
    pub fn start(
        opts: WorkerOptions,
        tap: Tap,
        shared: Arc<Shared>,
        metrics: MqttMetrics,
    ) -> Result<Worker, PublishError> {
        let mut mqtt = mqtt_options(&opts.url, &opts.client_id, false, opts.tls.clone())?;
        mqtt.set_ack_mode(rumqttc::AckMode::Manual);
        let (client, connection) = Client::builder(mqtt).capacity(10_000).build();
        let stopping = Arc::new(AtomicBool::new(false));
        let presence = Arc::new(Mutex::new(Presence::new(
            opts.presence_silence,
            opts.presence_move_m,
        )));
        let (first_tx, first_rx) = mpsc::channel();
        let mut run = Run {
            opts: opts.clone(),
            client: client.clone(),
            live_tap: tap,
            shared: shared.clone(),
            metrics: metrics.clone(),
            seen: HashMap::new(),
            ticked: Instant::now(),
            gateways: HashMap::new(),
            presence: presence.clone(),
            stopping: stopping.clone(),
        };
        let connection = std::thread::Builder::new()
            .name("mqtt-worker".into())
            .spawn(move || run.drive(connection, first_tx))?;
        let answer = first_rx.recv_timeout(Duration::from_secs(5));
        if answer.is_err() {
            tracing::warn!(broker = %opts.url, "not subscribed yet: the broker has not answered");
        }
        if let Ok(Err(reason)) = answer {
            let _ = connection.join();
            return Err(PublishError::Refused {
                url: opts.url.to_string(),
                reason,
            });
        }
        let out = Out {
            shared,
            metrics: metrics.clone(),
            client: client.clone(),
            url: opts.url.clone(),
        };
        let stop = stopping.clone();
        let estimates = std::thread::Builder::new()
            .name("mqtt-estimates".into())
            .spawn(move || publish_estimates(&out, &presence, &stop))?;
        Ok(Worker {
            client,
            stopping,
            connection: Some(connection),
            estimates: Some(estimates),
        })
    }

    /// Disconnects (unacknowledged messages stay in the session); the localizer it feeds is
    /// its owner's to stop.
    pub fn stop(mut self) {
        self.stopping.store(true, Ordering::Relaxed);
        let _ = self.client.disconnect();
        if let Some(c) = self.connection.take() {
            let _ = c.join();
        }
        if let Some(e) = self.estimates.take() {
            let _ = e.join();
        }
    }
}

/// The connection thread's state.
struct Run {
    opts: WorkerOptions,
    client: Client,
    live_tap: Tap,
    shared: Arc<Shared>,
    metrics: MqttMetrics,
    /// Per (gateway, reader, topic): the sequence numbers seen and the batches held.
    seen: HashMap<(String, String, String), Seq<Held>>,
    /// When the held batches were last looked at.
    ticked: Instant,
    /// Each reader's gateway, from the statuses.
    gateways: HashMap<String, String>,
    presence: Arc<Mutex<Presence>>,
    stopping: Arc<AtomicBool>,
}

impl Run {
    fn topics(&self) -> Vec<String> {
        let t = |rest: String| self.opts.url.topic(&format!("v{VERSION}/{rest}"));
        let mut topics: Vec<String> = self
            .opts
            .shards
            .iter()
            .map(|s| t(format!("reads/{s}")))
            .collect();
        topics.push(t("refs".into()));
        topics.push(t("poses/+/+".into()));
        topics.push(t("status/+".into()));
        topics.push(t("status/gateway/+".into()));
        topics
    }

    fn drive(&mut self, mut connection: Connection, first: mpsc::Sender<Result<(), String>>) {
        let mut first = Some(first);
        let mut backoff = reconnect_backoff();
        let mut down = false;
        let mut acks = 0;
        let topics = self.topics().len();
        for event in connection.iter() {
            // Every event (a keep-alive ping at least every 5 s) gives held batches their turn.
            self.tick(Instant::now());
            match event {
                Ok(Event::Incoming(Packet::SubAck(ack))) => {
                    if ack
                        .return_codes
                        .iter()
                        .any(|c| matches!(c, rumqttc::SubscribeReasonCode::Failure))
                    {
                        tracing::warn!(broker = %self.opts.url, "the broker refused a subscription (no rights to the topic?)");
                    }
                    acks += 1;
                    if acks >= topics {
                        if let Some(f) = first.take() {
                            let _ = f.send(Ok(()));
                        }
                    }
                }
                Ok(Event::Incoming(Packet::ConnAck(_))) => {
                    backoff.reset();
                    acks = 0;
                    if std::mem::take(&mut down) {
                        tracing::info!(broker = %self.opts.url, "broker connection back");
                    }
                    // Subscribing again to a session that has them is harmless.
                    for topic in self.topics() {
                        let _ = self.client.try_subscribe(topic, QoS::AtLeastOnce);
                    }
                }
                Ok(Event::Incoming(Packet::Publish(p))) => self.message(p),
                Ok(Event::Outgoing(rumqttc::Outgoing::Disconnect)) => return,
                Ok(_) => {}
                Err(e) => {
                    if self.stopping.load(Ordering::Relaxed) {
                        return;
                    }
                    if let Some(f) = first.take() {
                        if let Some(reason) = refusal(&e) {
                            let _ = f.send(Err(reason));
                            return;
                        }
                        let _ = f.send(Ok(()));
                    }
                    if !std::mem::replace(&mut down, true) {
                        self.metrics.disconnects.inc();
                        tracing::warn!(broker = %self.opts.url, error = %e, "broker connection lost: retrying");
                    }
                    std::thread::sleep(backoff.failed());
                }
            }
        }
    }

    /// Files one message (or holds a batch ahead of a gap), or counts it as malformed; a
    /// message is acknowledged once the localizer has it, or skipped.
    fn message(&mut self, p: Publish) {
        self.metrics.received.inc();
        let base = self.opts.url.topic(&format!("v{VERSION}/"));
        let topic = std::str::from_utf8(&p.topic).unwrap_or_default();
        let Some(rest) = topic.strip_prefix(&base).map(str::to_owned) else {
            self.metrics.malformed.inc();
            self.ack(&p);
            return;
        };
        let levels: Vec<&str> = rest.split('/').collect();
        let ok = match levels.as_slice() {
            ["reads", s] => match s.parse::<u16>() {
                Ok(s) if self.opts.shards.contains(&s) => return self.batch(&rest, p, false),
                _ => false,
            },
            ["refs"] => return self.batch(&rest, p, true),
            ["status", "gateway", _] | ["status", _] => self.status(&p.payload),
            ["poses", _, _] => match crate::localize::poses::parse_poses(&p.payload) {
                Ok(poses) => {
                    self.offer(Input::Poses(poses));
                    true
                }
                Err(_) => false,
            },
            _ => false,
        };
        if !ok {
            self.metrics.malformed.inc();
        }
        self.ack(&p);
    }

    /// Takes a reader's or gateway's status: the readers' views follow it, and a reader's
    /// clean `offline` with its `lastSeq` closes each of our topics (what has not come by
    /// then, or shortly after, is a gap). `false` when it is not a status of the schema.
    fn status(&mut self, payload: &[u8]) -> bool {
        let Ok(s) = serde_json::from_slice::<schema::Status>(payload) else {
            return false;
        };
        if s.v != VERSION {
            return false;
        }
        let online = s.status == "online";
        match &s.reader {
            Some(reader) => {
                self.gateways.insert(reader.clone(), s.gateway.clone());
                set_link(&self.shared, reader, online);
                let now = Instant::now();
                for (rest, &last) in &s.last_seq {
                    let key = (s.gateway.clone(), reader.clone(), rest.clone());
                    if let Some(seen) = self.seen.get_mut(&key) {
                        seen.close(s.run, last, now);
                    }
                }
            }
            // A gateway gone (its last will): its readers' statuses no longer count.
            None if !online => {
                for (reader, gateway) in &self.gateways {
                    if *gateway == s.gateway {
                        set_link(&self.shared, reader, false);
                    }
                }
            }
            None => {}
        }
        true
    }

    /// Takes a read batch in its topic's sequence order: files it and the held ones that
    /// follow on, holds it ahead of a gap, or skips a duplicate. Malformed: counted, acked.
    fn batch(&mut self, rest: &str, publish: Publish, refs: bool) {
        let batch = match serde_json::from_slice::<ReadBatch>(&publish.payload) {
            Ok(b) if b.v == VERSION => b,
            _ => {
                self.metrics.malformed.inc();
                self.ack(&publish);
                return;
            }
        };
        let reader = batch.reader.as_deref().unwrap_or_default().to_owned();
        let key = (batch.gateway.clone(), reader, rest.to_owned());
        let (run, seq) = (batch.run, batch.seq);
        let held = Held {
            batch,
            refs,
            publish: Some(publish),
        };
        let seen = self.seen.entry(key).or_default();
        let expected = seen.expected();
        let step = seen.arrive(run, seq, held, Instant::now());
        if step.held {
            // Acknowledged as it is held: a broker may hold back the missing message until
            // the ones it delivered are (NATS: max_ack_pending per subscription).
            if let Some(p) = seen.held_mut(seq).and_then(|h| h.publish.take()) {
                self.ack(&p);
            }
            self.metrics.reordered.inc();
            tracing::debug!(topic = rest, seq, expected, "batch ahead of a gap: held");
        } else if step.late {
            self.metrics.filed_late.inc();
            tracing::debug!(
                topic = rest,
                seq,
                expected,
                "batch filed behind later ones (late into a skipped gap, from before the first seen, or of an earlier run)"
            );
        }
        self.take(step);
    }

    /// Gives every topic's held batches their turn, at most every 100 ms.
    fn tick(&mut self, now: Instant) {
        if now.duration_since(self.ticked) < Duration::from_millis(100) {
            return;
        }
        self.ticked = now;
        let steps: Vec<Step<Held>> = self.seen.values_mut().map(|s| s.tick(now)).collect();
        for step in steps {
            self.take(step);
        }
    }

    /// Files, skips and counts what a step of a topic's sequence gives.
    fn take(&mut self, step: Step<Held>) {
        self.metrics.gaps.inc_by(step.lost);
        if let Some(dup) = step.duplicate {
            self.metrics.duplicates.inc();
            if let Some(p) = dup.publish {
                self.ack(&p);
            }
        }
        for held in step.file {
            self.file(&held.batch, held.refs);
            if let Some(p) = held.publish {
                self.ack(&p);
            }
        }
    }

    /// Files a read batch; `refs`: only the reads of tags in shards not ours (ours come on
    /// their shard).
    fn file(&mut self, b: &ReadBatch, refs: bool) {
        if !refs {
            let now = Instant::now();
            let events: Vec<PresenceEvent> = {
                let mut p = lock(&self.presence);
                b.reads
                    .iter()
                    .filter_map(|r| {
                        let reader = b.reader.as_ref();
                        p.read(&r.epc_hex, reader, r.antenna_port, r.first_seen_us, now)
                    })
                    .collect()
            };
            let out = Out {
                shared: self.shared.clone(),
                metrics: self.metrics.clone(),
                client: self.client.clone(),
                url: self.opts.url.clone(),
            };
            for e in events {
                out.presence(&e);
            }
        }
        let reads: Vec<_> = b
            .reads
            .iter()
            .filter(|r| {
                !refs
                    || !self
                        .opts
                        .shards
                        .contains(&schema::shard(&r.epc_hex, self.opts.shard_count))
            })
            // (A read whose EPC is not hex bytes names no tag: it is left out.)
            .filter_map(|r| r.to_read(b.reader.as_ref()))
            .collect();
        if !reads.is_empty() {
            self.offer(Input::Reads(reads));
        }
    }

    /// Acknowledges `p` to the broker.
    fn ack(&self, p: &Publish) {
        if let Err(e) = self.client.try_ack(p) {
            tracing::warn!(error = %e, "acknowledgement not sent");
        }
    }

    /// Hands `input` to the localizer, waiting while it is behind (the broker holds the rest).
    fn offer(&self, mut input: Input) {
        loop {
            match self.live_tap.try_offer(input) {
                Ok(()) => return,
                Err(back) => {
                    input = back;
                    std::thread::sleep(Duration::from_millis(1));
                }
            }
        }
    }
}

/// A read batch on its way to the localizer, and the message to acknowledge once it is there
/// (`None`: acknowledged when it was held).
#[derive(Debug)]
struct Held {
    batch: ReadBatch,
    refs: bool,
    publish: Option<Publish>,
}

/// Where a worker publishes.
struct Out {
    shared: Arc<Shared>,
    metrics: MqttMetrics,
    client: Client,
    url: BrokerUrl,
}

impl Out {
    /// Publishes `payload` to `PREFIX/v1/rest` at QoS 1, counted.
    fn publish(&self, rest: &str, retain: bool, payload: Vec<u8>) {
        let topic = self.url.topic(&format!("v{VERSION}/{rest}"));
        if self
            .client
            .try_publish(topic, payload, super::publish::at_least_once(retain))
            .is_ok()
        {
            self.metrics.published.inc();
        } else {
            self.metrics.dropped.inc();
        }
    }

    /// Publishes a presence event to `presence/{epc}`.
    fn presence(&self, e: &PresenceEvent) {
        // A presence event of plain values always serializes.
        let payload = serde_json::to_vec(e).unwrap_or_default();
        self.publish(&format!("presence/{}", topic_level(&e.epc)), false, payload);
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    // A panicked holder leaves a state still worth using.
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// Publishes every estimate update, retained, and the presence events they and the silences
/// make, until `stop`.
fn publish_estimates(out: &Out, presence: &Mutex<Presence>, stop: &AtomicBool) {
    let (tx, mut rx) = tokio::sync::broadcast::channel(crate::localize::shared::EVENT_BUFFER);
    // No subscriber (this loop gone) is not an error.
    out.shared
        .on_publish(move |view| drop(tx.send(std::sync::Arc::clone(view))));
    let mut ticked = Instant::now();
    while !stop.load(Ordering::Relaxed) {
        if ticked.elapsed() >= Duration::from_millis(200) {
            ticked = Instant::now();
            let departed = lock(presence).tick(ticked);
            for e in departed {
                out.presence(&e);
            }
        }
        match rx.try_recv() {
            Ok(view) => {
                let json = TagJson::from(&*view);
                let epc = &view.estimate.epc;
                // A TagJson of finite numbers always serializes.
                let payload = serde_json::to_vec(&json).unwrap_or_default();
                out.publish(&format!("estimates/{}", topic_level(epc)), true, payload);
                let moved = view
                    .estimate
                    .estimate
                    .and_then(|p| lock(presence).estimate(epc, p));
                if let Some(e) = moved {
                    out.presence(&e);
                }
            }
            Err(tokio::sync::broadcast::error::TryRecvError::Lagged(n)) => {
                out.metrics.dropped.inc_by(n);
            }
            Err(tokio::sync::broadcast::error::TryRecvError::Empty) => {
                std::thread::sleep(Duration::from_millis(5));
            }
            Err(tokio::sync::broadcast::error::TryRecvError::Closed) => return,
        }
    }
}

/// Marks reader `reader`'s link (dis)connected, from a status: a reader's name has a link; the
/// reads that name none (`""`) have none.
fn set_link(shared: &Shared, reader: &str, connected: bool) {
    if let Ok(name) = ReaderName::parse(reader) {
        shared.links().update(&name, |l| l.connected = connected);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shard_lists_take_ranges_and_lists_and_name_what_is_wrong() {
        let s = parse_shards("0-3, 8,10-11", 16).expect("parses");
        assert_eq!(s.into_iter().collect::<Vec<_>>(), [0, 1, 2, 3, 8, 10, 11]);
        assert!(parse_shards("3-1", 16)
            .expect_err("empty")
            .contains("empty"));
        assert!(parse_shards("0-16", 16)
            .expect_err("too high")
            .contains("--shard-count 16"));
        assert!(parse_shards("a", 16).expect_err("nan").contains("'a'"));
    }
}
