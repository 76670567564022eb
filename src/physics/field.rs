//! Which tags are in an antenna's field — within reach and powered by the forward link — at
//! the start of a 25 ms bucket ([`super::inventory`]), and a uniform draw among them, without
//! evaluating the full channel of every tag in every bucket.
//!
//! Time is cut into intervals on a fixed grid ([`MAX_SPAN_US`] long, halved while the antenna
//! moves or turns too much in them, down to one bucket), so the interval of a bucket depends on
//! nothing but the bucket. For each interval, bounds on how far the antenna and each tag can
//! move give every tag a status valid at every bucket start in it, on every channel:
//! * **out**: beyond reach, or even the most favourable gains, distances and an in-phase sum
//!   of all paths (|a₀| + Σ|aᵢ|) stay below the power threshold;
//! * **in**: within reach and even the least favourable direct path minus every reflected
//!   path at its strongest (|a₀| − Σ|aᵢ|) clears the threshold;
//! * **undecided**: evaluated exactly (the channel of [`super::multipath`]) when drawn.
//!
//! Once neither the antenna nor any tag moves any more, one interval lasts for ever and the
//! field of each channel is evaluated once.
//!
//! An undecided tag drawn in a bucket is first tested with the antenna's exact position then:
//! the phasor sum with the gain table's bounds (and the exact sum's phase factors), whose
//! error is bounded, decides unless the amplitude lies within that bound of the threshold,
//! when the exact sum of [`super::multipath`] does. A decision so made is kept for the
//! antenna's later buckets on the same channel for as long as a bound on how fast the
//! amplitude can change (from the antenna's and the tag's top speeds and the boresight's turn
//! rate) proves that it still holds ([`Near::steady`]).
//!
//! A draw picks uniformly among the bucket's in and undecided tags and draws again while it
//! hits one that is not powered (rejection sampling): every tag of the field is equally likely,
//! as when the field is listed in full, and the draw depends only on the attempt's generator
//! and the bucket's candidates (fixed by its interval of the grid), never on earlier draws. The bounds keep margins far above rounding errors,
//! so they never change which tags are in the field (unit tests check every decision, and
//! every kept decision up to its expiry, against the exact evaluation on the fixtures and on a
//! scenario where everything moves).

use std::sync::{Arc, Mutex, MutexGuard, OnceLock};

use rand::Rng;

use super::antenna::Lobe;
use super::geometry::{add_scaled, distance, dot, norm, sub, Vec3};
use super::multipath::{power_gain_with, Aim, Channel, Plane, MIN_DISTANCE_M};
use super::{fastmath, rssi, Model, Mover};

/// Longest interval one classification covers, µs: a power-of-two number of buckets, so the
/// halves of an interval are whole buckets down to one.
pub const MAX_SPAN_US: u64 = 128 * super::inventory::FIELD_BUCKET_US;
/// Largest antenna displacement (m) one classification allows: the interval is halved until
/// the antenna stays within it (or is one bucket long).
const MAX_EXCURSION_M: f64 = 0.2;
/// Largest boresight turn (rad) one classification allows, likewise.
const MAX_TURN_RAD: f64 = 0.1;
/// Added to every distance bound (m): far above the rounding errors of either computation.
const SLACK_M: f64 = 1e-9;
/// Added to every direction-cosine bound.
const SLACK_COS: f64 = 1e-9;
/// Relative margin on every gain and power-threshold bound.
const SLACK_REL: f64 = 1e-9;
/// Steps of the gain table over the direction cosine in [−1, 1].
const TABLE_STEPS: usize = 2048;

/// Status of one tag for one classification.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Status {
    Out,
    In,
    Undecided,
}

/// One antenna's classification: valid for bucket starts in `[t0_us, t1_us)` at `tx_bits`.
#[derive(Clone, Debug, Default)]
pub(super) struct Classified {
    t0_us: u64,
    t1_us: u64,
    tx_bits: u64,
    /// Tags in the field at every bucket start, ascending.
    inside: Vec<usize>,
    /// Tags to evaluate bucket by bucket, ascending.
    undecided: Vec<usize>,
    /// Both, merged in tag order, as a bucket's candidates start.
    pool: Vec<(usize, Known)>,
    /// Once nothing moves any more (the interval never ends), the field on each channel of
    /// the table (index channel − 1), evaluated once; empty otherwise.
    at_rest: Vec<Vec<usize>>,
    /// Then too, the channel and forward-link margin of each tag on each channel (index
    /// (channel − 1)·tags + tag), computed on first use: they no longer change.
    links: Vec<OnceLock<(Channel, f64)>>,
}

/// Per-antenna classifications of a model (a cache: the field never depends on it). The lock
/// is held only to look one up or to store one, so several threads share it freely.
#[derive(Debug, Default)]
pub(super) struct FieldCache {
    classified: Vec<Mutex<Option<Arc<Classified>>>>,
    /// Per antenna, the draw state of its last inventory: the decisions kept from earlier
    /// buckets, and buffers to reuse.
    buckets: Vec<Mutex<Bucket>>,
}

impl Clone for FieldCache {
    fn clone(&self) -> Self {
        FieldCache::new(self.classified.len())
    }
}

impl FieldCache {
    /// An empty cache for `antennas` antennas.
    pub(super) fn new(antennas: usize) -> FieldCache {
        FieldCache {
            classified: (0..antennas).map(|_| Mutex::new(None)).collect(),
            buckets: (0..antennas)
                .map(|_| Mutex::new(Bucket::default()))
                .collect(),
        }
    }

    /// The draw state of antenna index `i` (0-based), taken out of the cache for one
    /// inventory (a fresh one when another thread holds it, or for no such antenna).
    pub(super) fn take_bucket(&self, i: usize) -> Bucket {
        self.buckets.get(i).map_or_else(Bucket::default, |m| {
            // A panic while holding the lock leaves at worst a state of the same kind, which
            // every use checks or resets.
            std::mem::take(&mut *m.lock().unwrap_or_else(|e| e.into_inner()))
        })
    }

    /// Gives the draw state of antenna index `i` back to the cache.
    pub(super) fn put_bucket(&self, i: usize, bucket: Bucket) {
        if let Some(m) = self.buckets.get(i) {
            *m.lock().unwrap_or_else(|e| e.into_inner()) = bucket;
        }
    }

    /// The classification slot of antenna index `i` (0-based), if there is such an antenna.
    fn slot(&self, i: usize) -> Option<MutexGuard<'_, Option<Arc<Classified>>>> {
        // A panic while holding the lock leaves at worst a stale entry, which is checked for
        // validity before use; the cache can always be rebuilt.
        self.classified
            .get(i)
            .map(|m| m.lock().unwrap_or_else(|e| e.into_inner()))
    }
}

impl Classified {
    /// Whether this classification holds at bucket start `t_us` for `tx_power_dbm`.
    fn holds(&self, t_us: u64, tx_power_dbm: f64) -> bool {
        self.t0_us <= t_us && t_us < self.t1_us && self.tx_bits == tx_power_dbm.to_bits()
    }
}

/// Amplitude gain √(boresight × pattern) of a lobe tabulated over the direction cosine, for
/// bounds: it never decreases with the cosine.
#[derive(Clone, Debug)]
pub(super) struct GainTable(Box<[f64; TABLE_STEPS + 1]>);

impl GainTable {
    /// The table of `lobe`.
    pub(super) fn new(lobe: &Lobe) -> GainTable {
        let mut table = Box::new([0.0; TABLE_STEPS + 1]);
        for (i, g) in table.iter_mut().enumerate() {
            *g = lobe
                .gain_cos(-1.0 + 2.0 * i as f64 / TABLE_STEPS as f64)
                .sqrt();
        }
        GainTable(table)
    }

    /// Position of cosine `c` in the table, clamped to it (NaN gives 0).
    fn index(c: f64) -> f64 {
        ((c + 1.0) * 0.5 * TABLE_STEPS as f64).clamp(0.0, TABLE_STEPS as f64)
    }

    /// At least the amplitude gain at any direction cosine ≤ `c`.
    fn above(&self, c: f64) -> f64 {
        let x = if c.is_nan() {
            TABLE_STEPS as f64
        } else {
            Self::index(c)
        };
        // 0 ≤ x ≤ TABLE_STEPS: truncation is floor (through i64, a single instruction); the
        // next entry is at least the one at ⌈x⌉ (the table never decreases), without testing
        // whether x is whole.
        let i = x as i64 as usize + 1;
        self.0[i.min(TABLE_STEPS)] * (1.0 + SLACK_REL)
    }

    /// At most the amplitude gain at any direction cosine ≥ `c`.
    fn below(&self, c: f64) -> f64 {
        // 0 ≤ index ≤ TABLE_STEPS (NaN gives 0): truncation through i64 is floor.
        let i = Self::index(c) as i64 as usize;
        self.0[i.min(TABLE_STEPS)] * (1.0 - SLACK_REL)
    }
}

/// How far an antenna may move during an interval.
#[derive(Clone, Copy, Debug, Default)]
struct Motion {
    /// Largest change of each coordinate (m).
    axes: Vec3,
    /// Largest boresight turn (rad).
    turn: f64,
}

impl Motion {
    /// Largest displacement (m).
    fn total(&self) -> f64 {
        norm(self.axes)
    }

    /// Largest displacement along the unit vector `u` (m).
    fn along(&self, u: Vec3) -> f64 {
        u[0].abs() * self.axes[0] + u[1].abs() * self.axes[1] + u[2].abs() * self.axes[2]
    }
}

/// A boresight turn (rad), with its sine and cosine.
#[derive(Clone, Copy, Debug)]
struct Turn {
    rad: f64,
    sin: f64,
    cos: f64,
}

impl Turn {
    fn new(rad: f64) -> Turn {
        let (sin, cos) = rad.sin_cos();
        Turn { rad, sin, cos }
    }
}

/// The range `(highest, lowest)` of cos θ when θ, whose cosine is `c0`, changes by at most
/// asin(x) + `turn`; the whole range [−1, 1] when that is not below π.
fn widen(c0: f64, x: f64, turn: Turn) -> (f64, f64) {
    if !(x < 1.0 && turn.rad < std::f64::consts::FRAC_PI_2) {
        return (1.0, -1.0);
    }
    let c0 = c0.clamp(-1.0, 1.0);
    let s0 = (1.0 - c0 * c0).max(0.0).sqrt();
    let sa = x.max(0.0);
    let ca = (1.0 - sa * sa).max(0.0).sqrt();
    // δ = asin(x) + turn < π: cos θ ∈ [cos(θ + δ), cos(max(θ − δ, 0))].
    let (sd, cd) = (sa * turn.cos + ca * turn.sin, ca * turn.cos - sa * turn.sin);
    let hi = if c0 >= cd { 1.0 } else { c0 * cd + s0 * sd };
    let lo = if c0 <= -cd { -1.0 } else { c0 * cd - s0 * sd };
    (hi + SLACK_COS, lo - SLACK_COS)
}

/// A plane seen from the antenna at the start of an interval.
struct Mirror {
    plane: Plane,
    /// Signed distance of the antenna from the plane.
    da: f64,
    /// Largest change of `da` in the interval.
    da_moves: f64,
    /// The antenna's image.
    image: Vec3,
    /// boresight · n̂ (the boresight as [`Aim`] holds it, not a unit vector).
    beta: f64,
}

/// An antenna at the start of an interval, with how far it may move during it.
struct Around<'a> {
    aim: Aim,
    /// Largest antenna displacement (m) and boresight turn in the interval.
    moved: f64,
    turn: Turn,
    gains: &'a GainTable,
    reach: f64,
    mirrors: Vec<Mirror>,
    /// Amplitude thresholds over the channel table: the field needs A ≥ threshold(λ).
    threshold_low: f64,
    threshold_high: f64,
}

impl Around<'_> {
    /// Status of a tag at `q` at the interval start that moves at most `moves` metres in it.
    ///
    /// With a₀ = √g₀/D and aᵢ = Γᵢ·√gᵢ/dᵢ, the forward link powers the tag when
    /// A = |a₀ + Σ aᵢ·e^{jφᵢ}| reaches the threshold (the channel of
    /// [`super::multipath::channel`]: √g₀·|1 + Σ Hᵢ|/D = A).
    fn status(&self, q: Vec3, moves: f64) -> Status {
        let p = self.aim.position;
        let (b, bn) = (self.aim.boresight, self.aim.boresight_norm);
        let moved = self.moved;
        let r = moved + moves + SLACK_M;
        let v = sub(q, p);
        let d0 = norm(v);
        if d0 - r > self.reach {
            return Status::Out;
        }
        let within = d0 + r < self.reach;
        let bv = dot(b, v);
        // The direct path turns by at most asin(r/D), the boresight by `turn`.
        let (c_hi, c_lo) = widen(bv / (bn * d0), r / d0, self.turn);
        let d_min = (d0 - r).max(MIN_DISTANCE_M);
        let d_max = (d0 + r).max(MIN_DISTANCE_M);
        let direct_hi = self.gains.above(c_hi) / d_min;
        let direct_lo = self.gains.below(c_lo) / d_max;
        let mut reflected = 0.0;
        for m in &self.mirrors {
            let dt = dot(sub(q, m.plane.point), m.plane.unit);
            let mn = m.da_moves + SLACK_M;
            let mt = moves + SLACK_M;
            // The path exists only while antenna and tag are strictly on one side.
            if (m.da - mn > 0.0 && dt + mt < 0.0) || (m.da + mn < 0.0 && dt - mt > 0.0) {
                continue;
            }
            let length = distance(m.image, q);
            let l_min = (length - r).max(MIN_DISTANCE_M);
            // While the path exists, its first leg points from the antenna toward the tag's
            // image q' = q − 2·dt·n̂, which is `length` away and, like the antenna, moves at most
            // r (a mirrored tag moves as far as the tag).
            let c0 = (bv - 2.0 * dt * m.beta) / (bn * length);
            let c_up = widen(c0, r / length, self.turn).0;
            reflected += m.plane.coefficient.abs() * self.gains.above(c_up) / l_min;
        }
        let (a_hi, a_lo) = (direct_hi + reflected, direct_lo - reflected);
        if a_hi < self.threshold_low {
            Status::Out
        } else if within && a_lo > self.threshold_high {
            Status::In
        } else {
            Status::Undecided
        }
    }
}

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
/// [`super::multipath::channel_with`] evaluated with the gain table's bounds (the phase
/// factors of [`fastmath::cis`], as there), with a certified bound on its error. It decides whenever the sum is
/// clear of the threshold by more than that bound and leaves the rest to the exact sum.
#[derive(Clone, Debug, Default)]
struct Near {
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
    fn prepare(&mut self, aim: &Aim, planes: &[Plane], wavelength_m: f64) {
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
    fn decide(
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
        seen.count = 0;
        seen.side = f64::INFINITY;
        let keep = self.mirrors.len() <= MAX_KEPT_MIRRORS;
        if keep {
            seen.paths[0] = Path {
                gamma: 1.0,
                cos: c0,
                length: dist,
                inv_l: inv_d,
                mag: hi * inv_d,
                chord: 0.0,
            };
            seen.count = 1;
        }
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
                // The tag's image seen from the antenna: v − 2·dt·n̂, of length l.
                let image_dir = add_scaled(v, -2.0 * dt, m.plane.unit);
                let chord = norm(sub(
                    [v[0] * inv_d, v[1] * inv_d, v[2] * inv_d],
                    [
                        image_dir[0] * inv_l,
                        image_dir[1] * inv_l,
                        image_dir[2] * inv_l,
                    ],
                ));
                seen.paths[seen.count] = Path {
                    gamma: m.plane.coefficient.abs(),
                    cos: ci,
                    length: l,
                    inv_l,
                    mag: 0.0,
                    chord,
                };
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
    fn steady(
        &self,
        gains: &GainTable,
        margin: f64,
        (antenna, tag, turn): (f64, f64, f64),
        room: Option<f64>,
        exhaustive: bool,
        at_least: u64,
    ) -> u64 {
        let seen = &self.seen;
        let finite = antenna.is_finite() && tag.is_finite() && turn.is_finite();
        if !(margin > 0.0 && finite && seen.count > 0) {
            return 0;
        }
        let paths = &seen.paths[..seen.count];
        let side = seen.side.min(room.unwrap_or(f64::INFINITY));
        let inv_d0 = paths[0].inv_l;
        // The largest change over `hold_us`, or infinity when unbounded. With x = δ/l ≤ ½,
        // 1/(l − δ) ≤ (1 + 2x)/l and 1/(l + δ) ≥ (1 − x)/l.
        let change = |hold_us: u64| {
            let s = hold_us as f64 * 1e-6;
            let delta = (antenna + tag) * s + SLACK_M;
            let tau = turn * s + SLACK_COS;
            if delta >= side {
                return f64::INFINITY;
            }
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
        };
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
        let guess = 0.9e6 * margin / (rate + slope + f64::MIN_POSITIVE);
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
}

/// asin(x)/x at x = ½ (π/3), above asin(x)/x for every x in (0, ½].
const ASIN_SLOPE: f64 = std::f64::consts::FRAC_PI_3;

/// How long (µs after the bucket start where it was made) a field decision may be kept, when
/// [`Near::steady`] proves it holds that long.
const HOLD_US: [u64; 8] = [
    25_000, 50_000, 100_000, 200_000, 400_000, 800_000, 1_600_000, 3_200_000,
];

/// Upper bounds, at any time, on how fast an antenna moves (m/s) and its boresight turns
/// (rad/s), when they are known.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct Rates {
    /// m/s.
    pub(super) speed: f64,
    /// rad/s.
    pub(super) turn: f64,
}

/// A field decision kept for later bucket starts.
#[derive(Clone, Copy, Debug, Default)]
struct Kept {
    /// Valid for bucket starts in `[from_us, until_us]`.
    from_us: u64,
    until_us: u64,
    /// On this channel (0: nothing kept).
    channel: u16,
    inside: bool,
}

/// The field decisions of one antenna kept from earlier buckets, per tag (a cache: a decision
/// is kept only as long as [`Near::steady`] proves it holds, so it never changes a result).
#[derive(Clone, Debug, Default)]
pub(super) struct Memo {
    tx_bits: u64,
    kept: Vec<Kept>,
    /// Prove holds from the longest down instead of from a guess (tests: every hold is then
    /// as long as the proof alone allows).
    exhaustive: bool,
}

impl Memo {
    /// Makes the memo one for `tags` tags at `tx_power_dbm` (emptied if it was not).
    pub(super) fn fit(&mut self, tags: usize, tx_power_dbm: f64) {
        let bits = tx_power_dbm.to_bits();
        if self.tx_bits != bits || self.kept.len() != tags {
            self.tx_bits = bits;
            self.kept.clear();
            self.kept.resize(tags, Kept::default());
        }
    }
}

/// Whether a candidate tag is in the bucket's field.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Known {
    In,
    Out,
    Unknown,
}

/// One bucket's draw state: the tags that may be in its field, and what is known of each.
#[derive(Clone, Debug, Default)]
pub(super) struct Bucket {
    antenna: u16,
    t_us: u64,
    /// Time since this antenna's previous bucket (0 when unknown): a kept decision shorter
    /// than that is never asked for again, so it is not worth proving.
    revisit_us: u64,
    wavelength_m: f64,
    /// The field needs g₀·|1 + Σ Hᵢ|²/D² at least this (the tag sensitivity at this power and
    /// wavelength).
    threshold: f64,
    /// The same threshold on the amplitude √g₀·|1 + Σ Hᵢ|/D (its square root, up to rounding).
    amplitude: f64,
    /// Reach of the antenna (m).
    reach: f64,
    /// Candidates in tag order.
    pool: Vec<(usize, Known)>,
    /// How many candidates are known not to be in the field.
    out: usize,
    /// The antenna at the bucket start, once an undecided tag needed it.
    aim: Option<Aim>,
    /// The same, prepared for the fast field test (valid while `aim` is set).
    near: Near,
    /// The classification when nothing moves any more (its links serve the attempts).
    rest: Option<Arc<Classified>>,
    /// The antenna, power bits and [`amplitude_threshold`] of the last bucket prepared (its
    /// `powf` once per antenna and power rather than once per bucket).
    base: Option<(u16, u64, f64)>,
    /// The bucket's channel.
    channel: u16,
    /// The antenna's decisions kept from earlier buckets (see [`Memo`]).
    pub(super) memo: Memo,
}

impl Model {
    /// Prepares `bucket` for draws in the field of `antenna` at bucket start `t_us` on
    /// `channel`, with the antenna's classification for it in `held` (replaced if it does not
    /// hold there).
    pub(super) fn open_bucket(
        &self,
        antenna: u16,
        tx_power_dbm: f64,
        t_us: u64,
        channel: u16,
        held: &mut Option<Arc<Classified>>,
        bucket: &mut Bucket,
    ) {
        if !held.as_ref().is_some_and(|c| c.holds(t_us, tx_power_dbm)) {
            *held = Some(self.classification(antenna, tx_power_dbm, t_us));
        }
        self.prepare(bucket, antenna, tx_power_dbm, t_us, channel);
        let Some(c) = held.as_deref() else {
            return;
        };
        if let Some(field) = c.at_rest.get(usize::from(channel).wrapping_sub(1)) {
            bucket.pool.extend(field.iter().map(|&t| (t, Known::In)));
            bucket.rest = held.clone();
            return;
        }
        bucket.pool.extend_from_slice(&c.pool);
    }

    /// Empties `bucket` for the field of `antenna` at `t_us` on `channel`.
    fn prepare(
        &self,
        bucket: &mut Bucket,
        antenna: u16,
        tx_power_dbm: f64,
        t_us: u64,
        channel: u16,
    ) {
        let spec = &self.antennas[usize::from(antenna) - 1].spec;
        bucket.revisit_us = if bucket.antenna == antenna && bucket.t_us < t_us {
            t_us - bucket.t_us
        } else {
            0
        };
        bucket.antenna = antenna;
        bucket.t_us = t_us;
        bucket.channel = channel;
        bucket.wavelength_m = self.wavelength_m(channel);
        let key = (antenna, tx_power_dbm.to_bits());
        let base = match bucket.base {
            Some((a, tx, base)) if (a, tx) == key => base,
            _ => {
                let base = amplitude_threshold(spec, tx_power_dbm);
                bucket.base = Some((key.0, key.1, base));
                base
            }
        };
        bucket.amplitude = base / bucket.wavelength_m;
        bucket.threshold = bucket.amplitude.powi(2);
        bucket.reach = reach_m(spec);
        bucket.aim = None;
        bucket.pool.clear();
        bucket.out = 0;
        bucket.rest = None;
    }

    /// The channel and forward-link margin (dB) of `tag` from `antenna` at `t_us` on channel
    /// `channel`: those of [`Model::margin_with`] at the antenna's pose then (the delay only
    /// if `delay`), taken from `bucket`'s classification once nothing moves any more.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn link(
        &self,
        bucket: &Bucket,
        antenna: u16,
        tag: usize,
        t_us: u64,
        channel: u16,
        tx_power_dbm: f64,
        delay: bool,
    ) -> (Channel, f64) {
        let lambda = self.wavelength_m(channel);
        let compute = |delay| {
            let aim = self.aim(antenna, t_us);
            let position = self.tag_position(tag, t_us);
            self.margin_with(antenna, &aim, position, lambda, tx_power_dbm, delay)
        };
        // A kept link serves every later request, so it has its delay.
        let cached = bucket.rest.as_ref().and_then(|c| {
            let i = usize::from(channel).checked_sub(1)? * self.tags.len() + tag;
            let slot = c.links.get(i)?;
            (t_us >= c.t0_us && c.tx_bits == tx_power_dbm.to_bits())
                .then(|| *slot.get_or_init(|| compute(true)))
        });
        cached.unwrap_or_else(|| compute(delay))
    }

    /// A tag drawn uniformly from the field of the bucket, or `None` when it is empty.
    pub(super) fn draw<R: Rng + ?Sized>(&self, bucket: &mut Bucket, rng: &mut R) -> Option<usize> {
        while bucket.out < bucket.pool.len() {
            let i = rng.gen_range(0..bucket.pool.len());
            let (tag, known) = bucket.pool[i];
            match known {
                Known::In => return Some(tag),
                Known::Out => {}
                Known::Unknown => {
                    if self.in_field(bucket, tag) {
                        bucket.pool[i].1 = Known::In;
                        return Some(tag);
                    }
                    bucket.pool[i].1 = Known::Out;
                    bucket.out += 1;
                }
            }
        }
        None
    }

    /// Whether `tag` is in the field at the bucket start: within reach and powered.
    fn in_field(&self, bucket: &mut Bucket, tag: usize) -> bool {
        let antenna = bucket.antenna;
        let t_us = bucket.t_us;
        if let Some(k) = bucket.memo.kept.get(tag) {
            if k.channel == bucket.channel && k.from_us <= t_us && t_us <= k.until_us {
                return k.inside;
            }
        }
        let a = &self.antennas[usize::from(antenna) - 1];
        let aim = match bucket.aim {
            Some(aim) => aim,
            None => {
                let aim = self.aim(antenna, t_us);
                bucket.near.prepare(&aim, &self.planes, bucket.wavelength_m);
                bucket.aim = Some(aim);
                aim
            }
        };
        let position = self.tag_position(tag, t_us);
        let dist = distance(aim.position, position);
        if dist > bucket.reach {
            return false;
        }
        if let Some((known, margin)) =
            bucket
                .near
                .decide(&a.gains, position, dist, bucket.amplitude)
        {
            if let (Some(rates), Some(k)) = (a.rates, bucket.memo.kept.get_mut(tag)) {
                let tag_speed = self.tags[tag].motion.speed();
                let room = known.then_some(bucket.reach - dist);
                let hold = bucket.near.steady(
                    &a.gains,
                    margin,
                    (rates.speed, tag_speed, rates.turn),
                    room,
                    bucket.memo.exhaustive,
                    bucket.revisit_us,
                );
                if hold > 0 {
                    *k = Kept {
                        from_us: t_us,
                        until_us: t_us.saturating_add(hold),
                        channel: bucket.channel,
                        inside: known,
                    };
                }
            }
            return known;
        }
        power_gain_with(
            &aim,
            &a.pattern,
            position,
            &self.planes,
            bucket.wavelength_m,
        ) >= bucket.threshold
    }

    /// The classification of `antenna` holding at bucket start `t_us`: cached, or made and
    /// cached.
    fn classification(&self, antenna: u16, tx_power_dbm: f64, t_us: u64) -> Arc<Classified> {
        let i = usize::from(antenna).saturating_sub(1);
        if let Some(c) = self.field_cache.slot(i).and_then(|s| s.clone()) {
            if c.holds(t_us, tx_power_dbm) {
                return c;
            }
        }
        let c = Arc::new(self.classify(antenna, tx_power_dbm, t_us));
        if let Some(mut s) = self.field_cache.slot(i) {
            *s = Some(c.clone());
        }
        c
    }

    /// Classifies every tag for `antenna` over the grid interval holding bucket start `t_us`.
    fn classify(&self, antenna: u16, tx_power_dbm: f64, t_us: u64) -> Classified {
        let bucket = super::inventory::FIELD_BUCKET_US;
        let a = &self.antennas[usize::from(antenna) - 1];
        let rest = a.rest_us;
        let (t0_us, t1_us, motion) = if t_us >= rest {
            // Nothing moves any more: one interval for ever.
            (rest, u64::MAX, Motion::default())
        } else {
            let (mut t0_us, mut span) = (t_us / MAX_SPAN_US * MAX_SPAN_US, MAX_SPAN_US);
            let motion = loop {
                let m = self.excursion(antenna, t0_us, t0_us.saturating_add(span));
                if (m.total() <= MAX_EXCURSION_M && m.turn <= MAX_TURN_RAD) || span <= bucket {
                    break m;
                }
                span /= 2;
                if t_us >= t0_us + span {
                    t0_us += span;
                }
            };
            (t0_us, t0_us.saturating_add(span), motion)
        };
        let spec = &a.spec;
        let aim = self.aim(antenna, t0_us);
        let mirrors = self
            .planes
            .iter()
            .map(|plane| {
                let da = dot(sub(aim.position, plane.point), plane.unit);
                let da_moves = motion.along(plane.unit) + SLACK_M;
                let image = add_scaled(aim.position, -2.0 * da, plane.unit);
                Mirror {
                    plane: *plane,
                    da,
                    da_moves,
                    image,
                    beta: dot(aim.boresight, plane.unit),
                }
            })
            .collect();
        let base = amplitude_threshold(spec, tx_power_dbm);
        let fallback = [self.wavelength_m(1)];
        let lambdas = if self.wavelengths.is_empty() {
            &fallback[..]
        } else {
            &self.wavelengths[..]
        };
        let lambda_max = lambdas.iter().copied().fold(f64::NAN, f64::max);
        let lambda_min = lambdas.iter().copied().fold(f64::NAN, f64::min);
        let around = Around {
            aim,
            moved: motion.total() + SLACK_M,
            turn: Turn::new(motion.turn + SLACK_COS),
            gains: &a.gains,
            reach: reach_m(spec),
            mirrors,
            threshold_low: base / lambda_max * (1.0 - SLACK_REL),
            threshold_high: base / lambda_min * (1.0 + SLACK_REL),
        };
        let seconds = if t1_us == u64::MAX {
            0.0
        } else {
            (t1_us - t0_us) as f64 * 1e-6
        };
        let mut c = Classified {
            t0_us,
            t1_us,
            tx_bits: tx_power_dbm.to_bits(),
            ..Default::default()
        };
        for (k, tag) in self.tags.iter().enumerate() {
            let q = tag.motion.position(super::seconds(t0_us));
            match around.status(q, tag.motion.speed() * seconds) {
                Status::In => c.inside.push(k),
                Status::Undecided => c.undecided.push(k),
                Status::Out => {}
            }
        }
        c.pool = merge(&c.inside, &c.undecided);
        if t1_us == u64::MAX {
            c.at_rest = self.fields_at_rest(antenna, tx_power_dbm, t0_us, &c);
            c.links = (0..c.at_rest.len() * self.tags.len())
                .map(|_| OnceLock::new())
                .collect();
        }
        c
    }

    /// The field on every channel at `t_us` and for ever after, when nothing moves: `c`'s in
    /// tags and those of its undecided tags that each channel powers.
    fn fields_at_rest(
        &self,
        antenna: u16,
        tx_power_dbm: f64,
        t_us: u64,
        c: &Classified,
    ) -> Vec<Vec<usize>> {
        let channels = u16::try_from(self.table.len().max(1)).unwrap_or(u16::MAX);
        (1..=channels)
            .map(|channel| {
                let mut b = Bucket::default();
                self.prepare(&mut b, antenna, tx_power_dbm, t_us, channel);
                let mut field = c.inside.clone();
                field.extend(c.undecided.iter().filter(|&&t| self.in_field(&mut b, t)));
                field.sort_unstable();
                field
            })
            .collect()
    }

    /// How far antenna `antenna` moves and turns at most during `[t0_us, t1_us]`.
    fn excursion(&self, antenna: u16, t0_us: u64, t1_us: u64) -> Motion {
        let Some(a) = usize::from(antenna)
            .checked_sub(1)
            .and_then(|i| self.antennas.get(i))
        else {
            return Motion::default();
        };
        let (t0, t1) = (super::seconds(t0_us), super::seconds(t1_us));
        match &a.mover {
            Mover::Fixed(_) => Motion::default(),
            Mover::Recorded(poses) => {
                let [x, y, z, turn] = super::motion::recorded_excursion(poses, t0, t1);
                Motion {
                    axes: [x, y, z],
                    turn,
                }
            }
            Mover::Robot {
                robot,
                offset,
                vertical,
            } => {
                let Some(trajectory) = self.robots.get(*robot) else {
                    return Motion::default();
                };
                // The antenna sits at the robot's position plus its offset turned by the
                // heading: each coordinate moves by at most the robot's plus the arm times
                // the turn.
                let [dx, dy, dtheta] = trajectory.excursion(t0, t1);
                let arm = offset.position[0].hypot(offset.position[1]) * dtheta;
                let dz = vertical
                    .as_ref()
                    .filter(|v| v.speed.is_finite() && v.speed > 0.0)
                    .map_or(0.0, |v| v.speed * (t1 - t0));
                Motion {
                    axes: [dx + arm, dy + arm, dz],
                    turn: dtheta,
                }
            }
        }
    }
}

/// The tags of `inside` (known in) and `undecided` (unknown), both ascending, in tag order.
fn merge(inside: &[usize], undecided: &[usize]) -> Vec<(usize, Known)> {
    let mut pool = Vec::with_capacity(inside.len() + undecided.len());
    let (mut i, mut u) = (0, 0);
    loop {
        match (inside.get(i), undecided.get(u)) {
            (Some(&x), Some(&y)) if x < y => {
                pool.push((x, Known::In));
                i += 1;
            }
            (Some(&x), None) => {
                pool.push((x, Known::In));
                i += 1;
            }
            (_, Some(&y)) => {
                pool.push((y, Known::Unknown));
                u += 1;
            }
            (None, None) => return pool,
        }
    }
}

/// The forward link powers a tag when A = √g₀·|1 + Σ Hᵢ|/D reaches this over λ:
/// P_tag = P_tx − L + 10·log10(G_T) + 20·log10(λ/4π) + 20·log10(A) ≥ the tag's sensitivity.
fn amplitude_threshold(spec: &crate::scenario::AntennaSpec, tx_power_dbm: f64) -> f64 {
    10f64.powf(
        (spec.tag_sensitivity_dbm - tx_power_dbm + spec.cable_loss_db - rssi::TAG_GAIN_DBI) / 20.0,
    ) * 4.0
        * std::f64::consts::PI
}

/// The grid point at or after `t_us` (`u64::MAX` stays): where the interval that lasts for
/// ever begins once nothing moves.
pub(super) fn rest_grid(t_us: u64) -> u64 {
    t_us.div_ceil(MAX_SPAN_US).saturating_mul(MAX_SPAN_US)
}

/// Reach of an antenna: r·(1 + 4σ_r).
pub(super) fn reach_m(spec: &crate::scenario::AntennaSpec) -> f64 {
    spec.range_m * (1.0 + super::inventory::RANGE_SIGMAS * spec.range_sigma)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::antenna::Pattern;
    use crate::scenario::Scenario;

    /// Exact membership of `tag` at `t_us` on a wavelength, as listing the field in full does.
    fn exact(m: &Model, antenna: u16, tx: f64, t_us: u64, lambda: f64, tag: usize) -> bool {
        let spec = &m.antennas[usize::from(antenna) - 1].spec;
        let aim = Aim::new(&m.antenna_pose(antenna, t_us));
        let position = m.tag_position(tag, t_us);
        let by_margin = distance(aim.position, position) <= reach_m(spec)
            && m.margin_with(antenna, &aim, position, lambda, tx, true).1 >= 0.0;
        let mut b = Bucket {
            antenna,
            t_us,
            wavelength_m: lambda,
            threshold: (amplitude_threshold(spec, tx) / lambda).powi(2),
            amplitude: amplitude_threshold(spec, tx) / lambda,
            reach: reach_m(spec),
            ..Default::default()
        };
        // The linear test agrees with the margin in dB.
        assert_eq!(m.in_field(&mut b, tag), by_margin, "tag {tag} at {t_us} µs");
        by_margin
    }

    /// Every tag a classification calls in (out) is in (out of) the field at every bucket
    /// start of its interval, on the first, last and middle channel; returns how many tags
    /// were decided and how many left undecided.
    fn check(m: &Model, tx: f64, starts: impl Iterator<Item = u64>) -> (usize, usize) {
        let (mut decided, mut undecided) = (0, 0);
        let table = m.frequencies_khz().len().max(1) as u16;
        for t in starts {
            for antenna in 1..=m.antenna_count() {
                let c = m.classify(antenna, tx, t);
                assert!(c.t0_us <= t && t < c.t1_us);
                undecided += c.undecided.len();
                let bucket = crate::physics::inventory::FIELD_BUCKET_US;
                // An interval that never ends is probed an hour on.
                let end = c.t1_us.min(c.t0_us + 3_600_000_000);
                let probes = [
                    c.t0_us,
                    t,
                    (c.t0_us + end) / 2 / bucket * bucket,
                    end - bucket,
                ];
                for probe in probes {
                    for ch in [1, table / 2 + 1, table] {
                        let lambda = m.wavelength_m(ch);
                        if let Some(field) = c.at_rest.get(usize::from(ch) - 1) {
                            let exact: Vec<usize> = (0..m.tag_count())
                                .filter(|&tag| exact(m, antenna, tx, probe, lambda, tag))
                                .collect();
                            assert_eq!(field, &exact, "antenna {antenna} at rest, t {probe}");
                        }
                        for tag in 0..m.tag_count() {
                            let inside = c.inside.binary_search(&tag).is_ok();
                            let maybe = c.undecided.binary_search(&tag).is_ok();
                            if maybe {
                                continue;
                            }
                            decided += 1;
                            assert_eq!(
                                exact(m, antenna, tx, probe, lambda, tag),
                                inside,
                                "antenna {antenna}, tag {tag}, t {probe} µs, channel {ch}"
                            );
                        }
                    }
                }
            }
        }
        (decided, undecided)
    }

    fn fixture(name: &str) -> Scenario {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("fixtures/scenarios")
            .join(format!("{name}.json"));
        Scenario::load(&path).expect("fixture loads")
    }

    #[test]
    fn classification_agrees_with_exact_evaluation_on_the_fixtures() {
        for (name, horizon_s, tx) in [("s1", 50, 30.0), ("s2", 250, 27.0), ("s2", 120, 20.0)] {
            let s = fixture(name);
            let m = Model::new(&s, 0);
            let (decided, undecided) = check(&m, tx, (0..horizon_s).map(|k| k * 1_000_000));
            // The bounds must decide most tags, or they save nothing.
            assert!(decided > 4 * undecided, "{name}: {decided} vs {undecided}");
        }
        let s = fixture("s3");
        let m = Model::new(&s, 0);
        check(&m, 30.0, (0..300).map(|k| k * 1_370_000));
    }

    #[test]
    fn fields_at_rest_are_exact() {
        // S2's robot stops after 240 s; S1's after 44 s.
        for (name, from_s) in [("s2", 245), ("s1", 40)] {
            let m = Model::new(&fixture(name), 0);
            check(&m, 27.0, (from_s..from_s + 20).map(|k| k * 1_000_000));
            let late = 10_000_000_000;
            for antenna in 1..=m.antenna_count() {
                let c = m.classify(antenna, 27.0, late);
                assert_eq!(c.t1_us, u64::MAX, "{name}: the robot rests");
                assert_eq!(c.at_rest.len(), m.frequencies_khz().len());
                // Links served from the classification are those computed afresh.
                let (mut held, mut bucket) = (None, Bucket::default());
                m.open_bucket(antenna, 27.0, late, 1, &mut held, &mut bucket);
                assert!(bucket.rest.is_some());
                let lambda = m.wavelength_m(1);
                for tag in 0..m.tag_count() {
                    for t in [late + 1234, 2 * late] {
                        let aim = Aim::new(&m.antenna_pose(antenna, t));
                        let fresh = m.margin_with(
                            antenna,
                            &aim,
                            m.tag_position(tag, t),
                            lambda,
                            27.0,
                            true,
                        );
                        assert_eq!(m.link(&bucket, antenna, tag, t, 1, 27.0, true), fresh);
                    }
                    // The Doppler shortcut gives what the central difference gives.
                    let range =
                        |t| distance(m.antenna_position(antenna, t), m.tag_position(tag, t));
                    let v_r = (range(late + 10_000) - range(late - 10_000)) / 0.02;
                    assert_eq!(
                        m.doppler_hz(antenna, tag, late, lambda).to_bits(),
                        crate::physics::phase::doppler_hz(v_r, lambda).to_bits()
                    );
                }
            }
        }
        // A fixed antenna and still tags rest from the start; a looping tag never does.
        let v = |looping: bool| {
            serde_json::json!({
                "name": "fixed",
                "seed": 5,
                "world": { "min": [-5, -5, 0], "max": [5, 5, 3] },
                "reflectors": [ { "point": [0, 0, 0], "normal": [0, 0, 1], "coefficient": 0.5 } ],
                "tags": [
                    { "epc": "E20000000000000000000001", "position": [2, 0, 1] },
                    { "epc": "E20000000000000000000002", "position": [3, 1, 1],
                      "path": { "waypoints": [[3, -1, 1]], "speed": 0.5, "loop_path": looping } }
                ],
                "readers": [ { "name": "r", "region": "etsi", "antennas": [
                    { "mount": { "type": "fixed", "pose": { "position": [0, 0, 1] } } } ] } ]
            })
        };
        let m = Model::new(
            &Scenario::from_json(&v(false).to_string()).expect("valid"),
            0,
        );
        assert_eq!(
            m.classify(1, 30.0, 0).t1_us,
            MAX_SPAN_US,
            "the tag still moves at 0 s"
        );
        assert_eq!(m.classify(1, 30.0, 9_000_000).t1_us, u64::MAX);
        check(&m, 30.0, [0, 2_000_000, 5_000_000, 9_000_000].into_iter());
        let m = Model::new(
            &Scenario::from_json(&v(true).to_string()).expect("valid"),
            0,
        );
        assert!(m.classify(1, 30.0, 900_000_000).t1_us < u64::MAX);
    }

    /// A turning robot on a lift with a tilted, wide antenna; moving tags; a sloped and a
    /// vertical reflector close to the path.
    fn everything_moves() -> Scenario {
        let mut tags = Vec::new();
        for i in 0..40 {
            let x = 0.5 + 0.25 * f64::from(i);
            tags.push(serde_json::json!({
                "epc": format!("E2000000000000000000{i:04X}"),
                "position": [x, 2.0 + 0.1 * f64::from(i % 7), 0.3 + 0.05 * f64::from(i % 11)],
                "path": if i % 3 == 0 {
                    serde_json::json!({ "waypoints": [[x, 0.5, 1.0], [x + 1.0, 3.0, 1.5]],
                                        "speed": 0.3, "loop_path": true })
                } else {
                    serde_json::Value::Null
                }
            }));
        }
        for t in &mut tags {
            if let Some(o) = t.as_object_mut() {
                o.retain(|_, v| !v.is_null());
            }
        }
        let antenna = |yaw: f64, pitch: f64, bw: f64| {
            serde_json::json!({
                "mount": { "type": "robot", "robot": {
                    "start": [1, 1, 0], "waypoints": [[6, 1], [6, 3], [2, 2.5], [9, 1]],
                    "speed": 0.8, "loop_path": true,
                    "vertical": { "min_z": 0.3, "max_z": 1.8, "speed": 0.4 } },
                  "offset": { "position": [0.2, 0.3, 0.5], "yaw_deg": yaw, "pitch_deg": pitch } },
                "beamwidth_deg": bw, "gain_dbi": 7.0, "tx_power_dbm": 26, "range_m": 4
            })
        };
        let v = serde_json::json!({
            "name": "everything-moves",
            "seed": 11,
            "world": { "min": [-1, -1, -1], "max": [12, 6, 4] },
            "reflectors": [
                { "point": [0, 0, 0], "normal": [0, 0, 1], "coefficient": 0.6 },
                { "point": [0, 4, 0], "normal": [0, -1, 0.3], "coefficient": 0.5 },
                { "point": [10, 0, 0], "normal": [-1, 0, 0], "coefficient": 0.4 }
            ],
            "tags": tags,
            "readers": [ { "name": "r", "region": "fcc", "antennas": [
                antenna(90.0, 0.0, 65.0), antenna(45.0, 20.0, 240.0), antenna(-30.0, -15.0, 30.0)
            ] } ]
        });
        Scenario::from_json(&v.to_string()).expect("valid scenario")
    }

    #[test]
    fn classification_agrees_with_exact_evaluation_when_everything_moves() {
        let m = Model::new(&everything_moves(), 0);
        for tx in [30.0, 22.0] {
            check(&m, tx, (0..120).map(|k| k * 470_000));
        }
    }

    /// Every decision a bucket keeps agrees with the exact evaluation at bucket starts up to
    /// its expiry (the first, second and last, and every 7th); returns how many were kept,
    /// and how many decisions were made.
    fn check_kept(m: &Model, tx: f64, starts: impl Iterator<Item = u64>) -> (usize, usize) {
        let bucket_us = crate::physics::inventory::FIELD_BUCKET_US;
        let table = m.frequencies_khz().len().max(1) as u16;
        let (mut kept, mut made) = (0, 0);
        for t in starts {
            for antenna in 1..=m.antenna_count() {
                for ch in [1, table / 2 + 1, table] {
                    let mut b = Bucket::default();
                    b.memo.fit(m.tag_count(), tx);
                    b.memo.exhaustive = true;
                    m.prepare(&mut b, antenna, tx, t, ch);
                    for tag in 0..m.tag_count() {
                        m.in_field(&mut b, tag);
                    }
                    let lambda = m.wavelength_m(ch);
                    for (tag, k) in b.memo.kept.iter().enumerate() {
                        made += 1;
                        if k.channel == 0 {
                            continue;
                        }
                        kept += 1;
                        assert_eq!((k.channel, k.from_us), (ch, t));
                        let steps = (k.until_us - k.from_us) / bucket_us;
                        let probes = (0..=steps)
                            .filter(|j| *j < 2 || j % 7 == 0)
                            .map(|j| t + j * bucket_us)
                            .chain([k.until_us]);
                        for probe in probes {
                            assert_eq!(
                                exact(m, antenna, tx, probe, lambda, tag),
                                k.inside,
                                "antenna {antenna}, tag {tag}, kept from {t} to {} µs, \
                                 probe {probe}, channel {ch}",
                                k.until_us
                            );
                        }
                    }
                }
            }
        }
        (kept, made)
    }

    #[test]
    fn kept_decisions_hold_until_they_expire() {
        let s2 = fixture("s2");
        let m = Model::new(&s2, 0);
        let (kept, made) = check_kept(&m, 27.0, (0..40).map(|k| k * 5_010_000));
        // Most decisions on a slow robot are kept, or keeping saves nothing.
        assert!(2 * kept > made, "S2: {kept} of {made}");
        let m = Model::new(&everything_moves(), 0);
        for tx in [30.0, 22.0] {
            let (kept, _) = check_kept(&m, tx, (0..60).map(|k| k * 930_000));
            assert!(kept > 0, "the fast robot keeps some decisions too");
        }
    }

    #[test]
    fn fast_field_test_agrees_with_the_phasor_sum() {
        // Antennas of several lobes at several poses, tags all around them, sloped and
        // axis-aligned reflectors; thresholds at and around each tag's exact amplitude.
        let reflectors = [
            ([0.0, 0.0, 0.0], [0.0, 0.0, 1.0], 0.6),
            ([0.0, 4.0, 0.0], [0.0, -1.0, 0.3], 0.5),
            ([9.0, 0.0, 0.0], [-1.0, 0.2, 0.0], 0.3),
        ];
        let planes: Vec<Plane> = reflectors
            .iter()
            .map(|&(point, normal, coefficient)| {
                let n = norm(normal);
                Plane {
                    point,
                    unit: [normal[0] / n, normal[1] / n, normal[2] / n],
                    coefficient,
                }
            })
            .collect();
        let (mut decided, mut total) = (0, 0);
        for (gain_dbi, bw) in [(6.0, 65.0), (4.77, 70.0), (7.0, 30.0), (3.0, 240.0)] {
            let lobe = Lobe::new(gain_dbi, bw);
            let gains = GainTable::new(&lobe);
            let pattern = Pattern::new(&lobe);
            for (k, yaw) in [0.0f64, 1.3, -2.2, 3.0].into_iter().enumerate() {
                let k = k as f64;
                let pose = crate::physics::AntennaPose {
                    position: [1.0 + k, 1.5 + 0.4 * k, 0.3 + 0.5 * k],
                    yaw_rad: yaw,
                    pitch_rad: 0.2 * k - 0.3,
                };
                let aim = Aim::new(&pose);
                for lambda in [0.3275, 0.3463] {
                    let mut near = Near::default();
                    near.prepare(&aim, &planes, lambda);
                    for i in 0..400 {
                        let f = f64::from(i);
                        let q = [
                            0.5 + (f * 0.731) % 8.0,
                            0.2 + (f * 0.377) % 3.7,
                            0.05 + (f * 0.193) % 2.5,
                        ];
                        let dist = distance(aim.position, q);
                        let power = power_gain_with(&aim, &pattern, q, &planes, lambda);
                        let amplitude = power.sqrt();
                        for factor in [0.3, 0.9, 0.99, 0.999, 1.0, 1.001, 1.01, 1.1, 3.0] {
                            let threshold = amplitude * factor;
                            total += 1;
                            if let Some((known, _)) = near.decide(&gains, q, dist, threshold) {
                                decided += 1;
                                assert_eq!(
                                    known,
                                    power >= threshold * threshold,
                                    "lobe {bw}, pose {k}, tag {q:?}, factor {factor}"
                                );
                            }
                        }
                    }
                }
            }
        }
        // Thresholds a few per cent away from the amplitude are decided without the exact sum.
        assert!(decided > total / 2, "{decided} of {total}");
    }
}
