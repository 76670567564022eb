//! The filter's unit tests.

use super::synth::{error, run, LAMBDA};
use super::*;

#[test]
fn two_metres_at_867_mhz_take_twelve_filters() {
    // [M]'s own check (§IV); its printed n_max = ρ_max·λ/2 would give 0.35.
    assert_eq!(hypotheses(2.0, LAMBDA, TAU), 12);
    assert_eq!(hypotheses(2.0, LAMBDA, PI), 24);
}

#[test]
fn the_prediction_jacobians_match_finite_differences() {
    let xi = V5::new(1.3, 0.7, 0.2, -0.4, 2.1);
    let (u, om) = (0.03, -0.05);
    let (_, f, g) = predict(&xi, u, om);
    let h = 1e-6;
    for i in 0..5 {
        let mut a = xi;
        let mut b = xi;
        a[i] += h;
        b[i] -= h;
        let diff = (predict(&a, u, om).0 - predict(&b, u, om).0) / (2.0 * h);
        for r in 0..5 {
            assert!(
                (diff[r] - f[(r, i)]).abs() < 1e-6,
                "F[{r},{i}]: {diff} vs {f}"
            );
        }
    }
    let du = (predict(&xi, u + h, om).0 - predict(&xi, u - h, om).0) / (2.0 * h);
    let dw = (predict(&xi, u, om + h).0 - predict(&xi, u, om - h).0) / (2.0 * h);
    for r in 0..5 {
        assert!((du[r] - g[(r, 0)]).abs() < 1e-6 && (dw[r] - g[(r, 1)]).abs() < 1e-6);
    }
    // The tag stays put: its position from the predicted state is the same.
    let tag = |x: &V5| {
        [
            x[2] + x[0] * (x[4] - x[1]).cos(),
            x[3] + x[0] * (x[4] - x[1]).sin(),
        ]
    };
    let (next, _, _) = predict(&xi, u, om);
    let (t0, t1) = (tag(&xi), tag(&next));
    assert!((t0[0] - t1[0]).hypot(t0[1] - t1[1]) < 1e-12);
}

#[test]
fn a_noise_free_tag_is_recovered_within_a_millimetre() {
    // Exact odometry, told so: the pose is known, and only (ρ, β) are estimated.
    let s = Settings {
        k_r: 0.0,
        k_l: 0.0,
        ..Settings::default()
    };
    for (seed, tag, antenna_z) in [
        (1, [3.0, 2.0, 0.5], 0.5),
        (2, [-1.0, 4.0, 0.5], 0.5),
        (3, [2.0, -2.5, 0.8], 0.5),
    ] {
        let start = [tag[0] - 1.5, tag[1] + 0.3];
        let obs = run(tag, start, 0.4, antenna_z, 3000, 0.0, 0.0, seed);
        let fix = locate(&obs, tag[2], -1.0, None, &s).expect("a fix");
        let (err, _) = error(&fix, tag);
        assert!(err < 1e-3, "seed {seed}: {err} m, {fix:?}");
        assert!(fix.rms_rad < 1e-3, "{fix:?}");
    }
    // With Impinj's π ambiguity: every other phase reported π off, known modulo π.
    let tag = [3.0, 2.0, 0.5];
    let mut obs = run(tag, [1.5, 2.3], 0.4, 0.5, 3000, 0.0, 0.0, 1);
    for (k, o) in obs.iter_mut().enumerate() {
        o.phase_rad = (o.phase_rad + PI * (k % 2) as f64).rem_euclid(TAU);
        o.period_rad = PI;
    }
    let fix = locate(&obs, tag[2], -1.0, None, &s).expect("a fix");
    assert!(error(&fix, tag).0 < 1e-3, "{fix:?}");
}

#[test]
fn with_phase_noise_the_error_stays_within_the_covariance() {
    // σ_φ = 0.2 rad as in [M]'s S3, the poses exact (and the filter told so).
    let s = Settings {
        k_r: 0.0,
        k_l: 0.0,
        ..Settings::default()
    };
    let tag = [1.0, 1.0, 0.5];
    let mut within = 0;
    for seed in 0..20 {
        let obs = run(tag, [-0.5, 1.2], 0.0, 0.5, 3000, 0.2, 0.0, 100 + seed);
        let fix = locate(&obs, tag[2], -1.0, None, &s).expect("a fix");
        let (err, m2) = error(&fix, tag);
        assert!(err < 0.01, "seed {seed}: {err} m");
        within += usize::from(m2 <= 6.0);
        assert!((fix.rms_rad - 0.2).abs() < 0.02, "{}", fix.rms_rad);
    }
    assert!(within >= 16, "{within} of 20 within the 95 % ellipse");
}

#[test]
fn under_an_angle_error_the_error_stays_within_the_covariance() {
    // A phase error smooth in the direction the tag is read from, 0.3 rad RMS as a tag's own
    // pattern on hardware, drawn as the covariance models it (a Gaussian process over the
    // angle, length 12°: 16 cosines with frequencies from its spectrum), on top of 0.05 rad
    // of noise, the poses exact: 18 of 20 hold, the mean Mahalanobis distance² is 2.6 (2 for a
    // true covariance). The filter alone takes its phases as independent and holds none.
    use rand::{Rng, SeedableRng};
    use rand_distr::{Distribution, Normal};
    let s = Settings {
        k_r: 0.0,
        k_l: 0.0,
        ..Settings::default()
    };
    let tag = [1.0, 1.0, 0.5];
    let spectrum = Normal::new(0.0, 1.0 / crate::robust::SMOOTH_ERROR_RAD).expect("a positive σ");
    let mut m2 = Vec::new();
    for seed in 0..20 {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(500 + seed);
        let terms: Vec<(f64, f64)> = (0..16)
            .map(|_| (spectrum.sample(&mut rng), rng.gen_range(0.0..TAU)))
            .collect();
        let amplitude = 0.3 * (2.0_f64 / 16.0).sqrt();
        let mut obs = run(tag, [-0.5, 1.2], 0.0, 0.5, 3000, 0.05, 0.0, 300 + seed);
        for o in &mut obs {
            let angle = (o.antenna[1] - tag[1]).atan2(o.antenna[0] - tag[0]);
            let error: f64 = terms.iter().map(|(w, p)| (w * angle + p).cos()).sum();
            o.phase_rad = (o.phase_rad + amplitude * error).rem_euclid(TAU);
        }
        let fix = locate(&obs, tag[2], -1.0, None, &s).expect("a fix");
        m2.push(error(&fix, tag).1);
    }
    let within = m2.iter().filter(|&&m| m <= 5.991).count();
    assert!(within >= 17, "{within} of 20 within the 95 % ellipse");
}

#[test]
fn on_s3_the_error_meets_the_papers_figure() {
    // σ_φ = 0.2 rad and odometry-only poses with K = 1e-5, as in [M]'s S3: [M] reports a
    // mean of about 7.5 cm for one robot.
    let s = Settings::default();
    let tag = [1.0, 1.0, 0.5];
    let mut sum = 0.0;
    for seed in 0..20 {
        let obs = run(tag, [-0.5, 1.2], 0.0, 0.5, 3000, 0.2, 1e-5, 100 + seed);
        let fix = locate(&obs, tag[2], -1.0, None, &s).expect("a fix");
        let (err, _) = error(&fix, tag);
        // A wrong half-wavelength would put it ≥ 17 cm off.
        assert!(err < 0.1, "seed {seed}: {err} m");
        sum += err;
    }
    assert!(sum / 20.0 <= 0.075, "mean {} m", sum / 20.0);
}

#[test]
fn too_little_geometry_is_said_not_guessed() {
    let s = Settings::default();
    let tag = [1.0, 1.0, 0.5];
    let obs = run(tag, [-0.5, 1.2], 0.0, 0.5, 3000, 0.0, 0.0, 7);
    // No reads, too few reads, one pose.
    assert_eq!(
        locate(&[], 0.5, -1.0, None, &s),
        Err(NoFix::InsufficientGeometry)
    );
    assert_eq!(
        locate(&obs[..5], 0.5, -1.0, None, &s),
        Err(NoFix::InsufficientGeometry)
    );
    let still = vec![obs[0]; 200];
    assert_eq!(
        locate(&still, 0.5, -1.0, None, &s),
        Err(NoFix::InsufficientGeometry)
    );
    // A tag never in range: no reads at all.
    let far = run([50.0, 50.0, 0.5], [-0.5, 1.2], 0.0, 0.5, 10, 0.0, 0.0, 7);
    let none: Vec<PoseObs> = far.into_iter().filter(|o| o.antenna[0] > 40.0).collect();
    assert_eq!(
        locate(&none, 0.5, -1.0, None, &s),
        Err(NoFix::InsufficientGeometry)
    );
    // A phase that is not a number is refused, not propagated.
    let mut bad = obs.clone();
    bad[3].phase_rad = f64::NAN;
    assert_eq!(
        locate(&bad, 0.5, -1.0, None, &s),
        Err(NoFix::InsufficientGeometry)
    );
}

#[test]
fn the_drive_before_the_first_read_is_in_the_fix_covariance() {
    // [M] eq. 26: odometry noise over 20 m of straight driving before the tag is first read
    // (pose samples every 20 cm, leading into the first read) widens the fix's covariance.
    let tag = [3.0, 2.0, 0.5];
    let reads = run(tag, [1.5, 2.3], 0.4, 0.5, 3000, 0.05, 0.0, 1);
    let s = Settings::default();
    let first = reads[0];
    let before: Vec<PoseObs> = (1..=100)
        .rev()
        .map(|i| PoseObs {
            t_us: first.t_us.saturating_sub(1),
            antenna: [
                first.antenna[0] - 0.2 * f64::from(i),
                first.antenna[1],
                first.antenna[2],
            ],
            read: false,
            ..first
        })
        .collect();
    let with: Vec<PoseObs> = before.iter().chain(&reads).copied().collect();
    let trace = |f: &Fix| f.covariance[0] + f.covariance[3];
    let plain = locate(&reads, tag[2], -1.0, None, &s).expect("a fix");
    let driven = locate(&with, tag[2], -1.0, None, &s).expect("a fix");
    assert!(
        trace(&driven) > 10.0 * trace(&plain),
        "{driven:?} against {plain:?}"
    );
    // The reads alone decide the estimate's range: the drive moves it little.
    let (a, _) = error(&plain, tag);
    let (b, _) = error(&driven, tag);
    assert!(a < 0.02 && b < 0.05, "{a} {b}");
}

#[test]
fn a_prediction_spread_over_cycles_stands_for_each_cycle_within_three_sigma() {
    // Tight: the wrapped innovation alone.
    assert_eq!(cycles(0.3, 0.2f64.powi(2), TAU, 0.2), vec![0.3]);
    // σ = 1.5 rad: 3σ = 4.5 rad reaches neither 0.3 − 2π = −5.98 nor 0.3 + 2π = 6.58.
    assert_eq!(cycles(0.3, 1.5f64.powi(2), TAU, 0.2), vec![0.3]);
    // σ = 2.5 rad: 3σ = 7.5 rad takes one cycle each way.
    let two = cycles(0.3, 2.5f64.powi(2), TAU, 0.2);
    assert_eq!(two.len(), 3);
    assert!(two.iter().any(|v| (v - (0.3 - TAU)).abs() < 1e-12));
    assert!(two.iter().any(|v| (v - (0.3 + TAU)).abs() < 1e-12));
    // σ = 2π: every cycle within 3σ = 6π of the prediction, six of them.
    let wide = cycles(-3.0, TAU.powi(2), TAU, 0.2);
    assert!(wide.iter().all(|v| v.abs() <= 3.0 * TAU + 1e-12));
    assert_eq!(wide.len(), 6);
    // With the π ambiguity the cycles are π apart.
    assert_eq!(cycles(0.1, 1.2f64.powi(2), PI, 0.2).len(), 3);
    // Phase noise whose own 3σ passes half a period: one read tells no cycle from another.
    assert_eq!(cycles(0.3, 2.5f64.powi(2), TAU, PI / 2.0), vec![0.3]);
}
