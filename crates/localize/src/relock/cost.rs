//! The separate-offsets cost of the start's grids: the residual sum of squares of some phases
//! at any point, each segment's offset at its best, in vector registers.

use super::lanes;
use crate::fix::Obs;

/// The residual sum of squares of some phases at any point, each segment's offset at its best
/// (the segment's mean residual): in `f32`, structure of arrays, so that the residuals are
/// computed in vector registers as the coherence is ([`crate::join`]); then each
/// segment's sum of squared deviations from its mean.
struct SegmentCost {
    /// The point the antenna positions are taken relative to.
    origin: [f64; 3],
    /// The antennas' x, y, z, θ less its segment's mean θ, and s·4π/λ; padded to a multiple
    /// of LANES.
    columns: [Vec<f32>; 5],
    /// Each phase's weight (reads), 0 for padding.
    weights: Vec<f32>,
    /// Each segment's summed weight.
    totals: Vec<f32>,
    /// The phases are in segment order: where each segment's run of them is.
    runs: Vec<std::ops::Range<usize>>,
    /// Scratch: each phase's residual.
    residuals: Vec<f32>,
}

impl SegmentCost {
    fn new(obs: &[Obs], sign: f64) -> SegmentCost {
        let mut sorted: Vec<&Obs> = obs.iter().collect();
        sorted.sort_by_key(|o| o.segment);
        let runs = lanes::runs(&sorted, |o| o.segment);
        let origin = sorted.first().map_or([0.0; 3], |o| o.antenna);
        let padded = sorted.len().div_ceil(lanes::LANES) * lanes::LANES;
        let mut columns: [Vec<f32>; 5] = std::array::from_fn(|_| vec![0.0; padded]);
        let mut weights = vec![0.0; padded];
        let mut totals = Vec::with_capacity(runs.len());
        for r in &runs {
            let run = &sorted[r.clone()];
            let total: f64 = run.iter().map(|o| o.weight).sum();
            totals.push(total as f32);
            let mean = run.iter().map(|o| o.weight * o.phase_rad).sum::<f64>() / total;
            for i in r.clone() {
                let o = sorted[i];
                weights[i] = o.weight as f32;
                for a in 0..3 {
                    columns[a][i] = (o.antenna[a] - origin[a]) as f32;
                }
                columns[3][i] = (o.phase_rad - mean) as f32;
                columns[4][i] = (sign * 4.0 * std::f64::consts::PI / o.wavelength_m) as f32;
            }
        }
        SegmentCost {
            origin,
            columns,
            weights,
            totals,
            runs,
            residuals: vec![0.0; padded],
        }
    }

    /// The cost at `p`.
    fn at(&mut self, p: [f64; 3]) -> f64 {
        let p = [0, 1, 2].map(|a| (p[a] - self.origin[a]) as f32);
        let c = &self.columns;
        residuals(
            [c[0].as_slice(), &c[1], &c[2], &c[3], &c[4]],
            p,
            &mut self.residuals,
        );
        let (r, w) = (&self.residuals, &self.weights);
        self.runs
            .iter()
            .zip(&self.totals)
            .map(|(run, &total)| {
                let (v, w) = (&r[run.clone()], &w[run.clone()]);
                // One pass, on the residuals less the segment's first: they share a large
                // common part (s·4πd/λ), which Σr² − (Σr)²/W would cancel in f32; less one of
                // them, what is left is of the size of their spread.
                let first = v[0];
                let (mut sum, mut squares) = (0.0f32, 0.0f32);
                for (x, w) in v.iter().zip(w) {
                    let d = x - first;
                    sum += w * d;
                    squares += w * d * d;
                }
                f64::from((squares - sum * sum / total).max(0.0))
            })
            .sum()
    }
}

lanes::wide! {
    /// Each phase's residual θ − s·4πd/λ at `p` (relative to the origin) into `out`.
    fn residuals(columns: [&[f32]; 5], p: [f32; 3], out: &mut [f32]) = residuals_kernel
}

#[inline(always)]
fn residuals_kernel(columns: [&[f32]; 5], p: [f32; 3], out: &mut [f32]) {
    let [px, py, pz] = p;
    for i in (0..columns[0].len() / lanes::LANES).map(|c| c * lanes::LANES) {
        let lanes = |c: usize| lanes::lanes(columns[c], i);
        let (ax, ay, az, theta, k) = (lanes(0), lanes(1), lanes(2), lanes(3), lanes(4));
        let mut r = [0.0f32; lanes::LANES];
        for l in 0..lanes::LANES {
            let (dx, dy, dz) = (px - ax[l], py - ay[l], pz - az[l]);
            r[l] = theta[l] - k[l] * (dx * dx + dy * dy + dz * dz).sqrt();
        }
        out[i..i + lanes::LANES].copy_from_slice(&r);
    }
}

/// The per-segment cost of `obs` as a grid's cost.
pub(super) fn segment_cost(obs: &[Obs], sign: f64) -> impl FnMut([f64; 3]) -> f64 {
    let mut cost = SegmentCost::new(obs, sign);
    move |p| cost.at(p)
}

#[cfg(test)]
mod tests {
    use super::super::distance;
    use super::*;
    use crate::synthetic;

    /// One pass at z = 0.5 of a tag at that height, phase offset 1.7.
    fn pass(tag: [f64; 2], noise: f64, seed: u64) -> Vec<Obs> {
        synthetic::passes([tag[0], tag[1], 0.5], &[0.5], (1.7, 0.0), noise, seed)
    }

    #[test]
    fn the_vector_segment_cost_agrees_with_the_exact_one() {
        // Segments of uneven lengths (padding), phases far from zero.
        let mut obs = pass([1.2, 1.6], 0.2, 4);
        obs.truncate(obs.len() - 5);
        for (i, o) in obs.iter_mut().enumerate() {
            o.segment = (i / 7) % 9;
            o.phase_rad += 300.0 + 2.0 * o.segment as f64;
        }
        let exact = |p: [f64; 3]| {
            let mut by: Vec<Vec<f64>> = vec![Vec::new(); 9];
            for o in &obs {
                let d = distance(p, o.antenna);
                by[o.segment].push(o.phase_rad - 4.0 * std::f64::consts::PI * d / o.wavelength_m);
            }
            by.iter()
                .map(|r| {
                    let mean = r.iter().sum::<f64>() / r.len() as f64;
                    r.iter().map(|x| (x - mean).powi(2)).sum::<f64>()
                })
                .sum::<f64>()
        };
        let mut fast = SegmentCost::new(&obs, 1.0);
        for p in [[1.2, 1.6, 0.5], [0.4, 2.3, 0.5], [-1.0, 0.8, 1.5]] {
            let (f, e) = (fast.at(p), exact(p));
            assert!((f - e).abs() <= 1e-4 * e.max(1.0), "{p:?}: {f} {e}");
        }
    }
}
