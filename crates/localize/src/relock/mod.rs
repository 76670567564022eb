//! Phase ReLock (\[A\] §III-A1), in 2D or 3D: the tag position and one phase offset per segment
//! that best explain the unwrapped phases, θ_i ≈ s·4π·d_i/λ_i + c_k, by Levenberg–Marquardt
//! (the `levenberg-marquardt` crate on `nalgebra`), started from the best point of a grid on
//! the side the antenna faces (the mirror image about a straight path explains the phases as
//! well): 50 cm on up to 32 of the phases (in two levels: 1 m, then 50 cm around the best),
//! then 10 cm on up to 100 within 60 cm of its best.
//! Where a series is split, its segments are joined (`split`, ours, with [`crate::join`]).

use std::borrow::Cow;

use nalgebra::DVector;

use crate::calibrate::Calibration;
use crate::estimator::{Locate, Tag, Takes, SIGN};
use crate::fix::{Fix, Fix3, NoFix, Obs};
use crate::geometry::Geometry;
use crate::ingest::Ingest;
use crate::{distance, join, lanes};

mod bins;
mod cost;
mod problem;
mod split;

use bins::{bin, BIN_ABOVE, BIN_M, SEPARATE_BIN_M};
use cost::segment_cost;
use problem::{reported, solve, Problem, Solution};

/// The start's coarse grid: step (m) and most phases looked at.
const COARSE: (f64, usize) = (0.5, 32);
/// The fine grid around the coarse best: step (m), most phases, and steps either side.
const FINE: (f64, usize) = (0.1, 100);
const FINE_HALF_STEPS: i32 = 6;

/// Up to about `max` of `obs` for the start's grids, evenly spread within each segment and at
/// least [`GRID_MIN_PER_SEGMENT`] of each segment taken (a segment's offset takes one of its
/// phases, so a lone phase tells the grid nothing): the longest segments first.
fn spread(obs: &[Obs], max: usize) -> Vec<Obs> {
    if obs.len() <= max {
        return obs.to_vec();
    }
    let segments = obs.iter().map(|o| o.segment + 1).max().unwrap_or(0);
    let mut by_segment: Vec<Vec<Obs>> = vec![Vec::new(); segments];
    for o in obs {
        by_segment[o.segment].push(*o);
    }
    by_segment.retain(|s| s.len() >= GRID_MIN_PER_SEGMENT);
    by_segment.sort_by_key(|s| std::cmp::Reverse(s.len()));
    let mut out = Vec::with_capacity(max + GRID_MIN_PER_SEGMENT);
    for seg in by_segment {
        if out.len() >= max {
            break;
        }
        let take = (seg.len() * max / obs.len()).clamp(GRID_MIN_PER_SEGMENT, seg.len());
        out.extend(seg.iter().step_by(seg.len().div_ceil(take)).copied());
    }
    out
}

/// Fewest phases of a segment the start's grids look at.
const GRID_MIN_PER_SEGMENT: usize = 3;

/// Where a fit searches: dimensions (2: at height `z`), phase sign, the side the antennas
/// face and the middle of their path, and the box (x, y, z).
struct Search {
    dims: usize,
    z: f64,
    sign: f64,
    facing: [f64; 2],
    mid: [f64; 2],
    lo: [f64; 3],
    hi: [f64; 3],
    /// A start instead of the grid (the tag's last fix, for a live update).
    hint: Option<[f64; 3]>,
}

impl Search {
    /// Whether the horizontal point `p` is on the side the antennas face (or on their path).
    fn faces(&self, p: [f64; 2]) -> bool {
        (p[0] - self.mid[0]) * self.facing[0] + (p[1] - self.mid[1]) * self.facing[1] >= 0.0
    }
}

/// The points of the grid of `step` over (`lo`, `hi`) on the facing side, each with its
/// `cost`.
fn grid(
    s: &Search,
    lo: [f64; 3],
    hi: [f64; 3],
    step: f64,
    cost: &mut dyn FnMut([f64; 3]) -> f64,
) -> Vec<(f64, [f64; 3])> {
    let steps = [0, 1, 2].map(|a| ((hi[a] - lo[a]) / step).ceil().max(0.0) as i64);
    let mut out = Vec::new();
    for i in 0..=steps[0] {
        for j in 0..=steps[1] {
            let (x, y) = (lo[0] + i as f64 * step, lo[1] + j as f64 * step);
            if !s.faces([x, y]) {
                continue;
            }
            for k in 0..=steps[2] {
                let p = [x, y, lo[2] + k as f64 * step];
                out.push((cost(p), p));
            }
        }
    }
    out
}

/// The fit of the phases `all` in `s` (binned ([`bin`]) where there are more than
/// [`BIN_ABOVE`]: at [`SEPARATE_BIN_M`], and at [`BIN_M`] for the joining): a coarse grid
/// (COARSE) of the per-segment cost over the box, a finer one (FINE) around its best point,
/// and Levenberg–Marquardt from there, each segment with its own offset; when a series is
/// split or calibrated antennas hold several series ([`join::joinable`]) and that fit leaves
/// σ above [`JOIN_ABOVE_SIGMA_M`], also [`split::fit`], which joins them and is taken unless
/// it explains the phases clearly worse. A fit outside the box in height (under the floor,
/// say) is the mirror image of the tag about the antennas' path, which the phases could not
/// tell from it: no fix.
fn fit<'a>(all: &'a [Obs], s: &Search) -> Result<(Solution, Cow<'a, [Obs]>), NoFix> {
    let binned = |width: f64| {
        if all.len() > BIN_ABOVE {
            Cow::Owned(bin(all, width))
        } else {
            Cow::Borrowed(all)
        }
    };
    let separate_obs = binned(SEPARATE_BIN_M);
    let obs: &[Obs] = &separate_obs;
    let inside = |h: &[f64; 3]| (0..s.dims).all(|a| h[a] >= s.lo[a] && h[a] <= s.hi[a]);
    let start = match s.hint.filter(inside) {
        Some(h) => [h[0], h[1], if s.dims == 3 { h[2] } else { s.z }],
        None => {
            let (coarse, fine) = (spread(obs, COARSE.1), spread(obs, FINE.1));
            let mut coarse_cost = segment_cost(&coarse, s.sign);
            let best = coarse_starts(s, &mut coarse_cost, 1);
            let best = best.first().copied().ok_or(NoFix::InsufficientGeometry)?;
            let mut fine_cost = segment_cost(&fine, s.sign);
            refine(s, best, Some(&mut coarse_cost), &mut fine_cost)
        }
    };
    // A fit outside the box in height is no fix.
    let in_box = |f: Result<Solution, NoFix>| {
        f.ok().filter(|f| {
            let q = position(&f.0, s);
            q[2] >= s.lo[2] && q[2] <= s.hi[2]
        })
    };
    let separate = in_box(solve(Problem::new(obs, s.dims, s.z, s.sign, &start), s));
    if !join::joinable(obs) {
        return separate
            .map(|f| (f, separate_obs.clone()))
            .ok_or(NoFix::InsufficientGeometry);
    }
    // Separate offsets that already pin the tag down are kept: joining adds nothing there but
    // risk, where the poses are not exact.
    if let Some(sep) = &separate {
        let worst = (0..s.dims)
            .map(|a| sep.1[(a, a)])
            .fold(0.0, f64::max)
            .sqrt();
        if worst <= JOIN_ABOVE_SIGMA_M {
            return Ok((sep.clone(), separate_obs.clone()));
        }
    }
    let near = separate.as_ref().map(|f| position(&f.0, s));
    // Joined segments must explain the phases about as well as separate offsets do: over a
    // pose track that drifts (odometry), one offset does not hold for long.
    let joined = split::fit(&binned(BIN_M), s, near)
        .ok()
        .and_then(|(f, o)| in_box(Ok(f)).map(|f| (f, o)));
    match (joined, separate) {
        (Some(joined), Some(separate)) if joined.0 .2 > separate.2 * 1.5 + 0.02 => {
            Ok((separate, separate_obs.clone()))
        }
        (Some((joined, o)), _) => Ok((joined, Cow::Owned(o))),
        // Separate offsets leave the tag loose (above), and no joined fit stands (its phases
        // incoherent, or it is the mirror image under the floor): the phases do not fix it.
        (None, _) => Err(NoFix::InsufficientGeometry),
    }
}

/// Series are joined only when the fit with separate offsets leaves σ above this (m) on some
/// axis.
const JOIN_ABOVE_SIGMA_M: f64 = 0.02;

/// The best points of the coarse grid (`coarse` cost), up to `starts` of them at least
/// 1.5 steps apart, best first; each is moved to the best of the fine grid around it by
/// [`refine`] when it is tried.
fn coarse_starts(
    s: &Search,
    coarse: &mut dyn FnMut([f64; 3]) -> f64,
    starts: usize,
) -> Vec<[f64; 3]> {
    if starts == 1 {
        // One start: the grid in two levels (twice the step, then the step around the best).
        let centre = [0, 1, 2].map(|a| (s.lo[a] + s.hi[a]) / 2.0);
        let half = [0, 1, 2].map(|a| ((s.hi[a] - s.lo[a]) / 2.0 / COARSE.0).ceil() as i32);
        let half = if s.dims == 2 {
            [half[0], half[1], 0]
        } else {
            half
        };
        let mut score = |p: [f64; 3]| {
            let inside = (0..s.dims).all(|a| p[a] >= s.lo[a] - 1e-9 && p[a] <= s.hi[a] + 1e-9);
            (s.faces([p[0], p[1]]) && inside).then(|| -coarse(p))
        };
        return join::best_in_box(centre, half, COARSE.0, COARSE_TOP, &mut score)
            .map(|b| b.1)
            .into_iter()
            .collect();
    }
    let mut points = grid(s, s.lo, s.hi, COARSE.0, coarse);
    points.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut chosen: Vec<[f64; 3]> = Vec::new();
    for (_, p) in points {
        if chosen.len() >= starts {
            break;
        }
        if chosen.iter().all(|q| distance(p, *q) > 1.5 * COARSE.0) {
            chosen.push(p);
        }
    }
    chosen
}

/// Points of the coarse grid's first level (twice its step) whose neighbours are searched
/// (16, with twice the neighbours to score, gave the same fixes on S1 and S2 in every RF mode).
const COARSE_TOP: usize = 8;

/// The best point (`fine` cost) of the fine grid around the coarse grid's point `c`, its
/// first level (twice the step) ranked by the `coarse` cost where it is given (the
/// separate-offsets cost on the coarse grid's phases ranks the fine grid's first level as
/// the fine cost does on S1 and S2; the split fit's phase-pair cost does not).
fn refine(
    s: &Search,
    c: [f64; 3],
    coarse: Option<&mut dyn FnMut([f64; 3]) -> f64>,
    fine: &mut dyn FnMut([f64; 3]) -> f64,
) -> [f64; 3] {
    let n = FINE_HALF_STEPS;
    let half = [n, n, if s.dims == 3 { n } else { 0 }];
    let allowed = |p: [f64; 3]| s.faces([p[0], p[1]]) && p[2] >= s.lo[2] && p[2] <= s.hi[2];
    let mut score = |p: [f64; 3]| allowed(p).then(|| -fine(p));
    let best = match coarse {
        Some(coarse) => {
            let mut rough = |p: [f64; 3]| allowed(p).then(|| -coarse(p));
            join::best_in_box_rough(c, half, FINE.0, FINE_TOP, &mut rough, &mut score)
        }
        None => join::best_in_box(c, half, FINE.0, FINE_TOP, &mut score),
    };
    best.map_or(c, |b| b.1)
}

/// Points of the fine grid's first level (twice its step) whose neighbours are searched.
const FINE_TOP: usize = 8;

/// The position of a solution's parameters.
fn position(p: &DVector<f64>, s: &Search) -> [f64; 3] {
    [p[0], p[1], if s.dims == 3 { p[2] } else { s.z }]
}

/// The antennas' box over `obs` (m).
fn bounds(obs: &[Obs]) -> ([f64; 3], [f64; 3]) {
    obs.iter()
        .fold(([f64::MAX; 3], [f64::MIN; 3]), |(lo, hi), o| {
            (
                [0, 1, 2].map(|a| lo[a].min(o.antenna[a])),
                [0, 1, 2].map(|a| hi[a].max(o.antenna[a])),
            )
        })
}

/// The position of a tag at height `z` from `obs` (phase sign `sign`: +1 or −1), searching
/// the side of the antennas' path that `facing` (a horizontal direction) points to, within
/// `reach_m` of it.
pub fn locate(
    obs: &[Obs],
    z: f64,
    sign: f64,
    facing: [f64; 2],
    reach_m: f64,
) -> Result<Fix, NoFix> {
    locate_from(obs, z, sign, facing, reach_m, None)
}

/// [`locate`], started from `hint` (a previous fix) instead of the grid when it is given and
/// inside the search box: a live update of a tag already located.
pub fn locate_from(
    obs: &[Obs],
    z: f64,
    sign: f64,
    facing: [f64; 2],
    reach_m: f64,
    hint: Option<[f64; 3]>,
) -> Result<Fix, NoFix> {
    let segments = obs.iter().map(|o| o.segment + 1).max().unwrap_or(0);
    let (min, max) = bounds(obs);
    let aperture = (max[0] - min[0]).hypot(max[1] - min[1]);
    let lambda = obs.first().map_or(0.33, |o| o.wavelength_m);
    if obs.len() < segments + 3 || aperture < lambda / 2.0 {
        return Err(NoFix::InsufficientGeometry);
    }
    let search = Search {
        dims: 2,
        z,
        sign,
        facing,
        mid: [(min[0] + max[0]) / 2.0, (min[1] + max[1]) / 2.0],
        lo: [min[0] - reach_m, min[1] - reach_m, z],
        hi: [max[0] + reach_m, max[1] + reach_m, z],
        hint,
    };
    let (solution, used) = fit(obs, &search)?;
    let (p, rms, cov) = (&solution.0, solution.2, reported(&solution, &used, &search));
    Ok(Fix {
        position: [p[0], p[1], z],
        covariance: [cov[(0, 0)], cov[(0, 1)], cov[(1, 0)], cov[(1, 1)]],
        rms_rad: rms,
    })
}

/// Antenna heights must span this much (m) for the height to be estimated.
pub const MIN_HEIGHT_SPAN_M: f64 = 0.2;

/// Phase ReLock in 3D: (x, y, z) and the offsets, for antennas at several heights (at
/// least [`MIN_HEIGHT_SPAN_M`] apart); the grid runs over the heights from the floor to a
/// metre above the highest antenna.
pub fn locate3d(obs: &[Obs], sign: f64, facing: [f64; 2], reach_m: f64) -> Result<Fix3, NoFix> {
    locate3d_from(obs, sign, facing, reach_m, None)
}

/// [`locate3d`], started from `hint` (a previous fix) instead of the grid when it is given
/// and inside the search box.
pub fn locate3d_from(
    obs: &[Obs],
    sign: f64,
    facing: [f64; 2],
    reach_m: f64,
    hint: Option<[f64; 3]>,
) -> Result<Fix3, NoFix> {
    let segments = obs.iter().map(|o| o.segment + 1).max().unwrap_or(0);
    let (min, max) = bounds(obs);
    let aperture = (max[0] - min[0]).hypot(max[1] - min[1]);
    let lambda = obs.first().map_or(0.33, |o| o.wavelength_m);
    if obs.len() < segments + 4 || aperture < lambda / 2.0 || max[2] - min[2] < MIN_HEIGHT_SPAN_M {
        return Err(NoFix::InsufficientGeometry);
    }
    let search = Search {
        dims: 3,
        z: 0.0,
        sign,
        facing,
        mid: [(min[0] + max[0]) / 2.0, (min[1] + max[1]) / 2.0],
        lo: [min[0] - reach_m, min[1] - reach_m, 0.0],
        hi: [max[0] + reach_m, max[1] + reach_m, max[2] + 1.0],
        hint,
    };
    let (solution, used) = fit(obs, &search)?;
    let (p, rms, cov) = (&solution.0, solution.2, reported(&solution, &used, &search));
    let mut covariance = [0.0; 9];
    for a in 0..3 {
        for b in 0..3 {
            covariance[3 * a + b] = cov[(a, b)];
        }
    }
    Ok(Fix3 {
        position: [p[0], p[1], p[2]],
        covariance,
        rms_rad: rms,
    })
}

/// Phase ReLock as the localizer runs it: in 3D where the antennas' heights span
/// [`MIN_HEIGHT_SPAN_M`], else in 2D at the tag height assumed; from the tag's last fix when
/// given one; calibrated from the reference tags.
#[derive(Clone, Copy, Debug)]
pub struct Relock;

impl Locate for Relock {
    fn name(&self) -> &'static str {
        "relock"
    }

    fn takes(&self) -> Takes {
        Takes::Phases
    }

    fn fits_height(&self, obs: &[Obs]) -> bool {
        let (lo, hi) = obs.iter().fold((f64::MAX, f64::MIN), |(lo, hi), o| {
            (lo.min(o.antenna[2]), hi.max(o.antenna[2]))
        });
        hi - lo >= MIN_HEIGHT_SPAN_M
    }

    fn warm_starts(&self) -> bool {
        true
    }

    fn calibration(&self, ingest: &Ingest, g: &Geometry) -> Calibration {
        if g.references.is_empty() {
            Calibration::default()
        } else {
            Calibration::from_references(ingest, &g.references, &|r: &str| g.sign_of(r))
        }
    }

    fn locate(&self, tag: &Tag<'_>) -> Result<Fix3, NoFix> {
        let (obs, facing, g) = (&tag.observed.obs, tag.observed.facing, tag.geometry);
        if self.fits_height(obs) {
            // Antennas at several heights: the height is estimated too.
            locate3d_from(obs, SIGN, facing, g.reach_m, tag.hint)
        } else {
            locate_from(obs, g.tag_height_m, SIGN, facing, g.reach_m, tag.hint).map(Fix::planar)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic;

    /// One pass at z = 0.5 of a tag at that height, phase offset 1.7.
    fn pass(tag: [f64; 2], noise: f64, seed: u64) -> Vec<Obs> {
        synthetic::passes([tag[0], tag[1], 0.5], &[0.5], (1.7, 0.0), noise, seed)
    }

    /// Passes at the heights `zs`, offsets 0.4 apart.
    fn passes(tag: [f64; 3], zs: &[f64], noise: f64, seed: u64) -> Vec<Obs> {
        synthetic::passes(tag, zs, (0.0, 0.4), noise, seed)
    }

    #[test]
    fn a_noise_free_tag_is_recovered_within_a_millimetre() {
        let tag = [1.2, 1.6];
        let fix = locate(&pass(tag, 0.0, 1), 0.5, 1.0, [0.0, 1.0], 3.0).expect("a fix");
        let err = (fix.position[0] - tag[0]).hypot(fix.position[1] - tag[1]);
        assert!(err < 1e-3, "{err} m: {fix:?}");
        // The mirror image on the other side, when the antenna faces that way.
        let mirror = locate(&pass([1.2, -1.6], 0.0, 1), 0.5, 1.0, [0.0, -1.0], 3.0).expect("a fix");
        assert!((mirror.position[1] + 1.6).abs() < 1e-3, "{mirror:?}");
    }

    #[test]
    fn a_start_from_the_last_fix_lands_on_the_grids_fix() {
        let tag = [0.8, 2.1];
        for seed in 0..5 {
            let obs = pass(tag, 0.1, seed);
            let cold = locate(&obs, 0.5, 1.0, [0.0, 1.0], 3.0).expect("a fix");
            // From 3 cm off (a fix a few reads old), in the same lobe: the same minimum.
            let hint = [cold.position[0] + 0.03, cold.position[1] - 0.02, 0.5];
            let warm = locate_from(&obs, 0.5, 1.0, [0.0, 1.0], 3.0, Some(hint)).expect("a fix");
            let d =
                (warm.position[0] - cold.position[0]).hypot(warm.position[1] - cold.position[1]);
            assert!(d < 1e-6, "seed {seed}: {d} m");
            // A hint outside the search box is not taken: the grid's fix.
            let far = locate_from(&obs, 0.5, 1.0, [0.0, 1.0], 3.0, Some([50.0, 50.0, 0.5]));
            assert_eq!(far.expect("a fix").position, cold.position, "seed {seed}");
        }
    }

    #[test]
    fn with_noise_the_error_stays_within_the_covariance() {
        let tag = [0.8, 2.1];
        let mut within = 0;
        for seed in 0..20 {
            let fix = locate(&pass(tag, 0.1, seed), 0.5, 1.0, [0.0, 1.0], 3.0).expect("a fix");
            let (ex, ey) = (fix.position[0] - tag[0], fix.position[1] - tag[1]);
            assert!(ex.hypot(ey) < 0.02, "seed {seed}: {} m", ex.hypot(ey));
            // Mahalanobis distance² of a 2D Gaussian error: ≤ 6 holds 95 % of the time.
            let [a, b, c, d] = fix.covariance;
            let det = a * d - b * c;
            let m2 = (d * ex * ex - (b + c) * ex * ey + a * ey * ey) / det;
            within += usize::from(m2 <= 6.0);
            assert!((fix.rms_rad - 0.1).abs() < 0.02, "{}", fix.rms_rad);
        }
        assert!(within >= 16, "{within} of 20 within the 95 % ellipse");
    }

    #[test]
    fn a_phase_error_smooth_along_the_pass_widens_the_covariance_to_hold_the_tag() {
        // Before the cluster-robust covariance: 12 (relock) and 9 (linear) of 20.
        let held = synthetic::held_under_a_smooth_error(&|obs| {
            locate(obs, 0.5, 1.0, [0.0, 1.0], 3.0).expect("a fix")
        });
        assert!(held >= 15, "{held} of 20 inside the 95 % ellipse");
    }

    #[test]
    fn a_phase_error_smooth_in_the_angle_read_from_stays_inside_the_95_percent_ellipse() {
        let held = synthetic::held_under_an_angle_error(
            &|obs| locate(obs, 0.5, 1.0, [0.0, 1.0], 3.0).expect("a fix"),
            40,
        );
        // With the cluster-robust covariance alone: 17 or 18 of 40.
        assert!(held >= 35, "{held} of 40 inside the 95 % ellipse");
    }

    #[test]
    fn in_3d_antennas_at_several_heights_recover_the_tag_height() {
        let tag = [0.9, 1.2, 1.3];
        let zs = [0.4, 0.9, 1.4, 1.9];
        let fix = locate3d(&passes(tag, &zs, 0.0, 1), 1.0, [0.0, 1.0], 3.0).expect("a fix");
        let err = (0..3)
            .map(|a| (fix.position[a] - tag[a]).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(err < 1e-3, "{err} m: {fix:?}");
        // With noise: within 2 cm in every seed, the covariance's diagonal positive.
        for seed in 0..5 {
            let fix = locate3d(&passes(tag, &zs, 0.1, seed), 1.0, [0.0, 1.0], 3.0).expect("fix");
            let err = (0..3)
                .map(|a| (fix.position[a] - tag[a]).powi(2))
                .sum::<f64>()
                .sqrt();
            assert!(err < 0.02, "seed {seed}: {err} m");
            assert!(fix.covariance[0] > 0.0 && fix.covariance[4] > 0.0 && fix.covariance[8] > 0.0);
        }
        // One height cannot tell the tag's height.
        assert_eq!(
            locate3d(&passes(tag, &[0.9], 0.0, 1), 1.0, [0.0, 1.0], 3.0),
            Err(NoFix::InsufficientGeometry)
        );
    }

    #[test]
    fn too_little_geometry_is_said_not_guessed() {
        let mut short = pass([1.0, 1.0], 0.0, 1);
        short.truncate(10); // 9 cm of path: under half a wavelength
        assert_eq!(
            locate(&short, 0.5, 1.0, [0.0, 1.0], 3.0),
            Err(NoFix::InsufficientGeometry)
        );
        assert_eq!(
            locate(&[], 0.5, 1.0, [0.0, 1.0], 3.0),
            Err(NoFix::InsufficientGeometry)
        );
    }
}
