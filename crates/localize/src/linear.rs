//! Min-distance linear model (\[A\] §III-A2) in 2D: on a straight path the tag lies on the
//! perpendicular through the point of the path nearest to it, the point of minimum unwrapped
//! phase. With Δd_i = λΔθ_i/(4π) the range of sample i beyond the nearest one and L_i its
//! distance along the path from it, 2Δd_i·d0 = L_i² − Δd_i² is linear in the perpendicular
//! distance d0, solved in closed form (d0 = Σa_i b_i / Σa_i²). Ours: the along-path position
//! of the nearest point and the range at the reference sample are left free in the same linear
//! system (three unknowns, still closed form), so the result does not rest on one noisy sample
//! where the phase curve is flat; each row is weighted by 1/(2d_i) so that its residual is a
//! range error, and the residual variance gives the covariance.

use nalgebra::{DMatrix, Matrix2, Matrix3, SymmetricEigen, Vector2, Vector3};

use crate::estimator::{Locate, Tag, Takes, SIGN};
use crate::fix::{Fix, Fix3, NoFix, Obs};
use crate::robust;

/// Fewest phases a segment needs (ours).
pub const MIN_SAMPLES: usize = 10;
/// Largest RMS distance of a segment's antenna positions from their straight line (m, ours:
/// the jitter of a robot's own pose estimate, some centimetres, still counts as straight).
pub const MAX_PATH_RMS_M: f64 = 0.05;
/// Largest vertical component of a path's unit direction for a 2D fix (ours).
pub const MAX_SLOPE: f64 = 0.05;

/// What one straight segment tells: a circle around the path on which the tag lies.
#[derive(Clone, Debug, PartialEq)]
pub struct Circle {
    /// The point of the path nearest the tag (m): the circle's centre.
    pub centre: [f64; 3],
    /// Unit direction of the path: the circle's normal.
    pub direction: [f64; 3],
    /// Perpendicular distance from the path to the tag (m): the circle's radius.
    pub radius_m: f64,
    /// Covariance of (centre's position along the path, radius), m², row-major 2×2.
    pub covariance: [f64; 4],
    /// The covariance to report: at least `covariance` and at least the cluster-robust
    /// (sandwich) one in every direction, for range errors correlated along the path.
    pub reported: [f64; 4],
    /// Root-mean-square range residual, as phase (rad).
    pub rms_rad: f64,
    /// Phases behind it.
    pub samples: usize,
    /// How much (centre along the path, radius) moves per unit range error on each phase
    /// (m per m), in the segment's order: what a smooth error shared with other segments
    /// brings ([`robust::kernel_sum`]).
    pub influence: Vec<[f64; 2]>,
    /// What the fit's residuals tell about a smooth error ([`robust::evidence`]).
    pub evidence: Option<robust::Evidence>,
}

/// The straight line through `points`: (origin, unit direction, RMS distance from it).
pub(crate) fn line(points: &[[f64; 3]]) -> Option<([f64; 3], [f64; 3], f64)> {
    let n = points.len() as f64;
    if points.len() < 2 {
        return None;
    }
    let mean = points
        .iter()
        .fold(Vector3::zeros(), |s, p| s + Vector3::from(*p))
        / n;
    let scatter = points.iter().fold(Matrix3::zeros(), |s, p| {
        let d = Vector3::from(*p) - mean;
        s + d * d.transpose()
    }) / n;
    let eig = SymmetricEigen::new(scatter);
    let k = eig.eigenvalues.imax();
    let u = eig.eigenvectors.column(k).into_owned();
    let perp = (scatter.trace() - eig.eigenvalues[k]).max(0.0).sqrt();
    if !(u.norm() > 0.5 && perp.is_finite()) {
        return None;
    }
    Some((mean.into(), u.normalize().into(), perp))
}

/// The paper's closed form: d0 = Σa_i b_i / Σa_i² with a_i = 2Δd_i, b_i = L_i² − Δd_i², from
/// distances along the path `along` and range differences `dd`, both from the reference.
pub fn min_distance_d0(along: &[f64], dd: &[f64]) -> Option<f64> {
    let (ab, aa) = along.iter().zip(dd).fold((0.0, 0.0), |(ab, aa), (l, d)| {
        let (a, b) = (2.0 * d, l * l - d * d);
        (ab + a * b, aa + a * a)
    });
    let d0 = ab / aa;
    (aa > 0.0 && d0.is_finite() && d0 > 0.0).then_some(d0)
}

/// One straight segment set up for the fit: its line, reference sample and range differences.
struct Setup {
    /// A point of the path's line (m).
    origin: [f64; 3],
    /// The path's unit direction.
    u: [f64; 3],
    /// The segment's wavelength (m).
    lambda: f64,
    /// Each sample's position along the path from `origin` (m).
    t: Vec<f64>,
    /// The reference sample: the nearest (least range).
    r: usize,
    /// Each sample's distance along the path from the reference (m).
    l: Vec<f64>,
    /// Each sample's range beyond the reference's (m).
    dd: Vec<f64>,
    /// The paper's closed-form perpendicular distance (m).
    d0_paper: f64,
}

/// The circle of one straight segment's phases (`sign` the phase sign, ±1).
pub fn circle(seg: &[Obs], sign: f64) -> Result<Circle, NoFix> {
    let n = seg.len();
    if n < MIN_SAMPLES {
        return Err(NoFix::InsufficientGeometry);
    }
    let Setup {
        origin,
        u,
        lambda,
        t,
        r,
        l,
        dd,
        d0_paper,
    } = setup(seg, sign)?;
    let (p, inv) = solve(seg, &l, &dd, d0_paper)?;
    let sse: f64 = (0..n)
        .map(|i| {
            let w = 1.0 / (2.0 * (dd[i] + p[0]).max(1e-6));
            let fit = 2.0 * dd[i] * p[0] + 2.0 * l[i] * p[1] + p[2];
            seg[i].weight * (w * (l[i] * l[i] - dd[i] * dd[i] - fit)).powi(2)
        })
        .sum();
    // The reads the phases stand for ([`Obs::weight`]; a resting antenna's weigh less).
    let reads: f64 = seg.iter().map(|o| o.weight).sum();
    let cov_p = inv * (sse / (reads - 3.0).max(1.0));
    let reported_p = at_least_robust(&cov_p, &inv, n, |i| {
        let w = 1.0 / (2.0 * (dd[i] + p[0]).max(1e-6));
        let fit = 2.0 * dd[i] * p[0] + 2.0 * l[i] * p[1] + p[2];
        let r = l[i] * l[i] - dd[i] * dd[i] - fit;
        Vector3::new(2.0 * dd[i], 2.0 * l[i], 1.0) * (w * w * seg[i].weight * r)
    });
    let (c, tau, k) = (p[0], p[1], p[2]);
    let d0_sq = c * c - tau * tau - k;
    if !(d0_sq > 0.0 && d0_sq.is_finite()) {
        return Err(NoFix::InsufficientGeometry);
    }
    let d0 = d0_sq.sqrt();
    let jac = weighted_jacobian_and_residuals(seg, &l, &dd, p);
    let (evidence, reported_p) = with_smooth_error(seg, &l, tau, d0, &inv, &jac, reported_p);
    let jac = jac.0;
    // (t*, d0) from p, to first order.
    let g_t = Vector3::new(0.0, 1.0, 0.0);
    let g_d = Vector3::new(c / d0, -tau / d0, -0.5 / d0);
    let project = |c: &Matrix3<f64>| {
        let (tt, td, dd) = (
            (g_t.transpose() * c * g_t)[0],
            (g_t.transpose() * c * g_d)[0],
            (g_d.transpose() * c * g_d)[0],
        );
        [tt, td, td, dd]
    };
    let along = t[r] + tau;
    let influence = (0..n)
        .map(|i| {
            let g = inv * jac.row(i).transpose().fixed_rows::<3>(0) * seg[i].weight.sqrt();
            [g_t.dot(&g), g_d.dot(&g)]
        })
        .collect();
    Ok(Circle {
        centre: [0, 1, 2].map(|j| origin[j] + along * u[j]),
        direction: u,
        radius_m: d0,
        covariance: project(&cov_p),
        reported: project(&reported_p),
        rms_rad: (sse / reads.max(f64::MIN_POSITIVE)).sqrt() * 4.0 * std::f64::consts::PI / lambda,
        samples: n,
        influence,
        evidence,
    })
}

/// The segment's [`Setup`], if its geometry allows a fit.
fn setup(seg: &[Obs], sign: f64) -> Result<Setup, NoFix> {
    let n = seg.len();
    let points: Vec<[f64; 3]> = seg.iter().map(|o| o.antenna).collect();
    let (origin, u, perp) = line(&points).ok_or(NoFix::InsufficientGeometry)?;
    let lambda = seg[0].wavelength_m;
    let t: Vec<f64> = points
        .iter()
        .map(|p| (0..3).map(|k| (p[k] - origin[k]) * u[k]).sum())
        .collect();
    let (t_min, t_max) = t
        .iter()
        .fold((f64::MAX, f64::MIN), |(lo, hi), &x| (lo.min(x), hi.max(x)));
    if perp > MAX_PATH_RMS_M || t_max - t_min < lambda / 2.0 {
        return Err(NoFix::InsufficientGeometry);
    }
    // Range (m, up to a constant) of each sample; the reference is the nearest.
    let q: Vec<f64> = seg
        .iter()
        .map(|o| sign * o.wavelength_m * o.phase_rad / (4.0 * std::f64::consts::PI))
        .collect();
    let r = (0..n)
        .min_by(|&i, &j| q[i].total_cmp(&q[j]))
        .ok_or(NoFix::InsufficientGeometry)?;
    // The nearest point must lie inside the aperture, with samples on both sides.
    let before = t.iter().filter(|&&x| x < t[r]).count();
    let after = t.iter().filter(|&&x| x > t[r]).count();
    if before < 2 || after < 2 {
        return Err(NoFix::InsufficientGeometry);
    }
    let l: Vec<f64> = t.iter().map(|x| x - t[r]).collect();
    let dd: Vec<f64> = q.iter().map(|x| x - q[r]).collect();
    let d0_paper = min_distance_d0(&l, &dd).ok_or(NoFix::InsufficientGeometry)?;
    Ok(Setup {
        origin,
        u,
        lambda,
        t,
        r,
        l,
        dd,
        d0_paper,
    })
}

/// Ours: p = (C, τ, K) and the normal matrix's inverse, after two reweighted solves.
fn solve(
    seg: &[Obs],
    l: &[f64],
    dd: &[f64],
    d0_paper: f64,
) -> Result<(Vector3<f64>, Matrix3<f64>), NoFix> {
    // 2CΔ_i + 2τL_i + K = L_i² − Δ_i², C the range at the reference sample, τ the nearest
    // point's offset from it along the path, K = C² − d0² − τ²; started from `d0_paper`.
    let n = seg.len();
    let mut p = Vector3::new(d0_paper, 0.0, 0.0);
    let mut solved = None;
    for _ in 0..2 {
        let (mut nm, mut v) = (Matrix3::zeros(), Vector3::zeros());
        for i in 0..n {
            let w = 1.0 / (2.0 * (dd[i] + p[0]).max(1e-6));
            let row = Vector3::new(2.0 * dd[i], 2.0 * l[i], 1.0);
            let w2 = w * w * seg[i].weight;
            nm += row * row.transpose() * w2;
            v += row * ((l[i] * l[i] - dd[i] * dd[i]) * w2);
        }
        let inv = nm.try_inverse().ok_or(NoFix::InsufficientGeometry)?;
        p = inv * v;
        solved = Some(inv);
    }
    let inv = solved.ok_or(NoFix::InsufficientGeometry)?;
    Ok((p, inv))
}

/// The weighted Jacobian (n×3) and residuals of the fit at `p` = (C, τ, K).
fn weighted_jacobian_and_residuals(
    seg: &[Obs],
    l: &[f64],
    dd: &[f64],
    p: Vector3<f64>,
) -> (DMatrix<f64>, nalgebra::DVector<f64>) {
    let n = seg.len();
    let (c, tau, k) = (p[0], p[1], p[2]);
    let (jac, res): (Vec<Vector3<f64>>, Vec<f64>) = (0..n)
        .map(|i| {
            let w = 1.0 / (2.0 * (dd[i] + c).max(1e-6));
            let fit = 2.0 * dd[i] * c + 2.0 * l[i] * tau + k;
            let root = seg[i].weight.sqrt();
            (
                Vector3::new(2.0 * dd[i], 2.0 * l[i], 1.0) * (w * root),
                w * root * (l[i] * l[i] - dd[i] * dd[i] - fit),
            )
        })
        .unzip();
    let jac = DMatrix::from_fn(n, 3, |i, a| jac[i][a]);
    let res = nalgebra::DVector::from_vec(res);
    (jac, res)
}

/// The evidence of a smooth error, and `reported_p` made at least its covariance.
fn with_smooth_error(
    seg: &[Obs],
    l: &[f64],
    tau: f64,
    d0: f64,
    inv: &Matrix3<f64>,
    (jac, res): &(DMatrix<f64>, nalgebra::DVector<f64>),
    reported_p: Matrix3<f64>,
) -> (Option<robust::Evidence>, Matrix3<f64>) {
    let n = seg.len();
    let rows: Vec<robust::Row> = (0..n)
        .map(|i| {
            let (a, b) = (l[i] - tau, d0);
            let norm = a.hypot(b).max(1e-9);
            robust::Row {
                direction: [a / norm, b / norm, 0.0],
                weight: seg[i].weight,
                segment: 0,
            }
        })
        .collect();
    let dyn_inv = DMatrix::from_column_slice(3, 3, inv.as_slice());
    let found = robust::smooth_error_and_evidence(&dyn_inv, jac, res, &rows, false);
    let evidence = found.as_ref().map(|f| f.0);
    let reported_p = match found.and_then(|f| f.1) {
        Some(smooth) => {
            let dyn_reported = DMatrix::from_column_slice(3, 3, reported_p.as_slice());
            Matrix3::from_column_slice(robust::at_least(&dyn_reported, &smooth).as_slice())
        }
        None => reported_p,
    };
    (evidence, reported_p)
}

/// `classic` made at least the cluster-robust covariance in every direction
/// ([`robust::at_least_sandwich`]), `score(i)` sample i's row of the normal equations times its
/// residual, the samples in runs of a [`robust::CLUSTERS_PER_SEGMENT`]th of the segment.
fn at_least_robust(
    classic: &Matrix3<f64>,
    bread: &Matrix3<f64>,
    n: usize,
    score: impl Fn(usize) -> Vector3<f64>,
) -> Matrix3<f64> {
    let rows: Vec<Vector3<f64>> = (0..n).map(score).collect();
    let scores = DMatrix::from_fn(n, 3, |i, a| rows[i][a]);
    let cluster_of = robust::clusters(&vec![0; n], &vec![1.0; n]);
    let dyn_of = |m: &Matrix3<f64>| DMatrix::from_column_slice(3, 3, m.as_slice());
    let r = robust::at_least_sandwich(&dyn_of(classic), &dyn_of(bread), &scores, &cluster_of);
    Matrix3::from_column_slice(r.as_slice())
}

/// A tag placed on a circle: (x, y), its covariance, the covariance to report, and the
/// Jacobian of (x, y) in the circle's (centre along the path, radius).
pub(crate) type Placed = (Vector2<f64>, Matrix2<f64>, Matrix2<f64>, Matrix2<f64>);

/// The tag's (x, y) at height `z` from one circle, on the side `facing` points to, with its
/// covariance, the covariance to report, and the Jacobian of (x, y) in the circle's (centre
/// along the path, radius).
pub(crate) fn on_circle(c: &Circle, z: f64, facing: [f64; 2]) -> Option<Placed> {
    let [ux, uy, uz] = c.direction;
    let horizontal = ux.hypot(uy);
    if uz.abs() > MAX_SLOPE || horizontal < 1e-9 {
        return None;
    }
    let mut nrm = Vector2::new(-uy, ux) / horizontal;
    if nrm.dot(&Vector2::from(facing)) < 0.0 {
        nrm = -nrm;
    }
    let dz = z - c.centre[2];
    let h_sq = c.radius_m * c.radius_m - dz * dz;
    if h_sq <= 0.0 {
        return None;
    }
    let h = h_sq.sqrt();
    let pos = Vector2::new(c.centre[0], c.centre[1]) + nrm * h;
    let j = Matrix2::from_columns(&[Vector2::new(ux, uy), nrm * (c.radius_m / h)]);
    let map = |[a, b, cc, d]: [f64; 4]| j * Matrix2::new(a, b, cc, d) * j.transpose();
    Some((pos, map(c.covariance), map(c.reported), j))
}

/// The position of a tag at height `z` from `obs` (phase sign `sign`), on the side of the path
/// that `facing` points to: one fix per straight segment, combined by their information
/// (inverse covariance).
pub fn locate(obs: &[Obs], z: f64, sign: f64, facing: [f64; 2]) -> Result<Fix, NoFix> {
    let segments = obs.iter().map(|o| o.segment + 1).max().unwrap_or(0);
    let mut by_segment: Vec<Vec<Obs>> = vec![Vec::new(); segments];
    for o in obs {
        by_segment[o.segment].push(*o);
    }
    let (mut info, mut weighted) = (Matrix2::zeros(), Vector2::zeros());
    // Σ W_s R_s W_s: the reported covariances through the classic weights W_s.
    let mut spread = Matrix2::zeros();
    let (mut sq, mut used) = (0.0, 0usize);
    // Each circle used: its phases, (x, y)'s Jacobian in (centre, radius), its weight.
    let mut parts = Vec::new();
    for seg in &by_segment {
        let Ok(c) = circle(seg, sign) else { continue };
        let Some((pos, cov, reported, j)) = on_circle(&c, z, facing) else {
            continue;
        };
        let Some(inv) = cov.try_inverse() else {
            continue;
        };
        info += inv;
        weighted += inv * pos;
        spread += inv * reported * inv;
        sq += c.rms_rad * c.rms_rad * c.samples as f64;
        used += c.samples;
        parts.push((seg, c, j, inv));
    }
    let combined = info.try_inverse().ok_or(NoFix::InsufficientGeometry)?;
    let pos = combined * weighted;
    // The segments weighted by their classic covariances (the position as before), the
    // covariance of that weighted mean from the ones reported, and at least that of an
    // error smooth in the direction the tag is read from, which segments on other channels
    // or passes share.
    let cov = combined * spread * combined;
    let cov = at_least_shared(cov, combined, &parts, [pos[0], pos[1], z]);
    if used == 0 || !(pos.iter().chain(cov.iter()).all(|x| x.is_finite())) {
        return Err(NoFix::InsufficientGeometry);
    }
    Ok(Fix {
        position: [pos[0], pos[1], z],
        covariance: [cov[(0, 0)], cov[(0, 1)], cov[(1, 0)], cov[(1, 1)]],
        rms_rad: (sq / used as f64).sqrt(),
    })
}

/// A circle used in a fix: its phases, the circle, (x, y)'s Jacobian in (centre, radius), and
/// its weight (inverse classic covariance in (x, y)).
type Part<'a> = (&'a Vec<Obs>, Circle, Matrix2<f64>, Matrix2<f64>);

/// `cov` made at least `combined` (the classic covariance of the weighted mean) plus the
/// covariance of an error smooth in the direction the tag (at `tag`) is read from, shared by
/// every circle of `parts`, the weighted mean's weight of circle s being `combined`·W_s.
fn at_least_shared(
    cov: Matrix2<f64>,
    combined: Matrix2<f64>,
    parts: &[Part<'_>],
    tag: [f64; 3],
) -> Matrix2<f64> {
    let found = parts
        .iter()
        .filter_map(|p| p.1.evidence)
        .reduce(|a, b| a + b);
    let Some(smooth) = found.and_then(|e| e.smooth_variance()) else {
        return cov;
    };
    let influence = parts.iter().flat_map(|(seg, c, j, w)| {
        let a = combined * w * j;
        seg.iter().zip(&c.influence).map(move |(o, g)| {
            let v = [0, 1, 2].map(|k| o.antenna[k] - tag[k]);
            let d = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt().max(1e-9);
            let g = a * Vector2::new(g[0], g[1]);
            (v.map(|x| x / d), Vector3::new(g[0], g[1], 0.0))
        })
    });
    let shared = robust::kernel_sum(influence);
    let total = combined
        + Matrix2::new(
            shared[(0, 0)],
            shared[(0, 1)],
            shared[(1, 0)],
            shared[(1, 1)],
        ) * smooth;
    let dyn_of = |m: &Matrix2<f64>| DMatrix::from_column_slice(2, 2, m.as_slice());
    let r = robust::at_least(&dyn_of(&cov), &dyn_of(&total));
    Matrix2::from_column_slice(r.as_slice())
}

/// The min-distance linear model as the localizer runs it: in 2D at the tag height assumed.
#[derive(Clone, Copy, Debug)]
pub struct Linear;

impl Locate for Linear {
    fn name(&self) -> &'static str {
        "linear"
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
    use crate::synthetic::{self, LAMBDA};

    /// Passes at `heights`, phase offsets 0.7, 1.7, ...
    fn pass(tag: [f64; 3], heights: &[f64], noise: f64, seed: u64) -> Vec<Obs> {
        synthetic::passes(tag, heights, (0.7, 1.0), noise, seed)
    }

    fn err(fix: &Fix, tag: [f64; 3]) -> f64 {
        (fix.position[0] - tag[0]).hypot(fix.position[1] - tag[1])
    }

    #[test]
    fn the_papers_closed_form_is_exact_when_a_sample_is_nearest() {
        // Tag 1.5 m off the path, a sample right abreast of it.
        let along: Vec<f64> = (-50..=50).map(|k| 0.02 * f64::from(k)).collect();
        let dd: Vec<f64> = along
            .iter()
            .map(|l| (1.5f64.powi(2) + l * l).sqrt() - 1.5)
            .collect();
        let d0 = min_distance_d0(&along, &dd).expect("a distance");
        assert!((d0 - 1.5).abs() < 1e-12, "{d0}");
        assert_eq!(min_distance_d0(&[0.0], &[0.0]), None);
    }

    #[test]
    fn a_noise_free_tag_is_recovered_within_a_millimetre() {
        // Off the sampling grid, at the antenna's height and 0.3 m above it, either side.
        for tag in [[1.234f64, 1.6, 0.5], [0.517, 1.1, 0.8], [1.234, -1.6, 0.5]] {
            let facing = [0.0, tag[1].signum()];
            let fix = locate(&pass(tag, &[0.5], 0.0, 1), tag[2], 1.0, facing).expect("a fix");
            assert!(err(&fix, tag) < 1e-3, "{tag:?}: {fix:?}");
            assert!(fix.rms_rad < 1e-6, "{fix:?}");
        }
        // Two heights (two segments) combined.
        let tag = [0.9, 1.3, 0.6];
        let fix = locate(&pass(tag, &[0.3, 0.9], 0.0, 1), 0.6, 1.0, [0.0, 1.0]).expect("a fix");
        assert!(err(&fix, tag) < 1e-3, "{fix:?}");
        // A reader reporting the phase negated.
        let mut neg = pass([1.0, 1.5, 0.5], &[0.5], 0.0, 1);
        neg.iter_mut().for_each(|o| o.phase_rad = -o.phase_rad);
        let fix = locate(&neg, 0.5, -1.0, [0.0, 1.0]).expect("a fix");
        assert!(err(&fix, [1.0, 1.5, 0.5]) < 1e-3, "{fix:?}");
    }

    #[test]
    fn with_noise_the_error_stays_within_the_covariance() {
        let tag = [0.8, 2.1, 0.5];
        let mut within = 0;
        for seed in 0..20 {
            let fix = locate(&pass(tag, &[0.5], 0.1, seed), 0.5, 1.0, [0.0, 1.0]).expect("fix");
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
    fn a_phase_error_smooth_along_the_path_widens_the_covariance_to_hold_the_tag() {
        // Before the cluster-robust covariance: 12 (relock) and 9 (linear) of 20.
        let held = synthetic::held_under_a_smooth_error(&|obs| {
            locate(obs, 0.5, 1.0, [0.0, 1.0]).expect("a fix")
        });
        assert!(held >= 15, "{held} of 20 inside the 95 % ellipse");
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
    fn too_little_geometry_is_said_not_guessed() {
        let tag = [1.0, 1.0, 0.5];
        let insufficient = Err(NoFix::InsufficientGeometry);
        let mut short = pass(tag, &[0.5], 0.0, 1);
        short.truncate(9);
        assert_eq!(locate(&short, 0.5, 1.0, [0.0, 1.0]), insufficient);
        assert_eq!(locate(&[], 0.5, 1.0, [0.0, 1.0]), insufficient);
        // The nearest point outside the aperture: the pass stops before it.
        let mut early = pass([2.5, 1.0, 0.5], &[0.5], 0.0, 1);
        early.truncate(200);
        assert_eq!(locate(&early, 0.5, 1.0, [0.0, 1.0]), insufficient);
        // A curved path: a quarter circle of radius 2 m around the tag's side.
        let curved: Vec<Obs> = (0..300)
            .map(|k| {
                let a = f64::from(k) / 300.0 * std::f64::consts::FRAC_PI_2;
                let p = [2.0 * a.cos() - 1.0, 2.0 * a.sin() - 2.0, 0.5];
                let d = (p[0] - tag[0]).hypot(p[1] - tag[1]);
                Obs {
                    phase_rad: 4.0 * std::f64::consts::PI * d / LAMBDA,
                    antenna: p,
                    wavelength_m: LAMBDA,
                    segment: 0,
                    group: 0,
                    joint: 0,
                    period_rad: std::f64::consts::TAU,
                    weight: 1.0,
                    scatter_rad2: 0.0,
                    t_us: 0,
                }
            })
            .collect();
        assert_eq!(locate(&curved, 0.5, 1.0, [0.0, 1.0]), insufficient);
        // A tag height the distance cannot reach: 1 m off the path, assumed 2 m higher.
        assert_eq!(
            locate(&pass(tag, &[0.5], 0.0, 1), 2.5, 1.0, [0.0, 1.0]),
            insufficient
        );
    }
}
