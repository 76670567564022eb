//! The MQTT publisher of `sim --publish` (and the gateway commands): takes what the live
//! localizer's [`Tap`](crate::localize::live::Tap) is offered through a [`Mirror`], and
//! publishes reads by shard, reference reads, poses, reader events and statuses (topics and
//! schema: docs/fleet.md).
//!
//! Nothing here waits on the broker: the mirror drops (counted) when this thread is behind,
//! and the outbox ([`PublishOptions::queue`] messages) drops (counted) what does not fit
//! while the broker is away or slow. At most `WINDOW` (1,000) messages are with the connection
//! unacknowledged; they are sent again after a reconnection that resumes the session, and
//! counted as dropped after one that does not. Reconnection backs off from 100 ms to 5 s, and each
//! outage is logged once, when it starts and when it ends.

use std::collections::{BTreeMap, BTreeSet, HashMap, VecDeque};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use rumqttc::{Client, Connection, ConnectionError, Event, LastWill, MqttOptions, Packet, QoS};

use super::schema::{self, ReadBatch, Status, TagRead, VERSION};
use super::url::BrokerUrl;
use crate::localize::live::{Input, Mirror};
use crate::localize::poses::PoseSample;
use crate::localize::shared::Shared;
use crate::reads::{Read, ReadDecoder};

/// LLRP's message type of READER_EVENT_NOTIFICATION.
const READER_EVENT_NOTIFICATION: u16 = 63;

/// Most reads in one batch message.
pub const MAX_BATCH_READS: usize = 1000;

/// Largest MQTT packet sent or accepted (bytes).
pub const MAX_PACKET: usize = 1 << 20;

/// First wait before reconnecting, doubled per failure up to [`BACKOFF_MAX`].
const BACKOFF_MIN: Duration = Duration::from_millis(100);
/// Longest wait before reconnecting.
const BACKOFF_MAX: Duration = Duration::from_secs(5);

/// How to publish.
#[derive(Clone, Debug)]
pub struct PublishOptions {
    /// The broker.
    pub url: BrokerUrl,
    /// This gateway's name (its status topic, its client id, every message's `gateway`).
    pub gateway: String,
    /// Read shards (`PREFIX/v1/reads/0` … `S-1`).
    pub shard_count: u16,
    /// Messages held while the broker is away; beyond it they are dropped and counted.
    pub queue: usize,
    /// Reads are batched over this window per topic; zero: a message per report.
    pub window: Duration,
    /// EPCs (upper-case hex) of the reference tags, whose reads also go to `refs`.
    pub references: BTreeSet<String>,
    /// Inputs the mirror holds before it drops.
    pub mirror_capacity: usize,
    /// TLS settings for `mqtts://`.
    pub tls: Option<Arc<tokio_rustls::rustls::ClientConfig>>,
}

impl PublishOptions {
    /// Options for `url` with the defaults: 16 shards, 10,000 queued messages, a message
    /// per report.
    pub fn new(url: BrokerUrl, gateway: &str) -> PublishOptions {
        PublishOptions {
            url,
            gateway: gateway.to_owned(),
            shard_count: schema::DEFAULT_SHARDS,
            queue: 10_000,
            window: Duration::ZERO,
            references: BTreeSet::new(),
            mirror_capacity: 65_536,
            tls: None,
        }
    }
}

/// Why the publisher could not start.
#[derive(Debug, thiserror::Error)]
pub enum PublishError {
    /// The broker refused the connection (credentials, rights, client id).
    #[error("the broker {url} refused the connection: {reason}")]
    Refused {
        /// The broker.
        url: String,
        /// The broker's reason.
        reason: String,
    },
    /// `mqtts://` without the TLS settings it needs.
    #[error("{0}")]
    Tls(String),
    /// A thread could not be started.
    #[error("cannot start the publisher: {0}")]
    Thread(#[from] std::io::Error),
}

/// The broker connection's options for client `id` of `url`.
pub fn mqtt_options(
    url: &BrokerUrl,
    id: &str,
    clean: bool,
    tls: Option<Arc<tokio_rustls::rustls::ClientConfig>>,
) -> Result<MqttOptions, PublishError> {
    let mut o = MqttOptions::new(id, url.host.clone(), url.port);
    o.set_keep_alive(Duration::from_secs(5));
    o.set_clean_session(clean);
    o.set_max_packet_size(MAX_PACKET, MAX_PACKET);
    if let Some(user) = &url.user {
        o.set_credentials(user.clone(), url.password.clone().unwrap_or_default());
    }
    if url.tls {
        let config = tls.ok_or_else(|| {
            PublishError::Tls(format!(
                "{url}: mqtts:// needs --mqtt-ca FILE, the CA certificate (PEM) the broker's is signed by"
            ))
        })?;
        o.set_transport(rumqttc::Transport::tls_with_config(
            rumqttc::TlsConfiguration::Rustls(config),
        ));
    }
    Ok(o)
}

/// Most messages handed to the connection and not yet acknowledged.
const WINDOW: u64 = 1000;

/// A message waiting in the outbox.
struct Outgoing {
    topic: String,
    retain: bool,
    payload: Vec<u8>,
}

/// What the connection thread and the publishing thread share.
struct Link {
    client: Client,
    url: BrokerUrl,
    gateway: String,
    /// Readers online, which a reconnection announces again.
    online: Mutex<BTreeSet<String>>,
    /// The messages not yet handed to the connection (at most `queue`).
    outbox: Mutex<VecDeque<Outgoing>>,
    queue: usize,
    /// The connection is up.
    connected: AtomicBool,
    /// Publishes the broker acknowledged.
    acked: AtomicU64,
    /// Publishes handed to the connection.
    sent: AtomicU64,
    shared: Arc<Shared>,
    stopping: AtomicBool,
}

impl Link {
    /// Queues `payload` for `PREFIX/v1/rest` at QoS 1; `false` (counted as dropped, with
    /// `weight` reads or poses) when the outbox is full.
    fn publish(&self, rest: &str, retain: bool, payload: Vec<u8>, weight: u64) -> bool {
        let topic = self.url.topic(&format!("v{VERSION}/{rest}"));
        let mut q = lock(&self.outbox);
        if q.len() >= self.queue {
            drop(q);
            self.shared.metrics.mqtt_dropped.inc_by(weight);
            self.shared.metrics.mqtt_dropped_messages.inc();
            return false;
        }
        q.push_back(Outgoing {
            topic,
            retain,
            payload,
        });
        true
    }

    /// Hands queued messages to the connection while it is up and fewer than `WINDOW`
    /// await the broker's acknowledgement.
    fn pump(&self) {
        if !self.connected.load(Ordering::Acquire) {
            return;
        }
        let mut q = lock(&self.outbox);
        while self.sent.load(Ordering::Relaxed) - self.acked.load(Ordering::Relaxed) < WINDOW {
            let Some(m) = q.pop_front() else {
                break;
            };
            self.direct(m);
        }
    }

    /// Hands `m` to the connection at once.
    fn direct(&self, m: Outgoing) {
        match self
            .client
            .try_publish(m.topic, QoS::AtLeastOnce, m.retain, m.payload)
        {
            Ok(()) => {
                self.sent.fetch_add(1, Ordering::Relaxed);
                self.shared.metrics.mqtt_published.inc();
            }
            // The request channel holds the window and more: only a stopped connection.
            Err(_) => {
                self.shared.metrics.mqtt_dropped_messages.inc();
            }
        }
    }

    /// Nothing left to send or to be acknowledged.
    fn drained(&self) -> bool {
        lock(&self.outbox).is_empty()
            && self.acked.load(Ordering::Relaxed) >= self.sent.load(Ordering::Relaxed)
    }

    /// The retained status message of `reader` (the gateway's with `None`).
    fn status_message(
        &self,
        reader: Option<&str>,
        online: bool,
        last_seq: BTreeMap<String, u64>,
    ) -> Outgoing {
        let s = Status {
            v: VERSION,
            status: if online { "online" } else { "offline" }.into(),
            gateway: self.gateway.clone(),
            reader: reader.map(str::to_owned),
            last_seq,
        };
        let rest = match reader {
            Some(r) => format!("status/{}", topic_level(r)),
            None => format!("status/gateway/{}", topic_level(&self.gateway)),
        };
        Outgoing {
            topic: self.url.topic(&format!("v{VERSION}/{rest}")),
            retain: true,
            // A Status always serializes.
            payload: serde_json::to_vec(&s).unwrap_or_default(),
        }
    }

    /// Queues the status of `reader` (the gateway's with `None`).
    fn status(&self, reader: Option<&str>, online: bool, last_seq: BTreeMap<String, u64>) {
        let m = self.status_message(reader, online, last_seq);
        let mut q = lock(&self.outbox);
        // A status is never dropped: it may pass the bound by the readers' count.
        q.push_back(m);
    }
}

/// `name` usable as one topic level: `/`, `+`, `#` and NUL become `_`.
pub fn topic_level(name: &str) -> String {
    name.chars()
        .map(|c| match c {
            '/' | '+' | '#' | '\0' => '_',
            c => c,
        })
        .collect()
}

/// A running publisher.
pub struct Publisher {
    mirror: Mirror,
    link: Arc<Link>,
    builder: Option<JoinHandle<()>>,
    connection: Option<JoinHandle<()>>,
}

impl Publisher {
    /// Connects to the broker (waiting up to 3 s for its answer: a refusal is an error, an
    /// unreachable broker is retried in the background) and starts publishing.
    pub fn start(opts: PublishOptions, shared: Arc<Shared>) -> Result<Publisher, PublishError> {
        let id = format!("llrp-gateway-{}", topic_level(&opts.gateway));
        let mut mqtt = mqtt_options(&opts.url, &id, false, opts.tls.clone())?;
        let gone = Status {
            v: VERSION,
            status: "offline".into(),
            gateway: opts.gateway.clone(),
            reader: None,
            last_seq: BTreeMap::new(),
        };
        mqtt.set_last_will(LastWill::new(
            opts.url.topic(&format!(
                "v{VERSION}/status/gateway/{}",
                topic_level(&opts.gateway)
            )),
            serde_json::to_vec(&gone).unwrap_or_default(),
            QoS::AtLeastOnce,
            true,
        ));
        // The request channel holds the window of unacknowledged messages and the rest;
        // what waits for the broker waits in the outbox, which is bounded by `queue`.
        let (client, connection) = Client::new(mqtt, WINDOW as usize + 64);
        let link = Arc::new(Link {
            client,
            url: opts.url.clone(),
            gateway: opts.gateway.clone(),
            online: Mutex::new(BTreeSet::new()),
            outbox: Mutex::new(VecDeque::new()),
            queue: opts.queue.max(1),
            connected: AtomicBool::new(false),
            acked: AtomicU64::new(0),
            sent: AtomicU64::new(0),
            shared: shared.clone(),
            stopping: AtomicBool::new(false),
        });
        let (first_tx, first_rx) = mpsc::channel();
        let l = link.clone();
        let connection = std::thread::Builder::new()
            .name("mqtt-connection".into())
            .spawn(move || drive(connection, &l, first_tx))?;
        match first_rx.recv_timeout(Duration::from_secs(3)) {
            Ok(Err(reason)) => {
                link.stopping.store(true, Ordering::Relaxed);
                let _ = link.client.disconnect();
                let _ = connection.join();
                return Err(PublishError::Refused {
                    url: opts.url.to_string(),
                    reason,
                });
            }
            Ok(Ok(())) => {}
            Err(_) => {
                tracing::warn!(broker = %opts.url, "no answer from the broker yet: publishing as soon as it answers")
            }
        }
        let (tx, rx) = mpsc::sync_channel(opts.mirror_capacity.max(1));
        let mirror = Mirror {
            tx,
            dropped: shared.metrics.mqtt_dropped.clone(),
        };
        let l = link.clone();
        let builder = std::thread::Builder::new()
            .name("mqtt-publish".into())
            .spawn(move || Builder::new(opts, l).run(rx))?;
        Ok(Publisher {
            mirror,
            link,
            builder: Some(builder),
            connection: Some(connection),
        })
    }

    /// The mirror to add to the localizer's tap.
    pub fn mirror(&self) -> Mirror {
        self.mirror.clone()
    }

    /// Publishes what is queued, the readers' and the gateway's `offline`, waits (up to 3 s)
    /// for the broker to acknowledge everything, and disconnects; what taps offer the mirror
    /// afterwards is dropped and counted.
    pub fn stop(mut self) {
        // The builder drains what the mirror holds and ends within a tick.
        self.link.stopping.store(true, Ordering::Relaxed);
        if let Some(b) = self.builder.take() {
            let _ = b.join();
        }
        let until = Instant::now() + Duration::from_secs(3);
        while !self.link.drained() && Instant::now() < until {
            self.link.pump();
            std::thread::sleep(Duration::from_millis(5));
        }
        let _ = self.link.client.disconnect();
        if let Some(c) = self.connection.take() {
            let _ = c.join();
        }
    }
}

/// Runs the broker connection: reconnects with backoff, announces the statuses again after
/// each connection, counts acknowledgements. Tells `first` how the first attempt went.
fn drive(mut connection: Connection, link: &Link, first: mpsc::Sender<Result<(), String>>) {
    let mut first = Some(first);
    let mut backoff = BACKOFF_MIN;
    let mut outage: Option<(Instant, String)> = None;
    for event in connection.iter() {
        match event {
            Ok(Event::Incoming(Packet::ConnAck(ack))) => {
                backoff = BACKOFF_MIN;
                if let Some(f) = first.take() {
                    let _ = f.send(Ok(()));
                }
                if let Some((since, why)) = outage.take() {
                    tracing::info!(broker = %link.url, after_s = since.elapsed().as_secs_f64(), %why, "broker connection back");
                }
                if !ack.session_present {
                    // A new session: the connection dropped what awaited acknowledgement.
                    let sent = link.sent.load(Ordering::Relaxed);
                    let lost = sent.saturating_sub(link.acked.swap(sent, Ordering::Relaxed));
                    link.shared.metrics.mqtt_dropped_messages.inc_by(lost);
                }
                link.direct(link.status_message(None, true, BTreeMap::new()));
                let online: Vec<String> = lock(&link.online).iter().cloned().collect();
                for r in online {
                    link.direct(link.status_message(Some(&r), true, BTreeMap::new()));
                }
                link.connected.store(true, Ordering::Release);
                link.pump();
            }
            Ok(Event::Incoming(Packet::PubAck(_))) => {
                link.acked.fetch_add(1, Ordering::Relaxed);
            }
            Ok(Event::Outgoing(rumqttc::Outgoing::Disconnect)) => return,
            Ok(_) => {}
            Err(e) => {
                link.connected.store(false, Ordering::Release);
                if link.stopping.load(Ordering::Relaxed) {
                    return;
                }
                let refused = refusal(&e);
                if let Some(f) = first.take() {
                    if let Some(reason) = refused.clone() {
                        let _ = f.send(Err(reason));
                        return;
                    }
                    let _ = f.send(Ok(()));
                }
                if outage.is_none() {
                    link.shared.metrics.mqtt_disconnects.inc();
                    tracing::warn!(broker = %link.url, error = %e, "broker connection lost: queueing (bounded) and retrying");
                    outage = Some((Instant::now(), e.to_string()));
                }
                std::thread::sleep(backoff);
                backoff = (backoff * 2).min(BACKOFF_MAX);
            }
        }
    }
}

/// The broker's reason when `e` is a refusal of the connection rather than a network failure.
pub fn refusal(e: &ConnectionError) -> Option<String> {
    match e {
        ConnectionError::ConnectionRefused(code) => Some(match code {
            rumqttc::ConnectReturnCode::BadUserNamePassword => {
                "bad user name or password".to_owned()
            }
            rumqttc::ConnectReturnCode::NotAuthorized => "not authorized".to_owned(),
            other => format!("{other:?}"),
        }),
        _ => None,
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    // A panicked holder leaves a set still worth using.
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// Reads waiting for their batch's window to close, per topic.
struct Pending {
    reader: String,
    reads: Vec<TagRead>,
    since: Instant,
}

/// The publishing thread: turns inputs into messages.
struct Builder {
    opts: PublishOptions,
    link: Arc<Link>,
    decoders: HashMap<String, ReadDecoder>,
    /// Reader time − robot time, per reader (poses go out in the reads' clock).
    offsets: HashMap<String, i64>,
    /// Per reader, per topic (under `v1/`), the last sequence number used.
    seqs: BTreeMap<String, BTreeMap<String, u64>>,
    pending: BTreeMap<(String, String), Pending>,
}

impl Builder {
    fn new(opts: PublishOptions, link: Arc<Link>) -> Builder {
        Builder {
            opts,
            link,
            decoders: HashMap::new(),
            offsets: HashMap::new(),
            seqs: BTreeMap::new(),
            pending: BTreeMap::new(),
        }
    }

    fn run(mut self, rx: Receiver<Input>) {
        let tick = if self.opts.window.is_zero() {
            Duration::from_millis(100)
        } else {
            self.opts.window.min(Duration::from_millis(100))
        };
        loop {
            // Soon again while messages wait for a window.
            let wait = if lock(&self.link.outbox).is_empty() {
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
                ..
            } => {
                let decoder = self
                    .decoders
                    .remove(&name)
                    .unwrap_or_else(|| ReadDecoder::new(Some(name.clone())))
                    .with_fallback_table(hop_table);
                self.decoders.insert(name.clone(), decoder);
                self.offsets.insert(name.clone(), clock_offset_us);
                if lock(&self.link.online).insert(name.clone()) {
                    self.link.status(Some(&name), true, BTreeMap::new());
                }
            }
            Input::Frames {
                reader,
                bytes,
                now_utc_us,
            } => {
                let decoder = self
                    .decoders
                    .entry(reader.clone())
                    .or_insert_with(|| ReadDecoder::new(Some(reader.clone())));
                let mut reads = Vec::new();
                let mut events = Vec::new();
                let mut at = 0;
                while let Some(h) = llrp::FrameHeader::peek(&bytes[at..]) {
                    let len = h.length as usize;
                    if len < llrp::frame::HEADER_LEN || at + len > bytes.len() {
                        break;
                    }
                    let frame = &bytes[at..at + len];
                    if h.msg_type == READER_EVENT_NOTIFICATION {
                        if let Ok(m) = llrp::Message::decode(frame) {
                            if let llrp::MessageBody::ReaderEventNotification(n) = m.body {
                                events.push(n.reader_event_notification_data);
                            }
                        }
                    } else {
                        let _ = decoder.frame(frame, now_utc_us, &mut reads);
                    }
                    at += len;
                }
                self.reads(&reader, reads);
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
        let mut by_topic: BTreeMap<String, Vec<TagRead>> = BTreeMap::new();
        for r in &reads {
            let t = TagRead::from_read(r);
            let shard = schema::shard(&r.epc, self.opts.shard_count);
            if self.opts.references.contains(&r.epc) {
                by_topic.entry("refs".into()).or_default().push(t.clone());
            }
            by_topic
                .entry(format!("reads/{shard}"))
                .or_default()
                .push(t);
        }
        for (rest, reads) in by_topic {
            let key = (reader.to_owned(), rest);
            let p = self.pending.entry(key.clone()).or_insert_with(|| Pending {
                reader: reader.to_owned(),
                reads: Vec::new(),
                since: Instant::now(),
            });
            p.reads.extend(reads);
            if self.opts.window.is_zero() || p.reads.len() >= MAX_BATCH_READS {
                self.send(&key);
            }
        }
    }

    /// Sends the batches whose window has closed (all with `all`).
    fn flush(&mut self, all: bool) {
        let due: Vec<(String, String)> = self
            .pending
            .iter()
            .filter(|(_, p)| all || p.since.elapsed() >= self.opts.window)
            .map(|(k, _)| k.clone())
            .collect();
        for k in due {
            self.send(&k);
        }
    }

    fn send(&mut self, key: &(String, String)) {
        let Some(p) = self.pending.remove(key) else {
            return;
        };
        for chunk in p.reads.chunks(MAX_BATCH_READS) {
            let seq = self.next_seq(&p.reader, &key.1);
            let batch = ReadBatch {
                v: VERSION,
                gateway: self.opts.gateway.clone(),
                reader: p.reader.clone(),
                seq,
                reads: chunk.to_vec(),
            };
            // A batch of plain values always serializes.
            let payload = serde_json::to_vec(&batch).unwrap_or_default();
            self.link
                .publish(&key.1, false, payload, chunk.len() as u64);
        }
    }

    fn event(&mut self, reader: &str, data: &llrp::params::ReaderEventNotificationData) {
        let rest = format!("events/{}", topic_level(reader));
        let seq = self.next_seq(reader, &rest);
        let payload = serde_json::json!({
            "v": VERSION,
            "gateway": self.opts.gateway,
            "reader": reader,
            "seq": seq,
            "event": data,
        });
        self.link
            .publish(&rest, false, payload.to_string().into_bytes(), 1);
    }

    fn poses(&mut self, poses: Vec<PoseSample>) {
        let mut by_antenna: BTreeMap<(String, u16), Vec<PoseSample>> = BTreeMap::new();
        for mut p in poses {
            // In the reads' clock, as a worker files them.
            let offset = self.offsets.get(&p.reader).copied().unwrap_or(0);
            p.t_us = p.t_us.saturating_add_signed(offset);
            by_antenna
                .entry((p.reader.clone(), p.antenna))
                .or_default()
                .push(p);
        }
        for ((reader, antenna), poses) in by_antenna {
            let rest = format!("poses/{}/{antenna}", topic_level(&reader));
            // Pose samples of finite numbers always serialize.
            let payload = serde_json::to_vec(&poses).unwrap_or_default();
            self.link.publish(&rest, false, payload, poses.len() as u64);
        }
    }
}
