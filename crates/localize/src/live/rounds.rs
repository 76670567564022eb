//! Rounds of estimates: dirty tags first, longest waiting first, each from its last fix where
//! `relock` had converged, and settled tags once more from the grid (the module above).

use llrp_gateway_vocab::epc::Epc;
use std::time::{Duration, Instant};

use super::{TagState, Worker};
use crate::calibrate::Calibration;
use crate::estimate::{self, Estimate, State};

/// A tag whose last estimate started from its previous fix is estimated again from the grid
/// once it has had no new read for this long.
pub const SETTLE: Duration = Duration::from_secs(1);

/// A tag updated from its last fix for this long (since its first such update after the last
/// from the grid) is updated from the grid once: new reads may have moved the best fit to
/// another lobe, which a start from the old fix would not leave. A tag settled from the grid
/// and read again later (a robot's next pass) starts from its fix again.
pub const REFRESH: Duration = Duration::from_secs(5);

/// Most compute a round spends on refreshes from the grid ([`REFRESH`]); a refresh due
/// beyond it waits for a later round, the update starting from the last fix meanwhile (the
/// tags of a pass would otherwise all be due at once, and hold up every update for as long
/// as their grid searches take).
pub const REFRESH_BUDGET: Duration = Duration::from_millis(5);

/// A settling estimate within this of the warm one (m, on each axis) is not published again:
/// both are the same minimum, to the solver's precision.
pub const SETTLED_SAME_M: f64 = 1e-7;

/// A tag due for an estimate: (settling, since, epc, from the grid); dirty tags (`false`)
/// sort first, then the longest waiting.
type Due = (bool, Instant, Epc, bool);

impl Worker {
    /// Re-estimates dirty tags (longest waiting first), then settled ones whose last estimate
    /// was warm, for at most `budget`; `all`: every such tag, each from the grid.
    pub(super) fn estimate(&mut self, budget: Duration, all: bool) {
        let started = Instant::now();
        let due = self.due(Instant::now(), all);
        // Measured once a round: the references move little between rounds.
        let calibration = if due.is_empty() {
            Calibration::default()
        } else {
            estimate::calibration(
                &self.ingest,
                self.settings.estimator,
                &self.settings.geometry,
            )
        };
        let warm_starts = self.settings.estimator.locator().warm_starts();
        let mut refreshing = Duration::ZERO;
        for (settling, since, epc, cold) in due {
            if started.elapsed() >= budget {
                break;
            }
            let (hint, refresh) = match self.tags.get(&epc) {
                Some(t) if !cold && warm_starts => start(t, Instant::now(), refreshing),
                _ => (None, false),
            };
            let t0 = Instant::now();
            let run = |hint| {
                estimate::estimate_from(
                    &self.ingest,
                    &epc,
                    self.settings.estimator,
                    &self.settings.geometry,
                    &calibration,
                    hint,
                )
            };
            let mut e = run(hint);
            let mut warm = hint.is_some();
            if warm && e.state != State::Converged {
                // Not converged from the last fix: from the grid.
                e = run(None);
                warm = false;
            }
            let done = Instant::now();
            if refresh {
                refreshing += done.duration_since(t0);
            }
            self.shared
                .metrics
                .estimator_seconds
                .observe(done.duration_since(t0).as_secs_f64());
            if !settling {
                self.shared
                    .metrics
                    .update_latency_seconds
                    .observe(done.duration_since(since).as_secs_f64());
            }
            let unchanged = self.record(&epc, &e, settling, warm, (t0, done));
            if !unchanged {
                self.shared.publish(e);
            }
        }
    }

    /// The tags due for an estimate at `now`, in order: dirty ones rested for the minimum
    /// interval, then settled ones owed an estimate from the grid; `all`: every such tag.
    fn due(&self, now: Instant, all: bool) -> Vec<Due> {
        let mut due: Vec<Due> = self
            .tags
            .iter()
            .filter_map(|(epc, t)| {
                if let Some(since) = t.dirty_since {
                    let rested = t
                        .last_estimate
                        .is_none_or(|l| now.duration_since(l) >= self.settings.min_interval);
                    return (all || rested).then(|| (false, since, epc.clone(), all));
                }
                let last = t.last_estimate?;
                let settled = all || now.duration_since(last) >= SETTLE;
                (t.settle_due && settled).then(|| (true, last, epc.clone(), true))
            })
            .collect();
        due.sort();
        due
    }

    /// Records estimate `e` of tag `epc` (`settling`: from the grid after warm ones; `warm`:
    /// from the last fix; run from `times.0` to `times.1`) in its state; whether it is
    /// unchanged (a settling estimate where the warm one already was), so not published.
    fn record(
        &mut self,
        epc: &str,
        e: &Estimate,
        settling: bool,
        warm: bool,
        (t0, done): (Instant, Instant),
    ) -> bool {
        let warm_starts = self.settings.estimator.locator().warm_starts();
        let Some(t) = self.tags.get_mut(epc) else {
            return false;
        };
        // A settling estimate where the warm one already was (what the warm one converged
        // to): nothing to tell anyone.
        let unchanged = settling
            && e.state == State::Converged
            && matches!((e.estimate, t.warm), (Some(p), Some(q))
                if (0..3).all(|a| (p[a] - q[a]).abs() <= SETTLED_SAME_M));
        t.dirty_since = None;
        t.last_estimate = Some(done);
        t.warm = e
            .estimate
            .filter(|_| warm_starts && e.state == State::Converged);
        t.settle_due = warm;
        t.warm_since = if warm {
            t.warm_since.or(Some(t0))
        } else {
            None
        };
        unchanged
    }
}

/// Where an update of `t` starts at `now`, when the round has spent `refreshing` on refreshes
/// so far: from its last fix, or from the grid (`None`; `true` when that is a refresh).
fn start(t: &TagState, now: Instant, refreshing: Duration) -> (Option<[f64; 3]>, bool) {
    let Some(fix) = t.warm else {
        return (None, false);
    };
    let due = t
        .warm_since
        .is_some_and(|w| now.duration_since(w) >= REFRESH);
    if due && refreshing < REFRESH_BUDGET {
        (None, true)
    } else {
        (Some(fix), false)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn updates_start_from_the_fix_until_a_refresh_is_due_and_the_round_can_afford_it() {
        // Later than now by more than REFRESH: the times before it below all exist.
        let now = Instant::now() + 2 * REFRESH;
        let fix = [1.0, 2.0, 0.5];
        let mut t = TagState {
            warm: Some(fix),
            ..TagState::default()
        };
        // Settled from the grid, read again on a later pass: from the fix.
        assert_eq!(start(&t, now, Duration::ZERO), (Some(fix), false));
        // Updated from the fix for less than REFRESH: still from the fix.
        t.warm_since = Some(now - REFRESH / 2);
        assert_eq!(start(&t, now, Duration::ZERO), (Some(fix), false));
        // For REFRESH: from the grid, unless the round spent its refresh budget already.
        t.warm_since = Some(now - REFRESH);
        assert_eq!(start(&t, now, Duration::ZERO), (None, true));
        assert_eq!(start(&t, now, REFRESH_BUDGET), (Some(fix), false));
        // No converged fix: from the grid, not as a refresh.
        t.warm = None;
        assert_eq!(start(&t, now, Duration::ZERO), (None, false));
    }
}
