//! A simulated reader's session driven in process with a virtual clock: requests go in as
//! frames, time passes only when a test says so (stepping from deadline to deadline, as the
//! socket layer sleeps), and what the session sends is decoded into an inbox. Deterministic
//! and fast: no sockets, no sleeps.

use std::collections::VecDeque;
use std::sync::Arc;

use llrp::message::MessageBody;
use llrp::params::TagReportData;
use llrp::{Deframer, Inbound, Message, StatusCode};
use llrp_gateway::physics::Model;
use llrp_gateway::reader::session::{Accepted, ClientId, Now, ServerSession, Session};
use llrp_gateway::reader::{Reader, ReaderProfile};
use llrp_gateway::scenario::Scenario;

/// UTC of simulated time 0 in every virtual reader (so two runs give the same bytes).
pub const UTC_EPOCH_US: u64 = 1_700_000_000_000_000;

/// Reader 0 of a scenario, a client connected to it, and a virtual clock.
pub struct VirtualReader {
    session: Session,
    now: Now,
    client: Option<ClientId>,
    inbox: VecDeque<Message>,
    closed: bool,
    /// Whether the reader's last close was a reset (the connection dropped).
    reset: bool,
    next_id: u32,
    /// The LLRP version the client's messages carry (1 = 1.0.1, 2 = 1.1).
    version: u8,
}

impl VirtualReader {
    /// Reader 0 of `scenario` at simulated time 0, with a client connected (its greeting is
    /// in the inbox).
    pub fn new(scenario: &Scenario) -> Self {
        let model = Arc::new(Model::new(scenario, 0));
        let profile = ReaderProfile::from_scenario(scenario, 0, &model);
        let mut v = VirtualReader {
            session: Session::new(Reader::new(profile, model, UTC_EPOCH_US)),
            now: Now::default(),
            client: None,
            inbox: VecDeque::new(),
            closed: false,
            reset: false,
            next_id: 1,
            version: 1,
        };
        v.connect();
        v
    }

    /// The session behind it.
    pub fn session(&self) -> &Session {
        &self.session
    }

    /// Virtual simulated time, µs.
    pub fn now_us(&self) -> u64 {
        self.now.sim_us
    }

    /// A client connects (after a disconnect).
    pub fn connect(&mut self) {
        assert!(self.try_connect(), "a client is already connected");
    }

    /// A client tries to connect: whether the session took it (a refusal's bytes, if any,
    /// are dropped).
    pub fn try_connect(&mut self) -> bool {
        match self.session.connect(self.now) {
            Accepted::Client(id) => self.client = Some(id),
            Accepted::Refused(_) => return false,
        }
        self.closed = false;
        self.reset = false;
        self.collect();
        true
    }

    /// Whether the reader accepts connections now (not while it reboots).
    pub fn listening(&self) -> bool {
        self.session.listening()
    }

    /// Whether the reader's last close was a reset: the connection dropped, nothing more
    /// sent.
    pub fn was_reset(&self) -> bool {
        self.reset
    }

    /// Injects `fault` now, as the HTTP API does (through the session's fault panel), and
    /// lets the reader take it.
    pub fn inject(&mut self, fault: llrp_gateway::reader::faults::Fault) {
        self.session
            .fault_panel()
            .send(fault)
            .expect("a fault that fits the reader");
        self.session.advance(self.now);
        self.collect();
    }

    /// The client goes away.
    pub fn disconnect(&mut self) {
        if let Some(id) = self.client.take() {
            self.session.disconnect(id);
        }
        self.inbox.clear();
    }

    /// Whether the reader has closed the connection.
    pub fn is_closed(&self) -> bool {
        self.closed
    }

    /// Sends a request now; returns its message ID.
    pub fn send(&mut self, body: impl Into<MessageBody>) -> u32 {
        let id = self.next_id;
        self.next_id += 1;
        let mut m = Message::new(id, body);
        m.version = self.version;
        self.send_bytes(&m.to_bytes());
        id
    }

    /// Switches the session to LLRP `version` (SET_PROTOCOL_VERSION, which must succeed);
    /// later messages carry it.
    pub fn set_version(&mut self, version: u8) {
        let set = llrp::message::SetProtocolVersion {
            protocol_version: version,
            ..Default::default()
        };
        assert_eq!(self.status(set), StatusCode::M_Success);
        self.version = version;
    }

    /// Sends raw bytes now (whole frames, or the start of a broken one).
    pub fn send_bytes(&mut self, bytes: &[u8]) {
        let client = self.client.expect("a connected client");
        let mut d = Deframer::default();
        d.buffer_mut().extend_from_slice(bytes);
        while let Some(inbound) = d.next_frame() {
            let unsynced = matches!(inbound, Inbound::Unsynced(_));
            self.session.receive(client, inbound, self.now);
            self.collect();
            if unsynced {
                break;
            }
        }
    }

    /// Sends a request and returns its answer (the reader answers at once; no time passes).
    /// Other messages stay in the inbox.
    pub fn request(&mut self, body: impl Into<MessageBody>) -> Message {
        let id = self.send(body);
        let k = self
            .inbox
            .iter()
            .position(|m| m.id == id && m.body.status().is_some())
            .expect("the reader answers a request at once");
        self.inbox.remove(k).expect("index from position")
    }

    /// Sends a request and returns its answer's status code.
    pub fn status(&mut self, body: impl Into<MessageBody>) -> StatusCode {
        self.request(body)
            .body
            .status()
            .expect("a response")
            .status_code
    }

    /// Adds and enables `spec` (its ID must be free), collects its tag reports until `done`
    /// or `limit_us` of simulated time, then deletes it and drops what else arrived.
    #[allow(dead_code)] // not every test binary runs ROSpecs this way
    pub fn run_rospec(
        &mut self,
        spec: llrp::params::RoSpec,
        limit_us: u64,
        done: impl FnMut(&[TagReportData]) -> bool,
    ) -> Vec<TagReportData> {
        let id = spec.ro_spec_id;
        let add = llrp::message::AddRospec {
            ro_spec: spec,
            ..Default::default()
        };
        assert_eq!(self.status(add), StatusCode::M_Success);
        let enable = llrp::message::EnableRospec {
            ro_spec_id: id,
            ..Default::default()
        };
        assert_eq!(self.status(enable), StatusCode::M_Success);
        let (tags, _) = self.collect_reports(limit_us, done);
        let delete = llrp::message::DeleteRospec {
            ro_spec_id: id,
            ..Default::default()
        };
        assert_eq!(self.status(delete), StatusCode::M_Success);
        self.take();
        tags
    }

    /// Turns on the event notifications of `types` (SET_READER_CONFIG, which must succeed).
    #[allow(dead_code)] // not every test binary asks for events
    pub fn enable_events(&mut self, types: &[llrp::enums::NotificationEventType]) {
        use llrp::params::{EventNotificationState, ReaderEventNotificationSpec};
        let set = llrp::message::SetReaderConfig {
            reader_event_notification_spec: Some(ReaderEventNotificationSpec {
                event_notification_state: types
                    .iter()
                    .map(|&t| EventNotificationState {
                        event_type: t,
                        notification_state: true,
                        ..Default::default()
                    })
                    .collect(),
                ..Default::default()
            }),
            ..Default::default()
        };
        assert_eq!(self.status(set), StatusCode::M_Success);
    }

    /// ADD_ACCESSSPEC then ENABLE_ACCESSSPEC of `access`, each of which must succeed.
    pub fn add_access_spec(&mut self, access: llrp::params::AccessSpec) {
        let id = access.access_spec_id;
        let add = llrp::message::AddAccessspec {
            access_spec: access,
            ..Default::default()
        };
        assert_eq!(self.status(add), StatusCode::M_Success);
        let enable = llrp::message::EnableAccessspec {
            access_spec_id: id,
            ..Default::default()
        };
        assert_eq!(self.status(enable), StatusCode::M_Success);
    }

    /// Sets GPI `port` to `high` now, as the HTTP API does (through the reader's GPIO
    /// panel), and lets the reader take it.
    pub fn set_gpi(&mut self, port: u16, high: bool) {
        self.session
            .reader()
            .gpio_panel()
            .send(llrp_gateway::reader::gpio::Command::Set { port, high })
            .expect("a GPI port the reader has");
        self.session.advance(self.now);
        self.collect();
    }

    /// Moves time to the reader's next deadline (at most `target`) and runs the reader there.
    fn step_toward(&mut self, target: u64) {
        let d = self.session.deadline();
        let wall = d.wall_ms.map(|ms| ms * 1000);
        let next = [d.sim_us, wall, Some(target)]
            .into_iter()
            .flatten()
            .min()
            .unwrap_or(target)
            .clamp(self.now.sim_us + 1, target);
        self.now = Now {
            sim_us: next,
            wall_ms: next / 1000,
        };
        self.session.advance(self.now);
    }

    /// Lets `us` of simulated time pass (wall clock alike), running the reader at each of
    /// its deadlines on the way, as the socket layer does.
    pub fn run_for(&mut self, us: u64) {
        let target = self.now.sim_us + us;
        while self.now.sim_us < target && !self.closed {
            self.step_toward(target);
            self.collect();
        }
    }

    /// Lets `us` of simulated time pass (wall clock alike) without a client, running the
    /// reader at each of its deadlines (a reboot's end, the fault timeline, GPI changes).
    pub fn idle_for(&mut self, us: u64) {
        assert!(
            self.client.is_none(),
            "idle_for is for a reader without a client"
        );
        let target = self.now.sim_us + us;
        while self.now.sim_us < target {
            self.step_toward(target);
        }
    }

    /// Runs (at most `limit_us` of simulated time) until a message satisfying `pred` is in the
    /// inbox, and takes it; other messages stay.
    pub fn run_until(&mut self, limit_us: u64, pred: impl Fn(&Message) -> bool) -> Option<Message> {
        let end = self.now.sim_us + limit_us;
        loop {
            if let Some(k) = self.inbox.iter().position(&pred) {
                return self.inbox.remove(k);
            }
            if self.now.sim_us >= end || self.closed {
                return None;
            }
            let step = (end - self.now.sim_us).min(10_000);
            self.run_for(step);
        }
    }

    /// Collects the TagReportData of every RO_ACCESS_REPORT until `done` says stop or
    /// `limit_us` of simulated time has passed; other messages are returned separately.
    pub fn collect_reports(
        &mut self,
        limit_us: u64,
        mut done: impl FnMut(&[TagReportData]) -> bool,
    ) -> (Vec<TagReportData>, Vec<Message>) {
        let end = self.now.sim_us + limit_us;
        let (mut tags, mut others) = (Vec::new(), Vec::new());
        loop {
            for m in self.inbox.drain(..) {
                match m.body {
                    MessageBody::RoAccessReport(r) => tags.extend(r.tag_report_data),
                    _ => others.push(m),
                }
            }
            if done(&tags) || self.now.sim_us >= end || self.closed {
                return (tags, others);
            }
            self.run_for((end - self.now.sim_us).min(100_000));
        }
    }

    /// The next message, running (at most `limit_us` of simulated time) until one arrives.
    pub fn next_message(&mut self, limit_us: u64) -> Message {
        self.run_until(limit_us, |_| true)
            .expect("a message within the limit")
    }

    /// Takes every message received so far.
    pub fn take(&mut self) -> Vec<Message> {
        self.inbox.drain(..).collect()
    }

    /// Takes every RO_ACCESS_REPORT received so far (other messages stay), one Vec of
    /// TagReportData per report.
    pub fn take_reports(&mut self) -> Vec<Vec<TagReportData>> {
        let mut out = Vec::new();
        self.inbox.retain(|m| match &m.body {
            MessageBody::RoAccessReport(r) => {
                out.push(r.tag_report_data.clone());
                false
            }
            _ => true,
        });
        out
    }

    /// Decodes what the session has for the client into the inbox.
    fn collect(&mut self) {
        let Some(t) = self.session.transmit() else {
            return;
        };
        let mut d = Deframer::default();
        d.buffer_mut().extend_from_slice(t.bytes);
        t.bytes.clear();
        let close = t.close;
        let reset = self.session.abrupt();
        while let Some(Inbound::Frame(f)) = d.next_frame() {
            self.inbox
                .push_back(Message::decode(&f).expect("the reader sends valid LLRP"));
        }
        if close {
            self.closed = true;
            self.reset = reset;
            if let Some(id) = self.client.take() {
                self.session.disconnect(id);
            }
        }
    }
}
