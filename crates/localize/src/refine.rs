//! Joint pose refinement: the robot's reported poses corrected by what every tag's phases say
//! about them. A localization stack's pose error is shared by every tag read at one moment
//! and correlated over time; with the tags fixed at their estimates, each read's range
//! residual measures that error along the direction to its tag. A Kalman smoother over the
//! error, modelled as the first-order Gauss–Markov process in x and y the scenario (or the
//! settings) states, turns the residuals of all tags into a correction per moment; the tags
//! are then estimated again on the corrected poses, a few rounds over.

use std::collections::BTreeMap;

use nalgebra::{Matrix2, Vector2};

use crate::estimate::{estimate_all, Estimate, Estimator, Geometry};
use crate::ingest::Ingest;
use crate::live::Settings;
use crate::poses::{Pose, PoseSample, Poses};
use crate::series::Places;
pub use crate::settings::PoseErrorModel;
use llrp_gateway_vocab::reads::Read;

/// One read's range residual `r` ≈ `h`·δ(t), where δ is the pose's error correction.
#[derive(Clone, Copy, Debug)]
struct Residual {
    t_us: u64,
    h: Vector2<f64>,
    r: f64,
}

/// Range residuals per reader of every read of the tags in `tags` (EPC → position), each
/// segment of a series about its own mean (its phase offset unknown; a segment is long
/// against the error's correlation time, so its mean error is small). `sign_of` gives a
/// reader's phase sign.
fn residuals(
    ingest: &Ingest,
    tags: &BTreeMap<String, [f64; 3]>,
    sign_of: &dyn Fn(&str) -> f64,
) -> BTreeMap<String, Vec<Residual>> {
    let mut out: BTreeMap<String, Vec<Residual>> = BTreeMap::new();
    for (epc, t) in tags {
        for (key, series) in ingest.tag_series(epc) {
            let reader = &key.1;
            let k = sign_of(reader) * series.wavelength_m() / (4.0 * std::f64::consts::PI);
            for seg in series.segments().filter(|s| s.len() >= 3) {
                // A resting antenna's reads as thinning keeps them, whether or not it has
                // (the live localizer's [`crate::series::Series::thin_places`]): many reads from one place
                // pin its pose error to whatever bias the tags' estimates have.
                let mut place = Places::default();
                let rows: Vec<(u64, Vector2<f64>, f64)> = seg
                    .iter()
                    .filter(|s| place.keeps(s.antenna))
                    .map(|s| {
                        let d = [
                            t[0] - s.antenna[0],
                            t[1] - s.antenna[1],
                            t[2] - s.antenna[2],
                        ];
                        let g = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt().max(1e-9);
                        // ∂|T − a|/∂a in x and y.
                        let h = Vector2::new(-d[0] / g, -d[1] / g);
                        (s.t_us, h, k * s.phase_rad - g)
                    })
                    .collect();
                let n = rows.len() as f64;
                let mean_r = rows.iter().map(|r| r.2).sum::<f64>() / n;
                let list = out.entry(reader.clone()).or_default();
                for (t_us, h, r) in rows {
                    list.push(Residual {
                        t_us,
                        h,
                        r: r - mean_r,
                    });
                }
            }
        }
    }
    for list in out.values_mut() {
        list.sort_by_key(|r| r.t_us);
    }
    out
}

/// The smoothed correction δ(t) at each residual's time (Rauch–Tung–Striebel).
fn smooth(res: &[Residual], m: &PoseErrorModel) -> Vec<(u64, Vector2<f64>)> {
    let q = m.sigma_m * m.sigma_m;
    let r2 = m.range_sigma_m.powi(2).max(1e-12);
    let tau_us = (m.correlation_s * 1e6).max(1.0);
    let mut filtered: Vec<(Vector2<f64>, Matrix2<f64>)> = Vec::with_capacity(res.len());
    let mut predicted: Vec<(Vector2<f64>, Matrix2<f64>, f64)> = Vec::with_capacity(res.len());
    let (mut x, mut p) = (Vector2::zeros(), Matrix2::identity() * q);
    let mut last = res.first().map_or(0, |r| r.t_us);
    for e in res {
        let phi = (-((e.t_us - last) as f64) / tau_us).exp();
        last = e.t_us;
        x *= phi;
        p = p * (phi * phi) + Matrix2::identity() * (q * (1.0 - phi * phi));
        predicted.push((x, p, phi));
        let s = (e.h.transpose() * p * e.h)[(0, 0)] + r2;
        let k = p * e.h / s;
        x += k * (e.r - e.h.dot(&x));
        p = (Matrix2::identity() - k * e.h.transpose()) * p;
        filtered.push((x, p));
    }
    let mut out = vec![(0, Vector2::zeros()); res.len()];
    // The smoothed means only: the correction needs no covariance.
    let Some(&(mut xs, _)) = filtered.last() else {
        return out;
    };
    for i in (0..res.len()).rev() {
        if i + 1 < res.len() {
            let (xf, pf) = filtered[i];
            let (xp, pp, phi) = predicted[i + 1];
            xs = match pp.try_inverse() {
                Some(inv) => xf + pf * phi * inv * (xs - xp),
                None => xf,
            };
        }
        out[i] = (res[i].t_us, xs);
    }
    out
}

/// Corrections whose RMS is over this many times the stated pose error's are not used
/// ([`PoseCorrections::from_tags`]).
pub const IMPLAUSIBLE: f64 = 2.0;

/// The corrections of each reader's antenna positions: δ(t) in x and y (m) at the times of
/// its reads (the reads' clock), as the smoother gave them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PoseCorrections {
    per_reader: BTreeMap<String, Vec<(u64, Vector2<f64>)>>,
}

impl PoseCorrections {
    /// What tags at `tags` say of the poses' error (`sign_of` gives a reader's phase sign).
    /// A reader whose corrections come out larger than the error stated could make them (RMS
    /// over [`IMPLAUSIBLE`] times the model's, which a smoother's mean never is on average
    /// when the model holds) gets none: its residuals are not a pose error's but tags' that are
    /// not where they were put.
    pub fn from_tags(
        ingest: &Ingest,
        tags: &BTreeMap<String, [f64; 3]>,
        sign_of: &dyn Fn(&str) -> f64,
        m: &PoseErrorModel,
    ) -> PoseCorrections {
        // The model's RMS of δ in x and y together.
        let bound = IMPLAUSIBLE * m.sigma_m * std::f64::consts::SQRT_2;
        let per_reader = residuals(ingest, tags, sign_of)
            .into_iter()
            .map(|(reader, res)| (reader, smooth(&res, m)))
            .filter(|(_, s)| {
                let sum: f64 = s.iter().map(|c| c.1.norm_squared()).sum();
                (sum / s.len().max(1) as f64).sqrt() <= bound
            })
            .collect();
        PoseCorrections { per_reader }
    }

    /// The correction to add to reader `reader`'s antenna position (x, y) at `t_us`,
    /// interpolated between the nearest corrections; 0 for a reader without any.
    pub fn at(&self, reader: &str, t_us: u64) -> [f64; 2] {
        let Some(list) = self.per_reader.get(reader) else {
            return [0.0; 2];
        };
        let i = list.partition_point(|c| c.0 < t_us);
        let d = match (i.checked_sub(1).and_then(|j| list.get(j)), list.get(i)) {
            (Some(a), Some(b)) if b.0 > a.0 => {
                let f = (t_us - a.0) as f64 / (b.0 - a.0) as f64;
                a.1 + (b.1 - a.1) * f
            }
            (Some(a), _) => a.1,
            (None, Some(b)) => b.1,
            (None, None) => Vector2::zeros(),
        };
        [d[0], d[1]]
    }
}

/// `poses` corrected by what the tags at `tags` say of them; readers without reads as they
/// were.
pub fn refine(
    ingest: &Ingest,
    poses: &Poses,
    tags: &BTreeMap<String, [f64; 3]>,
    sign_of: &dyn Fn(&str) -> f64,
    m: &PoseErrorModel,
) -> Poses {
    let corrections = PoseCorrections::from_tags(ingest, tags, sign_of, m);
    poses.mapped(|p, offset| {
        let reader = p.reader.as_deref().unwrap_or_default();
        let d = corrections.at(reader, p.t_us.saturating_add_signed(offset));
        let [x, y, z] = p.pose.position;
        PoseSample {
            pose: Pose {
                position: [x + d[0], y + d[1], z],
                ..p.pose
            },
            ..p.clone()
        }
    })
}

/// The tags `linear` locates in `ingest` on its poses as reported (the estimator a pose
/// error throws least, docs/localize.md): what the corrections are measured against.
fn linear_tags(ingest: &Ingest, g: &Geometry) -> BTreeMap<String, [f64; 3]> {
    // With the pose error kept, so that a resting antenna's reads weigh as they do in the
    // estimates (docs/localize.md "Straight tracks"); its share of the covariance is unused.
    let plain = Geometry {
        pose_corrections: None,
        ..g.clone()
    };
    estimate_all(ingest, Estimator::Linear, &plain)
        .into_iter()
        .filter_map(|e| Some((e.epc, e.estimate?)))
        .collect()
}

/// `ingest`'s poses refined once from the tags `linear` locates on them.
pub fn refined_poses(ingest: &Ingest, g: &Geometry, m: &PoseErrorModel) -> Poses {
    refine(
        ingest,
        ingest.poses(),
        &linear_tags(ingest, g),
        &|r| g.sign_of(r),
        m,
    )
}

/// The corrections [`refined_poses`] applies, for the observations' antenna positions
/// ([`Geometry::pose_corrections`]): the live localizer's refinement, which does not file
/// its reads again.
pub fn corrections(ingest: &Ingest, g: &Geometry, m: &PoseErrorModel) -> PoseCorrections {
    PoseCorrections::from_tags(ingest, &linear_tags(ingest, g), &|r| g.sign_of(r), m)
}

/// Every tag of `reads` located by `estimator` on `poses` refined once ([`refined_poses`]),
/// the reads filed as `settings` say.
/// Returns the estimates and the corrected poses.
pub fn localize_refined(
    reads: &[Read],
    poses: &Poses,
    settings: &Settings,
    estimator: Estimator,
    g: &Geometry,
    m: &PoseErrorModel,
) -> (Vec<Estimate>, Poses) {
    let ingest_on = |poses: Poses| {
        let mut ingest = Ingest::new(poses, settings.ambiguity, settings.max_gap_us)
            .with_min_rssi(settings.min_rssi_dbm);
        ingest.extend(reads);
        ingest
    };
    let corrected = refined_poses(&ingest_on(poses.clone()), g, m);
    let ingest = ingest_on(corrected.clone());
    (estimate_all(&ingest, estimator, g), corrected)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::series::Ambiguity;
    use crate::synthetic::{read, FREQUENCY_HZ};
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// A robot passing five tags along y = 0 at 0.5 m/s for 20 s, its reported poses (every
    /// 100 ms) off by a Gauss–Markov error of σ 15 mm and τ 2 s; exact phases from the true
    /// path, every 20 ms for each tag within 3 m. Returns the reads, the true and the
    /// reported poses, and the tags.
    fn drive(seed: u64) -> (Vec<Read>, Poses, Poses, BTreeMap<String, [f64; 3]>) {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let unit = Normal::new(0.0, 1.0).expect("valid σ");
        let lambda = 299_792_458.0 / FREQUENCY_HZ as f64;
        let tags: BTreeMap<String, [f64; 3]> = (0..5)
            .map(|k| (format!("E{k:03}"), [1.0 + 2.0 * f64::from(k), 2.0, 0.5]))
            .collect();
        let (sigma, phi) = (0.015, (-0.1f64 / 2.0).exp());
        let mut e = [sigma * unit.sample(&mut rng), sigma * unit.sample(&mut rng)];
        let (mut truth, mut reported) = (Poses::new(), Poses::new());
        let sample = |t_us, x, y| PoseSample {
            t_us,
            reader: Some("r".parse().expect("a reader name")),
            antenna: 1,
            pose: Pose::from_degrees([x, y, 0.5], 90.0, 0.0),
        };
        for step in 0..=200u64 {
            let x = 0.05 * step as f64;
            truth.add(sample(step * 100_000, x, 0.0));
            reported.add(sample(step * 100_000, x + e[0], e[1]));
            for v in &mut e {
                *v = phi * *v + sigma * (1.0 - phi * phi).sqrt() * unit.sample(&mut rng);
            }
        }
        let mut reads = Vec::new();
        for step in 0..1000u64 {
            let x = 0.01 * step as f64;
            for (epc, t) in &tags {
                let d = (t[0] - x).hypot(t[1]).hypot(t[2] - 0.5);
                if d < 3.0 {
                    let phase = 4.0 * std::f64::consts::PI * d / lambda;
                    reads.push(Read {
                        reader: Some("r".parse().expect("a reader name")),
                        antenna_pose: None,
                        ..read(epc, step * 20_000, phase, [x, 0.0, 0.5])
                    });
                }
            }
        }
        (reads, truth, reported, tags)
    }

    /// RMS horizontal distance between the samples of `a` and `b` at the same times (m).
    fn rms(a: &Poses, b: &Poses) -> f64 {
        let b: BTreeMap<u64, (f64, f64)> = b
            .samples()
            .iter()
            .map(|s| (s.t_us, (s.pose.position[0], s.pose.position[1])))
            .collect();
        let d: Vec<f64> = a
            .samples()
            .iter()
            .filter_map(|s| {
                b.get(&s.t_us).map(|t| {
                    let [x, y, _] = s.pose.position;
                    (x - t.0).powi(2) + (y - t.1).powi(2)
                })
            })
            .collect();
        (d.iter().sum::<f64>() / d.len() as f64).sqrt()
    }

    #[test]
    fn the_tags_phases_take_a_good_part_of_a_correlated_pose_error_out() {
        let m = PoseErrorModel::new(0.015, 2.0);
        for seed in 1..=6 {
            let (reads, truth, reported, tags) = drive(seed);
            let ingest_on = |poses: &Poses| {
                let mut ingest = Ingest::new(poses.clone(), Ambiguity::None, 1_000_000);
                for r in &reads {
                    ingest.push(r);
                }
                ingest
            };
            let corrected = refine(&ingest_on(&reported), &reported, &tags, &|_| 1.0, &m);
            let (before, after) = (rms(&reported, &truth), rms(&corrected, &truth));
            // 26–55 % of the error taken out over these seeds (a segment's mean error stays).
            assert!(
                after < 0.8 * before,
                "seed {seed}: {:.1} mm → {:.1} mm",
                before * 1e3,
                after * 1e3
            );
            // Exact poses stay within a millimetre.
            let kept = refine(&ingest_on(&truth), &truth, &tags, &|_| 1.0, &m);
            assert!(rms(&kept, &truth) < 1e-3, "seed {seed}");
        }
    }

    #[test]
    fn corrections_of_the_filed_positions_locate_as_the_refined_poses_filed_again() {
        let m = PoseErrorModel::new(0.015, 2.0);
        let (reads, _, reported, tags) = drive(3);
        let ingest_on = |poses: Poses| {
            let mut ingest = Ingest::new(poses, Ambiguity::None, 1_000_000);
            for r in &reads {
                ingest.push(r);
            }
            ingest
        };
        let ingest = ingest_on(reported);
        let g = Geometry {
            tag_height_m: 0.5,
            reach_m: 3.0,
            ..crate::live::Settings::default().geometry
        };
        let mean_error = |estimates: &[Estimate]| {
            estimates
                .iter()
                .map(|e| {
                    let (p, t) = (e.estimate.expect("a position"), tags[&e.epc]);
                    (p[0] - t[0]).hypot(p[1] - t[1])
                })
                .sum::<f64>()
                / estimates.len() as f64
        };
        // Offline: the poses refined, the reads filed again on them.
        let again = ingest_on(refined_poses(&ingest, &g, &m));
        let offline = estimate_all(&again, Estimator::Relock, &g);
        // Live: the positions as filed, moved by the corrections.
        let corrected = Geometry {
            pose_corrections: Some(std::sync::Arc::new(corrections(&ingest, &g, &m))),
            ..g.clone()
        };
        let live = estimate_all(&ingest, Estimator::Relock, &corrected);
        let plain = estimate_all(&ingest, Estimator::Relock, &g);
        assert_eq!(offline.len(), tags.len());
        for (a, b) in offline.iter().zip(&live) {
            let (p, q) = (a.estimate.expect("offline"), b.estimate.expect("live"));
            assert!((p[0] - q[0]).hypot(p[1] - q[1]) < 1e-3, "{a:?} {b:?}");
        }
        assert!(
            mean_error(&live) < mean_error(&plain),
            "refined {} m, plain {} m",
            mean_error(&live),
            mean_error(&plain)
        );
    }

    #[test]
    fn tags_put_where_they_are_not_give_no_corrections() {
        let m = PoseErrorModel::new(0.015, 2.0);
        let (reads, _, reported, tags) = drive(2);
        let mut ingest = Ingest::new(reported, Ambiguity::None, 1_000_000);
        for r in &reads {
            ingest.push(r);
        }
        let times = || (0..200u64).map(|k| k * 100_000);
        let right = PoseCorrections::from_tags(&ingest, &tags, &|_| 1.0, &m);
        assert!(times().any(|t| right.at("r", t) != [0.0; 2]));
        // Every tag 30 cm off in y and 40 cm in height (a 2D fit's height assumed wrong).
        let wrong: BTreeMap<String, [f64; 3]> = tags
            .iter()
            .map(|(epc, t)| (epc.clone(), [t[0], t[1] + 0.3, t[2] + 0.4]))
            .collect();
        let refused = PoseCorrections::from_tags(&ingest, &wrong, &|_| 1.0, &m);
        assert!(times().all(|t| refused.at("r", t) == [0.0; 2]));
    }

    #[test]
    fn a_reader_with_no_reads_keeps_its_poses() {
        let (_, _, reported, tags) = drive(1);
        let ingest = Ingest::new(reported.clone(), Ambiguity::None, 1_000_000);
        let m = PoseErrorModel::new(0.015, 2.0);
        let corrected = refine(&ingest, &reported, &tags, &|_| 1.0, &m);
        assert_eq!(corrected.samples(), reported.samples());
    }

    #[test]
    fn a_resting_antennas_reads_give_residuals_as_thinning_keeps_them() {
        // 100 reads 1 cm apart, then 500 from one place: the rest gives its first 16.
        let tag = [0.5, 1.0, 0.5];
        let lambda = crate::SPEED_OF_LIGHT / FREQUENCY_HZ as f64;
        let at = |k: u64| [0.01 * k.min(100) as f64, 0.0, 0.5];
        let mut ingest = Ingest::new(Poses::new(), Ambiguity::None, 1_000_000);
        for k in 0..600u64 {
            let d = crate::distance(at(k), tag);
            ingest.push(&read(
                "AA",
                k * 10_000,
                4.0 * std::f64::consts::PI * d / lambda,
                at(k),
            ));
        }
        let tags = BTreeMap::from([("AA".to_string(), tag)]);
        let res = residuals(&ingest, &tags, &|_| 1.0);
        let n: usize = res.values().map(Vec::len).sum();
        assert_eq!(n, 100 + crate::series::KEPT_AT_ONE_PLACE);
    }
}
