//! Phase and Doppler of the backscattered carrier (\[G\] eq. 4, \[M\] eq. 13).

use super::geometry::wrap_2pi;

/// Speed of light in m/s.
pub const SPEED_OF_LIGHT: f64 = 299_792_458.0;

/// Wavelength in metres of a carrier given in kHz.
pub fn wavelength_m(frequency_khz: u32) -> f64 {
    SPEED_OF_LIGHT / (f64::from(frequency_khz) * 1e3)
}

/// Round-trip propagation phase 4πD/λ (rad, not wrapped) of a tag at `distance_m`.
pub fn round_trip_phase(distance_m: f64, wavelength_m: f64) -> f64 {
    4.0 * std::f64::consts::PI * distance_m / wavelength_m
}

/// Noise-free reported phase φ = (φ0 + sign·4πD/λ) mod 2π, in `[0, 2π)`.
pub fn phase(distance_m: f64, wavelength_m: f64, phi0: f64, sign: f64) -> f64 {
    reported_phase(round_trip_phase(distance_m, wavelength_m), phi0, sign, 0.0)
}

/// Reported phase for a round-trip propagation phase `delay_rad` (4πD/λ in free space):
/// (φ0 + sign·delay + noise) mod 2π, in `[0, 2π)`.
pub fn reported_phase(delay_rad: f64, phi0: f64, sign: f64, noise_rad: f64) -> f64 {
    wrap_2pi(phi0 + sign * delay_rad + noise_rad)
}

/// Phase (rad) a one-way group delay `delay_s` adds to the round trip at `frequency_hz`:
/// 4π·f·τ, the phase of a path longer by c·τ each way.
pub fn cable_phase(frequency_hz: f64, delay_s: f64) -> f64 {
    4.0 * std::f64::consts::PI * frequency_hz * delay_s
}

/// Doppler shift f_D = −2·v_r/λ in Hz for a radial velocity `v_r` (m/s, positive when the
/// tag moves away), so an approaching tag gives a positive shift.
pub fn doppler_hz(radial_velocity_mps: f64, wavelength_m: f64) -> f64 {
    -2.0 * radial_velocity_mps / wavelength_m
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{PI, TAU};

    #[test]
    fn wavelength_of_etsi_channel() {
        assert!((wavelength_m(865_700) - 0.3463).abs() < 1e-4);
        assert!((wavelength_m(915_000) - 0.3276).abs() < 1e-4);
    }

    #[test]
    fn phase_difference_between_two_positions_is_4_pi_delta_d_over_lambda() {
        let lambda = wavelength_m(866_300);
        let phi0 = 1.234;
        for (d0, d1) in [(2.0, 2.05), (3.0, 3.3), (1.0, 4.2), (5.5, 5.0)] {
            for sign in [1.0, -1.0] {
                let a = phase(d0, lambda, phi0, sign);
                let b = phase(d1, lambda, phi0, sign);
                let expected = (sign * 4.0 * PI * (d1 - d0) / lambda).rem_euclid(TAU);
                let got = (b - a).rem_euclid(TAU);
                let diff = (got - expected).abs();
                assert!(
                    diff.min(TAU - diff) < 1e-9,
                    "{d0}->{d1}: {got} vs {expected}"
                );
            }
        }
    }

    #[test]
    fn phase_is_in_range_and_periodic_in_half_wavelength() {
        let lambda = 0.34;
        let a = phase(1.0, lambda, 0.0, 1.0);
        let b = phase(1.0 + lambda / 2.0, lambda, 0.0, 1.0);
        let d = (a - b).abs();
        assert!(d.min(TAU - d) < 1e-9);
        assert!((0.0..TAU).contains(&phase(123.456, lambda, -7.0, -1.0)));
    }

    #[test]
    fn doppler_sign_and_magnitude() {
        let lambda = wavelength_m(915_000);
        // Approaching at 1 m/s: radial velocity −1 m/s, shift +2/λ ≈ +6.1 Hz.
        let f = doppler_hz(-1.0, lambda);
        assert!((f - 2.0 / lambda).abs() < 1e-12);
        assert!(f > 6.0 && f < 6.2);
        assert!(doppler_hz(0.5, lambda) < 0.0);
    }
}
