//! The classification grid: intervals of time on a fixed grid, the bounds on how far an
//! antenna and its tags move in one, and the status (in, out or undecided) they give each tag
//! for every bucket start of the interval, with the fields evaluated once when nothing moves.

use std::sync::{Arc, OnceLock};

use super::draw::{Bucket, Known};
use super::gains::GainTable;
use super::{amplitude_threshold, reach_m, SLACK_COS, SLACK_M, SLACK_REL};
use crate::physics::geometry::{add_scaled, distance, dot, norm, sub, Vec3};
use crate::physics::multipath::{Aim, Channel, Plane, MIN_DISTANCE_M};
use crate::physics::{Model, Mover};

/// Longest interval one classification covers, µs: a power-of-two number of buckets, so the
/// halves of an interval are whole buckets down to one.
pub const MAX_SPAN_US: u64 = 128 * crate::physics::inventory::FIELD_BUCKET_US;
/// Largest antenna displacement (m) one classification allows: the interval is halved until
/// the antenna stays within it (or is one bucket long).
const MAX_EXCURSION_M: f64 = 0.2;
/// Largest boresight turn (rad) one classification allows, likewise.
const MAX_TURN_RAD: f64 = 0.1;

/// Status of one tag for one classification.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Status {
    Out,
    In,
    Undecided,
}

/// One antenna's classification: valid for bucket starts in `[t0_us, t1_us)` at `tx_bits`.
#[derive(Clone, Debug, Default)]
pub(in crate::physics) struct Classified {
    pub(super) t0_us: u64,
    pub(super) t1_us: u64,
    pub(super) tx_bits: u64,
    /// Tags in the field at every bucket start, ascending.
    pub(super) inside: Vec<usize>,
    /// Tags to evaluate bucket by bucket, ascending.
    pub(super) undecided: Vec<usize>,
    /// Both, merged in tag order, as a bucket's candidates start.
    pub(super) pool: Vec<(usize, Known)>,
    /// Once nothing moves any more (the interval never ends), the field on each channel of
    /// the table (index channel − 1), evaluated once; empty otherwise.
    pub(super) at_rest: Vec<Vec<usize>>,
    /// Then too, the channel and forward-link margin of each tag in the field on each
    /// channel (beside its entry in `at_rest`), computed on first use: they no longer change.
    /// Only the tags in the field: a scenario's other tags (thousands, in a fleet) cost
    /// nothing here.
    pub(super) links: Vec<Vec<OnceLock<(Channel, f64)>>>,
}

impl Classified {
    /// Whether this classification holds at bucket start `t_us` for `tx_power_dbm`.
    pub(super) fn holds(&self, t_us: u64, tx_power_dbm: f64) -> bool {
        self.t0_us <= t_us && t_us < self.t1_us && self.tx_bits == tx_power_dbm.to_bits()
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
    /// [`crate::physics::multipath::channel`]: √g₀·|1 + Σ Hᵢ|/D = A).
    ///
    /// `scales` are the bounds on the tag's own factor on the threshold
    /// ([`crate::physics::tag::TagRadio::threshold_scales`]).
    fn status(&self, q: Vec3, moves: f64, scales: (f64, f64)) -> Status {
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
        if a_hi < self.threshold_low * scales.0 {
            Status::Out
        } else if within && a_lo > self.threshold_high * scales.1 {
            Status::In
        } else {
            Status::Undecided
        }
    }
}

impl Model {
    /// The classification of `antenna` holding at bucket start `t_us`: cached, or made and
    /// cached.
    pub(super) fn classification(
        &self,
        antenna: u16,
        tx_power_dbm: f64,
        t_us: u64,
    ) -> Arc<Classified> {
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

    /// Whether a tag may be in the field of `antenna` at bucket start `t_us` on `channel` by
    /// the classification's bounds alone (exact once nothing moves), from a cache of its own.
    pub(in crate::physics) fn may_be_occupied(
        &self,
        antenna: u16,
        tx_power_dbm: f64,
        t_us: u64,
        channel: u16,
    ) -> bool {
        let i = usize::from(antenna).saturating_sub(1);
        let cached = self
            .field_cache
            .idle_slot(i)
            .and_then(|s| s.clone())
            .filter(|c| c.holds(t_us, tx_power_dbm));
        let c = match cached {
            Some(c) => c,
            None => {
                let c = Arc::new(self.classify(antenna, tx_power_dbm, t_us));
                if let Some(mut s) = self.field_cache.idle_slot(i) {
                    *s = Some(c.clone());
                }
                c
            }
        };
        match c.at_rest.get(usize::from(channel).wrapping_sub(1)) {
            Some(field) => !field.is_empty(),
            None => !c.pool.is_empty(),
        }
    }

    /// Classifies every tag for `antenna` over the grid interval holding bucket start `t_us`.
    pub(super) fn classify(&self, antenna: u16, tx_power_dbm: f64, t_us: u64) -> Classified {
        let a = &self.antennas[usize::from(antenna) - 1];
        let (t0_us, t1_us, motion) = self.grid_interval(antenna, t_us, a.rest_us);
        let spec = &a.spec;
        let aim = self.aim(antenna, t0_us);
        let mirrors = self.mirrors_of(&aim, &motion);
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
            let q = tag.motion.position(crate::physics::seconds(t0_us));
            let scales = tag.radio.threshold_scales();
            match around.status(q, tag.motion.speed() * seconds, scales) {
                Status::In => c.inside.push(k),
                Status::Undecided => c.undecided.push(k),
                Status::Out => {}
            }
        }
        c.pool = merge(&c.inside, &c.undecided);
        if t1_us == u64::MAX {
            c.at_rest = self.fields_at_rest(antenna, tx_power_dbm, t0_us, &c);
            c.links = c
                .at_rest
                .iter()
                .map(|field| field.iter().map(|_| OnceLock::new()).collect())
                .collect();
        }
        c
    }

    /// The grid interval holding bucket start `t_us` for `antenna` (at rest from `rest`):
    /// its start, its end and the antenna's excursion over it, halved until small enough.
    fn grid_interval(&self, antenna: u16, t_us: u64, rest: u64) -> (u64, u64, Motion) {
        let bucket = crate::physics::inventory::FIELD_BUCKET_US;
        if t_us >= rest {
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
        }
    }

    /// The image of the antenna at `aim` in each reflector, with how far its distance to the
    /// plane may move by `motion`.
    fn mirrors_of(&self, aim: &Aim, motion: &Motion) -> Vec<Mirror> {
        self.planes
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
            .collect()
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
        let (t0, t1) = (
            crate::physics::seconds(t0_us),
            crate::physics::seconds(t1_us),
        );
        match &a.mover {
            Mover::Fixed(_) => Motion::default(),
            Mover::Recorded(poses) => {
                let [x, y, z, turn] =
                    crate::physics::motion::recorded_excursion(poses, t0_us, t1_us);
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
