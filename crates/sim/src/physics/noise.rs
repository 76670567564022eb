//! Draws of the measurement noises: Gaussian phase and RSSI noise, the perturbed read range,
//! and the optional extra phase noise n_opt of \[G\] eq. 4.

use rand::Rng;
use rand_distr::{Cauchy, ChiSquared, Distribution, Exp, Gamma, LogNormal, Normal, Weibull};

use crate::scenario::NoiseDist;

/// A draw from N(0, σ²); 0 when σ is 0 or invalid.
pub fn gaussian<R: Rng + ?Sized>(rng: &mut R, sigma: f64) -> f64 {
    match Normal::new(0.0, sigma) {
        Ok(d) if sigma > 0.0 => d.sample(rng),
        _ => 0.0,
    }
}

/// Largest factor [`weak_signal_scale`] gives.
pub const MAX_WEAK_SIGNAL_SCALE: f64 = 100.0;

/// How fast the phase and Doppler noise grow below the reference level: σ ∝ amplitude^−0.6,
/// i.e. ×4 per 20 dB, fitted to ~158,000 reads of a static tag on an Impinj R420 (public data
/// set `crozenboom/RFID-Locate-main`: σ_φ 0.030 rad at −42.5 dBm, 0.063 at −52.5, 0.123 at
/// −62.5; docs/simulator.md). A pure 1/√SNR law would be 1.0 (×10 per 20 dB).
pub const WEAK_SIGNAL_EXPONENT: f64 = 0.6;

/// Factor on a measurement noise σ for a read at `rssi_dbm`: 1 at or above `ref_dbm`, below it
/// 10^(0.6·(ref − RSSI)/20) ([`WEAK_SIGNAL_EXPONENT`]); at most [`MAX_WEAK_SIGNAL_SCALE`].
pub fn weak_signal_scale(rssi_dbm: f64, ref_dbm: f64) -> f64 {
    weak_signal_scale_with(rssi_dbm, ref_dbm, WEAK_SIGNAL_EXPONENT)
}

/// [`weak_signal_scale`] with the exponent `k`: 10^(k·(ref − RSSI)/20) below `ref_dbm`.
pub fn weak_signal_scale_with(rssi_dbm: f64, ref_dbm: f64, k: f64) -> f64 {
    if rssi_dbm >= ref_dbm {
        1.0
    } else if rssi_dbm.is_nan() {
        MAX_WEAK_SIGNAL_SCALE
    } else {
        // 10^(k·Δ/20) as one exp (cheaper than powf on every weak read).
        (k * std::f64::consts::LN_10 / 20.0 * (ref_dbm - rssi_dbm))
            .exp()
            .min(MAX_WEAK_SIGNAL_SCALE)
    }
}

/// A draw of the extra phase noise n_opt; 0 for parameters the distribution rejects (the
/// scenario validation refuses those) and for a non-finite draw.
pub fn extra<R: Rng + ?Sized>(rng: &mut R, dist: &NoiseDist) -> f64 {
    let x = match *dist {
        NoiseDist::Uniform { low, high } => {
            if high > low {
                rng.gen_range(low..high)
            } else {
                low
            }
        }
        NoiseDist::Exponential { lambda } => Exp::new(lambda).map_or(0.0, |d| d.sample(rng)),
        NoiseDist::Gamma { shape, scale } => {
            Gamma::new(shape, scale).map_or(0.0, |d| d.sample(rng))
        }
        NoiseDist::Weibull { scale, shape } => {
            Weibull::new(scale, shape).map_or(0.0, |d| d.sample(rng))
        }
        NoiseDist::Normal { mean, std } => Normal::new(mean, std).map_or(0.0, |d| d.sample(rng)),
        NoiseDist::Lognormal { mu, sigma } => {
            LogNormal::new(mu, sigma).map_or(0.0, |d| d.sample(rng))
        }
        NoiseDist::ChiSquared { k } => ChiSquared::new(k).map_or(0.0, |d| d.sample(rng)),
        NoiseDist::Cauchy { median, scale } => {
            Cauchy::new(median, scale).map_or(0.0, |d| d.sample(rng))
        }
    };
    if x.is_finite() {
        x
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn mean_of(dist: &NoiseDist) -> f64 {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let n = 20_000;
        (0..n).map(|_| extra(&mut rng, dist)).sum::<f64>() / n as f64
    }

    #[test]
    fn weak_signals_scale_the_noise_by_the_fitted_law() {
        assert_eq!(weak_signal_scale(-40.0, -70.0), 1.0);
        assert_eq!(weak_signal_scale(-70.0, -70.0), 1.0);
        // ×4 per 20 dB (10^0.6 = 3.98).
        assert!((weak_signal_scale(-90.0, -70.0) - 10f64.powf(0.6)).abs() < 1e-12);
        assert!((weak_signal_scale(-80.0, -70.0) - 10f64.powf(0.3)).abs() < 1e-12);
        assert_eq!(weak_signal_scale(-500.0, -70.0), MAX_WEAK_SIGNAL_SCALE);
        assert_eq!(weak_signal_scale(f64::NAN, -70.0), MAX_WEAK_SIGNAL_SCALE);
    }

    #[test]
    fn cauchy_draws_are_finite() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let d = NoiseDist::Cauchy {
            median: 0.0,
            scale: 0.1,
        };
        assert!((0..10_000).all(|_| extra(&mut rng, &d).is_finite()));
        assert_eq!(gaussian(&mut rng, 0.0), 0.0);
    }

    #[test]
    fn sample_means_match_the_distributions() {
        let cases = [
            (
                NoiseDist::Uniform {
                    low: 0.0,
                    high: 0.4,
                },
                0.2,
            ),
            (NoiseDist::Exponential { lambda: 10.0 }, 0.1),
            (
                NoiseDist::Gamma {
                    shape: 2.0,
                    scale: 0.05,
                },
                0.1,
            ),
            (
                NoiseDist::Normal {
                    mean: 0.3,
                    std: 0.1,
                },
                0.3,
            ),
            (NoiseDist::ChiSquared { k: 1.0 }, 1.0),
            (
                NoiseDist::Lognormal {
                    mu: -2.0,
                    sigma: 0.1,
                },
                (-2.0f64 + 0.005).exp(),
            ),
        ];
        for (dist, expected) in cases {
            let m = mean_of(&dist);
            assert!(
                (m - expected).abs() < 0.05 * expected.abs() + 0.01,
                "{dist:?}: {m}"
            );
        }
        // Weibull(scale 1, shape 1) is Exp(1).
        assert!(
            (mean_of(&NoiseDist::Weibull {
                scale: 1.0,
                shape: 1.0
            }) - 1.0)
                .abs()
                < 0.05
        );
    }
}
