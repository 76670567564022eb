//! `--foxglove ADDR`: a live view in Foxglove. A server of Foxglove's WebSocket protocol
//! (`foxglove.websocket.v1`, [`proto`]) streams what the command's MCAP output holds, as it
//! is written: the [`McapTap`] of its [`crate::record::mcap::McapOut`] hands every message to
//! the [`Hub`], which advertises each new channel (topic, `ros2msg` schema, `cdr` encoding)
//! to every client and sends each message to the clients subscribed to its channel (a new
//! subscriber first gets the channel's latest message, as a ROS 2 transient-local one would).
//!
//! A client that reads slower than messages come skips messages (it is told so, and they
//! are counted), one that takes nothing for [`SEND_TIMEOUT`] is dropped, at most
//! [`MAX_CLIENTS`] are served at once; nothing a client does holds the writer back.

mod client;
pub mod proto;

use std::collections::HashMap;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use bytes::Bytes;
use tokio::net::TcpListener;
use tokio::sync::{broadcast, watch, Semaphore};
use tokio::task::JoinHandle;

use crate::record::mcap::msgs::MsgType;
use crate::record::mcap::{McapTap, TapMessage, MESSAGE_ENCODING, SCHEMA_ENCODING};

/// Clients served at once; one more is refused (HTTP 503).
pub const MAX_CLIENTS: usize = 8;
/// Messages a client may fall behind before it skips the oldest.
pub const BACKLOG: usize = 4096;
/// Longest a client may take to accept one message (or the handshake) before it is dropped.
pub const SEND_TIMEOUT: Duration = Duration::from_secs(5);
/// Largest message a client may send (its requests are small JSON objects).
pub const MAX_CLIENT_MESSAGE: usize = 64 * 1024;
/// Channels advertised at most; messages on more are not streamed (the file has them).
pub const MAX_CHANNELS: usize = 10_000;

/// What the server allows its clients (the constants above by default).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limits {
    /// Clients served at once.
    pub max_clients: usize,
    /// Messages a client may fall behind before it skips the oldest.
    pub backlog: usize,
    /// Longest a client may take to accept one message (or the handshake).
    pub send_timeout: Duration,
}

impl Default for Limits {
    fn default() -> Limits {
        Limits {
            max_clients: MAX_CLIENTS,
            backlog: BACKLOG,
            send_timeout: SEND_TIMEOUT,
        }
    }
}

/// Why the live server could not start.
#[derive(Debug, thiserror::Error)]
#[error("Foxglove WebSocket server: cannot listen on {addr}: {source}")]
pub struct LiveError {
    /// The address.
    pub addr: String,
    /// Why.
    pub source: std::io::Error,
}

/// One channel as advertised.
#[derive(Debug, PartialEq, Eq)]
pub struct LiveChannel {
    /// Its id (from 1, in the order the channels first had a message).
    pub id: u32,
    /// Its topic.
    pub topic: String,
    /// The message encoding.
    pub encoding: &'static str,
    /// The schema's name.
    pub schema_name: &'static str,
    /// The schema's text (one copy per type, shared by its channels).
    pub schema: Arc<str>,
    /// The schema's encoding.
    pub schema_encoding: &'static str,
}

/// What the hub hands its clients.
#[derive(Clone, Debug)]
enum Event {
    /// A new channel.
    Advertise(Arc<LiveChannel>),
    /// A message on a channel.
    Message(Latest),
}

/// One message of a channel: its number in the channel, its log time and its data.
#[derive(Clone, Debug)]
struct Latest {
    channel: u32,
    seq: u64,
    log_ns: u64,
    data: Bytes,
}

/// Counts of what clients missed.
#[derive(Debug, Default)]
pub struct LiveStats {
    /// Messages skipped by clients that fell more than [`BACKLOG`] behind.
    pub skipped: AtomicU64,
    /// Clients dropped because they took nothing for [`SEND_TIMEOUT`] (or failed).
    pub dropped: AtomicU64,
    /// Clients refused because [`MAX_CLIENTS`] were served.
    pub refused: AtomicU64,
}

/// The channels seen so far and the stream of what follows, shared by the tap (writer)
/// and the clients (readers).
#[derive(Debug)]
pub struct Hub {
    channels: Mutex<Vec<Arc<LiveChannel>>>,
    /// Each channel's latest message, which a new subscriber gets first (so that what is
    /// sent once, such as the still tags' positions, shows in a view opened later).
    latest: Mutex<HashMap<u32, Latest>>,
    tx: broadcast::Sender<Event>,
    /// What clients are allowed.
    pub limits: Limits,
    /// What clients missed.
    pub stats: LiveStats,
}

impl Hub {
    /// A hub whose clients have `limits`.
    pub fn new(limits: Limits) -> Arc<Hub> {
        Arc::new(Hub {
            channels: Mutex::new(Vec::new()),
            latest: Mutex::new(HashMap::new()),
            tx: broadcast::channel(limits.backlog.max(1)).0,
            limits,
            stats: LiveStats::default(),
        })
    }

    /// The tap that feeds this hub (give it to the MCAP output).
    pub fn tap(self: &Arc<Hub>) -> Box<dyn McapTap> {
        Box::new(HubTap {
            hub: self.clone(),
            ids: HashMap::new(),
            schemas: HashMap::new(),
            seq: 0,
        })
    }

    /// The channels advertised so far.
    pub fn channels(&self) -> Vec<Arc<LiveChannel>> {
        self.lock().clone()
    }

    /// The channels so far and a receiver of everything after them (taken under the one
    /// lock the tap adds channels under, so that no channel is missed or advertised twice).
    fn join(&self) -> (Vec<Arc<LiveChannel>>, broadcast::Receiver<Event>) {
        let channels = self.lock();
        (channels.clone(), self.tx.subscribe())
    }

    /// Channel `channel`'s latest message.
    fn latest(&self, channel: u32) -> Option<Latest> {
        let latest = self.latest.lock().unwrap_or_else(PoisonError::into_inner);
        latest.get(&channel).cloned()
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Vec<Arc<LiveChannel>>> {
        // The list is only ever pushed to: one a panicking holder left is still whole.
        self.channels.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

/// The tap into a [`Hub`]: channel ids by topic, schema texts by type, and the number of
/// the last message.
struct HubTap {
    hub: Arc<Hub>,
    ids: HashMap<String, Option<u32>>,
    schemas: HashMap<MsgType, Arc<str>>,
    seq: u64,
}

impl McapTap for HubTap {
    fn message(&mut self, m: &TapMessage<'_>) {
        let id = match self.ids.get(m.topic) {
            Some(id) => *id,
            None => {
                let mut channels = self.hub.lock();
                let id = if channels.len() < MAX_CHANNELS {
                    let c = Arc::new(LiveChannel {
                        id: channels.len() as u32 + 1,
                        topic: m.topic.to_string(),
                        encoding: MESSAGE_ENCODING,
                        schema_name: m.ty.name(),
                        schema: (self.schemas.entry(m.ty))
                            .or_insert_with(|| m.ty.schema().into())
                            .clone(),
                        schema_encoding: SCHEMA_ENCODING,
                    });
                    channels.push(c.clone());
                    let id = c.id;
                    // No receiver (no client yet) is not an error: the list has it.
                    let _ = self.hub.tx.send(Event::Advertise(c));
                    Some(id)
                } else {
                    tracing::warn!(topic = m.topic, "too many channels: not streamed live");
                    None
                };
                drop(channels);
                self.ids.insert(m.topic.to_string(), id);
                id
            }
        };
        if let Some(channel) = id {
            self.seq += 1;
            let latest = Latest {
                channel,
                seq: self.seq,
                log_ns: m.log_ns,
                data: Bytes::copy_from_slice(m.data),
            };
            if self.hub.tx.receiver_count() > 0 {
                let _ = self.hub.tx.send(Event::Message(latest.clone()));
            }
            let mut all = self
                .hub
                .latest
                .lock()
                .unwrap_or_else(PoisonError::into_inner);
            all.insert(channel, latest);
        }
    }
}

/// The live server: its address, its hub and its accepting task.
pub struct LiveServer {
    addr: SocketAddr,
    hub: Arc<Hub>,
    shutdown: watch::Sender<bool>,
    task: JoinHandle<()>,
}

impl LiveServer {
    /// Listens on `addr` and serves clients from the hub of a new [`LiveServer::tap`].
    pub async fn bind(addr: &str) -> Result<LiveServer, LiveError> {
        LiveServer::bind_with(addr, Limits::default()).await
    }

    /// [`LiveServer::bind`] with other limits.
    pub async fn bind_with(addr: &str, limits: Limits) -> Result<LiveServer, LiveError> {
        let err = |source| LiveError {
            addr: addr.to_string(),
            source,
        };
        let listener = TcpListener::bind(addr).await.map_err(err)?;
        let local = listener.local_addr().map_err(err)?;
        let hub = Hub::new(limits);
        let (shutdown, rx) = watch::channel(false);
        let task = tokio::spawn(accept(listener, hub.clone(), rx));
        tracing::info!("Foxglove live view on ws://{local}");
        Ok(LiveServer {
            addr: local,
            hub,
            shutdown,
            task,
        })
    }

    /// The address it listens on.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// The tap to give the MCAP output (every message it writes is streamed).
    pub fn tap(&self) -> Box<dyn McapTap> {
        self.hub.tap()
    }

    /// Its hub.
    pub fn hub(&self) -> &Arc<Hub> {
        &self.hub
    }

    /// Stops accepting, closes every client and logs what clients missed.
    pub async fn shutdown(self) {
        let _ = self.shutdown.send(true);
        let _ = self.task.await;
        let s = &self.hub.stats;
        tracing::info!(
            skipped = s.skipped.load(Ordering::Relaxed),
            dropped = s.dropped.load(Ordering::Relaxed),
            refused = s.refused.load(Ordering::Relaxed),
            "the Foxglove live view has stopped"
        );
    }
}

/// The accepting task: one task per client, at most [`MAX_CLIENTS`].
async fn accept(listener: TcpListener, hub: Arc<Hub>, mut shutdown: watch::Receiver<bool>) {
    let max = hub.limits.max_clients;
    let slots = Arc::new(Semaphore::new(max));
    loop {
        let (tcp, peer) = tokio::select! {
            _ = shutdown.changed() => return,
            r = listener.accept() => match r {
                Ok(c) => c,
                Err(e) => {
                    // Out of file descriptors, most likely: wait rather than spin.
                    tracing::warn!(error = %e, "Foxglove WebSocket server: accept failed");
                    tokio::time::sleep(Duration::from_millis(100)).await;
                    continue;
                }
            },
        };
        match slots.clone().try_acquire_owned() {
            Ok(permit) => {
                tokio::spawn(client::serve(
                    tcp,
                    peer,
                    hub.clone(),
                    shutdown.clone(),
                    permit,
                ));
            }
            Err(_) => {
                hub.stats.refused.fetch_add(1, Ordering::Relaxed);
                tracing::warn!(%peer, "Foxglove client refused: {max} are served already");
                // Written if the socket takes it at once (it has room: nothing was sent on
                // it yet), never waited for.
                let body = format!("too many Foxglove clients (at most {max})\n");
                let reply = format!(
                    "HTTP/1.1 503 Service Unavailable\r\nContent-Type: text/plain\r\n\
                     Content-Length: {}\r\nConnection: close\r\n\r\n{body}",
                    body.len()
                );
                let _ = tcp.try_write(reply.as_bytes());
            }
        }
    }
}

#[cfg(test)]
mod tests;
