//! 3D by loci intersection (\[A\] §III-A3): each antenna on a straight path, treated alone
//! with the tag at its own height, gives a circle around the path (centre the path's point
//! nearest the tag, radius the perpendicular distance d0, normal along the path), here from
//! the min-distance linear model ([`crate::linear::circle`], one circle per segment). The tag's
//! position along the path is the mean of the circles' centres; across the path and in height
//! it minimises Σ w_i((y_i − y)² + (z_i − z)² − R_i²)² by Levenberg–Marquardt, on the side the
//! antennas face. Circles at two heights at least are needed.
//!
//! Ours, where \[A\] is silent: the mean of the centres and the terms of the sum are weighted
//! by the inverse variances from the circles (w_i = 1/(4R_i²σ_R²)); the covariance is the
//! circles' own propagated to the fix, with an error smooth in the direction the tag is read
//! from that the circles share, and at least the classic one scaled by the circles'
//! disagreement (`loci3d/covariance.rs`; docs/localize.md).

use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{DMatrix, DVector, Dyn, Owned, Vector2};

use crate::estimator::{Locate, Need, Tag, Takes, SIGN};
use crate::fix::{Fix3, NoFix, Obs};
use crate::linear::{circle, Circle, MAX_SLOPE};

mod covariance;
#[cfg(test)]
mod tests;

/// Least spread of the circles' heights for a 3D fix (m, ours).
pub const MIN_HEIGHT_SPREAD_M: f64 = 0.05;
/// Largest angle between a circle's path and the reference circle's (rad, ours).
pub const MAX_PATH_ANGLE_RAD: f64 = 0.05;
/// Least distance of the intersection from the circles' path line, on the facing side (m,
/// ours): nearer, the circles do not meet and the solver stopped on the line.
pub const MIN_ACROSS_M: f64 = 0.01;

/// One circle in the path's frame: across-path and height of its centre, radius, and the
/// radius's standard deviation.
struct Locus {
    y: f64,
    z: f64,
    r: f64,
    sigma_r: f64,
}

struct Problem<'a> {
    loci: &'a [Locus],
    p: DVector<f64>,
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
            self.loci.len(),
            self.loci.iter().map(|l| {
                let w = 1.0 / (2.0 * l.r * l.sigma_r);
                w * ((l.y - self.p[0]).powi(2) + (l.z - self.p[1]).powi(2) - l.r * l.r)
            }),
        ))
    }

    fn jacobian(&self) -> Option<DMatrix<f64>> {
        let mut j = DMatrix::zeros(self.loci.len(), 2);
        for (i, l) in self.loci.iter().enumerate() {
            let w = 1.0 / (2.0 * l.r * l.sigma_r);
            j[(i, 0)] = -2.0 * w * (l.y - self.p[0]);
            j[(i, 1)] = -2.0 * w * (l.z - self.p[1]);
        }
        Some(j)
    }
}

/// The tag's 3D position from `obs` (phase sign `sign`; one straight segment per antenna pass,
/// at least two heights), on the side of the path that `facing` points to.
pub fn locate(obs: &[Obs], sign: f64, facing: [f64; 2]) -> Result<Fix3, NoFix> {
    let circles = segment_circles(obs, sign);
    let (reference, u, n) = frame(&circles, facing)?;
    let o = reference.centre;
    let parallel: Vec<covariance::Part<'_>> = circles
        .iter()
        .filter(|(_, c)| {
            let d = c.direction;
            (d[0] * u[0] + d[1] * u[1]).abs() >= MAX_PATH_ANGLE_RAD.cos()
        })
        .map(|(seg, c)| (seg.as_slice(), c))
        .collect();
    let (sx, wx, loci) = loci_of(&parallel, o, u, n);
    let (z_lo, z_hi) = loci.iter().fold((f64::MAX, f64::MIN), |(lo, hi), l| {
        (lo.min(l.z), hi.max(l.z))
    });
    if loci.len() < 2 || z_hi - z_lo < MIN_HEIGHT_SPREAD_M {
        return Err(NoFix::InsufficientGeometry);
    }
    let x = sx / wx;
    let (y, z, jacobian, residuals) = intersect(&loci)?;
    let across = Vector2::from(n) * y;
    let position = [o[0] + x * u[0] + across[0], o[1] + x * u[1] + across[1], z];
    let covariance = covariance::covariance(&covariance::Solved {
        parts: &parallel,
        loci: &loci,
        u,
        n,
        jacobian: &jacobian,
        residuals: &residuals,
        position,
    })
    .ok_or(NoFix::InsufficientGeometry)?;
    let (sq, used) = parallel.iter().fold((0.0, 0usize), |(sq, used), (_, c)| {
        (
            sq + c.rms_rad * c.rms_rad * c.samples as f64,
            used + c.samples,
        )
    });
    Ok(Fix3 {
        position,
        covariance,
        rms_rad: (sq / used.max(1) as f64).sqrt(),
    })
}

/// The circle of each segment of `obs` that gives one with a positive covariance, with the
/// segment's phases.
fn segment_circles(obs: &[Obs], sign: f64) -> Vec<(Vec<Obs>, Circle)> {
    let segments = obs.iter().map(|o| o.segment + 1).max().unwrap_or(0);
    let mut by_segment: Vec<Vec<Obs>> = vec![Vec::new(); segments];
    for o in obs {
        by_segment[o.segment].push(*o);
    }
    by_segment
        .into_iter()
        .filter_map(|s| circle(&s, sign).ok().map(|c| (s, c)))
        .filter(|(_, c)| c.covariance[0] > 0.0 && c.covariance[3] > 0.0)
        .collect()
}

/// The best-sampled circle and its frame: u along its path, horizontal; n across it, facing.
fn frame(
    circles: &[(Vec<Obs>, Circle)],
    facing: [f64; 2],
) -> Result<(&Circle, [f64; 2], [f64; 2]), NoFix> {
    let reference = circles
        .iter()
        .map(|(_, c)| c)
        .max_by_key(|c| c.samples)
        .ok_or(NoFix::InsufficientGeometry)?;
    let [ux, uy, uz] = reference.direction;
    let horizontal = ux.hypot(uy);
    if uz.abs() > MAX_SLOPE || horizontal < 1e-9 {
        return Err(NoFix::InsufficientGeometry);
    }
    let u = [ux / horizontal, uy / horizontal];
    let mut n = [-u[1], u[0]];
    if n[0] * facing[0] + n[1] * facing[1] < 0.0 {
        n = [-n[0], -n[1]];
    }
    Ok((reference, u, n))
}

/// The `parallel` circles as loci, with Σw·along and Σw of their centres along the path.
fn loci_of(
    parallel: &[covariance::Part<'_>],
    o: [f64; 3],
    u: [f64; 2],
    n: [f64; 2],
) -> (f64, f64, Vec<Locus>) {
    let (mut sx, mut wx) = (0.0, 0.0);
    let mut loci = Vec::new();
    for (_, c) in parallel {
        let (dx, dy) = (c.centre[0] - o[0], c.centre[1] - o[1]);
        let w = 1.0 / c.covariance[0];
        sx += w * (dx * u[0] + dy * u[1]);
        wx += w;
        loci.push(Locus {
            y: dx * n[0] + dy * n[1],
            z: c.centre[2],
            r: c.radius_m,
            sigma_r: c.covariance[3].sqrt(),
        });
    }
    (sx, wx, loci)
}

/// Where the loci meet (across, height), on the facing side, with the weighted Jacobian and
/// residuals there.
fn intersect(loci: &[Locus]) -> Result<(f64, f64, DMatrix<f64>, DVector<f64>), NoFix> {
    let count = loci.len() as f64;
    let y_mean = loci.iter().map(|l| l.y).sum::<f64>() / count;
    let z_mean = loci.iter().map(|l| l.z).sum::<f64>() / count;
    let r_mean = loci.iter().map(|l| l.r).sum::<f64>() / count;
    // Started on the facing side, at the mean radius out from the centres.
    let problem = Problem {
        loci,
        p: DVector::from_vec(vec![y_mean + r_mean, z_mean]),
    };
    let (solved, _report) = LevenbergMarquardt::new().minimize(problem);
    let (y, z) = (solved.p[0], solved.p[1]);
    let r = solved.residuals().ok_or(NoFix::InsufficientGeometry)?;
    let j = solved.jacobian().ok_or(NoFix::InsufficientGeometry)?;
    // Off the path line on the facing side: on the line itself the sum's slope across the
    // path vanishes whatever the height, and circles that do not meet leave the solver there.
    if !(y > y_mean + MIN_ACROSS_M && y.is_finite() && z.is_finite()) {
        return Err(NoFix::InsufficientGeometry);
    }
    Ok((y, z, j, r))
}

/// 3D by loci intersection as the localizer runs it.
#[derive(Clone, Copy, Debug)]
pub struct Loci3d;

impl Locate for Loci3d {
    fn name(&self) -> &'static str {
        "loci3d"
    }

    fn takes(&self) -> Takes {
        Takes::Phases
    }

    fn needs(&self) -> &'static [Need] {
        &[Need::Heights]
    }

    fn fits_height(&self, _obs: &[Obs]) -> bool {
        true
    }

    fn locate(&self, tag: &Tag<'_>) -> Result<Fix3, NoFix> {
        locate(&tag.observed.obs, SIGN, tag.observed.facing)
    }
}
