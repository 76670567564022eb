//! The vector kernels' common parts: `f32` columns in chunks of [`LANES`], a function compiled
//! for AVX2 where the CPU has it ([`wide!`]), a branch-free sin and cos, and the runs of sorted
//! items that the kernels sum apart.

/// Defines a function that runs an `#[inline(always)]` kernel compiled for AVX2 where the CPU
/// has it (eight `f32` lanes where the x86-64 baseline, SSE2, has four), and as built
/// elsewhere. The same operations in the same order either way (no fused multiply–add), so
/// the results are the same to the bit.
macro_rules! wide {
    ($(#[$m:meta])* $vis:vis fn $name:ident($($arg:ident: $ty:ty),*) $(-> $ret:ty)? = $kernel:ident) => {
        $(#[$m])*
        $vis fn $name($($arg: $ty),*) $(-> $ret)? {
            #[cfg(target_arch = "x86_64")]
            {
                #[target_feature(enable = "avx2")]
                unsafe fn avx2($($arg: $ty),*) $(-> $ret)? {
                    $kernel($($arg),*)
                }
                if std::is_x86_feature_detected!("avx2") {
                    // SAFETY: the CPU has AVX2, checked just above.
                    return unsafe { avx2($($arg),*) };
                }
            }
            $kernel($($arg),*)
        }
    };
}
pub(crate) use wide;

/// Lanes of the kernels' chunks: the phases are padded to a multiple of this, so the
/// compiler turns the per-lane loops into vector instructions.
pub(crate) const LANES: usize = 8;

/// The LANES values of `column` from `i`.
#[inline(always)]
pub(crate) fn lanes(column: &[f32], i: usize) -> &[f32; LANES] {
    // The callers' columns are padded to a multiple of LANES and `i` is a multiple of
    // LANES below their length: the slice is LANES long.
    column[i..i + LANES]
        .try_into()
        .expect("a chunk of LANES values")
}

/// Σ `v`, in LANES partial sums (so that it runs in vector registers) and then the rest.
#[inline(always)]
pub(crate) fn sum_f32(v: &[f32]) -> f32 {
    let mut acc = [0.0f32; LANES];
    let chunks = v.chunks_exact(LANES);
    let rest: f32 = chunks.remainder().iter().sum();
    for chunk in chunks {
        for l in 0..LANES {
            acc[l] += chunk[l];
        }
    }
    acc.iter().sum::<f32>() + rest
}

/// sin and cos of `x` (|x| up to 10⁴ rad) within 2e-6, branch-free so that it vectorizes:
/// `x` reduced by whole half turns to [−π/2, π/2] (π split in two constants, Cody–Waite),
/// Taylor polynomials to the 11th (sin) and 12th (cos) power, and the signs flipped for an
/// odd count of half turns.
#[inline(always)]
pub(crate) fn sin_cos_f32(x: f32) -> (f32, f32) {
    // 1.5·2²³: adding and subtracting it rounds to the nearest integer (|v| < 2²²).
    const ROUND: f32 = 12_582_912.0;
    // π in two parts; PI_HI has 8 significant bits, so q·PI_HI is exact for |q| < 2¹⁶.
    const PI_HI: f32 = 3.140_625;
    const PI_LO: f32 = (std::f64::consts::PI - 3.140_625) as f32;
    let q = (x * std::f32::consts::FRAC_1_PI + ROUND) - ROUND;
    let r = (x - q * PI_HI) - q * PI_LO;
    let r2 = r * r;
    let s = r
        * (1.0
            + r2 * (-1.0 / 6.0
                + r2 * (1.0 / 120.0
                    + r2 * (-1.0 / 5040.0 + r2 * (1.0 / 362_880.0 - r2 * (1.0 / 39_916_800.0))))));
    let c = 1.0
        + r2 * (-0.5
            + r2 * (1.0 / 24.0
                + r2 * (-1.0 / 720.0
                    + r2 * (1.0 / 40_320.0
                        + r2 * (-1.0 / 3_628_800.0 + r2 * (1.0 / 479_001_600.0))))));
    // (−1)^q: 1 − 2·(q mod 2), from q's integer value.
    let sign = 1.0 - 2.0 * ((q as i32) & 1) as f32;
    (s * sign, c * sign)
}

/// The ranges of `items` (sorted by `key`) over which `key` is the same, in order.
pub(crate) fn runs<T>(items: &[T], key: impl Fn(&T) -> usize) -> Vec<std::ops::Range<usize>> {
    let mut out: Vec<std::ops::Range<usize>> = Vec::new();
    for (i, item) in items.iter().enumerate() {
        match out.last_mut() {
            Some(r) if key(&items[r.start]) == key(item) => r.end = i + 1,
            _ => out.push(i..i + 1),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_fast_sin_cos_matches_libm() {
        for i in -1_000_000..=1_000_000 {
            let x = i as f32 * 1e-2 + 0.123_456;
            let (s, c) = sin_cos_f32(x);
            let exact = f64::from(x);
            assert!(
                (f64::from(s) - exact.sin()).abs() < 2e-6
                    && (f64::from(c) - exact.cos()).abs() < 2e-6,
                "{x}: {s} {c}"
            );
        }
    }

    #[test]
    fn runs_cover_the_items_by_key() {
        assert_eq!(runs(&[3, 3, 5, 7, 7, 7], |&k| k), vec![0..2, 2..3, 3..6]);
        assert!(runs(&[] as &[usize], |&k| k).is_empty());
    }
}
