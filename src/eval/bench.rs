//! `llrp-gateway bench localize`: a scenario simulated faster than real time through the
//! simulated reader's own LLRP output (every reader inventories all its antennas, a report
//! per read), localized by every applicable estimator with the true antenna poses and with
//! the poses the robot itself reports; errors against the ground truth and compute times.

use crate::reads::ReaderName;
use std::time::Instant;

use crate::localize::estimate::{estimate_all, Estimate, Estimator, Geometry};
use crate::localize::estimator::Need;
use crate::localize::ingest::Ingest;
use crate::localize::live::Settings;
use crate::localize::poses::{PoseSample, Poses};
use crate::localize::refine::{localize_refined, PoseErrorModel};
use crate::physics::{AntennaPose, Model, World};
use crate::reader::session::Now;
use crate::reader::{Reader, ReaderProfile};
use crate::reads::{Read, ReadDecoder};
use crate::scenario::{Mount, Scenario};
use crate::sim::own::OwnInventory;

/// Simulated time between two steps of the readers (µs).
const STEP_US: u64 = 10_000;

/// Simulated time between two pose samples (µs).
const POSE_US: u64 = 100_000;

/// The reads and poses of one simulated run.
pub struct Run {
    /// Every read, in time order per reader.
    pub reads: Vec<Read>,
    /// The true antenna poses.
    pub true_poses: Poses,
    /// The poses the robots report.
    pub estimated_poses: Poses,
    /// Each tag's true position (at time 0), by EPC.
    pub truth: Vec<(String, [f64; 3], bool)>,
    /// The localizer's settings, from the scenario (geometry, π ambiguity).
    pub settings: Settings,
    /// Simulated seconds run.
    pub seconds: f64,
    /// Every antenna's phase offset φ0 is 0 on every channel (a calibrated reader): what the
    /// EKF and WLS of \[M\] assume.
    pub calibrated: bool,
    /// The robots' pose error as the scenario states it, where they report a localization
    /// stack's pose (`localized`): what [`crate::localize::refine`] assumes.
    pub pose_error: Option<PoseErrorModel>,
}

/// Which poses a run is localized on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PoseSource {
    /// The true antenna poses.
    True,
    /// The poses the robots report.
    Estimated,
    /// The poses the robots report, refined from the tags' phases ([`crate::localize::refine`]).
    Refined,
}

impl PoseSource {
    /// Its name in the tables.
    pub fn name(self) -> &'static str {
        match self {
            PoseSource::True => "true",
            PoseSource::Estimated => "estimated",
            PoseSource::Refined => "estimated, refined",
        }
    }
}

/// How long a scenario runs: until its slowest robot has driven its path (a 2 s margin),
/// 10 s without robots.
pub fn duration_s(s: &Scenario) -> f64 {
    let mut longest: f64 = 0.0;
    for r in &s.readers {
        for a in &r.antennas {
            if let Mount::Robot { robot, .. } = &a.mount {
                let mut at = [robot.start[0], robot.start[1]];
                let mut length = 0.0;
                for w in &robot.waypoints {
                    length += (w[0] - at[0]).hypot(w[1] - at[1]);
                    at = *w;
                }
                longest = longest.max(length / robot.speed.max(1e-6));
            }
        }
    }
    if longest > 0.0 {
        longest + 2.0
    } else {
        10.0
    }
}

fn sample(reader: &ReaderName, antenna: u16, t_us: u64, p: &AntennaPose) -> PoseSample {
    PoseSample {
        t_us,
        reader: Some(reader.clone()),
        antenna,
        pose: *p,
    }
}

/// The inventory settings a benchmark's client asks of every reader.
#[derive(Clone, Copy, Debug, Default)]
pub struct Inventory {
    /// RF mode (C1G2RFControl ModeIndex); `None`: the reader's default.
    pub mode: Option<u16>,
    /// Gen2 session (C1G2SingulationControl); `None`: the reader's default.
    pub session: Option<u8>,
}

/// Simulates `scenario` for `seconds` of simulated time, the readers at their defaults.
pub fn simulate(scenario: &Scenario, seconds: f64) -> Run {
    simulate_with(scenario, seconds, Inventory::default())
}

/// Simulates `scenario` for `seconds` of simulated time, every reader inventoried as
/// `inventory` asks.
pub fn simulate_with(scenario: &Scenario, seconds: f64, inventory: Inventory) -> Run {
    let world = World::new(scenario);
    let end_us = (seconds * 1e6) as u64;
    let mut reads = Vec::new();
    let mut poses = (Poses::new(), Poses::new());
    let settings = crate::sim::feed::settings(scenario, Settings::default());
    let mut truth = Vec::new();
    let mut calibrated = true;
    let pose_error = pose_error_model(scenario);
    for (i, spec) in scenario.readers.iter().enumerate() {
        let model = std::sync::Arc::new(Model::in_world(&world, scenario, i));
        if i == 0 {
            truth = truth_of(scenario, &model);
        }
        let profile = ReaderProfile::from_scenario(scenario, i, &model);
        calibrated &= spec.antennas.iter().all(|a| {
            a.phase_offset_rad.len() >= profile.frequencies_khz.len()
                && a.phase_offset_rad.iter().all(|&p| p == 0.0)
        });
        let table = llrp::units::HopTable {
            id: 1,
            frequencies_khz: profile.frequencies_khz.clone(),
        };
        // UTC 0 is simulated time 0: the poses need no clock offset.
        let reader = Reader::new(profile, model.clone(), 0);
        let mut decoder =
            ReadDecoder::new(Some(spec.name.clone())).with_fallback_table(Some(table));
        let Some(mut own) =
            OwnInventory::start_with(reader, Now::default(), inventory.mode, inventory.session)
        else {
            continue;
        };
        let mut t = 0;
        while t <= end_us {
            own.advance(Now {
                sim_us: t,
                wall_ms: t / 1000,
            });
            if let Some(bytes) = own.take_output() {
                decode_frames(&bytes, t, &mut decoder, &mut reads);
            }
            if t % POSE_US == 0 {
                add_poses(&spec.name, &model, t, &mut poses);
            }
            t += STEP_US;
        }
    }
    let (true_poses, estimated_poses) = poses;
    Run {
        reads,
        true_poses,
        estimated_poses,
        truth,
        settings,
        seconds,
        calibrated,
        pose_error,
    }
}

/// The pose error model of the first robot antenna whose pose is localized, if any.
fn pose_error_model(scenario: &Scenario) -> Option<PoseErrorModel> {
    scenario
        .readers
        .iter()
        .flat_map(|r| &r.antennas)
        .find_map(|a| match &a.mount {
            Mount::Robot { robot, .. }
                if robot.pose_estimate.kind == crate::scenario::PoseEstimateKind::Localized =>
            {
                let e = &robot.pose_estimate;
                Some(PoseErrorModel::new(e.position_sigma_m, e.correlation_s))
            }
            _ => None,
        })
}

/// Each tag of `model`'s world: (EPC, position at time 0, whether a reference tag).
fn truth_of(scenario: &Scenario, model: &Model) -> Vec<(String, [f64; 3], bool)> {
    (0..model.tag_count())
        .map(|k| {
            (
                crate::reads::hex_upper(model.tag_epc(k).as_bytes()),
                model.tag_position(k, 0),
                scenario.tags.get(k).is_some_and(|t| t.reference),
            )
        })
        .collect()
}

/// Decodes the whole LLRP frames in `bytes`, output at `t`, into `reads`.
fn decode_frames(bytes: &[u8], t: u64, decoder: &mut ReadDecoder, reads: &mut Vec<Read>) {
    let mut at = 0;
    while let Some(h) = llrp::FrameHeader::peek(&bytes[at..]) {
        let len = (h.length as usize).max(llrp::frame::HEADER_LEN);
        if at + len > bytes.len() {
            break;
        }
        let _ = decoder.frame(&bytes[at..at + len], t, reads);
        at += len;
    }
}

/// Adds every antenna's true and estimated pose at `t` to `poses` (true, estimated).
fn add_poses(name: &ReaderName, model: &Model, t: u64, poses: &mut (Poses, Poses)) {
    for a in 1..=model.antenna_count() {
        poses.0.add(sample(name, a, t, &model.antenna_pose(a, t)));
        poses.1.add(sample(name, a, t, &model.estimated_pose(a, t)));
    }
}

/// Error statistics of one estimator on one run (m), and its compute time (s).
#[derive(Clone, Debug, PartialEq)]
pub struct Scores {
    /// The estimator.
    pub estimator: Estimator,
    /// `true` or `estimated` poses.
    pub poses: &'static str,
    /// Tags with an estimate, of those the reads cover (reference tags left out).
    pub located: usize,
    /// Tags read.
    pub read: usize,
    /// Mean, median, max and standard deviation of the error.
    pub mean: f64,
    /// Median error.
    pub median: f64,
    /// Largest error.
    pub max: f64,
    /// Standard deviation of the error.
    pub std: f64,
    /// Ingest and estimation of every tag, reads already in memory (s).
    pub seconds: f64,
    /// Located tags whose true position lies inside the estimate's 95 % ellipse (ellipsoid
    /// for a 3D estimate), of those located with a covariance.
    pub covered: usize,
    /// Located tags with a covariance.
    pub with_covariance: usize,
    /// The estimates.
    pub estimates: Vec<Estimate>,
}

/// Localizes `run` with `estimator` on `poses` (`"true"` or `"estimated"`), told the
/// scenario's reference tags (fingerprinting's references, `relock`'s calibration).
pub fn score(run: &Run, estimator: Estimator, estimated: bool) -> Scores {
    score_with(run, estimator, estimated, true)
}

/// [`score`], told the reference tags only when `references` is set.
pub fn score_with(run: &Run, estimator: Estimator, estimated: bool, references: bool) -> Scores {
    let source = if estimated {
        PoseSource::Estimated
    } else {
        PoseSource::True
    };
    score_on(run, estimator, source, references)
}

/// [`score_with`] on the poses `source` names; refined poses fall back to the estimated ones
/// where the scenario states no pose error.
pub fn score_on(run: &Run, estimator: Estimator, source: PoseSource, references: bool) -> Scores {
    let mut g: Geometry = run.settings.geometry.clone();
    if !references {
        g.references.clear();
    }
    // On the robot's own poses their stated error widens each estimate's covariance, as the
    // live localizer's does (docs/localize.md "The antenna poses' own error").
    if source != PoseSource::True {
        g.pose_error = run.pose_error;
    }
    // The poses are in memory before the clock starts, as the reads are.
    let poses = if source == PoseSource::True {
        run.true_poses.clone()
    } else {
        run.estimated_poses.clone()
    };
    let start = Instant::now();
    let estimates = match (source, run.pose_error) {
        (PoseSource::Refined, Some(m)) => {
            let poses = &run.estimated_poses;
            localize_refined(&run.reads, poses, &run.settings, estimator, &g, &m).0
        }
        _ => {
            let mut ingest = Ingest::new(poses, run.settings.ambiguity, run.settings.max_gap_us)
                .with_min_rssi(run.settings.min_rssi_dbm);
            ingest.extend(&run.reads);
            estimate_all(&ingest, estimator, &g)
        }
    };
    let seconds = start.elapsed().as_secs_f64();
    let mut errors = Vec::new();
    let (mut covered, mut with_covariance) = (0, 0);
    let mut read = 0;
    for e in &estimates {
        let Some((_, p, reference)) = run.truth.iter().find(|(epc, _, _)| *epc == e.epc) else {
            continue;
        };
        if *reference {
            continue;
        }
        read += 1;
        if let Some(q) = e.estimate {
            // A 3D estimate (its covariance has a z term) is scored in 3D, a 2D one in (x, y).
            let dz = if e.covariance.is_some_and(|c| c[8] > 0.0) {
                q[2] - p[2]
            } else {
                0.0
            };
            errors.push(((q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2) + dz * dz).sqrt());
            if let Some(inside) = e
                .covariance
                .and_then(|c| inside_95(&c, [q[0] - p[0], q[1] - p[1], dz]))
            {
                with_covariance += 1;
                covered += usize::from(inside);
            }
        }
    }
    let (mean, median, max, std) = stats(&mut errors);
    Scores {
        estimator,
        poses: source.name(),
        located: errors.len(),
        read,
        mean,
        median,
        max,
        std,
        seconds,
        covered,
        with_covariance,
        estimates,
    }
}

/// χ² quantiles at 95 % for 2 and 3 degrees of freedom.
const CHI2_95: [f64; 2] = [5.991, 7.815];

/// Whether the error `d` lies inside the 95 % region of `covariance` (3×3, row-major): the
/// (x, y) block for a 2D estimate (no z variance), the whole for a 3D one; `None` for a
/// covariance that is not positive definite.
pub fn inside_95(covariance: &[f64; 9], d: [f64; 3]) -> Option<bool> {
    let c = nalgebra::Matrix3::from_row_slice(covariance);
    if c[(2, 2)] > 0.0 {
        let inv = c.try_inverse()?;
        let v = nalgebra::Vector3::from(d);
        let m2 = (v.transpose() * inv * v)[0];
        (m2.is_finite() && m2 >= 0.0).then_some(m2 <= CHI2_95[1])
    } else {
        let c2 = nalgebra::Matrix2::new(c[(0, 0)], c[(0, 1)], c[(1, 0)], c[(1, 1)]);
        let inv = c2.try_inverse()?;
        let v = nalgebra::Vector2::new(d[0], d[1]);
        let m2 = (v.transpose() * inv * v)[0];
        (m2.is_finite() && m2 >= 0.0).then_some(m2 <= CHI2_95[0])
    }
}

/// Mean, median, max and standard deviation (NaN for none).
fn stats(v: &mut [f64]) -> (f64, f64, f64, f64) {
    if v.is_empty() {
        return (f64::NAN, f64::NAN, f64::NAN, f64::NAN);
    }
    v.sort_by(f64::total_cmp);
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let median = if v.len() % 2 == 1 {
        v[v.len() / 2]
    } else {
        (v[v.len() / 2 - 1] + v[v.len() / 2]) / 2.0
    };
    let std = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt();
    (mean, median, v[v.len() - 1], std)
}

/// The estimators that apply to a scenario: the 2D phase estimators always, loci3d with
/// antennas at two heights or more, fingerprinting with reference tags, the EKF and WLS of
/// \[M\] with a calibrated reader (φ0 = 0).
pub fn applicable(run: &Run) -> Vec<Estimator> {
    Estimator::ALL
        .iter()
        .copied()
        .filter(|&e| why_not(run, e).is_none())
        .collect()
}

/// Why estimator `e` does not apply to `run`, if it does not: the first of its needs
/// ([`Need`]) that `run` does not meet.
pub fn why_not(run: &Run, e: Estimator) -> Option<&'static str> {
    let mut heights: Vec<f64> = run
        .true_poses
        .first_samples()
        .iter()
        .map(|p| (p.pose.position[2] * 100.0).round())
        .collect();
    heights.sort_by(f64::total_cmp);
    heights.dedup();
    e.locator().needs().iter().find_map(|need| match need {
        Need::Heights => (heights.len() < 2).then_some("its antennas are all at one height"),
        Need::References => (!run.truth.iter().any(|t| t.2)).then_some("it has no reference tags"),
        Need::CalibratedReader => {
            (!run.calibrated).then_some("its reader is not calibrated (φ0 = 0 on every channel)")
        }
    })
}

/// The scenario `name` (a fixture's name or a file).
pub fn scenario(name: &str) -> Result<Scenario, String> {
    scenario_with(name, None)
}

/// The scenario `name` (a fixture's name or a file), run with the reader model `model` when
/// given (docs/measurement.md "Reader models").
pub fn scenario_with(name: &str, model: Option<&str>) -> Result<Scenario, String> {
    let embedded = match name.to_ascii_uppercase().as_str() {
        "S1" => return Scenario::default_s1_with(model).map_err(|e| format!("{name}: {e}")),
        "S2" => include_str!("../../fixtures/scenarios/s2-side-by-side.json"),
        "S2-BACK-TO-BACK" => include_str!("../../fixtures/scenarios/s2-back-to-back.json"),
        "S3" => include_str!("../../fixtures/scenarios/s3.json"),
        _ => {
            return Scenario::load_with(std::path::Path::new(name), model)
                .map_err(|e| format!("{name}: {e}"))
        }
    };
    Scenario::from_json_with(embedded, std::path::Path::new("."), model)
        .map_err(|e| format!("{name}: {e}"))
}

#[cfg(test)]
mod tests {
    use super::inside_95;

    #[test]
    fn the_95_percent_region_is_an_ellipse_in_2d_and_an_ellipsoid_in_3d() {
        // σ 1 cm along x, 4 cm along y, no z: a 2D estimate.
        let c2 = [1e-4, 0.0, 0.0, 0.0, 16e-4, 0.0, 0.0, 0.0, 0.0];
        // √5.991 = 2.448 σ.
        assert_eq!(inside_95(&c2, [0.024, 0.0, 5.0]), Some(true));
        assert_eq!(inside_95(&c2, [0.025, 0.0, 0.0]), Some(false));
        assert_eq!(inside_95(&c2, [0.0, 0.097, 0.0]), Some(true));
        assert_eq!(inside_95(&c2, [0.0, 0.099, 0.0]), Some(false));
        // With a z variance the z error counts, against √7.815 = 2.796 σ.
        let c3 = [1e-4, 0.0, 0.0, 0.0, 1e-4, 0.0, 0.0, 0.0, 1e-4];
        assert_eq!(inside_95(&c3, [0.0, 0.0, 0.027]), Some(true));
        assert_eq!(inside_95(&c3, [0.0, 0.0, 0.029]), Some(false));
        // A singular covariance says nothing.
        assert_eq!(inside_95(&[0.0; 9], [0.0; 3]), None);
    }
}
