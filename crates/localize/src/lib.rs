//! The localizer (issue 18): antenna poses from a pose file or a live feed, interpolated to
//! each read's time ([`poses`]), per (reader, antenna, tag, channel) phase series unwrapped
//! with the λ/4 motion check ([`series`]), reads filed into them or set aside by reason
//! ([`ingest`]); the estimators, each implementing one trait ([`estimator::Locate`]): Phase
//! ReLock in 2D and 3D ([`relock`], with the joining of split series, [`join`], and the
//! antennas' calibration from reference tags, [`calibrate`]), the min-distance linear model
//! ([`linear`]), hyperbolic intersection ([`hyperbolic`]), 3D by loci intersection
//! ([`loci3d`]), fingerprinting ([`fingerprint`]), the multi-hypothesis EKF ([`mhekf`]) and
//! distributed WLS by consensus ([`wls`]); estimates with covariance and state ([`estimate`]),
//! the pose error's share of it ([`uncertainty`]); the live worker ([`live`], [`shared`]),
//! offline localization ([`offline`]). The application's `localize` command and `bench
//! localize` drive it from above. It sees only reads and poses (the vocabulary crate's), never
//! simulator internals, so it works the same on a real reader's data; it depends on no async
//! runtime, HTTP or MQTT crate.

pub mod calibrate;
pub mod estimate;
pub mod estimator;
pub mod fingerprint;
pub mod fix;
pub mod geometry;
pub mod hyperbolic;
pub mod ingest;
pub mod join;
mod lanes;
pub mod linear;
pub mod live;
pub mod loci3d;
pub mod mhekf;
pub mod observe;
pub mod offline;
pub mod outliers;
pub mod poses;
pub mod refine;
pub mod relock;
pub mod robust;
pub mod series;
pub mod settings;
pub mod shared;
#[cfg(test)]
mod synthetic;
pub mod uncertainty;
pub mod wls;

/// A point or vector in metres (x, y, z).
pub type Vec3 = [f64; 3];

/// Distance between two points (m).
pub fn distance(a: Vec3, b: Vec3) -> f64 {
    (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt()
}

/// Speed of light (m/s), for a channel's wavelength.
pub const SPEED_OF_LIGHT: f64 = 299_792_458.0;
