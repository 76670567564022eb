//! A differential-drive robot driven through waypoints (\[M\] eqs. 1–11), integrated once with a
//! fixed time step, with the pose it would dead-reckon from noisy wheel odometry.
//!
//! Control (on the true pose, as a robot with good localization would): heading error
//! e_θ = wrap(atan2(Δy, Δx) − θ), ω = K_ω·e_θ, v = min(K_v·δ, v_max)·max(cos e_θ, 0) (the cosine
//! factor, ours, makes the robot turn on the spot at sharp corners instead of circling), and
//! both wheel rim speeds v ± ω·d/2 are kept within v_max. Wheel displacements u_R, u_L
//! move the true pose; odometry sees û = u + η with Var η = K·|u| (\[M\] eq. 5) and integrates
//! û from the known start: Δs = (û_R + û_L)/2, Δθ = (û_R − û_L)/d, midpoint heading.
//!
//! The pose the robot reports ([`RobotTrajectory::estimated_pose`]) is that dead-reckoned pose,
//! or, for a `localized` pose estimate, the true pose plus an error as a localization stack's:
//! independent first-order Gauss–Markov processes ([`GaussMarkov`]) for x, y and θ, sampled
//! with the poses and drawn from their own stream.

use rand_chacha::ChaCha8Rng;

use super::geometry::wrap_pi;
use super::noise::gaussian;
use crate::scenario::{PoseEstimate, PoseEstimateKind, RobotSpec};

/// Integration time step in seconds.
pub const TIME_STEP_S: f64 = 0.01;
/// Integration steps per stored sample (poses are kept every 50 ms and interpolated).
pub const STORE_EVERY: usize = 5;
/// Longest simulated drive in seconds; a looping robot stops after it.
pub const MAX_DURATION_S: f64 = 7200.0;
/// Last seed word of a robot's localization-error stream (the odometry stream's words
/// followed by this one), so the error never takes draws from the odometry.
pub const ESTIMATE_STREAM: u64 = 1;
/// A localization error is held within this many standard deviations of zero.
pub const ERROR_BOUND_SIGMAS: f64 = 4.0;

/// One of a trajectory's poses `[x, y, θ]` at a time (s): true, odometry or estimated.
pub type PoseOf = fn(&RobotTrajectory, f64) -> [f64; 3];

/// A stationary first-order Gauss–Markov (Ornstein–Uhlenbeck) process sampled at a fixed step,
/// held within ±[`ERROR_BOUND_SIGMAS`]·σ.
///
/// x₀ ~ N(0, σ²), x_{k+1} = a·x_k + σ·√(1 − a²)·ξ_k with a = e^(−Δt/τ) and ξ_k ~ N(0, 1): the
/// exact discretisation, so Var x_k = σ² and the autocorrelation at lag τ' is e^(−τ'/τ).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GaussMarkov {
    a: f64,
    kick: f64,
    bound: f64,
    x: f64,
}

impl GaussMarkov {
    /// The process of standard deviation `sigma` and correlation time `tau_s` sampled every
    /// `dt_s`, its first value drawn from `rng`; constant 0 unless σ and τ are finite and
    /// positive (and Δt finite, non-negative).
    pub fn new(sigma: f64, tau_s: f64, dt_s: f64, rng: &mut ChaCha8Rng) -> GaussMarkov {
        let usable = sigma > 0.0
            && sigma.is_finite()
            && tau_s > 0.0
            && tau_s.is_finite()
            && dt_s >= 0.0
            && dt_s.is_finite();
        if !usable {
            return GaussMarkov {
                a: 0.0,
                kick: 0.0,
                bound: 0.0,
                x: 0.0,
            };
        }
        let a = (-dt_s / tau_s).exp();
        let bound = ERROR_BOUND_SIGMAS * sigma;
        GaussMarkov {
            a,
            kick: sigma * (1.0 - a * a).sqrt(),
            bound,
            x: gaussian(rng, sigma).clamp(-bound, bound),
        }
    }

    /// The current value; then moves the process one step on, drawing from `rng` (no draw for
    /// a constant process).
    pub fn step(&mut self, rng: &mut ChaCha8Rng) -> f64 {
        let now = self.x;
        if self.bound > 0.0 {
            self.x = (self.a * self.x + gaussian(rng, self.kick)).clamp(-self.bound, self.bound);
        }
        now
    }
}

/// A precomputed robot drive: true and dead-reckoned poses `[x, y, θ]` at a fixed interval,
/// and the localization error of a `localized` pose estimate.
#[derive(Clone, Debug, PartialEq)]
pub struct RobotTrajectory {
    sample_dt_s: f64,
    truth: Vec<[f64; 3]>,
    odometry: Vec<[f64; 3]>,
    /// Localization error `[x m, y m, θ rad]` at each sample of `truth`; empty: the robot
    /// reports its odometry.
    error: Vec<[f64; 3]>,
}

/// Linear and angular speed commanded toward `target` from `pose`.
fn control(spec: &RobotSpec, pose: [f64; 3], target: [f64; 2]) -> (f64, f64) {
    let (dx, dy) = (target[0] - pose[0], target[1] - pose[1]);
    let delta = dx.hypot(dy);
    let e_theta = wrap_pi(dy.atan2(dx) - pose[2]);
    let mut omega = spec.k_omega * e_theta;
    let mut v = (spec.k_v * delta).min(spec.speed) * e_theta.cos().max(0.0);
    // Keep both wheel rim speeds within the speed limit.
    let rim = v.abs() + omega.abs() * spec.wheel_base / 2.0;
    if rim > spec.speed && rim > 0.0 {
        v *= spec.speed / rim;
        omega *= spec.speed / rim;
    }
    (v, omega)
}

/// Moves `pose` by wheel displacements `u_r`, `u_l` (m) for a wheel base `d`.
fn advance(pose: &mut [f64; 3], u_r: f64, u_l: f64, d: f64) {
    let ds = (u_r + u_l) / 2.0;
    let dtheta = (u_r - u_l) / d;
    let mid = pose[2] + dtheta / 2.0;
    pose[0] += ds * mid.cos();
    pose[1] += ds * mid.sin();
    pose[2] += dtheta;
}

fn usable(spec: &RobotSpec) -> bool {
    let positive = |x: f64| x > 0.0 && x.is_finite();
    let non_negative = |x: f64| x >= 0.0 && x.is_finite();
    positive(spec.speed)
        && positive(spec.wheel_base)
        && positive(spec.wheel_radius)
        && positive(spec.k_v)
        && positive(spec.k_omega)
        && positive(spec.tolerance_m)
        && non_negative(spec.k_r)
        && non_negative(spec.k_l)
        && spec.start.iter().all(|v| v.is_finite())
        && spec.waypoints.iter().flatten().all(|v| v.is_finite())
}

impl RobotTrajectory {
    /// Simulates the drive of `spec` from t = 0 until the last waypoint is reached (or, for a
    /// looping path, for [`MAX_DURATION_S`]); `rng` draws the odometry noise. A spec with
    /// unusable values (not validated) leaves the robot at its start.
    pub fn simulate(spec: &RobotSpec, rng: &mut ChaCha8Rng) -> RobotTrajectory {
        let start = spec.start;
        let mut truth = start;
        let mut odo = start;
        let mut out = RobotTrajectory {
            sample_dt_s: TIME_STEP_S * STORE_EVERY as f64,
            truth: vec![truth],
            odometry: vec![odo],
            error: Vec::new(),
        };
        if !usable(spec) || spec.waypoints.is_empty() {
            return out;
        }
        let n = spec.waypoints.len();
        let max_steps = (MAX_DURATION_S / TIME_STEP_S) as usize;
        let mut target = 0;
        let mut done = false;
        for step in 1..=max_steps {
            // Skip waypoints already reached (at most one lap per step).
            for _ in 0..n {
                let w = spec.waypoints[target];
                if (w[0] - truth[0]).hypot(w[1] - truth[1]) > spec.tolerance_m {
                    break;
                }
                target += 1;
                if target == n {
                    if spec.loop_path {
                        target = 0;
                    } else {
                        done = true;
                        break;
                    }
                }
            }
            if done {
                // Stopped: the next stored sample is the resting pose.
                out.truth.push(truth);
                out.odometry.push(odo);
                break;
            }
            let (v, omega) = control(spec, truth, spec.waypoints[target]);
            let half = omega * spec.wheel_base / 2.0;
            let u_r = (v + half) * TIME_STEP_S;
            let u_l = (v - half) * TIME_STEP_S;
            advance(&mut truth, u_r, u_l, spec.wheel_base);
            let m_r = u_r + gaussian(rng, (spec.k_r * u_r.abs()).sqrt());
            let m_l = u_l + gaussian(rng, (spec.k_l * u_l.abs()).sqrt());
            advance(&mut odo, m_r, m_l, spec.wheel_base);
            if step % STORE_EVERY == 0 {
                out.truth.push(truth);
                out.odometry.push(odo);
            }
        }
        out
    }

    /// The drive with the pose estimate `estimate` asks for: for "localized", an error drawn
    /// from `rng` at every stored sample (x and y with σ = `position_sigma_m`, θ with σ =
    /// `heading_sigma_deg`, all with correlation time `correlation_s`); the error holds its
    /// last value while the robot rests. "odometry" changes nothing and draws nothing.
    pub fn with_estimate(mut self, estimate: &PoseEstimate, rng: &mut ChaCha8Rng) -> Self {
        if estimate.kind != PoseEstimateKind::Localized {
            self.error = Vec::new();
            return self;
        }
        let (tau, dt) = (estimate.correlation_s, self.sample_dt_s);
        let mut axes = [
            GaussMarkov::new(estimate.position_sigma_m, tau, dt, rng),
            GaussMarkov::new(estimate.position_sigma_m, tau, dt, rng),
            GaussMarkov::new(estimate.heading_sigma_deg.to_radians(), tau, dt, rng),
        ];
        self.error = (0..self.truth.len())
            .map(|_| {
                let mut e = [0.0; 3];
                for (v, p) in e.iter_mut().zip(axes.iter_mut()) {
                    *v = p.step(rng);
                }
                e
            })
            .collect();
        self
    }

    /// Time (s) of the last stored sample: the robot rests after it.
    pub fn duration_s(&self) -> f64 {
        (self.truth.len() - 1) as f64 * self.sample_dt_s
    }

    /// True pose `[x, y, θ]` at `t_s` (θ wrapped to (−π, π]).
    pub fn true_pose(&self, t_s: f64) -> [f64; 3] {
        interpolate(&self.truth, self.sample_dt_s, t_s)
    }

    /// Dead-reckoned pose `[x, y, θ]` at `t_s`.
    pub fn odometry_pose(&self, t_s: f64) -> [f64; 3] {
        interpolate(&self.odometry, self.sample_dt_s, t_s)
    }

    /// The pose `[x, y, θ]` the robot reports at `t_s`: the dead-reckoned pose, or the true
    /// pose plus the localization error ([`RobotTrajectory::with_estimate`]).
    pub fn estimated_pose(&self, t_s: f64) -> [f64; 3] {
        if self.error.is_empty() {
            return self.odometry_pose(t_s);
        }
        let p = interpolate_raw(&self.truth, self.sample_dt_s, t_s);
        let e = interpolate_raw(&self.error, self.sample_dt_s, t_s);
        [p[0] + e[0], p[1] + e[1], wrap_pi(p[2] + e[2])]
    }

    /// The largest speed (m/s) and turn rate (rad/s) of the true pose at any time: between
    /// samples the pose is linear in time, so the largest over consecutive samples.
    pub fn max_rates(&self) -> [f64; 2] {
        let dt = self.sample_dt_s;
        self.truth.windows(2).fold([0.0f64; 2], |[v, w], p| {
            let (a, b) = (p[0], p[1]);
            [
                v.max((b[0] - a[0]).hypot(b[1] - a[1]) / dt),
                w.max((b[2] - a[2]).abs() / dt),
            ]
        })
    }

    /// How far the true pose strays from its value at `t0_s` during `[t0_s, t1_s]`: the
    /// largest change of x and of y (m) and of the heading (rad, unwrapped).
    pub fn excursion(&self, t0_s: f64, t1_s: f64) -> [f64; 3] {
        let dt = self.sample_dt_s;
        let start = interpolate_raw(&self.truth, dt, t0_s);
        let mut far = [0.0f64; 3];
        let mut see = |p: [f64; 3]| {
            for (f, (a, b)) in far.iter_mut().zip(p.iter().zip(start)) {
                *f = f.max((a - b).abs());
            }
        };
        // Between samples the pose is linear in time, so each change is largest at a sample
        // or at the end.
        see(interpolate_raw(&self.truth, dt, t1_s));
        if t0_s.is_finite() && t1_s.is_finite() {
            let last = self.truth.len() - 1;
            let first = ((t0_s / dt).max(0.0).floor() as usize + 1).min(last + 1);
            let end = ((t1_s / dt).max(0.0).ceil() as usize).min(last);
            for sample in self.truth.get(first..=end).unwrap_or(&[]) {
                see(*sample);
            }
        }
        far
    }
}

/// Linear interpolation in samples taken every `dt` from t = 0 (θ is stored unwrapped).
fn interpolate(samples: &[[f64; 3]], dt: f64, t_s: f64) -> [f64; 3] {
    let p = interpolate_raw(samples, dt, t_s);
    [p[0], p[1], wrap_pi(p[2])]
}

/// [`interpolate`] without wrapping θ.
fn interpolate_raw(samples: &[[f64; 3]], dt: f64, t_s: f64) -> [f64; 3] {
    let last = samples.len() - 1;
    let x = if t_s.is_finite() {
        (t_s / dt).max(0.0)
    } else {
        0.0
    };
    // x ≥ 0: truncation is floor (without the library call of `f64::floor`).
    let i = x as usize;
    if i >= last {
        samples[last]
    } else {
        let f = x - i as f64;
        let (a, b) = (samples[i], samples[i + 1]);
        [
            a[0] + f * (b[0] - a[0]),
            a[1] + f * (b[1] - a[1]),
            a[2] + f * (b[2] - a[2]),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn spec(k: f64) -> RobotSpec {
        RobotSpec {
            start: [0.0, 0.0, 0.0],
            waypoints: vec![[5.0, 0.0], [5.0, 4.0], [1.0, 4.0]],
            speed: 1.0,
            wheel_radius: 0.2,
            wheel_base: 0.5,
            k_r: k,
            k_l: k,
            k_v: 1.0,
            k_omega: 2.0,
            tolerance_m: 0.05,
            vertical: None,
            loop_path: false,
            pose_estimate: PoseEstimate::default(),
        }
    }

    fn end_error(t: &RobotTrajectory) -> f64 {
        let (a, b) = (t.true_pose(1e9), t.odometry_pose(1e9));
        (a[0] - b[0]).hypot(a[1] - b[1])
    }

    #[test]
    fn reaches_every_waypoint_without_noise() {
        let s = spec(0.0);
        let t = RobotTrajectory::simulate(&s, &mut ChaCha8Rng::seed_from_u64(1));
        let dt = 0.01;
        let steps = (t.duration_s() / dt) as usize + 1;
        for w in &s.waypoints {
            let closest = (0..=steps)
                .map(|i| {
                    let p = t.true_pose(i as f64 * dt);
                    (p[0] - w[0]).hypot(p[1] - w[1])
                })
                .fold(f64::INFINITY, f64::min);
            assert!(closest <= s.tolerance_m + 1e-3, "{w:?}: {closest}");
        }
        let end = t.true_pose(t.duration_s() + 100.0);
        assert!((end[0] - 1.0).hypot(end[1] - 4.0) <= s.tolerance_m);
        // About 13 m at ≤ 1 m/s, with turns: between 13 s and a minute.
        assert!(
            t.duration_s() > 13.0 && t.duration_s() < 60.0,
            "{}",
            t.duration_s()
        );
        // Without noise, odometry is the truth.
        assert_eq!(end_error(&t), 0.0);
        // Never faster than the speed limit.
        for i in 0..steps {
            let (a, b) = (t.true_pose(i as f64 * dt), t.true_pose((i + 1) as f64 * dt));
            assert!((b[0] - a[0]).hypot(b[1] - a[1]) <= s.speed * dt + 1e-9);
        }
    }

    #[test]
    fn odometry_drift_grows_with_k() {
        let mean_error = |k: f64| {
            (0..20)
                .map(|seed| {
                    let t =
                        RobotTrajectory::simulate(&spec(k), &mut ChaCha8Rng::seed_from_u64(seed));
                    end_error(&t)
                })
                .sum::<f64>()
                / 20.0
        };
        let (e6, e5, e4) = (mean_error(1e-6), mean_error(1e-5), mean_error(1e-4));
        assert!(e6 > 0.0);
        assert!(e6 < e5 && e5 < e4, "{e6} {e5} {e4}");
        // Error grows like √K: a factor 100 in K is about a factor 10 in drift.
        assert!(e4 / e6 > 4.0 && e4 / e6 < 25.0, "{}", e4 / e6);
    }

    /// `n` samples of the Gauss–Markov process (σ, τ) every 50 ms from seed `seed`.
    fn process(sigma: f64, tau: f64, n: usize, seed: u64) -> Vec<f64> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut p = GaussMarkov::new(sigma, tau, 0.05, &mut rng);
        (0..n).map(|_| p.step(&mut rng)).collect()
    }

    /// Sample autocorrelation of `x` (mean 0 by construction) at lag `k`.
    fn autocorrelation(x: &[f64], k: usize) -> f64 {
        let var = x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64;
        let cov = x.iter().zip(&x[k..]).map(|(a, b)| a * b).sum::<f64>() / (x.len() - k) as f64;
        cov / var
    }

    #[test]
    fn gauss_markov_has_the_stationary_sigma_and_the_correlation_time() {
        // 400,000 samples of 50 ms with τ = 2 s: about 5,000 independent stretches, so the σ
        // estimate is within about 1 % and the autocorrelations within about 0.02.
        let (sigma, tau) = (0.015, 2.0);
        let x = process(sigma, tau, 400_000, 3);
        let mean = x.iter().sum::<f64>() / x.len() as f64;
        let sd = (x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / x.len() as f64).sqrt();
        assert!(mean.abs() < 0.1 * sigma, "mean {mean}");
        assert!((sd / sigma - 1.0).abs() < 0.05, "σ {sd} vs {sigma}");
        // Lag 1 step, τ and 2τ: e^(−Δt/τ), e^(−1), e^(−2).
        for (k, lag_s) in [(1, 0.05), (40, tau), (80, 2.0 * tau)] {
            let (got, want) = (autocorrelation(&x, k), (-lag_s / tau).exp());
            assert!((got - want).abs() < 0.05, "lag {lag_s} s: {got} vs {want}");
        }
    }

    #[test]
    fn gauss_markov_is_bounded_and_seeded() {
        // τ = Δt: consecutive samples nearly independent, so 200,000 of them would pass 4σ
        // about a dozen times without the bound.
        let x = process(1.0, 0.05, 200_000, 5);
        let largest = x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(largest <= ERROR_BOUND_SIGMAS, "{largest}");
        assert!(largest > 3.5, "{largest}");
        assert_eq!(x[..1000], process(1.0, 0.05, 1000, 5)[..]);
        assert_ne!(x[..1000], process(1.0, 0.05, 1000, 6)[..]);
        // σ = 0: always 0, and no draw is taken.
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut p = GaussMarkov::new(0.0, 2.0, 0.05, &mut rng);
        assert!((0..10).all(|_| p.step(&mut rng) == 0.0));
        assert_eq!(rng, ChaCha8Rng::seed_from_u64(5));
    }

    fn localized(position_sigma_m: f64, heading_sigma_deg: f64) -> PoseEstimate {
        PoseEstimate {
            kind: PoseEstimateKind::Localized,
            position_sigma_m,
            heading_sigma_deg,
            correlation_s: 2.0,
        }
    }

    #[test]
    fn estimated_pose_is_odometry_or_truth_plus_a_bounded_error() {
        let s = spec(1e-5);
        let drive = RobotTrajectory::simulate(&s, &mut ChaCha8Rng::seed_from_u64(1));
        let odometry = drive
            .clone()
            .with_estimate(&PoseEstimate::default(), &mut ChaCha8Rng::seed_from_u64(2));
        assert_eq!(odometry, drive);
        let located = drive
            .clone()
            .with_estimate(&localized(0.015, 0.5), &mut ChaCha8Rng::seed_from_u64(2));
        let end = drive.duration_s();
        let times: Vec<f64> = (0..=(end / 0.01) as usize + 100)
            .map(|i| i as f64 * 0.01)
            .collect();
        let (mut moved, mut turned) = (0.0f64, 0.0f64);
        for &t in &times {
            assert_eq!(odometry.estimated_pose(t), drive.odometry_pose(t));
            // The drive itself (truth and odometry) is the same.
            assert_eq!(located.true_pose(t), drive.true_pose(t));
            assert_eq!(located.odometry_pose(t), drive.odometry_pose(t));
            let (p, e) = (located.true_pose(t), located.estimated_pose(t));
            let (dx, dy, dth) = (e[0] - p[0], e[1] - p[1], wrap_pi(e[2] - p[2]));
            assert!(
                dx.abs().max(dy.abs()) <= 4.0 * 0.015 + 1e-12,
                "{t}: {dx} {dy}"
            );
            assert!(dth.abs() <= 4.0 * 0.5f64.to_radians() + 1e-12, "{t}: {dth}");
            moved = moved.max(dx.abs());
            turned = turned.max(dth.abs());
        }
        assert!(moved > 0.005 && turned > 0.002, "{moved} {turned}");
        // At rest the error holds its last value.
        assert_eq!(
            located.estimated_pose(end),
            located.estimated_pose(end + 60.0)
        );
        // Seeded: the same stream gives the same estimate, another a different one.
        let again = drive
            .clone()
            .with_estimate(&localized(0.015, 0.5), &mut ChaCha8Rng::seed_from_u64(2));
        assert_eq!(again, located);
        let other = drive.with_estimate(&localized(0.015, 0.5), &mut ChaCha8Rng::seed_from_u64(3));
        assert_ne!(other.estimated_pose(1.0), located.estimated_pose(1.0));
    }

    #[test]
    fn looping_robot_keeps_driving_and_bad_spec_stays_put() {
        let mut s = spec(0.0);
        s.loop_path = true;
        s.waypoints = vec![[3.0, 0.0], [3.0, 3.0], [0.0, 3.0], [0.0, 0.0]];
        let t = RobotTrajectory::simulate(&s, &mut ChaCha8Rng::seed_from_u64(1));
        assert!((t.duration_s() - MAX_DURATION_S).abs() < 0.1);
        let mut bad = spec(0.0);
        bad.speed = f64::NAN;
        let t = RobotTrajectory::simulate(&bad, &mut ChaCha8Rng::seed_from_u64(1));
        assert_eq!(t.true_pose(10.0), [0.0, 0.0, 0.0]);
    }
}
