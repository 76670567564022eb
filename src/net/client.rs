//! An async LLRP client over a [`Connection`].
//!
//! The low level: connect, send typed messages, receive and match responses by message ID;
//! unsolicited messages (reports, events, keepalives) are queued for the caller. The tests use
//! it this way.
//!
//! The reader-session level, used by `llrp-gateway inventory`: the handshake (the reader's
//! ConnectionAttemptEvent), requests checked for success ([`Client::check`]), capabilities,
//! keepalives answered automatically ([`Client::answer_keepalives`]), an inventory set up from
//! an [`InventorySpec`] (configuration, Impinj extensions, ROSpec) and its reports turned into
//! typed [`Read`]s ([`ReadStream`]), reconnection with a capped exponential [`Backoff`], and a
//! clean close (CLOSE_CONNECTION, then the reader's close).

use std::collections::VecDeque;
use std::io;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use llrp::enums::{ConnectionAttemptStatus, KeepaliveTriggerType, RoReportTriggerType};
use llrp::impinj::ImpinjEnableExtensions;
use llrp::message::{
    AddRospec, CloseConnection, DeleteRospec, EnableRospec, GetReaderCapabilities,
    GetReaderCapabilitiesResponse, KeepaliveAck, MessageBody, MessageDef, SetReaderConfig,
    StartRospec, StopRospec,
};
use llrp::params::{
    AntennaConfiguration, C1g2InventoryCommand, C1g2RfControl, C1g2SingulationControl, Custom,
    ImpinjInventorySearchMode, KeepaliveSpec, LlrpStatus, RoReportSpec, RoSpec,
    TagReportContentSelector,
};
use llrp::{Inbound, Message, Request, Response};
use tokio::net::{TcpStream, ToSocketAddrs};

use super::connection::Connection;
use super::tls::{self, Connector};
use crate::reads::{Read, ReadDecoder};

/// Errors of the client.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// Socket error.
    #[error("i/o: {0}")]
    Io(#[from] io::Error),
    /// The TLS handshake failed ([`tls::rustls_error`] gives rustls' reason, when it has one).
    #[error("TLS handshake: {0}")]
    Tls(#[source] io::Error),
    /// The peer sent bytes that are not LLRP.
    #[error("bad frame from peer: {0}")]
    Frame(#[from] llrp::FrameError),
    /// The peer sent a message that does not decode.
    #[error("undecodable message from peer: {0}")]
    Decode(#[from] llrp::DecodeError),
    /// Nothing arrived in time.
    #[error("timed out waiting for {0}")]
    Timeout(&'static str),
    /// The peer closed the connection.
    #[error("connection closed by peer")]
    Closed,
    /// The peer answered a request with another message (e.g. ERROR_MESSAGE).
    #[error("unexpected answer {0}")]
    Unexpected(&'static str),
    /// The reader refused the connection (the status of its ConnectionAttemptEvent).
    #[error("the reader refused the connection: {0:?}")]
    Refused(ConnectionAttemptStatus),
    /// The reader answered a request with a failure status (or with ERROR_MESSAGE).
    #[error("{request} failed: {}", describe_status(.status))]
    Status {
        /// The request's message name.
        request: &'static str,
        /// The status the reader sent.
        status: Box<LlrpStatus>,
    },
    /// The request asks for something the reader's capabilities say it cannot do.
    #[error("{0}")]
    Unsupported(String),
}

impl ClientError {
    /// Whether connecting again may help: the connection failed, closed, stalled or was
    /// refused (another client held it), as opposed to a request the reader rejects or a
    /// certificate that will be refused again.
    pub fn is_transient(&self) -> bool {
        match self {
            ClientError::Tls(e) => {
                !tls::is_certificate_error(e) && e.kind() != io::ErrorKind::InvalidInput
            }
            e => matches!(
                e,
                ClientError::Io(_)
                    | ClientError::Timeout(_)
                    | ClientError::Closed
                    | ClientError::Frame(_)
                    | ClientError::Refused(_)
            ),
        }
    }
}

/// An LLRPStatus in one line: code, description and the innermost parameter and field named.
pub fn describe_status(status: &LlrpStatus) -> String {
    let mut s = format!("{}", status.status_code);
    if !status.error_description.is_empty() {
        s.push_str(&format!(" ({})", status.error_description));
    }
    let mut p = status.parameter_error.as_ref();
    let mut path = Vec::new();
    let mut field = status.field_error.as_ref();
    while let Some(e) = p {
        path.push(format!("{}", e.parameter_type));
        if e.field_error.is_some() {
            field = e.field_error.as_ref();
        }
        p = e.parameter_error.as_deref();
    }
    if !path.is_empty() {
        s.push_str(&format!(" in parameter {}", path.join("/")));
    }
    if let Some(f) = field {
        s.push_str(&format!(", field {}: {}", f.field_num, f.error_code));
    }
    s
}

/// An LLRP client connection.
pub struct Client {
    conn: Connection,
    next_id: u32,
    version: u8,
    /// Messages received but not yet taken.
    pending: VecDeque<Message>,
    /// Whether KEEPALIVEs are answered (and not queued).
    answer_keepalives: bool,
    /// KEEPALIVEs answered so far.
    keepalives_answered: u64,
}

impl Client {
    /// Connects to a reader.
    pub async fn connect(addr: impl ToSocketAddrs) -> Result<Client, ClientError> {
        Ok(Client::over(Connection::connect(addr).await?))
    }

    /// Connects to a reader over TLS (LLRP over TLS, port 5085 by convention): TCP, then the
    /// handshake; the reader's certificate is checked as `tls` says, for the host of `addr`
    /// unless `tls` names another. A failed handshake is [`ClientError::Tls`].
    pub async fn connect_tls(addr: &str, tls: &Connector) -> Result<Client, ClientError> {
        let tcp = TcpStream::connect(addr).await?;
        let stream = tls.connect(addr, tcp).await.map_err(ClientError::Tls)?;
        Ok(Client::over(Connection::from_stream(stream)))
    }

    /// A client on an established connection.
    pub fn over(conn: Connection) -> Client {
        Client {
            conn,
            next_id: 1000,
            version: 1,
            pending: VecDeque::new(),
            answer_keepalives: false,
            keepalives_answered: 0,
        }
    }

    /// Connects within `timeout` and waits (within `timeout` too) for the reader's greeting,
    /// a READER_EVENT_NOTIFICATION with a ConnectionAttemptEvent: `Err(Refused)` unless its
    /// status is Success.
    pub async fn connect_reader(
        addr: impl ToSocketAddrs,
        timeout: Duration,
    ) -> Result<Client, ClientError> {
        let mut c = tokio::time::timeout(timeout, Client::connect(addr))
            .await
            .map_err(|_| ClientError::Timeout("the TCP connection"))??;
        c.handshake(timeout).await?;
        Ok(c)
    }

    /// [`Client::connect_reader`], over TLS when `tls` is given ([`Client::connect_tls`]).
    pub async fn connect_reader_with(
        addr: &str,
        tls: Option<&Connector>,
        timeout: Duration,
    ) -> Result<Client, ClientError> {
        let Some(tls) = tls else {
            return Client::connect_reader(addr, timeout).await;
        };
        let mut c = tokio::time::timeout(timeout, Client::connect_tls(addr, tls))
            .await
            .map_err(|_| ClientError::Timeout("the TLS connection"))??;
        c.handshake(timeout).await?;
        Ok(c)
    }

    /// Waits for the reader's ConnectionAttemptEvent (other messages are kept): `Ok` on
    /// Success, `Err(Refused)` with any other status.
    pub async fn handshake(&mut self, timeout: Duration) -> Result<(), ClientError> {
        let m = self
            .wait_for(|m| m.body.connection_attempt().is_some(), timeout)
            .await
            .map_err(|e| match e {
                ClientError::Timeout(_) => ClientError::Timeout("the reader's greeting"),
                e => e,
            })?;
        match m.body.connection_attempt() {
            Some(ConnectionAttemptStatus::Success) => Ok(()),
            Some(other) => Err(ClientError::Refused(other)),
            // Not reached: wait_for returns only a message the predicate accepted.
            None => Err(ClientError::Unexpected(m.name())),
        }
    }

    /// From now on, answer every KEEPALIVE with a KEEPALIVE_ACK (same message ID) as it is
    /// read, instead of queueing it (`false`, the default, queues it like any message).
    pub fn answer_keepalives(&mut self, on: bool) {
        self.answer_keepalives = on;
    }

    /// How many KEEPALIVEs have been answered.
    pub fn keepalives_answered(&self) -> u64 {
        self.keepalives_answered
    }

    /// Sets the header version of messages sent from now on.
    pub fn set_version(&mut self, version: u8) {
        self.version = version;
    }

    /// Sends a message with a fresh ID; returns the ID.
    pub async fn send(&mut self, body: impl Into<MessageBody>) -> Result<u32, ClientError> {
        let id = self.next_id;
        self.next_id = self.next_id.wrapping_add(1);
        let m = Message {
            version: self.version,
            id,
            body: body.into(),
        };
        self.conn.write_message(&m).await?;
        Ok(id)
    }

    /// Sends raw bytes (for malformed-input tests).
    pub async fn send_raw(&mut self, bytes: &[u8]) -> Result<(), ClientError> {
        self.conn.write_bytes(bytes).await?;
        Ok(())
    }

    /// The next message from the peer, waiting at most `timeout`.
    pub async fn recv(&mut self, timeout: Duration) -> Result<Message, ClientError> {
        if let Some(m) = self.pending.pop_front() {
            return Ok(m);
        }
        self.read_one(timeout).await
    }

    async fn read_one(&mut self, timeout: Duration) -> Result<Message, ClientError> {
        let frame = self.read_frame(timeout, "a message").await?;
        Ok(Message::decode(&frame)?)
    }

    /// The next frame within `timeout`; KEEPALIVEs are answered and skipped when
    /// [`Client::answer_keepalives`] is on.
    async fn read_frame(
        &mut self,
        timeout: Duration,
        what: &'static str,
    ) -> Result<bytes::Bytes, ClientError> {
        let deadline = tokio::time::Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(tokio::time::Instant::now());
            // Only the read is under the timeout (it is cancel-safe); an answer is always
            // written whole.
            let frame = match tokio::time::timeout(left, self.conn.read_frame())
                .await
                .map_err(|_| ClientError::Timeout(what))??
            {
                Some(Inbound::Frame(f)) => f,
                Some(Inbound::Unsynced(e)) => return Err(ClientError::Frame(e)),
                None => return Err(ClientError::Closed),
            };
            if self.answer_keepalives {
                if let Some(h) = llrp::FrameHeader::peek(&frame) {
                    if h.msg_type == llrp::message::Keepalive::TYPE {
                        let ack = Message {
                            version: self.version,
                            id: h.id,
                            body: KeepaliveAck::default().into(),
                        };
                        self.conn.write_message(&ack).await?;
                        self.keepalives_answered += 1;
                        continue;
                    }
                }
            }
            return Ok(frame);
        }
    }

    /// The next frame from the peer as bytes, messages queued earlier first (re-encoded),
    /// waiting at most `timeout`; with [`Client::answer_keepalives`] on, KEEPALIVEs never
    /// come out. For callers that walk reports without decoding them (see [`ReadStream`]).
    pub async fn recv_frame(&mut self, timeout: Duration) -> Result<bytes::Bytes, ClientError> {
        if let Some(m) = self.pending.pop_front() {
            return Ok(m.to_bytes().freeze());
        }
        self.read_frame(timeout, "a message").await
    }

    /// The next frame as raw bytes, whatever its version (for checking what a peer sends to
    /// a version it does not speak).
    pub async fn recv_raw(&mut self, timeout: Duration) -> Result<Vec<u8>, ClientError> {
        Ok(self.read_frame(timeout, "a frame").await?.to_vec())
    }

    /// Sends a request and waits for its response, typed.
    pub async fn transact<R: Request>(
        &mut self,
        request: R,
        timeout: Duration,
    ) -> Result<R::Response, ClientError> {
        let m = self.request(request, timeout).await?;
        let name = m.name();
        R::Response::try_from(m.body).map_err(|_| ClientError::Unexpected(name))
    }

    /// Sends a request and waits for the message answering it (same ID); other messages
    /// arriving meanwhile are kept for [`Client::recv`].
    pub async fn request(
        &mut self,
        body: impl Into<MessageBody>,
        timeout: Duration,
    ) -> Result<Message, ClientError> {
        let id = self.send(body).await?;
        // Reader-initiated messages have their own ID sequence: match the ID on answers only.
        self.wait_for(|m| m.id == id && !is_unsolicited(m), timeout)
            .await
    }

    /// Waits for the first message satisfying `pred`, keeping the others.
    pub async fn wait_for(
        &mut self,
        pred: impl Fn(&Message) -> bool,
        timeout: Duration,
    ) -> Result<Message, ClientError> {
        if let Some(i) = self.pending.iter().position(&pred) {
            return Ok(self.pending.remove(i).expect("index from position"));
        }
        let deadline = tokio::time::Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(tokio::time::Instant::now());
            let m = self.read_one(left).await?;
            if pred(&m) {
                return Ok(m);
            }
            self.pending.push_back(m);
        }
    }

    /// Takes the queued messages.
    pub fn drain_pending(&mut self) -> Vec<Message> {
        self.pending.drain(..).collect()
    }

    /// Sends a request and waits for its response; `Err(Status)` unless the reader answers
    /// with the request's response type carrying M_Success (an ERROR_MESSAGE gives its
    /// status too).
    pub async fn check<R: Request>(
        &mut self,
        request: R,
        timeout: Duration,
    ) -> Result<R::Response, ClientError> {
        let body: MessageBody = request.into();
        let request_name = body.name();
        let m = self.request(body, timeout).await?;
        if let MessageBody::ErrorMessage(e) = m.body {
            return Err(ClientError::Status {
                request: request_name,
                status: Box::new(e.llrp_status),
            });
        }
        let name = m.name();
        let response = R::Response::try_from(m.body).map_err(|_| ClientError::Unexpected(name))?;
        if response.status().is_success() {
            Ok(response)
        } else {
            Err(ClientError::Status {
                request: request_name,
                status: Box::new(response.status().clone()),
            })
        }
    }

    /// GET_READER_CAPABILITIES (all of them), checked.
    pub async fn capabilities(
        &mut self,
        timeout: Duration,
    ) -> Result<GetReaderCapabilitiesResponse, ClientError> {
        self.check(GetReaderCapabilities::default(), timeout).await
    }

    /// IMPINJ_ENABLE_EXTENSIONS, checked.
    pub async fn enable_impinj_extensions(&mut self, timeout: Duration) -> Result<(), ClientError> {
        self.check(ImpinjEnableExtensions::default(), timeout)
            .await
            .map(drop)
    }

    /// ADD_ROSPEC, checked.
    pub async fn add_rospec(&mut self, spec: RoSpec, timeout: Duration) -> Result<(), ClientError> {
        let add = AddRospec {
            ro_spec: spec,
            ..Default::default()
        };
        self.check(add, timeout).await.map(drop)
    }

    /// ENABLE_ROSPEC `id`, checked.
    pub async fn enable_rospec(&mut self, id: u32, timeout: Duration) -> Result<(), ClientError> {
        let m = EnableRospec {
            ro_spec_id: id,
            ..Default::default()
        };
        self.check(m, timeout).await.map(drop)
    }

    /// START_ROSPEC `id`, checked.
    pub async fn start_rospec(&mut self, id: u32, timeout: Duration) -> Result<(), ClientError> {
        let m = StartRospec {
            ro_spec_id: id,
            ..Default::default()
        };
        self.check(m, timeout).await.map(drop)
    }

    /// STOP_ROSPEC `id`, checked.
    pub async fn stop_rospec(&mut self, id: u32, timeout: Duration) -> Result<(), ClientError> {
        let m = StopRospec {
            ro_spec_id: id,
            ..Default::default()
        };
        self.check(m, timeout).await.map(drop)
    }

    /// DELETE_ROSPEC `id` (0: all), checked.
    pub async fn delete_rospec(&mut self, id: u32, timeout: Duration) -> Result<(), ClientError> {
        let m = DeleteRospec {
            ro_spec_id: id,
            ..Default::default()
        };
        self.check(m, timeout).await.map(drop)
    }

    /// The clean end of a session: CLOSE_CONNECTION, its response checked, then (within
    /// `timeout` in all) the reader's close of the connection.
    pub async fn close_connection(mut self, timeout: Duration) -> Result<(), ClientError> {
        let deadline = tokio::time::Instant::now() + timeout;
        self.check(CloseConnection::default(), timeout).await?;
        let left = deadline.saturating_duration_since(tokio::time::Instant::now());
        self.until_closed(left).await
    }

    /// Closes the sending side and waits (at most `timeout`) for the peer to close too, so
    /// that the peer has seen the close when this returns; messages still arriving meanwhile
    /// are dropped.
    pub async fn close(mut self, timeout: Duration) -> Result<(), ClientError> {
        self.conn.shutdown().await?;
        self.until_closed(timeout).await
    }

    /// Waits (at most `timeout`) until the peer closes the connection, by end-of-stream or a
    /// reset; messages arriving meanwhile are dropped. `Err(Timeout)` if it stays open.
    pub async fn until_closed(&mut self, timeout: Duration) -> Result<(), ClientError> {
        self.pending.clear();
        let deadline = tokio::time::Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(tokio::time::Instant::now());
            match self.read_frame(left, "the peer to close").await {
                Ok(_) => continue,
                Err(ClientError::Closed) => return Ok(()),
                Err(ClientError::Io(e)) if e.kind() == io::ErrorKind::ConnectionReset => {
                    return Ok(())
                }
                Err(e) => return Err(e),
            }
        }
    }
}

/// Whether a message is one a reader sends on its own (reports, events, keepalives).
pub fn is_unsolicited(m: &Message) -> bool {
    matches!(
        m.body,
        MessageBody::RoAccessReport(_)
            | MessageBody::ReaderEventNotification(_)
            | MessageBody::Keepalive(_)
    )
}

/// Capped exponential back-off between connection attempts: `initial`, twice that, four
/// times, … never more than `max`; after `retries` failed retries in a row (`None`: never)
/// there is no next attempt. Deterministic (no jitter): one client per reader.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Backoff {
    initial: Duration,
    max: Duration,
    retries: Option<u32>,
    failures: u32,
}

impl Backoff {
    /// A schedule starting at `initial`, capped at `max` (at least `initial`), allowing
    /// `retries` retries after failures in a row (`None`: unlimited).
    pub fn new(initial: Duration, max: Duration, retries: Option<u32>) -> Self {
        Backoff {
            initial,
            max: max.max(initial),
            retries,
            failures: 0,
        }
    }

    /// Records a failed attempt; the wait before the next one, or `None` when no retry is
    /// left.
    pub fn next_delay(&mut self) -> Option<Duration> {
        self.failures = self.failures.saturating_add(1);
        if self.retries.is_some_and(|r| self.failures > r) {
            return None;
        }
        // 2^(failures-1), saturating long before u32 runs out: the cap applies anyway.
        let factor = 1u32 << (self.failures - 1).min(20);
        Some(self.initial.saturating_mul(factor).min(self.max))
    }

    /// Failed attempts in a row so far.
    pub fn failures(&self) -> u32 {
        self.failures
    }

    /// The retries allowed after failures in a row (`None`: unlimited).
    pub fn retries(&self) -> Option<u32> {
        self.retries
    }

    /// Starts over after a success.
    pub fn reset(&mut self) {
        self.failures = 0;
    }
}

/// What an inventory asks the reader for. Every Gen2 setting left `None` keeps the reader's
/// own.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct InventorySpec {
    /// ROSpecID of the inventory's ROSpec.
    pub rospec_id: u32,
    /// Antenna ports to inventory (1-based); empty: all.
    pub antennas: Vec<u16>,
    /// Enable the Impinj extensions and ask for Impinj phase, peak RSSI and Doppler.
    pub impinj: bool,
    /// A report after every N TagReportData (ROReportTrigger "upon N tags or end of ROSpec").
    pub report_every: u16,
    /// Gen2 session 0..=3 (C1G2SingulationControl).
    pub session: Option<u8>,
    /// Impinj inventory search mode (ImpinjInventorySearchMode).
    pub search_mode: Option<u16>,
    /// RF mode: a ModeIdentifier of the reader's C1G2UHFRFModeTable (C1G2RFControl ModeIndex).
    pub mode: Option<u16>,
    /// Periodic KEEPALIVE interval asked of the reader, ms; 0: none.
    pub keepalive_ms: u32,
}

impl Default for InventorySpec {
    fn default() -> Self {
        InventorySpec {
            rospec_id: 1,
            antennas: Vec::new(),
            impinj: false,
            report_every: 1,
            session: None,
            search_mode: None,
            mode: None,
            keepalive_ms: 5000,
        }
    }
}

impl InventorySpec {
    /// The SET_READER_CONFIG this inventory sends: the keepalive setting only.
    pub fn reader_config(&self) -> SetReaderConfig {
        let keepalive = if self.keepalive_ms > 0 {
            KeepaliveSpec {
                keepalive_trigger_type: KeepaliveTriggerType::Periodic,
                periodic_trigger_value: self.keepalive_ms,
                ..Default::default()
            }
        } else {
            KeepaliveSpec::default()
        };
        SetReaderConfig {
            keepalive_spec: Some(keepalive),
            ..Default::default()
        }
    }

    /// The ROSpec: started by START_ROSPEC (a Null start trigger, which every reader
    /// honours), no stop trigger, the spec's antennas, every standard report field (and the
    /// Impinj ones), and one AntennaConfiguration per antenna (`antenna_count` of them when
    /// all are inventoried) when a Gen2 setting is given.
    pub fn rospec(&self, antenna_count: u16) -> RoSpec {
        let antennas = if self.antennas.is_empty() {
            vec![0]
        } else {
            self.antennas.clone()
        };
        let mut report = RoReportSpec::new(
            RoReportTriggerType::UponNTagsOrEndOfRoSpec,
            self.report_every,
        )
        .with_content(TagReportContentSelector::all());
        if self.impinj {
            report = report.with_impinj(true, true, true);
        }
        let mut spec = RoSpec::immediate(self.rospec_id, antennas)
            .with_start(llrp::params::RoSpecStartTrigger::null())
            .with_report(report);
        if self.session.is_some() || self.mode.is_some() || self.search_mode.is_some() {
            let ids: Vec<u16> = if self.antennas.is_empty() {
                (1..=antenna_count.max(1)).collect()
            } else {
                self.antennas.clone()
            };
            let command = C1g2InventoryCommand {
                c1g2_rf_control: self.mode.map(|m| C1g2RfControl {
                    mode_index: m,
                    tari: 0,
                    ..Default::default()
                }),
                c1g2_singulation_control: self.session.map(|s| C1g2SingulationControl {
                    session: s,
                    tag_population: 32,
                    tag_transit_time: 0,
                    ..Default::default()
                }),
                custom: self
                    .search_mode
                    .map(|m| {
                        Custom::ImpinjInventorySearchMode(ImpinjInventorySearchMode {
                            inventory_search_mode: m,
                            ..Default::default()
                        })
                    })
                    .into_iter()
                    .collect(),
                ..Default::default()
            };
            spec = spec.with_antenna_configuration(
                ids.into_iter()
                    .map(|antenna_id| AntennaConfiguration {
                        antenna_id,
                        c1g2_inventory_command: vec![command.clone()],
                        ..Default::default()
                    })
                    .collect(),
            );
        }
        spec
    }

    /// Checks the spec against the reader's capabilities: antennas it has, an RF mode in its
    /// mode table. Capabilities the reader does not report are not checked.
    pub fn check(&self, caps: &GetReaderCapabilitiesResponse) -> Result<(), ClientError> {
        if let Some(g) = &caps.general_device_capabilities {
            let n = g.max_number_of_antenna_supported;
            if let Some(a) = self.antennas.iter().find(|&&a| a == 0 || a > n) {
                return Err(ClientError::Unsupported(format!(
                    "antenna {a}: the reader has antennas 1..={n}"
                )));
            }
        }
        let modes: Vec<u32> = caps
            .regulatory_capabilities
            .iter()
            .flat_map(|r| r.uhf_band_capabilities.iter())
            .flat_map(|u| u.c1g2_uhf_rf_mode_table.iter())
            .flat_map(|t| t.entries.iter().map(|e| e.mode_identifier))
            .collect();
        if let Some(m) = self.mode {
            if !modes.is_empty() && !modes.contains(&u32::from(m)) {
                let list: Vec<String> = modes.iter().map(u32::to_string).collect();
                return Err(ClientError::Unsupported(format!(
                    "RF mode {m} is not in the reader's mode table ({})",
                    list.join(", ")
                )));
            }
        }
        Ok(())
    }
}

/// UTC now in µs since the Unix epoch (0 if the clock is before it).
pub fn utc_now_us() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_micros() as u64)
        .unwrap_or(0)
}

/// A running inventory on one connection: its reports as typed [`Read`]s, its keepalives
/// answered, and its channel frequencies from the hop table the reader itself advertises.
pub struct ReadStream {
    client: Client,
    decoder: ReadDecoder,
    rospec_id: u32,
    /// RO_ACCESS_REPORTs that did not decode (skipped).
    bad_reports: u64,
}

impl ReadStream {
    /// Sets up `spec` on a connected `client` (each request within `timeout`):
    /// capabilities (the hop table, and [`InventorySpec::check`]), SET_READER_CONFIG (the
    /// keepalive), IMPINJ_ENABLE_EXTENSIONS when asked, DELETE_ROSPEC 0 (whatever an earlier
    /// client left; a reader without any may say so), ADD_ROSPEC, ENABLE_ROSPEC and
    /// START_ROSPEC. Reads are labelled with `reader`.
    pub async fn start(
        mut client: Client,
        spec: &InventorySpec,
        reader: Option<String>,
        timeout: Duration,
    ) -> Result<ReadStream, ClientError> {
        client.answer_keepalives(true);
        let caps = client.capabilities(timeout).await?;
        spec.check(&caps)?;
        let antenna_count = caps
            .general_device_capabilities
            .as_ref()
            .map_or(1, |g| g.max_number_of_antenna_supported);
        let mut decoder = ReadDecoder::new(reader);
        decoder.observe(&Message::new(0, caps));
        client.check(spec.reader_config(), timeout).await?;
        if spec.impinj {
            client.enable_impinj_extensions(timeout).await?;
        }
        match client.delete_rospec(0, timeout).await {
            // No ROSpec to delete is not an error here (some readers answer with one).
            Ok(()) | Err(ClientError::Status { .. }) => {}
            Err(e) => return Err(e),
        }
        client
            .add_rospec(spec.rospec(antenna_count), timeout)
            .await?;
        client.enable_rospec(spec.rospec_id, timeout).await?;
        client.start_rospec(spec.rospec_id, timeout).await?;
        Ok(ReadStream {
            client,
            decoder,
            rospec_id: spec.rospec_id,
            bad_reports: 0,
        })
    }

    /// Waits at most `timeout` for the next frame and appends its reads to `out` (none for
    /// frames other than RO_ACCESS_REPORT). `Err(Timeout)` if nothing came; `Err(Closed)`
    /// once the reader closed the connection, or announced it with a ConnectionCloseEvent.
    pub async fn next(
        &mut self,
        timeout: Duration,
        out: &mut Vec<Read>,
    ) -> Result<(), ClientError> {
        let frame = self.client.recv_frame(timeout).await?;
        let Some(h) = llrp::FrameHeader::peek(&frame) else {
            return Ok(());
        };
        if h.msg_type == llrp::message::ReaderEventNotification::TYPE {
            if let Ok(m) = Message::decode(&frame) {
                if m.body.is_connection_close() {
                    return Err(ClientError::Closed);
                }
            }
            return Ok(());
        }
        if self.decoder.frame(&frame, utc_now_us(), out).is_err() {
            self.bad_reports += 1;
        }
        Ok(())
    }

    /// The hop table the reads' frequencies come from (the reader's), if it advertised one.
    pub fn hop_table(&self) -> Option<&llrp::units::HopTable> {
        self.decoder.hop_table()
    }

    /// KEEPALIVEs answered on this connection.
    pub fn keepalives_answered(&self) -> u64 {
        self.client.keepalives_answered()
    }

    /// RO_ACCESS_REPORTs skipped because they did not decode.
    pub fn bad_reports(&self) -> u64 {
        self.bad_reports
    }

    /// Ends the inventory cleanly: STOP_ROSPEC and DELETE_ROSPEC (their failures ignored:
    /// the reader may have ended the spec itself), then CLOSE_CONNECTION and the reader's
    /// close, all within `timeout`. The reads the reader sends on the way (the report "at the
    /// end of the ROSpec" of reads not yet reported) are appended to `out`.
    pub async fn finish(
        mut self,
        timeout: Duration,
        out: &mut Vec<Read>,
    ) -> Result<(), ClientError> {
        let deadline = tokio::time::Instant::now() + timeout;
        let left = || deadline.saturating_duration_since(tokio::time::Instant::now());
        for stop in [true, false] {
            let r = if stop {
                self.client.stop_rospec(self.rospec_id, left()).await
            } else {
                // Answered after everything the reader sent on stopping.
                self.client.delete_rospec(self.rospec_id, left()).await
            };
            match r {
                Ok(()) | Err(ClientError::Status { .. }) => {}
                Err(e) => return Err(e),
            }
        }
        for m in self.client.drain_pending() {
            if matches!(m.body, MessageBody::RoAccessReport(_))
                && self
                    .decoder
                    .frame(&m.to_bytes(), utc_now_us(), out)
                    .is_err()
            {
                self.bad_reports += 1;
            }
        }
        self.client.close_connection(left()).await
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use llrp::params::SpecParameter;

    fn ms(v: u64) -> Duration {
        Duration::from_millis(v)
    }

    #[test]
    fn the_backoff_doubles_up_to_its_cap_and_stops_after_the_retries() {
        let mut b = Backoff::new(ms(100), ms(1000), Some(6));
        let delays: Vec<_> = std::iter::from_fn(|| b.next_delay()).collect();
        assert_eq!(
            delays,
            [ms(100), ms(200), ms(400), ms(800), ms(1000), ms(1000)]
        );
        assert_eq!(b.next_delay(), None, "still none after the last retry");
        b.reset();
        assert_eq!(b.next_delay(), Some(ms(100)), "a success starts it over");
    }

    #[test]
    fn an_unlimited_backoff_keeps_its_cap() {
        let mut b = Backoff::new(ms(500), ms(30_000), None);
        let last = (0..1000).map(|_| b.next_delay()).last().flatten();
        assert_eq!(last, Some(ms(30_000)));
        let mut zero = Backoff::new(ms(50), ms(10), Some(0));
        assert_eq!(
            zero.next_delay(),
            None,
            "no retries: the first failure is the last"
        );
    }

    #[test]
    fn the_rospec_carries_the_settings_per_antenna() {
        let spec = InventorySpec {
            antennas: vec![1, 3],
            impinj: true,
            report_every: 7,
            session: Some(1),
            search_mode: Some(2),
            mode: Some(1002),
            ..Default::default()
        };
        let ro = spec.rospec(4);
        let report = ro.ro_report_spec.as_ref().expect("a report spec");
        assert_eq!(report.n, 7);
        assert_eq!(report.custom.len(), 1, "the Impinj selector");
        let SpecParameter::AiSpec(ai) = &ro.specs[0] else {
            panic!("an AISpec first");
        };
        assert_eq!(ai.antenna_ids, [1, 3]);
        let configs = &ai.inventory_parameter_specs[0].antenna_configuration;
        assert_eq!(
            configs.iter().map(|c| c.antenna_id).collect::<Vec<_>>(),
            [1, 3]
        );
        let cmd = &configs[1].c1g2_inventory_command[0];
        assert_eq!(
            cmd.c1g2_rf_control.as_ref().map(|r| r.mode_index),
            Some(1002)
        );
        assert_eq!(
            cmd.c1g2_singulation_control.as_ref().map(|s| s.session),
            Some(1)
        );
        assert!(matches!(
            &cmd.custom[..],
            [Custom::ImpinjInventorySearchMode(m)] if m.inventory_search_mode == 2
        ));
        // All antennas: one configuration per antenna the reader has.
        let all = InventorySpec {
            session: Some(0),
            ..Default::default()
        }
        .rospec(4);
        let SpecParameter::AiSpec(ai) = &all.specs[0] else {
            panic!("an AISpec first");
        };
        assert_eq!(ai.antenna_ids, [0]);
        assert_eq!(
            ai.inventory_parameter_specs[0].antenna_configuration.len(),
            4
        );
        // No Gen2 setting: the reader's own, no configuration sent.
        let plain = InventorySpec::default().rospec(4);
        let SpecParameter::AiSpec(ai) = &plain.specs[0] else {
            panic!("an AISpec first");
        };
        assert!(ai.inventory_parameter_specs[0]
            .antenna_configuration
            .is_empty());
        assert!(plain.ro_report_spec.expect("report spec").custom.is_empty());
    }

    #[test]
    fn a_failure_status_names_code_description_and_field() {
        let mut status = LlrpStatus::new(llrp::StatusCode::M_ParameterError, "bad mode");
        let mut pe = llrp::params::ParameterError::new(177, llrp::StatusCode::P_ParameterError);
        let mut inner = llrp::params::ParameterError::new(335, llrp::StatusCode::P_FieldError);
        inner.field_error = Some(llrp::params::FieldError {
            field_num: 0,
            error_code: llrp::StatusCode::A_OutOfRange,
            ..Default::default()
        });
        pe.parameter_error = Some(Box::new(inner));
        status.parameter_error = Some(pe);
        let text = describe_status(&status);
        assert!(text.contains("bad mode"), "{text}");
        assert!(text.contains("177/335"), "{text}");
        assert!(text.contains("field 0"), "{text}");
    }
}
