//! Phase ReLock (\[A\] §III-A1) in 2D: the tag position (x, y) and one phase offset per segment
//! that best explain the unwrapped phases, θ_i ≈ s·4π·d_i/λ_i + c_k, by Levenberg–Marquardt
//! (the `levenberg-marquardt` crate on `nalgebra`), started from the best point of a grid on
//! the side the antenna faces (the mirror image about a straight path explains the phases as
//! well): 50 cm on up to 32 of the phases, then 10 cm on up to 100 within 60 cm of its best.

use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{DMatrix, DVector, Dyn, Owned};

/// One unwrapped phase with where the antenna was.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Obs {
    /// Unwrapped phase (rad).
    pub phase_rad: f64,
    /// Antenna position (m).
    pub antenna: [f64; 3],
    /// Channel wavelength (m).
    pub wavelength_m: f64,
    /// Segment the phase belongs to (its own offset), 0-based.
    pub segment: usize,
}

/// A 2D estimate.
#[derive(Clone, Debug, PartialEq)]
pub struct Fix {
    /// Position (m); z is the tag height assumed.
    pub position: [f64; 3],
    /// Covariance of (x, y), m², row-major 2×2.
    pub covariance: [f64; 4],
    /// Root-mean-square phase residual (rad).
    pub rms_rad: f64,
}

/// Why no estimate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NoFix {
    /// Too few phases, or an aperture too short to fix a position.
    InsufficientGeometry,
}

/// The least-squares problem in the position alone: each segment's offset is at its best
/// for the position (the mean residual of the segment), so residuals and Jacobian columns are
/// centred per segment (variable projection: the offsets are linear, and the position's
/// covariance from the centred Jacobian is its marginal covariance).
struct Problem<'a> {
    obs: &'a [Obs],
    /// Phases per segment.
    counts: Vec<usize>,
    /// 2: (x, y) at height `z`; 3: (x, y, z).
    dims: usize,
    z: f64,
    sign: f64,
    p: DVector<f64>,
}

impl<'a> Problem<'a> {
    fn new(obs: &'a [Obs], dims: usize, z: f64, sign: f64, start: &[f64]) -> Problem<'a> {
        let segments = obs.iter().map(|o| o.segment + 1).max().unwrap_or(0);
        let mut counts = vec![0; segments];
        for o in obs {
            counts[o.segment] += 1;
        }
        Problem {
            obs,
            counts,
            dims,
            z,
            sign,
            p: DVector::from_column_slice(&start[..dims]),
        }
    }

    fn distance(&self, o: &Obs) -> (f64, [f64; 3]) {
        let z = if self.dims == 3 { self.p[2] } else { self.z };
        let d = [
            self.p[0] - o.antenna[0],
            self.p[1] - o.antenna[1],
            z - o.antenna[2],
        ];
        (
            (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt().max(1e-9),
            d,
        )
    }
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for Problem<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, x: &DVector<f64>) {
        self.p.copy_from(x);
    }

    fn params(&self) -> DVector<f64> {
        self.p.clone()
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        let mut r = DVector::from_iterator(
            self.obs.len(),
            self.obs.iter().map(|o| {
                let (d, _) = self.distance(o);
                o.phase_rad - self.sign * 4.0 * std::f64::consts::PI * d / o.wavelength_m
            }),
        );
        let mut mean = vec![0.0; self.counts.len()];
        for (o, v) in self.obs.iter().zip(r.iter()) {
            mean[o.segment] += v / self.counts[o.segment] as f64;
        }
        for (o, v) in self.obs.iter().zip(r.iter_mut()) {
            *v -= mean[o.segment];
        }
        Some(r)
    }

    fn jacobian(&self) -> Option<DMatrix<f64>> {
        let mut j = DMatrix::zeros(self.obs.len(), self.dims);
        let mut mean = vec![[0.0; 3]; self.counts.len()];
        for (i, o) in self.obs.iter().enumerate() {
            let (d, v) = self.distance(o);
            let k = self.sign * 4.0 * std::f64::consts::PI / o.wavelength_m;
            for (a, va) in v.iter().enumerate().take(self.dims) {
                j[(i, a)] = -k * va / d;
                mean[o.segment][a] += j[(i, a)] / self.counts[o.segment] as f64;
            }
        }
        for (i, o) in self.obs.iter().enumerate() {
            for a in 0..self.dims {
                j[(i, a)] -= mean[o.segment][a];
            }
        }
        Some(j)
    }
}

/// Residual sum of squares at (x, y) with each segment's offset at its best (the mean);
/// `sum` and `n` are scratch space of one entry per segment.
#[allow(clippy::too_many_arguments)]
fn cost(
    obs: &[Obs],
    z: f64,
    sign: f64,
    x: f64,
    y: f64,
    sum: &mut [f64],
    sq: &mut [f64],
    n: &mut [usize],
) -> f64 {
    sum.fill(0.0);
    sq.fill(0.0);
    n.fill(0);
    for o in obs {
        let d =
            ((x - o.antenna[0]).powi(2) + (y - o.antenna[1]).powi(2) + (z - o.antenna[2]).powi(2))
                .sqrt();
        let r = o.phase_rad - sign * 4.0 * std::f64::consts::PI * d / o.wavelength_m;
        sum[o.segment] += r;
        sq[o.segment] += r * r;
        n[o.segment] += 1;
    }
    // Σ(r − mean)² = Σr² − (Σr)²/n per segment.
    sum.iter()
        .zip(sq.iter())
        .zip(n.iter())
        .map(|((s, q), &k)| if k == 0 { 0.0 } else { q - s * s / k as f64 })
        .sum()
}

/// The start's coarse grid: step (m) and most phases looked at.
const COARSE: (f64, usize) = (0.5, 32);
/// The fine grid around the coarse best: step (m), most phases, and steps either side.
const FINE: (f64, usize) = (0.1, 100);
const FINE_HALF_STEPS: f64 = 6.0;

/// Up to `max` of `obs`, evenly spread.
fn spread(obs: &[Obs], max: usize) -> Vec<Obs> {
    let stride = obs.len().div_ceil(max).max(1);
    obs.iter().step_by(stride).copied().collect()
}

/// The position of a tag at height `z` from `obs` (phase sign `sign`: +1 or −1), searching
/// the side of the antennas' path that `facing` (a horizontal direction) points to, within
/// `reach_m` of it.
pub fn locate(
    obs: &[Obs],
    z: f64,
    sign: f64,
    facing: [f64; 2],
    reach_m: f64,
) -> Result<Fix, NoFix> {
    let segments = obs.iter().map(|o| o.segment + 1).max().unwrap_or(0);
    let (min, max) = obs
        .iter()
        .fold(([f64::MAX; 2], [f64::MIN; 2]), |(lo, hi), o| {
            (
                [lo[0].min(o.antenna[0]), lo[1].min(o.antenna[1])],
                [hi[0].max(o.antenna[0]), hi[1].max(o.antenna[1])],
            )
        });
    let aperture = (max[0] - min[0]).hypot(max[1] - min[1]);
    let lambda = obs.first().map_or(0.33, |o| o.wavelength_m);
    if obs.len() < segments + 3 || aperture < lambda / 2.0 {
        return Err(NoFix::InsufficientGeometry);
    }
    // A coarse grid (COARSE) over the path's box widened by the reach, on the facing side,
    // then a finer one (FINE) around its best point; after
    // unwrapping the cost is smooth on that side, so the coarse best is near the minimum.
    let mid = [(min[0] + max[0]) / 2.0, (min[1] + max[1]) / 2.0];
    let (mut sum, mut sq, mut n) = (vec![0.0; segments], vec![0.0; segments], vec![0; segments]);
    let mut search =
        |obs: &[Obs], lo: [f64; 2], hi: [f64; 2], step: f64, best: &mut (f64, f64, f64)| {
            let nx = ((hi[0] - lo[0]) / step).ceil() as i64;
            let ny = ((hi[1] - lo[1]) / step).ceil() as i64;
            for i in 0..=nx {
                for j in 0..=ny {
                    let (x, y) = (lo[0] + i as f64 * step, lo[1] + j as f64 * step);
                    if (x - mid[0]) * facing[0] + (y - mid[1]) * facing[1] < 0.0 {
                        continue;
                    }
                    let c = cost(obs, z, sign, x, y, &mut sum, &mut sq, &mut n);
                    if c < best.0 {
                        *best = (c, x, y);
                    }
                }
            }
        };
    let mut best = (f64::INFINITY, mid[0], mid[1]);
    search(
        &spread(obs, COARSE.1),
        [min[0] - reach_m, min[1] - reach_m],
        [max[0] + reach_m, max[1] + reach_m],
        COARSE.0,
        &mut best,
    );
    let (cx, cy) = (best.1, best.2);
    best.0 = f64::INFINITY;
    let r = FINE.0 * FINE_HALF_STEPS;
    search(
        &spread(obs, FINE.1),
        [cx - r, cy - r],
        [cx + r, cy + r],
        FINE.0,
        &mut best,
    );
    let problem = Problem::new(obs, 2, z, sign, &[best.1, best.2]);
    let (p, cov, rms) = solve(
        problem,
        [min[0] - reach_m, min[1] - reach_m],
        [max[0] + reach_m, max[1] + reach_m],
    )?;
    Ok(Fix {
        position: [p[0], p[1], z],
        covariance: [cov[(0, 0)], cov[(0, 1)], cov[(1, 0)], cov[(1, 1)]],
        rms_rad: rms,
    })
}

/// Runs Levenberg–Marquardt from `problem`'s start; the solution, its covariance ((JᵀJ)⁻¹
/// times the residual variance) and the RMS residual. A solution outside the search box
/// (`lo`, `hi` in x and y) is no fix: the phases did not pin the tag down.
fn solve(
    problem: Problem<'_>,
    lo: [f64; 2],
    hi: [f64; 2],
) -> Result<(DVector<f64>, DMatrix<f64>, f64), NoFix> {
    let (obs, dims, segments) = (problem.obs, problem.dims, problem.counts.len());
    let (solved, _report) = LevenbergMarquardt::new().minimize(problem);
    let r = solved.residuals().ok_or(NoFix::InsufficientGeometry)?;
    let j = solved.jacobian().ok_or(NoFix::InsufficientGeometry)?;
    let dof = (obs.len() - (dims + segments)).max(1) as f64;
    let variance = r.norm_squared() / dof;
    let info = j.transpose() * &j;
    let cov = info.try_inverse().ok_or(NoFix::InsufficientGeometry)? * variance;
    let p = solved.p;
    let inside = (0..2).all(|a| p[a].is_finite() && p[a] >= lo[a] && p[a] <= hi[a]);
    let finite = (0..dims).all(|a| p[a].is_finite() && cov[(a, a)].is_finite());
    if !(inside && finite) {
        return Err(NoFix::InsufficientGeometry);
    }
    Ok((p, cov, (r.norm_squared() / obs.len() as f64).sqrt()))
}

/// A 3D estimate.
#[derive(Clone, Debug, PartialEq)]
pub struct Fix3 {
    /// Position (m).
    pub position: [f64; 3],
    /// Covariance of (x, y, z), m², row-major 3×3.
    pub covariance: [f64; 9],
    /// Root-mean-square phase residual (rad).
    pub rms_rad: f64,
}

/// Antenna heights must span this much (m) for the height to be estimated.
pub const MIN_HEIGHT_SPAN_M: f64 = 0.2;

/// Phase ReLock in 3D: (x, y, z) and the offsets, for antennas at several heights (at
/// least [`MIN_HEIGHT_SPAN_M`] apart); the grid runs over the heights from the floor to a
/// metre above the highest antenna.
pub fn locate3d(obs: &[Obs], sign: f64, facing: [f64; 2], reach_m: f64) -> Result<Fix3, NoFix> {
    let segments = obs.iter().map(|o| o.segment + 1).max().unwrap_or(0);
    let (min, max) = obs
        .iter()
        .fold(([f64::MAX; 3], [f64::MIN; 3]), |(lo, hi), o| {
            (
                [0, 1, 2].map(|a| lo[a].min(o.antenna[a])),
                [0, 1, 2].map(|a| hi[a].max(o.antenna[a])),
            )
        });
    let aperture = (max[0] - min[0]).hypot(max[1] - min[1]);
    let lambda = obs.first().map_or(0.33, |o| o.wavelength_m);
    if obs.len() < segments + 4 || aperture < lambda / 2.0 || max[2] - min[2] < MIN_HEIGHT_SPAN_M {
        return Err(NoFix::InsufficientGeometry);
    }
    let mid = [(min[0] + max[0]) / 2.0, (min[1] + max[1]) / 2.0];
    let (mut sum, mut sq, mut n) = (vec![0.0; segments], vec![0.0; segments], vec![0; segments]);
    let mut search =
        |obs: &[Obs], lo: [f64; 3], hi: [f64; 3], step: f64, best: &mut (f64, [f64; 3])| {
            let steps = [0, 1, 2].map(|a| ((hi[a] - lo[a]) / step).ceil().max(0.0) as i64);
            for i in 0..=steps[0] {
                for j in 0..=steps[1] {
                    let (x, y) = (lo[0] + i as f64 * step, lo[1] + j as f64 * step);
                    if (x - mid[0]) * facing[0] + (y - mid[1]) * facing[1] < 0.0 {
                        continue;
                    }
                    for k in 0..=steps[2] {
                        let z = lo[2] + k as f64 * step;
                        let c = cost(obs, z, sign, x, y, &mut sum, &mut sq, &mut n);
                        if c < best.0 {
                            *best = (c, [x, y, z]);
                        }
                    }
                }
            }
        };
    let mut best = (f64::INFINITY, [mid[0], mid[1], (min[2] + max[2]) / 2.0]);
    search(
        &spread(obs, COARSE.1),
        [min[0] - reach_m, min[1] - reach_m, 0.0],
        [max[0] + reach_m, max[1] + reach_m, max[2] + 1.0],
        COARSE.0,
        &mut best,
    );
    let c = best.1;
    best.0 = f64::INFINITY;
    let r = FINE.0 * FINE_HALF_STEPS;
    search(
        &spread(obs, FINE.1),
        [c[0] - r, c[1] - r, (c[2] - r).max(0.0)],
        [c[0] + r, c[1] + r, c[2] + r],
        FINE.0,
        &mut best,
    );
    let problem = Problem::new(obs, 3, 0.0, sign, &best.1);
    let (p, cov, rms) = solve(
        problem,
        [min[0] - reach_m, min[1] - reach_m],
        [max[0] + reach_m, max[1] + reach_m],
    )?;
    let mut covariance = [0.0; 9];
    for a in 0..3 {
        for b in 0..3 {
            covariance[3 * a + b] = cov[(a, b)];
        }
    }
    Ok(Fix3 {
        position: [p[0], p[1], p[2]],
        covariance,
        rms_rad: rms,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::localize::synthetic;

    /// One pass at z = 0.5 of a tag at that height, phase offset 1.7.
    fn pass(tag: [f64; 2], noise: f64, seed: u64) -> Vec<Obs> {
        synthetic::passes([tag[0], tag[1], 0.5], &[0.5], (1.7, 0.0), noise, seed)
    }

    /// Passes at the heights `zs`, offsets 0.4 apart.
    fn passes(tag: [f64; 3], zs: &[f64], noise: f64, seed: u64) -> Vec<Obs> {
        synthetic::passes(tag, zs, (0.0, 0.4), noise, seed)
    }

    #[test]
    fn a_noise_free_tag_is_recovered_within_a_millimetre() {
        let tag = [1.2, 1.6];
        let fix = locate(&pass(tag, 0.0, 1), 0.5, 1.0, [0.0, 1.0], 3.0).expect("a fix");
        let err = (fix.position[0] - tag[0]).hypot(fix.position[1] - tag[1]);
        assert!(err < 1e-3, "{err} m: {fix:?}");
        // The mirror image on the other side, when the antenna faces that way.
        let mirror = locate(&pass([1.2, -1.6], 0.0, 1), 0.5, 1.0, [0.0, -1.0], 3.0).expect("a fix");
        assert!((mirror.position[1] + 1.6).abs() < 1e-3, "{mirror:?}");
    }

    #[test]
    fn with_noise_the_error_stays_within_the_covariance() {
        let tag = [0.8, 2.1];
        let mut within = 0;
        for seed in 0..20 {
            let fix = locate(&pass(tag, 0.1, seed), 0.5, 1.0, [0.0, 1.0], 3.0).expect("a fix");
            let (ex, ey) = (fix.position[0] - tag[0], fix.position[1] - tag[1]);
            assert!(ex.hypot(ey) < 0.02, "seed {seed}: {} m", ex.hypot(ey));
            // Mahalanobis distance² of a 2D Gaussian error: ≤ 6 holds 95 % of the time.
            let [a, b, c, d] = fix.covariance;
            let det = a * d - b * c;
            let m2 = (d * ex * ex - (b + c) * ex * ey + a * ey * ey) / det;
            within += usize::from(m2 <= 6.0);
            assert!((fix.rms_rad - 0.1).abs() < 0.02, "{}", fix.rms_rad);
        }
        assert!(within >= 16, "{within} of 20 within the 95 % ellipse");
    }

    #[test]
    fn in_3d_antennas_at_several_heights_recover_the_tag_height() {
        let tag = [0.9, 1.2, 1.3];
        let zs = [0.4, 0.9, 1.4, 1.9];
        let fix = locate3d(&passes(tag, &zs, 0.0, 1), 1.0, [0.0, 1.0], 3.0).expect("a fix");
        let err = (0..3)
            .map(|a| (fix.position[a] - tag[a]).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(err < 1e-3, "{err} m: {fix:?}");
        // With noise: within 2 cm in every seed, the covariance's diagonal positive.
        for seed in 0..5 {
            let fix = locate3d(&passes(tag, &zs, 0.1, seed), 1.0, [0.0, 1.0], 3.0).expect("fix");
            let err = (0..3)
                .map(|a| (fix.position[a] - tag[a]).powi(2))
                .sum::<f64>()
                .sqrt();
            assert!(err < 0.02, "seed {seed}: {err} m");
            assert!(fix.covariance[0] > 0.0 && fix.covariance[4] > 0.0 && fix.covariance[8] > 0.0);
        }
        // One height cannot tell the tag's height.
        assert_eq!(
            locate3d(&passes(tag, &[0.9], 0.0, 1), 1.0, [0.0, 1.0], 3.0),
            Err(NoFix::InsufficientGeometry)
        );
    }

    #[test]
    fn too_little_geometry_is_said_not_guessed() {
        let mut short = pass([1.0, 1.0], 0.0, 1);
        short.truncate(10); // 9 cm of path: under half a wavelength
        assert_eq!(
            locate(&short, 0.5, 1.0, [0.0, 1.0], 3.0),
            Err(NoFix::InsufficientGeometry)
        );
        assert_eq!(
            locate(&[], 0.5, 1.0, [0.0, 1.0], 3.0),
            Err(NoFix::InsufficientGeometry)
        );
    }
}
