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

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc;
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use rumqttc::{Client, Connection, ConnectionError, Event, LastWill, MqttOptions, Packet, QoS};

use super::metrics::MqttMetrics;
use super::schema::{self, Status, VERSION};
use super::url::BrokerUrl;
use crate::localize::live::Mirror;
use crate::net::backoff::Backoff;
use crate::secret::Secret;

/// Largest MQTT packet sent or accepted (bytes).
pub const MAX_PACKET: usize = 1 << 20;

/// Least wait before reconnecting to the broker, about doubled per failure up to
/// [`BACKOFF_MAX`] ([`reconnect_backoff`]).
const BACKOFF_MIN: Duration = Duration::from_millis(100);
/// Longest wait before reconnecting.
const BACKOFF_MAX: Duration = Duration::from_secs(5);

/// The wait between reconnections to the broker, the publisher's and the workers': the
/// shared [`Backoff`] with jitter, from [`BACKOFF_MIN`] to [`BACKOFF_MAX`], so the gateways
/// and workers of a fleet do not all come back at once after a broker restart.
pub(super) fn reconnect_backoff() -> Backoff {
    Backoff::new(BACKOFF_MIN, BACKOFF_MAX, None)
}

/// How to publish.
#[derive(Clone, Debug)]
pub struct PublishOptions {
    /// The broker.
    pub url: BrokerUrl,
    /// This gateway's name (its status topic, its client id, every message's `gateway`).
    pub gateway: String,
    /// This run of the gateway (every message's `run`): when it started, UTC µs.
    pub run: u64,
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
            run: crate::utc::now_us(),
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
    let mut o = MqttOptions::new(id, rumqttc::Broker::tcp(url.host.clone(), url.port));
    o.set_keep_alive(5);
    o.set_clean_session(clean);
    o.set_max_packet_size(MAX_PACKET, MAX_PACKET);
    if let Some(user) = &url.user {
        let password = url.password.as_ref().map_or("", Secret::expose);
        o.set_credentials(user.clone(), password.to_owned());
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

/// A QoS 1 publication, retained or not: how every message of the fleet is sent.
pub fn at_least_once(retain: bool) -> rumqttc::PublishOptions {
    rumqttc::PublishOptions::new(QoS::AtLeastOnce).retain(retain)
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
pub(super) struct Link {
    client: Client,
    url: BrokerUrl,
    gateway: String,
    run: u64,
    /// Readers online, which a reconnection announces again.
    pub(super) online: Mutex<BTreeSet<String>>,
    /// The messages not yet handed to the connection (at most `queue`).
    outbox: Mutex<VecDeque<Outgoing>>,
    queue: usize,
    /// The connection is up.
    connected: AtomicBool,
    /// Publishes the broker acknowledged.
    acked: AtomicU64,
    /// Publishes handed to the connection.
    sent: AtomicU64,
    metrics: MqttMetrics,
    pub(super) stopping: AtomicBool,
}

impl Link {
    /// Queues `payload` for `PREFIX/v1/rest` at QoS 1; `false` (counted as dropped, with
    /// `weight` reads or poses, and as a dropped message when it carries a sequence number)
    /// when the outbox is full.
    pub(super) fn publish(
        &self,
        rest: &str,
        retain: bool,
        payload: Vec<u8>,
        weight: u64,
        sequenced: bool,
    ) -> bool {
        let topic = self.url.topic(&format!("v{VERSION}/{rest}"));
        let mut q = lock(&self.outbox);
        if q.len() >= self.queue {
            drop(q);
            self.metrics.dropped.inc_by(weight);
            if sequenced {
                self.metrics.dropped_messages.inc();
            }
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
    pub(super) fn pump(&self) {
        if !self.connected.load(Ordering::Acquire) {
            return;
        }
        let mut q = lock(&self.outbox);
        while self
            .sent
            .load(Ordering::Relaxed)
            .saturating_sub(self.acked.load(Ordering::Relaxed))
            < WINDOW
        {
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
            .try_publish(m.topic, m.payload, at_least_once(m.retain))
        {
            Ok(()) => {
                self.sent.fetch_add(1, Ordering::Relaxed);
                self.metrics.published.inc();
            }
            // The request channel holds the window and more: only a stopped connection.
            Err(_) => {
                self.metrics.dropped_messages.inc();
            }
        }
    }

    /// No message waits in the outbox.
    pub(super) fn outbox_empty(&self) -> bool {
        lock(&self.outbox).is_empty()
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
            run: self.run,
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
    pub(super) fn status(
        &self,
        reader: Option<&str>,
        online: bool,
        last_seq: BTreeMap<String, u64>,
    ) {
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
    pub fn start(opts: PublishOptions, metrics: MqttMetrics) -> Result<Publisher, PublishError> {
        let id = format!("llrp-gateway-{}", topic_level(&opts.gateway));
        let mut mqtt = mqtt_options(&opts.url, &id, false, opts.tls.clone())?;
        let gone = Status {
            v: VERSION,
            status: "offline".into(),
            gateway: opts.gateway.clone(),
            reader: None,
            run: opts.run,
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
        let (client, connection) = Client::builder(mqtt).capacity(WINDOW as usize + 64).build();
        let link = Arc::new(Link {
            client,
            url: opts.url.clone(),
            gateway: opts.gateway.clone(),
            run: opts.run,
            online: Mutex::new(BTreeSet::new()),
            outbox: Mutex::new(VecDeque::new()),
            queue: opts.queue.max(1),
            connected: AtomicBool::new(false),
            acked: AtomicU64::new(0),
            sent: AtomicU64::new(0),
            metrics: metrics.clone(),
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
            dropped: metrics.dropped.clone(),
        };
        let l = link.clone();
        let builder = std::thread::Builder::new()
            .name("mqtt-publish".into())
            .spawn(move || super::builder::Builder::new(opts, l).run(rx))?;
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

/// Runs the broker connection: reconnects with back-off ([`reconnect_backoff`]), announces
/// the statuses again after each connection, counts acknowledgements. Tells `first` how the
/// first attempt went.
fn drive(mut connection: Connection, link: &Link, first: mpsc::Sender<Result<(), String>>) {
    let mut first = Some(first);
    let mut backoff = reconnect_backoff();
    let mut outage: Option<(Instant, String)> = None;
    for event in connection.iter() {
        match event {
            Ok(Event::Incoming(Packet::ConnAck(ack))) => {
                backoff.reset();
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
                    link.metrics.dropped_messages.inc_by(lost);
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
                    link.metrics.disconnects.inc();
                    tracing::warn!(broker = %link.url, error = %e, "broker connection lost: queueing (bounded) and retrying");
                    outage = Some((Instant::now(), e.to_string()));
                }
                std::thread::sleep(backoff.failed());
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

pub(super) fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    // A panicked holder leaves a set still worth using.
    m.lock().unwrap_or_else(|e| e.into_inner())
}
