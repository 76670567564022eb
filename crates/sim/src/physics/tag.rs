//! What makes one tag differ from another of the same model: chip sensitivity, backscatter
//! strength and the phase its chip adds (seeded per tag), and, when the scenario gives one,
//! the orientation of its dipole.
//!
//! A half-wave dipole's power pattern relative to its peak is
//! g(θ) = [cos(π/2·cos θ) / sin θ]², θ the angle between the dipole axis and the direction to
//! the antenna (Balanis, *Antenna Theory*, §4.6); against a circularly polarised reader antenna
//! a linear tag also loses half the power whatever its roll (polarisation loss factor 0.5,
//! 3 dB: Ahson & Ilyas, *RFID Handbook*, ch. 10). An oriented tag gets both, on each link.

use super::geometry::{dot, norm, sub, Vec3};
use super::{noise, seed};
use crate::scenario::{Scenario, TagSpec};

/// Polarisation loss factor of a linear tag against a circularly polarised reader antenna.
pub const CIRCULAR_PLF: f64 = 0.5;

/// Draws beyond this many σ are clipped (a tag far off its model's spread is a defect, not
/// variation).
const CLIP_SIGMAS: f64 = 3.0;

/// The per-tag part of the channel.
#[derive(Clone, Debug, PartialEq)]
pub struct TagRadio {
    /// Chip sensitivity against the antenna's nominal (dB; positive: needs more power).
    pub sensitivity_db: f64,
    /// Backscatter strength against the nominal (dB), added to every RSSI of the tag.
    pub backscatter_db: f64,
    /// Unit dipole axis, when the scenario orients the tag.
    pub axis: Option<Vec3>,
    /// The phase the tag's chip adds to every read (rad, in `[0, 2π)`).
    pub phase_rad: f64,
    /// 10^(sensitivity_db/20): the factor on the forward-link amplitude the tag needs.
    pub amplitude_scale: f64,
    /// The tag's own group delay against the nominal (ns): a phase linear in frequency.
    pub delay_ns: f64,
    /// The tag's angle-dependent phase error, if the scenario gives one.
    pub phase_field: Option<super::hardware::SmoothField>,
    /// The tag's phase curvature a (rad per rad²): a·θ² added to its phase, θ the angle off
    /// the reading antenna's boresight ([`super::hardware::curvature_phase`]).
    pub phase_curvature_rad: f64,
}

impl TagRadio {
    /// The radio of tag `index` of `scenario`: the spec's own offsets, or draws from the
    /// scenario's spread seeded by (seed, tag index).
    pub fn new(scenario: &Scenario, index: usize, spec: &TagSpec) -> TagRadio {
        let mut rng = seed::stream(&[scenario.seed, seed::domain::TAG, index as u64]);
        let v = &scenario.tag_variation;
        let mut spread = |sigma: f64| {
            noise::gaussian(&mut rng, sigma).clamp(-CLIP_SIGMAS * sigma, CLIP_SIGMAS * sigma)
        };
        // Drawn in a fixed order whether or not the spec overrides them, so that overriding
        // one value changes no other.
        let sensitivity = spread(v.sensitivity_sigma_db);
        let backscatter = spread(v.backscatter_sigma_db);
        let phase_rad = std::f64::consts::TAU * rand::Rng::gen::<f64>(&mut rng);
        let delay_ns = noise::gaussian(&mut rng, v.delay_sigma_ns).clamp(
            -CLIP_SIGMAS * v.delay_sigma_ns,
            CLIP_SIGMAS * v.delay_sigma_ns,
        );
        let phase_field = super::hardware::SmoothField::new(
            &[scenario.seed, seed::domain::TAG, index as u64, 1],
            v.phase_pattern_rad,
            v.phase_pattern_deg.to_radians(),
        );
        // A stream of its own, so that a scenario without curvature keeps every other draw.
        let phase_curvature_rad = {
            let sigma = v.phase_curvature_sigma_rad;
            let mut own = seed::stream(&[scenario.seed, seed::domain::TAG, index as u64, 2]);
            noise::gaussian(&mut own, sigma).clamp(-CLIP_SIGMAS * sigma, CLIP_SIGMAS * sigma)
        };
        let sensitivity_db = spec.sensitivity_offset_db.unwrap_or(sensitivity);
        TagRadio {
            sensitivity_db,
            amplitude_scale: 10f64.powf(sensitivity_db / 20.0),
            backscatter_db: spec.backscatter_offset_db.unwrap_or(backscatter),
            axis: spec.orientation.and_then(|a| {
                let n = norm(a);
                (n > 0.0 && n.is_finite()).then(|| [a[0] / n, a[1] / n, a[2] / n])
            }),
            phase_rad,
            delay_ns,
            phase_field,
            phase_curvature_rad,
        }
    }

    /// Factor on the tag's peak gain toward an antenna at `antenna` when the tag is at `tag`:
    /// 1 for a tag without orientation, otherwise the dipole pattern times [`CIRCULAR_PLF`].
    pub fn gain_factor(&self, antenna: Vec3, tag: Vec3) -> f64 {
        match self.axis {
            None => 1.0,
            Some(axis) => {
                let v = sub(antenna, tag);
                let d = norm(v);
                if d.is_nan() || d <= 0.0 {
                    return CIRCULAR_PLF;
                }
                dipole_pattern(dot(v, axis) / d) * CIRCULAR_PLF
            }
        }
    }

    /// Bounds on the factor on an antenna's amplitude threshold this tag needs, over every
    /// direction: (lowest, highest), the highest infinite for an oriented tag (its dipole has
    /// nulls).
    pub fn threshold_scales(&self) -> (f64, f64) {
        match self.axis {
            None => (self.amplitude_scale, self.amplitude_scale),
            Some(_) => (
                self.amplitude_scale / self.max_gain_factor().sqrt(),
                f64::INFINITY,
            ),
        }
    }

    /// The largest [`TagRadio::gain_factor`] over all directions.
    pub fn max_gain_factor(&self) -> f64 {
        if self.axis.is_some() {
            CIRCULAR_PLF
        } else {
            1.0
        }
    }
}

/// Power pattern of a half-wave dipole relative to its peak, for the cosine of the angle
/// between its axis and the direction: [cos(π/2·cos θ) / sin θ]², 0 along the axis.
pub fn dipole_pattern(cos_theta: f64) -> f64 {
    let c = cos_theta.clamp(-1.0, 1.0);
    let s2 = 1.0 - c * c;
    if s2 <= 1e-12 {
        return 0.0;
    }
    let f = (std::f64::consts::FRAC_PI_2 * c).cos();
    f * f / s2
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scenario(sigma: f64) -> Scenario {
        let mut s = Scenario::default_s1();
        s.tag_variation.sensitivity_sigma_db = sigma;
        s.tag_variation.backscatter_sigma_db = sigma;
        s
    }

    #[test]
    fn dipole_pattern_closed_form() {
        assert!((dipole_pattern(0.0) - 1.0).abs() < 1e-15);
        assert_eq!(dipole_pattern(1.0), 0.0);
        assert_eq!(dipole_pattern(-1.0), 0.0);
        // θ = 45°: cos(π/2·0.7071)² / 0.5.
        let c = std::f64::consts::FRAC_1_SQRT_2;
        let expected = (std::f64::consts::FRAC_PI_2 * c).cos().powi(2) / 0.5;
        assert!((dipole_pattern(c) - expected).abs() < 1e-12);
        // The pattern's −3 dB points of a half-wave dipole lie near θ = 51° and 129°.
        let half = dipole_pattern(51f64.to_radians().cos());
        assert!((half - 0.5).abs() < 0.02, "{half}");
    }

    #[test]
    fn orientation_sets_the_gain_factor() {
        let s = Scenario::default_s1();
        let mut spec = s.tags[0].clone();
        assert_eq!(
            TagRadio::new(&s, 0, &spec).gain_factor([0.0; 3], [1.0, 0.0, 0.0]),
            1.0
        );
        spec.orientation = Some([0.0, 0.0, 2.0]);
        let r = TagRadio::new(&s, 0, &spec);
        // Broadside: peak gain, half of it lost to polarisation.
        assert!((r.gain_factor([0.0; 3], [1.0, 0.0, 0.0]) - 0.5).abs() < 1e-15);
        // End-on: the dipole's null.
        assert_eq!(r.gain_factor([0.0, 0.0, 3.0], [0.0; 3]), 0.0);
        assert_eq!(r.max_gain_factor(), CIRCULAR_PLF);
    }

    #[test]
    fn spread_is_seeded_per_tag_and_follows_sigma() {
        let s = scenario(1.0);
        let spec = &s.tags[0];
        let draws: Vec<TagRadio> = (0..4000).map(|i| TagRadio::new(&s, i, spec)).collect();
        assert_eq!(draws[7], TagRadio::new(&s, 7, spec));
        assert_ne!(draws[7].sensitivity_db, draws[8].sensitivity_db);
        let n = draws.len() as f64;
        for pick in [
            |r: &TagRadio| r.sensitivity_db,
            |r: &TagRadio| r.backscatter_db,
        ] {
            let mean = draws.iter().map(pick).sum::<f64>() / n;
            let var = draws.iter().map(|r| (pick(r) - mean).powi(2)).sum::<f64>() / n;
            assert!(mean.abs() < 0.06, "{mean}");
            assert!((var.sqrt() - 1.0).abs() < 0.05, "{}", var.sqrt());
            assert!(draws.iter().all(|r| pick(r).abs() <= 3.0));
        }
        // No spread: every tag nominal; a spec's own value wins.
        let flat = scenario(0.0);
        let mut own = flat.tags[0].clone();
        assert_eq!(TagRadio::new(&flat, 3, &own).sensitivity_db, 0.0);
        own.sensitivity_offset_db = Some(2.5);
        let r = TagRadio::new(&flat, 3, &own);
        assert_eq!((r.sensitivity_db, r.backscatter_db), (2.5, 0.0));
        assert_eq!(
            r.phase_rad,
            TagRadio::new(&flat, 3, &flat.tags[0]).phase_rad
        );
    }
}
