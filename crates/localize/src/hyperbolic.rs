//! Hyperbolic intersection (\[G\] §III-D, after \[T\]) in 2D: the phase difference between two
//! antenna positions a stride apart is a range difference Δr = λΔφ/(4π), so the tag lies on
//! the hyperbola with those positions as foci. Hyperbolae that share a focus are intersected;
//! each intersection point, on the side the antenna faces, carries a quality, inconsistent
//! pairs are counted, and the points' robust (weighted median) centre starts a final
//! Levenberg–Marquardt fit of all range differences, whose Jacobian gives the covariance.
//!
//! Ours, where \[G\] is silent: the stride is λ/8 and each anchor is the mean of the stride's
//! phases and positions; on a straight segment with anchors at t_i along the path, the
//! hyperbolae (i, j) and (i, k) meet where −2t(t_j − t_i) − 2r_iΔ_ij = Δ_ij² − t_j² + t_i²
//! (and the same for k), linear in (t, r_i); j = i + g, k = i + 2g with g a quarter of the
//! segment's anchors; a point's quality E is the trace of its covariance per unit anchor
//! variance; the final fit has one range offset per segment (the differences' model written
//! without a reference anchor, so its residuals are independent).

use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{DMatrix, DVector, Dyn, Matrix2, Owned, Vector2};

use crate::estimator::{Locate, Tag, Takes, SIGN};
use crate::fix::{Fix, Fix3, NoFix, Obs};
use crate::linear::{line, MAX_PATH_RMS_M, MAX_SLOPE};
use crate::robust;

/// The stride between anchors, as a fraction of the wavelength (ours).
pub const STRIDE_WAVELENGTHS: f64 = 0.125;

/// A fix with what the intersections gave.
#[derive(Clone, Debug, PartialEq)]
pub struct Report {
    /// The fix.
    pub fix: Fix,
    /// Intersection points found on the facing side.
    pub points: usize,
    /// Pairs of hyperbolae without an intersection (noise, or a height the ranges cannot
    /// reach).
    pub inconsistent: usize,
}

/// The mean of one stride's phases: a focus of the hyperbolae.
#[derive(Clone, Copy, Debug)]
struct Anchor {
    pos: [f64; 3],
    /// s·λθ/(4π), the range up to the segment's constant (m).
    range: f64,
    segment: usize,
    n: usize,
}

fn anchors(obs: &[Obs], sign: f64) -> Vec<Anchor> {
    let mut out: Vec<Anchor> = Vec::new();
    let mut bin: Vec<&Obs> = Vec::new();
    let close = |bin: &[&Obs], out: &mut Vec<Anchor>| {
        let n = bin.len();
        if n == 0 {
            return;
        }
        let mut pos = [0.0; 3];
        for o in bin {
            (0..3).for_each(|k| pos[k] += o.antenna[k] / n as f64);
        }
        let range = bin
            .iter()
            .map(|o| sign * o.wavelength_m * o.phase_rad / (4.0 * std::f64::consts::PI))
            .sum::<f64>()
            / n as f64;
        out.push(Anchor {
            pos,
            range,
            segment: bin[0].segment,
            n,
        });
    };
    for o in obs {
        if let Some(first) = bin.first() {
            let moved = (0..3)
                .map(|k| (o.antenna[k] - first.antenna[k]).powi(2))
                .sum::<f64>()
                .sqrt();
            if o.segment != first.segment || moved >= STRIDE_WAVELENGTHS * first.wavelength_m {
                close(&bin, &mut out);
                bin.clear();
            }
        }
        bin.push(o);
    }
    close(&bin, &mut out);
    out
}

/// The intersection of hyperbolae (i, j) and (i, k) on a line: (t, r_i) from the anchors'
/// positions along it and the range differences.
fn meet(ti: f64, tj: f64, tk: f64, dij: f64, dik: f64) -> Option<(f64, f64)> {
    let m = Matrix2::new(-2.0 * (tj - ti), -2.0 * dij, -2.0 * (tk - ti), -2.0 * dik);
    let v = Vector2::new(dij * dij - tj * tj + ti * ti, dik * dik - tk * tk + ti * ti);
    let x = m.try_inverse()? * v;
    (x.iter().all(|c| c.is_finite()) && x[1] > 0.0).then_some((x[0], x[1]))
}

/// Intersection points (x, y, quality E) of one straight segment's hyperbolae at height `z` on
/// the facing side, and the pairs without one.
fn intersections(anchors: &[Anchor], z: f64, facing: [f64; 2]) -> (Vec<[f64; 3]>, usize) {
    let points: Vec<[f64; 3]> = anchors.iter().map(|a| a.pos).collect();
    let Some((o, u, perp)) = line(&points) else {
        return (Vec::new(), 0);
    };
    let horizontal = u[0].hypot(u[1]);
    if perp > MAX_PATH_RMS_M || u[2].abs() > MAX_SLOPE || horizontal < 1e-9 {
        return (Vec::new(), 0);
    }
    let mut nrm = [-u[1] / horizontal, u[0] / horizontal];
    if nrm[0] * facing[0] + nrm[1] * facing[1] < 0.0 {
        nrm = [-nrm[0], -nrm[1]];
    }
    let t: Vec<f64> = points
        .iter()
        .map(|p| (0..3).map(|k| (p[k] - o[k]) * u[k]).sum())
        .collect();
    let dz = z - o[2];
    // (along, across) of the tag from anchors i, j, k and the two range differences.
    let solve = |i: usize, j: usize, k: usize, dij: f64, dik: f64| {
        let (along, ri) = meet(t[i], t[j], t[k], dij, dik)?;
        let across_sq = ri * ri - (along - t[i]).powi(2) - dz * dz;
        (across_sq > 0.0).then(|| Vector2::new(along, across_sq.sqrt()))
    };
    let m = anchors.len();
    let g = (m / 4).max(1);
    let (mut found, mut inconsistent) = (Vec::new(), 0);
    for i in 0..m.saturating_sub(2 * g) {
        let (j, k) = (i + g, i + 2 * g);
        let (dij, dik) = (
            anchors[j].range - anchors[i].range,
            anchors[k].range - anchors[i].range,
        );
        let h = 1e-6;
        let (Some(p), Some(pj), Some(pk)) = (
            solve(i, j, k, dij, dik),
            solve(i, j, k, dij + h, dik),
            solve(i, j, k, dij, dik + h),
        ) else {
            inconsistent += 1;
            continue;
        };
        // Quality: trace of J Σ Jᵀ, Σ the differences' covariance per unit anchor variance
        // (both share anchor i).
        let jac = Matrix2::from_columns(&[(pj - p) / h, (pk - p) / h]);
        let e = (jac * Matrix2::new(2.0, 1.0, 1.0, 2.0) * jac.transpose()).trace();
        let (x, y) = (
            o[0] + p[0] * u[0] + p[1] * nrm[0],
            o[1] + p[0] * u[1] + p[1] * nrm[1],
        );
        if e.is_finite() && e > 0.0 && x.is_finite() && y.is_finite() {
            found.push([x, y, e]);
        } else {
            inconsistent += 1;
        }
    }
    (found, inconsistent)
}

/// The median of (value, weight) pairs.
fn weighted_median(mut pairs: Vec<(f64, f64)>) -> Option<f64> {
    pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
    let total: f64 = pairs.iter().map(|p| p.1).sum();
    let mut acc = 0.0;
    pairs.into_iter().find_map(|(v, w)| {
        acc += w;
        (acc >= total / 2.0).then_some(v)
    })
}

struct Problem<'a> {
    anchors: &'a [Anchor],
    segments: usize,
    z: f64,
    p: DVector<f64>,
}

impl Problem<'_> {
    fn distance(&self, a: &Anchor) -> (f64, f64, f64) {
        let (dx, dy, dz) = (
            self.p[0] - a.pos[0],
            self.p[1] - a.pos[1],
            self.z - a.pos[2],
        );
        ((dx * dx + dy * dy + dz * dz).sqrt().max(1e-9), dx, dy)
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
        Some(DVector::from_iterator(
            self.anchors.len(),
            self.anchors.iter().map(|a| {
                let (d, _, _) = self.distance(a);
                (a.n as f64).sqrt() * (a.range - d - self.p[2 + a.segment])
            }),
        ))
    }

    fn jacobian(&self) -> Option<DMatrix<f64>> {
        let mut j = DMatrix::zeros(self.anchors.len(), 2 + self.segments);
        for (i, a) in self.anchors.iter().enumerate() {
            let (d, dx, dy) = self.distance(a);
            let w = (a.n as f64).sqrt();
            j[(i, 0)] = -w * dx / d;
            j[(i, 1)] = -w * dy / d;
            j[(i, 2 + a.segment)] = -w;
        }
        Some(j)
    }
}

/// The position of a tag at height `z` from `obs` (phase sign `sign`), on the side `facing`
/// points to.
pub fn locate(obs: &[Obs], z: f64, sign: f64, facing: [f64; 2]) -> Result<Fix, NoFix> {
    locate_with_report(obs, z, sign, facing).map(|r| r.fix)
}

/// As [`locate`], with the intersection points found and the inconsistent pairs.
pub fn locate_with_report(
    obs: &[Obs],
    z: f64,
    sign: f64,
    facing: [f64; 2],
) -> Result<Report, NoFix> {
    let segments = obs.iter().map(|o| o.segment + 1).max().unwrap_or(0);
    let all = anchors(obs, sign);
    let (points, inconsistent) = all_intersections(&all, segments, z, facing);
    if points.is_empty() || all.len() < segments + 3 {
        return Err(NoFix::InsufficientGeometry);
    }
    let problem = started(&all, segments, z, &points)?;
    let (solved, _report) = LevenbergMarquardt::new().minimize(problem);
    let r = solved.residuals().ok_or(NoFix::InsufficientGeometry)?;
    let j = solved.jacobian().ok_or(NoFix::InsufficientGeometry)?;
    let cov = reported_covariance(&j, &r, &all, segments)?;
    let (x, y) = (solved.p[0], solved.p[1]);
    let cov = with_smooth_error(&cov, &j, &r, &all, [x, y, z]);
    let sq = phase_sq(obs, [x, y, z], sign, &solved.p);
    let c = [cov[(0, 0)], cov[(0, 1)], cov[(1, 0)], cov[(1, 1)]];
    if !(x.is_finite() && y.is_finite() && c.iter().all(|v| v.is_finite())) {
        return Err(NoFix::InsufficientGeometry);
    }
    Ok(Report {
        fix: Fix {
            position: [x, y, z],
            covariance: c,
            rms_rad: (sq / obs.len() as f64).sqrt(),
        },
        points: points.len(),
        inconsistent,
    })
}

/// The intersection points of the segments with three anchors or more, and inconsistent pairs.
fn all_intersections(
    all: &[Anchor],
    segments: usize,
    z: f64,
    facing: [f64; 2],
) -> (Vec<[f64; 3]>, usize) {
    let (mut points, mut inconsistent) = (Vec::new(), 0);
    for s in 0..segments {
        let seg: Vec<Anchor> = all.iter().filter(|a| a.segment == s).copied().collect();
        if seg.len() >= 3 {
            let (found, bad) = intersections(&seg, z, facing);
            points.extend(found);
            inconsistent += bad;
        }
    }
    (points, inconsistent)
}

/// The fit's problem, started at the points' weighted median with each offset at its best.
fn started<'a>(
    all: &'a [Anchor],
    segments: usize,
    z: f64,
    points: &[[f64; 3]],
) -> Result<Problem<'a>, NoFix> {
    let start =
        [0, 1].map(|k| weighted_median(points.iter().map(|p| (p[k], 1.0 / p[2])).collect()));
    let (Some(x0), Some(y0)) = (start[0], start[1]) else {
        return Err(NoFix::InsufficientGeometry);
    };
    let mut p = DVector::zeros(2 + segments);
    p[0] = x0;
    p[1] = y0;
    let mut problem = Problem {
        anchors: all,
        segments,
        z,
        p,
    };
    // Each offset at its best for the start.
    for s in 0..segments {
        let (sum, n) = all
            .iter()
            .filter(|a| a.segment == s)
            .fold((0.0, 0usize), |(sum, n), a| {
                (sum + a.range - problem.distance(a).0, n + 1)
            });
        problem.p[2 + s] = sum / n.max(1) as f64;
    }
    Ok(problem)
}

/// The fit's classic covariance made at least the cluster-robust one.
fn reported_covariance(
    j: &DMatrix<f64>,
    r: &DVector<f64>,
    all: &[Anchor],
    segments: usize,
) -> Result<DMatrix<f64>, NoFix> {
    let dof = all.len().saturating_sub(2 + segments).max(1) as f64;
    let bread = (j.transpose() * j)
        .try_inverse()
        .ok_or(NoFix::InsufficientGeometry)?;
    let classic = &bread * (r.norm_squared() / dof);
    // Reported: at least the cluster-robust covariance too, for range errors correlated along
    // the path (runs of consecutive anchors of a segment; docs/localize.md).
    let scores = DMatrix::from_fn(r.len(), j.ncols(), |i, a| j[(i, a)] * r[i]);
    let segment_of: Vec<usize> = all.iter().map(|a| a.segment).collect();
    let weight: Vec<f64> = all.iter().map(|a| a.n as f64).collect();
    Ok(robust::at_least_sandwich(
        &classic,
        &bread,
        &scores,
        &robust::clusters(&segment_of, &weight),
    ))
}

/// The sum of every phase's squared residual against the fit (`p`: position, then offsets).
fn phase_sq(obs: &[Obs], tag: [f64; 3], sign: f64, p: &DVector<f64>) -> f64 {
    let [x, y, z] = tag;
    obs.iter()
        .map(|o| {
            let d = ((x - o.antenna[0]).powi(2)
                + (y - o.antenna[1]).powi(2)
                + (z - o.antenna[2]).powi(2))
            .sqrt();
            let k = 4.0 * std::f64::consts::PI / o.wavelength_m;
            (sign * o.phase_rad - k * (d + p[2 + o.segment])).powi(2)
        })
        .sum()
}

/// `cov`'s position block made at least the covariance of a smooth angle-dependent error
/// ([`robust::smooth_error`]) in every direction, from the final fit's Jacobian `j` (position
/// columns first, then the segments' offsets) and residuals `r` over `anchors`, the tag at
/// `tag`.
fn with_smooth_error(
    cov: &DMatrix<f64>,
    j: &DMatrix<f64>,
    r: &DVector<f64>,
    anchors: &[Anchor],
    tag: [f64; 3],
) -> DMatrix<f64> {
    let position = cov.view((0, 0), (2, 2)).into_owned();
    let segments = anchors.iter().map(|a| a.segment + 1).max().unwrap_or(0);
    // The position's columns centred on each segment, weighted by the anchors' reads as the
    // fit weighs them: its offset eliminated. `j`'s rows carry √n.
    let mut mean = vec![[0.0; 2]; segments];
    let mut count = vec![0.0_f64; segments];
    for (i, a) in anchors.iter().enumerate() {
        let root = (a.n as f64).sqrt();
        count[a.segment] += a.n as f64;
        for c in 0..2 {
            mean[a.segment][c] += root * j[(i, c)];
        }
    }
    let jc = DMatrix::from_fn(anchors.len(), 2, |i, c| {
        let (s, root) = (anchors[i].segment, (anchors[i].n as f64).sqrt());
        j[(i, c)] - root * mean[s][c] / count[s].max(1.0)
    });
    let Some(bread) = (jc.transpose() * &jc).try_inverse() else {
        return position;
    };
    let rows: Vec<robust::Row> = anchors
        .iter()
        .map(|a| {
            let v = [0, 1, 2].map(|k| a.pos[k] - tag[k]);
            let d = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt().max(1e-9);
            robust::Row {
                direction: v.map(|x| x / d),
                weight: a.n as f64,
                segment: a.segment,
            }
        })
        .collect();
    match robust::smooth_error(&bread, &jc, r, &rows, true) {
        Some(smooth) => robust::at_least(&position, &smooth),
        None => position,
    }
}

/// Hyperbolic intersection as the localizer runs it: in 2D at the tag height assumed.
#[derive(Clone, Copy, Debug)]
pub struct Hyperbolic;

impl Locate for Hyperbolic {
    fn name(&self) -> &'static str {
        "hyperbolic"
    }

    fn takes(&self) -> Takes {
        Takes::Phases
    }

    fn locate(&self, tag: &Tag<'_>) -> Result<Fix3, NoFix> {
        let o = tag.observed;
        locate(&o.obs, tag.geometry.tag_height_m, SIGN, o.facing).map(Fix::planar)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic;

    /// One pass at z = 0.5, phase offset 2.1.
    fn pass(tag: [f64; 3], noise: f64, seed: u64) -> Vec<Obs> {
        synthetic::passes(tag, &[0.5], (2.1, 0.0), noise, seed)
    }

    #[test]
    fn a_phase_error_smooth_in_the_angle_read_from_stays_inside_the_95_percent_ellipse() {
        let held = synthetic::held_under_an_angle_error(
            &|obs| locate(obs, 0.5, 1.0, [0.0, 1.0]).expect("a fix"),
            40,
        );
        // With the cluster-robust covariance alone: 17 or 18 of 40.
        assert!(held >= 35, "{held} of 40 inside the 95 % ellipse");
    }

    #[test]
    fn a_noise_free_tag_is_recovered_within_a_millimetre() {
        for tag in [[1.234f64, 1.6, 0.5], [0.4, 0.9, 0.8], [1.234, -1.6, 0.5]] {
            let facing = [0.0, tag[1].signum()];
            let r = locate_with_report(&pass(tag, 0.0, 1), tag[2], 1.0, facing).expect("a fix");
            let e = (r.fix.position[0] - tag[0]).hypot(r.fix.position[1] - tag[1]);
            assert!(e < 1e-3, "{tag:?}: {r:?}");
            assert_eq!(r.inconsistent, 0, "{r:?}");
            assert!(r.points > 10, "{r:?}");
        }
    }

    #[test]
    fn noise_free_intersection_points_lie_on_the_tag() {
        // The points alone, before the final fit: each within 1 mm.
        let tag = [0.7, 1.4, 0.5];
        let a = anchors(&pass(tag, 0.0, 1), 1.0);
        let (points, bad) = intersections(&a, 0.5, [0.0, 1.0]);
        assert_eq!(bad, 0);
        for p in &points {
            assert!((p[0] - tag[0]).hypot(p[1] - tag[1]) < 1e-3, "{p:?}");
        }
    }

    #[test]
    fn with_noise_the_error_stays_within_the_covariance() {
        let tag = [0.8, 2.1, 0.5];
        let mut within = 0;
        for seed in 0..20 {
            let fix = locate(&pass(tag, 0.1, seed), 0.5, 1.0, [0.0, 1.0]).expect("a fix");
            let (ex, ey) = (fix.position[0] - tag[0], fix.position[1] - tag[1]);
            assert!(ex.hypot(ey) < 0.02, "seed {seed}: {} m", ex.hypot(ey));
            // Mahalanobis distance² of a 2D Gaussian error: ≤ 5.99 holds 95 % of the time.
            let [a, b, c, d] = fix.covariance;
            let m2 = (d * ex * ex - (b + c) * ex * ey + a * ey * ey) / (a * d - b * c);
            within += usize::from(m2 <= 5.99);
            assert!((fix.rms_rad - 0.1).abs() < 0.02, "{}", fix.rms_rad);
        }
        assert!(within >= 16, "{within} of 20 within the 95 % ellipse");
    }

    #[test]
    fn too_little_geometry_is_said_not_guessed() {
        let insufficient = Err(NoFix::InsufficientGeometry);
        let mut short = pass([1.0, 1.0, 0.5], 0.0, 1);
        short.truncate(8); // 7 cm of path: two anchors
        assert_eq!(locate(&short, 0.5, 1.0, [0.0, 1.0]), insufficient);
        assert_eq!(locate(&[], 0.5, 1.0, [0.0, 1.0]), insufficient);
        // A height the ranges cannot reach: every pair inconsistent.
        let r = locate_with_report(&pass([1.0, 1.0, 0.5], 0.0, 1), 2.5, 1.0, [0.0, 1.0]);
        assert_eq!(r, Err(NoFix::InsufficientGeometry));
        let a = anchors(&pass([1.0, 1.0, 0.5], 0.0, 1), 1.0);
        let (points, bad) = intersections(&a, 2.5, [0.0, 1.0]);
        assert!(points.is_empty() && bad > 0, "{bad}");
    }
}
