//! The live localizer's estimates in an MCAP file: each tag's estimate, as the localizer
//! publishes it, as `llrp_gateway_msgs/msg/TagEstimate` on `/estimates/tags` (the package's
//! `.msg` file is the schema).

use std::io::Write;

use super::cdr::Cdr;
use super::geo::WORLD;
use super::msgs::MsgType;
use super::{McapError, McapOut};

/// The topic of the estimates.
pub const TOPIC: &str = "/estimates/tags";

/// How far an estimate has come (the localizer's states).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EstimateState {
    /// A position, not yet converged.
    Converging,
    /// A converged position.
    Converged,
    /// Too little geometry for a position.
    InsufficientGeometry,
}

impl EstimateState {
    /// The message's `state` (its constants `STATE_*`).
    pub fn code(self) -> u8 {
        match self {
            EstimateState::Converging => 0,
            EstimateState::Converged => 1,
            EstimateState::InsufficientGeometry => 2,
        }
    }

    /// Its name as the HTTP API writes it.
    pub fn name(self) -> &'static str {
        match self {
            EstimateState::Converging => "converging",
            EstimateState::Converged => "converged",
            EstimateState::InsufficientGeometry => "insufficient_geometry",
        }
    }
}

/// One tag's estimate as the live localizer published it, and when.
#[derive(Clone, Debug, PartialEq)]
pub struct EstimateItem {
    /// When the localizer published it, UTC µs (the MCAP log time; a simulation's clock).
    pub logged_us: u64,
    /// EPC, upper-case hex.
    pub epc: String,
    /// The estimator's name.
    pub estimator: String,
    /// How far it has come.
    pub state: EstimateState,
    /// Position (m), when there is one.
    pub position: Option<[f64; 3]>,
    /// Covariance of the position, 3×3 row-major (m²).
    pub covariance: Option<[f64; 9]>,
    /// σ along the worse axis of the covariance's share from the antenna poses' error (m).
    pub pose_sigma_m: Option<f64>,
    /// Phases the estimate rests on.
    pub samples: u32,
    /// Time of the newest phase (UTC µs, the reads' clock); 0 when none.
    pub newest_phase_us: u64,
    /// Reads of the tag taken in.
    pub reads: u64,
    /// Reads per second over the last rate window.
    pub reads_per_s: f64,
    /// Time of the tag's newest read (UTC µs).
    pub last_seen_us: u64,
    /// Why it is not converged, in words (empty when it is).
    pub reason: String,
}

/// `llrp_gateway_msgs/msg/TagEstimate` of `e`.
pub fn tag_estimate(cdr: &mut Cdr, e: &EstimateItem) -> Vec<u8> {
    cdr.header(e.newest_phase_us.saturating_mul(1000), WORLD)
        .string(&e.epc.to_uppercase())
        .string(&e.estimator)
        .u8(e.state.code());
    for v in e.position.unwrap_or([f64::NAN; 3]) {
        cdr.f64(v);
    }
    for v in e.covariance.unwrap_or([f64::NAN; 9]) {
        cdr.f64(v);
    }
    cdr.f64(e.pose_sigma_m.unwrap_or(f64::NAN))
        .u32(e.samples)
        .u64(e.reads)
        .f64(e.reads_per_s)
        .time(e.last_seen_us.saturating_mul(1000))
        .string(&e.reason)
        .finish()
}

impl<W: Write> McapOut<W> {
    /// One estimate on `/estimates/tags`: logged when it was published, its publish time and
    /// stamp the time of the newest phase it rests on (the log time when it has none). The
    /// scene ([`super::scene`]) shows it from then on.
    pub fn estimate(&mut self, item: &EstimateItem) -> Result<(), McapError> {
        let log_ns = item.logged_us.saturating_mul(1000);
        let publish_ns = match item.newest_phase_us {
            0 => log_ns,
            us => us.saturating_mul(1000),
        };
        self.scene.estimate(item);
        let bytes = tag_estimate(&mut self.cdr, item);
        self.write(TOPIC, MsgType::TagEstimate, log_ns, publish_ns, &bytes)
    }
}
