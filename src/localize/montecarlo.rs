//! `bench localize --scenario S3`'s Monte-Carlo variants after \[M\] §IV: the phase noise
//! σ_φ, the odometry noise K and the swarm size, each over seeded runs. Every run draws its
//! own robot paths (random waypoints in the room) and noise seed; robots report odometry
//! only; one robot is localized by `mhekf`, a swarm by `wls` (its consensus over the robots).

use rand::{Rng, SeedableRng};

use super::bench::{score, simulate, Run};
use super::estimate::Estimator;
use crate::scenario::Scenario;

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
/// robot on 30 random waypoints from a random start (seeded by the run).
pub fn scenario(base: &str, v: &Variant, run: u64) -> Result<Scenario, String> {
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
    Scenario::from_json(&s.to_string()).map_err(|e| e.to_string())
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
}

/// Runs `v` `runs` times (odometry poses) and scores the final estimate of each.
pub fn run_variant(base: &str, v: &Variant, runs: usize) -> Result<Outcome, String> {
    let estimator = if v.robots > 1 {
        Estimator::Wls
    } else {
        Estimator::Mhekf
    };
    let mut errors = Vec::new();
    for k in 0..runs {
        let s = scenario(base, v, k as u64)?;
        let run: Run = simulate(&s, super::bench::duration_s(&s));
        let sc = score(&run, estimator, true);
        if sc.located > 0 {
            errors.push(sc.mean);
        }
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
    })
}
