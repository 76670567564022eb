//! `loci3d`'s unit tests.

use super::*;
use crate::synthetic;
use nalgebra::Matrix3;

/// Passes at `heights`, phase offsets 0.3 apart.
fn pass(tag: [f64; 3], heights: &[f64], noise: f64, seed: u64) -> Vec<Obs> {
    synthetic::passes(tag, heights, (0.0, 0.3), noise, seed)
}

const HEIGHTS: [f64; 4] = [0.3, 0.6, 0.9, 1.2];

fn err(fix: &Fix3, tag: [f64; 3]) -> f64 {
    (0..3)
        .map(|k| (fix.position[k] - tag[k]).powi(2))
        .sum::<f64>()
        .sqrt()
}

#[test]
fn a_noise_free_tag_is_recovered_within_a_millimetre_in_3d() {
    for tag in [[0.8f64, 1.5, 0.75], [1.234, -1.2, 1.4], [0.3, 0.9, 0.1]] {
        let facing = [0.0, tag[1].signum()];
        let fix = locate(&pass(tag, &HEIGHTS, 0.0, 1), 1.0, facing).expect("a fix");
        assert!(err(&fix, tag) < 1e-3, "{tag:?}: {fix:?}");
    }
    // Two heights are enough.
    let tag = [0.5, 1.3, 0.9];
    let fix = locate(&pass(tag, &[0.4, 1.1], 0.0, 1), 1.0, [0.0, 1.0]).expect("a fix");
    assert!(err(&fix, tag) < 1e-3, "{fix:?}");
    assert!(fix.covariance[8] > 0.0, "the height is estimated: {fix:?}");
}

#[test]
fn with_noise_the_error_stays_within_the_covariance() {
    let tag = [0.8, 1.5, 0.75];
    let mut within = 0;
    for seed in 0..20 {
        let fix = locate(&pass(tag, &HEIGHTS, 0.1, seed), 1.0, [0.0, 1.0]).expect("a fix");
        assert!(err(&fix, tag) < 0.05, "seed {seed}: {} m", err(&fix, tag));
        // Mahalanobis distance² of a 3D Gaussian error: ≤ 7.81 holds 95 % of the time.
        let c = Matrix3::from_row_slice(&fix.covariance);
        let e = nalgebra::Vector3::from(fix.position) - nalgebra::Vector3::from(tag);
        let m2 = (e.transpose() * c.try_inverse().expect("invertible") * e)[0];
        within += usize::from(m2 <= 7.81);
    }
    assert!(within >= 16, "{within} of 20 within the 95 % ellipsoid");
}

#[test]
fn one_height_or_too_little_is_insufficient_geometry() {
    let insufficient = Err(NoFix::InsufficientGeometry);
    let tag = [0.8, 1.5, 0.75];
    // Two passes at one height: the circles cannot fix z.
    assert_eq!(
        locate(&pass(tag, &[0.5, 0.5], 0.0, 1), 1.0, [0.0, 1.0]),
        insufficient
    );
    assert_eq!(
        locate(&pass(tag, &[0.5], 0.0, 1), 1.0, [0.0, 1.0]),
        insufficient
    );
    assert_eq!(locate(&[], 1.0, [0.0, 1.0]), insufficient);
    // Two heights but one pass too short for its circle.
    let mut obs = pass(tag, &[0.3, 1.2], 0.0, 1);
    obs.retain(|o| o.segment == 0 || o.antenna[0] < -0.95);
    assert_eq!(locate(&obs, 1.0, [0.0, 1.0]), insufficient);
}

#[test]
fn a_phase_error_smooth_in_the_direction_read_from_stays_inside_the_95_percent_ellipsoid() {
    let tag = [0.8, 1.5, 0.75];
    let held = synthetic::held_in_3d_under_an_angle_error(
        &|obs| locate(obs, 1.0, [0.0, 1.0]).ok(),
        tag,
        &HEIGHTS,
        40,
    );
    // 35 of 40 at the time of writing; 2 with the covariance before (the circles' radii
    // only, scaled by the reduced χ², no cross terms).
    assert!(held >= 33, "{held} of 40 inside the 95 % ellipsoid");
}

#[test]
fn circles_that_do_not_meet_are_insufficient_geometry_not_a_fix_on_the_path() {
    // Radii 0.5 m at heights 1.6 m apart: the sum is least on the path line itself, where its
    // slope across the path vanishes; the solver stops there, a hair either side by rounding.
    for (gap, r) in [(1.6, 0.5), (1.2, 0.3), (2.0, 0.9), (0.9, 0.2)] {
        let loci = [
            Locus {
                y: 0.25,
                z: 0.4,
                r,
                sigma_r: 0.01,
            },
            Locus {
                y: 0.25,
                z: 0.4 + gap,
                r,
                sigma_r: 0.02,
            },
        ];
        assert!(intersect(&loci).is_err(), "{gap} m apart, radius {r} m");
    }
}
