//! Estimates as the localizer reports them: per tag, the estimator's position with its
//! covariance, the samples behind it, a state, and when it was last updated.

use serde::Serialize;

use crate::calibrate::Calibration;
use crate::estimator::{Locate, Tag};
pub use crate::geometry::{Geometry, ReaderGeometry};
use crate::ingest::Ingest;
pub use crate::observe::{
    calibrated_observations, observations, pose_observations, Observed, PoseTrack,
};
use crate::{fingerprint, hyperbolic, linear, loci3d, mhekf, relock, wls};
use crate::{fix, uncertainty};

/// Position standard deviation (m) at or under which an estimate counts as converged.
pub const CONVERGED_SIGMA_M: f64 = 0.01;

/// How far an estimate has come.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum State {
    /// A position, not yet within [`CONVERGED_SIGMA_M`].
    Converging,
    /// A position within [`CONVERGED_SIGMA_M`] (one σ along its worse axis).
    Converged,
    /// Too little geometry for a position (too few phases, too short an aperture).
    InsufficientGeometry,
}

/// One tag's estimate.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Estimate {
    /// EPC, upper-case hex.
    pub epc: String,
    /// Estimator name.
    pub estimator: &'static str,
    /// Position (m), when there is one.
    pub estimate: Option<[f64; 3]>,
    /// Covariance of the position, 3×3 row-major (m²); a 2D estimator's z row and column are 0
    /// (the height is assumed, not estimated).
    pub covariance: Option<[f64; 9]>,
    /// Phases the estimate rests on.
    pub samples: usize,
    /// How far it has come.
    pub state: State,
    /// Time of the newest phase (µs, the reads' clock).
    pub last_update_us: u64,
    /// σ along the worse axis (m) of the covariance's share from the antenna poses' own
    /// error, when that error is known and the geometry passes it on no more than threefold.
    pub pose_sigma_m: Option<f64>,
}

/// The estimators the localizer offers, by the names the API and the command line use.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Estimator {
    /// Phase ReLock by Levenberg–Marquardt (\[A\] §III-A1), in 2D at the tag height assumed.
    Relock,
    /// The min-distance linear model (\[A\] §III-A2), in 2D at the tag height assumed.
    Linear,
    /// Hyperbolic intersection (\[G\] §III-D, after \[T\]), in 2D at the tag height assumed.
    Hyperbolic,
    /// 3D by intersecting one circle per antenna pass (\[A\] §III-A3), the circles from the
    /// min-distance linear model.
    Loci3d,
    /// Fingerprinting against reference tags at known positions (\[A\] §III-B, LANDMARC), 3D.
    Fingerprint,
    /// The multi-hypothesis EKF per (reader, antenna) from the phases as reported and the
    /// antenna's motion (\[M\] §III-A), in 2D at the tag height assumed; the best track's fix.
    Mhekf,
    /// Distributed WLS by average consensus over the readers' MHEKF fixes (\[M\] §III-B), in
    /// 2D at the tag height assumed.
    Wls,
}

impl Estimator {
    /// Every estimator, in the order the docs list them.
    pub const ALL: &'static [Estimator] = &[
        Estimator::Relock,
        Estimator::Linear,
        Estimator::Hyperbolic,
        Estimator::Loci3d,
        Estimator::Fingerprint,
        Estimator::Mhekf,
        Estimator::Wls,
    ];

    /// The estimator's name (`relock`, ...).
    pub fn name(self) -> &'static str {
        match self {
            Estimator::Relock => "relock",
            Estimator::Linear => "linear",
            Estimator::Hyperbolic => "hyperbolic",
            Estimator::Loci3d => "loci3d",
            Estimator::Fingerprint => "fingerprint",
            Estimator::Mhekf => "mhekf",
            Estimator::Wls => "wls",
        }
    }

    /// The estimator's implementation.
    pub fn locator(self) -> &'static dyn Locate {
        match self {
            Estimator::Relock => &relock::Relock,
            Estimator::Linear => &linear::Linear,
            Estimator::Hyperbolic => &hyperbolic::Hyperbolic,
            Estimator::Loci3d => &loci3d::Loci3d,
            Estimator::Fingerprint => &fingerprint::Fingerprint,
            Estimator::Mhekf => &mhekf::Mhekf,
            Estimator::Wls => &wls::Wls,
        }
    }
}

impl std::fmt::Display for Estimator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Estimator {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        Estimator::ALL
            .iter()
            .copied()
            .find(|e| e.name() == s)
            .ok_or_else(|| {
                let names: Vec<_> = Estimator::ALL.iter().map(|e| e.name()).collect();
                format!("unknown estimator {s:?}; one of: {}", names.join(", "))
            })
    }
}

/// `p` lies within twice `reach_m` (horizontally) of an antenna position of `obs`.
fn near_the_path(p: &[f64; 3], obs: &[fix::Obs], reach_m: f64) -> bool {
    obs.iter()
        .any(|o| (p[0] - o.antenna[0]).hypot(p[1] - o.antenna[1]) <= 2.0 * reach_m)
}

/// Tag `epc`'s estimate by `estimator` from the reads of `ingest`.
pub fn estimate_tag(ingest: &Ingest, epc: &str, estimator: Estimator, g: &Geometry) -> Estimate {
    estimate_calibrated(
        ingest,
        epc,
        estimator,
        g,
        &calibration(ingest, estimator, g),
    )
}

/// The calibration `estimator` uses ([`Locate::calibration`]) from the references of `g`:
/// `relock`'s antenna offsets, `fingerprint`'s references located from each other, nothing
/// for the others.
pub fn calibration(ingest: &Ingest, estimator: Estimator, g: &Geometry) -> Calibration {
    estimator.locator().calibration(ingest, g)
}

/// [`estimate_tag`] with the antenna calibration already measured.
pub fn estimate_calibrated(
    ingest: &Ingest,
    epc: &str,
    estimator: Estimator,
    g: &Geometry,
    calibration: &Calibration,
) -> Estimate {
    estimate_from(ingest, epc, estimator, g, calibration, None)
}

/// [`estimate_calibrated`], with `relock` started from `hint` (the tag's last fix) instead of
/// its grid; the other estimators ignore it ([`Locate::warm_starts`]).
pub fn estimate_from(
    ingest: &Ingest,
    epc: &str,
    estimator: Estimator,
    g: &Geometry,
    calibration: &Calibration,
    hint: Option<[f64; 3]>,
) -> Estimate {
    let locator = estimator.locator();
    let observed = calibrated_observations(ingest, epc, g, calibration);
    let base = Estimate {
        epc: epc.to_string(),
        estimator: estimator.name(),
        estimate: None,
        covariance: None,
        samples: observed.obs.len(),
        state: State::InsufficientGeometry,
        last_update_us: observed.last_us,
        pose_sigma_m: None,
    };
    let tag = Tag {
        observed: &observed,
        ingest,
        epc,
        geometry: g,
        hint,
        calibration,
    };
    // A fix farther than twice the reach from every antenna position that read the tag is
    // a solver gone astray (a degenerate geometry, bad poses), not an estimate.
    let fix = locator.locate(&tag).and_then(|f| {
        if near_the_path(&f.position, &observed.obs, g.reach_m) {
            Ok(f)
        } else {
            Err(fix::NoFix::InsufficientGeometry)
        }
    });
    match fix {
        Ok(f) => {
            let dims = if locator.fits_height(&observed.obs) {
                3
            } else {
                2
            };
            let (mut covariance, pose_sigma_m) =
                with_pose_share(&observed, f.position, f.covariance, dims, g);
            if g.tag_curvature_sigma_rad > 0.0 {
                if let Some(share) = uncertainty::curvature_share(
                    &observed.obs,
                    f.position,
                    dims,
                    g.tag_curvature_sigma_rad,
                ) {
                    for (c, s) in covariance.iter_mut().zip(share) {
                        *c += s;
                    }
                }
            }
            Estimate {
                estimate: Some(f.position),
                covariance: Some(covariance),
                state: state_of(&covariance),
                pose_sigma_m,
                ..base
            }
        }
        Err(fix::NoFix::InsufficientGeometry) => base,
    }
}

/// Covariance `c` of a fix at `p` from `observed` (its position axes `dims`) widened by the
/// share the poses' own error brings, where `g` knows it, and that share's σ along the worse
/// axis where the geometry passes the error on no more than threefold.
fn with_pose_share(
    observed: &Observed,
    p: [f64; 3],
    mut c: [f64; 9],
    dims: usize,
    g: &Geometry,
) -> ([f64; 9], Option<f64>) {
    let share = g.pose_error.as_ref().and_then(|m| {
        uncertainty::pose_share(&observed.obs, p, dims, m, &|group| {
            observed.reader_of_group.get(group).copied().unwrap_or(0)
        })
    });
    if let Some(share) = share {
        for (c, s) in c.iter_mut().zip(share) {
            *c += s;
        }
    }
    // Told as the poses' only where the geometry passes their error on no more than
    // threefold: beyond, a weak geometry amplifies it, and more aperture is the remedy.
    let pose_sigma = share
        .map(|s| worse_sigma(&s))
        .zip(g.pose_error.as_ref())
        .filter(|(s, m)| *s <= 3.0 * m.sigma_m * std::f64::consts::SQRT_2)
        .map(|(s, _)| s);
    (c, pose_sigma)
}

/// The σ along the worse axis of a 3×3 covariance (m), bounded by its largest diagonal term.
pub fn worse_sigma(covariance: &[f64; 9]) -> f64 {
    covariance[0]
        .max(covariance[4])
        .max(covariance[8])
        .max(0.0)
        .sqrt()
}

/// `converged` when the σ along the worse axis ([`worse_sigma`]) is at most
/// [`CONVERGED_SIGMA_M`], else `converging`.
pub fn state_of(covariance: &[f64; 9]) -> State {
    if worse_sigma(covariance) <= CONVERGED_SIGMA_M {
        State::Converged
    } else {
        State::Converging
    }
}

/// Every tag's estimate by `estimator`, in EPC order.
pub fn estimate_all(ingest: &Ingest, estimator: Estimator, g: &Geometry) -> Vec<Estimate> {
    let cal = calibration(ingest, estimator, g);
    ingest
        .tags()
        .map(|epc| estimate_calibrated(ingest, epc, estimator, g, &cal))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;

    #[test]
    fn a_fix_far_beyond_reach_of_every_antenna_is_no_fix() {
        let obs = crate::synthetic::passes([0.0, 1.0, 0.5], &[0.5], (0.0, 0.0), 0.0, 1);
        // The pass runs along y = 0 from x = −1 m to 1.99 m; reach 3 m.
        assert!(near_the_path(&[0.5, 1.0, 0.5], &obs, 3.0));
        assert!(near_the_path(&[-1.0, 5.99, 0.5], &obs, 3.0));
        assert!(!near_the_path(&[-1.0, 6.01, 0.5], &obs, 3.0));
        assert!(!near_the_path(&[1.2e10, 0.0, 0.5], &obs, 3.0));
        assert!(!near_the_path(&[f64::NAN, 0.0, 0.5], &obs, 3.0));
        assert!(!near_the_path(&[0.0, 0.0, 0.5], &[], 3.0));
    }
    use crate::poses::Poses;
    use crate::series::Ambiguity;
    use crate::synthetic;
    use llrp_gateway_vocab::reads::{Pose, Read};

    fn read(epc: &str, t_us: u64, x: f64, tag: [f64; 2]) -> Read {
        let f = 865_700_000u64;
        let lambda = crate::SPEED_OF_LIGHT / f as f64;
        let d = ((tag[0] - x).powi(2) + tag[1].powi(2)).sqrt();
        Read {
            reader: Some("r".parse().expect("a reader name")),
            channel_index: Some(1),
            channel_frequency_hz: Some(f),
            ..synthetic::read(
                epc,
                t_us,
                0.9 + 4.0 * std::f64::consts::PI * d / lambda,
                [x, 0.0, 0.5],
            )
        }
    }

    #[test]
    fn every_estimator_is_listed_once_and_parses_from_its_name() {
        // An exhaustive match: a new estimator must be placed here, and then in ALL.
        let place = |e: Estimator| match e {
            Estimator::Relock => 0,
            Estimator::Linear => 1,
            Estimator::Hyperbolic => 2,
            Estimator::Loci3d => 3,
            Estimator::Fingerprint => 4,
            Estimator::Mhekf => 5,
            Estimator::Wls => 6,
        };
        let mut seen: Vec<usize> = Estimator::ALL.iter().map(|&e| place(e)).collect();
        seen.sort();
        assert_eq!(seen, (0..7).collect::<Vec<_>>());
        for &e in Estimator::ALL {
            assert_eq!(e.name().parse::<Estimator>(), Ok(e));
        }
        assert!("kalman"
            .parse::<Estimator>()
            .is_err_and(|m| m.contains("relock, linear")));
    }

    #[test]
    fn every_estimators_implementation_goes_by_its_name() {
        for &e in Estimator::ALL {
            assert_eq!(e.locator().name(), e.name(), "{e:?}");
        }
        // Only relock starts from the last fix, and only the phase estimators read the
        // antenna positions the phases were filed with.
        let warm: Vec<_> = Estimator::ALL
            .iter()
            .filter(|e| e.locator().warm_starts())
            .collect();
        assert_eq!(warm, [&Estimator::Relock]);
        let phases: Vec<_> = Estimator::ALL
            .iter()
            .filter(|e| e.locator().takes() == crate::estimator::Takes::Phases)
            .map(|e| e.name())
            .collect();
        assert_eq!(phases, ["relock", "linear", "hyperbolic", "loci3d"]);
        // What each needs of a setting, as `bench localize` tells it.
        use crate::estimator::Need;
        let needs: Vec<_> = Estimator::ALL
            .iter()
            .map(|e| (e.name(), e.locator().needs()))
            .filter(|(_, n)| !n.is_empty())
            .collect();
        assert_eq!(
            needs,
            [
                ("loci3d", &[Need::Heights][..]),
                ("fingerprint", &[Need::References][..]),
                ("mhekf", &[Need::CalibratedReader][..]),
                ("wls", &[Need::CalibratedReader][..]),
            ]
        );
    }

    #[test]
    fn every_tag_gets_an_estimate_or_says_why_not() {
        let mut ingest = Ingest::new(Poses::new(), Ambiguity::None, 1_000_000);
        // Tag A seen over 3 m of path, tag B in two reads only.
        for k in 0..300u64 {
            ingest.push(&read("AA", k * 10_000, -1.0 + 0.01 * k as f64, [0.5, 1.5]));
        }
        ingest.push(&read("BB", 0, 0.0, [1.0, 2.0]));
        ingest.push(&read("BB", 10_000, 0.01, [1.0, 2.0]));
        let g = Geometry {
            tag_height_m: 0.5,
            phase_sign: 1.0,
            facing: [0.0, 1.0],
            reach_m: 3.0,
            references: Vec::new(),
            readers: BTreeMap::new(),
            pose_error: None,
            pose_corrections: None,
            tag_curvature_sigma_rad: 0.0,
        };
        let all = estimate_all(&ingest, Estimator::Relock, &g);
        assert_eq!(all.len(), 2);
        let a = &all[0];
        assert_eq!(
            (a.epc.as_str(), a.estimator, a.samples),
            ("AA", "relock", 300)
        );
        let p = a.estimate.expect("a position");
        assert!((p[0] - 0.5).hypot(p[1] - 1.5) < 1e-3, "{p:?}");
        assert_eq!(a.state, State::Converged);
        assert_eq!(a.last_update_us, 2_990_000);
        let cov = a.covariance.expect("a covariance");
        assert_eq!(cov[8], 0.0, "the height is assumed");
        let b = &all[1];
        assert_eq!(b.state, State::InsufficientGeometry);
        assert_eq!((b.estimate, b.covariance, b.samples), (None, None, 2));
        // As JSON: the state in snake case, no NaN anywhere.
        let json = serde_json::to_string(&all).expect("serialises");
        assert!(
            json.contains("\"insufficient_geometry\"") && !json.contains("NaN"),
            "{json}"
        );
    }

    /// Reader `reader`'s reads of tag `epc` along a synthetic S3 robot run, noise-free, phase
    /// sign −1, alternating between two channels.
    fn robot_reads(
        reader: &str,
        epc: &str,
        tag: [f64; 3],
        start: [f64; 2],
        seed: u64,
    ) -> Vec<Read> {
        let run = crate::mhekf::synth::run(tag, start, 0.3, 0.5, 1500, 0.0, 0.0, seed);
        run.iter()
            .enumerate()
            .map(|(k, o)| {
                let f = if k % 2 == 0 {
                    867_000_000u64
                } else {
                    865_700_000
                };
                let lambda = crate::SPEED_OF_LIGHT / f as f64;
                let d = (0..3)
                    .map(|k| (o.antenna[k] - tag[k]).powi(2))
                    .sum::<f64>()
                    .sqrt();
                Read {
                    epc: llrp_gateway_vocab::epc::Epc::parse(epc).expect("hex"),
                    reader: Some(reader.parse().expect("a reader name")),
                    antenna: 1,
                    t_us: o.t_us,
                    phase_rad: Some(
                        (-4.0 * std::f64::consts::PI * d / lambda)
                            .rem_euclid(std::f64::consts::TAU),
                    ),
                    rssi_dbm: None,
                    channel_index: Some(1),
                    channel_frequency_hz: Some(f),
                    doppler_hz: None,
                    antenna_pose: Some(Pose {
                        position: o.antenna,
                        yaw_rad: o.yaw_rad,
                        pitch_rad: 0.0,
                    }),
                    last_seen_us: None,
                }
            })
            .collect()
    }

    #[test]
    fn the_filters_take_each_readers_reads_as_reported() {
        let tag = [1.0, 2.0, 0.5];
        let mut ingest = Ingest::new(Poses::new(), Ambiguity::None, 1_000_000);
        let (r1, r2) = (
            robot_reads("r1", "AA", tag, [-0.3, 2.2], 1),
            robot_reads("r2", "AA", tag, [2.2, 1.5], 2),
        );
        for r in r1.iter().chain(&r2) {
            ingest.push(r);
        }
        let mut bb = r1[..3].to_vec();
        bb.iter_mut()
            .for_each(|r| r.epc = llrp_gateway_vocab::epc::Epc::parse("BB").expect("hex"));
        bb.iter().for_each(|r| ingest.push(r));
        let g = Geometry {
            tag_height_m: 0.5,
            phase_sign: -1.0,
            facing: [0.0, 1.0],
            reach_m: 2.0,
            references: Vec::new(),
            readers: BTreeMap::new(),
            pose_error: None,
            pose_corrections: None,
            tag_curvature_sigma_rad: 0.0,
        };
        // One track per (reader, antenna), both channels merged in time order, as reported
        // (times the phase sign: +1 here).
        let plus = Geometry {
            phase_sign: 1.0,
            ..g.clone()
        };
        let tracks = pose_observations(&ingest, "AA", &plus);
        assert_eq!(tracks.len(), 2);
        assert_eq!(
            (tracks[0].reader.as_deref(), tracks[0].antenna),
            (Some("r1"), 1)
        );
        assert_eq!(tracks[0].obs.len(), r1.len());
        assert!(tracks[0].obs.windows(2).all(|w| w[0].t_us <= w[1].t_us));
        let o = tracks[0].obs[2];
        assert_eq!((o.t_us, Some(o.phase_rad)), (r1[2].t_us, r1[2].phase_rad));
        let yaw = r1[2].antenna_pose.map_or(f64::NAN, |p| p.yaw_rad);
        assert!((o.yaw_rad - yaw).abs() < 1e-12, "{} vs {yaw}", o.yaw_rad);
        assert_ne!(tracks[0].obs[0].wavelength_m, tracks[0].obs[1].wavelength_m);
        for estimator in [Estimator::Mhekf, Estimator::Wls] {
            let e = estimate_tag(&ingest, "AA", estimator, &g);
            let p = e.estimate.expect("a position");
            // Default odometry noise (K = 1e-5) on exact poses: millimetres, not 1 mm.
            assert!(
                (p[0] - tag[0]).hypot(p[1] - tag[1]) < 5e-3,
                "{estimator}: {p:?}"
            );
            let cov = e.covariance.expect("a covariance");
            assert_eq!(
                (cov[2], cov[5], cov[8]),
                (0.0, 0.0, 0.0),
                "the height is assumed"
            );
            let b = estimate_tag(&ingest, "BB", estimator, &g);
            assert_eq!((b.state, b.estimate), (State::InsufficientGeometry, None));
        }
    }
}
