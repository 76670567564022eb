//! `localize --mcap FILE`: the offline localizer's estimates as an MCAP file, each tag's as
//! `llrp_gateway_msgs/msg/TagEstimate` on `/estimates/tags` and all of them drawn in one
//! `foxglove_msgs/msg/SceneUpdate` on `/scene` (docs/robotics.md).

use crate::files::Output;
use crate::localize::estimate::State;
use crate::localize::shared::TagJson;
use crate::record::mcap::estimates::{EstimateItem, EstimateState};
use crate::record::mcap::{McapError, McapOut};

/// Writes `tags`' estimates and their scene to `file`, all logged at the newest read's time,
/// and puts the file in place.
pub fn write(file: Output, tags: &[TagJson]) -> Result<(), McapError> {
    let mut mcap = McapOut::new(file)?;
    let at_us = tags.iter().map(|t| t.last_seen).max().unwrap_or(0);
    for t in tags {
        mcap.estimate(&item(at_us, t))?;
    }
    mcap.scene_at(at_us)?;
    let (_, file) = mcap.finish()?;
    file.commit()?;
    Ok(())
}

/// The MCAP file's estimate of `t`, logged at `logged_us`.
fn item(logged_us: u64, t: &TagJson) -> EstimateItem {
    EstimateItem {
        logged_us,
        epc: t.epc.to_uppercase(),
        estimator: t.estimator.to_string(),
        state: match t.state {
            State::Converging => EstimateState::Converging,
            State::Converged => EstimateState::Converged,
            State::InsufficientGeometry => EstimateState::InsufficientGeometry,
        },
        position: t.estimate.map(|p| [p.x, p.y, p.z]),
        covariance: t.covariance,
        pose_sigma_m: None,
        samples: u32::try_from(t.samples).unwrap_or(u32::MAX),
        newest_phase_us: t.last_seen,
        reads: 0,
        reads_per_s: t.reads_per_s,
        last_seen_us: t.last_seen,
        reason: t.reason.clone().unwrap_or_default(),
    }
}
