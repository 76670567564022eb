//! Faults injected into the reader, sans IO: the scenario's timeline of them (simulated time)
//! and a [`FaultPanel`] shared with whoever injects them from outside (the HTTP API, a test).
//! The reader's own part is here (antenna ports unplugged and plugged back, keepalives lost,
//! the report buffer held full, a ReaderExceptionEvent, the state a reboot loses); the
//! session's part (the connection dropped, the reboot's outage, requests delayed) is in
//! `session::faults`.

use std::sync::Mutex;

use llrp::enums::{AntennaEventType, NotificationEventType};
use llrp::params::{AntennaEvent, ReaderEventNotificationData, ReaderExceptionEvent};

use super::{access, rospec, Output, Reader, ReaderConfig};
pub use crate::scenario::faults::{Fault, ScheduledFault};

/// Why a fault asked for from outside was refused: the field that is wrong and why.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{field}: {reason}")]
pub struct FaultError {
    /// The fault's field (`antenna`, `ms`, …).
    pub field: &'static str,
    /// Why.
    pub reason: String,
}

/// A callback of the panel.
type Hook = Box<dyn Fn() + Send + Sync>;
/// A callback given the name of each fault applied.
type Applied = Box<dyn Fn(&'static str) + Send + Sync>;

/// A reader's faults as seen from outside: faults queued here are applied by the reader on
/// its clock at once; whoever counts them is told of each applied (the timeline's too).
pub struct FaultPanel {
    antennas: usize,
    pending: Mutex<Vec<Fault>>,
    wake: Mutex<Option<Hook>>,
    applied: Mutex<Option<Applied>>,
}

impl std::fmt::Debug for FaultPanel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FaultPanel")
            .field("antennas", &self.antennas)
            .finish_non_exhaustive()
    }
}

impl FaultPanel {
    /// A panel for a reader of `antennas` antenna ports.
    pub fn new(antennas: usize) -> Self {
        FaultPanel {
            antennas,
            pending: Mutex::new(Vec::new()),
            wake: Mutex::new(None),
            applied: Mutex::new(None),
        }
    }

    /// Queues `fault` for the reader and wakes it; refused, naming the field, when its
    /// parameters do not fit the reader.
    pub fn send(&self, fault: Fault) -> Result<(), FaultError> {
        fault
            .check(self.antennas)
            .map_err(|(field, reason)| FaultError { field, reason })?;
        lock(&self.pending).push(fault);
        if let Some(wake) = lock(&self.wake).as_ref() {
            wake();
        }
        Ok(())
    }

    /// Calls `wake` whenever a fault is queued (the host running the reader wakes it then).
    pub fn on_change(&self, wake: impl Fn() + Send + Sync + 'static) {
        *lock(&self.wake) = Some(Box::new(wake));
    }

    /// Calls `count` with the name of each fault the reader applies (queued here or on the
    /// scenario's timeline).
    pub fn on_applied(&self, count: impl Fn(&'static str) + Send + Sync + 'static) {
        *lock(&self.applied) = Some(Box::new(count));
    }

    pub(crate) fn take(&self) -> Vec<Fault> {
        std::mem::take(&mut *lock(&self.pending))
    }

    pub(crate) fn applied(&self, name: &'static str) {
        if let Some(count) = lock(&self.applied).as_ref() {
            count(name);
        }
    }
}

/// A lock whose holder cannot leave the value half-changed (every critical section is a
/// push, a take, a call or an assignment), so a poisoned one is used as is.
fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// The scenario's faults in time order (simulated µs), and the next one due.
#[derive(Clone, Debug, Default)]
pub(crate) struct Timeline {
    faults: Vec<(u64, Fault)>,
    next: usize,
}

impl Timeline {
    /// The timeline of a scenario reader's `faults`.
    pub(crate) fn new(faults: &[ScheduledFault]) -> Self {
        Timeline {
            faults: (faults.iter())
                .map(|f| (f.t_ms.saturating_mul(1000), f.fault.clone()))
                .collect(),
            next: 0,
        }
    }

    /// When the next fault is due, simulated µs.
    pub(crate) fn next_at(&self) -> Option<u64> {
        self.faults.get(self.next).map(|(t, _)| *t)
    }

    /// The next fault due at or before `upto`, taken.
    pub(crate) fn pop_due(&mut self, upto: u64) -> Option<(u64, Fault)> {
        let due = self
            .faults
            .get(self.next)
            .filter(|(t, _)| *t <= upto)?
            .clone();
        self.next += 1;
        Some(due)
    }
}

/// The reader's side of the faults in force.
#[derive(Clone, Debug, Default)]
pub(crate) struct State {
    /// Per antenna port (index = port − 1): whether its cable is unplugged.
    unplugged: Vec<bool>,
    /// KEEPALIVEs still to be lost.
    lose_keepalives: u32,
    /// Wall ms until which the report buffer is held full.
    buffer_full_until_ms: Option<u64>,
}

impl State {
    /// Whether antenna port `antenna` is connected (any port not unplugged is).
    pub(crate) fn connected(&self, antenna: u16) -> bool {
        let k = usize::from(antenna).wrapping_sub(1);
        !self.unplugged.get(k).copied().unwrap_or(false)
    }

    /// Per antenna port of `count` (index = port − 1): whether it is connected.
    pub(crate) fn connected_ports(&self, count: u16) -> Vec<bool> {
        (1..=count).map(|a| self.connected(a)).collect()
    }
}

impl Reader {
    /// Whether antenna port `antenna` is connected (no fault unplugged it).
    pub fn antenna_connected(&self, antenna: u16) -> bool {
        self.faults.connected(antenna)
    }

    /// Whether the report buffer is held full at wall ms `wall_ms` (the fill_report_buffer
    /// fault): the server then drops reports as for a client that does not read.
    pub fn report_buffer_held_full(&self, wall_ms: u64) -> bool {
        self.faults
            .buffer_full_until_ms
            .is_some_and(|t| wall_ms < t)
    }

    /// Unplugs (`connected` false) or plugs back antenna port `antenna` at `at_us`: the
    /// client hears of a change by an AntennaEvent, if it enabled them (with no client
    /// connected, the next one, if the last asked for holding: [`Reader::deliver`]).
    pub(crate) fn plug(&mut self, antenna: u16, connected: bool, at_us: u64) -> Vec<Output> {
        let mut out = Vec::new();
        let k = usize::from(antenna).wrapping_sub(1);
        if k >= usize::from(self.profile.antennas) || self.faults.connected(antenna) == connected {
            return out;
        }
        if self.faults.unplugged.len() <= k {
            self.faults.unplugged.resize(k + 1, false);
        }
        self.faults.unplugged[k] = !connected;
        if !self
            .config
            .event_enabled(NotificationEventType::AntennaEvent)
        {
            return out;
        }
        let event = AntennaEvent {
            event_type: if connected {
                AntennaEventType::AntennaConnected
            } else {
                AntennaEventType::AntennaDisconnected
            },
            antenna_id: antenna,
            ..Default::default()
        };
        let data = ReaderEventNotificationData {
            timestamp: self.timestamp_at(at_us),
            antenna_event: Some(event),
            ..Default::default()
        };
        self.notify(data, &mut out);
        out
    }

    /// A ReaderExceptionEvent with `message`, if the client enabled them (held for the next
    /// client as an AntennaEvent is).
    pub(crate) fn exception(&mut self, message: String) -> Vec<Output> {
        let mut out = Vec::new();
        if !(self.config).event_enabled(NotificationEventType::ReaderExceptionEvent) {
            return out;
        }
        let data = ReaderEventNotificationData {
            timestamp: self.timestamp_at(self.now_us),
            reader_exception_event: Some(ReaderExceptionEvent {
                message,
                ..Default::default()
            }),
            ..Default::default()
        };
        self.notify(data, &mut out);
        out
    }

    /// The next `count` KEEPALIVEs are not sent.
    pub(crate) fn lose_keepalives(&mut self, count: u32) {
        self.faults.lose_keepalives = self.faults.lose_keepalives.saturating_add(count);
    }

    /// Whether the KEEPALIVE due now is lost (one fewer to lose then).
    pub(crate) fn keepalive_lost(&mut self) -> bool {
        let lost = self.faults.lose_keepalives > 0;
        if lost {
            self.faults.lose_keepalives -= 1;
            tracing::info!(reader = %self.profile.name, left = self.faults.lose_keepalives, "KEEPALIVE lost (fault)");
        }
        lost
    }

    /// Holds the report buffer full until wall ms `until_ms`.
    pub(crate) fn hold_buffer_full(&mut self, until_ms: u64) {
        self.faults.buffer_full_until_ms = Some(until_ms);
    }

    /// The reader reboots: without a client, its faults of the moment over; unless `keep`,
    /// its ROSpecs, AccessSpecs, configuration (GPO levels included) and inventoried flags are
    /// lost, as on a reader that does not persist them. Its cables stay as they are.
    pub(crate) fn reboot(&mut self, keep: bool) {
        self.disconnect();
        self.held.clear();
        let _ = self.specs.take_reports();
        self.next_id = 1;
        self.faults.lose_keepalives = 0;
        self.faults.buffer_full_until_ms = None;
        if !keep {
            self.config = ReaderConfig::factory(&self.profile);
            self.specs = rospec::Specs::default();
            self.access = access::AccessSpecs::default();
            self.flags = self.model.new_flags();
            self.publish_gpio();
        }
    }

    fn timestamp_at(&self, at_us: u64) -> llrp::params::Timestamp {
        llrp::params::Timestamp::Utc(llrp::params::UtcTimestamp {
            microseconds: self.utc_us(at_us),
            ..Default::default()
        })
    }
}
