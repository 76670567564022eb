//! Phase ReLock on split series (ours): the segments of each series joined, then the series
//! of calibrated antennas ([`crate::calibrate`]) joined into one group ([`join`]).
//!
//! 1. The fit with separate offsets (loose, but near the tag) is the first start; grids on
//!    the phase differences of consecutive reads of a series ([`pairs`]), which hold across
//!    its splits, give up to [`STARTS`] more, computed only when that one is not taken.
//! 2. Around each, in the grid's order, the most coherent point within [`START_BOX_M`]
//!    ([`join::search_box`], each series its own group, 4 cm steps on 80 phases).
//! 3. From a start: 2.5 cm steps within 5 cm, the segments of each series joined there
//!    ([`join::join`]) and solved; joined again from the fit while that merges more and the
//!    fit explains the phases about as well ([`rejoin`]); then the same with the calibrated
//!    antennas' series in one group.
//! 4. A fit whose phases are [`COHERENT`] (calibrated antennas in one group) is taken; else
//!    the next start, and when none is, a box of [`WIDE_BOX_M`] around the best fit; the most
//!    coherent fit wins.

use super::{
    coarse_starts, distance, position, refine, solve, NoFix, Obs, Problem, Search, Solution,
};
use super::{COARSE, FINE};
use crate::{join, lanes};

/// Starts tried (the best grid points at least 1.5 grid steps apart).
const STARTS: usize = 4;
/// Half-width of the box around a grid point searched for the most coherent point (m).
const START_BOX_M: f64 = 0.3;

/// Two reads of one series next to each other in time, for the grids of a split series.
#[derive(Clone, Copy, Debug)]
struct Pair {
    a: [f64; 3],
    b: [f64; 3],
    /// θ_b − θ_a (rad).
    dphase: f64,
    /// s·4π/λ.
    k: f64,
    /// 2π over the period.
    scale: f64,
}

/// The pairs of consecutive phases of one group (one series, in time order) whose antennas
/// are less than λ/2 apart, up to `max` of them evenly spread: their phase differences hold
/// across the splits of a series, and change slowly with the tag's position (the range
/// difference of two antenna positions δ apart is at most δ), so a coarse grid finds their
/// best without unwrapping.
fn pairs(obs: &[Obs], sign: f64, max: usize) -> Vec<Pair> {
    let all: Vec<Pair> = obs
        .windows(2)
        .filter(|w| {
            w[0].group == w[1].group
                && w[0].wavelength_m == w[1].wavelength_m
                && distance(w[0].antenna, w[1].antenna) < w[0].wavelength_m / 2.0
        })
        .map(|w| Pair {
            a: w[0].antenna,
            b: w[1].antenna,
            dphase: w[1].phase_rad - w[0].phase_rad,
            k: sign * 4.0 * std::f64::consts::PI / w[0].wavelength_m,
            scale: std::f64::consts::TAU / w[0].period_rad,
        })
        .collect();
    let stride = all.len().div_ceil(max).max(1);
    all.into_iter().step_by(stride).collect()
}

/// Σ (1 − cos) of the pairs' phase differences against the model's, at any point: in
/// `f32`, structure of arrays, relative to the first pair's antenna, so that it vectorizes
/// as the coherence does ([`join`]); a padding pair adds cos 0 = 1, nothing.
struct PairCost {
    origin: [f64; 3],
    /// The two antennas' coordinates, then 2π/P·Δθ reduced to [0, 2π) and 2π/P·s·4π/λ.
    columns: [Vec<f32>; 8],
}

impl PairCost {
    fn new(pairs: &[Pair]) -> PairCost {
        let origin = pairs.first().map_or([0.0; 3], |q| q.a);
        let padded = pairs.len().div_ceil(lanes::LANES) * lanes::LANES;
        let mut columns: [Vec<f32>; 8] = std::array::from_fn(|_| vec![0.0; padded]);
        for (i, q) in pairs.iter().enumerate() {
            for a in 0..3 {
                columns[a][i] = (q.a[a] - origin[a]) as f32;
                columns[3 + a][i] = (q.b[a] - origin[a]) as f32;
            }
            columns[6][i] = (q.dphase * q.scale).rem_euclid(std::f64::consts::TAU) as f32;
            columns[7][i] = (q.k * q.scale) as f32;
        }
        PairCost { origin, columns }
    }

    fn at(&self, p: [f64; 3]) -> f64 {
        let p = [0, 1, 2].map(|a| (p[a] - self.origin[a]) as f32);
        let c = &self.columns;
        pair_cost(
            [
                c[0].as_slice(),
                &c[1],
                &c[2],
                &c[3],
                &c[4],
                &c[5],
                &c[6],
                &c[7],
            ],
            p,
        )
    }
}

lanes::wide! {
    /// [`PairCost::at`] over its columns, at `p` relative to its origin.
    fn pair_cost(columns: [&[f32]; 8], p: [f32; 3]) -> f64 = pair_cost_kernel
}

#[inline(always)]
fn pair_cost_kernel(columns: [&[f32]; 8], p: [f32; 3]) -> f64 {
    let [px, py, pz] = p;
    // Chunks of LANES in arrays of LANES, lanes summed apart: the loop runs in vector
    // registers (a loop over the whole slice leaves LLVM a scalar remainder, and summing into
    // `acc[i % LANES]` kept it scalar).
    let mut acc = [0.0f32; lanes::LANES];
    for i in (0..columns[0].len() / lanes::LANES).map(|c| c * lanes::LANES) {
        let lanes = |c: usize| lanes::lanes(columns[c], i);
        let (ax, ay, az, bx, by, bz) = (lanes(0), lanes(1), lanes(2), lanes(3), lanes(4), lanes(5));
        let (th, k) = (lanes(6), lanes(7));
        for l in 0..lanes::LANES {
            let (dx, dy, dz) = (px - ax[l], py - ay[l], pz - az[l]);
            let da = (dx * dx + dy * dy + dz * dz).sqrt();
            let (dx, dy, dz) = (px - bx[l], py - by[l], pz - bz[l]);
            let db = (dx * dx + dy * dy + dz * dz).sqrt();
            let (_, c) = lanes::sin_cos_f32(th[l] - k[l] * (db - da));
            acc[l] += 1.0 - c;
        }
    }
    acc.iter().map(|&v| f64::from(v)).sum()
}

/// The fit of a tag with split series, as the module describes it; `near`: the position of
/// the fit with separate offsets, the first start.
pub(super) fn fit(
    obs: &[Obs],
    s: &Search,
    near: Option<[f64; 3]>,
) -> Result<(Solution, Vec<Obs>), NoFix> {
    let (dims, sign) = (s.dims, s.sign);
    // The phases with each calibrated antenna's series in one group: what a fit is judged by.
    let joint: Vec<Obs> = obs
        .iter()
        .map(|o| Obs {
            group: o.joint,
            ..*o
        })
        .collect();
    // The grid's starts, each refined when its turn comes, computed only if `near` is not
    // taken.
    let grid = std::iter::once(()).flat_map(|()| {
        let coarse = PairCost::new(&pairs(obs, sign, COARSE.1));
        let fine = PairCost::new(&pairs(obs, sign, FINE.1));
        let starts = coarse_starts(s, &mut |p| coarse.at(p), STARTS);
        starts
            .into_iter()
            .map(move |c| refine(s, c, None, &mut |p| fine.at(p)))
    });
    let mut best: Option<(f64, (Solution, Vec<Obs>))> = None;
    for c in near.into_iter().chain(grid) {
        let q = join::search_box(obs, c, (dims, START_BOX_M, 0.04, 80), sign);
        let Ok(fit) = join_from(obs, q, s) else {
            continue;
        };
        let score = join::coherence(&joint, position(&fit.0 .0, s), sign);
        if best.as_ref().is_none_or(|b| score > b.0) {
            best = Some((score, fit));
        }
        if score >= COHERENT {
            break;
        }
    }
    let (score, fit) = best.ok_or(NoFix::InsufficientGeometry)?;
    if score >= COHERENT {
        return Ok(fit);
    }
    // No start was coherent: a wider box around the best fit.
    let q = join::search_box(
        obs,
        position(&fit.0 .0, s),
        (dims, WIDE_BOX_M, 0.05, 60),
        sign,
    );
    let (score, fit) = match join_from(obs, q, s) {
        Ok(wide) => match join::coherence(&joint, position(&wide.0 .0, s), sign) {
            w if w > score => (w, wide),
            _ => (score, fit),
        },
        Err(_) => (score, fit),
    };
    // Phases that no joining brings near agreement do not fix the tag: no estimate, not a
    // guess.
    if score < INCOHERENT {
        return Err(NoFix::InsufficientGeometry);
    }
    Ok(fit)
}

/// A fit on split series whose phases are less coherent than this at its best is no fix.
const INCOHERENT: f64 = 0.45;

/// Half-width of the box searched when no start gave a coherent fit (m).
const WIDE_BOX_M: f64 = 0.75;

/// A fit whose phases are at least this coherent ([`join::coherence`], calibrated antennas in
/// one group) is taken; below it the next start is tried, and the most coherent fit wins.
const COHERENT: f64 = 0.6;

/// From `start` (a coherent point of the series): 2.5 cm steps around it, the segments of each
/// series joined there and solved, then joined again from the fit while that merges more; then,
/// where antennas are calibrated, their series joined into one group the same way.
/// The fit, and the phases as joined for it.
fn join_from(obs: &[Obs], start: [f64; 3], s: &Search) -> Result<(Solution, Vec<Obs>), NoFix> {
    let q = join::search_box(obs, start, (s.dims, 0.05, 0.025, 400), s.sign);
    let (current, segments) = join::join(obs, q, s.sign);
    let fit = solve(Problem::new(&current, s.dims, s.z, s.sign, &q), s)?;
    let (mut current, mut fit) = rejoin(current, segments, fit, s);
    if current.iter().any(|o| o.joint != o.group) {
        for o in &mut current {
            o.group = o.joint;
        }
        // One more than there are, so that the first round runs even if it merges nothing.
        let segments = current.iter().map(|o| o.segment + 1).max().unwrap_or(0);
        (current, fit) = rejoin(current, segments + 1, fit, s);
    }
    Ok((fit, current))
}

/// Rounds of search (± 3σ along the weak axes), join and solve while joining merges segments
/// and the joined fit explains the phases about as well (a wrong join leaves whole turns in
/// the residuals).
fn rejoin(
    mut current: Vec<Obs>,
    mut segments: usize,
    mut fit: Solution,
    s: &Search,
) -> (Vec<Obs>, Solution) {
    for _ in 0..JOIN_ROUNDS {
        let q = join::search(&current, position(&fit.0, s), &fit.1, s.sign);
        let (joined, n) = join::join(&current, q, s.sign);
        if n >= segments {
            break;
        }
        match solve(Problem::new(&joined, s.dims, s.z, s.sign, &q), s) {
            Ok(better) if better.2 <= fit.2 * 1.5 + 0.02 => {
                fit = better;
                current = joined;
                segments = n;
            }
            _ => break,
        }
    }
    (current, fit)
}

/// Most rounds of search, join and solve.
const JOIN_ROUNDS: usize = 3;

#[cfg(test)]
mod tests {
    use super::super::locate3d;
    use super::*;
    use crate::synthetic;

    /// Passes at four heights, each cut into segments of five phases (5 cm of path), every
    /// segment shifted by a whole number of turns: what unwrapping leaves of sparse reads.
    fn short_segments(tag: [f64; 3], noise: f64, seed: u64, joint: bool) -> Vec<Obs> {
        let zs = [0.4, 0.9, 1.4, 1.9];
        let mut obs = synthetic::passes(tag, &zs, (0.7, 0.0), noise, seed);
        for (i, o) in obs.iter_mut().enumerate() {
            o.segment = i / 5;
            o.phase_rad += std::f64::consts::TAU * ((i / 5) % 3) as f64;
            if joint {
                o.joint = 0;
            }
        }
        obs
    }

    fn error(p: [f64; 3], tag: [f64; 3]) -> f64 {
        distance(p, tag)
    }

    #[test]
    fn a_noise_free_tag_in_short_segments_is_recovered_within_a_millimetre() {
        let tag = [0.3, 1.1, 1.0];
        for joint in [false, true] {
            let obs = short_segments(tag, 0.0, 1, joint);
            let fix = locate3d(&obs, 1.0, [0.0, 1.0], 3.0).expect("a fix");
            assert!(error(fix.position, tag) < 1e-3, "joint {joint}: {fix:?}");
        }
    }

    #[test]
    fn with_noise_joined_segments_stay_within_a_centimetre() {
        let tag = [0.3, 1.1, 1.0];
        for seed in 0..5 {
            let obs = short_segments(tag, 0.1, seed, true);
            let fix = locate3d(&obs, 1.0, [0.0, 1.0], 3.0).expect("a fix");
            assert!(error(fix.position, tag) < 0.01, "seed {seed}: {fix:?}");
        }
    }

    #[test]
    fn phases_no_joining_brings_together_are_no_fix() {
        // The short segments of a tag, each phase then replaced by an unrelated one: no
        // position explains them, and the fit says so rather than guess.
        let mut obs = short_segments([0.3, 1.1, 1.0], 0.0, 1, true);
        let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
        for o in &mut obs {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            o.phase_rad = (x % 10_000) as f64 / 10_000.0 * std::f64::consts::TAU;
        }
        assert_eq!(
            locate3d(&obs, 1.0, [0.0, 1.0], 3.0),
            Err(NoFix::InsufficientGeometry)
        );
    }

    #[test]
    fn the_vector_pair_cost_agrees_with_the_exact_one() {
        let mut obs = short_segments([0.3, 1.1, 1.0], 0.2, 3, false);
        obs.truncate(obs.len() - 3);
        let all = pairs(&obs, 1.0, 203);
        let fast = PairCost::new(&all);
        for p in [[0.3, 1.1, 1.0], [0.8, 2.0, 0.2], [-1.0, 0.5, 1.5]] {
            let exact: f64 = all
                .iter()
                .map(|q| {
                    let m = q.k * (distance(p, q.b) - distance(p, q.a));
                    1.0 - ((q.dphase - m) * q.scale).cos()
                })
                .sum();
            assert!(
                (fast.at(p) - exact).abs() < 1e-3,
                "{p:?}: {} {exact}",
                fast.at(p)
            );
        }
    }

    #[test]
    fn pairs_keep_consecutive_phases_of_one_series_only() {
        let obs = short_segments([0.3, 1.1, 1.0], 0.0, 1, false);
        let all = pairs(&obs, 1.0, usize::MAX);
        // 300 phases a height, four heights: 299 pairs each; none across heights.
        assert_eq!(all.len(), 4 * 299);
        assert!(all.iter().all(|p| p.a[2] == p.b[2]));
        assert_eq!(pairs(&obs, 1.0, 100).len(), 100);
    }
}
