//! `llrp-gateway bench realism`: the parked-rail replica of a real Impinj measurement
//! (`fixtures/scenarios/rail/`, written by `scripts/rail-scenario`) run through the simulated
//! reader's own LLRP output, its reads' statistics printed beside the real ones
//! (`../shared/research/real-reads.md`, docs/measurement.md "Validation").

pub mod real;
pub mod stats;

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use crate::localize::bench::{simulate_with, Inventory};
use crate::scenario::{Mount, Scenario};
use real::{short, DISTANCES, FIGURES};
use stats::{Layout, Park, Stats};

/// Nominal x of the three tags along the rail (m), as `scripts/rail-scenario` places them.
pub const NOMINAL_X: [f64; 3] = [0.29, 0.49, 0.69];

/// `llrp-gateway bench realism`.
#[derive(Clone, Debug, clap::Args)]
pub struct BenchRealismArgs {
    /// Directory of the rail scenarios (`rail-0.88.json`, `rail-0.68.json`, `rail-0.51.json`).
    #[arg(long, default_value = concat!(env!("CARGO_MANIFEST_DIR"), "/fixtures/scenarios/rail"))]
    pub dir: PathBuf,
    /// Reader model the scenarios are run with (docs/measurement.md "Reader models"); default:
    /// the scenario's own.
    #[arg(long)]
    pub reader_model: Option<String>,
}

/// The outcome of one setup: its statistics and how many figures fall outside their band.
pub struct Outcome {
    /// Tag distance (m).
    pub distance: f64,
    /// The statistics of the simulated reads.
    pub stats: Stats,
    /// Names of the figures outside their band (a missing value counts as outside).
    pub outside: Vec<&'static str>,
}

/// Runs the rail replica at `distance` from the scenario in `dir`, with `reader_model` if
/// given.
pub fn run_setup(dir: &Path, distance: f64, reader_model: Option<&str>) -> Result<Outcome, String> {
    let path = dir.join(format!("rail-{distance:.2}.json"));
    let text = std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
    let scenario = Scenario::from_json_with(&text, dir, reader_model)
        .map_err(|e| format!("{}: {e}", path.display()))?;
    let layout = layout(&scenario, distance)?;
    let seconds = layout.parks.last().map_or(0.0, |p| p.to_us as f64 * 1e-6);
    let run = simulate_with(&scenario, seconds, Inventory::default());
    let stats = stats::compute(&run.reads, &layout);
    let setup = DISTANCES
        .iter()
        .position(|&d| (d - distance).abs() < 1e-9)
        .unwrap_or(0);
    let outside = FIGURES
        .iter()
        .filter(|f| !(f.get)(&stats).is_some_and(|v| f.band.holds(v, setup)))
        .map(|f| f.name)
        .collect();
    Ok(Outcome {
        distance,
        stats,
        outside,
    })
}

/// The parks of the scenario's recorded antenna (runs of equal positions) and the tags'
/// nominal places at `distance`.
fn layout(s: &Scenario, distance: f64) -> Result<Layout, String> {
    let antenna = s
        .readers
        .first()
        .and_then(|r| r.antennas.first())
        .ok_or("the rail scenario has no antenna")?;
    let Mount::Recorded { poses, .. } = &antenna.mount else {
        return Err("the rail scenario's antenna is not a recorded mount".to_string());
    };
    let mut parks = Vec::new();
    for w in poses.windows(2) {
        let (a, b) = (&w[0], &w[1]);
        if (a.x, a.y, a.z) == (b.x, b.y, b.z) {
            parks.push(Park {
                // A read stamped at the very start or end belongs to the move.
                from_us: (a.t_s * 1e6).round() as u64 + 1,
                to_us: (b.t_s * 1e6).round() as u64 - 1,
                at: [a.x, a.y, a.z],
            });
        }
    }
    let first = poses.first().ok_or("no poses")?;
    let yaw = first.yaw_deg.to_radians();
    let pitch = first.pitch_deg.to_radians();
    let boresight = [
        yaw.cos() * pitch.cos(),
        yaw.sin() * pitch.cos(),
        pitch.sin(),
    ];
    if s.tags.len() != NOMINAL_X.len() {
        return Err(format!(
            "the rail scenario has {} tags, not 3",
            s.tags.len()
        ));
    }
    let tags = s
        .tags
        .iter()
        .zip(NOMINAL_X)
        .map(|(t, x)| {
            (
                t.epc.to_ascii_uppercase(),
                [x, first.y + distance, t.position[2]],
            )
        })
        .collect();
    Ok(Layout {
        parks,
        tags,
        boresight,
    })
}

/// `llrp-gateway bench realism`: every setup's table, exit 1 on an error.
pub fn run(args: BenchRealismArgs) -> ExitCode {
    let mut outcomes = Vec::new();
    for d in DISTANCES {
        match run_setup(&args.dir, d, args.reader_model.as_deref()) {
            Ok(o) => outcomes.push(o),
            Err(e) => {
                eprintln!("bench realism: {e}");
                return ExitCode::FAILURE;
            }
        }
    }
    print!("{}", table(&outcomes));
    ExitCode::SUCCESS
}

/// The Markdown table: each figure, real, and per setup the simulated value with ✗ outside.
pub fn table(outcomes: &[Outcome]) -> String {
    let mut out = String::from("| statistic | real (0.88 / 0.68 / 0.51 m) |");
    for o in outcomes {
        out.push_str(&format!(" simulated {:.2} m | band |", o.distance));
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
