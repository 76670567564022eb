//! `bench localize --scenario S3`'s Monte-Carlo variants after \[M\] §IV: the phase noise
//! σ_φ, the odometry noise K and the swarm size, each over seeded runs. Every run draws its
//! own robot paths (random waypoints in the room) and noise seed; robots report odometry
//! only; one robot is localized by `mhekf`, a swarm by `wls` (its consensus over the robots).

use rand::{Rng, SeedableRng};

use super::bench::{score, simulate, Run};
use crate::localize::estimate::Estimator;
use crate::scenario::{Mount, Scenario};

/// One variant of S3.
#[derive(Clone, Debug, PartialEq)]
pub struct Variant {
    /// What is varied, for the table.
    pub name: String,
    /// Phase noise σ_φ (rad).
    pub sigma_rad: f64,
    /// Odometry noise K (m² per m of wheel travel), both wheels.
    pub k: f64,
    /// Robots.
    pub robots: usize,
}

/// \[M\]'s variants: σ_φ ∈ {0.2, π/4, π/2, 3π/4, π, 2π}, K ∈ {1e-4, 1e-5, 1e-6}, swarms of
/// 1, 5, 10 and 30 robots; the rest at S3's own values (σ_φ 0.2, K 1e-5, one robot).
pub fn variants() -> Vec<Variant> {
    use std::f64::consts::PI;
    let v = |name: String, sigma_rad, k, robots| Variant {
        name,
        sigma_rad,
        k,
        robots,
    };
    let mut out = Vec::new();
    for (label, s) in [
        ("0.2", 0.2),
        ("π/4", PI / 4.0),
        ("π/2", PI / 2.0),
        ("3π/4", 3.0 * PI / 4.0),
        ("π", PI),
        ("2π", 2.0 * PI),
    ] {
        out.push(v(format!("σ_φ = {label}"), s, 1e-5, 1));
    }
    for k in [1e-4, 1e-6] {
        out.push(v(format!("K = {k:e}"), 0.2, k, 1));
    }
    for n in [5, 10, 30] {
        out.push(v(format!("{n} robots"), 0.2, 1e-5, n));
    }
    out
}

/// S3 as variant `v`, run `run`: S3's room, tag and robot, with `v`'s noise and robots, each
/// robot on 30 random waypoints from a random start (seeded by the run); in a swarm, the
/// robots not the first to find the tag head for it once it is found (\[M\] §IV).
pub fn scenario(base: &str, v: &Variant, run: u64) -> Result<Scenario, String> {
    let (mut s, mut rng) = drawn(base, v, run)?;
    if v.robots > 1 {
        let first = Scenario::from_json(&s.to_string()).map_err(|e| e.to_string())?;
        tell_the_swarm(&first, &mut s, &mut rng);
    }
    Scenario::from_json(&s.to_string()).map_err(|e| e.to_string())
}

/// The variant's scenario (JSON) with every robot on its own random search, and the random
/// source it was drawn from, to go on with.
fn drawn(
    base: &str,
    v: &Variant,
    run: u64,
) -> Result<(serde_json::Value, rand_chacha::ChaCha8Rng), String> {
    let mut s: serde_json::Value = serde_json::from_str(base).map_err(|e| e.to_string())?;
    let seed = s["seed"].as_u64().unwrap_or(0) + run;
    s["seed"] = seed.into();
    let template = s["readers"][0].clone();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut readers = Vec::new();
    for r in 0..v.robots {
        let mut reader = template.clone();
        reader["name"] = format!("s3-robot-{r}").into();
        // Never bound here; each reader of a scenario must have its own.
        reader["listen"] = format!("127.0.0.1:{}", 20_000 + r).into();
        let a = &mut reader["antennas"][0];
        a["phase_noise_rad"] = v.sigma_rad.into();
        let robot = &mut a["mount"]["robot"];
        robot["k_r"] = v.k.into();
        robot["k_l"] = v.k.into();
        let mut point = || [rng.gen_range(1.0..9.0), rng.gen_range(1.0..9.0)];
        let start = point();
        robot["start"] = serde_json::json!([start[0], start[1], 0.0]);
        let waypoints: Vec<[f64; 2]> = (0..30).map(|_| point()).collect();
        robot["waypoints"] = serde_json::json!(waypoints);
        readers.push(reader);
    }
    s["readers"] = readers.into();
    Ok((s, rng))
}

/// Every this many seconds of a drive is looked at for the tag's first detection.
const LOOK_S: f64 = 0.05;

/// Radius (m) of the search round the tag by the robots told where it is (ours, within
/// \[M\]'s 2 m range: the synthetic swarms of `wls`'s tests use the same).
const SEARCH_RADIUS_M: f64 = 1.8;

/// \[M\] §IV: "If one of the robots finds the tag while it is within the range of the RFID
/// signal, it sends its location to the other robot, which immediately points to the
/// communicated location." The finder is the robot whose antenna first comes within range of
/// the tag on the true drives; from that moment every other robot ends its leg where it is and
/// searches on random points within [`SEARCH_RADIUS_M`] of the tag, as many as the waypoints it
/// had left (ours: \[M\] says no more; the location sent is the true one, not the finder's
/// first estimate). The finder keeps to its own search.
fn tell_the_swarm(first: &Scenario, s: &mut serde_json::Value, rng: &mut rand_chacha::ChaCha8Rng) {
    use crate::physics::robot::RobotTrajectory;
    let Some(tag) = first.tags.first().map(|t| t.position) else {
        return;
    };
    // Each robot's true drive (the odometry noise drawn here is not used), the antenna's
    // offset and range.
    let mut drives = Vec::new();
    for r in &first.readers {
        let Some(a) = r.antennas.first() else {
            return;
        };
        let Mount::Robot { robot, offset } = &a.mount else {
            return;
        };
        let mut quiet = rand_chacha::ChaCha8Rng::seed_from_u64(0);
        drives.push((
            RobotTrajectory::simulate(robot, &mut quiet),
            robot,
            offset.position,
            a.range_m,
        ));
    }
    let antenna = |pose: [f64; 3], o: [f64; 3]| {
        let (c, sn) = (pose[2].cos(), pose[2].sin());
        [
            pose[0] + c * o[0] - sn * o[1],
            pose[1] + sn * o[0] + c * o[1],
            o[2],
        ]
    };
    let in_range = |drive: &RobotTrajectory, o: [f64; 3], range: f64, t: f64| {
        let p = antenna(drive.true_pose(t), o);
        (p[0] - tag[0]).hypot(p[1] - tag[1]).hypot(p[2] - tag[2]) <= range
    };
    let found = drives
        .iter()
        .enumerate()
        .filter_map(|(i, (d, _, o, range))| {
            let steps = (d.duration_s() / LOOK_S).ceil() as usize;
            (0..=steps)
                .map(|k| k as f64 * LOOK_S)
                .find(|&t| in_range(d, *o, *range, t))
                .map(|t| (t, i))
        });
    let Some((t_found, finder)) = found.min_by(|a, b| a.0.total_cmp(&b.0)) else {
        return;
    };
    for (i, (drive, robot, _, _)) in drives.iter().enumerate() {
        if i == finder || t_found >= drive.duration_s() {
            continue;
        }
        // The waypoints reached by then, the same rule as the drive's.
        let mut reached = 0;
        let mut t = 0.0;
        while t <= t_found && reached < robot.waypoints.len() {
            let (p, w) = (drive.true_pose(t), robot.waypoints[reached]);
            if (w[0] - p[0]).hypot(w[1] - p[1]) <= robot.tolerance_m * 1.5 {
                reached += 1;
            } else {
                t += LOOK_S;
            }
        }
        let here = drive.true_pose(t_found);
        let mut waypoints: Vec<[f64; 2]> = robot.waypoints[..reached].to_vec();
        waypoints.push([here[0], here[1]]);
        for _ in reached..robot.waypoints.len() {
            let (r, a) = (
                SEARCH_RADIUS_M * rng.gen::<f64>().sqrt(),
                rng.gen::<f64>() * std::f64::consts::TAU,
            );
            waypoints.push([tag[0] + r * a.cos(), tag[1] + r * a.sin()]);
        }
        s["readers"][i]["antennas"][0]["mount"]["robot"]["waypoints"] =
            serde_json::json!(waypoints);
    }
}

/// One variant's result over its runs (m).
#[derive(Clone, Debug, PartialEq)]
pub struct Outcome {
    /// The variant.
    pub variant: Variant,
    /// The estimator used.
    pub estimator: Estimator,
    /// Runs, and those that gave an estimate.
    pub runs: usize,
    /// Runs with an estimate.
    pub located: usize,
    /// Mean error over the located runs.
    pub mean: f64,
    /// Median error.
    pub median: f64,
    /// Located runs whose true position lies inside the estimate's 95 % ellipse, of those
    /// with a covariance.
    pub covered: usize,
    /// Located runs with a covariance.
    pub with_covariance: usize,
}

/// Runs `v` `runs` times (odometry poses) and scores the final estimate of each.
pub fn run_variant(base: &str, v: &Variant, runs: usize) -> Result<Outcome, String> {
    let estimator = if v.robots > 1 {
        Estimator::Wls
    } else {
        Estimator::Mhekf
    };
    let (mut errors, mut covered, mut with_covariance) = (Vec::new(), 0, 0);
    for k in 0..runs {
        let s = scenario(base, v, k as u64)?;
        let run: Run = simulate(&s, super::bench::duration_s(&s));
        let sc = score(&run, estimator, true);
        if sc.located > 0 {
            errors.push(sc.mean);
        }
        covered += sc.covered;
        with_covariance += sc.with_covariance;
    }
    let located = errors.len();
    errors.sort_by(f64::total_cmp);
    let mean = if located > 0 {
        errors.iter().sum::<f64>() / located as f64
    } else {
        f64::NAN
    };
    let median = errors.get(located / 2).copied().unwrap_or(f64::NAN);
    Ok(Outcome {
        variant: v.clone(),
        estimator,
        runs,
        located,
        mean,
        median,
        covered,
        with_covariance,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const S3: &str = include_str!("../../fixtures/scenarios/s3.json");

    /// Equal to a nanometre (a scenario's numbers go through JSON text once more).
    fn same(a: &[f64; 2], b: &[f64; 2]) -> bool {
        (a[0] - b[0]).abs() < 1e-9 && (a[1] - b[1]).abs() < 1e-9
    }

    fn waypoints(s: &serde_json::Value, r: usize) -> Vec<[f64; 2]> {
        serde_json::from_value(
            s["readers"][r]["antennas"][0]["mount"]["robot"]["waypoints"].clone(),
        )
        .expect("waypoints")
    }

    #[test]
    fn the_robots_the_finder_tells_head_for_the_tag_and_search_round_it() {
        let v = Variant {
            name: "5 robots".into(),
            sigma_rad: 0.2,
            k: 1e-5,
            robots: 5,
        };
        for run in 0..3 {
            let (own, _) = drawn(S3, &v, run).expect("drawn");
            let told = scenario(S3, &v, run).expect("told");
            let tag = told.tags[0].position;
            let mut unchanged = 0;
            for (r, reader) in told.readers.iter().enumerate() {
                let Mount::Robot { robot, .. } = &reader.antennas[0].mount else {
                    panic!("run {run}: robot {r} is not on a robot");
                };
                let before = waypoints(&own, r);
                // The legs driven before the call, the spot it was at, then the search.
                let k = robot
                    .waypoints
                    .iter()
                    .zip(&before)
                    .take_while(|(a, b)| same(a, b))
                    .count();
                if k == before.len() && robot.waypoints.len() == k {
                    unchanged += 1;
                    continue;
                }
                assert_eq!(
                    robot.waypoints.len(),
                    before.len() + 1,
                    "run {run}, robot {r}"
                );
                for w in &robot.waypoints[k + 1..] {
                    let d = (w[0] - tag[0]).hypot(w[1] - tag[1]);
                    assert!(
                        d <= SEARCH_RADIUS_M,
                        "run {run}, robot {r}: {w:?} {d} m out"
                    );
                }
            }
            assert_eq!(
                unchanged, 1,
                "run {run}: only the finder keeps its own search"
            );
        }
        // One robot has nobody to tell.
        let one = Variant { robots: 1, ..v };
        let (own, _) = drawn(S3, &one, 0).expect("drawn");
        let alone = scenario(S3, &one, 0).expect("scenario");
        let Mount::Robot { robot, .. } = &alone.readers[0].antennas[0].mount else {
            panic!("not on a robot");
        };
        let before = waypoints(&own, 0);
        assert_eq!(robot.waypoints.len(), before.len());
        assert!(robot.waypoints.iter().zip(&before).all(|(a, b)| same(a, b)));
    }
}
