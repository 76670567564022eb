//! Sine, cosine and arc tangent for the per-read channel, cheaper than the library's and
//! within a few units in the last place of them (the error bounds are stated per function
//! and checked by the unit tests against `f64::sin_cos` and `f64::atan2`).

use std::f64::consts::{FRAC_PI_2, PI};

/// π/2 to 32 significant bits: n·`PIO2_HI`/16 is exact for |n| < 2²¹.
const PIO2_HI: f64 = 1.570_796_326_734_125_6;
/// π/2 − `PIO2_HI`, to double precision (the rest is below 4e-27).
const PIO2_MID: f64 = 6.077_100_506_506_192e-11;
/// Largest |x| [`cis`] reduces itself (beyond it, `f64::sin_cos`).
const CIS_REDUCED_MAX: f64 = 1.0e5;

/// cos(jπ/32) for j = 0..=16.
const COS_32THS: [f64; 17] = [
    1.0,
    0.995_184_726_672_196_9,
    0.980_785_280_403_230_4,
    0.956_940_335_732_208_8,
    0.923_879_532_511_286_7,
    0.881_921_264_348_355,
    0.831_469_612_302_545_2,
    0.773_010_453_362_737,
    std::f64::consts::FRAC_1_SQRT_2,
    0.634_393_284_163_645_5,
    0.555_570_233_019_602_3,
    0.471_396_736_825_997_8,
    0.382_683_432_365_089_84,
    0.290_284_677_254_462_33,
    0.195_090_322_016_128_33,
    0.098_017_140_329_560_77,
    0.0,
];

/// (cos, sin) of qπ/32 for q = 0..64, from [`COS_32THS`] by symmetry.
const CIS_64THS: [(f64, f64); 64] = {
    let mut t = [(0.0, 0.0); 64];
    let mut q = 0;
    while q < 64 {
        let j = q % 16;
        let (c, s) = (COS_32THS[j], COS_32THS[16 - j]);
        t[q] = match q / 16 {
            0 => (c, s),
            1 => (-s, c),
            2 => (-c, -s),
            _ => (s, -c),
        };
        q += 1;
    }
    t
};

/// (cos x, sin x), each within 1e-15 of `f64::sin_cos` for |x| ≤ 1e4 (and of the same
/// accuracy up to 1e5; beyond that it is `f64::sin_cos`). The argument is reduced by nπ/32
/// in two parts (the first exact, Sterbenz: x and n·`PIO2_HI`/16 are within a factor of
/// two), leaving |r| ≤ π/64 + 1e-11, where the Taylor polynomials of degree 8 (cos) and 7
/// (sin) leave remainders below (π/64)¹⁰/10! < 3e-20 and (π/64)⁹/9! < 5e-18; the table
/// values of cos and sin of nπ/32 are correctly rounded, and the angle sum adds a few
/// rounding errors of 1.1e-16.
#[inline]
pub fn cis(x: f64) -> (f64, f64) {
    if x.abs() > CIS_REDUCED_MAX || x.is_nan() {
        let (s, c) = x.sin_cos();
        return (c, s);
    }
    let n = round_small(x * (16.0 * std::f64::consts::FRAC_2_PI));
    let r = (x - n * (PIO2_HI / 16.0)) - n * (PIO2_MID / 16.0);
    let z = r * r;
    let cr = 1.0 + z * (-1.0 / 2.0 + z * (1.0 / 24.0 + z * (-1.0 / 720.0 + z * (1.0 / 40_320.0))));
    let sr = r * (1.0 + z * (-1.0 / 6.0 + z * (1.0 / 120.0 + z * (-1.0 / 5_040.0))));
    // |n| ≤ 1e5·32/π: exact in i64, and n mod 64 is in its low bits (two's complement).
    let (ct, st) = CIS_64THS[(n as i64 & 63) as usize];
    (ct * cr - st * sr, st * cr + ct * sr)
}

/// 1.5·2⁵²: adding and subtracting it rounds a number of magnitude below 2⁵¹ to a whole one.
const ROUNDER: f64 = 6_755_399_441_055_744.0;

/// `y` rounded to a whole number (ties to even) for |y| < 2⁵¹: an addition and a subtraction
/// instead of `f64::round`, which is a library call on baseline x86-64.
pub fn round_small(y: f64) -> f64 {
    (y + ROUNDER) - ROUNDER
}

/// atan(j/8) for j = 0..=8.
const ATAN_EIGHTHS: [f64; 9] = [
    0.0,
    0.124_354_994_546_761_44,
    0.244_978_663_126_864_14,
    0.358_770_670_270_572_25,
    0.463_647_609_000_806_1,
    0.558_599_315_343_562_4,
    0.643_501_108_793_284_4,
    0.718_829_999_621_624_5,
    std::f64::consts::FRAC_PI_4,
];

/// `y.atan2(x)` (in `[−π, π]`, the same quadrant and sign conventions), within 2e-15 of it.
/// With t = min/max of |x|, |y| in [0, 1] and c = j/8 the nearest eighth, atan t =
/// atan c + atan u with u = (t − c)/(1 + t·c), |u| ≤ 1/16, where the Taylor polynomial of
/// degree 11 leaves a remainder below (1/16)¹³/13 < 2e-17. Zeros, infinities and NaN go to
/// `f64::atan2`.
pub fn atan2(y: f64, x: f64) -> f64 {
    let (ax, ay) = (x.abs(), y.abs());
    let (num, den) = if ay > ax { (ax, ay) } else { (ay, ax) };
    if !(den > 0.0 && den.is_finite()) || num == 0.0 {
        return y.atan2(x);
    }
    let t = num / den;
    // 0 < t ≤ 1: the nearest eighth is 0..=8 (truncation of a positive number is floor).
    let j = (t * 8.0 + 0.5) as i64 as f64;
    let c = j * 0.125;
    let u = (t - c) / (1.0 + t * c);
    let z = u * u;
    let p = u
        * (1.0
            + z * (-1.0 / 3.0
                + z * (1.0 / 5.0 + z * (-1.0 / 7.0 + z * (1.0 / 9.0 + z * (-1.0 / 11.0))))));
    let mut a = ATAN_EIGHTHS[(j as usize).min(8)] + p;
    if ay > ax {
        a = FRAC_PI_2 - a;
    }
    if x < 0.0 {
        a = PI - a;
    }
    if y < 0.0 {
        -a
    } else {
        a
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cis_is_within_its_bound() {
        let mut worst: f64 = 0.0;
        for i in -400_000..=400_000 {
            let x = f64::from(i) * 0.025 + 1e-4 * f64::from(i % 13);
            let (c, s) = cis(x);
            let (es, ec) = x.sin_cos();
            worst = worst.max((c - ec).abs()).max((s - es).abs());
        }
        assert!(worst <= 1e-15, "{worst}");
        // Near the quadrant boundaries and at the ends of the reduced range.
        for k in -20_000..=20_000 {
            for d in [-1e-12, 0.0, 1e-12] {
                let x = f64::from(k) * (std::f64::consts::PI / 64.0) + d;
                let (c, s) = cis(x);
                let (es, ec) = x.sin_cos();
                assert!((c - ec).abs() <= 1e-15 && (s - es).abs() <= 1e-15, "{x}");
            }
        }
        for x in [0.0, -0.0, 1e5, -1e5, 2e5, 1e7, f64::NAN] {
            let (c, s) = cis(x);
            let (es, ec) = x.sin_cos();
            assert!(
                (c - ec).abs() <= 1e-9 && (s - es).abs() <= 1e-9 || x.is_nan() && c.is_nan(),
                "{x}"
            );
        }
    }

    #[test]
    fn round_small_rounds() {
        for y in [
            0.0,
            0.4,
            0.5,
            0.6,
            1.5,
            2.5,
            -0.4,
            -0.6,
            -2.5,
            123_456.7,
            -7.0e9 - 0.3,
        ] {
            let r = round_small(y);
            assert_eq!(r.fract(), 0.0, "{y}");
            assert!((r - y).abs() <= 0.5, "{y}");
        }
    }

    #[test]
    fn atan2_is_within_its_bound() {
        let mut worst: f64 = 0.0;
        for i in 0..200_000 {
            let angle = -std::f64::consts::PI + f64::from(i) * (std::f64::consts::TAU / 200_000.0);
            for r in [1e-3, 0.7, 1.0, 3.5] {
                let (y, x) = (r * angle.sin(), r * angle.cos());
                worst = worst.max((atan2(y, x) - y.atan2(x)).abs());
            }
        }
        assert!(worst <= 2e-15, "{worst}");
        for (y, x) in [
            (0.0, 1.0),
            (-0.0, 1.0),
            (0.0, -1.0),
            (-0.0, -1.0),
            (1.0, 0.0),
            (-1.0, 0.0),
            (0.0, 0.0),
            (1.0, 1.0),
            (-1.0, -1.0),
            (f64::INFINITY, 2.0),
        ] {
            assert_eq!(atan2(y, x), y.atan2(x), "({y}, {x})");
        }
        assert!(atan2(f64::NAN, 1.0).is_nan());
    }
}
