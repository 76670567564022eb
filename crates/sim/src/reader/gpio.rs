//! The reader's general-purpose inputs, sans IO: each GPI line's level over simulated time,
//! from the scenario (a timeline of changes, photo-eyes pulsing at a period) and from outside
//! (a [`GpioPanel`] shared with whoever toggles the lines: the HTTP API, a test).
//!
//! A change is an edge on the reader's simulated clock: the reader runs its ROSpecs up to it,
//! then applies it (GPIEvent, GPI start and stop triggers), and the session wakes for the
//! next one (`Lines::next_at`). What the reader last knew (levels, whether each input is
//! enabled, the outputs) is published to the panel, which answers without the reader.

use std::sync::{Arc, Mutex};

use crate::scenario::gpio::GpioSpec;

/// A level change of GPI `port` at simulated time `at_us`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Edge {
    /// When, simulated µs.
    pub at_us: u64,
    /// GPI port, 1-based.
    pub port: u16,
    /// The level the line moves to (true: high).
    pub high: bool,
}

/// What drives a reader's GPI lines over simulated time: the scenario's timeline and
/// photo-eyes.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GpiSchedule {
    /// Level changes in time order.
    pub timeline: Vec<Edge>,
    /// Periodic pulses.
    pub eyes: Vec<Eye>,
}

/// A line pulsing to its active level for `width_us` every `period_us` from `start_us`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Eye {
    /// GPI port, 1-based.
    pub port: u16,
    /// First leading edge, µs.
    pub start_us: u64,
    /// Leading edge to leading edge, µs.
    pub period_us: u64,
    /// Pulse width, µs (less than the period).
    pub width_us: u64,
    /// Number of pulses (none: for ever).
    pub count: Option<u64>,
    /// The level of a pulse (true: high); the line rests at the other.
    pub active_high: bool,
}

impl Eye {
    /// Edge `j` of the eye (even: a pulse's leading edge, odd: its trailing edge), if the eye
    /// has that many.
    fn edge(&self, j: u64) -> Option<Edge> {
        let k = j / 2;
        if self.count.is_some_and(|c| k >= c) {
            return None;
        }
        let lead = self.start_us.checked_add(k.checked_mul(self.period_us)?)?;
        let (at_us, high) = if j.is_multiple_of(2) {
            (lead, self.active_high)
        } else {
            (lead.checked_add(self.width_us)?, !self.active_high)
        };
        Some(Edge {
            at_us,
            port: self.port,
            high,
        })
    }
}

impl GpiSchedule {
    /// The schedule a scenario reader's `gpio` describes.
    pub fn from_spec(g: &GpioSpec) -> Self {
        let us = |ms: u64| ms.saturating_mul(1000);
        GpiSchedule {
            timeline: g
                .gpi_timeline
                .iter()
                .map(|c| Edge {
                    at_us: us(c.t_ms),
                    port: c.port,
                    high: c.state.is_high(),
                })
                .collect(),
            eyes: g
                .photo_eyes
                .iter()
                .map(|e| Eye {
                    port: e.port,
                    start_us: us(e.start_ms),
                    period_us: us(e.period_ms),
                    width_us: us(e.width_ms),
                    count: e.count,
                    active_high: e.active.is_high(),
                })
                .collect(),
        }
    }
}

/// A change asked for from outside the reader.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Command {
    /// Set GPI `port` to a level.
    Set {
        /// GPI port, 1-based.
        port: u16,
        /// The level (true: high).
        high: bool,
    },
    /// Set GPI `port` to a level, and back to the other after `width_us` of simulated time.
    Pulse {
        /// GPI port, 1-based.
        port: u16,
        /// The pulse's level (true: high).
        high: bool,
        /// Pulse width, simulated µs.
        width_us: u64,
    },
}

impl Command {
    fn port(&self) -> u16 {
        match *self {
            Command::Set { port, .. } | Command::Pulse { port, .. } => port,
        }
    }
}

/// One GPI port as the reader last knew it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GpiState {
    /// GPI port, 1-based.
    pub port: u16,
    /// Its level (true: high).
    pub high: bool,
    /// Whether the port is enabled (GPIPortCurrentState.Config): a disabled port raises no
    /// event and fires no trigger.
    pub enabled: bool,
}

/// The reader's GPIO as it last knew it.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct GpioSnapshot {
    /// Every GPI port, in port order.
    pub gpis: Vec<GpiState>,
    /// Every GPO port's level (index = port − 1; true: high).
    pub gpos: Vec<bool>,
}

/// Why a change from outside was refused.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum PanelError {
    /// The reader has no such GPI port.
    #[error("no GPI port {port}: the reader has GPI ports 1..={gpis}")]
    NoSuchPort {
        /// The port asked for.
        port: u16,
        /// How many GPI ports the reader has.
        gpis: u16,
    },
    /// A pulse of no width.
    #[error("a pulse must last at least 1 ms")]
    EmptyPulse,
}

/// A waker the panel calls after a change is queued.
type Waker = Box<dyn Fn() + Send + Sync>;

/// A reader's GPIO as seen from outside: changes to its inputs are queued here for the
/// reader to apply on its clock, and its last known state is read from here.
pub struct GpioPanel {
    gpis: u16,
    pending: Mutex<Vec<Command>>,
    snapshot: Mutex<GpioSnapshot>,
    wake: Mutex<Option<Waker>>,
}

impl std::fmt::Debug for GpioPanel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpioPanel")
            .field("gpis", &self.gpis)
            .field("snapshot", &self.snapshot())
            .finish_non_exhaustive()
    }
}

impl GpioPanel {
    fn new(gpis: u16) -> Self {
        GpioPanel {
            gpis,
            pending: Mutex::new(Vec::new()),
            snapshot: Mutex::new(GpioSnapshot::default()),
            wake: Mutex::new(None),
        }
    }

    /// Queues `command` for the reader and wakes it.
    pub fn send(&self, command: Command) -> Result<(), PanelError> {
        let port = command.port();
        if port == 0 || port > self.gpis {
            return Err(PanelError::NoSuchPort {
                port,
                gpis: self.gpis,
            });
        }
        if matches!(command, Command::Pulse { width_us: 0, .. }) {
            return Err(PanelError::EmptyPulse);
        }
        lock(&self.pending).push(command);
        if let Some(wake) = lock(&self.wake).as_ref() {
            wake();
        }
        Ok(())
    }

    /// The reader's GPIO as it last knew it.
    pub fn snapshot(&self) -> GpioSnapshot {
        lock(&self.snapshot).clone()
    }

    /// Calls `wake` whenever a change is queued (the host running the reader wakes it then).
    pub fn on_change(&self, wake: impl Fn() + Send + Sync + 'static) {
        *lock(&self.wake) = Some(Box::new(wake));
    }

    fn take(&self) -> Vec<Command> {
        std::mem::take(&mut *lock(&self.pending))
    }

    fn publish(&self, snapshot: GpioSnapshot) {
        *lock(&self.snapshot) = snapshot;
    }
}

/// A lock whose holder cannot leave the value half-changed (every critical section is a
/// push, a take or an assignment), so a poisoned one is used as is.
fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// The reader's GPI lines: their levels and what changes them next.
#[derive(Debug)]
pub(crate) struct Lines {
    levels: Vec<bool>,
    schedule: GpiSchedule,
    /// Next timeline entry.
    next_change: usize,
    /// Per eye, its next edge's number.
    next_eye_edge: Vec<u64>,
    /// Trailing edges of pulses asked for from outside.
    pulse_ends: Vec<Edge>,
    panel: Arc<GpioPanel>,
}

impl Lines {
    /// `gpis` lines at rest (low, or high for a photo-eye pulsing low) under `schedule`.
    pub(crate) fn new(gpis: u16, schedule: GpiSchedule) -> Self {
        let mut levels = vec![false; usize::from(gpis)];
        for eye in &schedule.eyes {
            if let Some(l) = levels.get_mut(usize::from(eye.port).wrapping_sub(1)) {
                *l = !eye.active_high;
            }
        }
        Lines {
            levels,
            next_eye_edge: vec![0; schedule.eyes.len()],
            schedule,
            next_change: 0,
            pulse_ends: Vec::new(),
            panel: Arc::new(GpioPanel::new(gpis)),
        }
    }

    /// The panel shared with the outside.
    pub(crate) fn panel(&self) -> &Arc<GpioPanel> {
        &self.panel
    }

    /// Whether GPI `port` is high (false for a port the reader lacks).
    #[cfg(test)]
    pub(crate) fn level(&self, port: u16) -> bool {
        (self.levels.get(usize::from(port).wrapping_sub(1))).is_some_and(|&l| l)
    }

    /// Every line's level, index = port − 1.
    pub(crate) fn levels(&self) -> &[bool] {
        &self.levels
    }

    /// Queues the changes asked for from outside as edges at `now_us`.
    pub(crate) fn take_commands(&mut self, now_us: u64) -> Vec<Edge> {
        let mut edges = Vec::new();
        for c in self.panel.take() {
            match c {
                Command::Set { port, high } => edges.push(Edge {
                    at_us: now_us,
                    port,
                    high,
                }),
                Command::Pulse {
                    port,
                    high,
                    width_us,
                } => {
                    edges.push(Edge {
                        at_us: now_us,
                        port,
                        high,
                    });
                    self.pulse_ends.push(Edge {
                        at_us: now_us.saturating_add(width_us),
                        port,
                        high: !high,
                    });
                }
            }
        }
        edges
    }

    /// When the schedule next changes a line, if ever.
    pub(crate) fn next_at(&self) -> Option<u64> {
        let timeline = self
            .schedule
            .timeline
            .get(self.next_change)
            .map(|e| e.at_us);
        let eyes = (self.schedule.eyes.iter().zip(&self.next_eye_edge))
            .filter_map(|(eye, &j)| eye.edge(j).map(|e| e.at_us));
        let pulses = self.pulse_ends.iter().map(|e| e.at_us);
        timeline.into_iter().chain(eyes).chain(pulses).min()
    }

    /// The schedule's earliest edge at or before `upto`, taken (the timeline first, then the
    /// eyes, then pulse ends, at equal times).
    pub(crate) fn pop_due(&mut self, upto: u64) -> Option<Edge> {
        let at = self.next_at().filter(|&t| t <= upto)?;
        if let Some(e) = self.schedule.timeline.get(self.next_change) {
            if e.at_us == at {
                self.next_change += 1;
                return Some(*e);
            }
        }
        for (eye, j) in self.schedule.eyes.iter().zip(&mut self.next_eye_edge) {
            if let Some(e) = eye.edge(*j).filter(|e| e.at_us == at) {
                *j += 1;
                return Some(e);
            }
        }
        let k = self.pulse_ends.iter().position(|e| e.at_us == at)?;
        Some(self.pulse_ends.remove(k))
    }

    /// Moves the photo-eyes on to their last pulse before `t_us` without going through every
    /// edge between (after a long time without a client).
    pub(crate) fn skip_eyes_to(&mut self, t_us: u64) {
        for (eye, j) in self.schedule.eyes.iter().zip(&mut self.next_eye_edge) {
            let Some(elapsed) = t_us.checked_sub(eye.start_us) else {
                continue;
            };
            let mut k = elapsed / eye.period_us.max(1);
            if let Some(c) = eye.count {
                k = k.min(c);
            }
            // Edges before pulse k are over; the level is the resting one until pulse k.
            if 2 * k > *j {
                *j = 2 * k;
                if let Some(l) = self.levels.get_mut(usize::from(eye.port).wrapping_sub(1)) {
                    *l = !eye.active_high;
                }
            }
        }
    }

    /// Sets the line of `edge`; whether its level changed.
    pub(crate) fn apply(&mut self, edge: Edge) -> bool {
        match self.levels.get_mut(usize::from(edge.port).wrapping_sub(1)) {
            Some(l) if *l != edge.high => {
                *l = edge.high;
                true
            }
            _ => false,
        }
    }

    /// Publishes the reader's GPIO state (`enabled` per GPI, `gpos` per GPO) to the panel.
    pub(crate) fn publish(&self, enabled: &[bool], gpos: &[bool]) {
        let gpis = (self.levels.iter().enumerate())
            .map(|(i, &high)| GpiState {
                port: i as u16 + 1,
                high,
                enabled: enabled.get(i).copied().unwrap_or(false),
            })
            .collect();
        self.panel.publish(GpioSnapshot {
            gpis,
            gpos: gpos.to_vec(),
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn eye(count: Option<u64>) -> Eye {
        Eye {
            port: 1,
            start_us: 1_000,
            period_us: 10_000,
            width_us: 2_000,
            count,
            active_high: true,
        }
    }

    #[test]
    fn a_photo_eye_pulses_its_count_of_times_and_rests() {
        let mut lines = Lines::new(
            2,
            GpiSchedule {
                timeline: vec![],
                eyes: vec![eye(Some(2))],
            },
        );
        let mut edges = Vec::new();
        while let Some(e) = lines.pop_due(u64::MAX) {
            edges.push((e.at_us, e.high));
        }
        assert_eq!(
            edges,
            [
                (1_000, true),
                (3_000, false),
                (11_000, true),
                (13_000, false)
            ]
        );
        assert_eq!(lines.next_at(), None);
    }

    #[test]
    fn skipping_ahead_lands_on_the_pulse_in_progress_at_rest_level() {
        let mut lines = Lines::new(
            1,
            GpiSchedule {
                timeline: vec![],
                eyes: vec![eye(None)],
            },
        );
        lines.skip_eyes_to(1_000_000 + 1_500);
        // Pulse 100 starts at 1_001_000: its leading edge is still to come through pop_due.
        assert_eq!(lines.next_at(), Some(1_001_000));
        assert!(!lines.level(1));
    }

    #[test]
    fn the_panel_refuses_a_port_the_reader_lacks() {
        let lines = Lines::new(4, GpiSchedule::default());
        let err = lines.panel().send(Command::Set {
            port: 5,
            high: true,
        });
        assert_eq!(err, Err(PanelError::NoSuchPort { port: 5, gpis: 4 }));
    }
}
