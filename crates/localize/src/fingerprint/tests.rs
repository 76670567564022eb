//! `fingerprint`'s unit tests.

use super::*;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

const LAMBDA: f64 = 0.3463;

/// Readings of a tag at `tag` from antennas at `heights` (one track each) passing along
/// y = 0, x from −0.995 m to 2.995 m in 1 cm steps (symmetric about x = 1); phase offset
/// `offset`.
fn reads(tag: [f64; 3], heights: &[f64], offset: f64, rng: &mut impl rand::Rng) -> Vec<Reading> {
    let noise = Normal::new(0.0, 0.1).expect("valid σ");
    let noisy = offset.is_nan();
    let mut out = Vec::new();
    for (track, &az) in heights.iter().enumerate() {
        for k in 0..400 {
            let a = [-0.995 + 0.01 * f64::from(k), 0.0, az];
            let d = (0..3).map(|j| (tag[j] - a[j]).powi(2)).sum::<f64>().sqrt();
            let (c, e) = if noisy {
                (0.4, noise.sample(rng))
            } else {
                (offset, 0.0)
            };
            out.push(Reading {
                track,
                segment: 0,
                antenna: a,
                value: c + 4.0 * std::f64::consts::PI * d / LAMBDA + e,
            });
        }
    }
    out
}

fn quiet(tag: [f64; 3], heights: &[f64], offset: f64) -> Vec<Reading> {
    reads(
        tag,
        heights,
        offset,
        &mut rand_chacha::ChaCha8Rng::seed_from_u64(0),
    )
}

fn err(p: [f64; 3], tag: [f64; 3]) -> f64 {
    (0..3).map(|k| (p[k] - tag[k]).powi(2)).sum::<f64>().sqrt()
}

#[test]
fn a_target_read_like_a_reference_is_placed_on_it() {
    let h = [0.5, 1.1];
    let spots = [
        [1.0, 1.5, 0.7],
        [0.6, 1.2, 0.5],
        [1.4, 1.8, 0.9],
        [0.2, 1.0, 0.3],
        [2.0, 2.0, 1.2],
    ];
    let refs: Vec<_> = spots.iter().map(|&p| (p, quiet(p, &h, 0.0))).collect();
    // Another phase offset, and a whole turn, change nothing.
    let target = quiet([1.0, 1.5, 0.7], &h, 2.0 + std::f64::consts::TAU);
    let fix = locate(&target, &refs, &[]).expect("a fix");
    assert!(err(fix.position, [1.0, 1.5, 0.7]) < 1e-3, "{fix:?}");
}

#[test]
fn a_target_amid_symmetric_references_is_placed_at_their_centre_within_a_millimetre() {
    // The pass is symmetric about x = 1 and the antenna at z = 0.5: the four references
    // around the target resemble it equally; the far ones are not chosen.
    let tag = [1.0, 1.5, 0.5];
    let spots = [
        [0.9, 1.5, 0.5],
        [1.1, 1.5, 0.5],
        [1.0, 1.5, 0.4],
        [1.0, 1.5, 0.6],
        [2.5, 2.5, 0.5],
        [-0.5, 1.0, 0.5],
    ];
    let refs: Vec<_> = spots.iter().map(|&p| (p, quiet(p, &[0.5], 0.3))).collect();
    let fix = locate(&quiet(tag, &[0.5], 1.1), &refs, &[]).expect("a fix");
    assert!(err(fix.position, tag) < 1e-3, "{fix:?}");
    assert!(
        fix.covariance[0] > 0.0 && fix.covariance[8] > 0.0,
        "{fix:?}"
    );
}

#[test]
fn with_noise_the_estimate_stays_among_the_nearest_references() {
    // A 20 cm grid of references; the estimate is a weighted mean of the four chosen, so
    // it is within the 4th-nearest reference's distance whenever those are the nearest.
    let h = [0.5, 1.1];
    let tag = [1.0, 1.55, 0.65];
    let mut spots = Vec::new();
    for x in [0.7, 0.9, 1.1, 1.3] {
        for y in [1.3, 1.5, 1.7] {
            for z in [0.4, 0.6, 0.8] {
                spots.push([x, y, z]);
            }
        }
    }
    let mut dist: Vec<f64> = spots.iter().map(|&p| err(p, tag)).collect();
    dist.sort_by(f64::total_cmp);
    let r4 = dist[K - 1];
    let mut within = 0;
    for seed in 0..20 {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let refs: Vec<_> = spots
            .iter()
            .map(|&p| (p, reads(p, &h, f64::NAN, &mut rng)))
            .collect();
        let fix = locate(&reads(tag, &h, f64::NAN, &mut rng), &refs, &[]).expect("a fix");
        within += usize::from(err(fix.position, tag) <= r4);
    }
    assert!(within >= 16, "{within} of 20 within {r4} m");
}

#[test]
fn too_few_references_or_common_poses_is_insufficient_geometry() {
    let insufficient = Err(NoFix::InsufficientGeometry);
    let tag = [1.0, 1.5, 0.5];
    let spots = [
        [0.9, 1.5, 0.5],
        [1.1, 1.5, 0.5],
        [1.0, 1.5, 0.4],
        [1.0, 1.5, 0.6],
    ];
    let refs: Vec<_> = spots.iter().map(|&p| (p, quiet(p, &[0.5], 0.0))).collect();
    assert_eq!(
        locate(&quiet(tag, &[0.5], 0.0), &refs[..3], &[]),
        insufficient
    );
    assert_eq!(locate(&quiet(tag, &[0.5], 0.0), &[], &[]), insufficient);
    assert_eq!(locate(&[], &refs, &[]), insufficient);
    // Read by another antenna than the references: no common poses.
    let mut other = quiet(tag, &[0.5], 0.0);
    other.iter_mut().for_each(|r| r.track = 7);
    assert_eq!(locate(&other, &refs, &[]), insufficient);
    // Sharing only 19 cells (38 readings at 1 cm) with each reference.
    let mut few = quiet(tag, &[0.5], 0.0);
    few.truncate(38);
    assert_eq!(locate(&few, &refs, &[]), insufficient);
}

/// Readings as [`reads`] gives them with σ 0.1 rad of noise, plus `pattern` of the unit
/// direction from the antenna to the tag (an antenna's phase pattern, the same for every tag).
fn patterned(
    tag: [f64; 3],
    heights: &[f64],
    pattern: &dyn Fn([f64; 3]) -> f64,
    rng: &mut impl rand::Rng,
) -> Vec<Reading> {
    let mut out = reads(tag, heights, f64::NAN, rng);
    for r in &mut out {
        let v = [0, 1, 2].map(|k| tag[k] - r.antenna[k]);
        let d = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        r.value += pattern(v.map(|x| x / d));
    }
    out
}

/// Whether `p` lies inside the 95 % ellipsoid of `covariance` about `fix`.
fn inside(covariance: &[f64; 9], fix: [f64; 3], p: [f64; 3]) -> bool {
    let c = nalgebra::Matrix3::from_row_slice(covariance);
    let e = nalgebra::Vector3::from(fix) - nalgebra::Vector3::from(p);
    c.try_inverse()
        .is_some_and(|inv| (e.transpose() * inv * e)[0] <= 7.815)
}

#[test]
fn the_95_percent_ellipsoid_holds_the_tag_where_the_references_spread_does_not() {
    // In each seed 36 references and a target, all at random places in one box (the target
    // placed like a reference, whose errors then tell its own), read with σ 0.1 rad of noise
    // and 0.3 rad of an antenna pattern (four cosines of the direction turning over 30–80°).
    use rand::Rng;
    let h = [0.5, 1.1];
    let (mut held, mut spread_held, seeds) = (0, 0, 40);
    for seed in 0..seeds {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(100 + seed);
        let terms: Vec<([f64; 3], f64, f64)> = (0..4)
            .map(|_| {
                let axis = [0, 1, 2].map(|_| rng.gen_range(-1.0..1.0));
                let norm = axis.iter().map(|x| x * x).sum::<f64>().sqrt();
                let turn = rng.gen_range(30.0_f64..80.0).to_radians();
                let phase = rng.gen_range(0.0..std::f64::consts::TAU);
                (axis.map(|x| x / norm), std::f64::consts::TAU / turn, phase)
            })
            .collect();
        let pattern = |u: [f64; 3]| {
            let each = |(a, w, p): &([f64; 3], f64, f64)| {
                (w * (a[0] * u[0] + a[1] * u[1] + a[2] * u[2]) + p).cos()
            };
            0.3 * 0.5_f64.sqrt() * terms.iter().map(each).sum::<f64>()
        };
        let mut place = || {
            [
                rng.gen_range(0.6..1.4),
                rng.gen_range(1.2..1.8),
                rng.gen_range(0.3..0.9),
            ]
        };
        let spots: Vec<[f64; 3]> = (0..36).map(|_| place()).collect();
        let tag = place();
        let refs: Vec<_> = spots
            .iter()
            .map(|&p| (p, patterned(p, &h, &pattern, &mut rng)))
            .collect();
        let target = patterned(tag, &h, &pattern, &mut rng);
        let fix = locate(&target, &refs, &[]).expect("a fix");
        held += usize::from(inside(&fix.covariance, fix.position, tag));
        // The covariance before: the spread of the k references about the estimate.
        let cells_of: Vec<_> = refs.iter().map(|(p, r)| (*p, cells(r))).collect();
        let (_, spread, _) = nearest(&cells(&target), &cells_of, None).expect("a fix");
        spread_held += usize::from(inside(&spread, fix.position, tag));
    }
    // 40 and 22 of 40 at the time of writing.
    assert!(held >= 36, "{held} of {seeds} inside the 95 % ellipsoid");
    assert!(
        spread_held <= 28,
        "{spread_held} of {seeds} inside the spread's"
    );
}

#[test]
fn references_in_one_plane_give_a_positive_definite_covariance_with_its_floor_across() {
    // Every reference at y = 1.5 (a banner): their errors have no y part, and the floor
    // keeps the 3D covariance invertible, its height variance that of the references' errors.
    let h = [0.5, 1.1];
    let mut spots = Vec::new();
    for x in [0.7, 0.9, 1.1, 1.3] {
        for z in [0.3, 0.5, 0.7, 0.9] {
            spots.push([x, 1.5, z]);
        }
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let refs: Vec<_> = spots
        .iter()
        .map(|&p| (p, reads(p, &h, f64::NAN, &mut rng)))
        .collect();
    let fix = locate(&reads([1.0, 1.5, 0.6], &h, f64::NAN, &mut rng), &refs, &[]).expect("a fix");
    let c = nalgebra::Matrix3::from_row_slice(&fix.covariance);
    let floor = covariance::FLOOR_M * covariance::FLOOR_M;
    assert!(c.try_inverse().is_some(), "{c}");
    assert!((c[(1, 1)] - floor).abs() < 1e-9, "{c}");
    assert!(c[(2, 2)] > floor, "{c}");
}
