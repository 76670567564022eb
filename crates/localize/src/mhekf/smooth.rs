//! The filter's covariance made at least that of a phase error smooth in the direction the tag
//! is read from (docs/localize.md "An error smooth in the direction the tag is read from"):
//! the filter takes its phases as independent, so a phase pattern of the antenna or the tag,
//! which moves its fix along whole stretches of the path, is missing from its covariance.

use nalgebra::{DMatrix, DVector};
use std::f64::consts::PI;

use super::{wrap, PoseObs};
use crate::robust;

/// `cov` (the fix's 2×2 horizontal covariance) made at least the covariance a least-squares
/// fit of the tag at `tag` (height `tag[2]`) to `reads` would have under white noise plus a
/// smooth angle-dependent error ([`robust::smooth_error`]), with a phase offset per channel;
/// `cov` itself when the residuals show no smooth error. `sign` is the phase sign.
pub(super) fn at_least(cov: [f64; 4], tag: [f64; 3], reads: &[&PoseObs], sign: f64) -> [f64; 4] {
    let filter = DMatrix::from_row_slice(2, 2, &cov);
    match smooth(tag, reads, sign) {
        Some(s) => {
            let c = robust::at_least(&filter, &s);
            [c[(0, 0)], c[(0, 1)], c[(1, 0)], c[(1, 1)]]
        }
        None => cov,
    }
}

/// The smooth-error covariance of the horizontal position, or `None`.
fn smooth(tag: [f64; 3], reads: &[&PoseObs], sign: f64) -> Option<DMatrix<f64>> {
    // Channels (segments) by wavelength, each in time order (the reads are).
    let mut waves: Vec<f64> = Vec::new();
    let segment_of: Vec<usize> = reads
        .iter()
        .map(
            |o| match waves.iter().position(|w| (w - o.wavelength_m).abs() < 1e-9) {
                Some(s) => s,
                None => {
                    waves.push(o.wavelength_m);
                    waves.len() - 1
                }
            },
        )
        .collect();
    let mut order: Vec<usize> = (0..reads.len()).collect();
    order.sort_by_key(|&i| (segment_of[i], reads[i].t_us));
    let segments = waves.len();
    // Residuals against the fix, unwrapped along each segment, and the phase's Jacobian in
    // (x, y); both centred per segment (its offset eliminated).
    let (mut r, mut j, mut rows) = (Vec::new(), Vec::new(), Vec::new());
    let mut last: Option<(usize, f64)> = None;
    for &i in &order {
        let o = reads[i];
        let v = [0, 1, 2].map(|k| o.antenna[k] - tag[k]);
        let d = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt().max(1e-9);
        let k = sign * 4.0 * PI / o.wavelength_m;
        let raw = wrap(o.phase_rad - k * d, o.period_rad);
        let residual = match last {
            Some((s, prev)) if s == segment_of[i] => prev + wrap(raw - prev, o.period_rad),
            _ => raw,
        };
        last = Some((segment_of[i], residual));
        r.push(residual);
        j.push([-k * v[0] / d, -k * v[1] / d]);
        rows.push(robust::Row {
            direction: v.map(|x| x / d),
            weight: 1.0,
            segment: segment_of[i],
        });
    }
    let (mut mean_r, mut mean_j, mut count) = (
        vec![0.0; segments],
        vec![[0.0; 2]; segments],
        vec![0.0; segments],
    );
    for (n, row) in rows.iter().enumerate() {
        let s = row.segment;
        count[s] += 1.0;
        mean_r[s] += r[n];
        mean_j[s][0] += j[n][0];
        mean_j[s][1] += j[n][1];
    }
    let n = rows.len();
    let residuals = DVector::from_fn(n, |m, _| {
        let s = rows[m].segment;
        r[m] - mean_r[s] / count[s]
    });
    let jacobian = DMatrix::from_fn(n, 2, |m, c| {
        let s = rows[m].segment;
        j[m][c] - mean_j[s][c] / count[s]
    });
    let bread = (jacobian.transpose() * &jacobian).try_inverse()?;
    robust::smooth_error(&bread, &jacobian, &residuals, &rows, true)
}
