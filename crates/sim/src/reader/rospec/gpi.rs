//! The GPI triggers: an ROSpec that starts on a GPI event, an ROSpec or AISpec that stops on
//! one (LLRP 1.0.1 §10.2.1.1.1.2: GPIEvent true is the line's 0 → 1 transition, false its
//! 1 → 0; a start trigger's Timeout is ignored; a stop trigger's ends the spec after that many
//! ms, `stops::ro_stop_end` and `stops::ai_stop_end`).

use super::schedule::start_type;
use super::*;

impl Specs {
    /// GPI `port` moved to `high` at `at`: the enabled ROSpecs waiting for that event start
    /// (as START_ROSPEC would, by priority, on the next run), then the active ROSpec ends, or
    /// its current AISpec does, if its stop trigger waits for it. `default_report` is the
    /// reader's ROReportSpec, for a spec without its own.
    pub fn gpi_edge(
        &mut self,
        port: u16,
        high: bool,
        at: u64,
        default_report: &RoReportSpec,
    ) -> Vec<Produced> {
        let fires = |g: &Option<GpiTriggerValue>| {
            g.as_ref()
                .is_some_and(|g| g.gpi_port_num == port && g.gpi_event == high)
        };
        let active = self.active_idx();
        for (i, s) in self.specs.iter_mut().enumerate() {
            let start = &s.spec.ro_boundary_spec.ro_spec_start_trigger;
            if Some(i) != active
                && s.state == SpecState::Inactive
                && start_type(&s.spec) == RoSpecStartTriggerType::Gpi
                && fires(&start.gpi_trigger_value)
            {
                s.next_start_us = Some(at);
            }
        }
        let mut out = Vec::new();
        let Some(a) = active else {
            return out;
        };
        let spec = Arc::clone(&self.specs[a].spec);
        let report = spec.ro_report_spec.as_ref().unwrap_or(default_report);
        let stop = &spec.ro_boundary_spec.ro_spec_stop_trigger;
        if stop.ro_spec_stop_trigger_type == RoSpecStopTriggerType::GpiWithTimeout
            && fires(&stop.gpi_trigger_value)
        {
            self.end_ai(a, at, report, &mut out);
            self.finish_ro(a, at, report, &mut out);
            return out;
        }
        let idx = self.specs[a].run.as_ref().map_or(0, |r| r.spec_idx);
        if let Some(SpecParameter::AiSpec(ai)) = spec.specs.get(idx) {
            let trig = &ai.ai_spec_stop_trigger;
            if trig.ai_spec_stop_trigger_type == AiSpecStopTriggerType::GpiWithTimeout
                && fires(&trig.gpi_trigger_value)
            {
                self.next_ai(a, at, report, &mut out);
            }
        }
        out
    }
}
