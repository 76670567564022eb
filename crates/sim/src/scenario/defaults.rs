//! The built-in defaults of the scenario format's fields (the reader model `ideal`).

pub(super) fn default_listen() -> String {
    "127.0.0.1:5084".to_string()
}
/// Marks a field whose default depends on other fields; replaced before validation.
pub(super) fn unset_f64() -> f64 {
    f64::NAN
}
pub(super) fn default_report_interval_ms() -> u32 {
    1000
}
pub(super) fn default_wheel_radius() -> f64 {
    0.20
}
pub(super) fn default_wheel_base() -> f64 {
    0.50
}
pub(super) fn default_k_odometry() -> f64 {
    1e-5
}
pub(super) fn default_k_v() -> f64 {
    1.0
}
pub(super) fn default_k_omega() -> f64 {
    2.0
}
pub(super) fn default_tolerance() -> f64 {
    0.05
}
pub(super) fn default_gain_dbi() -> f64 {
    4.77
}
pub(super) fn default_beamwidth() -> f64 {
    70.0
}
pub(super) fn default_tx_power() -> f64 {
    30.0
}
pub(super) fn default_cable_loss() -> f64 {
    1.0
}
pub(super) fn default_tag_sensitivity() -> f64 {
    -18.0
}
pub(super) fn default_phase_sign() -> f64 {
    1.0
}
pub(super) fn default_phase_noise() -> f64 {
    0.025
}

pub(super) fn default_rssi_sigma() -> f64 {
    0.4
}
pub(super) fn default_rssi_resolution() -> f64 {
    0.5
}
pub(super) fn default_noise_ref() -> f64 {
    -40.0
}
pub(super) fn default_doppler_sigma() -> f64 {
    5.0
}
pub(super) fn default_cable_delay() -> f64 {
    15.0
}
pub(super) fn default_tag_spread() -> f64 {
    1.0
}
pub(super) fn default_range() -> f64 {
    7.0
}
pub(super) fn default_range_sigma() -> f64 {
    0.05
}
pub(super) fn default_phase_bits() -> u8 {
    12
}
pub(super) fn default_noise_exponent() -> f64 {
    crate::physics::noise::WEAK_SIGNAL_EXPONENT
}
pub(super) fn default_pattern_deg() -> f64 {
    30.0
}
