//! The session's side of injected faults: the connection dropped (a reset, nothing more
//! sent), the reboot (the connection closed, nothing listening for the boot time, the
//! reader's state lost or kept), requests taken late, and the faults of the scenario's
//! timeline applied at their simulated time. The reader's side is `reader::faults`.

use std::collections::VecDeque;
use std::sync::Arc;

use llrp::Inbound;

use super::{Now, Session};
use crate::reader::faults::{Fault, FaultPanel, Timeline};

/// The faults in force on the session's side.
pub(super) struct Faults {
    /// Shared with whoever injects faults from outside.
    pub(super) panel: Arc<FaultPanel>,
    /// The scenario's faults still to come.
    pub(super) timeline: Timeline,
    /// Requests are taken this many wall ms late until the second wall ms.
    delay: Option<(u64, u64)>,
    /// Requests waiting to be taken: when (wall ms), and what.
    delayed: VecDeque<(u64, Inbound)>,
    /// Rebooting: nothing listens until this wall ms.
    down_until_ms: Option<u64>,
    /// The close asked for is a reset (the connection dropped).
    pub(super) abort: bool,
}

impl Faults {
    /// No fault in force; the scenario's `timeline`, a panel for `antennas` ports.
    pub(super) fn new(timeline: Timeline, antennas: usize) -> Self {
        Faults {
            panel: Arc::new(FaultPanel::new(antennas)),
            timeline,
            delay: None,
            delayed: VecDeque::new(),
            down_until_ms: None,
            abort: false,
        }
    }

    /// The client is gone: what waited for it goes with it.
    pub(super) fn disconnected(&mut self) {
        self.delayed.clear();
        self.abort = false;
    }

    /// The wall ms at which something of the faults falls due: a delayed request, the end
    /// of a reboot.
    pub(super) fn wall_deadline(&self) -> Option<u64> {
        let first = self.delayed.front().map(|(t, _)| *t);
        [first, self.down_until_ms].into_iter().flatten().min()
    }
}

impl Session {
    /// The reader's faults as seen from outside: inject them.
    pub fn fault_panel(&self) -> &Arc<FaultPanel> {
        &self.faults.panel
    }

    /// Whether the reader accepts connections (not while it reboots).
    pub fn listening(&self) -> bool {
        self.faults.down_until_ms.is_none()
    }

    /// Whether the close the session asks for is a reset (the drop_connection fault): the
    /// connection is dropped at once, what waits to be sent is lost.
    pub fn abrupt(&self) -> bool {
        self.close && self.faults.abort
    }

    /// Whether a request arriving now waits (requests are delayed, or earlier ones wait).
    pub(super) fn delaying(&self, now: Now) -> bool {
        let on = self
            .faults
            .delay
            .is_some_and(|(_, until)| now.wall_ms < until);
        on || !self.faults.delayed.is_empty()
    }

    /// Keeps `inbound` until its delay is over (after every request that waits before it).
    pub(super) fn hold(&mut self, inbound: Inbound, now: Now) {
        let delay = match self.faults.delay {
            Some((ms, until)) if now.wall_ms < until => ms,
            _ => 0,
        };
        let last = self.faults.delayed.back().map_or(0, |(t, _)| *t);
        let due = now.wall_ms.saturating_add(delay).max(last);
        self.faults.delayed.push_back((due, inbound));
    }

    /// Applies what of the faults falls due by `now`: the end of a reboot, the timeline's
    /// faults (each at its simulated time), those queued on the panel, then the delayed
    /// requests whose time has come.
    pub(super) fn run_faults(&mut self, now: Now) {
        if self.faults.down_until_ms.is_some_and(|t| now.wall_ms >= t) {
            self.faults.down_until_ms = None;
            let name = &self.reader.profile().name;
            tracing::info!(reader = %name, "the reader is back up after its reboot: listening");
        }
        while let Some((at_us, fault)) = self.faults.timeline.pop_due(now.sim_us) {
            let at = Now {
                sim_us: at_us.max(self.reader.now_us()),
                wall_ms: now.wall_ms,
            };
            self.run_reader(at);
            self.inject(fault, at);
        }
        let queued = self.faults.panel.take();
        if !queued.is_empty() {
            self.run_reader(now);
        }
        for fault in queued {
            self.inject(fault, now);
        }
        while self.client.is_some() && !self.close {
            match self.faults.delayed.front() {
                Some((due, _)) if *due <= now.wall_ms => {}
                _ => break,
            }
            if let Some((_, inbound)) = self.faults.delayed.pop_front() {
                self.take(inbound, now);
            }
        }
    }

    /// Applies `fault` at `now` (logged, and counted through the panel).
    fn inject(&mut self, fault: Fault, now: Now) {
        let name = fault.name();
        let reader = self.reader.profile().name.clone();
        let client = self.client.is_some() && !self.close;
        tracing::info!(reader = %reader, fault = name, detail = ?fault, client, "fault injected");
        match fault {
            Fault::AntennaDisconnect { antenna } => {
                let out = self.reader.plug(antenna, false, now.sim_us);
                self.push_live(out);
            }
            Fault::AntennaReconnect { antenna } => {
                let out = self.reader.plug(antenna, true, now.sim_us);
                self.push_live(out);
            }
            Fault::DropConnection => {
                if client {
                    self.out.clear();
                    self.close = true;
                    self.faults.abort = true;
                }
            }
            Fault::Reboot {
                keep_state,
                boot_ms,
            } => {
                let keep = keep_state.unwrap_or(self.reader.profile().persist_state);
                if client {
                    // The reader's software stops: the connection closes, nothing more said.
                    self.out.clear();
                    self.close = true;
                }
                self.faults.delay = None;
                self.faults.delayed.clear();
                self.reader.reboot(keep);
                self.faults.down_until_ms = Some(now.wall_ms.saturating_add(boot_ms));
                tracing::info!(reader = %reader, keep, boot_ms, "the reader reboots: not listening");
            }
            Fault::DelayResponses { ms, for_ms } => {
                self.faults.delay = Some((ms, now.wall_ms.saturating_add(for_ms)));
            }
            Fault::LoseKeepalives { count } => self.reader.lose_keepalives(count),
            Fault::FillReportBuffer { for_ms } => {
                self.reader
                    .hold_buffer_full(now.wall_ms.saturating_add(for_ms));
            }
            Fault::ReaderException { message } => {
                let out = self.reader.exception(message);
                self.push_live(out);
            }
        }
        self.faults.panel.applied(name);
    }
}
