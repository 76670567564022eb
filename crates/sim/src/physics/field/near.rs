//! The near-field (fast) test: the phasor sum at an antenna's exact position with the gain
//! table's bounds and a certified bound on its error, and the proofs of how long a decision
//! it makes still holds.

use super::gains::GainTable;
use super::{SLACK_COS, SLACK_M, SLACK_REL};
use crate::physics::fastmath;
use crate::physics::geometry::{add_scaled, dot, norm, sub, Vec3};
use crate::physics::multipath::{Aim, Plane, MIN_DISTANCE_M};

/// A reflector seen from the antenna at a bucket start, for [`Near`].
#[derive(Clone, Copy, Debug)]
struct NearMirror {
    plane: Plane,
    /// Signed distance of the antenna from the plane, as `multipath::image_path` computes it.
    da: f64,
    /// The antenna's image, as `multipath::image_path` computes it.
    image: Vec3,
    /// −2·(b̂·n̂): b̂·(image − antenna) is `f·da`.
    f: f64,
    /// 1/da.
    inv_da: f64,
}

/// The antenna at a bucket start, prepared for a fast field test: the phasor sum of
/// [`crate::physics::multipath::channel_with`] evaluated with the gain table's bounds (the phase
/// factors of [`fastmath::cis`], as there), with a certified bound on its error. It decides whenever the sum is
/// clear of the threshold by more than that bound and leaves the rest to the exact sum.
#[derive(Clone, Debug, Default)]
pub(super) struct Near {
    /// Antenna position.
    p: Vec3,
    /// Unit boresight.
    b: Vec3,
    /// Wave number 2π/λ.
    k: f64,
    /// Largest coordinate magnitude of the antenna and its images, plus 1 (m): sets the
    /// rounding error of the exact geometry.
    scale: f64,
    mirrors: Vec<NearMirror>,
    /// What the last [`Near::decide`] saw, for [`Near::steady`].
    seen: Seen,
}

/// The paths of the last decision, the direct one first.
#[derive(Clone, Debug, Default)]
struct Seen {
    paths: [Path; 1 + MAX_KEPT_MIRRORS],
    /// Number of paths recorded (0: none, the decision cannot be kept).
    count: usize,
    /// The nearest either end came to a reflector's plane (m).
    side: f64,
}

/// One path of a decision, for [`Near::steady`].
#[derive(Clone, Copy, Debug, Default)]
struct Path {
    /// |Γ| (1 for the direct path).
    gamma: f64,
    /// Cosine between the boresight and the path's first leg.
    cos: f64,
    /// Length (m).
    length: f64,
    /// 1/length.
    inv_l: f64,
    /// At least the term's magnitude |Γ|·√g/l.
    mag: f64,
    /// |û₀ − ûᵢ|: the chord between the unit vectors from the antenna toward the tag and
    /// toward the tag's image (0 for the direct path); the antenna moving at w changes
    /// lᵢ − D at the rate w·(û₀ − ûᵢ).
    chord: f64,
}

/// Most reflectors a kept decision may involve.
const MAX_KEPT_MIRRORS: usize = 8;

/// Largest phase (rad) the fast test handles (within [`fastmath::cis`]'s reduced range).
const CIS_MAX_RAD: f64 = 1e4;

impl Near {
    /// Prepares for `aim` on `wavelength_m`.
    pub(super) fn prepare(&mut self, aim: &Aim, planes: &[Plane], wavelength_m: f64) {
        let p = aim.position;
        let bn = aim.boresight_norm;
        self.p = p;
        self.b = [
            aim.boresight[0] / bn,
            aim.boresight[1] / bn,
            aim.boresight[2] / bn,
        ];
        self.k = std::f64::consts::TAU / wavelength_m;
        let inf = |v: Vec3| v[0].abs().max(v[1].abs()).max(v[2].abs());
        let mut scale = 1.0 + inf(p);
        self.mirrors.clear();
        for plane in planes {
            let da = dot(sub(p, plane.point), plane.unit);
            let image = add_scaled(p, -2.0 * da, plane.unit);
            scale = scale.max(1.0 + inf(image)).max(1.0 + inf(plane.point));
            self.mirrors.push(NearMirror {
                plane: *plane,
                da,
                image,
                f: -2.0 * dot(self.b, plane.unit),
                inv_da: 1.0 / da,
            });
        }
        self.scale = scale;
    }

    /// Whether the amplitude √g₀·|1 + Σ Hᵢ|/D at a tag at `q`, `dist` from the antenna (as
    /// `distance` computes it), reaches `threshold`: `Some` when the error bound decides it,
    /// with how far (beyond every error and rounding bound) the exact amplitude is from the
    /// threshold.
    pub(super) fn decide(
        &mut self,
        gains: &GainTable,
        q: Vec3,
        dist: f64,
        threshold: f64,
    ) -> Option<(bool, f64)> {
        if !(dist >= MIN_DISTANCE_M && dist.is_finite()) {
            return None;
        }
        let v = sub(q, self.p);
        let inv_d = 1.0 / dist;
        // Relative rounding of the exact geometry: coordinates of `scale` metres, lengths of a
        // centimetre at least.
        let rel = 1e-14 * (self.scale + q[0].abs().max(q[1].abs()).max(q[2].abs()));
        let c0 = dot(self.b, v) * inv_d;
        let eta = 1e-12 + rel * inv_d;
        let (lo, hi) = (gains.below(c0 - eta), gains.above(c0 + eta));
        let mut re = (lo + hi) * 0.5 * inv_d;
        let mut im = 0.0;
        let mut err = (hi - lo) * 0.5 * inv_d;
        let mut mag = hi * inv_d;
        let seen = &mut self.seen;
        let keep = self.mirrors.len() <= MAX_KEPT_MIRRORS;
        seen.restart(keep, c0, dist, inv_d, hi);
        for m in &self.mirrors {
            let dt = dot(sub(q, m.plane.point), m.plane.unit);
            seen.side = seen.side.min(m.da.abs()).min(dt.abs());
            // The same test as `image_path`, on the same numbers.
            if m.da * dt <= 0.0 {
                continue;
            }
            let u = sub(q, m.image);
            let l = norm(u);
            // The reflection point is 1/s = (da + dt)/da times nearer the antenna than the
            // tag's image distance: below a millimetre, the exact sum decides.
            let w_inv = (m.da + dt) * m.inv_da;
            if !(l >= MIN_DISTANCE_M && self.k * (l + dist) < CIS_MAX_RAD) {
                return None;
            }
            let inv_l = 1.0 / l;
            // cos between boresight and reflection point: (f·(da + dt) + b̂·u)/l.
            let ci = (m.f * (m.da + dt) + dot(self.b, u)) * inv_l;
            if keep {
                seen.paths[seen.count] = m.path(v, inv_d, dt, l, inv_l, ci);
            }
            let eta = 1e-12 + rel * w_inv * inv_l * 4.0;
            let (glo, ghi) = (gains.below(ci - eta), gains.above(ci + eta));
            let a = m.plane.coefficient.abs() * inv_l;
            if keep {
                seen.paths[seen.count].mag = ghi * a;
                seen.count += 1;
            }
            let (c, s) = fastmath::cis(-self.k * (l - dist));
            // H carries −Γ (the π flip).
            let mid = -m.plane.coefficient * (glo + ghi) * 0.5 * inv_l;
            re += mid * c;
            im += mid * s;
            // Both sums take their phase factors from `fastmath::cis` (within 1e-15 of sin
            // and cos), of arguments that differ by rounding.
            let phase_err = 1e-12 + 1e-14 * self.k * (l + dist);
            err += (ghi - glo) * 0.5 * a + ghi * a * 2.0 * phase_err;
            mag += ghi * a;
        }
        err += mag * 1e-12;
        let amplitude = (re * re + im * im).sqrt();
        verdict(amplitude, err, threshold, mag)
    }

    /// The longest of [`HOLD_US`] during which the amplitude at the tag of the last
    /// [`Near::decide`] that decided cannot change by `margin` or more, when the antenna moves
    /// at most `antenna` m/s, the tag at most `tag` m/s and the boresight turns at most `turn`
    /// rad/s; 0 if not even the shortest. With `room` (m) set, the tag must also stay within
    /// that much more distance (a tag in the field must stay within reach). `exhaustive`
    /// proves holds from the longest down rather than from a guess at it; otherwise holds
    /// shorter than `at_least` µs are not tried.
    ///
    /// Each path's term cᵢ = Γᵢ·√gᵢ/lᵢ·e^{−jk(lᵢ − D)} (the direct one: √g₀/D) changes by at
    /// most its magnitude's range plus its largest magnitude times its phase change. With each
    /// end moving at most δ, lᵢ changes by at most δ and the direction toward the tag (or its
    /// image) by at most asin(δ/lᵢ) ≤ (π/3)·δ/lᵢ (δ ≤ lᵢ/2), plus the boresight's turn for the gain (the
    /// gain table bounds √g over the cosines within that angle). The relative phase changes
    /// at most k·2δ, and by the antenna's motion at most k·|w|·|û₀ − ûᵢ| per second, the
    /// chord growing by at most those angles. No path appears or vanishes while neither end
    /// comes within δ of its plane.
    pub(super) fn steady(
        &self,
        gains: &GainTable,
        margin: f64,
        speeds: (f64, f64, f64),
        room: Option<f64>,
        exhaustive: bool,
        at_least: u64,
    ) -> u64 {
        let (antenna, tag, turn) = speeds;
        let seen = &self.seen;
        let finite = antenna.is_finite() && tag.is_finite() && turn.is_finite();
        if !(margin > 0.0 && finite && seen.count > 0) {
            return 0;
        }
        let paths = &seen.paths[..seen.count];
        let side = seen.side.min(room.unwrap_or(f64::INFINITY));
        let change = |hold_us: u64| self.change_over(gains, paths, speeds, side, hold_us);
        let guess = self.hold_guess(gains, paths, margin, speeds);
        let (mut j, tries) = if exhaustive {
            (HOLD_US.len() - 1, HOLD_US.len())
        } else {
            let j = HOLD_US
                .iter()
                .rposition(|&h| h as f64 <= guess)
                .unwrap_or(0);
            (j, 2)
        };
        for _ in 0..tries {
            if !exhaustive && HOLD_US[j] < at_least {
                // Shorter holds would expire before the decision is asked for again.
                break;
            }
            if change(HOLD_US[j]) < margin {
                return HOLD_US[j];
            }
            if j == 0 {
                break;
            }
            j -= 1;
        }
        0
    }

    /// The largest change of the amplitude over `hold_us` at the given `speeds` (antenna,
    /// tag m/s; boresight turn rad/s) of a tag kept `side` m from every plane, or infinity
    /// when unbounded.
    fn change_over(
        &self,
        gains: &GainTable,
        paths: &[Path],
        (antenna, tag, turn): (f64, f64, f64),
        side: f64,
        hold_us: u64,
    ) -> f64 {
        let inv_d0 = paths[0].inv_l;
        let s = hold_us as f64 * 1e-6;
        let delta = (antenna + tag) * s + SLACK_M;
        let tau = turn * s + SLACK_COS;
        if delta >= side {
            return f64::INFINITY;
        }
        // With x = δ/l ≤ ½, 1/(l − δ) ≤ (1 + 2x)/l and 1/(l + δ) ≥ (1 − x)/l.
        let mut v = 0.0;
        for (i, p) in paths.iter().enumerate() {
            let x = delta * p.inv_l;
            if !(x <= 0.5 && p.length >= 2.0 * MIN_DISTANCE_M) {
                return f64::INFINITY;
            }
            // asin is convex: asin(x) ≤ 2·asin(½)·x for x ≤ ½. Rounding of the cosine
            // itself is below 1e-9 (see `decide`'s eta).
            let dc = x * ASIN_SLOPE + tau + 1e-9;
            let hi = gains.above(p.cos + dc) * p.inv_l * (1.0 + 2.0 * x);
            let lo = gains.below(p.cos - dc) * p.inv_l * (1.0 - x);
            v += p.gamma * (hi - lo);
            if i > 0 {
                let chord = p.chord + 1e-9 + ASIN_SLOPE * (delta * inv_d0 + x);
                let moved = (antenna * s * chord + 2.0 * tag * s).min(2.0 * delta);
                v += p.gamma * hi * self.k * (moved + SLACK_M);
            }
        }
        v * (1.0 + SLACK_REL)
    }

    /// A guess at the longest hold worth proving at the given `speeds` (antenna, tag m/s;
    /// boresight turn rad/s), µs.
    fn hold_guess(
        &self,
        gains: &GainTable,
        paths: &[Path],
        margin: f64,
        (antenna, tag, turn): (f64, f64, f64),
    ) -> f64 {
        // The relative phases dominate the change: guess from them the longest hold worth
        // proving (the change only grows with the hold), then prove it, or the one before.
        let rate: f64 = paths[1..]
            .iter()
            .map(|p| p.mag * (antenna * p.chord + 2.0 * tag))
            .sum::<f64>()
            * self.k;
        // So does the direct path's gain off the boresight: its change per second of the
        // view turning (a guess only: `change` proves the hold).
        let p0 = &paths[0];
        let swing = (antenna + tag) * p0.inv_l * ASIN_SLOPE + turn;
        let slope = (gains.above(p0.cos + swing) - gains.below(p0.cos - swing)) * p0.inv_l;
        0.9e6 * margin / (rate + slope + f64::MIN_POSITIVE)
    }
}

impl Seen {
    /// Forgets the last decision's paths; with `keep`, records the direct one (cosine `c0`,
    /// length `dist`, its inverse `inv_d`, gain bound `hi`).
    #[inline]
    fn restart(&mut self, keep: bool, c0: f64, dist: f64, inv_d: f64, hi: f64) {
        self.count = 0;
        self.side = f64::INFINITY;
        if keep {
            self.paths[0] = Path {
                gamma: 1.0,
                cos: c0,
                length: dist,
                inv_l: inv_d,
                mag: hi * inv_d,
                chord: 0.0,
            };
            self.count = 1;
        }
    }
}

impl NearMirror {
    /// The path through this reflector to a tag at `v` from the antenna (`inv_d`: 1/|v|),
    /// `dt` from the plane, of length `l` (`inv_l`: 1/l) and boresight cosine `ci` (its
    /// magnitude set later).
    #[inline]
    fn path(&self, v: Vec3, inv_d: f64, dt: f64, l: f64, inv_l: f64, ci: f64) -> Path {
        // The tag's image seen from the antenna: v − 2·dt·n̂, of length l.
        let image_dir = add_scaled(v, -2.0 * dt, self.plane.unit);
        let chord = norm(sub(
            [v[0] * inv_d, v[1] * inv_d, v[2] * inv_d],
            [
                image_dir[0] * inv_l,
                image_dir[1] * inv_l,
                image_dir[2] * inv_l,
            ],
        ));
        Path {
            gamma: self.plane.coefficient.abs(),
            cos: ci,
            length: l,
            inv_l,
            mag: 0.0,
            chord,
        }
    }
}

/// The decision on an amplitude within `err` of `amplitude` against `threshold` (`mag`: the
/// sum of the paths' magnitude bounds), with its margin; `None` when too close to call.
#[inline]
fn verdict(amplitude: f64, err: f64, threshold: f64, mag: f64) -> Option<(bool, f64)> {
    // What a later exact evaluation rounds differently, far above its rounding.
    let slack = threshold * SLACK_REL + mag * 1e-12;
    if amplitude + err < threshold * (1.0 - SLACK_REL) {
        Some((
            false,
            threshold * (1.0 - SLACK_REL) - amplitude - err - slack,
        ))
    } else if amplitude - err > threshold * (1.0 + SLACK_REL) {
        Some((
            true,
            amplitude - err - threshold * (1.0 + SLACK_REL) - slack,
        ))
    } else {
        None
    }
}

/// asin(x)/x at x = ½ (π/3), above asin(x)/x for every x in (0, ½].
const ASIN_SLOPE: f64 = std::f64::consts::FRAC_PI_3;

/// How long (µs after the bucket start where it was made) a field decision may be kept, when
/// [`Near::steady`] proves it holds that long.
const HOLD_US: [u64; 8] = [
    25_000, 50_000, 100_000, 200_000, 400_000, 800_000, 1_600_000, 3_200_000,
];
