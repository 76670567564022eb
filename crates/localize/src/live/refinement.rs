//! Live pose refinement: with a stated pose error, the antenna positions the phases were
//! filed with are corrected from every tag's phases ([`crate::refine`]) as the
//! reads' clock moves on, and the tags whose corrections moved are estimated again.

use std::sync::Arc;
use std::time::Instant;

use super::Worker;
use crate::estimator::Takes;

/// Reads' time between two refinements of the poses, at the least (µs); later in a long
/// run, a tenth of the time read so far.
pub const REFINE_EVERY_US: u64 = 2_000_000;

/// A tag is estimated again after a refinement of the poses when the corrections at its reads
/// moved by more than this (m).
pub const REFINED_SAME_M: f64 = 5e-4;

impl Worker {
    /// With a stated pose error and a phase estimator, the antenna positions corrected again
    /// from every tag once the reads' clock has moved on by [`REFINE_EVERY_US`] or a tenth of
    /// the time read so far, whichever is longer (`last`: whenever a read came since), and
    /// every estimated tag whose reads' corrections moved by more than [`REFINED_SAME_M`]
    /// marked for a new estimate on them. Paced by the reads' clock alone, so the estimates do
    /// not depend on the machine's load.
    pub(super) fn refine_poses(&mut self, last: bool) {
        let Some(m) = self.settings.geometry.pose_error else {
            return;
        };
        let phase = self.settings.estimator.locator().takes() == Takes::Phases;
        let Some((first, newest)) = self.read_span_us.filter(|_| phase) else {
            return;
        };
        let due = match self.refined_at_us {
            None => true,
            Some(at) if last => newest > at,
            Some(at) => {
                newest.saturating_sub(at) >= REFINE_EVERY_US.max(newest.saturating_sub(first) / 10)
            }
        };
        if !due {
            return;
        }
        self.refined_at_us = Some(newest);
        let new = crate::refine::corrections(&self.ingest, &self.settings.geometry, &m);
        let old = self.settings.geometry.pose_corrections.take();
        let now = Instant::now();
        for (epc, t) in &mut self.tags {
            // Estimated again where the corrections at its reads moved.
            let moved = || {
                self.ingest.tag_series(epc).any(|(key, series)| {
                    series.samples().iter().any(|s| {
                        let a = new.at(&key.1, s.t_us);
                        let b = old.as_ref().map_or([0.0; 2], |c| c.at(&key.1, s.t_us));
                        (a[0] - b[0]).hypot(a[1] - b[1]) > REFINED_SAME_M
                    })
                })
            };
            if t.last_estimate.is_some() && t.dirty_since.is_none() && moved() {
                t.dirty_since = Some(now);
            }
        }
        self.settings.geometry.pose_corrections = Some(Arc::new(new));
    }
}
