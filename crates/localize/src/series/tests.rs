//! The series' unit tests.

use super::*;

#[test]
fn the_step_and_the_fold_agree_with_rem_euclid() {
    for period in [std::f64::consts::TAU, std::f64::consts::PI] {
        for k in -4000..4000 {
            let prev = f64::from(k) * 0.0731;
            for folded in [0.0, 0.3, 1.7, 3.1, period - 1e-12] {
                let want = (folded - prev + period / 2.0).rem_euclid(period) - period / 2.0;
                let got = step(folded, prev, period);
                // Equal, or both ends of the half-open range at a rounding boundary.
                let same = (got - want).abs() < 1e-12 || ((got - want).abs() - period).abs() < 1e-9;
                assert!(same, "{folded} {prev} {period}: {got} {want}");
                assert!((-period / 2.0..period / 2.0).contains(&got), "{got}");
            }
            let phase = f64::from(k) * 0.0137;
            assert_eq!(fold(phase, period), phase.rem_euclid(period), "{phase}");
        }
    }
}

#[test]
fn thinning_keeps_each_segments_ends_and_allocates_nothing_in_steady_state() {
    let mut s = Series::new(0.346, Ambiguity::None, 1_000);
    // 200 segments of 100 reads (a gap between each), thinned as a tag's bound would.
    let mut room = 0;
    for k in 0..200u64 {
        for i in 0..100u64 {
            s.push(k * 1_000_000 + i * 10, 0.01 * i as f64, [0.0; 3], 0.0);
        }
        if s.len() > 4096 {
            s.thin();
        }
        if k == 100 {
            room = s.capacity();
        }
    }
    assert!(s.len() <= 4096 + 100, "{}", s.len());
    assert_eq!(s.capacity(), room, "no growth once thinning has begun");
    // Every segment keeps its first and last read.
    for (k, seg) in s.segments().enumerate() {
        let first = k as u64 * 1_000_000;
        assert_eq!(seg.first().map(|x| x.t_us), Some(first));
        assert_eq!(seg.last().map(|x| x.t_us), Some(first + 990));
    }
    s.drop_segments(&(0..150).collect::<Vec<_>>());
    assert_eq!(s.segments().len(), 50);
    assert_eq!(s.segments().next().map(|g| g[0].t_us), Some(150_000_000));
    // Segments anywhere: the others keep their reads and order.
    s.drop_segments(&[1, 3]);
    let firsts: Vec<u64> = s.segments().take(4).map(|g| g[0].t_us).collect();
    assert_eq!(firsts, [150, 152, 154, 155].map(|k| k * 1_000_000));
    assert_eq!(s.segments().len(), 48);
    assert!(s
        .segments()
        .all(|g| g.last().map(|x| x.t_us % 1_000_000) == Some(990)));
}
use std::f64::consts::{PI, TAU};

const LAMBDA: f64 = 0.3276;

/// The reported phase of a tag at the origin from an antenna at `a`.
fn reported(a: Vec3, phi0: f64) -> f64 {
    (phi0 + 4.0 * PI * distance(a, [0.0; 3]) / LAMBDA).rem_euclid(TAU)
}

#[test]
fn unwrapping_recovers_the_distance_along_a_slow_path() {
    let mut s = Series::new(LAMBDA, Ambiguity::None, 1_000_000);
    // The antenna passes the tag 1 m away at 0.5 m/s, a read every 20 ms (1 cm).
    let path: Vec<Vec3> = (0..400)
        .map(|k| [-2.0 + 0.01 * k as f64, 1.0, 0.0])
        .collect();
    for (k, a) in path.iter().enumerate() {
        s.push(k as u64 * 20_000, reported(*a, 1.3), *a, 0.0);
    }
    assert_eq!(s.segments().len(), 1);
    assert_eq!(s.splits(), (0, 0));
    let seg = s.segments().next().expect("a segment");
    let d0 = distance(path[0], [0.0; 3]);
    for (smp, a) in seg.iter().zip(&path) {
        let d = distance(*a, [0.0; 3]);
        let from_phase = (smp.phase_rad - seg[0].phase_rad) * LAMBDA / (4.0 * PI);
        assert!(
            (from_phase - (d - d0)).abs() < 1e-9,
            "{from_phase} vs {}",
            d - d0
        );
    }
}

#[test]
fn a_move_of_a_quarter_wavelength_or_a_long_gap_starts_a_new_segment() {
    let mut s = Series::new(LAMBDA, Ambiguity::None, 100_000);
    s.push(0, 0.1, [0.0, 1.0, 0.0], 0.0);
    s.push(10_000, 0.2, [LAMBDA / 4.0 * 0.99, 1.0, 0.0], 0.0);
    s.push(20_000, 0.3, [LAMBDA / 4.0 * 1.99, 1.0, 0.0], 0.0);
    assert_eq!(s.segments().len(), 1);
    s.push(30_000, 0.4, [LAMBDA / 4.0 * 3.0, 1.0, 0.0], 0.0);
    assert_eq!(s.splits(), (1, 0));
    s.push(200_000, 0.5, [LAMBDA / 4.0 * 3.0, 1.0, 0.0], 0.0);
    assert_eq!(s.splits(), (1, 1));
    assert_eq!(
        s.segments().map(<[Sample]>::len).collect::<Vec<_>>(),
        vec![3, 1, 1]
    );
}

#[test]
fn reads_that_come_late_give_the_series_of_reads_in_time_order() {
    use rand::seq::SliceRandom;
    use rand::SeedableRng;
    // A pass with a long gap and a jump beyond λ/4 in it: three segments in time order.
    let mut reads: Vec<(u64, f64, Vec3)> = Vec::new();
    for k in 0..300u64 {
        let x = -1.5 + 0.01 * k as f64 + if k >= 200 { 0.2 } else { 0.0 };
        let t = k * 20_000 + if k >= 100 { 2_000_000 } else { 0 };
        let a = [x, 1.0, 0.0];
        reads.push((t, reported(a, 0.7), a));
    }
    let mut ordered = Series::new(LAMBDA, Ambiguity::None, 1_000_000);
    for &(t, phi, a) in &reads {
        ordered.push(t, phi, a, 0.0);
    }
    assert_eq!(ordered.segments().len(), 3);
    assert_eq!(ordered.splits(), (1, 1));
    for seed in 0..20 {
        // Blocks of up to 40 reads delivered in a shuffled order, as batches may be.
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut blocks: Vec<&[(u64, f64, Vec3)]> = reads.chunks(1 + seed as usize * 2).collect();
        blocks.shuffle(&mut rng);
        let mut late = Series::new(LAMBDA, Ambiguity::None, 1_000_000);
        for &(t, phi, a) in blocks.concat().iter() {
            late.push(t, phi, a, 0.0);
        }
        assert_eq!(late.splits(), ordered.splits(), "seed {seed}");
        let lens = |s: &Series| s.segments().map(<[Sample]>::len).collect::<Vec<_>>();
        assert_eq!(lens(&late), lens(&ordered), "seed {seed}");
        for (x, y) in late.samples().iter().zip(ordered.samples()) {
            // The same bits: two workers must agree to the last digit.
            assert_eq!(x, y, "seed {seed}");
        }
    }
}

#[test]
fn wrap_edges_unwrap_both_ways() {
    let mut s = Series::new(LAMBDA, Ambiguity::None, 1_000_000);
    let a = [0.0; 3];
    for (k, phi) in [6.2, 0.05, 6.25, 0.1, 3.3].iter().enumerate() {
        s.push(k as u64, *phi, a, 0.0);
    }
    let got: Vec<f64> = s.samples().iter().map(|x| x.phase_rad).collect();
    let want = [6.2, TAU + 0.05, 6.25, TAU + 0.1, 3.3];
    for (g, w) in got.iter().zip(want) {
        assert!((g - w).abs() < 1e-12, "{got:?}");
    }
}

#[test]
fn with_the_pi_ambiguity_random_flips_vanish_and_the_limit_halves() {
    let mut plain = Series::new(LAMBDA, Ambiguity::None, 1_000_000);
    let mut folded = Series::new(LAMBDA, Ambiguity::Pi, 1_000_000);
    assert!((folded.motion_limit_m() - LAMBDA / 8.0).abs() < 1e-15);
    for k in 0..200u64 {
        let a = [-1.0 + 0.005 * k as f64, 1.0, 0.0];
        let true_phase = reported(a, 0.4);
        // Every third read flipped by π.
        let flipped = if k % 3 == 0 {
            true_phase + PI
        } else {
            true_phase
        };
        plain.push(k * 10_000, true_phase, a, 0.0);
        folded.push(k * 10_000, flipped, a, 0.0);
    }
    let p = plain.segments().next().expect("a segment");
    let f = folded.segments().next().expect("a segment");
    assert_eq!(folded.segments().len(), 1);
    // Folded and unwrapped by π, the flipped series changes exactly as the true one.
    for (x, y) in p.iter().zip(f) {
        let dp = x.phase_rad - p[0].phase_rad;
        let df = y.phase_rad - f[0].phase_rad;
        assert!((dp - df).abs() < 1e-9, "{dp} vs {df}");
    }
}
