//! The simulated reader's LLRP state machine, sans IO: requests in, responses, reports and
//! events out, driven by a simulated clock. `net::server` feeds it bytes and time; tests can
//! drive it directly; [`session::Session`] adds the connections and the framing around it.
//!
//! It behaves like an Impinj-class reader: the ROSpec and AccessSpec lifecycles, start/stop
//! triggers, report triggers, event notifications, keepalives and the Impinj extensions; its
//! [`device::Device`] sets the identity, tables and extensions it presents.

// An LLRPStatus is the natural error of request handling (it is what goes on the wire); it is
// built only on a client's mistake, so its size on the error path does not matter.
#![allow(clippy::result_large_err)]

mod access;
pub mod caps;
mod config;
pub mod device;
#[cfg(test)]
mod device_tests;
pub mod faults;
pub mod gpio;
mod held;
mod inputs;
pub mod memory;
pub mod memory_file;
pub mod report;
mod requests;
mod rospec;
pub mod select;
pub mod session;
#[cfg(test)]
mod tests;
mod vendor;

use std::sync::Arc;

use llrp::enums::*;
use llrp::message::*;
use llrp::params::*;
use llrp::{DecodeError, FrameHeader, Message, MessageKind, StatusCode};

use crate::physics::Model;
use crate::scenario::Scenario;
use llrp_gateway_vocab::reader_name::ReaderName;

pub use config::ReaderConfig;
pub use rospec::SpecState;
pub use rospec::ANTENNA_DWELL_US;

/// Most ROSpecs the default device holds at once.
pub const MAX_ROSPECS: u32 = device::DEFAULT.max_rospecs;
/// Most AccessSpecs the default device holds at once.
pub const MAX_ACCESS_SPECS: u32 = device::DEFAULT.max_access_specs;

/// Most TagReportData in one RO_ACCESS_REPORT (about 40 kB with every field).
pub const REPORT_CHUNK: usize = 500;

/// Most events and reports held for a client that has not sent ENABLE_EVENTS_AND_REPORTS.
pub const MAX_HELD: usize = 10_000;

/// Keepalives that may go unanswered before the reader drops the client.
pub const KEEPALIVE_MISSES: u32 = 3;

/// What the reader knows about itself, fixed for its lifetime (from the scenario).
#[derive(Clone, Debug, PartialEq)]
pub struct ReaderProfile {
    /// Reader name in the scenario.
    pub name: ReaderName,
    /// The device it presents itself as (the scenario reader's `device`).
    pub device: &'static device::Device,
    /// Antennas the scenario connects, on ports 1..=antennas (AISpec antenna 0 inventories
    /// these).
    pub antennas: u16,
    /// Antenna ports of the device (MaxNumberOfAntennaSupported): those past `antennas` exist
    /// with nothing connected.
    pub ports: u16,
    /// Frequency hopping (FCC) or a fixed channel list (ETSI).
    pub hopping: bool,
    /// The advertised channel table, kHz (ChannelIndex k is entry k − 1).
    pub frequencies_khz: Vec<u32>,
    /// RegulatoryCapabilities.CommunicationsStandard.
    pub communications_standard: u16,
    /// RegulatoryCapabilities.CountryCode.
    pub country_code: u16,
    /// Power-table index of each antenna's scenario transmit power.
    pub default_power_index: Vec<u16>,
    /// Gain of each antenna, dBi.
    pub antenna_gain_dbi: Vec<f64>,
    /// Reader identity (MAC-like EPC of the reader) for Identification.
    pub reader_id: Vec<u8>,
    /// How often an AISpec without its own end reports under ROReportTrigger 1 with N = 0,
    /// µs (0: only when the ROSpec ends).
    pub report_interval_us: u64,
    /// Time at each AISpec's start before its first inventory round, µs.
    pub aispec_setup_us: u64,
    /// The reader's pause after each inventory round before the next, µs.
    pub round_gap_us: u64,
    /// Number of GPI ports (GPIOCapabilities.NumGPIs).
    pub gpis: u16,
    /// Number of GPO ports (GPIOCapabilities.NumGPOs).
    pub gpos: u16,
    /// What changes the GPI lines over simulated time.
    pub gpi_schedule: gpio::GpiSchedule,
    /// Faults injected over simulated time (the scenario reader's `faults`).
    pub faults: Vec<faults::ScheduledFault>,
    /// Whether the state survives a reboot (the scenario reader's `persist_state`).
    pub persist_state: bool,
}

impl ReaderProfile {
    /// The profile of reader `index` of a scenario.
    pub fn from_scenario(s: &Scenario, index: usize, model: &Model) -> Self {
        let r = &s.readers[index];
        // The scenario checked the name; an unknown one cannot reach here.
        let device = r
            .device
            .as_deref()
            .and_then(device::Device::named)
            .unwrap_or(device::DEFAULT);
        let mut id = vec![0x00, 0x16, 0x25, 0x00, 0x00];
        id.push(index as u8);
        ReaderProfile {
            name: r.name.clone(),
            device,
            antennas: model.antenna_count(),
            // The scenario checked that its antennas fit the device's ports.
            ports: device.antenna_ports.max(model.antenna_count()),
            hopping: r.region.hopping(),
            frequencies_khz: model.frequencies_khz().to_vec(),
            communications_standard: r.region.communications_standard(),
            country_code: r.region.country_code(),
            default_power_index: r
                .antennas
                .iter()
                .map(|a| device.power.index(a.tx_power_dbm))
                .collect(),
            antenna_gain_dbi: r.antennas.iter().map(|a| a.gain_dbi).collect(),
            reader_id: id,
            report_interval_us: u64::from(r.report_interval_ms) * 1000,
            // Validated finite and in [0, 10 s].
            aispec_setup_us: (r.aispec_setup_ms * 1000.0).round() as u64,
            // Validated finite and in [0, 1 s].
            round_gap_us: (r.round_gap_ms * 1000.0).round() as u64,
            gpis: r.gpio.ports(r.device.as_deref()).0,
            gpos: r.gpio.ports(r.device.as_deref()).1,
            gpi_schedule: gpio::GpiSchedule::from_spec(&r.gpio),
            faults: r.faults.clone(),
            persist_state: r.persist_state,
        }
    }
}

/// Something the connection must do.
#[derive(Clone, Debug, PartialEq)]
#[allow(clippy::large_enum_variant)] // almost every output is a message; Close comes once
pub enum Output {
    /// Send this message.
    Send(Message),
    /// Close the connection (after sending what came before).
    Close,
}

/// The simulated reader: configuration, ROSpecs, AccessSpecs, report buffer and clock.
pub struct Reader {
    profile: ReaderProfile,
    model: Arc<Model>,
    /// UTC of simulated time 0, µs since the Unix epoch.
    utc_epoch_us: u64,
    /// Simulated time the reader has run up to, µs.
    now_us: u64,
    /// Whether inventory runs only while a client is connected (it does; see `connect`).
    connected: bool,
    /// Protocol version of the session (1 = LLRP 1.0.1, 2 = LLRP 1.1).
    version: u8,
    /// Impinj extensions enabled on this connection.
    impinj: bool,
    /// Events and reports held until ENABLE_EVENTS_AND_REPORTS.
    holding: bool,
    held: Vec<Message>,
    next_id: u32,
    config: ReaderConfig,
    specs: rospec::Specs,
    access: access::AccessSpecs,
    /// The tags' memory, shared with every reader of the run.
    memory: Arc<memory::TagMemory>,
    /// The tags' inventoried flags in sessions 1–3 as this reader left them.
    flags: crate::physics::flags::Flags,
    /// Wall-clock ms of the next keepalive, and how many went unanswered.
    keepalive_due_ms: Option<u64>,
    keepalive_unanswered: u32,
    /// The GPI lines and what changes them.
    lines: gpio::Lines,
    /// The faults in force on the reader's side.
    faults: faults::State,
}

impl Reader {
    /// A reader for `model` (its scenario reader), with UTC `utc_epoch_us` at simulated time 0.
    pub fn new(profile: ReaderProfile, model: Arc<Model>, utc_epoch_us: u64) -> Self {
        let config = ReaderConfig::factory(&profile);
        let flags = model.new_flags();
        let lines = gpio::Lines::new(profile.gpis, profile.gpi_schedule.clone());
        lines.publish(&config.gpi_enabled, &config.gpos);
        Reader {
            lines,
            flags,
            profile,
            model,
            utc_epoch_us,
            now_us: 0,
            connected: false,
            version: 1,
            impinj: false,
            holding: false,
            held: Vec::new(),
            next_id: 1,
            config,
            specs: rospec::Specs::default(),
            access: access::AccessSpecs::default(),
            memory: Arc::new(memory::TagMemory::new()),
            keepalive_due_ms: None,
            keepalive_unanswered: 0,
            faults: faults::State::default(),
        }
    }

    /// The reader with the tags' memory `memory`, shared with the run's other readers (by
    /// default a reader has a memory of its own).
    pub fn with_memory(mut self, memory: Arc<memory::TagMemory>) -> Self {
        self.memory = memory;
        self
    }

    /// The tags' memory as this reader sees it.
    pub fn memory(&self) -> &Arc<memory::TagMemory> {
        &self.memory
    }

    /// The reader's fixed description.
    pub fn profile(&self) -> &ReaderProfile {
        &self.profile
    }

    /// The physics model behind the reader.
    pub fn model(&self) -> &Model {
        &self.model
    }

    /// The reader's GPIO as seen from outside: toggle its inputs, read its state.
    pub fn gpio_panel(&self) -> &Arc<gpio::GpioPanel> {
        self.lines.panel()
    }

    /// Simulated time the reader has run up to, µs.
    pub fn now_us(&self) -> u64 {
        self.now_us
    }

    /// UTC of a simulated time, µs since the Unix epoch.
    pub fn utc_us(&self, sim_us: u64) -> u64 {
        self.utc_epoch_us + sim_us
    }

    /// Whether an ROSpec is executing.
    pub fn inventorying(&self) -> bool {
        self.specs.active().is_some()
    }

    /// State of ROSpec `id`, if it exists.
    pub fn rospec_state(&self, id: u32) -> Option<SpecState> {
        self.specs.get(id).map(|s| s.state)
    }

    fn alloc_id(&mut self) -> u32 {
        let id = self.next_id;
        self.next_id = self.next_id.wrapping_add(1).max(1);
        id
    }

    fn message(&mut self, body: impl Into<MessageBody>) -> Message {
        let id = self.alloc_id();
        Message {
            version: self.version,
            id,
            body: body.into(),
        }
    }

    fn timestamp(&self) -> Timestamp {
        Timestamp::Utc(UtcTimestamp {
            microseconds: self.utc_us(self.now_us),
            ..Default::default()
        })
    }

    /// A READER_EVENT_NOTIFICATION with a ConnectionAttemptEvent of `status`.
    pub fn connection_event(&mut self, status: ConnectionAttemptStatus) -> Message {
        let data = ReaderEventNotificationData {
            timestamp: self.timestamp(),
            connection_attempt_event: Some(ConnectionAttemptEvent {
                status,
                ..Default::default()
            }),
            ..Default::default()
        };
        self.message(ReaderEventNotification {
            reader_event_notification_data: data,
            ..Default::default()
        })
    }

    /// A READER_EVENT_NOTIFICATION with a ConnectionCloseEvent: what a reader sends before it
    /// closes a connection itself.
    pub fn close_event(&mut self) -> Message {
        let data = ReaderEventNotificationData {
            timestamp: self.timestamp(),
            connection_close_event: Some(ConnectionCloseEvent::default()),
            ..Default::default()
        };
        self.message(ReaderEventNotification {
            reader_event_notification_data: data,
            ..Default::default()
        })
    }

    /// A READER_EVENT_NOTIFICATION with a ReportBufferLevelWarningEvent at `percent` full, if
    /// the client enabled that event (EventNotificationState, type 3).
    pub fn buffer_warning_event(&mut self, percent: u8) -> Option<Message> {
        if !self
            .config
            .event_enabled(NotificationEventType::ReportBufferFillWarning)
        {
            return None;
        }
        let data = ReaderEventNotificationData {
            timestamp: self.timestamp(),
            report_buffer_level_warning_event: Some(ReportBufferLevelWarningEvent {
                report_buffer_percentage_full: percent,
                ..Default::default()
            }),
            ..Default::default()
        };
        Some(self.message(ReaderEventNotification {
            reader_event_notification_data: data,
            ..Default::default()
        }))
    }

    /// A READER_EVENT_NOTIFICATION with a ReportBufferOverflowErrorEvent: reports were lost
    /// (always sent: LLRP makes this event mandatory).
    pub fn buffer_overflow_event(&mut self) -> Message {
        let data = ReaderEventNotificationData {
            timestamp: self.timestamp(),
            report_buffer_overflow_error_event: Some(ReportBufferOverflowErrorEvent::default()),
            ..Default::default()
        };
        self.message(ReaderEventNotification {
            reader_event_notification_data: data,
            ..Default::default()
        })
    }

    /// A client connected at simulated time `now_us` (wall clock `wall_ms`): the greeting.
    ///
    /// While no client is connected the reader does not inventory; ROSpecs and configuration
    /// persist across connections as on a real reader, and time spent disconnected is skipped.
    pub fn connect(&mut self, now_us: u64, wall_ms: u64) -> Vec<Output> {
        self.idle_inputs(now_us);
        self.now_us = self.now_us.max(now_us);
        self.specs.skip_to(self.now_us);
        self.connected = true;
        self.version = 1;
        self.impinj = false;
        self.holding = self
            .config
            .events_and_reports
            .hold_events_and_reports_upon_reconnect;
        self.keepalive_unanswered = 0;
        self.keepalive_due_ms = self.config.keepalive_period_ms().map(|p| wall_ms + p);
        vec![Output::Send(
            self.connection_event(ConnectionAttemptStatus::Success),
        )]
    }

    /// The client went away (closed, or dropped by the reader).
    ///
    /// ROSpecs and the configuration stay, as on an Impinj reader. Reads gathered for the
    /// client and not yet reported, and messages held for it, are dropped unless
    /// HoldEventsAndReportsUponReconnect is set: then the next client gets them when it sends
    /// ENABLE_EVENTS_AND_REPORTS (LLRP 1.1 §20: a reader MAY keep data state across
    /// connections; docs/simulator.md, "Across connections").
    pub fn disconnect(&mut self) {
        self.connected = false;
        self.impinj = false;
        self.keepalive_due_ms = None;
        if !self
            .config
            .events_and_reports
            .hold_events_and_reports_upon_reconnect
        {
            let dropped = self.specs.take_reports().len();
            self.held.clear();
            if dropped > 0 {
                tracing::debug!("{dropped} unreported reads of the departed client dropped");
            }
        }
    }

    /// The message a reader answers a frame it could not decode with: the request's
    /// response type carrying the error status, or ERROR_MESSAGE.
    pub fn reject(&mut self, header: &FrameHeader, frame: &[u8], err: &DecodeError) -> Message {
        let status = err.to_status();
        let kind = MessageKind::of_frame(frame).unwrap_or(MessageKind::standard(header.msg_type));
        let body = kind
            .error_response(status.clone())
            .unwrap_or_else(|| MessageBody::ErrorMessage(error_message(status)));
        Message {
            version: header.version.clamp(1, 2),
            id: header.id,
            body,
        }
    }

    /// ERROR_MESSAGE for a frame whose version the reader does not speak.
    pub fn unsupported_version(header: &FrameHeader) -> Message {
        Message {
            version: header.version,
            id: header.id,
            body: MessageBody::ErrorMessage(error_message(LlrpStatus::new(
                StatusCode::M_UnsupportedVersion,
                format!("unsupported LLRP version {}", header.version),
            ))),
        }
    }

    /// Runs the reader up to simulated time `now_us` (wall clock `wall_ms`): inventory,
    /// triggers, reports, events and keepalives that fall due.
    pub fn advance(&mut self, now_us: u64, wall_ms: u64) -> Vec<Output> {
        let mut out = Vec::new();
        if !self.connected {
            self.idle_inputs(now_us);
            return out;
        }
        self.run_until(now_us, &mut out);
        if let Some(due) = self.keepalive_due_ms {
            if wall_ms >= due {
                if self.keepalive_unanswered >= KEEPALIVE_MISSES {
                    // The client stopped answering: say why, then close.
                    out.push(Output::Send(self.close_event()));
                    out.push(Output::Close);
                    self.keepalive_due_ms = None;
                } else {
                    if !self.keepalive_lost() {
                        let m = self.message(Keepalive::default());
                        out.push(Output::Send(m));
                        self.keepalive_unanswered += 1;
                    }
                    let period = self.config.keepalive_period_ms().unwrap_or(u64::MAX / 2);
                    self.keepalive_due_ms = Some(due.saturating_add(period).max(wall_ms));
                }
            }
        }
        out
    }

    /// Simulated time at which something is next due (a trigger, the end of a slice or a
    /// GPI change), if anything is.
    pub fn next_deadline_us(&self) -> Option<u64> {
        let gpi = self.next_gpi_us();
        match (self.specs.next_deadline(self.now_us), gpi) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    /// Simulated time of the next scheduled GPI change, if any.
    pub fn next_gpi_us(&self) -> Option<u64> {
        self.lines.next_at()
    }

    /// Wall-clock ms at which the next keepalive is due.
    pub fn next_keepalive_ms(&self) -> Option<u64> {
        self.keepalive_due_ms
    }

    fn send_reports(&mut self, reports: Vec<TagReportData>, out: &mut Vec<Output>, always: bool) {
        if reports.is_empty() && !always {
            return;
        }
        // Keep each RO_ACCESS_REPORT well under the frame limit clients use.
        let mut rest = reports;
        loop {
            let tail = if rest.len() > REPORT_CHUNK {
                rest.split_off(REPORT_CHUNK)
            } else {
                Vec::new()
            };
            let m = self.message(RoAccessReport {
                tag_report_data: rest,
                ..Default::default()
            });
            self.deliver(m, out);
            if tail.is_empty() {
                break;
            }
            rest = tail;
        }
    }

    fn emit(&mut self, events: Vec<rospec::Event>, out: &mut Vec<Output>) {
        for e in events {
            let enabled = self.config.event_enabled(e.notification_type());
            if !enabled {
                continue;
            }
            let mut data = ReaderEventNotificationData {
                timestamp: Timestamp::Utc(UtcTimestamp {
                    microseconds: self.utc_us(e.at_us),
                    ..Default::default()
                }),
                ..Default::default()
            };
            match e.kind {
                rospec::EventKind::RoSpec {
                    event_type,
                    ro_spec_id,
                    preempting,
                } => {
                    data.ro_spec_event = Some(RoSpecEvent {
                        event_type,
                        ro_spec_id,
                        preempting_ro_spec_id: preempting,
                        ..Default::default()
                    })
                }
                rospec::EventKind::AiSpecEnd {
                    ro_spec_id,
                    spec_index,
                } => {
                    data.ai_spec_event = Some(AiSpecEvent {
                        event_type: AiSpecEventType::EndOfAiSpec,
                        ro_spec_id,
                        spec_index,
                        ..Default::default()
                    })
                }
            }
            let m = self.message(ReaderEventNotification {
                reader_event_notification_data: data,
                ..Default::default()
            });
            self.deliver(m, out);
        }
    }
}

/// The ImpinjRequestedData values among a request's Custom parameters.
fn impinj_requested(custom: &[Custom]) -> Vec<u32> {
    custom
        .iter()
        .filter_map(|c| match c {
            Custom::ImpinjRequestedData(r) => Some(r.requested_data),
            _ => None,
        })
        .collect()
}

/// An ERROR_MESSAGE body.
fn error_message(status: LlrpStatus) -> llrp::message::ErrorMessage {
    llrp::message::ErrorMessage {
        llrp_status: status,
        ..Default::default()
    }
}

/// LLRPStatus for a bad field of the message itself.
pub(crate) fn field_error(field: u16, code: StatusCode, what: &str) -> LlrpStatus {
    let mut s = LlrpStatus::new(StatusCode::M_FieldError, format!("invalid {what}"));
    s.field_error = Some(FieldError {
        field_num: field,
        error_code: code,
        ..Default::default()
    });
    s
}
