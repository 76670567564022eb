//! Synthetic robot runs after \[M\]'s S3, for the tests here and in `wls`.

use super::*;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};

/// 867 MHz.
pub const LAMBDA: f64 = 299_792_458.0 / 867e6;

/// A robot driving to random waypoints within 1.8 m of `tag` (horizontal) at up to 2 m/s,
/// from `start` heading `heading`, for `steps` steps of 10 ms, its antenna at height
/// `antenna_z`; a read each step within 2 m, phase sign −1, noise `sigma_phi`. Its poses
/// are dead reckoned from wheel displacements with odometry noise K·|u| (\[M\] eq. 5).
#[allow(clippy::too_many_arguments)]
pub fn run(
    tag: [f64; 3],
    start: [f64; 2],
    heading: f64,
    antenna_z: f64,
    steps: usize,
    sigma_phi: f64,
    k: f64,
    seed: u64,
) -> Vec<PoseObs> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let unit = Normal::new(0.0, 1.0).expect("valid σ");
    let (dt, d) = (0.01, 0.5);
    let (mut p, mut th) = (start, heading);
    let (mut e, mut eth) = (start, heading);
    let waypoint = |rng: &mut rand_chacha::ChaCha8Rng| {
        let (r, a) = (1.8 * rng.gen::<f64>().sqrt(), rng.gen::<f64>() * TAU);
        [tag[0] + r * a.cos(), tag[1] + r * a.sin()]
    };
    let mut goal = waypoint(&mut rng);
    let mut out = Vec::new();
    for step in 0..steps {
        let dist = (tag[0] - p[0])
            .hypot(tag[1] - p[1])
            .hypot(tag[2] - antenna_z);
        if dist <= 2.0 {
            let noise = sigma_phi * unit.sample(&mut rng);
            out.push(PoseObs {
                t_us: step as u64 * 10_000,
                phase_rad: (-4.0 * PI * dist / LAMBDA + noise).rem_euclid(TAU),
                antenna: [e[0], e[1], antenna_z],
                yaw_rad: eth,
                wavelength_m: LAMBDA,
                period_rad: TAU,
                read: true,
            });
        }
        let delta = (goal[0] - p[0]).hypot(goal[1] - p[1]);
        if delta < 0.1 {
            goal = waypoint(&mut rng);
        }
        let e_th = wrap((goal[1] - p[1]).atan2(goal[0] - p[0]) - th, TAU);
        let (v, w) = ((2.0 * delta).min(2.0), (8.0 * e_th).clamp(-6.0, 6.0));
        let (u, om) = (v * dt, w * dt);
        // True wheel displacements, then the encoders' readings.
        let (ur, ul) = (u + om * d / 2.0, u - om * d / 2.0);
        let (mr, ml) = (
            ur + (k * ur.abs()).sqrt() * unit.sample(&mut rng),
            ul + (k * ul.abs()).sqrt() * unit.sample(&mut rng),
        );
        p = [p[0] + u * th.cos(), p[1] + u * th.sin()];
        th += om;
        let (mu, mom) = ((mr + ml) / 2.0, (mr - ml) / d);
        e = [e[0] + mu * eth.cos(), e[1] + mu * eth.sin()];
        eth += mom;
    }
    out
}

/// Horizontal error of `fix` from `tag` and its Mahalanobis distance² under the covariance.
pub fn error(fix: &Fix, tag: [f64; 3]) -> (f64, f64) {
    let (ex, ey) = (fix.position[0] - tag[0], fix.position[1] - tag[1]);
    let [a, b, c, d] = fix.covariance;
    let m2 = (d * ex * ex - (b + c) * ex * ey + a * ey * ey) / (a * d - b * c);
    (ex.hypot(ey), m2)
}
