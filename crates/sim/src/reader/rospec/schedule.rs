//! When specs start and what falls due next: start triggers, restarts and deadlines.

use super::*;

impl Specs {
    /// Simulated time something is next due, if any spec is active or waiting to start.
    pub fn next_deadline(&self, now: u64) -> Option<u64> {
        let mut best: Option<u64> = None;
        for s in &self.specs {
            let t = match (&s.run, s.next_start_us) {
                (Some(r), _) => Some(r.slice_end_us.min(now + ANTENNA_DWELL_US)),
                (None, Some(t)) if s.state == SpecState::Inactive => Some(t),
                _ => None,
            };
            if let Some(t) = t {
                best = Some(best.map_or(t, |b| b.min(t)));
            }
        }
        best
    }

    /// The spec (index) whose start is due by `t` with the best priority.
    pub(super) fn due(&self, t: u64) -> Option<usize> {
        self.specs
            .iter()
            .enumerate()
            .filter(|(_, s)| {
                s.state == SpecState::Inactive && s.next_start_us.is_some_and(|n| n <= t)
            })
            .min_by_key(|(_, s)| (s.spec.priority, s.next_start_us))
            .map(|(i, _)| i)
    }

    pub(super) fn next_start_after(&self, t: u64) -> Option<u64> {
        self.specs
            .iter()
            .filter(|s| s.state == SpecState::Inactive)
            .filter_map(|s| s.next_start_us)
            .filter(|&n| n > t)
            .min()
    }
}

pub(super) fn start_type(s: &RoSpec) -> RoSpecStartTriggerType {
    s.ro_boundary_spec
        .ro_spec_start_trigger
        .ro_spec_start_trigger_type
}

/// When an enabled spec first starts: Immediate now, Periodic after its offset, else never
/// (it waits for START_ROSPEC).
pub(super) fn first_start(s: &RoSpec, enabled_at: u64) -> Option<u64> {
    let st = &s.ro_boundary_spec.ro_spec_start_trigger;
    match st.ro_spec_start_trigger_type {
        RoSpecStartTriggerType::Immediate => Some(enabled_at),
        RoSpecStartTriggerType::Periodic => st
            .periodic_trigger_value
            .as_ref()
            .map(|p| enabled_at + u64::from(p.offset) * 1000),
        _ => None,
    }
}

/// When a spec that ran from `started` and ended at `ended` starts again by itself:
/// Immediate at once (as Impinj readers loop an Immediate ROSpec), Periodic one period after
/// the previous start.
pub(super) fn next_start(s: &RoSpec, started: u64, ended: u64) -> Option<u64> {
    let st = &s.ro_boundary_spec.ro_spec_start_trigger;
    match st.ro_spec_start_trigger_type {
        RoSpecStartTriggerType::Immediate => Some(ended.max(started + MIN_RESTART_US)),
        RoSpecStartTriggerType::Periodic => st
            .periodic_trigger_value
            .as_ref()
            .filter(|p| p.period > 0)
            .map(|p| {
                let period = u64::from(p.period) * 1000;
                let mut n = started + period;
                while n < ended {
                    n += period;
                }
                n
            }),
        _ => None,
    }
}
