//! Fingerprinting's covariance (docs/localize.md "Fingerprinting, 3D"): the error the method
//! makes in this very geometry, measured on the reference tags located from each other. The
//! references whose own estimates fall nearest this estimate are draws of where a truth lies
//! given an estimate there; the second moment of their truth − estimate (not centred: the
//! estimate's bias, a weighted mean pulled towards the references' middle, is part of its
//! error), widened for being measured on few draws (a predictive region, Hotelling's T²); at
//! least the spread of the k references about the estimate, and a floor on every axis.

use nalgebra::{DMatrix, Matrix3, SymmetricEigen, Vector3};

use super::Located;
use crate::robust;

/// Located references, by the distance of their estimates from this estimate, whose errors
/// make the covariance (ours: 3·[`super::K`]).
pub const NEIGHBOURS: usize = 12;

/// σ added on every axis (m, ours): where the references measure nothing (across their plane
/// when they all lie in one) the covariance is not singular.
pub const FLOOR_M: f64 = 0.02;

/// For m = 3..=[`NEIGHBOURS`] errors spanning r = 1, 2, 3 dimensions, what their second
/// moment is multiplied by so that a new error drawn like them lies inside the 95 % ellipsoid
/// (Mahalanobis² ≤ χ²₃(0.95) = 7.815, the 3D check) 95 % of the time: for Gaussian errors
/// eᵀ(W/m)⁻¹e ~ rm/(m − r + 1)·F(r, m − r + 1) (Hotelling's T², W the sum of their outer
/// products), so rm·F₀.₉₅(r, m − r + 1)/((m − r + 1)·7.815), the F quantiles by the
/// regularised incomplete beta function. Used at least 1: never under the moment measured.
const PREDICTIVE: [[f64; NEIGHBOURS - 2]; 3] = [
    [
        1.296, 0.986, 0.846, 0.766, 0.716, 0.68, 0.655, 0.635, 0.62, 0.607,
    ],
    [
        7.294, 3.26, 2.222, 1.777, 1.536, 1.386, 1.284, 1.21, 1.155, 1.112,
    ],
    [
        248.424, 14.714, 5.935, 3.796, 2.907, 2.435, 2.145, 1.951, 1.812, 1.708,
    ],
];

/// The covariance (row-major 3×3) of an estimate at `position` whose k references spread as
/// `spread` about it, from the references `located` from each other.
pub(super) fn covariance(position: [f64; 3], spread: [f64; 9], located: &[Located]) -> [f64; 9] {
    let at = Vector3::from(position);
    let mut near: Vec<(f64, Vector3<f64>)> = located
        .iter()
        .map(|(p, e)| {
            let (p, e) = (Vector3::from(*p), Vector3::from(*e));
            ((e - at).norm_squared(), p - e)
        })
        .collect();
    near.sort_by(|a, b| a.0.total_cmp(&b.0));
    near.truncate(NEIGHBOURS);
    let spread = DMatrix::from_row_slice(3, 3, &spread);
    let mut cov = match near.len() {
        m if m >= 3 => {
            let moment = near
                .iter()
                .fold(Matrix3::zeros(), |s, (_, d)| s + d * d.transpose());
            let moment = moment / m as f64;
            // The dimensions the errors span: beyond the floor (none across the references'
            // plane when every reference and estimate lies in it).
            let dims = SymmetricEigen::new(moment)
                .eigenvalues
                .iter()
                .filter(|&&v| v > FLOOR_M * FLOOR_M)
                .count();
            let factor = PREDICTIVE[dims.max(1) - 1][m - 3].max(1.0);
            let moment = DMatrix::from_column_slice(3, 3, moment.as_slice()) * factor;
            robust::at_least(&moment, &spread)
        }
        _ => spread,
    };
    for k in 0..3 {
        cov[(k, k)] += FLOOR_M * FLOOR_M;
    }
    std::array::from_fn(|k| cov[(k / 3, k % 3)])
}
