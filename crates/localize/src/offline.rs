//! `llrp-gateway localize`: estimates from a recording or a reads file, with a pose file or
//! the reads' own `antenna_pose`, written as the same JSON as `GET /api/tags`.
//!
//! The per-reader settings a real reader's data cannot carry (the phase sign, the side the
//! antennas face, the tags' assumed height, the reference tags, the readers' clock offsets)
//! come from a settings file; without one, the tags are assumed at the first antenna pose's
//! height and on the side its yaw faces, with the phase sign +1.

use llrp_gateway_vocab::epc::Epc;
use std::collections::BTreeMap;
use std::path::PathBuf;

use crate::estimate::{self, Estimate, Estimator, Geometry, ReaderGeometry};
use crate::ingest::{Ingest, SetAside};
use crate::poses::{PoseError, Poses};
use crate::refine::refined_poses;
use crate::series::Ambiguity;
use crate::settings::PoseErrorModel;
pub use crate::settings::{
    AntennaOffset, PoseErrorSettings, ReaderSettings, ReferenceTag, SettingsError, SettingsFile,
};
use crate::shared::{TagJson, TagsJson};
use llrp_gateway_vocab::reads::Read;

/// Why `localize` could not run.
#[derive(Debug, thiserror::Error)]
pub enum OfflineError {
    /// A file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A line of the reads file is bad.
    #[error("{path}: line {line}: {message}")]
    Reads {
        /// The file.
        path: PathBuf,
        /// The line.
        line: usize,
        /// Why.
        message: String,
    },
    /// The pose file is bad.
    #[error("{path}: {source}")]
    Poses {
        /// The file.
        path: PathBuf,
        /// Why.
        source: PoseError,
    },
    /// The settings file cannot be read or is bad.
    #[error(transparent)]
    Settings(#[from] SettingsError),
}

/// What a `localize` run found.
#[derive(Clone, Debug)]
pub struct Outcome {
    /// One estimate per tag, in EPC order, with its newest read time and read rate.
    pub tags: TagsJson,
    /// Reads filed into series.
    pub taken: u64,
    /// Reads set aside, by reason.
    pub set_aside: SetAside,
}

/// The estimator's settings for `reads` and `poses` under `file`: what the file gives, the
/// rest from the first pose (its height, the side its yaw faces).
pub fn geometry(file: &SettingsFile, reads: &[Read], poses: &Poses) -> Geometry {
    let first = reads
        .iter()
        .find_map(|r| r.antenna_pose.as_ref())
        .or_else(|| poses.first().map(|p| &p.pose))
        .map(|p| (p.position[2], p.yaw_rad));
    let (z, yaw) = first.unwrap_or((0.0, std::f64::consts::FRAC_PI_2));
    let towards = |yaw_rad: f64| [yaw_rad.cos(), yaw_rad.sin()];
    let facing = file.facing.unwrap_or(towards(yaw));
    let phase_sign = file.phase_sign.unwrap_or(1.0);
    // Each reader faces where its own first pose does, unless the file says otherwise.
    let mut own: BTreeMap<String, [f64; 2]> = BTreeMap::new();
    for p in poses.first_samples() {
        own.entry(p.reader.as_deref().unwrap_or_default().to_owned())
            .or_insert(towards(p.pose.yaw_rad));
    }
    for r in reads {
        if let (Some(reader), Some(p)) = (&r.reader, &r.antenna_pose) {
            own.entry(reader.to_string()).or_insert(towards(p.yaw_rad));
        }
    }
    for name in file.readers.keys() {
        own.entry(name.to_string()).or_insert(facing);
    }
    let readers = own
        .into_iter()
        .map(|(name, derived)| {
            let mine = file.readers.get(name.as_str()).cloned().unwrap_or_default();
            let r = ReaderGeometry {
                phase_sign: mine.phase_sign.unwrap_or(phase_sign),
                facing: mine.facing.or(file.facing).unwrap_or(derived),
            };
            (name, r)
        })
        .collect();
    Geometry {
        tag_height_m: file.tag_height_m.unwrap_or(z),
        phase_sign,
        facing,
        reach_m: file.reach_m.unwrap_or(4.0),
        references: file
            .references
            .iter()
            .map(|r| (r.epc.clone(), [r.x, r.y, r.z]))
            .collect(),
        readers,
        pose_error: file
            .pose_error
            .as_ref()
            .map(|e| PoseErrorModel::new(e.sigma_m, e.correlation_s)),
        pose_corrections: None,
        tag_curvature_sigma_rad: file.tag_curvature_sigma_rad.unwrap_or(0.0).max(0.0),
    }
}

/// Localizes every tag of `reads` with `estimator`; `progress` is told of each read filed
/// and each tag estimated.
pub fn localize(
    mut reads: Vec<Read>,
    mut poses: Poses,
    file: &SettingsFile,
    estimator: Estimator,
    progress: &mut dyn FnMut(Progress),
) -> Outcome {
    for (reader, offset) in &file.clock_offsets_us {
        poses.set_offset(reader, *offset);
    }
    let g = geometry(file, &reads, &poses);
    let ambiguity = if file.pi_ambiguity {
        Ambiguity::Pi
    } else {
        Ambiguity::None
    };
    // Series want their reads in time order (a recording of several connections, or a
    // merged reads file, may not be).
    reads.sort_by_key(|r| r.t_us);
    let mut stats: BTreeMap<Epc, (u64, u64, u64)> = BTreeMap::new();
    let ingest_on = |poses: Poses| {
        Ingest::new(poses, ambiguity, crate::series::DEFAULT_MAX_GAP_US)
            .with_min_rssi(file.min_rssi_dbm)
    };
    let mut ingest = ingest_on(poses);
    for r in &reads {
        ingest.push(r);
        let s = stats.entry(r.epc.clone()).or_insert((r.t_us, r.t_us, 0));
        s.1 = s.1.max(r.t_us);
        s.2 += 1;
        progress(Progress::Read);
    }
    if let Some(e) = &file.pose_error {
        // The poses refined once, the reads filed again.
        let m = PoseErrorModel::new(e.sigma_m, e.correlation_s);
        let corrected = refined_poses(&ingest, &g, &m);
        ingest = ingest_on(corrected);
        for r in &reads {
            ingest.push(r);
        }
    }
    let epcs: Vec<String> = ingest.tags().map(String::from).collect();
    let mut estimates: BTreeMap<String, Estimate> = BTreeMap::new();
    let calibration = estimate::calibration(&ingest, estimator, &g);
    for epc in epcs {
        let e = estimate::estimate_calibrated(&ingest, &epc, estimator, &g, &calibration);
        estimates.insert(epc, e);
        progress(Progress::Tag);
    }
    let tags = stats
        .into_iter()
        .map(|(epc, (first, last, n))| {
            let span = (last - first) as f64 / 1e6;
            let rate = if span > 0.0 { n as f64 / span } else { 0.0 };
            let e = estimates.remove(epc.as_str()).unwrap_or_else(|| Estimate {
                epc: epc.to_string(),
                estimator: estimator.name(),
                estimate: None,
                covariance: None,
                samples: 0,
                state: estimate::State::InsufficientGeometry,
                last_update_us: 0,
                pose_sigma_m: None,
            });
            TagJson::new(&e, last, rate)
        })
        .collect();
    Outcome {
        tags: TagsJson { tags },
        taken: ingest.taken(),
        set_aside: ingest.set_aside(),
    }
}

/// A step of a `localize` run, for a progress bar.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Progress {
    /// A read was filed.
    Read,
    /// A tag was estimated.
    Tag,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::poses::{Pose, PoseSample};

    fn pose(reader: &str, yaw_deg: f64) -> PoseSample {
        PoseSample {
            t_us: 0,
            reader: Some(reader.parse().expect("a reader name")),
            antenna: 1,
            pose: Pose::from_degrees([0.0, 0.0, 0.8], yaw_deg, 0.0),
        }
    }

    #[test]
    fn each_reader_faces_where_its_first_pose_does_unless_the_file_says_otherwise() {
        let mut poses = Poses::new();
        poses.add(pose("left", 90.0));
        poses.add(pose("right", -90.0));
        let mut file = SettingsFile::default();
        let g = geometry(&file, &[], &poses);
        let near = |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).hypot(a[1] - b[1]) < 1e-9;
        assert!(near(g.facing_of("left"), [0.0, 1.0]), "{g:?}");
        assert!(near(g.facing_of("right"), [0.0, -1.0]), "{g:?}");
        assert_eq!(g.sign_of("right"), 1.0);
        // The file's own values: a default facing for all, a reader's own above it.
        file.facing = Some([1.0, 0.0]);
        file.readers.insert(
            "right".parse().expect("a reader name"),
            ReaderSettings {
                phase_sign: Some(-1.0),
                facing: None,
            },
        );
        let g = geometry(&file, &[], &poses);
        assert!(near(g.facing_of("left"), [1.0, 0.0]) && near(g.facing_of("right"), [1.0, 0.0]));
        assert_eq!((g.sign_of("left"), g.sign_of("right")), (1.0, -1.0));
    }
}
