//! The covariance an estimator reports when its residuals are correlated along the pass (an
//! angle-dependent phase error, a reflection, the poses' own error): at least the classic
//! (JᵀJ)⁻¹·σ² and at least the cluster-robust (sandwich) one in every direction, the clusters
//! runs of consecutive phases (Liang & Zeger, *Biometrika* 1986; Cameron & Miller, *J. Human
//! Resources* 2015). docs/localize.md "Residuals correlated along the pass".

use nalgebra::{DMatrix, DVector, SymmetricEigen};

/// Clusters of consecutive phases a segment is cut into.
pub const CLUSTERS_PER_SEGMENT: usize = 10;

/// The cluster of each phase: runs of consecutive phases of one segment (`segment_of`), each
/// holding about a [`CLUSTERS_PER_SEGMENT`]th of its segment's `weight`, numbered in order.
pub fn clusters(segment_of: &[usize], weight: &[f64]) -> Vec<usize> {
    let segments = segment_of.iter().map(|s| s + 1).max().unwrap_or(0);
    let mut total = vec![0.0; segments];
    for (&s, &w) in segment_of.iter().zip(weight) {
        total[s] += w;
    }
    let (mut ids, mut id, mut filled) = (Vec::with_capacity(segment_of.len()), 0, 0.0);
    let mut current = usize::MAX;
    for (&s, &w) in segment_of.iter().zip(weight) {
        let limit = total[s] / CLUSTERS_PER_SEGMENT as f64;
        if current != usize::MAX && (s != current || filled >= limit) {
            id += 1;
            filled = 0.0;
        }
        current = s;
        ids.push(id);
        filled += w;
    }
    ids
}

/// `classic` made at least the sandwich `bread`·(Σ g_c g_cᵀ)·`bread`·G/(G − 1) in every
/// direction, g_c the sum of the rows of `scores` (one a phase: its Jacobian row times its
/// residual) over cluster c of `cluster_of`: `classic` plus the positive part of their
/// difference; `classic` itself when that is not finite.
pub fn at_least_sandwich(
    classic: &DMatrix<f64>,
    bread: &DMatrix<f64>,
    scores: &DMatrix<f64>,
    cluster_of: &[usize],
) -> DMatrix<f64> {
    let dims = bread.nrows();
    let count = cluster_of.iter().map(|c| c + 1).max().unwrap_or(0);
    let mut sums = vec![DVector::<f64>::zeros(dims); count];
    for (i, &c) in cluster_of.iter().enumerate() {
        for a in 0..dims {
            sums[c][a] += scores[(i, a)];
        }
    }
    let mut meat = DMatrix::<f64>::zeros(dims, dims);
    for g in &sums {
        meat += g * g.transpose();
    }
    let correction = if count > 1 {
        count as f64 / (count - 1) as f64
    } else {
        1.0
    };
    let extra = bread * meat * bread * correction - classic;
    if !extra.iter().all(|x| x.is_finite()) {
        return classic.clone();
    }
    let eigen = SymmetricEigen::new(extra);
    let positive = eigen.eigenvalues.map(|v| v.max(0.0));
    classic
        + &eigen.eigenvectors * DMatrix::from_diagonal(&positive) * eigen.eigenvectors.transpose()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clusters_cut_each_segment_into_runs_by_weight() {
        let ids = clusters(
            &[0; 20].iter().chain(&[1; 5]).copied().collect::<Vec<_>>(),
            &[1.0; 25],
        );
        // 20 phases in runs of 2, then 5 in runs of one (a tenth of 5 is under a phase).
        assert_eq!(&ids[..4], &[0, 0, 1, 1]);
        assert_eq!(ids[19], 9);
        assert_eq!(&ids[20..], &[10, 11, 12, 13, 14]);
    }

    #[test]
    fn the_reported_covariance_is_at_least_either_in_every_direction() {
        let classic = DMatrix::from_row_slice(2, 2, &[4.0, 0.0, 0.0, 1.0]);
        let bread = DMatrix::identity(2, 2);
        // Two clusters whose scores sum to (0, 3) and (0, −3): a sandwich of 18·2 along y only.
        let scores = DMatrix::from_row_slice(4, 2, &[0.0, 1.0, 0.0, 2.0, 0.0, -1.0, 0.0, -2.0]);
        let r = at_least_sandwich(&classic, &bread, &scores, &[0, 0, 1, 1]);
        assert!(
            (r[(0, 0)] - 4.0).abs() < 1e-9 && (r[(1, 1)] - 36.0).abs() < 1e-9,
            "{r}"
        );
        // Uncorrelated scores that cancel: the classic stands.
        let quiet = DMatrix::from_row_slice(2, 2, &[0.0, 0.1, 0.0, -0.1]);
        assert_eq!(
            at_least_sandwich(&classic, &bread, &quiet, &[0, 0]),
            classic
        );
    }
}
