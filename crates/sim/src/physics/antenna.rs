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

/// Intervals of [`Pattern`]'s table over x in [0, 1].
const PATTERN_STEPS: usize = 1024;

/// Largest relative error [`Pattern::amplitude_cos`] allows itself: a step whose cubic misses
/// the exact value by more than a tenth of this at its quarter points is evaluated exactly.
pub const PATTERN_REL_ERROR: f64 = 1e-12;

/// A lobe's amplitude gain √(boresight × pattern) for fast evaluation on the per-read path:
/// the lobe is x^e (x = cos θ and e = n/2 for the cos^n lobe, x = (1 + cos θ)/2 and e = n/4
/// for the wide one) floored at the back lobe, and x^e is a piecewise cubic (Hermite, exact
/// values and slopes at 1025 nodes between the floor's x and 1) instead of a `powf`. Within
/// [`PATTERN_REL_ERROR`] of `√Lobe::gain_cos` (relative): every step is checked when the
/// table is built (at its quarter points, to a tenth of that; the cubic's error, h⁴/384 times
/// the fourth derivative, peaks near the middle of a step) and falls back to `powf` where it
/// misses (near x = 0 for small exponents, whose derivatives grow without bound there).
#[derive(Clone, Debug)]
pub struct Pattern {
    /// The lobe tabulated.
    pub lobe: Lobe,
    /// √boresight.
    boresight_amp: f64,
    /// √floor.
    floor_amp: f64,
    /// Exponent e of x^e.
    e: f64,
    /// Below this x, x^e is below the floor (by more than rounding): the table starts here.
    x_lo: f64,
    /// Steps per unit of x.
    inv_h: f64,
    /// Cubic coefficients of x^e on each step (in the step's local coordinate t ∈ [0, 1]);
    /// NaN for a step evaluated exactly. Empty when the lobe is isotropic.
    cubics: Box<[[f64; 4]]>,
}

impl Pattern {
    /// The tabulated pattern of `lobe`.
    pub fn new(lobe: &Lobe) -> Pattern {
        let wide = lobe.beamwidth_deg >= 180.0;
        let e = if wide {
            lobe.exponent / 4.0
        } else {
            lobe.exponent / 2.0
        };
        let mut p = Pattern {
            lobe: *lobe,
            boresight_amp: lobe.boresight.sqrt(),
            floor_amp: lobe.floor.sqrt(),
            e,
            x_lo: 0.0,
            inv_h: PATTERN_STEPS as f64,
            cubics: Box::new([]),
        };
        if lobe.exponent == 0.0 || !(e > 0.0 && e.is_finite()) {
            return p;
        }
        // x_lo^e is the floor up to rounding (relative 1e-16·e); below it, the floor.
        let x_lo = p.floor_amp.powf(1.0 / e).clamp(0.0, 1.0 - 1e-6);
        let h = (1.0 - x_lo) / PATTERN_STEPS as f64;
        p.x_lo = x_lo;
        p.inv_h = 1.0 / h;
        let at = |i: usize, t: f64| x_lo + (i as f64 + t) * h;
        let node = |i: usize| {
            let x = at(i, 0.0);
            (x.powf(e), e * x.powf(e - 1.0) * h)
        };
        let mut cubics = Vec::with_capacity(PATTERN_STEPS);
        for i in 0..PATTERN_STEPS {
            let ((y0, m0), (y1, m1)) = (node(i), node(i + 1));
            let cubic = [
                y0,
                m0,
                3.0 * (y1 - y0) - 2.0 * m0 - m1,
                2.0 * (y0 - y1) + m0 + m1,
            ];
            let good = [0.25, 0.5, 0.75].iter().all(|&t| {
                let exact = at(i, t).powf(e);
                let err = (cubic_at(&cubic, t) - exact).abs();
                err <= 0.1 * PATTERN_REL_ERROR * exact.max(p.floor_amp)
            });
            cubics.push(if good { cubic } else { [f64::NAN; 4] });
        }
        p.cubics = cubics.into_boxed_slice();
        p
    }

    /// √(`Lobe::gain_cos(c)`) within [`PATTERN_REL_ERROR`] (relative).
    #[inline]
    pub fn amplitude_cos(&self, cos_off_axis: f64) -> f64 {
        if self.cubics.is_empty() {
            return self.boresight_amp;
        }
        let c = cos_off_axis.clamp(-1.0, 1.0);
        let x = if self.lobe.beamwidth_deg < 180.0 {
            if c <= 0.0 {
                return self.boresight_amp * self.floor_amp;
            }
            c
        } else {
            (1.0 + c) * 0.5
        };
        let s = (x - self.x_lo) * self.inv_h;
        if s < 0.0 {
            return self.boresight_amp * self.floor_amp;
        }
        // 0 ≤ s ≤ PATTERN_STEPS (up to rounding; a NaN cosine gives a NaN s, which `as` turns
        // into 0): truncation through i64 is floor.
        let i = (s as i64 as usize).min(PATTERN_STEPS - 1);
        let cubic = &self.cubics[i];
        let v = if cubic[0].is_nan() {
            x.powf(self.e)
        } else {
            cubic_at(cubic, s - i as f64)
        };
        self.boresight_amp * v.max(self.floor_amp)
    }
}

/// a + b·t + c·t² + d·t³.
fn cubic_at(k: &[f64; 4], t: f64) -> f64 {
    k[0] + t * (k[1] + t * (k[2] + t * k[3]))
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

    #[test]
    fn tabulated_amplitude_is_within_its_bound() {
        for bw in [
            5.0, 30.0, 65.0, 70.0, 100.0, 150.0, 179.0, 180.0, 240.0, 300.0, 359.0, 360.0,
        ] {
            for gain_dbi in [6.0, -3.0] {
                let lobe = Lobe::new(gain_dbi, bw);
                let p = Pattern::new(&lobe);
                for k in 0..=100_000 {
                    // Irregular points, the ends and the nodes.
                    let c = -1.0 + 2.0 * (f64::from(k) / 100_000.0).powf(0.93);
                    for c in [c, -1.0 + 2.0 * f64::from(k % 2049) / 2048.0] {
                        let exact = lobe.gain_cos(c).sqrt();
                        let fast = p.amplitude_cos(c);
                        assert!(
                            (fast - exact).abs() <= PATTERN_REL_ERROR * exact,
                            "bw {bw}, c {c}: {fast} vs {exact}"
                        );
                    }
                }
            }
        }
    }
}
