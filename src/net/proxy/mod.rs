//! The transparent LLRP proxy: each client connection gets its own upstream connection to
//! the reader, and every byte is forwarded unchanged both ways (frames the codec cannot
//! decode and bytes that are not LLRP included). Beside the forwarding, a copy of each
//! direction is split into frames (the codec's sans-IO [`llrp::FrameSplitter`]) for the recording and
//! the tap; neither can change or drop what is forwarded.
//!
//! Backpressure is end to end: a direction reads its next chunk only once the last one is
//! written, so a slow client slows the reading from the reader and memory stays bounded
//! (one chunk buffer and at most one partial frame per direction).
//!
//! Either side may be TLS ([`ProxyConfig::tls`] towards the clients, [`ProxyConfig::upstream_tls`]
//! towards the reader): the forwarding is then of the plaintext, byte for byte as over TCP, and
//! each side's TLS session is its own (the proxy terminates both). The streams are split with
//! [`Stream::into_split`]: TCP's owned halves, or for TLS two halves sharing the one TLS state
//! (tokio's split), which both directions of a session poll from the session's one task. A
//! chunk counts as written once it is flushed, so that TLS holds no record back. A client
//! whose TLS handshake fails is dropped (logged, and in the recording); an upstream whose TLS
//! handshake fails is treated as unreachable: the client gets a failed ConnectionAttemptEvent.

use crate::reads::ReaderName;
use std::future::Future;
use std::io;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::pin::Pin;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use bytes::BytesMut;
use llrp::message::{CloseConnection, ReaderEventNotification};
use llrp::units::HopTable;
use llrp::Message;
use tokio::io::AsyncWriteExt;
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{mpsc, watch};

pub mod keepalive;
mod pump;

use pump::{pump, write_flushed, End, PumpDone, Tee};

use super::stream::{ReadHalf, Stream, WriteHalf};
use super::{serve, tls};
use crate::reads::Read;
use crate::record::{Direction, Event, Recorder};
use crate::utc::now_us as utc_now_us;

/// Bytes one direction reads at a time.
const CHUNK: usize = 64 * 1024;
/// How long the proxy waits for the reader to answer a CLOSE_CONNECTION it sent for a
/// client that left (or at shutdown) before closing anyway.
const CLOSE_WAIT: Duration = Duration::from_secs(2);
/// How long a closing direction may take to hand its last bytes to its peer.
const LINGER: Duration = Duration::from_secs(5);
/// The message ID of the CLOSE_CONNECTION the proxy itself sends.
const PROXY_CLOSE_ID: u32 = 0x7072_7879;

/// One proxied reader.
#[derive(Clone, Debug)]
pub struct ProxyConfig {
    /// Name in logs and on tapped reads.
    pub name: ReaderName,
    /// The reader, `HOST:PORT`.
    pub upstream: String,
    /// Where clients connect.
    pub listen: String,
    /// Record every session to this file.
    pub record: Option<PathBuf>,
    /// Hop table for tapped reads until the reader's capabilities are seen (`--region`).
    pub region: Option<HopTable>,
    /// Longest wait for the upstream connection.
    pub connect_timeout: Duration,
    /// Clients connect with TLS (`--tls-cert`, `--tls-key`).
    pub tls: Option<tls::Acceptor>,
    /// The reader is reached with TLS (`--upstream-tls`).
    pub upstream_tls: Option<tls::Connector>,
}

/// What the tap hands on.
#[derive(Clone, Debug)]
pub enum Tapped {
    /// The tag reads of one RO_ACCESS_REPORT.
    Reads(Vec<Read>),
    /// A READER_EVENT_NOTIFICATION, decoded.
    Event {
        /// The proxy's name.
        reader: ReaderName,
        /// Its connection number.
        conn: u32,
        /// The message.
        message: Box<Message>,
    },
}

/// The sending side of the tap: a bounded channel (of reports and events) that never waits;
/// what does not fit is counted, read by read, in [`Tap::dropped`].
#[derive(Clone, Debug)]
pub struct Tap {
    tx: mpsc::Sender<Tapped>,
    dropped: Arc<AtomicU64>,
    links: keepalive::Links,
}

impl Tap {
    /// A tap holding at most `capacity` items, and its receiver.
    pub fn new(capacity: usize) -> (Tap, mpsc::Receiver<Tapped>) {
        let (tx, rx) = mpsc::channel(capacity.max(1));
        (
            Tap {
                tx,
                dropped: Arc::new(AtomicU64::new(0)),
                links: keepalive::Links::default(),
            },
            rx,
        )
    }

    /// The sessions' keepalive links, for whoever watches them.
    pub fn links(&self) -> keepalive::Links {
        self.links.clone()
    }

    /// Reads and events dropped because the receiver was behind (or gone).
    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }

    fn offer(&self, item: Tapped) {
        let n = match &item {
            Tapped::Reads(r) => r.len() as u64,
            Tapped::Event { .. } => 1,
        };
        if self.tx.try_send(item).is_err() {
            self.dropped.fetch_add(n, Ordering::Relaxed);
        }
    }
}

/// A bound proxy, ready to run.
pub struct Proxy {
    listener: TcpListener,
    config: Arc<ProxyConfig>,
    recorder: Option<Recorder>,
    tap: Option<Tap>,
    stats: Arc<Stats>,
    max_clients: usize,
}

/// Clients a proxy serves at once unless told otherwise (`proxy --max-clients`).
pub const MAX_CLIENTS: usize = 64;

/// Counters of a proxy, over all its sessions (cheap: one atomic add per frame).
#[derive(Debug, Default)]
pub struct Stats {
    /// Client connections accepted.
    pub sessions: AtomicU64,
    /// Whole LLRP frames forwarded from the reader to clients.
    pub frames_from_reader: AtomicU64,
    /// Whole LLRP frames forwarded from clients to the reader.
    pub frames_to_reader: AtomicU64,
    /// Of the frames from the reader, those the codec could not decode (counted only while
    /// something decodes them: a recording or the tap).
    pub undecodable_from_reader: AtomicU64,
    /// Of the frames from clients, those the codec could not decode (as above).
    pub undecodable_to_reader: AtomicU64,
}

impl Stats {
    fn frames(&self, dir: Direction) -> &AtomicU64 {
        match dir {
            Direction::ToReader => &self.frames_to_reader,
            Direction::FromReader => &self.frames_from_reader,
        }
    }

    fn undecodable(&self, dir: Direction) -> &AtomicU64 {
        match dir {
            Direction::ToReader => &self.undecodable_to_reader,
            Direction::FromReader => &self.undecodable_from_reader,
        }
    }
}

impl Proxy {
    /// Binds the listening address.
    pub async fn bind(
        config: ProxyConfig,
        recorder: Option<Recorder>,
        tap: Option<Tap>,
    ) -> io::Result<Proxy> {
        let listener = TcpListener::bind(&config.listen).await?;
        Ok(Proxy {
            listener,
            config: Arc::new(config),
            recorder,
            tap,
            stats: Arc::default(),
            max_clients: MAX_CLIENTS,
        })
    }

    /// The proxy's counters.
    pub fn stats(&self) -> Arc<Stats> {
        Arc::clone(&self.stats)
    }

    /// The address clients connect to.
    pub fn local_addr(&self) -> io::Result<SocketAddr> {
        self.listener.local_addr()
    }

    /// This proxy serving at most `max` clients at once (each with its own connection to the
    /// reader); one more is told, as when the reader cannot be reached, and closed.
    pub fn with_max_clients(mut self, max: usize) -> Proxy {
        self.max_clients = max.max(1);
        self
    }

    /// Accepts clients until `shutdown` turns true (at most [`Proxy::with_max_clients`] at
    /// once, [`MAX_CLIENTS`] unless set); then each session sends CLOSE_CONNECTION upstream
    /// and closes, and this returns once all have ended.
    pub async fn run(self, shutdown: watch::Receiver<bool>) -> io::Result<()> {
        let what = format!("proxy {}", self.config.name);
        let plain = self.config.tls.is_none();
        serve::accept_loop(
            &self.listener,
            self.max_clients,
            shutdown.clone(),
            &what,
            |stream, peer| {
                let conn = self.recorder.as_ref().map_or(0, Recorder::next_conn);
                let id = self.stats.sessions.fetch_add(1, Ordering::Relaxed);
                let s = Session {
                    config: Arc::clone(&self.config),
                    recorder: self.recorder.clone(),
                    tap: self.tap.clone(),
                    stats: Arc::clone(&self.stats),
                    conn,
                    id,
                    peer,
                };
                s.run(stream, shutdown.clone())
            },
            // (A TLS client over the limit is closed: a refusal in the clear means nothing
            // to it before its handshake.)
            move |stream, _| async move {
                if plain {
                    refuse(Stream::from(stream)).await;
                }
            },
        )
        .await
    }
}

/// One client connection and its upstream connection.
struct Session {
    config: Arc<ProxyConfig>,
    recorder: Option<Recorder>,
    tap: Option<Tap>,
    stats: Arc<Stats>,
    conn: u32,
    /// Numbered from 0 in the order clients came (the tap's session id).
    id: u64,
    peer: SocketAddr,
}

/// Why the reader could not be reached.
#[derive(Debug, thiserror::Error)]
enum Unreachable {
    /// No TCP connection (refused, timed out, no route).
    #[error("upstream {addr} unreachable: {source}")]
    Connect {
        /// The reader's address.
        addr: String,
        /// Why.
        source: io::Error,
    },
    /// TCP connected, the TLS handshake failed.
    #[error("upstream {addr} unreachable: TLS handshake failed: {source}")]
    Tls {
        /// The reader's address.
        addr: String,
        /// Why (rustls' reason inside, when it has one).
        source: io::Error,
    },
}

impl Session {
    async fn run(self, client: TcpStream, shutdown: watch::Receiver<bool>) {
        let _ = client.set_nodelay(true);
        let name = &self.config.name;
        let tls = if self.config.tls.is_some() {
            " over TLS"
        } else {
            ""
        };
        self.marker(
            Event::Connect,
            format!(
                "client {}{tls} via proxy {name} to {}",
                self.peer, self.config.upstream
            ),
        )
        .await;
        let client = match &self.config.tls {
            Some(acceptor) => match acceptor.accept(client).await {
                Ok(s) => Stream::from(s),
                Err(e) => {
                    tracing::warn!(
                        proxy = %name,
                        client = %self.peer,
                        "TLS handshake with the client failed: {e}; the client is dropped"
                    );
                    self.marker(
                        Event::Disconnect,
                        format!("client TLS handshake failed: {e}"),
                    )
                    .await;
                    return;
                }
            },
            None => Stream::from(client),
        };
        let upstream = match self.connect_upstream().await {
            Ok(u) => u,
            Err(e) => {
                tracing::warn!(
                    proxy = %name,
                    client = %self.peer,
                    "{e}: the client gets a failed ConnectionAttemptEvent"
                );
                refuse(client).await;
                self.marker(Event::Disconnect, e.to_string()).await;
                return;
            }
        };
        tracing::info!(proxy = %name, client = %self.peer, "forwarding to {}", self.config.upstream);
        let reason = self.forward(client, upstream, shutdown).await;
        tracing::info!(proxy = %name, client = %self.peer, "session ended: {reason}");
        if let Some(tap) = &self.tap {
            tap.links.end(self.id);
        }
        self.marker(Event::Disconnect, reason).await;
    }

    /// Tells the tap's watch of this session's keepalive link.
    fn link(&self, note: keepalive::LinkNote) {
        if let Some(tap) = &self.tap {
            tap.links
                .note(self.id, &self.config.name, note, std::time::Instant::now());
        }
    }

    /// The upstream connection: TCP within the connect timeout, then the TLS handshake if
    /// configured (within [`tls::HANDSHAKE_TIMEOUT`]).
    async fn connect_upstream(&self) -> Result<Stream, Unreachable> {
        let addr = &self.config.upstream;
        let tcp = tokio::time::timeout(self.config.connect_timeout, TcpStream::connect(addr))
            .await
            .unwrap_or_else(|_| Err(io::Error::new(io::ErrorKind::TimedOut, "timed out")))
            .map_err(|source| Unreachable::Connect {
                addr: addr.clone(),
                source,
            })?;
        let _ = tcp.set_nodelay(true);
        match &self.config.upstream_tls {
            Some(connector) => connector
                .connect(addr, tcp)
                .await
                .map(Stream::from)
                .map_err(|source| Unreachable::Tls {
                    addr: addr.clone(),
                    source,
                }),
            None => Ok(Stream::from(tcp)),
        }
    }

    async fn marker(&self, event: Event, reason: String) {
        if let Some(r) = &self.recorder {
            if r.marker(self.conn, event, reason).await.is_err() {
                tracing::error!(proxy = %self.config.name, "the recording has stopped");
            }
        }
    }

    /// Forwards both ways until one side ends; returns why the session ended.
    async fn forward(
        &self,
        client: Stream,
        upstream: Stream,
        shutdown: watch::Receiver<bool>,
    ) -> String {
        let (client_rd, client_wr) = client.into_split();
        let (upstream_rd, upstream_wr) = upstream.into_split();
        let to_reader = Tee::new(self, Direction::ToReader);
        let from_reader = Tee::new(self, Direction::FromReader);
        // The client's direction also stops at a shutdown (while waiting to read, or in the
        // middle of a write to a reader that does not read); the proxy then sends
        // CLOSE_CONNECTION only if the stream stands on a frame boundary.
        let up = pump(client_rd, upstream_wr, to_reader, Some(shutdown));
        let mut down = Box::pin(pump(upstream_rd, client_wr, from_reader, None));
        tokio::pin!(up);
        tokio::select! {
            done = &mut down => self.reader_ended(done, up).await,
            done = &mut up => self.client_ended(done, down).await,
        }
    }

    /// Ends the session after the reader's direction ended (`done`); says why.
    async fn reader_ended<'a>(
        &'a self,
        done: PumpDone<'a, ReadHalf, WriteHalf>,
        mut up: Pin<&mut impl Future<Output = PumpDone<'a, ReadHalf, WriteHalf>>>,
    ) -> String {
        let (end, upstream_rd, mut client_wr, from_reader) = done;
        if let End::WriteError(e) = end {
            // The client is gone (a reset): free the reader as when it closes.
            let _ = tokio::time::timeout(LINGER, client_wr.shutdown()).await;
            let Ok((_, _, mut upstream_wr, to_reader)) =
                tokio::time::timeout(LINGER, &mut up).await
            else {
                return format!("writing to the client failed: {e}; the client's side did not end");
            };
            let drain = async move {
                pump(upstream_rd, tokio::io::sink(), from_reader, None)
                    .await
                    .0
            };
            let freed = self
                .close_upstream(&mut upstream_wr, to_reader.at_frame_boundary(), drain)
                .await;
            return format!("writing to the client failed: {e}; {freed}");
        }
        // The reader went away: the client's connection closes too. The client's
        // direction then runs on until the client closes (or LINGER passes), so that
        // what it had read is recorded, and what it still sends finds its end.
        let _ = tokio::time::timeout(LINGER, client_wr.shutdown()).await;
        let _ = tokio::time::timeout(LINGER, &mut up).await;
        match end {
            End::Eof if from_reader.saw_close_response => {
                "reader closed the connection after CLOSE_CONNECTION".into()
            }
            End::Eof => "upstream closed the connection mid-session".into(),
            End::ReadError(e) => format!("upstream connection failed: {e}"),
            End::WriteError(_) | End::Stopped => {
                unreachable!("handled above / the reader's direction has no stop signal")
            }
        }
    }

    /// Ends the session after the client's direction ended (`done`); says why.
    async fn client_ended<'a>(
        &'a self,
        done: PumpDone<'a, ReadHalf, WriteHalf>,
        mut down: Pin<Box<impl Future<Output = PumpDone<'a, ReadHalf, WriteHalf>>>>,
    ) -> String {
        let (end, _, mut upstream_wr, to_reader) = done;
        if matches!(end, End::Eof) && to_reader.saw_close {
            // The client closed after its own CLOSE_CONNECTION: pass the end of stream
            // on, and the rest of the reader's answer back until the reader closes.
            let _ = tokio::time::timeout(LINGER, upstream_wr.shutdown()).await;
            return match tokio::time::timeout(LINGER, &mut down).await {
                Ok((_, _, mut client_wr, _)) => {
                    let _ = tokio::time::timeout(LINGER, client_wr.shutdown()).await;
                    "client closed after CLOSE_CONNECTION".into()
                }
                Err(_) => {
                    "client closed after CLOSE_CONNECTION; the reader did not close in time".into()
                }
            };
        }
        let why = match end {
            End::Eof => "client closed".to_string(),
            End::ReadError(e) => format!("client connection failed: {e}"),
            End::WriteError(e) => format!("writing to the reader failed: {e}"),
            End::Stopped => "proxy shutting down".to_string(),
        };
        let drain = async move {
            let (end, rd, mut client_wr, tee) = down.await;
            let _ = tokio::time::timeout(LINGER, client_wr.shutdown()).await;
            match end {
                // The client is gone: keep reading (and recording) what the reader
                // sends until it closes.
                End::WriteError(_) => pump(rd, tokio::io::sink(), tee, None).await.0,
                end => end,
            }
        };
        let freed = self
            .close_upstream(&mut upstream_wr, to_reader.at_frame_boundary(), drain)
            .await;
        format!("{why}; {freed}")
    }

    /// Frees the reader for its next client: sends CLOSE_CONNECTION (recorded as sent) when
    /// the client's stream ended on a frame boundary (else it would land inside the cut
    /// frame: then only the end of stream is sent), and waits for the reader to close while
    /// `drain` reads what it still sends; says how that went.
    async fn close_upstream(
        &self,
        wr: &mut WriteHalf,
        boundary: bool,
        drain: impl Future<Output = End>,
    ) -> String {
        let sent = if boundary {
            let close = Message::new(PROXY_CLOSE_ID, CloseConnection::default()).to_bytes();
            match tokio::time::timeout(CLOSE_WAIT, write_flushed(wr, &close)).await {
                Ok(Ok(())) => {}
                Ok(Err(e)) => return format!("the reader's connection is gone ({e})"),
                Err(_) => {
                    return "the reader takes no more bytes: closed by the proxy without CLOSE_CONNECTION".into()
                }
            }
            if let Some(r) = &self.recorder {
                let _ = r
                    .frame(r.now(), self.conn, Direction::ToReader, close.freeze())
                    .await;
            }
            "proxy sent CLOSE_CONNECTION"
        } else {
            let _ = tokio::time::timeout(LINGER, wr.shutdown()).await;
            "the client's stream ended inside a frame, so the proxy closed without CLOSE_CONNECTION"
        };
        match tokio::time::timeout(CLOSE_WAIT, drain).await {
            Ok(End::Eof) => format!("{sent} and the reader closed"),
            Ok(End::ReadError(e)) | Ok(End::WriteError(e)) => {
                format!("{sent}; the reader's connection failed: {e}")
            }
            Ok(End::Stopped) | Err(_) => {
                let _ = tokio::time::timeout(LINGER, wr.shutdown()).await;
                format!("{sent}; the reader did not close in time, closed by the proxy")
            }
        }
    }
}

/// Tells a client whose reader cannot be reached: a READER_EVENT_NOTIFICATION with a failed
/// ConnectionAttemptEvent, as a reader that cannot take the connection sends; then closes.
async fn refuse(client: Stream) {
    let m = Message::new(0, connection_failed(utc_now_us()));
    let mut bytes = BytesMut::new();
    m.encode(&mut bytes);
    serve::refuse(client, &bytes, Duration::from_millis(500)).await;
}

/// The READER_EVENT_NOTIFICATION a client gets when the proxy cannot reach the reader.
pub fn connection_failed(utc_us: u64) -> ReaderEventNotification {
    ReaderEventNotification::connection_attempt(
        llrp::enums::ConnectionAttemptStatus::FailedOtherReason,
        utc_us,
    )
}
