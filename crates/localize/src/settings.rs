//! The localizer's settings, in one place for every way it runs: the live worker's
//! ([`Settings`]), the settings file a real reader's data needs ([`SettingsFile`]: phase sign,
//! the side the antennas face, the tags' height, reference tags, clock offsets, the robot's
//! pose error) and the pose error model the pose refinement assumes ([`PoseErrorModel`]).

use llrp_gateway_vocab::epc::Epc;
use llrp_gateway_vocab::reader_name::ReaderName;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::Deserialize;

use crate::estimate::{Estimator, Geometry};
use crate::series::Ambiguity;

/// Why a settings file could not be used.
#[derive(Debug, thiserror::Error)]
pub enum SettingsError {
    /// It could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A key of it is bad.
    #[error("{path}: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// Why, naming the field.
        message: String,
    },
}

/// How the live localizer works.
#[derive(Clone, Debug)]
pub struct Settings {
    /// The estimator run on every tag.
    pub estimator: Estimator,
    /// The per-reader settings the estimator is told.
    pub geometry: Geometry,
    /// Whether the readers report phase with Impinj's π ambiguity.
    pub ambiguity: Ambiguity,
    /// Longest gap between two reads of one series segment (µs).
    pub max_gap_us: u64,
    /// Reads weaker than this (dBm) are set aside ([`crate::ingest::Ingest::with_min_rssi`]).
    pub min_rssi_dbm: Option<f64>,
    /// Longest gap between two pose samples a read may be interpolated in (µs).
    pub pose_reach_us: u64,
    /// A tag is re-estimated at most this often.
    pub min_interval: Duration,
    /// Longest the worker computes estimates before it takes in input again.
    pub compute_budget: Duration,
    /// Inputs the tap holds before it drops.
    pub tap_capacity: usize,
    /// Phases kept per tag (see the module's documentation).
    pub max_samples_per_tag: usize,
    /// Derive the geometry from this settings file and the first pose of each reader as it
    /// comes (as `localize` does offline from its pose file), for a localizer started before
    /// any pose: a worker, or a proxy whose robot posts its poses.
    pub derive_geometry: Option<SettingsFile>,
    /// Called every few seconds to give the allocator's free memory back to the system (the
    /// application passes glibc's `malloc_trim`); `None`: nothing is called.
    pub release_memory: Option<fn()>,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            estimator: Estimator::Relock,
            geometry: Geometry {
                tag_height_m: 0.5,
                phase_sign: 1.0,
                facing: [0.0, 1.0],
                reach_m: 4.0,
                references: Vec::new(),
                readers: BTreeMap::new(),
                pose_error: None,
                pose_corrections: None,
                tag_curvature_sigma_rad: 0.0,
            },
            ambiguity: Ambiguity::None,
            max_gap_us: crate::series::DEFAULT_MAX_GAP_US,
            min_rssi_dbm: None,
            pose_reach_us: crate::poses::DEFAULT_REACH_US,
            min_interval: Duration::from_millis(50),
            compute_budget: Duration::from_millis(50),
            tap_capacity: 4096,
            max_samples_per_tag: 4096,
            derive_geometry: None,
            release_memory: None,
        }
    }
}

/// A reference tag of the settings file.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ReferenceTag {
    /// EPC, hex in any case (`references[i].epc` names one that is not).
    pub epc: Epc,
    /// x (m).
    pub x: f64,
    /// y (m).
    pub y: f64,
    /// z (m).
    pub z: f64,
}

/// The settings file (JSON; every key optional).
#[derive(Clone, Debug, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SettingsFile {
    /// Height assumed for the tags by the 2D estimators (m).
    pub tag_height_m: Option<f64>,
    /// +1, or −1 for a reader that reports the phase negated.
    pub phase_sign: Option<f64>,
    /// The side the antennas face, `[x, y]`.
    pub facing: Option<[f64; 2]>,
    /// Farthest a tag is searched for from the path (m).
    pub reach_m: Option<f64>,
    /// The reader reports phase with Impinj's π ambiguity.
    #[serde(default)]
    pub pi_ambiguity: bool,
    /// Reads weaker than this (dBm) are set aside: their phase noise slips the unwrapping.
    pub min_rssi_dbm: Option<f64>,
    /// Reference tags at known positions (fingerprinting).
    #[serde(default)]
    pub references: Vec<ReferenceTag>,
    /// Per reader, reader time − robot time of the pose file (µs).
    #[serde(default)]
    pub clock_offsets_us: BTreeMap<ReaderName, i64>,
    /// Where the antennas sit on the robot, for poses taken from a robot's bag (the robot's
    /// pose ⊕ the offset is the antenna's pose).
    #[serde(default)]
    pub antenna_offsets: Vec<AntennaOffset>,
    /// Per reader name, its own phase sign and facing (the keys above for the others).
    #[serde(default)]
    pub readers: BTreeMap<ReaderName, ReaderSettings>,
    /// The robot's pose error, where its poses come from a localization stack: the poses
    /// are then refined from the tags' phases ([`crate::refine`]).
    pub pose_error: Option<PoseErrorSettings>,
    /// σ across tags of each tag's own phase curvature (rad per rad²), widening every
    /// estimate's covariance ([`Geometry::tag_curvature_sigma_rad`]); none: 0.
    #[serde(default)]
    pub tag_curvature_sigma_rad: Option<f64>,
}

/// An antenna's offset in the robot frame (x forward, y left, z up; the settings file's
/// `antenna_offsets`, or `localize --antenna-offset`).
#[derive(Clone, Debug, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct AntennaOffset {
    /// The reader it is of (`None`: every reader).
    #[serde(default)]
    pub reader: Option<ReaderName>,
    /// The antenna port (`None`: every antenna without an offset of its own).
    #[serde(default)]
    pub antenna: Option<u16>,
    /// Forward of the robot's origin (m).
    pub x: f64,
    /// Left of it (m).
    pub y: f64,
    /// Above it (m).
    #[serde(default)]
    pub z: f64,
    /// The boresight's yaw from the robot's heading (degrees, counter-clockwise).
    #[serde(default)]
    pub yaw_deg: f64,
}

/// The pose error of the settings file's `pose_error`.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct PoseErrorSettings {
    /// σ of the error in x and in y (m).
    pub sigma_m: f64,
    /// Its correlation time (s).
    pub correlation_s: f64,
}

/// One reader's own settings in the settings file.
#[derive(Clone, Debug, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ReaderSettings {
    /// +1, or −1 for a reader that reports the phase negated.
    pub phase_sign: Option<f64>,
    /// The side its antennas face, `[x, y]`.
    pub facing: Option<[f64; 2]>,
}

/// Why `phase_sign` is not one a reader has.
fn check_sign(sign: Option<f64>) -> Result<(), String> {
    match sign.filter(|&v| v != 1.0 && v != -1.0) {
        Some(v) => Err(format!("must be 1 or -1, got {v}")),
        None => Ok(()),
    }
}

/// Why `facing` is not a direction.
fn check_facing(facing: Option<[f64; 2]>) -> Result<(), String> {
    match facing.filter(|f| {
        let n = f[0].hypot(f[1]);
        n.is_nan() || n.is_infinite() || n <= 0.0
    }) {
        Some(f) => Err(format!("must be a non-zero direction, got {f:?}")),
        None => Ok(()),
    }
}

impl SettingsFile {
    /// Reads and checks a settings file.
    pub fn load(path: &Path) -> Result<SettingsFile, SettingsError> {
        let text = std::fs::read_to_string(path).map_err(|source| SettingsError::Io {
            path: path.to_owned(),
            source,
        })?;
        let bad = |message: String| SettingsError::Invalid {
            path: path.to_owned(),
            message,
        };
        let mut de = serde_json::Deserializer::from_str(&text);
        let s: SettingsFile = serde_path_to_error::deserialize(&mut de)
            .map_err(|e| bad(format!("{}: {}", e.path(), e.inner())))?;
        check_sign(s.phase_sign).map_err(|e| bad(format!("phase_sign: {e}")))?;
        if let Some(v) = s.min_rssi_dbm.filter(|v| !v.is_finite()) {
            return Err(bad(format!("min_rssi_dbm: not a finite number: {v}")));
        }
        if let Some(h) = s.tag_height_m.filter(|h| !h.is_finite()) {
            return Err(bad(format!("tag_height_m: not a finite number: {h}")));
        }
        if let Some(r) = s
            .reach_m
            .filter(|&r| r.is_nan() || r.is_infinite() || r <= 0.0)
        {
            return Err(bad(format!("reach_m: must be a positive number, got {r}")));
        }
        check_facing(s.facing).map_err(|e| bad(format!("facing: {e}")))?;
        for (name, r) in &s.readers {
            check_sign(r.phase_sign).map_err(|e| bad(format!("readers.{name}.phase_sign: {e}")))?;
            check_facing(r.facing).map_err(|e| bad(format!("readers.{name}.facing: {e}")))?;
        }
        if let Some(e) = &s.pose_error {
            let positive = |v: f64| v.is_finite() && v > 0.0;
            if !positive(e.sigma_m) {
                let v = e.sigma_m;
                return Err(bad(format!(
                    "pose_error.sigma_m: must be a positive number, got {v}"
                )));
            }
            if !positive(e.correlation_s) {
                let v = e.correlation_s;
                return Err(bad(format!(
                    "pose_error.correlation_s: must be a positive number, got {v}"
                )));
            }
        }
        Ok(s)
    }
}

/// The pose error the smoother assumes: x and y, each a Gauss–Markov process.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseErrorModel {
    /// σ of the error in x and in y (m).
    pub sigma_m: f64,
    /// Its correlation time (s).
    pub correlation_s: f64,
    /// σ of one read's range from its phase (m): σ_φ·λ/4π.
    pub range_sigma_m: f64,
}

impl PoseErrorModel {
    /// An error of σ `sigma_m` in x and y with correlation time `correlation_s`, reads whose
    /// range is good to 3 mm (σ_φ 0.1 rad at 866 MHz).
    pub fn new(sigma_m: f64, correlation_s: f64) -> PoseErrorModel {
        PoseErrorModel {
            sigma_m,
            correlation_s,
            range_sigma_m: 0.003,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bad_reader_name_is_named_with_its_reason() {
        let dir = std::env::temp_dir().join(format!("llrp-settings-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("a temporary folder");
        let path = dir.join("settings.json");
        let load = |text: &str| {
            std::fs::write(&path, text).expect("written");
            SettingsFile::load(&path)
        };
        let good = load(r#"{"clock_offsets_us": {"dock 1": 5}, "readers": {"R": {}}}"#)
            .expect("good names");
        assert_eq!(good.clock_offsets_us.get("dock 1"), Some(&5));
        assert!(good.readers.contains_key("R") && !good.readers.contains_key("r"));
        let e = load(r#"{"clock_offsets_us": {"": 5}}"#)
            .expect_err("an empty name")
            .to_string();
        assert!(
            e.contains("clock_offsets_us") && e.contains("the reader name is empty"),
            "{e}"
        );
        let e = load(r#"{"readers": {"r\t": {}}}"#)
            .expect_err("a tab")
            .to_string();
        assert!(
            e.contains("readers") && e.contains("control character"),
            "{e}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
