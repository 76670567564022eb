//! The covariance `loci3d` reports (docs/localize.md "3D by loci intersection"): each circle's
//! (centre along the path, radius) propagated to first order through the weighted mean of the
//! centres and the intersection of the circles, with the cross terms between the position
//! along the path and (y, z); each circle's reported covariance (cluster-robust, and its own
//! smooth error), and at least the one of an error smooth in the direction the tag is read
//! from that every circle shares ([`robust::kernel_sum`], as `linear` combines its circles);
//! and at least the classic one scaled by how far the circles disagree (reduced χ²).

use nalgebra::{DMatrix, DVector, Matrix2, Matrix3, Matrix3x2, Vector2, Vector3};

use super::Locus;
use crate::fix::Obs;
use crate::linear::Circle;
use crate::robust;

/// A circle used in a fix, with the phases it is made of.
pub(super) type Part<'a> = (&'a [Obs], &'a Circle);

/// What the fix solved: the path's frame, the weights of the centres along the path, and
/// the intersection's weighted Jacobian and residuals at (y, z).
pub(super) struct Solved<'a> {
    /// The circles used, in the order of `loci`.
    pub parts: &'a [Part<'a>],
    /// The circles as loci in the frame.
    pub loci: &'a [Locus],
    /// Unit vector along the path and across it (facing), horizontal.
    pub u: [f64; 2],
    /// See `u`.
    pub n: [f64; 2],
    /// The weighted Jacobian of the intersection's residuals in (y, z).
    pub jacobian: &'a DMatrix<f64>,
    /// The intersection's weighted residuals.
    pub residuals: &'a DVector<f64>,
    /// The fix (world frame).
    pub position: [f64; 3],
}

/// The covariance of the fix (world frame, row-major 3×3), or `None` when the intersection's
/// normal matrix is singular.
pub(super) fn covariance(s: &Solved<'_>) -> Option<[f64; 9]> {
    let jt = s.jacobian.transpose();
    let normal = &jt * s.jacobian;
    let a = Matrix2::new(
        normal[(0, 0)],
        normal[(0, 1)],
        normal[(1, 0)],
        normal[(1, 1)],
    )
    .try_inverse()?;
    let weights: Vec<f64> = s.parts.iter().map(|(_, c)| 1.0 / c.covariance[0]).collect();
    let total: f64 = weights.iter().sum();
    let rot = Matrix3::new(s.u[0], s.n[0], 0.0, s.u[1], s.n[1], 0.0, 0.0, 0.0, 1.0);
    // Each circle's ∂(x, y, z)/∂(centre along its path, radius), in the world frame.
    let gains: Vec<Matrix3x2<f64>> = (0..s.parts.len())
        .map(|c| rot * gain(s, c, &a, weights[c] / total))
        .collect();
    let (mut classic, mut reported) = (Matrix3::zeros(), Matrix3::zeros());
    for ((_, circle), g) in s.parts.iter().zip(&gains) {
        let of = |m: [f64; 4]| Matrix2::new(m[0], m[1], m[2], m[3]);
        classic += g * of(circle.covariance) * g.transpose();
        reported += g * of(circle.reported) * g.transpose();
    }
    let dyn_of = |m: &Matrix3<f64>| DMatrix::from_column_slice(3, 3, m.as_slice());
    let mut cov = dyn_of(&reported);
    if let Some(shared) = shared(s, &gains, &classic) {
        cov = robust::at_least(&cov, &dyn_of(&shared));
    }
    cov = robust::at_least(&cov, &dyn_of(&disagreement(s, &a, &weights, &rot)));
    let out: [f64; 9] = std::array::from_fn(|k| cov[(k / 3, k % 3)]);
    out.iter().all(|v| v.is_finite()).then_some(out)
}

/// Circle `c`'s ∂(along, across, height)/∂(centre along its path, radius) in the path's
/// frame: the centre's weight `share` in the mean along the path, and the intersection moved
/// to first order (Gauss–Newton) by the change of its residual, −A·J_cᵀ·∂ρ_c, A = (JᵀJ)⁻¹.
fn gain(s: &Solved<'_>, c: usize, a: &Matrix2<f64>, share: f64) -> Matrix3x2<f64> {
    let (l, d) = (&s.loci[c], s.parts[c].1.direction);
    let along = d[0] * s.u[0] + d[1] * s.u[1];
    let across = d[0] * s.n[0] + d[1] * s.n[1];
    let row = Vector2::new(s.jacobian[(c, 0)], s.jacobian[(c, 1)]);
    // ρ_c = ((y_c − y)² + (z_c − z)² − R²)/(2Rσ): the centre moving along the circle's own
    // path moves (y_c, z_c) by (across, d_z), and ∂ρ_c/∂(y_c, z_c) = −J_c.
    let by_centre = a * row * (row[0] * across + row[1] * d[2]);
    let by_radius = a * row * (1.0 / l.sigma_r + s.residuals[c] / l.r);
    Matrix3x2::new(
        share * along,
        0.0,
        by_centre[0],
        by_radius[0],
        by_centre[1],
        by_radius[1],
    )
}

/// The classic covariance plus that of an error smooth in the direction the tag is read
/// from, one pattern shared by every circle, each circle's part of it as large as its own
/// residuals show (σ_s,c; a circle whose residuals show none adds nothing); `None` when none
/// shows one.
fn shared(
    s: &Solved<'_>,
    gains: &[Matrix3x2<f64>],
    classic: &Matrix3<f64>,
) -> Option<Matrix3<f64>> {
    let tag = s.position;
    let mut any = false;
    let influence: Vec<([f64; 3], Vector3<f64>)> = s
        .parts
        .iter()
        .zip(gains)
        .filter_map(|((seg, c), g)| {
            let sigma = c.evidence?.smooth_variance()?.sqrt();
            any = true;
            Some(seg.iter().zip(&c.influence).map(move |(o, i)| {
                let v = [0, 1, 2].map(|k| o.antenna[k] - tag[k]);
                let d = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt().max(1e-9);
                (v.map(|x| x / d), g * Vector2::new(i[0], i[1]) * sigma)
            }))
        })
        .flatten()
        .collect();
    any.then(|| classic + robust::kernel_sum(influence.into_iter()))
}

/// The classic covariance scaled by the circles' disagreement: along the path 1/Σw times
/// the reduced χ² of the centres about their weighted mean, across and in height (JᵀJ)⁻¹
/// times the intersection's reduced χ² (each when over 1, with a degree of freedom at least).
fn disagreement(
    s: &Solved<'_>,
    a: &Matrix2<f64>,
    weights: &[f64],
    rot: &Matrix3<f64>,
) -> Matrix3<f64> {
    let total: f64 = weights.iter().sum();
    let at = |c: &Circle| {
        let centre = c.centre;
        centre[0] * s.u[0] + centre[1] * s.u[1]
    };
    let mean = s
        .parts
        .iter()
        .zip(weights)
        .map(|((_, c), w)| w * at(c))
        .sum::<f64>()
        / total;
    let chi2_along: f64 = s
        .parts
        .iter()
        .zip(weights)
        .map(|((_, c), w)| w * (at(c) - mean).powi(2))
        .sum();
    let reduced = |chi2: f64, dof: usize| {
        if dof > 0 {
            (chi2 / dof as f64).max(1.0)
        } else {
            1.0
        }
    };
    let m = s.parts.len();
    let mut path = Matrix3::zeros();
    path[(0, 0)] = reduced(chi2_along, m.saturating_sub(1)) / total;
    let yz = a * reduced(s.residuals.norm_squared(), m.saturating_sub(2));
    path.fixed_view_mut::<2, 2>(1, 1).copy_from(&yz);
    rot * path * rot.transpose()
}
