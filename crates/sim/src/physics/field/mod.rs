//! Which tags are in an antenna's field — within reach and powered by the forward link — at
//! the start of a 25 ms bucket (an epoch of inventory rounds, [`super::rounds`]), without
//! evaluating the full channel of every tag in every bucket.
//!
//! Time is cut into intervals on a fixed grid ([`MAX_SPAN_US`] long, halved while the antenna
//! moves or turns too much in them, down to one bucket), so the interval of a bucket depends on
//! nothing but the bucket. For each interval, bounds on how far the antenna and each tag can
//! move give every tag a status valid at every bucket start in it, on every channel:
//! * **out**: beyond reach, or even the most favourable gains, distances and an in-phase sum
//!   of all paths (|a₀| + Σ|aᵢ|) stay below the power threshold;
//! * **in**: within reach and even the least favourable direct path minus every reflected
//!   path at its strongest (|a₀| − Σ|aᵢ|) clears the threshold;
//! * **undecided**: evaluated exactly (the channel of [`super::multipath`]) when drawn.
//!
//! Once neither the antenna nor any tag moves any more, one interval lasts for ever and the
//! field of each channel is evaluated once.
//!
//! An undecided tag drawn in a bucket is first tested with the antenna's exact position then:
//! the phasor sum with the gain table's bounds (and the exact sum's phase factors), whose
//! error is bounded, decides unless the amplitude lies within that bound of the threshold,
//! when the exact sum of [`super::multipath`] does. A decision so made is kept for the
//! antenna's later buckets on the same channel for as long as a bound on how fast the
//! amplitude can change (from the antenna's and the tag's top speeds and the boresight's turn
//! rate) proves that it still holds ([`Near::steady`](near::Near::steady)).
//!
//! An epoch's rounds take every in and every undecided tag that the exact evaluation puts in
//! the field (`Model::settle`). The bounds keep margins far above
//! rounding errors, so they never change which tags are in the field (unit tests check every
//! decision, and every kept decision up to its expiry, against the exact evaluation on the
//! fixtures and on a scenario where everything moves).

mod cache;
mod draw;
mod gains;
mod grid;
mod near;
#[cfg(test)]
mod tests;

pub(super) use cache::{FieldCache, Rates};
pub(super) use draw::Bucket;
pub(super) use gains::GainTable;
pub(super) use grid::Classified;
pub use grid::MAX_SPAN_US;

use super::rssi;

/// Added to every distance bound (m): far above the rounding errors of either computation.
const SLACK_M: f64 = 1e-9;
/// Added to every direction-cosine bound.
const SLACK_COS: f64 = 1e-9;
/// Relative margin on every gain and power-threshold bound.
const SLACK_REL: f64 = 1e-9;

/// The forward link powers a tag when A = √g₀·|1 + Σ Hᵢ|/D reaches this over λ:
/// P_tag = P_tx − L + 10·log10(G_T) + 20·log10(λ/4π) + 20·log10(A) ≥ the tag's sensitivity.
fn amplitude_threshold(spec: &crate::scenario::AntennaSpec, tx_power_dbm: f64) -> f64 {
    10f64.powf(
        (spec.tag_sensitivity_dbm - tx_power_dbm + spec.cable_loss_db - rssi::TAG_GAIN_DBI) / 20.0,
    ) * 4.0
        * std::f64::consts::PI
}

/// The grid point at or after `t_us` (`u64::MAX` stays): where the interval that lasts for
/// ever begins once nothing moves.
pub(super) fn rest_grid(t_us: u64) -> u64 {
    t_us.div_ceil(MAX_SPAN_US).saturating_mul(MAX_SPAN_US)
}

/// Reach of an antenna: r·(1 + 4σ_r).
pub(super) fn reach_m(spec: &crate::scenario::AntennaSpec) -> f64 {
    spec.range_m * (1.0 + super::inventory::RANGE_SIGMAS * spec.range_sigma)
}
