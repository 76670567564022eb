//! What real reader and tag hardware adds to a read beyond the free-space channel
//! (docs/measurement.md): a smooth angle-dependent phase error, backscatter compression at
//! strong signal, heavy-tailed noise and rare outliers, per-channel RSSI and phase, and the
//! reader's phase quantum. Every part is seeded; each is off at its default.

use rand::Rng;
use rand_distr::{Distribution, StudentT};

use super::geometry::{norm, sub, Vec3};
use super::seed;

/// Terms of a [`SmoothField`].
const TERMS: usize = 8;

/// A seeded random smooth function of a direction: a sum of eight cosines of random
/// directions' projections, so nearby directions get nearly the same value and directions
/// about `correlation_rad` apart are no longer alike. Its RMS over directions is `rms`.
#[derive(Clone, Debug, PartialEq)]
pub struct SmoothField {
    waves: [[f64; 3]; TERMS],
    phases: [f64; TERMS],
    amplitude: f64,
}

impl SmoothField {
    /// The field seeded by `words`, of RMS `rms` (rad) and correlation angle
    /// `correlation_rad`; `None` when `rms` is 0.
    pub fn new(words: &[u64], rms: f64, correlation_rad: f64) -> Option<SmoothField> {
        if rms <= 0.0 || !rms.is_finite() {
            return None;
        }
        let mut rng = seed::stream(words);
        let k = 1.0 / correlation_rad.max(1e-3);
        let mut waves = [[0.0; 3]; TERMS];
        let mut phases = [0.0; TERMS];
        for (w, p) in waves.iter_mut().zip(phases.iter_mut()) {
            // A direction uniform on the sphere, its length spread about 1/correlation.
            let z: f64 = rng.gen_range(-1.0..1.0);
            let a: f64 = rng.gen_range(0.0..std::f64::consts::TAU);
            let r = (1.0 - z * z).sqrt();
            let len = k * rng.gen_range(0.5..1.5);
            *w = [r * a.cos() * len, r * a.sin() * len, z * len];
            *p = rng.gen_range(0.0..std::f64::consts::TAU);
        }
        Some(SmoothField {
            waves,
            phases,
            // Each cosine has RMS 1/√2 over its phase: √(2/TERMS) makes the sum's RMS 1.
            amplitude: rms * (2.0 / TERMS as f64).sqrt(),
        })
    }

    /// The field's value for the unit direction `u`.
    pub fn at(&self, u: Vec3) -> f64 {
        let mut sum = 0.0;
        for (w, p) in self.waves.iter().zip(&self.phases) {
            sum += (w[0] * u[0] + w[1] * u[1] + w[2] * u[2] + p).cos();
        }
        self.amplitude * sum
    }
}

/// The unit direction from `from` to `to`; +x when they coincide.
pub fn direction(from: Vec3, to: Vec3) -> Vec3 {
    let v = sub(to, from);
    let n = norm(v);
    if n > 0.0 && n.is_finite() {
        [v[0] / n, v[1] / n, v[2] / n]
    } else {
        [1.0, 0.0, 0.0]
    }
}

/// The direction `u` in an antenna's own frame (boresight `b`, unit): (along the horizontal
/// right axis, along the up axis, along the boresight), so the antenna's phase pattern turns
/// with the antenna.
pub fn in_antenna_frame(u: Vec3, b: Vec3) -> Vec3 {
    // right = b × z (horizontal), up = right × b; a vertical boresight takes x as right.
    let right = {
        let r = [b[1], -b[0], 0.0];
        let n = norm(r);
        if n > 1e-9 {
            [r[0] / n, r[1] / n, 0.0]
        } else {
            [1.0, 0.0, 0.0]
        }
    };
    let up = [
        right[1] * b[2] - right[2] * b[1],
        right[2] * b[0] - right[0] * b[2],
        right[0] * b[1] - right[1] * b[0],
    ];
    let dot = |a: Vec3, c: Vec3| a[0] * c[0] + a[1] * c[1] + a[2] * c[2];
    [dot(u, right), dot(u, up), dot(u, b)]
}

/// The angle off boresight (degrees) beyond which the phase error stops growing: the real
/// rail's reads reach 55° (docs/measurement.md "Where the model still differs"); past 60° the
/// growth is held rather than extrapolated.
pub const PATTERN_GROWTH_HELD_DEG: f64 = 60.0;

/// How many times the angle-dependent phase error's boresight RMS it has at `off_axis_rad`
/// off the antenna's boresight: 1 + (θ/`growth_rad`)², θ held at
/// [`PATTERN_GROWTH_HELD_DEG`]; 1 everywhere when `growth_rad` is 0 (no growth).
pub fn pattern_growth(off_axis_rad: f64, growth_rad: f64) -> f64 {
    if growth_rad <= 0.0 || !growth_rad.is_finite() || !off_axis_rad.is_finite() {
        return 1.0;
    }
    let theta = off_axis_rad.abs().min(PATTERN_GROWTH_HELD_DEG.to_radians());
    1.0 + (theta / growth_rad).powi(2)
}

/// The phase (rad) a tag of curvature `a` (rad per rad²) adds when read `off_axis_rad` off
/// the antenna's boresight: a·θ², θ held at [`PATTERN_GROWTH_HELD_DEG`]. Along an aperture x
/// at range R, 4π/λ·(R + x²/2R) + a·(x/R)² has the curvature of a tag at
/// R / (1 + a·λ/(2πR)), about a·λ/2π nearer: a range offset of the same sign and nearly the
/// same size at every distance (docs/measurement.md).
pub fn curvature_phase(a: f64, off_axis_rad: f64) -> f64 {
    if a == 0.0 || !off_axis_rad.is_finite() {
        return 0.0;
    }
    let theta = off_axis_rad.abs().min(PATTERN_GROWTH_HELD_DEG.to_radians());
    a * theta * theta
}

/// An antenna's share of what hardware adds, prepared once per model.
#[derive(Clone, Debug, Default)]
pub struct AntennaHardware {
    /// The antenna's angle-dependent phase error, if any.
    pub phase_field: Option<SmoothField>,
    /// Angle (rad) off boresight at which the angle-dependent phase error (the antenna's and
    /// the tags') has doubled its boresight RMS ([`pattern_growth`]); 0: the same everywhere.
    pub pattern_growth_rad: f64,
    /// RSSI offset per channel (index 0 = channel 1) from the band tilt; empty: none.
    pub band_db: Vec<f64>,
    /// Seed prefix of the fixed per-(tag, channel) draws.
    pub prefix: u64,
    /// σ of the fixed phase per (tag, channel) (rad).
    pub channel_phase_sigma: f64,
    /// σ of the fixed RSSI per (tag, channel) (dB).
    pub channel_rssi_sigma: f64,
}

/// Kinds of fixed per-(tag, channel) draws.
const FIXED_PHASE: u64 = 1;
const FIXED_RSSI: u64 = 2;

impl AntennaHardware {
    /// The fixed per-channel RSSI (dB) of `tag` on `channel` (1-based): the band tilt plus
    /// the tag's own per-channel offset.
    pub fn rssi_db(&self, tag: usize, channel: u16) -> f64 {
        let band = self
            .band_db
            .get(usize::from(channel).wrapping_sub(1))
            .copied()
            .unwrap_or(0.0);
        if self.channel_rssi_sigma <= 0.0 {
            return band;
        }
        let own = fixed_normal(
            seed::mix_on(self.prefix, &[FIXED_RSSI, tag as u64, u64::from(channel)]),
            self.channel_rssi_sigma,
        );
        band + own
    }

    /// The fixed per-channel phase (rad) of `tag` on `channel` (1-based).
    pub fn phase_rad(&self, tag: usize, channel: u16) -> f64 {
        if self.channel_phase_sigma <= 0.0 {
            return 0.0;
        }
        fixed_normal(
            seed::mix_on(self.prefix, &[FIXED_PHASE, tag as u64, u64::from(channel)]),
            self.channel_phase_sigma,
        )
    }
}

/// The band tilt's offset per channel of `table_khz`: `db_per_mhz` times the distance from
/// the table's centre (the middle of its lowest and highest channels); empty for no tilt.
pub fn band_offsets(table_khz: &[u32], db_per_mhz: f64) -> Vec<f64> {
    if db_per_mhz == 0.0 || table_khz.is_empty() {
        return Vec::new();
    }
    let lo = table_khz.iter().min().copied().unwrap_or(0);
    let hi = table_khz.iter().max().copied().unwrap_or(0);
    let centre = (f64::from(lo) + f64::from(hi)) / 2.0;
    table_khz
        .iter()
        .map(|&f| db_per_mhz * (f64::from(f) - centre) / 1000.0)
        .collect()
}

/// RSSI reduction (dB) of a tag whose forward link is `margin_db` over its wake-up power:
/// above `knee_db` the backscattered power grows only by (1 − `compression`) dB per dB.
pub fn compression_db(margin_db: f64, knee_db: f64, compression: f64) -> f64 {
    if compression > 0.0 && margin_db > knee_db {
        compression * (margin_db - knee_db)
    } else {
        0.0
    }
}

/// A noise draw of standard deviation `sigma`: Gaussian, or Student's t with `dof` degrees of
/// freedom scaled to the same σ when `dof` > 2.
pub fn heavy<R: Rng + ?Sized>(rng: &mut R, sigma: f64, dof: f64) -> f64 {
    if sigma <= 0.0 || !sigma.is_finite() {
        return 0.0;
    }
    if dof > 2.0 && dof.is_finite() {
        match StudentT::new(dof) {
            Ok(t) => sigma * ((dof - 2.0) / dof).sqrt() * t.sample(rng),
            Err(_) => 0.0,
        }
    } else {
        super::noise::gaussian(rng, sigma)
    }
}

/// How far out a phase outlier lands, in σ of the read's own noise.
pub const PHASE_OUTLIER_SIGMAS: f64 = 12.0;

/// An outlier's extra phase (rad) with probability `rate`: N(0, (12σ)²), else 0.
pub fn phase_outlier<R: Rng + ?Sized>(rng: &mut R, rate: f64, sigma: f64) -> f64 {
    if rate > 0.0 && rng.gen::<f64>() < rate {
        super::noise::gaussian(rng, PHASE_OUTLIER_SIGMAS * sigma)
    } else {
        0.0
    }
}

/// An outlier's extra RSSI (dB) with probability `rate`: 2–6 dB either way, else 0.
pub fn rssi_outlier<R: Rng + ?Sized>(rng: &mut R, rate: f64) -> f64 {
    if rate > 0.0 && rng.gen::<f64>() < rate {
        let size = rng.gen_range(2.0..6.0);
        if rng.gen::<bool>() {
            size
        } else {
            -size
        }
    } else {
        0.0
    }
}

/// A seeded N(0, σ²) draw from a hash: the fixed per-channel part of a (tag, channel).
pub fn fixed_normal(hash: u64, sigma: f64) -> f64 {
    if sigma <= 0.0 {
        return 0.0;
    }
    // Box–Muller from two halves of the hash chain.
    let u1 = seed::unit(hash).max(1e-300);
    let u2 = seed::unit(seed::splitmix64(hash));
    sigma * (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// `phase` (rad, in [0, 2π)) rounded to the nearest of 2^`bits` steps per turn; unchanged for
/// 0 or more than 16 bits.
pub fn quantise_phase(phase: f64, bits: u8) -> f64 {
    if bits == 0 || bits > 16 {
        return phase;
    }
    let steps = f64::from(1u32 << bits);
    let tau = std::f64::consts::TAU;
    ((phase / tau * steps).round() % steps) * tau / steps
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn a_smooth_field_has_its_rms_and_is_smooth() {
        let mut sum2 = 0.0;
        let mut n = 0.0;
        let mut step2 = 0.0;
        for s in 0..200u64 {
            let f = SmoothField::new(&[s], 0.3, 0.5).expect("field");
            for i in 0..40 {
                let a = f64::from(i) * 0.02;
                let u = [a.sin(), a.cos(), 0.0];
                let v = [(a + 0.01).sin(), (a + 0.01).cos(), 0.0];
                sum2 += f.at(u).powi(2);
                step2 += (f.at(u) - f.at(v)).powi(2);
                n += 1.0;
            }
        }
        let rms = (sum2 / n).sqrt();
        assert!((rms - 0.3).abs() < 0.03, "{rms}");
        // 0.01 rad apart, with a 0.5 rad correlation: a small fraction of the RMS.
        assert!(
            (step2 / n).sqrt() < 0.03 * 0.3 / 0.5 * 2.0,
            "{}",
            (step2 / n).sqrt()
        );
        assert!(SmoothField::new(&[1], 0.0, 0.5).is_none());
    }

    #[test]
    fn the_phase_error_grows_off_boresight_and_is_held_past_sixty_degrees() {
        let w = 25f64.to_radians();
        assert_eq!(pattern_growth(0.0, w), 1.0);
        // At the growth angle it has doubled; either side of boresight alike.
        assert!((pattern_growth(w, w) - 2.0).abs() < 1e-12);
        assert!((pattern_growth(-w, w) - 2.0).abs() < 1e-12);
        let g = |deg: f64| pattern_growth(deg.to_radians(), w);
        assert!(g(10.0) < g(30.0) && g(30.0) < g(50.0));
        assert!((g(60.0) - g(80.0)).abs() < 1e-12 && (g(60.0) - g(170.0)).abs() < 1e-12);
        // No growth angle: the same everywhere, as before the growth existed.
        assert_eq!(pattern_growth(1.2, 0.0), 1.0);
        assert_eq!(pattern_growth(f64::NAN, w), 1.0);
    }

    #[test]
    fn a_curvature_moves_the_fitted_range_by_a_wavelength_over_two_pi() {
        // The rail's aperture (±0.49 m) at its nearest and farthest tags: the range whose
        // phase curve, its offset free, fits the curved one best is the one of the same
        // curvature, R' = R / (1 + a·λ/(2πR)): about a·λ/2π nearer, the same sign at every R.
        let lambda = 299_792_458.0 / 922.375e6;
        let k = 4.0 * std::f64::consts::PI / lambda;
        let xs: Vec<f64> = (0..50).map(|i| f64::from(i) * 0.02 - 0.49).collect();
        for r in [0.51, 0.88] {
            for a in [-2.3, 1.5] {
                let seen: Vec<f64> = xs
                    .iter()
                    .map(|x| k * x.hypot(r) + curvature_phase(a, (x / r).atan()))
                    .collect();
                let cost = |rr: f64| {
                    let d: Vec<f64> = xs
                        .iter()
                        .zip(&seen)
                        .map(|(x, s)| s - k * x.hypot(rr))
                        .collect();
                    let m = d.iter().sum::<f64>() / d.len() as f64;
                    d.iter().map(|v| (v - m).powi(2)).sum::<f64>()
                };
                let best = (0..4000)
                    .map(|i| r - 0.2 + f64::from(i) * 1e-4)
                    .min_by(|p, q| cost(*p).total_cmp(&cost(*q)))
                    .unwrap_or(r);
                let expected = r / (1.0 + a * lambda / (std::f64::consts::TAU * r)) - r;
                assert!(expected * a < 0.0);
                assert!(
                    ((best - r) - expected).abs() < 0.1 * expected.abs(),
                    "R {r}, a {a}: shift {} against {expected}",
                    best - r
                );
            }
        }
        assert_eq!(curvature_phase(0.0, 0.5), 0.0);
        assert_eq!(curvature_phase(2.0, 1.5), curvature_phase(2.0, 1.2));
    }

    #[test]
    fn compression_starts_at_the_knee() {
        assert_eq!(compression_db(5.0, 10.0, 0.8), 0.0);
        assert!((compression_db(20.0, 10.0, 0.8) - 8.0).abs() < 1e-12);
        assert_eq!(compression_db(20.0, 10.0, 0.0), 0.0);
    }

    #[test]
    fn heavy_tails_keep_sigma_and_raise_kurtosis() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let xs: Vec<f64> = (0..200_000).map(|_| heavy(&mut rng, 0.02, 6.0)).collect();
        let m2 = xs.iter().map(|x| x * x).sum::<f64>() / xs.len() as f64;
        let m4 = xs.iter().map(|x| x.powi(4)).sum::<f64>() / xs.len() as f64;
        assert!((m2.sqrt() - 0.02).abs() < 0.001, "{}", m2.sqrt());
        // t with 6 degrees of freedom: excess kurtosis 6/(ν − 4) = 3.
        let k = m4 / (m2 * m2) - 3.0;
        assert!(k > 2.0 && k < 4.5, "{k}");
    }

    #[test]
    fn phase_quantum_is_a_power_of_two_of_a_turn() {
        let q = quantise_phase(1.0, 10);
        let steps = q / std::f64::consts::TAU * 1024.0;
        assert!((steps - steps.round()).abs() < 1e-9);
        assert!((q - 1.0).abs() <= std::f64::consts::TAU / 2048.0);
        assert_eq!(quantise_phase(std::f64::consts::TAU - 1e-4, 10), 0.0);
        assert_eq!(quantise_phase(1.0, 0), 1.0);
    }

    #[test]
    fn fixed_normal_draws_have_their_sigma() {
        let xs: Vec<f64> = (0..50_000u64)
            .map(|i| fixed_normal(seed::mix(&[i]), 0.3))
            .collect();
        let m = xs.iter().sum::<f64>() / xs.len() as f64;
        let sd = (xs.iter().map(|x| (x - m).powi(2)).sum::<f64>() / xs.len() as f64).sqrt();
        assert!(m.abs() < 0.01 && (sd - 0.3).abs() < 0.01, "{m} {sd}");
    }

    #[test]
    fn the_antenna_frame_puts_boresight_last() {
        let b = [0.0, 1.0, 0.0];
        let f = in_antenna_frame([0.0, 1.0, 0.0], b);
        assert!((f[2] - 1.0).abs() < 1e-12 && f[0].abs() < 1e-12 && f[1].abs() < 1e-12);
        let side = in_antenna_frame([1.0, 0.0, 0.0], b);
        assert!((side[0].abs() - 1.0).abs() < 1e-12);
        let up = in_antenna_frame([0.0, 0.0, 1.0], b);
        assert!((up[1].abs() - 1.0).abs() < 1e-12);
    }
}
