//! The reader's run over simulated time with its GPI lines: the ROSpecs run up to each GPI
//! change, which then raises its GPIEvent and fires the GPI start and stop triggers; the
//! changes come from the scenario's schedule and from the [`GpioPanel`](super::gpio::GpioPanel).

use llrp::enums::NotificationEventType;
use llrp::params::{GpiEvent, ReaderEventNotificationData, Timestamp, UtcTimestamp};

use super::gpio::Edge;
use super::{rospec, Output, Reader};

impl Reader {
    /// Runs the ROSpecs to `now_us` through the GPI changes due by then, each at its time,
    /// then applies the changes asked for from outside (at `now_us`).
    pub(super) fn run_until(&mut self, now_us: u64, out: &mut Vec<Output>) {
        let commands = self.lines.take_commands(now_us.max(self.now_us));
        let mut changed = !commands.is_empty();
        while let Some(edge) = self.lines.pop_due(now_us) {
            let at_us = edge.at_us.max(self.now_us);
            self.run_specs(at_us, out);
            self.on_edge(Edge { at_us, ..edge }, false, out);
            changed = true;
        }
        self.run_specs(now_us, out);
        for edge in commands {
            self.on_edge(edge, true, out);
        }
        if changed {
            self.publish_gpio();
        }
    }

    /// Runs the ROSpecs from where the reader is to `to_us`.
    fn run_specs(&mut self, to_us: u64, out: &mut Vec<Output>) {
        if to_us <= self.now_us {
            return;
        }
        let ctx = rospec::RunContext {
            model: &self.model,
            profile: &self.profile,
            config: &self.config,
            access: &mut self.access,
            memory: &self.memory,
            version: self.version,
            flags: &mut self.flags,
            utc_epoch_us: self.utc_epoch_us,
            impinj: self.impinj,
            faults: &self.faults,
        };
        let produced = self.specs.run(ctx, self.now_us, to_us);
        self.now_us = to_us;
        self.produce(produced, out);
    }

    /// Sends what running the specs produced: reports and events.
    fn produce(&mut self, produced: Vec<rospec::Produced>, out: &mut Vec<Output>) {
        for p in produced {
            match p {
                rospec::Produced::Reports(r) => self.send_reports(r, out, false),
                rospec::Produced::Event(e) => self.emit(vec![e], out),
            }
        }
    }

    /// GPI `edge` (`asked`: from outside, else scheduled): the line changes; on an enabled
    /// port the client hears of it (GPIEvent, if it enabled them) and the GPI triggers fire.
    fn on_edge(&mut self, edge: Edge, asked: bool, out: &mut Vec<Output>) {
        if !self.lines.apply(edge) {
            return;
        }
        let enabled = self.config.gpi_enabled(edge.port);
        let level = if edge.high { "high" } else { "low" };
        if asked {
            tracing::info!(reader = %self.profile.name, port = edge.port, level, enabled, "GPI set");
        } else {
            tracing::debug!(reader = %self.profile.name, port = edge.port, level, enabled, "GPI changed");
        }
        if !enabled {
            return;
        }
        self.gpi_event(edge, out);
        let produced = self.specs.gpi_edge(
            edge.port,
            edge.high,
            edge.at_us,
            &self.config.ro_report_spec,
        );
        self.produce(produced, out);
    }

    /// The GPIEvent of `edge` on an enabled port, if the client enabled them.
    fn gpi_event(&mut self, edge: Edge, out: &mut Vec<Output>) {
        if !self.config.event_enabled(NotificationEventType::GpiEvent) {
            return;
        }
        let data = ReaderEventNotificationData {
            timestamp: Timestamp::Utc(UtcTimestamp {
                microseconds: self.utc_us(edge.at_us),
                ..Default::default()
            }),
            gpi_event: Some(GpiEvent {
                gpi_port_number: edge.port,
                gpi_event: edge.high,
                ..Default::default()
            }),
            ..Default::default()
        };
        self.notify(data, out);
    }

    /// Without a client: the lines follow their schedule and what is asked from outside up
    /// to `now_us`. No inventory runs, so no trigger fires; a change on an enabled port is
    /// heard only if the last client asked for holding (its GPIEvent is held for the next
    /// client, [`Reader::deliver`]).
    pub(super) fn idle_inputs(&mut self, now_us: u64) {
        let now_us = now_us.max(self.now_us);
        self.lines.skip_eyes_to(now_us);
        let commands = self.lines.take_commands(now_us);
        let mut changed = !commands.is_empty();
        let mut held = Vec::new();
        while let Some(edge) = self.lines.pop_due(now_us) {
            if self.lines.apply(edge) {
                changed = true;
                self.idle_edge(edge, &mut held);
            }
        }
        for edge in commands {
            let level = if edge.high { "high" } else { "low" };
            tracing::info!(reader = %self.profile.name, port = edge.port, level, "GPI set (no client connected)");
            if self.lines.apply(edge) {
                self.idle_edge(edge, &mut held);
            }
        }
        debug_assert!(held.is_empty(), "nothing is sent without a client");
        if changed {
            self.publish_gpio();
        }
    }

    /// A line changed with no client connected: its GPIEvent, on an enabled port, is held
    /// if the last client asked for holding (no one hears otherwise).
    fn idle_edge(&mut self, edge: Edge, out: &mut Vec<Output>) {
        if self.config.gpi_enabled(edge.port) {
            self.gpi_event(edge, out);
        }
    }

    /// Publishes the GPIO state to the panel (after a change of a line or of the
    /// configuration).
    pub(super) fn publish_gpio(&self) {
        self.lines
            .publish(&self.config.gpi_enabled, &self.config.gpos);
    }

    /// Logs the GPO writes between configuration `before` and the current one.
    pub(super) fn log_gpo_writes(&self, before: &[bool]) {
        for (i, (&now, &was)) in self.config.gpos.iter().zip(before).enumerate() {
            if now != was {
                let level = if now { "high" } else { "low" };
                tracing::info!(reader = %self.profile.name, port = i + 1, level, "GPO written");
            }
        }
    }
}
