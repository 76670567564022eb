//! Synthetic phases for the estimators' unit tests: a tag seen from antennas passing along
//! y = 0 at given heights, x from −1 m in 1 cm steps, one segment per height.

use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

use crate::fix::Obs;
use llrp_gateway_vocab::reads::{Pose, Read};

/// The wavelength of the synthetic channel (m).
pub const LAMBDA: f64 = 0.3463;

/// Unwrapped phases of a tag at `tag` from 300 positions of a pass along y = 0 at each of
/// `heights` (segment `s` for `heights[s]`), with phase offset `offset.0 + offset.1 · s` and
/// Gaussian noise of σ `noise` (rad) from `seed`.
pub fn passes(
    tag: [f64; 3],
    heights: &[f64],
    offset: (f64, f64),
    noise: f64,
    seed: u64,
) -> Vec<Obs> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let n = Normal::new(0.0, noise.max(1e-300)).expect("valid σ");
    let mut obs = Vec::new();
    for (s, &az) in heights.iter().enumerate() {
        for k in 0..300 {
            let a = [-1.0 + 0.01 * f64::from(k), 0.0, az];
            let d = (0..3).map(|j| (tag[j] - a[j]).powi(2)).sum::<f64>().sqrt();
            let e = if noise > 0.0 { n.sample(&mut rng) } else { 0.0 };
            obs.push(Obs {
                phase_rad: offset.0
                    + offset.1 * s as f64
                    + 4.0 * std::f64::consts::PI * d / LAMBDA
                    + e,
                antenna: a,
                wavelength_m: LAMBDA,
                segment: s,
                group: s,
                joint: s,
                period_rad: std::f64::consts::TAU,
                weight: 1.0,
                scatter_rad2: 0.0,
                t_us: 0,
            });
        }
    }
    obs
}

/// A read of tag `epc` at `t_us` by antenna 1 of an unnamed reader at `at` facing +y, its
/// phase `phase_rad` (wrapped onto [0, 2π)) on 866.9 MHz; change what a test needs with
/// `Read { .., ..read(..) }`.
pub fn read(epc: &str, t_us: u64, phase_rad: f64, at: [f64; 3]) -> Read {
    Read {
        epc: llrp_gateway_vocab::epc::Epc::parse(epc).expect("hex"),
        reader: None,
        antenna: 1,
        t_us,
        phase_rad: Some(phase_rad.rem_euclid(std::f64::consts::TAU)),
        rssi_dbm: None,
        channel_index: None,
        channel_frequency_hz: Some(FREQUENCY_HZ),
        doppler_hz: None,
        antenna_pose: Some(Pose::from_degrees([at[0], at[1], at[2]], 90.0, 0.0)),
        last_seen_us: None,
    }
}

/// The channel of [`read`] (Hz).
pub const FREQUENCY_HZ: u64 = 866_900_000;

/// Of 20 seeds of a pass at z = 0.5 past a tag at (0.8, 2.1, 0.5) with σ 0.01 rad of white
/// noise and 0.3 rad of an error turning over 0.8 m of path (an antenna's phase pattern), how
/// many fixes by `locate` hold the tag inside their 95 % ellipse. A covariance that takes the
/// 300 reads as independent holds about half.
pub fn held_under_a_smooth_error(locate: &dyn Fn(&[Obs]) -> crate::fix::Fix) -> usize {
    let tag = [0.8, 2.1, 0.5];
    (0..20u64)
        .filter(|&seed| {
            let mut obs = passes(tag, &[0.5], (0.7, 0.0), 0.01, seed);
            for o in &mut obs {
                o.phase_rad += 0.3 * (o.antenna[0] * 8.0 + seed as f64).sin();
            }
            let fix = locate(&obs);
            let (ex, ey) = (fix.position[0] - tag[0], fix.position[1] - tag[1]);
            let [a, b, c, d] = fix.covariance;
            (d * ex * ex - (b + c) * ex * ey + a * ey * ey) / (a * d - b * c) <= 5.991
        })
        .count()
}

/// Of `seeds` passes at z = 0.5 past a tag at (0.8, 2.1, 0.5) with σ 0.01 rad of white noise
/// and an error of RMS 0.3 rad smooth in the angle the tag is read from (eight cosines of that
/// angle, each turning over 30–80°: a phase pattern, not a function of the path), how many
/// fixes by `locate` hold the tag inside their 95 % ellipse.
pub fn held_under_an_angle_error(locate: &dyn Fn(&[Obs]) -> crate::fix::Fix, seeds: u64) -> usize {
    use rand::Rng;
    let tag = [0.8, 2.1, 0.5];
    (0..seeds)
        .filter(|&seed| {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1000 + seed);
            let terms: Vec<(f64, f64)> = (0..8)
                .map(|_| {
                    let turn = rng.gen_range(30.0_f64..80.0).to_radians();
                    (
                        std::f64::consts::TAU / turn,
                        rng.gen_range(0.0..std::f64::consts::TAU),
                    )
                })
                .collect();
            let amplitude = 0.3 * (2.0_f64 / 8.0).sqrt();
            let mut obs = passes(tag, &[0.5], (0.7, 0.0), 0.01, seed);
            for o in &mut obs {
                let angle = (o.antenna[0] - tag[0]).atan2(tag[1] - o.antenna[1]);
                o.phase_rad += terms
                    .iter()
                    .map(|(w, p)| amplitude * (w * angle + p).cos())
                    .sum::<f64>();
            }
            let fix = locate(&obs);
            let (ex, ey) = (fix.position[0] - tag[0], fix.position[1] - tag[1]);
            let [a, b, c, d] = fix.covariance;
            (d * ex * ex - (b + c) * ex * ey + a * ey * ey) / (a * d - b * c) <= 5.991
        })
        .count()
}

/// Of `seeds` passes at `heights` past a tag at `tag` with σ 0.01 rad of white noise and an
/// error of RMS 0.3 rad smooth in the direction the tag is read from (eight cosines of the
/// angle along the path and four of the elevation, each turning over 30–80°), how many 3D
/// fixes by `locate` hold the tag inside their 95 % ellipsoid (Mahalanobis² ≤ 7.815); a seed
/// without a fix does not count.
pub fn held_in_3d_under_an_angle_error(
    locate: &dyn Fn(&[Obs]) -> Option<crate::fix::Fix3>,
    tag: [f64; 3],
    heights: &[f64],
    seeds: u64,
) -> usize {
    use rand::Rng;
    (0..seeds)
        .filter(|&seed| {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2000 + seed);
            let mut term = || {
                let turn = rng.gen_range(30.0_f64..80.0).to_radians();
                let phase = rng.gen_range(0.0..std::f64::consts::TAU);
                (std::f64::consts::TAU / turn, phase)
            };
            let along: Vec<(f64, f64)> = (0..8).map(|_| term()).collect();
            let up: Vec<(f64, f64)> = (0..4).map(|_| term()).collect();
            let amplitude = 0.3 * (2.0_f64 / 12.0).sqrt();
            let mut obs = passes(tag, heights, (0.7, 0.4), 0.01, seed);
            for o in &mut obs {
                let v = [0, 1, 2].map(|k| o.antenna[k] - tag[k]);
                let angle = v[0].atan2(-v[1]);
                let elevation = v[2].atan2(v[0].hypot(v[1]));
                let sum = |terms: &[(f64, f64)], x: f64| {
                    terms.iter().map(|(w, p)| (w * x + p).cos()).sum::<f64>()
                };
                o.phase_rad += amplitude * (sum(&along, angle) + sum(&up, elevation));
            }
            locate(&obs).is_some_and(|fix| {
                let c = nalgebra::Matrix3::from_row_slice(&fix.covariance);
                let e = nalgebra::Vector3::from(fix.position) - nalgebra::Vector3::from(tag);
                c.try_inverse()
                    .is_some_and(|inv| (e.transpose() * inv * e)[0] <= 7.815)
            })
        })
        .count()
}
