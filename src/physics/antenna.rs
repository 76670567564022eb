//! Reader antenna gain: a rotationally symmetric cos^n lobe about the boresight.
//!
//! For a beamwidth below 180° the relative power gain is cos^n(θ) with n chosen so that
//! cos^n(bw/2) = ½ (−3 dB at half the beamwidth); beyond 90° off axis only the back lobe
//! remains. For 180° ≤ bw < 360° the lobe is cos^n(θ/2) with cos^n(bw/4) = ½ (a cardioid at
//! 180°); 360° is isotropic. The pattern never drops below the back-lobe level.

use super::geometry::{angle_between, boresight, sub, Vec3};
use super::AntennaPose;

/// Relative power level of the back lobe, in dB below boresight.
pub const BACK_LOBE_DB: f64 = -25.0;

/// Exponent n of the lobe for a full −3 dB beamwidth in degrees (0 for isotropic).
pub fn pattern_exponent(beamwidth_deg: f64) -> f64 {
    let ln_half = -std::f64::consts::LN_2;
    if beamwidth_deg.is_nan() || beamwidth_deg <= 0.0 || beamwidth_deg >= 360.0 {
        0.0
    } else if beamwidth_deg < 180.0 {
        ln_half / (beamwidth_deg / 2.0).to_radians().cos().ln()
    } else {
        ln_half / (beamwidth_deg / 4.0).to_radians().cos().ln()
    }
}

/// Relative power gain in `(0, 1]` at `off_axis_rad` from boresight, for a full −3 dB
/// beamwidth `beamwidth_deg`.
pub fn gain_pattern(off_axis_rad: f64, beamwidth_deg: f64) -> f64 {
    pattern_with(
        off_axis_rad,
        beamwidth_deg,
        pattern_exponent(beamwidth_deg),
        back_lobe_floor(),
    )
}

/// The back-lobe floor as a linear power ratio.
fn back_lobe_floor() -> f64 {
    10f64.powf(BACK_LOBE_DB / 10.0)
}

/// [`gain_pattern`] with its exponent `n` and floor already computed.
fn pattern_with(off_axis_rad: f64, beamwidth_deg: f64, n: f64, floor: f64) -> f64 {
    if n == 0.0 {
        return 1.0;
    }
    let theta = off_axis_rad.abs().min(std::f64::consts::PI);
    let lobe = if beamwidth_deg < 180.0 {
        let c = theta.cos();
        if c > 0.0 {
            c.powf(n)
        } else {
            0.0
        }
    } else {
        (theta / 2.0).cos().max(0.0).powf(n)
    };
    lobe.max(floor)
}

/// Linear power gain (boresight gain `gain_dbi` times the pattern) at `off_axis_rad`.
pub fn gain_linear(gain_dbi: f64, beamwidth_deg: f64, off_axis_rad: f64) -> f64 {
    Lobe::new(gain_dbi, beamwidth_deg).gain(off_axis_rad)
}

/// An antenna's gain pattern with its constants computed once; [`Lobe::gain`] returns exactly
/// what [`gain_linear`] does.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lobe {
    /// Full −3 dB beamwidth (degrees).
    pub beamwidth_deg: f64,
    /// Boresight gain as a linear power ratio.
    pub boresight: f64,
    /// Exponent of the cos^n lobe ([`pattern_exponent`]).
    pub exponent: f64,
    /// Back-lobe floor as a linear power ratio.
    pub floor: f64,
}

impl Lobe {
    /// The lobe of an antenna of `gain_dbi` and `beamwidth_deg`.
    pub fn new(gain_dbi: f64, beamwidth_deg: f64) -> Lobe {
        Lobe {
            beamwidth_deg,
            boresight: 10f64.powf(gain_dbi / 10.0),
            exponent: pattern_exponent(beamwidth_deg),
            floor: back_lobe_floor(),
        }
    }

    /// Linear power gain at `off_axis_rad` from boresight.
    pub fn gain(&self, off_axis_rad: f64) -> f64 {
        self.boresight * pattern_with(off_axis_rad, self.beamwidth_deg, self.exponent, self.floor)
    }

    /// Linear power gain toward a direction at cos θ = `cos_off_axis` from boresight: the
    /// same lobe as [`Lobe::gain`] (cos θ for the cos^n lobe, cos(θ/2) = √((1 + cos θ)/2) for
    /// the wide one) without going through the angle.
    pub fn gain_cos(&self, cos_off_axis: f64) -> f64 {
        if self.exponent == 0.0 {
            return self.boresight;
        }
        let c = cos_off_axis.clamp(-1.0, 1.0);
        let lobe = if self.beamwidth_deg < 180.0 {
            if c > 0.0 {
                c.powf(self.exponent)
            } else {
                0.0
            }
        } else {
            ((1.0 + c) * 0.5).sqrt().powf(self.exponent)
        };
        self.boresight * lobe.max(self.floor)
    }
}

/// Angle in `[0, π]` between the antenna's boresight and the direction to `point`.
pub fn off_axis_angle(pose: &AntennaPose, point: Vec3) -> f64 {
    angle_between(
        boresight(pose.yaw_rad, pose.pitch_rad),
        sub(point, pose.position),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn db(x: f64) -> f64 {
        10.0 * x.log10()
    }

    #[test]
    fn minus_3_db_at_half_beamwidth() {
        for bw in [30.0, 70.0, 100.0, 179.0, 180.0, 240.0, 300.0] {
            let g = gain_pattern((bw / 2.0f64).to_radians(), bw);
            assert!((db(g) + 3.0103).abs() < 1e-3, "bw {bw}: {} dB", db(g));
            assert_eq!(gain_pattern(0.0, bw), 1.0);
            // Monotone fall-off inside the main lobe.
            assert!(gain_pattern((bw / 4.0f64).to_radians(), bw) > g);
        }
    }

    #[test]
    fn back_lobe_and_isotropic() {
        let g = gain_pattern(std::f64::consts::PI, 70.0);
        assert!((db(g) - BACK_LOBE_DB).abs() < 1e-9);
        assert_eq!(gain_pattern(2.0, 360.0), 1.0);
        assert!((db(gain_linear(4.77, 70.0, 0.0)) - 4.77).abs() < 1e-9);
    }

    #[test]
    fn gain_by_cosine_matches_gain_by_angle() {
        for bw in [30.0, 65.0, 70.0, 179.0, 180.0, 240.0, 360.0] {
            let lobe = Lobe::new(6.0, bw);
            for k in 0..=200 {
                let theta = std::f64::consts::PI * f64::from(k) / 200.0;
                let (a, b) = (lobe.gain(theta), lobe.gain_cos(theta.cos()));
                assert!((a - b).abs() <= 1e-12 * a, "bw {bw}, θ {theta}: {a} vs {b}");
            }
        }
    }

    #[test]
    fn off_axis_of_point_in_front_and_behind() {
        let pose = AntennaPose {
            position: [0.0, 0.0, 1.0],
            yaw_rad: std::f64::consts::FRAC_PI_2,
            pitch_rad: 0.0,
        };
        assert!(off_axis_angle(&pose, [0.0, 3.0, 1.0]).abs() < 1e-12);
        assert!((off_axis_angle(&pose, [0.0, -3.0, 1.0]) - std::f64::consts::PI).abs() < 1e-12);
        assert!(
            (off_axis_angle(&pose, [3.0, 3.0, 1.0]) - std::f64::consts::FRAC_PI_4).abs() < 1e-12
        );
    }
}
