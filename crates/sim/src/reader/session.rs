//! A simulated reader's session, sans IO: the connections that come and go, the frames they
//! bring, and the time that passes, in; the bytes to send, whether to close, and when to be
//! woken next, out. The socket layer (`net::server`) only moves bytes and sleeps until
//! [`ServerSession::deadline`]; tests drive a session with a virtual clock and no sockets.
//!
//! Every LLRP decision is here or in [`Reader`]: a second client is refused with the
//! ConnectionAttemptEvent a reader sends (and the connected one is told), a frame that does
//! not decode gets its response type or ERROR_MESSAGE, an unsupported version gets
//! M_UnsupportedVersion, a length field that cannot be resynchronised gets ERROR_MESSAGE and
//! the connection closes, and a shutting-down reader says ConnectionCloseEvent first.

use bytes::BytesMut;
use llrp::params::LlrpStatus;
use llrp::{FrameError, FrameHeader, Inbound, Message, StatusCode};

use llrp::enums::ConnectionAttemptStatus;

use super::{Output, Reader};

mod faults;

pub use llrp_gateway_vocab::session::{Accepted, ClientId, ServerSession, Transmit};

/// While an ROSpec runs, the longest a session lets simulated time pass without running the
/// reader (reports of the reads in between leave at most this late), µs.
pub const REPORT_LATENCY_US: u64 = 10_000;

/// The times a session sees: simulated time (inventory, reports) and wall-clock time
/// (keepalives, which run on the client's clock whatever the simulation speed).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Now {
    /// Simulated time, µs.
    pub sim_us: u64,
    /// Wall-clock time since the simulation started, ms.
    pub wall_ms: u64,
}

/// When a session next needs to run, if nothing arrives before.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Deadline {
    /// Simulated time at which something falls due, µs.
    pub sim_us: Option<u64>,
    /// Wall-clock time at which a keepalive falls due, ms.
    pub wall_ms: Option<u64>,
}

/// One simulated reader's LLRP session: the reader, and the client connected to it.
pub struct Session {
    reader: Reader,
    client: Option<ClientId>,
    next_client: ClientId,
    out: BytesMut,
    close: bool,
    /// Simulated time the reader last ran to while an ROSpec was active.
    ran_to_us: u64,
    /// The faults in force on the session's side, and those to come.
    faults: faults::Faults,
}

impl Session {
    /// A session for `reader`, no client connected.
    pub fn new(reader: Reader) -> Self {
        let timeline = super::faults::Timeline::new(&reader.profile().faults);
        let faults = faults::Faults::new(timeline, usize::from(reader.profile().antennas));
        Session {
            faults,
            reader,
            client: None,
            next_client: ClientId::FIRST,
            // Grows to what the client is sent between two flushes (a fleet of idle readers
            // holds next to nothing).
            out: BytesMut::new(),
            close: false,
            ran_to_us: 0,
        }
    }

    /// The reader behind the session.
    pub fn reader(&self) -> &Reader {
        &self.reader
    }

    /// The reader behind the session, for configuration before it serves.
    pub fn reader_mut(&mut self) -> &mut Reader {
        &mut self.reader
    }

    /// The connected client, if any.
    pub fn client(&self) -> Option<ClientId> {
        self.client
    }

    fn frame(&mut self, frame: &[u8], now: Now) {
        let Some(h) = FrameHeader::peek(frame) else {
            return; // a connection yields whole frames only
        };
        if h.version != llrp::frame::VERSION_1_0_1 && h.version != llrp::frame::VERSION_1_1 {
            Reader::unsupported_version(&h).encode(&mut self.out);
            return;
        }
        let outputs = match Message::decode(frame) {
            Ok(m) => {
                tracing::debug!(message = m.name(), id = m.id, "request");
                self.reader.handle(m, now.sim_us, now.wall_ms)
            }
            Err(e) => {
                // A client's mistake: answered on the wire, logged quietly.
                tracing::info!(
                    "malformed {}: {e}",
                    llrp::message::message_name(h.msg_type, frame)
                );
                vec![Output::Send(self.reader.reject(&h, frame, &e))]
            }
        };
        self.push(outputs);
    }

    /// Pushes `outputs` for the client, if one is connected and not being closed.
    fn push_live(&mut self, outputs: Vec<Output>) {
        if self.client.is_some() && !self.close {
            self.push(outputs);
        }
    }

    /// What the client sent, taken now.
    fn take(&mut self, inbound: Inbound, now: Now) {
        match inbound {
            Inbound::Frame(frame) => self.frame(&frame, now),
            Inbound::Unsynced(e) => {
                tracing::info!("unrecoverable framing error: {e}");
                bad_length(&e).encode(&mut self.out);
                self.close = true;
            }
        }
    }

    /// Runs the reader up to `now` (without a client, its GPI lines alone).
    fn run_reader(&mut self, now: Now) {
        if self.client.is_none() {
            self.reader.advance(now.sim_us, now.wall_ms);
            return;
        }
        if self.close {
            return;
        }
        let outputs = self.reader.advance(now.sim_us, now.wall_ms);
        self.ran_to_us = self.reader.now_us();
        self.push(outputs);
    }

    fn push(&mut self, outputs: Vec<Output>) {
        for o in outputs {
            match o {
                Output::Send(m) => m.encode(&mut self.out),
                Output::Close => {
                    self.close = true;
                    return;
                }
            }
        }
    }
}

impl ServerSession for Session {
    type Now = Now;
    type Deadline = Deadline;

    /// A connection arrived at `now`.
    fn connect(&mut self, now: Now) -> Accepted {
        if !self.listening() {
            // Rebooting: nothing answers (the server stops listening meanwhile).
            return Accepted::Refused(BytesMut::new());
        }
        if self.client.is_some() {
            let refusal = self
                .reader
                .connection_event(ConnectionAttemptStatus::FailedClientInitiatedConnectionExists);
            let notice = self
                .reader
                .connection_event(ConnectionAttemptStatus::AnotherConnectionAttempted);
            notice.encode(&mut self.out);
            return Accepted::Refused(refusal.to_bytes());
        }
        let id = self.next_client;
        self.next_client = id.next();
        self.client = Some(id);
        self.out.clear();
        self.close = false;
        let greeting = self.reader.connect(now.sim_us, now.wall_ms);
        self.ran_to_us = self.reader.now_us();
        self.push(greeting);
        Accepted::Client(id)
    }

    /// Connection `id` is gone (closed by the peer, or after the session asked to close it).
    fn disconnect(&mut self, id: ClientId) {
        if self.client == Some(id) {
            self.client = None;
            self.out.clear();
            self.close = false;
            self.faults.disconnected();
            self.reader.disconnect();
        }
    }

    /// What connection `id` received, at `now`.
    fn receive(&mut self, id: ClientId, inbound: Inbound, now: Now) {
        if self.client != Some(id) || self.close {
            return;
        }
        if self.delaying(now) {
            self.hold(inbound, now);
        } else {
            self.take(inbound, now);
        }
    }

    /// Runs the reader up to `now`: faults, inventory, reports, events, GPI changes and
    /// keepalives that fall due (without a client, the faults and GPI lines alone).
    fn advance(&mut self, now: Now) {
        self.run_faults(now);
        self.run_reader(now);
    }

    /// The reader is shutting down: the client is told (ConnectionCloseEvent) and closed.
    fn shutdown(&mut self) {
        if self.client.is_some() && !self.close {
            self.reader.close_event().encode(&mut self.out);
            self.close = true;
        }
    }

    /// What to send to the connected client now, if anything.
    fn transmit(&mut self) -> Option<Transmit<'_>> {
        let to = self.client?;
        if self.out.is_empty() && !self.close {
            return None;
        }
        Some(Transmit {
            to,
            bytes: &mut self.out,
            close: self.close,
        })
    }

    /// Bytes waiting for the connected client.
    fn pending(&self) -> usize {
        self.out.len()
    }

    /// When the session next needs [`ServerSession::advance`], if nothing arrives before: the next
    /// trigger or antenna slice while an ROSpec runs (at most [`REPORT_LATENCY_US`] ahead),
    /// the next GPI change, the next keepalive, or never (without a client: the next GPI
    /// change, so the lines' state stays current).
    fn deadline(&self) -> Deadline {
        if self.close {
            return Deadline::default();
        }
        let fault = self.faults.timeline.next_at();
        if self.client.is_none() {
            let after = self.reader.now_us().max(self.ran_to_us) + 1;
            return Deadline {
                sim_us: earliest(self.reader.next_gpi_us(), fault).map(|t| t.max(after)),
                wall_ms: self.faults.wall_deadline(),
            };
        }
        let mut sim = earliest(self.reader.next_deadline_us(), fault);
        if self.reader.inventorying() {
            let soon = self.ran_to_us + REPORT_LATENCY_US;
            sim = Some(sim.map_or(soon, |t| t.min(soon)));
        }
        Deadline {
            // Never at or before the time already run to (that would wake the driver for
            // nothing, over and over).
            sim_us: sim.map(|t| t.max(self.ran_to_us + 1)),
            wall_ms: earliest(self.reader.next_keepalive_ms(), self.faults.wall_deadline()),
        }
    }
}

/// The earlier of two times, either of which may be none.
fn earliest(a: Option<u64>, b: Option<u64>) -> Option<u64> {
    match (a, b) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    }
}

/// ERROR_MESSAGE for a frame whose length field cannot be right.
fn bad_length(e: &FrameError) -> Message {
    let id = match e {
        FrameError::TooShort { id, .. } | FrameError::TooLong { id, .. } => *id,
        FrameError::UnsupportedVersion(h) => h.id,
    };
    Message::new(
        id,
        llrp::message::ErrorMessage {
            llrp_status: LlrpStatus::new(StatusCode::M_FieldError, e.to_string()),
            ..Default::default()
        },
    )
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use bytes::Bytes;
    use llrp::message::*;
    use llrp::params::*;
    use llrp::{Deframer, MessageBody};

    use super::*;
    use crate::physics::Model;
    use crate::reader::ReaderProfile;
    use crate::scenario::Scenario;

    fn session() -> Session {
        let s = Scenario::default_s1();
        let model = Arc::new(Model::new(&s, 0));
        let profile = ReaderProfile::from_scenario(&s, 0, &model);
        Session::new(Reader::new(profile, model, 1_700_000_000_000_000))
    }

    fn at(sim_us: u64, wall_ms: u64) -> Now {
        Now { sim_us, wall_ms }
    }

    fn client(s: &mut Session, now: Now) -> ClientId {
        match s.connect(now) {
            Accepted::Client(id) => id,
            Accepted::Refused(_) => panic!("the first client is accepted"),
        }
    }

    /// Decodes every message in `bytes`.
    fn messages(bytes: &[u8]) -> Vec<Message> {
        let mut d = Deframer::default();
        d.buffer_mut().extend_from_slice(bytes);
        let mut out = Vec::new();
        while let Some(Inbound::Frame(f)) = d.next_frame() {
            out.push(Message::decode(&f).expect("the session sends valid LLRP"));
        }
        assert_eq!(d.buffered(), 0, "whole frames only");
        out
    }

    /// What the session has for its client, taken; and whether it asked to close.
    fn take(s: &mut Session) -> (Vec<Message>, bool) {
        match s.transmit() {
            Some(t) => {
                let m = messages(t.bytes);
                t.bytes.clear();
                (m, t.close)
            }
            None => (Vec::new(), false),
        }
    }

    fn frame(m: impl Into<MessageBody>, id: u32) -> Inbound {
        Inbound::Frame(Message::new(id, m).to_bytes().freeze())
    }

    fn attempt_status(m: &Message) -> Option<ConnectionAttemptStatus> {
        m.body.connection_attempt()
    }

    #[test]
    fn a_second_client_is_refused_and_the_first_is_told() {
        let mut s = session();
        let first = client(&mut s, at(0, 0));
        let (greeting, close) = take(&mut s);
        assert_eq!(
            greeting.iter().map(attempt_status).collect::<Vec<_>>(),
            [Some(ConnectionAttemptStatus::Success)]
        );
        assert!(!close);
        let Accepted::Refused(refusal) = s.connect(at(10, 0)) else {
            panic!("a second client is refused");
        };
        let refusal = messages(&refusal);
        assert_eq!(
            refusal.iter().map(attempt_status).collect::<Vec<_>>(),
            [Some(
                ConnectionAttemptStatus::FailedClientInitiatedConnectionExists
            )]
        );
        let (notice, close) = take(&mut s);
        assert_eq!(
            notice.iter().map(attempt_status).collect::<Vec<_>>(),
            [Some(ConnectionAttemptStatus::AnotherConnectionAttempted)]
        );
        assert!(!close, "the connected client carries on");
        // It still gets answers; once it is gone, the next client is accepted.
        s.receive(first, frame(GetRospecs::default(), 5), at(20, 0));
        let (answer, _) = take(&mut s);
        assert_eq!(
            (answer[0].name(), answer[0].id),
            ("GET_ROSPECS_RESPONSE", 5)
        );
        s.disconnect(first);
        assert!(matches!(s.connect(at(30, 0)), Accepted::Client(_)));
    }

    #[test]
    fn a_length_that_cannot_be_resynchronised_gets_error_message_then_close() {
        let mut s = session();
        let c = client(&mut s, at(0, 0));
        take(&mut s);
        let mut d = Deframer::default();
        d.buffer_mut()
            .extend_from_slice(&[0x04, 0x01, 0, 0, 0, 3, 0, 0, 0, 77]);
        let inbound = d.next_frame().expect("an unsynced stream");
        s.receive(c, inbound, at(0, 0));
        let (out, close) = take(&mut s);
        assert!(close);
        assert_eq!(
            (out.len(), out[0].name(), out[0].id),
            (1, "ERROR_MESSAGE", 77)
        );
        assert_eq!(
            out[0].body.status().map(|st| st.status_code),
            Some(StatusCode::M_FieldError)
        );
        // Nothing more is taken from that connection.
        s.receive(c, frame(GetRospecs::default(), 6), at(0, 0));
        assert_eq!(s.pending(), 0);
    }

    #[test]
    fn an_unsupported_version_gets_error_message_echoing_version_and_id() {
        let mut s = session();
        let c = client(&mut s, at(0, 0));
        take(&mut s);
        let mut f = Message::new(12, GetRospecs::default()).to_bytes();
        f[0] = (f[0] & 0xE3) | (4 << 2);
        s.receive(c, Inbound::Frame(f.freeze()), at(0, 0));
        let t = s.transmit().expect("an answer");
        let h = llrp::FrameHeader::peek(t.bytes).expect("a header");
        assert_eq!((h.version, h.msg_type, h.id), (4, 100, 12));
        assert!(!t.close, "the connection carries on");
    }

    #[test]
    fn a_malformed_request_gets_its_response_type_with_the_decoders_status() {
        let mut s = session();
        let c = client(&mut s, at(0, 0));
        take(&mut s);
        // ADD_ROSPEC whose ROSpec parameter is cut short.
        let f = Bytes::from_static(&[0x04, 0x14, 0, 0, 0, 14, 0, 0, 0, 3, 0x00, 0xB1, 0, 40]);
        s.receive(c, Inbound::Frame(f), at(0, 0));
        let (out, close) = take(&mut s);
        assert!(!close);
        assert_eq!((out[0].name(), out[0].id), ("ADD_ROSPEC_RESPONSE", 3));
        assert!(!out[0].body.status().expect("a status").is_success());
    }

    #[test]
    fn an_idle_session_needs_no_wake_up_and_shutdown_says_connection_close() {
        let mut s = session();
        assert_eq!(
            s.deadline(),
            Deadline::default(),
            "no client: nothing to do"
        );
        let c = client(&mut s, at(0, 0));
        take(&mut s);
        assert_eq!(s.deadline(), Deadline::default(), "no ROSpec, no keepalive");
        // A periodic keepalive is a wall-clock deadline.
        let set = SetReaderConfig {
            keepalive_spec: Some(KeepaliveSpec {
                keepalive_trigger_type: llrp::enums::KeepaliveTriggerType::Periodic,
                periodic_trigger_value: 3000,
                ..Default::default()
            }),
            ..Default::default()
        };
        s.receive(c, frame(set, 1), at(0, 500));
        let (out, _) = take(&mut s);
        assert!(out[0].body.status().expect("a status").is_success());
        assert_eq!(s.deadline().wall_ms, Some(3500));
        s.advance(at(1_000, 3500));
        let (out, _) = take(&mut s);
        assert_eq!(
            out.iter().map(|m| m.name()).collect::<Vec<_>>(),
            ["KEEPALIVE"]
        );
        assert_eq!(s.deadline().wall_ms, Some(6500));

        s.shutdown();
        let (out, close) = take(&mut s);
        assert!(close);
        match &out[..] {
            [m] => assert!(m.body.is_connection_close(), "{m:?}"),
            other => panic!("expected one message, got {other:?}"),
        }
        assert_eq!(s.deadline(), Deadline::default());
    }

    #[test]
    fn a_running_rospec_sets_a_simulated_deadline_within_the_report_latency() {
        let mut s = session();
        let c = client(&mut s, at(0, 0));
        take(&mut s);
        let spec = RoSpec::immediate(1, vec![0]);
        s.receive(
            c,
            frame(
                AddRospec {
                    ro_spec: spec,
                    ..Default::default()
                },
                1,
            ),
            at(0, 0),
        );
        s.receive(
            c,
            frame(
                EnableRospec {
                    ro_spec_id: 1,
                    ..Default::default()
                },
                2,
            ),
            at(0, 0),
        );
        take(&mut s);
        s.advance(at(1_000, 1));
        assert!(s.reader().inventorying());
        let d = s
            .deadline()
            .sim_us
            .expect("a running ROSpec has a deadline");
        assert!(d > 1_000 && d <= 1_000 + REPORT_LATENCY_US, "{d}");
        s.disconnect(c);
        assert_eq!(
            s.deadline(),
            Deadline::default(),
            "no inventory without a client"
        );
    }
}
