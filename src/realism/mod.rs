//! `llrp-gateway bench realism`: the parked-rail replica of a real Impinj measurement
//! (`fixtures/scenarios/rail/`, written by `scripts/rail-scenario`) run through the simulated
//! reader's own LLRP output, its reads' statistics printed beside the real ones
//! (`../shared/research/real-reads.md`, docs/measurement.md "Validation"); its command line
//! and table printing are `cli::bench`.

pub mod real;
pub mod stats;

use std::path::Path;

use crate::eval::bench::{simulate_with, Inventory};
use crate::scenario::{Mount, Scenario};
use llrp_gateway_vocab::pose::{Pose, PoseSample};
pub use real::DISTANCES;
use real::{short, FIGURES};
use stats::{Layout, Park, Stats};

/// Nominal x of the three tags along the rail (m), as `scripts/rail-scenario` places them.
pub const NOMINAL_X: [f64; 3] = [0.29, 0.49, 0.69];

/// The outcome of one setup: its statistics and how many figures fall outside their band.
pub struct Outcome {
    /// Tag distance (m).
    pub distance: f64,
    /// The statistics of the simulated reads.
    pub stats: Stats,
    /// Names of the figures outside their band (a missing value counts as outside).
    pub outside: Vec<&'static str>,
}

/// The scenario at `path` with `reader_model` if given; the error names the file.
fn load(path: &Path, reader_model: Option<&str>) -> Result<Scenario, String> {
    Scenario::load_with(path, reader_model).map_err(|e| format!("{}: {e}", path.display()))
}

/// Runs the rail replica at `distance` from the scenario in `dir`, with `reader_model` if
/// given.
pub fn run_setup(dir: &Path, distance: f64, reader_model: Option<&str>) -> Result<Outcome, String> {
    let path = dir.join(format!("rail-{distance:.2}.json"));
    let scenario = load(&path, reader_model)?;
    if scenario.tags.len() != NOMINAL_X.len() {
        return Err(format!(
            "{}: the rail scenario has {} tags, not 3",
            path.display(),
            scenario.tags.len()
        ));
    }
    let first_y = first_pose(&scenario)?.position[1];
    let nominal: Vec<[f64; 3]> = scenario
        .tags
        .iter()
        .zip(NOMINAL_X)
        .map(|(t, x)| [x, first_y + distance, t.position[2]])
        .collect();
    let layout = layout(&scenario, &nominal)?;
    Ok(judge(distance, simulate_layout(&scenario, &layout)))
}

/// Runs any parked-aperture scenario (a recorded antenna that stops at points), its tags'
/// own positions taken as nominal, judged against the real setup nearest its distance.
pub fn run_scenario(path: &Path, reader_model: Option<&str>) -> Result<Outcome, String> {
    let scenario = load(path, reader_model)?;
    let nominal: Vec<[f64; 3]> = scenario.tags.iter().map(|t| t.position).collect();
    let layout = layout(&scenario, &nominal)?;
    let distance = nearest_setup(&layout);
    Ok(judge(distance, simulate_layout(&scenario, &layout)))
}

/// The statistics of `scenario` simulated until its last park ends.
fn simulate_layout(scenario: &Scenario, layout: &Layout) -> Stats {
    let seconds = layout.parks.last().map_or(0.0, |p| p.to_us as f64 * 1e-6);
    let run = simulate_with(scenario, seconds, Inventory::default());
    stats::compute(&run.reads, layout)
}

/// The recorded poses of the scenario's first antenna.
fn recorded(s: &Scenario) -> Result<&[PoseSample], String> {
    let antenna = s
        .readers
        .first()
        .and_then(|r| r.antennas.first())
        .ok_or("the rail scenario has no antenna")?;
    let Mount::Recorded { poses, .. } = &antenna.mount else {
        return Err("the rail scenario's antenna is not a recorded mount".to_string());
    };
    Ok(poses)
}

/// The first recorded pose of the scenario's first antenna.
fn first_pose(s: &Scenario) -> Result<Pose, String> {
    recorded(s)?
        .first()
        .map(|p| p.pose)
        .ok_or_else(|| "no poses".to_string())
}

/// Of the real setups, the one nearest the tags' mean distance along the boresight.
fn nearest_setup(layout: &Layout) -> f64 {
    let p = layout.parks.first().map_or([0.0; 3], |p| p.at);
    let b = layout.boresight;
    let mean = layout
        .tags
        .iter()
        .map(|(_, at)| (at[0] - p[0]) * b[0] + (at[1] - p[1]) * b[1] + (at[2] - p[2]) * b[2])
        .sum::<f64>()
        / layout.tags.len().max(1) as f64;
    DISTANCES
        .iter()
        .copied()
        .min_by(|a, b| (a - mean).abs().total_cmp(&(b - mean).abs()))
        .unwrap_or(DISTANCES[0])
}

/// The parks of the scenario's recorded antenna (runs of equal positions) and its tags at
/// their `nominal` places.
fn layout(s: &Scenario, nominal: &[[f64; 3]]) -> Result<Layout, String> {
    let poses = recorded(s)?;
    let mut parks = Vec::new();
    for w in poses.windows(2) {
        let (a, b) = (&w[0], &w[1]);
        if a.pose.position == b.pose.position {
            parks.push(Park {
                // A read stamped at the very start or end belongs to the move.
                from_us: a.t_us + 1,
                to_us: b.t_us - 1,
                at: a.pose.position,
            });
        }
    }
    let first = poses.first().ok_or("no poses")?;
    let (yaw, pitch) = (first.pose.yaw_rad, first.pose.pitch_rad);
    let boresight = [
        yaw.cos() * pitch.cos(),
        yaw.sin() * pitch.cos(),
        pitch.sin(),
    ];
    let tags = s
        .tags
        .iter()
        .zip(nominal)
        .map(|(t, at)| (t.epc.to_ascii_uppercase(), *at))
        .collect();
    Ok(Layout {
        parks,
        tags,
        boresight,
    })
}

/// Scores the reads of `reads` (JSON Lines) against `layout` (JSON), judged against the real
/// setup nearest to the tags' mean distance from the parks.
pub fn score_file(reads: &Path, layout: &Path) -> Result<Outcome, String> {
    let text = std::fs::read_to_string(layout).map_err(|e| format!("{}: {e}", layout.display()))?;
    let mut de = serde_json::Deserializer::from_str(&text);
    let layout: Layout = serde_path_to_error::deserialize(&mut de)
        .map_err(|e| format!("{}: {}: {}", layout.display(), e.path(), e.inner()))?;
    let file = std::fs::File::open(reads).map_err(|e| format!("{}: {e}", reads.display()))?;
    let mut all = Vec::new();
    for (n, line) in std::io::BufRead::lines(std::io::BufReader::new(file)).enumerate() {
        let line = line.map_err(|e| format!("{}: {e}", reads.display()))?;
        if line.trim().is_empty() {
            continue;
        }
        let r: crate::reads::Read = serde_json::from_str(&line)
            .map_err(|e| format!("{} line {}: {e}", reads.display(), n + 1))?;
        all.push(r);
    }
    let distance = nearest_setup(&layout);
    let stats = stats::compute(&all, &layout);
    Ok(judge(distance, stats))
}

/// The outcome of `stats` judged against the real setup at `distance`.
fn judge(distance: f64, stats: Stats) -> Outcome {
    let setup = DISTANCES
        .iter()
        .position(|&d| (d - distance).abs() < 1e-9)
        .unwrap_or(0);
    let outside = FIGURES
        .iter()
        .filter(|f| !(f.get)(&stats).is_some_and(|v| f.band.holds(v, setup)))
        .map(|f| f.name)
        .collect();
    Outcome {
        distance,
        stats,
        outside,
    }
}

/// The Markdown table: each figure, real, and per setup the simulated value with ✗ outside.
pub fn table(outcomes: &[Outcome]) -> String {
    let mut out = String::from("| statistic | real (0.88 / 0.68 / 0.51 m) |");
    for o in outcomes {
        out.push_str(&format!(" measured, bands of {:.2} m | band |", o.distance));
    }
    out.push_str("\n|---|---|");
    for _ in outcomes {
        out.push_str("---|---|");
    }
    out.push('\n');
    for f in &FIGURES {
        out.push_str(&format!("| {} | {} |", f.name, f.real));
        for o in outcomes {
            let setup = DISTANCES
                .iter()
                .position(|&d| (d - o.distance).abs() < 1e-9)
                .unwrap_or(0);
            let cell = match (f.get)(&o.stats) {
                Some(v) if f.band.holds(v, setup) => short(v),
                Some(v) => format!("**{}** ✗", short(v)),
                None => "— ✗".to_string(),
            };
            out.push_str(&format!(" {cell} | {} |", f.band.describe(setup)));
        }
        out.push('\n');
    }
    out.push_str("| **outside the band** | |");
    for o in outcomes {
        out.push_str(&format!(
            " **{} of {}** ({} groups, {} reads) | |",
            o.outside.len(),
            FIGURES.len(),
            o.stats.groups,
            o.stats.reads
        ));
    }
    out.push('\n');
    out
}
