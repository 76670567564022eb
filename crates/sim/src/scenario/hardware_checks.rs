//! Checks of the fields of what hardware adds to a read (docs/measurement.md "What hardware
//! adds"): an antenna's and the tags' variation.

use super::validate::{in_range, invalid, positive, Check};
use super::{AntennaSpec, TagVariation};

/// The tags' variation fields of what hardware adds.
pub(super) fn tag_variation(v: &TagVariation) -> Check {
    in_range(
        "tag_variation.phase_pattern_rad",
        v.phase_pattern_rad,
        0.0,
        10.0,
    )?;
    positive(
        "tag_variation.phase_pattern_deg",
        v.phase_pattern_deg,
        360.0,
    )?;
    in_range(
        "tag_variation.phase_curvature_sigma_rad",
        v.phase_curvature_sigma_rad,
        0.0,
        20.0,
    )?;
    in_range("tag_variation.delay_sigma_ns", v.delay_sigma_ns, 0.0, 100.0)?;
    in_range(
        "tag_variation.channel_phase_sigma_rad",
        v.channel_phase_sigma_rad,
        0.0,
        10.0,
    )?;
    in_range(
        "tag_variation.channel_rssi_sigma_db",
        v.channel_rssi_sigma_db,
        0.0,
        20.0,
    )?;
    Ok(())
}

/// An antenna's fields of what hardware adds.
pub(super) fn antenna(p: &str, a: &AntennaSpec) -> Check {
    if !(1..=16).contains(&a.phase_resolution_bits) {
        return Err(invalid(
            format!("{p}.phase_resolution_bits"),
            format!("must be 1 to 16, got {}", a.phase_resolution_bits),
        ));
    }
    in_range(&format!("{p}.noise_exponent"), a.noise_exponent, 0.0, 2.0)?;
    if a.phase_noise_dof != 0.0 && !(a.phase_noise_dof > 2.0 && a.phase_noise_dof <= 1000.0) {
        return Err(invalid(
            format!("{p}.phase_noise_dof"),
            format!(
                "must be 0 (Gaussian) or above 2 (a finite σ) up to 1000, got {}",
                a.phase_noise_dof
            ),
        ));
    }
    in_range(
        &format!("{p}.phase_outlier_rate"),
        a.phase_outlier_rate,
        0.0,
        0.5,
    )?;
    in_range(
        &format!("{p}.rssi_outlier_rate"),
        a.rssi_outlier_rate,
        0.0,
        0.5,
    )?;
    in_range(
        &format!("{p}.backscatter_compression"),
        a.backscatter_compression,
        0.0,
        1.0,
    )?;
    in_range(
        &format!("{p}.compression_knee_db"),
        a.compression_knee_db,
        0.0,
        100.0,
    )?;
    in_range(
        &format!("{p}.rssi_tilt_db_per_mhz"),
        a.rssi_tilt_db_per_mhz,
        -10.0,
        10.0,
    )?;
    in_range(
        &format!("{p}.phase_pattern_rad"),
        a.phase_pattern_rad,
        0.0,
        10.0,
    )?;
    positive(
        &format!("{p}.phase_pattern_deg"),
        a.phase_pattern_deg,
        360.0,
    )?;
    in_range(
        &format!("{p}.phase_pattern_growth_deg"),
        a.phase_pattern_growth_deg,
        0.0,
        180.0,
    )
}
