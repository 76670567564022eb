//! The live localizer's estimates into the MCAP output (`--mcap`) and the live view
//! (`--foxglove`), for every command that localizes live: `sim`, `proxy`, `replay` and
//! `worker` (docs/robotics.md). It names the localizer and the recordings, so it is neither
//! of them: `src/record/` names no localizer.

use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use crate::localize::estimate::State;
use crate::localize::shared::{reason, Shared, TagView};
use crate::record::mcap::estimates::{EstimateItem, EstimateState};
use crate::record::mcap::geo::ReceivedPoses;
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
    let next_scene = match pacing {
        ScenePacing::ByTruth => None,
        ScenePacing::ByEstimates => Some(Arc::new(AtomicU64::new(0))),
    };
    estimates_paced(shared, sender, now, next_scene);
}

/// [`estimates_to_mcap`], the scene written when `next_scene` (UTC µs) is due, if given.
fn estimates_paced(
    shared: &Shared,
    sender: McapSender,
    now: impl Fn() -> u64 + Send + Sync + 'static,
    next_scene: Option<Arc<AtomicU64>>,
) {
    let dropped = AtomicU64::new(0);
    shared.on_publish(move |tag: &Arc<TagView>| {
        let at = now();
        let mut sent = sender.try_send(McapItem::Estimate(estimate_item(at, tag)));
        if let Some(next_scene) = next_scene
            .as_ref()
            .filter(|n| at >= n.load(Ordering::Relaxed))
        {
            next_scene.store(at.saturating_add(SCENE_INTERVAL_US), Ordering::Relaxed);
            sent &= sender.try_send(McapItem::Scene(at));
        }
        if !sent && !sender.is_closed() && dropped.fetch_add(1, Ordering::Relaxed) == 0 {
            tracing::warn!("the MCAP writer is behind: estimates are dropped while it is");
        }
    });
}

/// Least time between two poses of one antenna written to the MCAP output (µs of the poses'
/// own clock): 10 Hz, whatever rate they come at.
pub const POSE_INTERVAL_US: u64 = 100_000;

/// Hands the antenna poses the localizer takes from now on (`POST /api/poses`, MQTT, a pose
/// file) to `sender`, logged at `now()` (UTC µs): of each antenna's, at most one every
/// [`POSE_INTERVAL_US`] of the poses' time; each batch is one item of the queue, offered
/// without waiting (dropped, with a warning, when there is no room). When the scene is due
/// (`next_scene`, shared with the estimates'), the scene as well.
fn poses_to_mcap(
    shared: &Shared,
    sender: McapSender,
    now: impl Fn() -> u64 + Send + Sync + 'static,
    next_scene: Arc<AtomicU64>,
) {
    let last: Mutex<HashMap<(String, u16), u64>> = Mutex::default();
    let dropped = AtomicU64::new(0);
    shared.on_poses(move |batch| {
        let mut poses = Vec::new();
        {
            // A holder that panicked leaves times that are still right.
            let mut last = last.lock().unwrap_or_else(|e| e.into_inner());
            for p in batch {
                let reader = p.reader.as_ref().map(|r| r.as_str()).unwrap_or("");
                let key = (reader.to_string(), p.antenna);
                let due = last
                    .get(&key)
                    .is_none_or(|t| p.t_us >= t.saturating_add(POSE_INTERVAL_US) || p.t_us < *t);
                if due {
                    last.insert(key, p.t_us);
                    poses.push((reader.to_string(), p.t_us, p.antenna, p.pose));
                }
            }
        }
        if poses.is_empty() {
            return;
        }
        let at = now();
        let mut sent = sender.try_send(McapItem::Poses(ReceivedPoses {
            received_us: at,
            poses,
        }));
        if at >= next_scene.load(Ordering::Relaxed) {
            next_scene.store(at.saturating_add(SCENE_INTERVAL_US), Ordering::Relaxed);
            sent &= sender.try_send(McapItem::Scene(at));
        }
        if !sent && !sender.is_closed() && dropped.fetch_add(1, Ordering::Relaxed) == 0 {
            tracing::warn!("the MCAP writer is behind: antenna poses are dropped while it is");
        }
    });
}

/// With both a live localizer (`shared`) and an MCAP output (`mcap`): [`estimates_to_mcap`]
/// at the wall clock, the estimates pacing the scene, and the antenna poses received
/// (`proxy`, `replay`, `worker`).
pub fn by_wall_clock(shared: Option<&Shared>, mcap: Option<&McapThread>) {
    if let (Some(shared), Some(mcap)) = (shared, mcap) {
        let next_scene = Arc::new(AtomicU64::new(0));
        estimates_paced(
            shared,
            mcap.sender(),
            crate::utc::now_us,
            Some(next_scene.clone()),
        );
        poses_to_mcap(shared, mcap.sender(), crate::utc::now_us, next_scene);
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
