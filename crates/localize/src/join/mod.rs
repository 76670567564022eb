//! Joining a tag's unwrapped segments that share one phase offset (ours, for sparse reads).
//!
//! The phase offset φ0 of a (reader, antenna, tag, channel) series is one physical constant,
//! but every split of the series (a gap, a step over the λ/4 motion limit) gives Phase ReLock
//! an offset of its own, and with it the phase history across the split is lost: at a few
//! reads a second per antenna, a slow robot splits a series into dozens of short segments and
//! the fix is poor. The offsets of one series' segments are equal modulo the series' period
//! (2π, or π with the π ambiguity), and so are those of a reader's antennas on one channel
//! once calibrated ([`crate::calibrate`]). Such a group of segments is:
//!
//! 1. judged by its coherence, |Σ exp(i·2π/P·(θ − s·4πd/λ))| over its phases, summed over the
//!    groups ([`coherence`]): it needs no unwrapping, so the splits do not matter to it, and
//!    is searched for its best point in a box ([`search_box`]) or along a fix's weak axes
//!    ([`search`]);
//! 2. joined at that point ([`join`]): each segment's offset is compared with its group's,
//!    and a segment within a quarter period of it is shifted by whole periods onto the
//!    group's offset and merged into one segment with it; the others stay as they were.
//!
//! Phase ReLock then solves again on the joined segments ([`crate::relock`]).

use nalgebra::{DMatrix, SymmetricEigen};

use crate::fix::Obs;
use crate::lanes::{lanes, runs, sin_cos_f32, sum_f32, wide, LANES};

/// A weak direction is searched when its σ is at least this (m).
pub const SEARCH_MIN_SIGMA_M: f64 = 0.005;
/// Farthest from the fix the coherence is searched, along each weak direction (m).
pub const SEARCH_MAX_M: f64 = 1.0;
/// Points either side of the fix along a searched direction.
pub const SEARCH_HALF_POINTS: i32 = 6;
/// Finest search step (m): well under the λ/4 a coherence lobe is wide.
const SEARCH_MIN_STEP_M: f64 = 0.01;
/// Phases the coherence is evaluated on (evenly spread over the tag's).
pub const SEARCH_PHASES: usize = 400;

/// Whether `obs` has a group of several segments, so that joining can change anything.
pub fn has_splits(obs: &[Obs]) -> bool {
    spans(obs, |o| o.group, |o| o.segment)
}

/// Whether joining can change anything in `obs`: a series split into segments, or a joint
/// group of calibrated antennas holding several series.
pub fn joinable(obs: &[Obs]) -> bool {
    has_splits(obs) || spans(obs, |o| o.joint, |o| o.group)
}

/// Whether some `outer` value of `obs` holds two `inner` values.
fn spans(obs: &[Obs], outer: fn(&Obs) -> usize, inner: fn(&Obs) -> usize) -> bool {
    let mut first: Vec<Option<usize>> = Vec::new();
    for o in obs {
        let (k, v) = (outer(o), inner(o));
        if first.len() <= k {
            first.resize(k + 1, None);
        }
        match first[k] {
            None => first[k] = Some(v),
            Some(s) if s != v => return true,
            Some(_) => {}
        }
    }
    false
}

/// The model phase s·4πd/λ of `o` for a tag at `p`.
fn model(o: &Obs, p: [f64; 3], sign: f64) -> f64 {
    let d = (0..3)
        .map(|a| (p[a] - o.antenna[a]).powi(2))
        .sum::<f64>()
        .sqrt();
    sign * 4.0 * std::f64::consts::PI * d / o.wavelength_m
}

/// The coherence of `obs` at `p`: Σ over the groups of |Σ w·exp(i·2π/P·(θ − s·4πd/λ))|, over
/// Σ w (1: every group's residuals equal modulo its period), w the reads a phase stands for.
pub fn coherence(obs: &[Obs], p: [f64; 3], sign: f64) -> f64 {
    let reads: f64 = obs.iter().map(|o| o.weight).sum();
    Evaluator::new(obs, usize::MAX, sign).sum(p) / reads.max(1.0)
}

/// The summed coherence of up to `phases` of a tag's phases (evenly spread), at any point:
/// the residuals' sin and cos in `f32`, structure of arrays, branch-free, so that the loop
/// over the phases runs in vector registers (the coherence searches are most of relock's
/// time on split series); then the sums per group.
struct Evaluator {
    /// The point the antenna positions are taken relative to, so that `f32` keeps their
    /// differences to well under a micrometre.
    origin: [f64; 3],
    ax: Vec<f32>,
    ay: Vec<f32>,
    az: Vec<f32>,
    /// 2π/P·θ reduced to [0, 2π) (whole periods of θ do not change the coherence).
    theta: Vec<f32>,
    /// 2π/P·s·4π/λ (rad/m).
    k: Vec<f32>,
    /// The reads each phase stands for (0 for padding).
    w: Vec<f32>,
    /// The phases are in group order: where each group's run of them is.
    runs: Vec<std::ops::Range<usize>>,
    /// Scratch: each phase's cos and sin.
    cos: Vec<f32>,
    sin: Vec<f32>,
}

impl Evaluator {
    fn new(obs: &[Obs], phases: usize, sign: f64) -> Evaluator {
        let stride = obs.len().div_ceil(phases.max(1)).max(1);
        let mut sub: Vec<&Obs> = obs.iter().step_by(stride).collect();
        // Each group's phases together: summed in registers, not through memory.
        sub.sort_by_key(|o| o.group);
        let runs = runs(&sub, |o| o.group);
        let origin = sub.first().map_or([0.0; 3], |o| o.antenna);
        let padded = sub.len().div_ceil(LANES) * LANES;
        let mut e = Evaluator {
            origin,
            ax: vec![0.0; padded],
            ay: vec![0.0; padded],
            az: vec![0.0; padded],
            theta: vec![0.0; padded],
            k: vec![0.0; padded],
            w: vec![0.0; padded],
            runs,
            cos: vec![0.0; padded],
            sin: vec![0.0; padded],
        };
        for (i, o) in sub.iter().enumerate() {
            let scale = std::f64::consts::TAU / o.period_rad;
            e.ax[i] = (o.antenna[0] - origin[0]) as f32;
            e.ay[i] = (o.antenna[1] - origin[1]) as f32;
            e.az[i] = (o.antenna[2] - origin[2]) as f32;
            e.theta[i] = (o.phase_rad * scale).rem_euclid(std::f64::consts::TAU) as f32;
            e.k[i] = (scale * sign * 4.0 * std::f64::consts::PI / o.wavelength_m) as f32;
            e.w[i] = o.weight as f32;
        }
        e
    }

    /// Σ over the groups of the coherence of the phases' residuals at `p`.
    fn sum(&mut self, p: [f64; 3]) -> f64 {
        let [px, py, pz] = [0, 1, 2].map(|a| (p[a] - self.origin[a]) as f32);
        // Slices of one length, so that no bounds check stands between the loop and vector
        // instructions.
        residuals(
            [px, py, pz],
            [&self.ax, &self.ay, &self.az, &self.theta, &self.k, &self.w],
            &mut self.sin,
            &mut self.cos,
        );
        let (cos, sin) = (&self.cos, &self.sin);
        self.runs
            .iter()
            .map(|r| {
                let (re, im) = (sum_f32(&cos[r.clone()]), sum_f32(&sin[r.clone()]));
                // The squares of f32 sums are exact in f64, so this is as good as `hypot`
                // (which is a libm call) to an ulp.
                let (re, im) = (f64::from(re), f64::from(im));
                (re * re + im * im).sqrt()
            })
            .sum()
    }
}

wide! {
    /// The sin and cos of each phase's residual at `p` (relative to the evaluator's origin),
    /// times its weight, into `sin` and `cos`; `columns` are the antennas' x, y, z, θ, k and
    /// the weights, all of one length.
    fn residuals(p: [f32; 3], columns: [&[f32]; 6], sin: &mut [f32], cos: &mut [f32]) = residuals_kernel
}

#[inline(always)]
fn residuals_kernel(p: [f32; 3], columns: [&[f32]; 6], sin: &mut [f32], cos: &mut [f32]) {
    let [px, py, pz] = p;
    // Chunks of LANES in arrays of LANES: the loop runs in vector registers with no scalar
    // remainder (the columns are padded to a multiple of LANES).
    for i in (0..columns[0].len() / LANES).map(|c| c * LANES) {
        let (ax, ay, az) = (
            lanes(columns[0], i),
            lanes(columns[1], i),
            lanes(columns[2], i),
        );
        let (theta, k, w) = (
            lanes(columns[3], i),
            lanes(columns[4], i),
            lanes(columns[5], i),
        );
        let (mut s, mut c) = ([0.0f32; LANES], [0.0f32; LANES]);
        for l in 0..LANES {
            let (dx, dy, dz) = (px - ax[l], py - ay[l], pz - az[l]);
            let d = (dx * dx + dy * dy + dz * dz).sqrt();
            let (sl, cl) = sin_cos_f32(theta[l] - k[l] * d);
            (s[l], c[l]) = (w[l] * sl, w[l] * cl);
        }
        sin[i..i + LANES].copy_from_slice(&s);
        cos[i..i + LANES].copy_from_slice(&c);
    }
}

/// The point of best coherence near `start` along the weak axes of `covariance` (`dims`×`dims`,
/// over the first `dims` coordinates of the position; the others held): ± 3σ along each (at
/// most [`SEARCH_MAX_M`]) in ± [`SEARCH_HALF_POINTS`] steps of at least 1 cm on up to
/// [`COARSE_PHASES`] phases, then in 1 cm steps around the best on up to [`SEARCH_PHASES`].
pub fn search(obs: &[Obs], start: [f64; 3], covariance: &DMatrix<f64>, sign: f64) -> [f64; 3] {
    let dims = covariance.nrows().min(3);
    let eigen = SymmetricEigen::new(covariance.clone());
    // The weak axes, weakest first; at most two are searched (a plane of points).
    let mut axes: Vec<(f64, [f64; 3])> = (0..dims)
        .filter_map(|k| {
            let sigma = eigen.eigenvalues[k].max(0.0).sqrt();
            (sigma.is_finite() && sigma >= SEARCH_MIN_SIGMA_M).then(|| {
                let mut v = [0.0; 3];
                for (a, va) in v.iter_mut().enumerate().take(dims) {
                    *va = eigen.eigenvectors[(a, k)];
                }
                (sigma, v)
            })
        })
        .collect();
    axes.sort_by(|a, b| b.0.total_cmp(&a.0));
    axes.truncate(2);
    if axes.is_empty() {
        return start;
    }
    // Steps of at most a sixth of a half-width on up to COARSE_PHASES, then 1 cm around the
    // best on up to SEARCH_PHASES.
    let plan: Vec<([f64; 3], f64, i32)> = axes
        .iter()
        .map(|&(sigma, v)| {
            let half = (3.0 * sigma).min(SEARCH_MAX_M);
            let step = (half / f64::from(SEARCH_HALF_POINTS)).max(SEARCH_MIN_STEP_M);
            (v, step, (half / step).round() as i32)
        })
        .collect();
    let coarse = best_on(obs, start, &plan, COARSE_PHASES, sign);
    if plan.iter().all(|p| p.1 <= SEARCH_MIN_STEP_M) {
        return coarse;
    }
    let fine: Vec<([f64; 3], f64, i32)> = plan
        .iter()
        .map(|&(v, step, _)| {
            (
                v,
                SEARCH_MIN_STEP_M,
                (step / SEARCH_MIN_STEP_M).ceil() as i32,
            )
        })
        .collect();
    best_on(obs, coarse, &fine, SEARCH_PHASES, sign)
}

/// Phases the coarse pass of [`search`] is evaluated on.
pub const COARSE_PHASES: usize = 100;

/// The most coherent point of the grid `centre` + Σ i_k·step_k·v_k, |i_k| ≤ n_k, over the
/// one or two axes of `plan`, on up to `phases` of `obs`.
fn best_on(
    obs: &[Obs],
    centre: [f64; 3],
    plan: &[([f64; 3], f64, i32)],
    phases: usize,
    sign: f64,
) -> [f64; 3] {
    let mut at = Evaluator::new(obs, phases, sign);
    let (v0, h0, n0) = plan[0];
    let (v1, h1, n1) = plan.get(1).copied().unwrap_or(([0.0; 3], 0.0, 0));
    let point = |a: f64, b: f64| [0, 1, 2].map(|k| centre[k] + a * h0 * v0[k] + b * h1 * v1[k]);
    // A plane of more points than two levels take ([`best_in_box`]) is searched in two.
    let full = (2 * n0 + 1) * (2 * n1 + 1);
    let levels = (2 * (n0 / 2) + 1) * (2 * (n1 / 2) + 1) + BOX_TOP as i32 * 8;
    if n1 > 0 && levels < full {
        let mut score = |q: [f64; 3]| Some(at.sum(point(q[0], q[1])));
        return best_in_box([0.0; 3], [n0, n1, 0], 1.0, BOX_TOP, &mut score)
            .map_or(centre, |b| point(b.1[0], b.1[1]));
    }
    let mut best = (at.sum(centre), centre);
    for i in -n0..=n0 {
        for j in -n1..=n1 {
            let p = point(f64::from(i), f64::from(j));
            let c = at.sum(p);
            if c > best.0 {
                best = (c, p);
            }
        }
    }
    best.1
}

/// The point of best coherence on the grid of `step` within `half` of `centre` (in the first
/// `dims` coordinates), on up to `phases` of `obs`.
pub fn search_box(
    obs: &[Obs],
    centre: [f64; 3],
    (dims, half, step, phases): (usize, f64, f64, usize),
    sign: f64,
) -> [f64; 3] {
    let mut at = Evaluator::new(obs, phases, sign);
    let n = (half / step).round() as i32;
    let nz = if dims == 3 { n } else { 0 };
    if n >= 4 {
        // Large boxes in two levels ([`best_in_box`]); a small one is cheaper whole.
        return best_in_box(centre, [n, n, nz], step, BOX_TOP, &mut |p| Some(at.sum(p)))
            .map_or(centre, |b| b.1);
    }
    let mut best = (f64::MIN, centre);
    for i in -n..=n {
        for j in -n..=n {
            for k in -nz..=nz {
                let p = [
                    centre[0] + f64::from(i) * step,
                    centre[1] + f64::from(j) * step,
                    centre[2] + f64::from(k) * step,
                ];
                let c = at.sum(p);
                if c > best.0 {
                    best = (c, p);
                }
            }
        }
    }
    best.1
}

/// Points of a large box's first level whose neighbours [`search_box`] searches.
const BOX_TOP: usize = 16;

/// The point of the grid `centre` + (i, j, k)·`step`, |i|, |j|, |k| up to `half`, where
/// `score` is highest (`None`: a point not to consider), found in two levels: the grid of
/// twice the step, then the neighbours at the step of its `top` best points. Where a half
/// count is under 2, that axis is searched at the step throughout.
pub fn best_in_box(
    centre: [f64; 3],
    half: [i32; 3],
    step: f64,
    top: usize,
    score: &mut dyn FnMut([f64; 3]) -> Option<f64>,
) -> Option<(f64, [f64; 3])> {
    levels(centre, half, step, top, None, score)
}

/// [`best_in_box`] with the first level scored by `rough` (a cheaper score that ranks points
/// as `score` does, roughly); its `top` best points are then scored by `score` with their
/// neighbours.
pub fn best_in_box_rough(
    centre: [f64; 3],
    half: [i32; 3],
    step: f64,
    top: usize,
    rough: &mut dyn FnMut([f64; 3]) -> Option<f64>,
    score: &mut dyn FnMut([f64; 3]) -> Option<f64>,
) -> Option<(f64, [f64; 3])> {
    levels(centre, half, step, top, Some(rough), score)
}

/// [`best_in_box`]'s two levels, the first scored by `rough` where it is given.
fn levels(
    centre: [f64; 3],
    half: [i32; 3],
    step: f64,
    top: usize,
    mut rough: Option<&mut dyn FnMut([f64; 3]) -> Option<f64>>,
    score: &mut dyn FnMut([f64; 3]) -> Option<f64>,
) -> Option<(f64, [f64; 3])> {
    let at =
        |c: [f64; 3], d: [i32; 3], h: [f64; 3]| [0, 1, 2].map(|a| c[a] + f64::from(d[a]) * h[a]);
    // Axes of 2 half steps or more are searched at twice the step first.
    let coarse_half = half.map(|n| if n >= 2 { n / 2 } else { n });
    let coarse_step = half.map(|n| if n >= 2 { 2.0 * step } else { step });
    let mut points = Vec::new();
    for i in -coarse_half[0]..=coarse_half[0] {
        for j in -coarse_half[1]..=coarse_half[1] {
            for k in -coarse_half[2]..=coarse_half[2] {
                let p = at(centre, [i, j, k], coarse_step);
                let v = match rough.as_mut() {
                    Some(rough) => rough(p),
                    None => score(p),
                };
                if let Some(v) = v {
                    points.push((v, p));
                }
            }
        }
    }
    points.sort_by(|a, b| b.0.total_cmp(&a.0));
    points.truncate(top);
    let mut best = match rough {
        Some(_) => None,
        None => points.first().copied(),
    };
    let near = half.map(|n| i32::from(n >= 2));
    for &(_, p) in &points {
        for i in -near[0]..=near[0] {
            for j in -near[1]..=near[1] {
                for k in -near[2]..=near[2] {
                    // The point itself has its score already, unless it was scored roughly.
                    if (i, j, k) == (0, 0, 0) && rough.is_none() {
                        continue;
                    }
                    let q = at(p, [i, j, k], [step; 3]);
                    if let Some(v) = score(q) {
                        if best.is_none_or(|b| v > b.0) {
                            best = Some((v, q));
                        }
                    }
                }
            }
        }
    }
    best
}

/// `obs` with every segment whose offset at `p` is within a quarter period of its group's
/// shifted onto it by whole periods and merged into one segment per group; the segments
/// renumbered from 0. The count of segments after joining is returned with them.
pub fn join(obs: &[Obs], p: [f64; 3], sign: f64) -> (Vec<Obs>, usize) {
    let segments = obs.iter().map(|o| o.segment + 1).max().unwrap_or(0);
    let groups = obs.iter().map(|o| o.group + 1).max().unwrap_or(0);
    // Each segment's mean residual (its best offset), group and period.
    let mut sum = vec![0.0; segments];
    let mut count = vec![0.0; segments];
    let mut info: Vec<Option<(usize, f64)>> = vec![None; segments];
    for o in obs {
        sum[o.segment] += o.weight * (o.phase_rad - model(o, p, sign));
        count[o.segment] += o.weight;
        info[o.segment] = Some((o.group, o.period_rad));
    }
    // The group's offset: the circular mean of its segments' offsets, weighted by phases.
    let (mut re, mut im) = (vec![0.0; groups], vec![0.0; groups]);
    for k in 0..segments {
        if let Some((g, period)) = info[k] {
            let c = sum[k] / count[k] * std::f64::consts::TAU / period;
            re[g] += count[k] * c.cos();
            im[g] += count[k] * c.sin();
        }
    }
    // Each segment's new number and its shift (whole periods).
    let mut joined_id: Vec<Option<usize>> = vec![None; groups];
    let mut map = vec![(0usize, 0.0f64); segments];
    let mut next = 0;
    for k in 0..segments {
        let Some((g, period)) = info[k] else {
            continue;
        };
        let c = sum[k] / count[k];
        let centre = im[g].atan2(re[g]) * period / std::f64::consts::TAU;
        let turns = ((c - centre) / period).round();
        let deviation = c - centre - turns * period;
        if deviation.abs() < period / 4.0 {
            let id = *joined_id[g].get_or_insert_with(|| {
                next += 1;
                next - 1
            });
            map[k] = (id, turns * period);
        } else {
            map[k] = (next, 0.0);
            next += 1;
        }
    }
    let out = obs
        .iter()
        .map(|o| {
            let (segment, shift) = map[o.segment];
            Obs {
                phase_rad: o.phase_rad - shift,
                segment,
                ..*o
            }
        })
        .collect();
    (out, next)
}

#[cfg(test)]
mod tests;
