//! The live localizer's estimates in an MCAP file: each tag's estimate, as the localizer
//! publishes it, as `llrp_gateway_msgs/msg/TagEstimate` on `/estimates/tags` (the package's
//! `.msg` file is the schema).

use std::io::Write;
use std::sync::Arc;

use super::cdr::Cdr;
use super::geo::WORLD;
use super::msgs::MsgType;
use super::{McapError, McapOut};
use crate::localize::estimate::State;
use crate::localize::shared::{reason, TagView};

/// The topic of the estimates.
pub const TOPIC: &str = "/estimates/tags";

/// One published estimate and when it was published.
#[derive(Clone, Debug)]
pub struct EstimateItem {
    /// When the localizer published it, UTC µs (the MCAP log time; a simulation's clock).
    pub logged_us: u64,
    /// The tag as the localizer shows it: the estimate and the read statistics.
    pub tag: Arc<TagView>,
}

/// The message's `state` of `state` (its constants `STATE_*`).
pub fn state_code(state: State) -> u8 {
    match state {
        State::Converging => 0,
        State::Converged => 1,
        State::InsufficientGeometry => 2,
    }
}

/// `llrp_gateway_msgs/msg/TagEstimate` of `tag`.
pub fn tag_estimate(cdr: &mut Cdr, tag: &TagView) -> Vec<u8> {
    let e = &tag.estimate;
    cdr.header(e.last_update_us.saturating_mul(1000), WORLD)
        .string(&e.epc.to_uppercase())
        .string(e.estimator)
        .u8(state_code(e.state));
    for v in e.estimate.unwrap_or([f64::NAN; 3]) {
        cdr.f64(v);
    }
    for v in e.covariance.unwrap_or([f64::NAN; 9]) {
        cdr.f64(v);
    }
    cdr.f64(e.pose_sigma_m.unwrap_or(f64::NAN))
        .u32(u32::try_from(e.samples).unwrap_or(u32::MAX))
        .u64(tag.reads)
        .f64(tag.reads_per_s)
        .time(tag.last_seen_us.saturating_mul(1000))
        .string(reason(e).as_deref().unwrap_or(""))
        .finish()
}

impl<W: Write> McapOut<W> {
    /// One estimate on `/estimates/tags`: logged when it was published, its publish time and
    /// stamp the time of the newest phase it rests on (the log time when it has none). The
    /// scene ([`super::scene`]) shows it from then on.
    pub fn estimate(&mut self, item: &EstimateItem) -> Result<(), McapError> {
        let log_ns = item.logged_us.saturating_mul(1000);
        let publish_ns = match item.tag.estimate.last_update_us {
            0 => log_ns,
            us => us.saturating_mul(1000),
        };
        self.scene.estimate(&item.tag);
        let bytes = tag_estimate(&mut self.cdr, &item.tag);
        self.write(TOPIC, MsgType::TagEstimate, log_ns, publish_ns, &bytes)
    }
}
