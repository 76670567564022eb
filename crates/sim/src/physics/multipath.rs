//! Multipath by the image method: each reflecting plane adds one first-order path from the
//! antenna's mirror image to the tag, with the plane's reflection coefficient and a π phase
//! flip; the paths are summed as complex phasors (\[G\] eq. 1's 1 + Σ H_i).

use super::antenna::{Lobe, Pattern};
use super::fastmath;
use super::geometry::{add_scaled, boresight, distance, dot, norm, sub, Vec3};
use super::AntennaPose;
use crate::scenario::Reflector;

/// One reflected path.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImagePath {
    /// The antenna mirrored across the reflector.
    pub image: Vec3,
    /// Where the path meets the reflector.
    pub reflection_point: Vec3,
    /// Total path length antenna → reflector → tag (m).
    pub length_m: f64,
    /// Signed amplitude reflection coefficient (−magnitude: the π flip).
    pub coefficient: f64,
}

/// Mirror image of `point` across the plane through `plane_point` with normal `normal`
/// (`point` itself if the normal is zero).
pub fn mirror_point(point: Vec3, plane_point: Vec3, normal: Vec3) -> Vec3 {
    let n = norm(normal);
    if n == 0.0 || !n.is_finite() {
        return point;
    }
    let unit = [normal[0] / n, normal[1] / n, normal[2] / n];
    let d = dot(sub(point, plane_point), unit);
    add_scaled(point, -2.0 * d, unit)
}

/// A reflector with its unit normal computed once.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plane {
    /// A point of the plane.
    pub point: Vec3,
    /// Unit normal.
    pub unit: Vec3,
    /// Reflection coefficient magnitude (the scenario's `coefficient`).
    pub coefficient: f64,
}

/// The reflectors with a usable normal, prepared for [`channel_with`] (a zero or non-finite
/// normal reflects nothing, as in [`image_paths`]).
pub fn planes(reflectors: &[Reflector]) -> Vec<Plane> {
    reflectors
        .iter()
        .filter_map(|r| {
            let n = norm(r.normal);
            if n == 0.0 || !n.is_finite() {
                return None;
            }
            Some(Plane {
                point: r.point,
                unit: [r.normal[0] / n, r.normal[1] / n, r.normal[2] / n],
                coefficient: r.coefficient,
            })
        })
        .collect()
}

/// The image path of `antenna` to `tag` across `plane`, if both are strictly on one side.
fn image_path(antenna: Vec3, tag: Vec3, plane: &Plane) -> Option<ImagePath> {
    let unit = plane.unit;
    let da = dot(sub(antenna, plane.point), unit);
    let dt = dot(sub(tag, plane.point), unit);
    if da * dt <= 0.0 {
        return None;
    }
    let image = add_scaled(antenna, -2.0 * da, unit);
    // The segment image → tag crosses the plane at the fraction da / (da + dt).
    let s = da / (da + dt);
    let reflection_point = add_scaled(image, s, sub(tag, image));
    Some(ImagePath {
        image,
        reflection_point,
        length_m: distance(image, tag),
        coefficient: -plane.coefficient,
    })
}

/// First-order image paths from `antenna` to `tag`, one per reflector that has both strictly
/// on the same side (a plane between them, or touching either, reflects nothing).
pub fn image_paths(antenna: Vec3, tag: Vec3, reflectors: &[Reflector]) -> Vec<ImagePath> {
    planes(reflectors)
        .iter()
        .filter_map(|p| image_path(antenna, tag, p))
        .collect()
}

/// A complex number (phasor).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Complex {
    /// Real part.
    pub re: f64,
    /// Imaginary part.
    pub im: f64,
}

impl Complex {
    /// `magnitude · e^{j·angle}`.
    pub fn from_polar(magnitude: f64, angle: f64) -> Complex {
        Complex {
            re: magnitude * angle.cos(),
            im: magnitude * angle.sin(),
        }
    }

    /// Magnitude.
    pub fn abs(self) -> f64 {
        self.re.hypot(self.im)
    }

    /// Argument in `(−π, π]`.
    pub fn arg(self) -> f64 {
        self.im.atan2(self.re)
    }
}

/// The radio channel between one antenna and one tag on one wavelength.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Channel {
    /// Direct tag–antenna distance D (m).
    pub distance_m: f64,
    /// Reader antenna linear gain toward the tag (boresight gain × pattern).
    pub gain_linear: f64,
    /// |1 + Σ H_i|: multipath amplitude factor (1 in free space).
    pub multipath_factor: f64,
    /// Round-trip propagation phase (rad): 4πD/λ − 2·arg(1 + Σ H_i).
    pub delay_rad: f64,
}

/// Smallest distance used, so a tag touching the antenna stays finite (m).
pub const MIN_DISTANCE_M: f64 = 0.01;

/// The channel for an antenna (`gain_dbi`, `beamwidth_deg`) at `pose` and a tag at `tag`:
/// H_i = Γ_i · √(G(θ_i)/G(θ_0)) · (D/d_i) · e^{−j2π(d_i − D)/λ} for each image path i.
pub fn channel(
    pose: &AntennaPose,
    gain_dbi: f64,
    beamwidth_deg: f64,
    tag: Vec3,
    reflectors: &[Reflector],
    wavelength_m: f64,
) -> Channel {
    channel_with(
        &Aim::new(pose),
        &Pattern::new(&Lobe::new(gain_dbi, beamwidth_deg)),
        tag,
        &planes(reflectors),
        wavelength_m,
    )
}

/// An antenna pose with its boresight computed once, for many off-axis angles.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aim {
    /// Antenna position.
    pub position: Vec3,
    /// Boresight vector (unit up to rounding).
    pub boresight: Vec3,
    /// Its computed length.
    pub boresight_norm: f64,
}

impl Aim {
    /// The aim of an antenna at `pose`.
    pub fn new(pose: &AntennaPose) -> Aim {
        let b = boresight(pose.yaw_rad, pose.pitch_rad);
        Aim {
            position: pose.position,
            boresight: b,
            boresight_norm: norm(b),
        }
    }

    /// Cosine of the angle between the boresight and `v`, a vector of length `len` from the
    /// antenna (1 for a zero vector, whose angle counts as 0).
    pub fn cos_of(&self, v: Vec3, len: f64) -> f64 {
        let n = self.boresight_norm * len;
        if n == 0.0 || !n.is_finite() {
            return 1.0;
        }
        (dot(self.boresight, v) / n).clamp(-1.0, 1.0)
    }
}

/// [`channel`] with the pose, lobe and reflectors prepared.
///
/// Evaluated with cheap forms of the exact functions: the lobe through [`Pattern`] (relative
/// error ≤ 1e-12 of the amplitude gain), the phase factors through [`fastmath::cis`] (≤ 1e-15
/// on each component) and the argument of the sum through [`fastmath::atan2`] (≤ 2e-15 rad),
/// so the gain, the multipath factor and the delay are those of `powf`, `sin_cos` and `atan2`
/// to within about 1e-12 (relative) and 1e-14 rad.
pub fn channel_with(
    aim: &Aim,
    pattern: &Pattern,
    tag: Vec3,
    planes: &[Plane],
    wavelength_m: f64,
) -> Channel {
    channel_of(aim, pattern, tag, planes, wavelength_m, true)
}

/// [`channel_with`], its delay worked out only if `delay` (0 otherwise): the argument of the
/// sum is the costliest step, and only a reported phase needs it.
pub fn channel_of(
    aim: &Aim,
    pattern: &Pattern,
    tag: Vec3,
    planes: &[Plane],
    wavelength_m: f64,
    delay: bool,
) -> Channel {
    let (d, a0, sum, k) = phasors(aim, pattern, tag, planes, wavelength_m);
    Channel {
        distance_m: d,
        gain_linear: a0 * a0,
        multipath_factor: (sum.re * sum.re + sum.im * sum.im).sqrt(),
        delay_rad: if delay {
            2.0 * k * d - 2.0 * fastmath::atan2(sum.im, sum.re)
        } else {
            0.0
        },
    }
}

/// g₀·|1 + Σ Hᵢ|²/D² of [`channel_with`]'s channel (the forward link's power gain up to
/// constants), without the phase.
pub fn power_gain_with(
    aim: &Aim,
    pattern: &Pattern,
    tag: Vec3,
    planes: &[Plane],
    wavelength_m: f64,
) -> f64 {
    let (d, a0, sum, _) = phasors(aim, pattern, tag, planes, wavelength_m);
    let a = a0 / d;
    a * a * (sum.re * sum.re + sum.im * sum.im)
}

/// Distance D (clamped), the direct amplitude gain √g₀, the sum 1 + Σ Hᵢ and the wave number.
///
/// The geometry of [`image_path`] without working out the image or the reflection point:
/// with v = tag − antenna and u = tag − image = v + 2·da·n̂, l² = |u|² = |v|² + 4·da·dt (both
/// terms ≥ 0 where the path exists), and the first leg points along the mirror of u, so the
/// cosine of its off-axis angle is (b·u − 2·(b·n̂)·(u·n̂))/(|b|·l) = (b·v − 2·(b·n̂)·dt)/(|b|·l):
/// the same numbers up to rounding.
fn phasors(
    aim: &Aim,
    pattern: &Pattern,
    tag: Vec3,
    planes: &[Plane],
    wavelength_m: f64,
) -> (f64, f64, Complex, f64) {
    let p = aim.position;
    let b = aim.boresight;
    let v = sub(tag, p);
    let dist = norm(v);
    let d = dist.max(MIN_DISTANCE_M);
    let a0 = pattern.amplitude_cos(aim.cos_of(v, dist));
    let k = std::f64::consts::TAU / wavelength_m;
    let mut sum = Complex { re: 1.0, im: 0.0 };
    if planes.is_empty() {
        return (d, a0, sum, k);
    }
    let inv_bn = 1.0 / aim.boresight_norm;
    // Each path's amplitude relative to the direct one: Γ·(aᵢ/a₀)·(D/dᵢ).
    let scale = d / a0;
    let (vv, bv) = (dot(v, v), dot(b, v));
    for plane in planes {
        let n = plane.unit;
        let da = dot(sub(p, plane.point), n);
        let dt = dot(sub(tag, plane.point), n);
        // The same test as `image_path`.
        if da * dt <= 0.0 {
            continue;
        }
        let l = (vv + 4.0 * da * dt).sqrt();
        let inv_l = 1.0 / l;
        let c = (bv - 2.0 * dot(b, n) * dt) * inv_l * inv_bn;
        // A non-finite cosine counts as boresight, as in `Aim::cos_of`.
        let c = if c.is_finite() { c } else { 1.0 };
        let ai = pattern.amplitude_cos(c);
        // H carries −Γ (the π flip).
        let inv_length = if l >= MIN_DISTANCE_M {
            inv_l
        } else {
            1.0 / MIN_DISTANCE_M
        };
        let amplitude = -plane.coefficient * ai * scale * inv_length;
        let (cos, sin) = fastmath::cis(-k * (l - d));
        sum.re += amplitude * cos;
        sum.im += amplitude * sin;
    }
    (d, a0, sum, k)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::TAU;

    fn floor(coefficient: f64) -> Reflector {
        Reflector {
            name: "floor".into(),
            point: [0.0, 0.0, 0.0],
            normal: [0.0, 0.0, 1.0],
            coefficient,
        }
    }

    #[test]
    fn mirror_and_reflection_point() {
        let m = mirror_point([1.0, 2.0, 3.0], [0.0, 0.0, 1.0], [0.0, 0.0, 5.0]);
        assert_eq!(m, [1.0, 2.0, -1.0]);
        let paths = image_paths([0.0, 0.0, 1.0], [4.0, 0.0, 3.0], &[floor(0.5)]);
        assert_eq!(paths.len(), 1);
        let p = paths[0];
        assert_eq!(p.image, [0.0, 0.0, -1.0]);
        assert!(p.reflection_point[2].abs() < 1e-12);
        // Equal angles: the reflection point splits x in the ratio of the heights 1 : 3.
        assert!((p.reflection_point[0] - 1.0).abs() < 1e-12);
        assert!((p.length_m - (16.0f64 + 16.0).sqrt()).abs() < 1e-12);
        assert_eq!(p.coefficient, -0.5);
        // A plane between antenna and tag reflects nothing.
        let wall = Reflector {
            name: "wall".into(),
            point: [2.0, 0.0, 0.0],
            normal: [1.0, 0.0, 0.0],
            coefficient: 0.5,
        };
        assert!(image_paths([0.0, 0.0, 1.0], [4.0, 0.0, 3.0], &[wall]).is_empty());
    }

    #[test]
    fn one_floor_reflection_matches_the_two_ray_sum() {
        let (h1, h2, rho, lambda) = (1.2, 0.7, 0.6, 0.3463);
        let pose = AntennaPose {
            position: [0.0, 0.0, h1],
            yaw_rad: 0.0,
            pitch_rad: 0.0,
        };
        for x in [0.5, 1.0, 2.3, 4.0, 6.7] {
            let tag = [x, 0.0, h2];
            // Isotropic antenna (360°) so both rays have the same gain.
            let ch = channel(&pose, 0.0, 360.0, tag, &[floor(rho)], lambda);
            let d_direct = (x * x + (h1 - h2) * (h1 - h2)).sqrt();
            let d_image = (x * x + (h1 + h2) * (h1 + h2)).sqrt();
            let k = TAU / lambda;
            // One-way field: e^{−jkD}/D − ρ·e^{−jk d_r}/d_r.
            let re = (-k * d_direct).cos() / d_direct - rho * (-k * d_image).cos() / d_image;
            let im = (-k * d_direct).sin() / d_direct - rho * (-k * d_image).sin() / d_image;
            let field = Complex { re, im };
            assert!((ch.distance_m - d_direct).abs() < 1e-12);
            assert!((ch.multipath_factor - field.abs() * d_direct).abs() < 1e-9);
            let expected_delay = (-2.0 * field.arg()).rem_euclid(TAU);
            let diff = (ch.delay_rad.rem_euclid(TAU) - expected_delay).abs();
            assert!(diff.min(TAU - diff) < 1e-9, "x {x}: {diff}");
        }
    }

    #[test]
    fn free_space_channel_is_the_direct_path() {
        let pose = AntennaPose {
            position: [0.0; 3],
            yaw_rad: 0.0,
            pitch_rad: 0.0,
        };
        let ch = channel(&pose, 6.0, 70.0, [3.0, 0.0, 0.0], &[], 0.33);
        assert_eq!(ch.multipath_factor, 1.0);
        assert!((ch.delay_rad - 4.0 * std::f64::consts::PI * 3.0 / 0.33).abs() < 1e-9);
        assert!((ch.gain_linear - 10f64.powf(0.6)).abs() < 1e-12);
    }

    #[test]
    fn a_channel_without_its_delay_is_otherwise_the_same() {
        let aim = Aim::new(&AntennaPose {
            position: [1.0, 4.25, 0.9],
            yaw_rad: 1.2,
            pitch_rad: 0.1,
        });
        let pattern = Pattern::new(&Lobe::new(6.0, 65.0));
        let walls = planes(&[floor(0.4), floor(0.3)]);
        for tag in [[4.0, 5.2, 0.4], [2.5, 6.0, 1.6], [1.2, 4.3, 2.0]] {
            let full = channel_with(&aim, &pattern, tag, &walls, 0.3463);
            let bare = channel_of(&aim, &pattern, tag, &walls, 0.3463, false);
            assert_ne!(full.delay_rad, 0.0);
            assert_eq!(
                Channel {
                    delay_rad: full.delay_rad,
                    ..bare
                },
                full
            );
        }
    }
}
