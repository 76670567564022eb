//! Synthetic phases for the estimators' unit tests: a tag seen from antennas passing along
//! y = 0 at given heights, x from −1 m in 1 cm steps, one segment per height.

use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

use super::relock::Obs;

/// The wavelength of the synthetic channel (m).
pub const LAMBDA: f64 = 0.3463;

/// Unwrapped phases of a tag at `tag` from 300 positions of a pass along y = 0 at each of
/// `heights` (segment `s` for `heights[s]`), with phase offset `offset.0 + offset.1 · s` and
/// Gaussian noise of σ `noise` (rad) from `seed`.
pub fn passes(
    tag: [f64; 3],
    heights: &[f64],
    offset: (f64, f64),
    noise: f64,
    seed: u64,
) -> Vec<Obs> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let n = Normal::new(0.0, noise.max(1e-300)).expect("valid σ");
    let mut obs = Vec::new();
    for (s, &az) in heights.iter().enumerate() {
        for k in 0..300 {
            let a = [-1.0 + 0.01 * f64::from(k), 0.0, az];
            let d = (0..3).map(|j| (tag[j] - a[j]).powi(2)).sum::<f64>().sqrt();
            let e = if noise > 0.0 { n.sample(&mut rng) } else { 0.0 };
            obs.push(Obs {
                phase_rad: offset.0
                    + offset.1 * s as f64
                    + 4.0 * std::f64::consts::PI * d / LAMBDA
                    + e,
                antenna: a,
                wavelength_m: LAMBDA,
                segment: s,
                group: s,
                joint: s,
                period_rad: std::f64::consts::TAU,
            });
        }
    }
    obs
}
