//! Small 3-vector helpers and angle wrapping.

/// A point or vector in metres.
pub type Vec3 = [f64; 3];

/// `a - b`.
pub fn sub(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// `a + s·b`.
pub fn add_scaled(a: Vec3, s: f64, b: Vec3) -> Vec3 {
    [a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2]]
}

/// Dot product.
pub fn dot(a: Vec3, b: Vec3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Euclidean length.
pub fn norm(a: Vec3) -> f64 {
    dot(a, a).sqrt()
}

/// Distance between two points.
pub fn distance(a: Vec3, b: Vec3) -> f64 {
    norm(sub(a, b))
}

/// Unit boresight vector for an azimuth `yaw` (about +z, 0 = +x) and elevation `pitch` (rad).
pub fn boresight(yaw_rad: f64, pitch_rad: f64) -> Vec3 {
    [
        pitch_rad.cos() * yaw_rad.cos(),
        pitch_rad.cos() * yaw_rad.sin(),
        pitch_rad.sin(),
    ]
}

/// Angle in `[0, π]` between two non-zero vectors (0 if either is zero).
pub fn angle_between(a: Vec3, b: Vec3) -> f64 {
    let n = norm(a) * norm(b);
    if n == 0.0 || !n.is_finite() {
        return 0.0;
    }
    (dot(a, b) / n).clamp(-1.0, 1.0).acos()
}

/// Wraps an angle to `(-π, π]`.
pub fn wrap_pi(a: f64) -> f64 {
    if a > -std::f64::consts::PI && a <= std::f64::consts::PI {
        return a;
    }
    let tau = std::f64::consts::TAU;
    let w = (a + std::f64::consts::PI).rem_euclid(tau) - std::f64::consts::PI;
    if w <= -std::f64::consts::PI {
        w + tau
    } else {
        w
    }
}

/// Wraps an angle to `[0, 2π)` (never returns 2π, even after rounding; non-finite gives 0).
pub fn wrap_2pi(a: f64) -> f64 {
    let tau = std::f64::consts::TAU;
    // Below 1e9 rad a whole number n of turns is taken off without `rem_euclid` (a library
    // `fmod`, slow): the rounded product n·2π is within n·7e-16 rad of n·`TAU`, so the result
    // is within (n + 1)·1e-15 rad of `rem_euclid`'s: 2e-7 rad at 1e9 rad, 2e-14 at 100 rad.
    let w = if a.abs() < 1e9 {
        let w = a - tau * super::fastmath::round_small(a * (1.0 / tau));
        if w < 0.0 {
            w + tau
        } else {
            w
        }
    } else {
        a.rem_euclid(tau)
    };
    if w.is_finite() && (0.0..tau).contains(&w) {
        w
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{FRAC_PI_2, PI, TAU};

    #[test]
    fn wrapping_stays_in_range() {
        for a in [-10.0, -PI, -1e-18, 0.0, 1.0, PI, TAU, 7.0 * TAU + 0.5] {
            let w = wrap_2pi(a);
            assert!((0.0..TAU).contains(&w), "{a} -> {w}");
            assert!(((w - a) / TAU - ((w - a) / TAU).round()).abs() < 1e-9);
            let p = wrap_pi(a);
            assert!(p > -PI && p <= PI, "{a} -> {p}");
        }
        assert_eq!(wrap_2pi(f64::NAN), 0.0);
        // Within its bound of the exact remainder.
        for i in -100_000..=100_000 {
            let a = f64::from(i) * 0.0173 + 1e-3 * f64::from(i % 7);
            let (w, exact) = (wrap_2pi(a), a.rem_euclid(TAU));
            let turns = (a / TAU).abs() + 1.0;
            let d = (w - exact).abs();
            assert!(d.min(TAU - d) <= turns * 1e-15, "{a}: {w} vs {exact}");
        }
        assert_eq!(wrap_2pi(2e9), 2e9f64.rem_euclid(TAU));
    }

    #[test]
    fn boresight_axes() {
        let x = boresight(0.0, 0.0);
        assert!((x[0] - 1.0).abs() < 1e-12);
        let y = boresight(FRAC_PI_2, 0.0);
        assert!((y[1] - 1.0).abs() < 1e-12);
        let z = boresight(0.3, FRAC_PI_2);
        assert!((z[2] - 1.0).abs() < 1e-12);
        assert!((angle_between(x, y) - FRAC_PI_2).abs() < 1e-12);
    }
}
