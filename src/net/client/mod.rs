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
//! typed [`Read`](crate::reads::Read)s ([`ReadStream`]), reconnection with the capped exponential
//! [`Backoff`] with jitter (`net::backoff`, shared with the servers and MQTT), and a clean
//! close (CLOSE_CONNECTION, then the reader's close).
//!
//! Here: the errors and [`Client`]; the inventory spec and the read stream are in submodules,
//! re-exported, as is the back-off.

use std::collections::VecDeque;
use std::io;
use std::time::Duration;

use llrp::enums::ConnectionAttemptStatus;
use llrp::impinj::ImpinjEnableExtensions;
use llrp::message::{
    AddRospec, CloseConnection, DeleteRospec, EnableRospec, GetReaderCapabilities,
    GetReaderCapabilitiesResponse, KeepaliveAck, MessageBody, MessageDef, StartRospec, StopRospec,
};
use llrp::params::{LlrpStatus, RoSpec};
use llrp::{Inbound, Message, Request, Response};
use tokio::net::{TcpStream, ToSocketAddrs};

use super::connection::Connection;
use super::tls::{self, Connector};

mod read_stream;
mod spec;

pub use super::backoff::Backoff;
pub use read_stream::ReadStream;
pub use spec::InventorySpec;

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

    /// Drops the queued RO_ACCESS_REPORTs (keeping the other messages in order); the number
    /// of tag reads they held.
    pub fn discard_pending_reports(&mut self) -> usize {
        let mut reads = 0;
        self.pending.retain(|m| match &m.body {
            MessageBody::RoAccessReport(r) => {
                reads += r.tag_report_data.len();
                false
            }
            _ => true,
        });
        reads
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

#[cfg(test)]
mod tests {
    use super::*;

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
