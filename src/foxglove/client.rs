//! One client of the live server: the handshake (subprotocol `foxglove.websocket.v1`), then
//! its requests and the hub's channels and messages until either side ends.

use std::collections::{HashMap, HashSet};
use std::net::SocketAddr;
use std::sync::atomic::Ordering;
use std::sync::Arc;

use futures_util::{SinkExt, StreamExt};
use tokio::net::TcpStream;
use tokio::sync::broadcast::error::RecvError;
use tokio::sync::{watch, OwnedSemaphorePermit};
use tokio_tungstenite::tungstenite::handshake::server::{ErrorResponse, Request, Response};
use tokio_tungstenite::tungstenite::http::{HeaderValue, StatusCode};
use tokio_tungstenite::tungstenite::protocol::WebSocketConfig;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::WebSocketStream;

use super::proto::{self, Level, SUBPROTOCOL};
use super::{Event, Hub, Latest, LiveChannel, MAX_CLIENT_MESSAGE};

/// Why a client's session ended early.
#[derive(Debug, thiserror::Error)]
enum End {
    /// The WebSocket failed (the peer went away, sent a bad frame or too big a message).
    #[error("{0}")]
    Ws(#[from] tokio_tungstenite::tungstenite::Error),
    /// It took nothing for the send timeout.
    #[error("it took nothing for {0:?}")]
    Slow(std::time::Duration),
}

/// Serves one client until it leaves, fails or the server stops; `_permit` holds its slot.
pub(super) async fn serve(
    tcp: TcpStream,
    peer: SocketAddr,
    hub: Arc<Hub>,
    shutdown: watch::Receiver<bool>,
    _permit: OwnedSemaphorePermit,
) {
    let config = WebSocketConfig::default()
        .max_message_size(Some(MAX_CLIENT_MESSAGE))
        .max_frame_size(Some(MAX_CLIENT_MESSAGE));
    let handshake =
        tokio_tungstenite::accept_hdr_async_with_config(tcp, choose_subprotocol, Some(config));
    let timeout = hub.limits.send_timeout;
    let ws = match tokio::time::timeout(timeout, handshake).await {
        Ok(Ok(ws)) => ws,
        Ok(Err(e)) => {
            tracing::info!(%peer, error = %e, "Foxglove client refused at the handshake");
            return;
        }
        Err(_) => {
            tracing::info!(%peer, "Foxglove client refused: no handshake within {timeout:?}");
            return;
        }
    };
    tracing::info!(%peer, "Foxglove client connected");
    let mut session = Session {
        ws,
        hub: hub.clone(),
        advertised: HashSet::new(),
        subscriptions: HashMap::new(),
        by_channel: HashMap::new(),
        sent_up_to: HashMap::new(),
        skipped: 0,
    };
    match session.run(shutdown).await {
        Ok(()) => tracing::info!(%peer, "Foxglove client left"),
        Err(e) => {
            hub.stats.dropped.fetch_add(1, Ordering::Relaxed);
            tracing::warn!(%peer, error = %e, skipped = session.skipped, "Foxglove client dropped");
        }
    }
}

/// The handshake's callback: takes the request only when it offers `foxglove.websocket.v1`,
/// and answers with it. (Its signature is tungstenite's `Callback`, whose error is a whole
/// HTTP response.)
#[allow(clippy::result_large_err)]
fn choose_subprotocol(req: &Request, mut resp: Response) -> Result<Response, ErrorResponse> {
    let offered = req
        .headers()
        .get_all("sec-websocket-protocol")
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(','))
        .any(|p| p.trim() == SUBPROTOCOL);
    if !offered {
        let mut e = ErrorResponse::new(Some(format!(
            "this server speaks the WebSocket subprotocol {SUBPROTOCOL} only\n"
        )));
        *e.status_mut() = StatusCode::BAD_REQUEST;
        return Err(e);
    }
    resp.headers_mut().insert(
        "sec-websocket-protocol",
        HeaderValue::from_static(SUBPROTOCOL),
    );
    Ok(resp)
}

/// A client's state: what it was told of and what it subscribed to.
struct Session {
    ws: WebSocketStream<TcpStream>,
    hub: Arc<Hub>,
    /// The channels it was told of.
    advertised: HashSet<u32>,
    /// Its subscriptions: subscription id to channel.
    subscriptions: HashMap<u32, u32>,
    /// Channel to subscription id.
    by_channel: HashMap<u32, u32>,
    /// Each channel's latest message number when it was subscribed (sent then).
    sent_up_to: HashMap<u32, u64>,
    /// Messages it skipped.
    skipped: u64,
}

impl Session {
    /// Server info, the channels so far, then requests and messages until either side ends.
    async fn run(&mut self, mut shutdown: watch::Receiver<bool>) -> Result<(), End> {
        let session_id = crate::utc::now_us().to_string();
        self.send(Message::text(proto::server_info(&session_id)))
            .await?;
        let (channels, mut rx) = self.hub.join();
        self.advertise(&channels).await?;
        loop {
            tokio::select! {
                _ = shutdown.changed() => {
                    let timeout = self.hub.limits.send_timeout;
                    let _ = tokio::time::timeout(timeout, self.ws.close(None)).await;
                    return Ok(());
                }
                m = self.ws.next() => match m {
                    None | Some(Ok(Message::Close(_))) => return Ok(()),
                    Some(Err(e)) => return Err(e.into()),
                    Some(Ok(Message::Text(t))) => self.request(t.as_str()).await?,
                    Some(Ok(Message::Binary(_))) => {
                        let s = "binary messages (client publishing) are not supported";
                        self.status(Level::Error, s).await?;
                    }
                    // Pings are answered by the WebSocket layer itself.
                    Some(Ok(_)) => {}
                },
                e = rx.recv() => match e {
                    Ok(Event::Advertise(c)) => self.advertise(&[c]).await?,
                    Ok(Event::Message(m)) => self.message(&m).await?,
                    Err(RecvError::Lagged(n)) => self.lagged(n).await?,
                    Err(RecvError::Closed) => return Ok(()),
                },
            }
        }
    }

    /// Sends message `m` if its channel is subscribed (and it was not sent as the latest
    /// message on subscribing).
    async fn message(&mut self, m: &Latest) -> Result<(), End> {
        let Some(sub) = self.by_channel.get(&m.channel) else {
            return Ok(());
        };
        if self.sent_up_to.get(&m.channel).is_some_and(|s| m.seq <= *s) {
            return Ok(());
        }
        let frame = proto::message_data(*sub, m.log_ns, &m.data);
        self.send(Message::binary(frame)).await
    }

    /// Sends `m`, dropping the client when it takes nothing for the send timeout.
    async fn send(&mut self, m: Message) -> Result<(), End> {
        let timeout = self.hub.limits.send_timeout;
        match tokio::time::timeout(timeout, self.ws.send(m)).await {
            Ok(r) => Ok(r?),
            Err(_) => Err(End::Slow(timeout)),
        }
    }

    /// A status message.
    async fn status(&mut self, level: Level, message: &str) -> Result<(), End> {
        self.send(Message::text(proto::status(level, message)))
            .await
    }

    /// Advertises those of `channels` not advertised yet (all at once, even none: the spec
    /// wants an Advertise on connection).
    async fn advertise(&mut self, channels: &[Arc<LiveChannel>]) -> Result<(), End> {
        let new: Vec<&LiveChannel> = channels
            .iter()
            .filter(|c| self.advertised.insert(c.id))
            .map(|c| c.as_ref())
            .collect();
        if new.is_empty() && !channels.is_empty() {
            return Ok(());
        }
        self.send(Message::text(proto::advertise(new))).await
    }

    /// The client fell `n` messages behind: they are skipped; channels advertised meanwhile
    /// are advertised now.
    async fn lagged(&mut self, n: u64) -> Result<(), End> {
        self.skipped += n;
        self.hub.stats.skipped.fetch_add(n, Ordering::Relaxed);
        let channels = self.hub.channels();
        self.advertise(&channels).await?;
        let s = format!("{n} messages skipped: this client reads slower than they come");
        self.status(Level::Warning, &s).await
    }

    /// One text message of the client's.
    async fn request(&mut self, text: &str) -> Result<(), End> {
        match proto::request(text) {
            Ok(proto::Request::Subscribe(subs)) => {
                for s in subs {
                    if let Err(e) = self.subscribe(s) {
                        self.status(Level::Error, &e).await?;
                    } else if let Some(m) = self.hub.latest(s.channel_id) {
                        self.sent_up_to.insert(s.channel_id, m.seq);
                        let frame = proto::message_data(s.id, m.log_ns, &m.data);
                        self.send(Message::binary(frame)).await?;
                    }
                }
                Ok(())
            }
            Ok(proto::Request::Unsubscribe(ids)) => {
                for id in ids {
                    match self.subscriptions.remove(&id) {
                        Some(channel) => {
                            self.by_channel.remove(&channel);
                        }
                        None => {
                            let e = format!("unsubscribe: no subscription {id}");
                            self.status(Level::Warning, &e).await?;
                        }
                    }
                }
                Ok(())
            }
            Err(e) => self.status(Level::Error, &e).await,
        }
    }

    /// Takes one subscription, or says why not.
    fn subscribe(&mut self, s: proto::Subscription) -> Result<(), String> {
        if !self.advertised.contains(&s.channel_id) {
            return Err(format!("subscribe: no channel {}", s.channel_id));
        }
        if self.subscriptions.contains_key(&s.id) {
            return Err(format!("subscribe: subscription id {} is in use", s.id));
        }
        if let Some(other) = self.by_channel.get(&s.channel_id) {
            return Err(format!(
                "subscribe: channel {} is subscribed already (subscription {other})",
                s.channel_id
            ));
        }
        self.subscriptions.insert(s.id, s.channel_id);
        self.by_channel.insert(s.channel_id, s.id);
        Ok(())
    }
}
