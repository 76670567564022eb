//! Received signal strength (\[G\] eqs. 1, 2, 5) and the forward link that powers the tag.
//!
//! Every RSSI form shares one absolute scale and one gain convention: RSSI (dBm) =
//! P_tx − 2·L_cable + K_BS + 40·log10(a), with the one-way amplitude gain
//! a = √(G_R·G_T)·λ/(4πD)·|1 + Σ H_i| (\[G\] eq. 1; in free space the sum is 0, so a reflector of
//! coefficient 0 changes nothing). The reader model ([`reader_dbm`]) adds measurement noise in
//! dB to that and quantises it as a reader reports it; \[G\] eq. 5 ([`backscatter_dbm`] with a
//! noise) adds an absolute noise to `a` inside the log, so that when a + n ≤ 0 the read fails
//! and the relative noise grows with distance. With \[G\]'s Table-1 mobile antenna (G = 3) and a
//! dipole tag at 30 dBm and 1 dB of cable, a tag at 3 m reads about −49 dBm and at 7 m about
//! −64 dBm.

/// Tag antenna gain (a half-wave dipole), in dBi.
pub const TAG_GAIN_DBI: f64 = 2.15;
/// Backscatter loss K_BS (tag modulation efficiency; \[G\]'s K_RT without the power), in dB.
pub const BACKSCATTER_LOSS_DB: f64 = -10.0;
/// Weakest backscatter the reader decodes (Impinj R420-class receiver), in dBm.
pub const READER_SENSITIVITY_DBM: f64 = -84.0;

/// Free-space amplitude factor λ/(4πD).
pub fn free_space_amplitude(wavelength_m: f64, distance_m: f64) -> f64 {
    wavelength_m / (4.0 * std::f64::consts::PI * distance_m)
}

/// Absolute RSSI in dBm for a one-way amplitude gain `amplitude` and an additive noise inside
/// the log; `None` when `amplitude + noise` is not positive (the read fails).
pub fn backscatter_dbm(
    tx_power_dbm: f64,
    cable_loss_db: f64,
    amplitude: f64,
    noise: f64,
) -> Option<f64> {
    let arg = amplitude + noise;
    if !(arg > 0.0 && arg.is_finite()) {
        return None;
    }
    let dbm = tx_power_dbm - 2.0 * cable_loss_db + BACKSCATTER_LOSS_DB + 40.0 * log10(arg);
    dbm.is_finite().then_some(dbm)
}

/// The reader model's RSSI in dBm: the noise-free `clean_dbm` plus `noise_db`, rounded to the
/// nearest multiple of `resolution_db` (unrounded when it is 0).
pub fn reader_dbm(clean_dbm: f64, noise_db: f64, resolution_db: f64) -> f64 {
    quantise(clean_dbm + noise_db, resolution_db)
}

/// `x` rounded to the nearest multiple of `step` (halves away from zero); `x` when `step` is
/// not positive.
pub fn quantise(x: f64, step: f64) -> f64 {
    if step > 0.0 {
        (x / step).round() * step
    } else {
        x
    }
}

/// Simplified model (\[G\] eq. 5) in dBm: 40·log10(G·λ/(4πD) + n) on the absolute scale above.
pub fn simplified_dbm(
    tx_power_dbm: f64,
    cable_loss_db: f64,
    gain_linear: f64,
    wavelength_m: f64,
    distance_m: f64,
    noise: f64,
) -> Option<f64> {
    let a = gain_linear * free_space_amplitude(wavelength_m, distance_m);
    backscatter_dbm(tx_power_dbm, cable_loss_db, a, noise)
}

/// Full model (\[G\] eq. 1) in dBm: (λ/4πD)⁴·K·G_R²·G_T²·|1 + Σ H_i|⁴, with `noise` added to
/// the amplitude inside the log as in eq. 5.
#[allow(clippy::too_many_arguments)]
pub fn full_model(
    tx_power_dbm: f64,
    cable_loss_db: f64,
    reader_gain_linear: f64,
    tag_gain_linear: f64,
    wavelength_m: f64,
    distance_m: f64,
    multipath_factor: f64,
    noise: f64,
) -> Option<f64> {
    let a = (reader_gain_linear * tag_gain_linear).sqrt()
        * free_space_amplitude(wavelength_m, distance_m)
        * multipath_factor;
    backscatter_dbm(tx_power_dbm, cable_loss_db, a, noise)
}

/// Power reaching the tag chip in dBm (forward link, Friis with the multipath factor):
/// P_tx − L_cable + G_R + G_T + 20·log10(λ/(4πD)·|1 + Σ H_i|); −∞ when the paths cancel.
pub fn tag_power_dbm(
    tx_power_dbm: f64,
    cable_loss_db: f64,
    reader_gain_linear: f64,
    tag_gain_linear: f64,
    wavelength_m: f64,
    distance_m: f64,
    multipath_factor: f64,
) -> f64 {
    let a = free_space_amplitude(wavelength_m, distance_m) * multipath_factor;
    // One logarithm: 10·log10(G_R·G_T) + 20·log10(a) = 10·log10(G_R·G_T·a²).
    let p =
        tx_power_dbm - cable_loss_db + 10.0 * log10(reader_gain_linear * tag_gain_linear * a * a);
    if p.is_nan() {
        f64::NEG_INFINITY
    } else {
        p
    }
}

/// log₁₀ `x` through the natural logarithm, within two units in the last place of
/// `f64::log10` (glibc's `log10` is an older routine about twice as slow as its `log`, and
/// every read takes two).
fn log10(x: f64) -> f64 {
    x.ln() * std::f64::consts::LOG10_E
}

/// Linear power gain for a gain in dB(i).
pub fn db_to_linear(db: f64) -> f64 {
    10f64.powf(db / 10.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    const LAMBDA: f64 = 0.3463;

    #[test]
    fn reader_model_adds_db_noise_and_quantises() {
        assert_eq!(reader_dbm(-52.3, 0.0, 0.5), -52.5);
        assert_eq!(reader_dbm(-52.2, 0.0, 0.5), -52.0);
        assert_eq!(reader_dbm(-52.2, -1.0, 0.5), -53.0);
        assert_eq!(reader_dbm(-52.2, 0.0, 0.0), -52.2);
        assert_eq!(quantise(-61.25, 0.5), -61.5);
        // The step applies at any level: the noise is in dB, not inside the log.
        let near = reader_dbm(-30.0, 0.25, 0.5);
        let far = reader_dbm(-75.0, 0.25, 0.5);
        assert_eq!(near - far, 45.0);
    }

    #[test]
    fn free_space_is_the_full_model_without_paths() {
        // The simplified model with the geometric mean of the two gains is the full model
        // with a multipath factor of 1.
        let g = db_to_linear(TAG_GAIN_DBI);
        for d in [0.5, 2.0, 6.0] {
            let simple = simplified_dbm(30.0, 1.0, (3.0 * g).sqrt(), LAMBDA, d, 0.0);
            let full = full_model(30.0, 1.0, 3.0, g, LAMBDA, d, 1.0, 0.0);
            let (a, b) = (simple.expect("positive"), full.expect("positive"));
            assert!((a - b).abs() < 1e-9, "{a} {b}");
        }
    }

    #[test]
    fn log10_through_ln_matches_the_library() {
        for x in [1e-12, 3.7e-7, 0.01, 0.5, 1.0, 2.0, 10.0, 12_345.678, 1e30] {
            let (fast, lib) = (log10(x), x.log10());
            assert!(
                (fast - lib).abs() <= 4.0 * f64::EPSILON * lib.abs().max(1.0),
                "{x}"
            );
        }
        assert_eq!(log10(100.0), 2.0);
        assert!(log10(0.0) == f64::NEG_INFINITY && log10(-1.0).is_nan());
    }

    #[test]
    fn simplified_model_falls_40_db_per_decade() {
        let near = simplified_dbm(30.0, 1.0, 3.0, LAMBDA, 0.5, 0.0).expect("positive");
        let far = simplified_dbm(30.0, 1.0, 3.0, LAMBDA, 5.0, 0.0).expect("positive");
        assert!((near - far - 40.0).abs() < 1e-9, "{near} {far}");
        let a = simplified_dbm(30.0, 1.0, 3.0, LAMBDA, 2.0, 0.0).expect("positive");
        let b = simplified_dbm(30.0, 1.0, 3.0, LAMBDA, 4.0, 0.0).expect("positive");
        assert!((a - b - 40.0 * 2f64.log10()).abs() < 1e-9);
    }

    #[test]
    fn full_model_without_multipath_falls_40_db_per_decade() {
        let g = db_to_linear(TAG_GAIN_DBI);
        let near = full_model(30.0, 1.0, 3.0, g, LAMBDA, 0.7, 1.0, 0.0).expect("positive");
        let far = full_model(30.0, 1.0, 3.0, g, LAMBDA, 7.0, 1.0, 0.0).expect("positive");
        assert!((near - far - 40.0).abs() < 1e-9);
        // Gains enter squared: +3 dB of reader gain is +6 dB of RSSI.
        let louder = full_model(30.0, 1.0, 6.0, g, LAMBDA, 7.0, 1.0, 0.0).expect("positive");
        assert!((louder - far - 40.0 * 2f64.log10() / 2.0).abs() < 1e-9);
    }

    #[test]
    fn table_1_antenna_gives_realistic_levels() {
        for d in [2.0, 3.0, 5.0, 7.0] {
            let r = simplified_dbm(30.0, 1.0, 3.0, LAMBDA, d, 0.0).expect("positive");
            assert!((-75.0..=-35.0).contains(&r), "{d} m: {r} dBm");
        }
        let r3 = simplified_dbm(30.0, 1.0, 3.0, LAMBDA, 3.0, 0.0).expect("positive");
        assert!((-47.0..=-41.0).contains(&r3), "{r3}");
    }

    #[test]
    fn non_positive_log_argument_fails_the_read() {
        assert_eq!(simplified_dbm(30.0, 1.0, 3.0, LAMBDA, 7.0, -1.0), None);
        assert_eq!(backscatter_dbm(30.0, 1.0, 0.01, -0.01), None);
        assert_eq!(backscatter_dbm(30.0, 1.0, f64::NAN, 0.0), None);
    }

    #[test]
    fn forward_link_sets_range_with_tx_power() {
        let g = db_to_linear(TAG_GAIN_DBI);
        let strong = tag_power_dbm(30.0, 1.0, 3.0, g, LAMBDA, 6.0, 1.0);
        let weak = tag_power_dbm(20.0, 1.0, 3.0, g, LAMBDA, 6.0, 1.0);
        assert!((strong - weak - 10.0).abs() < 1e-9);
        // Doubling distance costs 6 dB one way.
        let far = tag_power_dbm(30.0, 1.0, 3.0, g, LAMBDA, 12.0, 1.0);
        assert!((strong - far - 20.0 * 2f64.log10()).abs() < 1e-9);
        assert_eq!(
            tag_power_dbm(30.0, 1.0, 3.0, g, LAMBDA, 6.0, 0.0),
            f64::NEG_INFINITY
        );
    }
}
