//! The one trait every estimator implements ([`Locate`]): its name, the calibration it wants,
//! what it reads of a tag ([`Takes`]) and needs of a setting ([`Need`]), whether it fits the
//! height, and one tag's fix from what [`Tag`] holds. [`crate::estimate::Estimator`] names the estimators; its
//! [`locator`](crate::estimate::Estimator::locator) gives each one's implementation.

use crate::calibrate::Calibration;
use crate::fix::{Fix3, NoFix, Obs};
use crate::geometry::Geometry;
use crate::ingest::Ingest;
use crate::observe::Observed;

/// The phase sign the estimators are given: the phases are times their readers' own signs
/// ([`crate::observe`]), so every estimator sees s = +1.
pub const SIGN: f64 = 1.0;

/// What an estimator locates one tag from.
#[derive(Clone, Copy, Debug)]
pub struct Tag<'a> {
    /// The tag's phases, calibrated, times their readers' signs ([`SIGN`]).
    pub observed: &'a Observed,
    /// The reads filed so far, every tag's (the references' too).
    pub ingest: &'a Ingest,
    /// The tag's EPC.
    pub epc: &'a str,
    /// The readers' geometry.
    pub geometry: &'a Geometry,
    /// The tag's last fix, for an estimator that can start from it ([`Locate::warm_starts`]).
    pub hint: Option<[f64; 3]>,
    /// What the estimator measured on the reference tags ([`Locate::calibration`]).
    pub calibration: &'a Calibration,
}

/// What of a tag's reads an estimator locates it from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Takes {
    /// The unwrapped phases with the antenna positions they were filed with, corrected where
    /// the poses are refined ([`Tag::observed`]).
    Phases,
    /// The series' phases against the reference tags', the antenna positions only telling
    /// poses apart.
    References,
    /// The phases as reported per (reader, antenna) track, with the antenna's pose samples
    /// along the path driven between reads (so the whole pose track is kept).
    Tracks,
}

/// What an estimator needs of a setting to locate anything at all.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Need {
    /// Antennas at two heights or more.
    Heights,
    /// Reference tags at known positions.
    References,
    /// Readers whose phase offset φ0 is 0 on every channel (the phases taken as reported).
    CalibratedReader,
}

/// One estimator: locates a tag from its reads.
pub trait Locate: Sync {
    /// Its name, as [`crate::estimate::Estimator::name`] gives it.
    fn name(&self) -> &'static str;

    /// What of a tag's reads it locates the tag from.
    fn takes(&self) -> Takes;

    /// Whether it fits the tag's height to the phases `obs` (else it assumes the height, or
    /// does not fit the phases at all); the pose error's share of the covariance is
    /// propagated in 3D when it does, in 2D otherwise ([`crate::uncertainty::pose_share`]).
    fn fits_height(&self, _obs: &[Obs]) -> bool {
        false
    }

    /// What it needs of a setting to locate anything: nothing by default.
    fn needs(&self) -> &'static [Need] {
        &[]
    }

    /// Whether it starts from [`Tag::hint`] when given one (else it ignores it).
    fn warm_starts(&self) -> bool {
        false
    }

    /// What it measures on the reference tags of `g` in `ingest` once for every tag (antenna
    /// offsets, the references located from each other): nothing by default.
    fn calibration(&self, _ingest: &Ingest, _g: &Geometry) -> Calibration {
        Calibration::default()
    }

    /// The tag's position with its covariance (3×3; a 2D fix's z row and column 0).
    fn locate(&self, tag: &Tag<'_>) -> Result<Fix3, NoFix>;
}
