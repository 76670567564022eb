use super::*;
use crate::synthetic;

/// One pass at z = 0.5 of a tag 1.5 m off the path, cut into segments of 30 phases, each
/// shifted by a different whole number of turns: one group.
fn split_pass(tag: [f64; 3]) -> Vec<Obs> {
    let mut obs = synthetic::passes(tag, &[0.5], (1.0, 0.0), 0.0, 1);
    for (i, o) in obs.iter_mut().enumerate() {
        o.segment = i / 30;
        o.phase_rad += std::f64::consts::TAU * ((i / 30) % 4) as f64;
    }
    obs
}

#[test]
fn the_vector_evaluator_agrees_with_the_exact_coherence() {
    // Groups of uneven sizes (padding), two periods, phases far from zero.
    let tag = [0.4, 1.5, 0.5];
    let mut obs = split_pass(tag);
    for (i, o) in obs.iter_mut().enumerate() {
        o.group = i % 3;
        o.phase_rad += 0.3 * (i as f64).sin() + 400.0;
        if o.group == 2 {
            o.period_rad = std::f64::consts::PI;
        }
    }
    obs.truncate(obs.len() - 5);
    let exact = |p: [f64; 3]| {
        let mut sums = [(0.0f64, 0.0f64); 3];
        for o in &obs {
            let r = (o.phase_rad - model(o, p, 1.0)) * std::f64::consts::TAU / o.period_rad;
            sums[o.group].0 += r.cos();
            sums[o.group].1 += r.sin();
        }
        sums.iter().map(|(a, b)| a.hypot(*b)).sum::<f64>() / obs.len() as f64
    };
    for p in [tag, [0.5, 1.2, 0.7], [-2.0, 3.0, 1.0]] {
        let fast = coherence(&obs, p, 1.0);
        assert!((fast - exact(p)).abs() < 1e-4, "{p:?}: {fast} {}", exact(p));
    }
}

#[test]
fn the_two_level_box_finds_a_peak_between_its_coarse_points() {
    // A peak at an odd step (not on the first level's grid of twice the step), and a
    // higher one in a region the score leaves out.
    let peak = [0.03, -0.05, 0.07];
    let mut score = |p: [f64; 3]| {
        (p[0] < 0.15).then(|| -((0..3).map(|a| (p[a] - peak[a]).powi(2)).sum::<f64>()))
    };
    let (_, best) = best_in_box([0.0; 3], [8, 8, 8], 0.01, 4, &mut score).expect("a point");
    for a in 0..3 {
        assert!((best[a] - peak[a]).abs() < 1e-9, "{best:?}");
    }
    // A flat axis (half 0) stays at the centre's coordinate.
    let (_, flat) = best_in_box([0.0, 0.0, 0.5], [8, 8, 0], 0.01, 4, &mut score).unwrap();
    assert_eq!(flat[2], 0.5);
    // Nothing to consider: no point.
    assert!(best_in_box([0.0; 3], [4, 4, 4], 0.01, 4, &mut |_| None).is_none());
}

#[test]
fn a_rough_first_level_picks_the_points_the_exact_score_then_decides_among() {
    // The exact score peaks at an odd step; the rough one agrees near the peak but ranks
    // a far point (the box's corner) above everything: the corner's rough score must not
    // stand for the point, and the exact peak is still found from the other top points.
    let peak = [0.03, -0.05, 0.07];
    let exact = |p: [f64; 3]| -((0..3).map(|a| (p[a] - peak[a]).powi(2)).sum::<f64>());
    let corner = |p: [f64; 3]| p.iter().all(|&x| x < -0.07);
    let mut rough = |p: [f64; 3]| Some(if corner(p) { 1.0 } else { exact(p) });
    let mut score = |p: [f64; 3]| Some(exact(p));
    let (v, best) =
        best_in_box_rough([0.0; 3], [8, 8, 8], 0.01, 4, &mut rough, &mut score).unwrap();
    for a in 0..3 {
        assert!((best[a] - peak[a]).abs() < 1e-9, "{best:?}");
    }
    assert_eq!(v, exact(best), "the value is the exact score");
}

#[test]
fn segments_of_one_group_are_joined_at_the_tag() {
    let tag = [0.4, 1.5, 0.5];
    let obs = split_pass(tag);
    assert!(has_splits(&obs));
    let (joined, segments) = join(&obs, tag, 1.0);
    assert_eq!(segments, 1);
    // Joined, the phases are one unwrapped series again: every step under λ/4's phase.
    for w in joined.windows(2) {
        assert!((w[1].phase_rad - w[0].phase_rad).abs() < std::f64::consts::PI);
    }
    assert!(!has_splits(&joined) && !joinable(&joined));
    // Two series of one joint group (calibrated antennas) are joinable though unsplit.
    let two: Vec<Obs> = joined
        .iter()
        .enumerate()
        .map(|(i, o)| Obs {
            group: i % 2,
            segment: i % 2,
            joint: 0,
            ..*o
        })
        .collect();
    assert!(!has_splits(&two) && joinable(&two));
}

#[test]
fn a_segment_that_disagrees_is_left_alone() {
    let tag = [0.4, 1.5, 0.5];
    let mut obs = split_pass(tag);
    // Segment 3 gets half a turn more: it cannot share the group's offset.
    for o in obs.iter_mut().filter(|o| o.segment == 3) {
        o.phase_rad += std::f64::consts::PI;
    }
    let (joined, segments) = join(&obs, tag, 1.0);
    assert_eq!(segments, 2, "the group and the odd segment");
    let odd = joined
        .iter()
        .find(|o| o.antenna == obs[95].antenna)
        .unwrap();
    assert!(joined.iter().filter(|o| o.segment == odd.segment).count() == 30);
}

#[test]
fn the_search_finds_the_coherent_point_along_the_weak_axis() {
    let tag = [0.4, 1.5, 0.5];
    let obs = split_pass(tag);
    // A start 12 cm off along y, with a covariance that is weak along y only.
    let start = [0.4, 1.62, 0.5];
    let cov = DMatrix::from_row_slice(2, 2, &[1e-6, 0.0, 0.0, 0.01]);
    let p = search(&obs, start, &cov, 1.0);
    assert!((p[1] - tag[1]).abs() < SEARCH_MIN_STEP_M, "{p:?}");
    assert_eq!(p[0], start[0]);
    // Phases in the period π (the π ambiguity) are as coherent.
    let folded: Vec<Obs> = obs
        .iter()
        .map(|o| Obs {
            phase_rad: o.phase_rad.rem_euclid(std::f64::consts::PI),
            period_rad: std::f64::consts::PI,
            ..*o
        })
        .collect();
    let p = search(&folded, start, &cov, 1.0);
    assert!((p[1] - tag[1]).abs() < SEARCH_MIN_STEP_M, "{p:?}");
}
