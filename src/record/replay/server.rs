//! The replay as a server's session, sans IO: one client at a time gets a [`ReplaySession`]
//! of the script; a second is refused as a reader refuses it (a READER_EVENT_NOTIFICATION
//! with FailedClientInitiatedConnectionExists, then close); a stream that is not LLRP gets
//! ERROR_MESSAGE, then close. The application's serve loop (`net::drive`) runs it.

use std::sync::Arc;

use bytes::BytesMut;
use llrp::enums::ConnectionAttemptStatus;
use llrp::message::{ErrorMessage, ReaderEventNotification};
use llrp::params::LlrpStatus;
use llrp::{Inbound, Message, StatusCode};
use llrp_gateway_vocab::session::{Accepted, ClientId, ServerSession, Transmit};

use super::{ReplayOptions, ReplaySession, Script};

/// Bytes a session moves to its output in one advance; its driver waits for the client to
/// take about this much before it runs the session again.
pub const BACKLOG_BYTES: usize = 256 * 1024;

/// The replay's time: a monotonic clock for the script's offsets, and the wall clock for the
/// timestamp of a refusal.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ReplayNow {
    /// Monotonic µs (any origin).
    pub us: u64,
    /// UTC µs.
    pub utc_us: u64,
}

/// A recording's connection served as a reader, to one client at a time.
#[derive(Debug)]
pub struct ReplayServer {
    script: Arc<Script>,
    options: ReplayOptions,
    client: Option<(ClientId, ReplaySession)>,
    next: ClientId,
}

impl ReplayServer {
    /// Serves `script` with `options`; no client yet.
    pub fn new(script: Arc<Script>, options: ReplayOptions) -> Self {
        ReplayServer {
            script,
            options,
            client: None,
            next: ClientId::FIRST,
        }
    }

    /// The script served.
    pub fn script(&self) -> &Script {
        &self.script
    }

    /// Whether a client is connected.
    pub fn connected(&self) -> bool {
        self.client.is_some()
    }
}

/// What a reader tells a second client: a READER_EVENT_NOTIFICATION with
/// FailedClientInitiatedConnectionExists, stamped `utc_us`.
pub fn refusal(utc_us: u64) -> BytesMut {
    let body = ReaderEventNotification::connection_attempt(
        ConnectionAttemptStatus::FailedClientInitiatedConnectionExists,
        utc_us,
    );
    Message::new(0, body).to_bytes()
}

impl ServerSession for ReplayServer {
    type Now = ReplayNow;
    type Deadline = Option<u64>;

    fn connect(&mut self, now: ReplayNow) -> Accepted {
        if self.client.is_some() {
            return Accepted::Refused(refusal(now.utc_us));
        }
        let id = self.next;
        self.next = id.next();
        let session = ReplaySession::new(Arc::clone(&self.script), self.options, now.us);
        self.client = Some((id, session));
        Accepted::Client(id)
    }

    fn receive(&mut self, id: ClientId, inbound: Inbound, now: ReplayNow) {
        let Some((_, s)) = self
            .client
            .as_mut()
            .filter(|(c, s)| *c == id && !s.closing())
        else {
            return;
        };
        match inbound {
            Inbound::Frame(frame) => s.receive(&frame, now.us),
            Inbound::Unsynced(e) => {
                // As a reader does: ERROR_MESSAGE, then close.
                tracing::info!("the client's stream is not LLRP: {e}");
                let m = Message::new(
                    0,
                    ErrorMessage {
                        llrp_status: LlrpStatus::new(StatusCode::M_FieldError, e.to_string()),
                        ..Default::default()
                    },
                );
                let out = s.transmit();
                m.encode(&mut out.bytes);
                out.close = true;
            }
        }
    }

    fn advance(&mut self, now: ReplayNow) {
        match &mut self.client {
            Some((_, s)) if !s.closing() => s.advance(now.us, BACKLOG_BYTES),
            _ => {}
        }
    }

    fn transmit(&mut self) -> Option<Transmit<'_>> {
        let (to, s) = self.client.as_mut()?;
        let out = s.transmit();
        if out.bytes.is_empty() && !out.close {
            return None;
        }
        Some(Transmit {
            to: *to,
            bytes: &mut out.bytes,
            close: out.close,
        })
    }

    fn pending(&self) -> usize {
        self.client.as_ref().map_or(0, |(_, s)| s.out.bytes.len())
    }

    fn deadline(&self) -> Option<u64> {
        // A closing session sends nothing more.
        self.client
            .as_ref()
            .filter(|(_, s)| !s.closing())
            .and_then(|(_, s)| s.deadline())
    }

    fn disconnect(&mut self, id: ClientId) {
        if self.client.as_ref().is_some_and(|(c, _)| *c == id) {
            self.client = None;
        }
    }

    fn shutdown(&mut self) {
        if let Some((_, s)) = &mut self.client {
            s.transmit().close = true;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use llrp::message::MessageBody;

    const OPTIONS: ReplayOptions = ReplayOptions {
        speed: Some(1.0),
        looped: false,
    };

    fn script() -> Arc<Script> {
        Arc::new(super::super::tests::script_for_server())
    }

    fn e2() -> llrp::FrameError {
        llrp::FrameError::TooShort {
            len: 2,
            msg_type: 3,
            id: 1,
        }
    }

    fn now(us: u64) -> ReplayNow {
        ReplayNow {
            us,
            utc_us: 1_700_000_000_000_000 + us,
        }
    }

    #[test]
    fn a_second_client_is_refused_as_a_reader_refuses_and_the_first_is_served_on() {
        let mut s = ReplayServer::new(script(), OPTIONS);
        let Accepted::Client(first) = s.connect(now(0)) else {
            panic!("the first client is taken");
        };
        let Accepted::Refused(bytes) = s.connect(now(1)) else {
            panic!("a second client is refused");
        };
        let m = Message::decode(&bytes).expect("the refusal decodes");
        let MessageBody::ReaderEventNotification(n) = m.body else {
            panic!("a READER_EVENT_NOTIFICATION: {m:?}");
        };
        let status = n
            .reader_event_notification_data
            .connection_attempt_event
            .map(|e| e.status);
        assert_eq!(
            status,
            Some(ConnectionAttemptStatus::FailedClientInitiatedConnectionExists)
        );
        // Once the first is gone, the next is taken.
        s.disconnect(first);
        assert!(matches!(s.connect(now(2)), Accepted::Client(_)));
    }

    #[test]
    fn a_stream_that_is_not_llrp_gets_error_message_then_close() {
        let mut s = ReplayServer::new(script(), OPTIONS);
        let Accepted::Client(id) = s.connect(now(0)) else {
            panic!("the first client is taken");
        };
        let e = llrp::FrameError::TooShort {
            len: 3,
            msg_type: 3,
            id: 9,
        };
        s.receive(id, Inbound::Unsynced(e), now(1));
        let t = s.transmit().expect("something to send");
        assert!(t.close, "the connection closes");
        let m = Message::decode(t.bytes).expect("decodes");
        let sent = t.bytes.len();
        assert!(
            matches!(&m.body, MessageBody::ErrorMessage(e) if e.llrp_status.status_code == StatusCode::M_FieldError),
            "{m:?}"
        );
        // After the close nothing more is taken, and nothing falls due (the greeting was).
        s.receive(id, Inbound::Unsynced(e2()), now(2));
        s.advance(now(10_000));
        assert_eq!(s.pending(), sent);
        assert_eq!(s.deadline(), None);
    }
}
