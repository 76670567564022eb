//! The live localizer's estimates into the MCAP output (`--mcap`) and the live view
//! (`--foxglove`), for every command that localizes live: `sim`, `proxy`, `replay` and
//! `worker` (docs/robotics.md). It names the localizer and the recordings, so it is neither
//! of them: `src/record/` names no localizer.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use crate::localize::estimate::State;
use crate::localize::shared::{reason, Shared, TagView};
use crate::record::mcap::estimates::{EstimateItem, EstimateState};
use crate::record::mcap::scene::SCENE_INTERVAL_US;
use crate::record::mcap::{McapItem, McapSender, McapThread};

/// The MCAP file's estimate of `tag`, published at `logged_us` (UTC µs).
pub fn estimate_item(logged_us: u64, tag: &TagView) -> EstimateItem {
    let e = &tag.estimate;
    EstimateItem {
        logged_us,
        epc: e.epc.to_uppercase(),
        estimator: e.estimator.to_string(),
        state: match e.state {
            State::Converging => EstimateState::Converging,
            State::Converged => EstimateState::Converged,
            State::InsufficientGeometry => EstimateState::InsufficientGeometry,
        },
        position: e.estimate,
        covariance: e.covariance,
        pose_sigma_m: e.pose_sigma_m,
        samples: u32::try_from(e.samples).unwrap_or(u32::MAX),
        newest_phase_us: e.last_update_us,
        reads: tag.reads,
        reads_per_s: tag.reads_per_s,
        last_seen_us: tag.last_seen_us,
        reason: reason(e).unwrap_or_default(),
    }
}

/// Whether the estimates also pace the scene.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ScenePacing {
    /// A simulation's truth writes the scene (`sim`): the estimates only join it.
    ByTruth,
    /// The estimates write the scene, at most every [`SCENE_INTERVAL_US`] of `now` (`proxy`,
    /// `replay`, `worker`: no truth there).
    ByEstimates,
}

/// Hands every estimate `shared` publishes from now on to `sender`, logged at `now()` (UTC
/// µs), and with [`ScenePacing::ByEstimates`] the scene as it stands when one is due. The
/// localizer's thread offers them without waiting: an estimate with no room in the queue is
/// dropped, with a warning (those published once the file is finished, silently).
pub fn estimates_to_mcap(
    shared: &Shared,
    sender: McapSender,
    now: impl Fn() -> u64 + Send + Sync + 'static,
    pacing: ScenePacing,
) {
    let dropped = AtomicU64::new(0);
    let next_scene = AtomicU64::new(0);
    shared.on_publish(move |tag: &Arc<TagView>| {
        let at = now();
        let mut sent = sender.try_send(McapItem::Estimate(estimate_item(at, tag)));
        if pacing == ScenePacing::ByEstimates && at >= next_scene.load(Ordering::Relaxed) {
            next_scene.store(at.saturating_add(SCENE_INTERVAL_US), Ordering::Relaxed);
            sent &= sender.try_send(McapItem::Scene(at));
        }
        if !sent && !sender.is_closed() && dropped.fetch_add(1, Ordering::Relaxed) == 0 {
            tracing::warn!("the MCAP writer is behind: estimates are dropped while it is");
        }
    });
}

/// With both a live localizer (`shared`) and an MCAP output (`mcap`): [`estimates_to_mcap`]
/// at the wall clock, the estimates pacing the scene (`proxy`, `replay`, `worker`).
pub fn by_wall_clock(shared: Option<&Shared>, mcap: Option<&McapThread>) {
    if let (Some(shared), Some(mcap)) = (shared, mcap) {
        estimates_to_mcap(
            shared,
            mcap.sender(),
            crate::utc::now_us,
            ScenePacing::ByEstimates,
        );
    }
}

/// With both a live localizer and an MCAP output: the scene as it stands now, the newest
/// estimates', written before the output is finished.
pub fn last_scene(shared: Option<&Shared>, mcap: Option<&McapThread>) {
    if let (Some(_), Some(mcap)) = (shared, mcap) {
        mcap.sender()
            .try_send(McapItem::Scene(crate::utc::now_us()));
    }
}
