//! The `bench localize` command line: the table of errors and compute times, and the plot.

use std::path::PathBuf;
use std::process::ExitCode;

use super::bench::{
    applicable, duration_s, score_on, simulate_with, why_not, Inventory, PoseSource, Scores,
};
use crate::localize::estimate::Estimator;
use crate::scenario::Scenario;

/// `llrp-gateway bench localize`.
#[derive(Clone, Debug, clap::Args)]
pub struct BenchLocalizeArgs {
    /// `S1` (the embedded default), `S2` (\[A\]'s side-by-side banners), `S2-back-to-back`,
    /// `S3`, or a scenario file.
    #[arg(long, default_value = "S1")]
    pub scenario: String,
    /// Simulated seconds (default: until the slowest robot has driven its path, + 2 s).
    #[arg(long, value_parser = crate::options::parser::<f64>("seconds"))]
    pub seconds: Option<f64>,
    /// Write the plot of truth against the `relock` estimates here (PNG).
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Offer the reads to a live localizer with its HTTP API at this multiple of real time
    /// and measure the read-to-HTTP latency of its updates; 0 skips it.
    #[arg(long, default_value = "10", value_parser = crate::options::parser::<f64>("live-speed"))]
    pub live_speed: f64,
    /// Runs per Monte-Carlo variant of S3 (σ_φ, odometry K, swarm size); 0 skips them.
    #[arg(long, default_value = "20", value_parser = crate::options::parser::<usize>("runs"))]
    pub runs: usize,
    /// RF mode (ModeIndex of the reader's mode table) the benchmark's client asks for;
    /// default: the reader's own (1000).
    #[arg(long, value_parser = crate::options::parser::<u16>("mode"))]
    pub mode: Option<u16>,
    /// Gen2 session (0–3) the benchmark's client asks for; default: the reader's own (2).
    #[arg(long, value_parser = crate::options::parser::<u8>("session"))]
    pub session: Option<u8>,
    /// Runs of each row's localization; the compute time is the best of them (a shared
    /// host's noise).
    #[arg(long, default_value = "1", value_parser = crate::options::parser::<u32>("repeat"))]
    pub repeat: u32,
    /// Only these estimators (repeatable; default: every one that applies).
    #[arg(long = "estimator")]
    pub estimators: Vec<Estimator>,
    /// Set aside reads weaker than this (dBm), as the settings file's `min_rssi_dbm` does.
    #[arg(long, allow_hyphen_values = true, value_parser = crate::options::parser::<f64>("min-rssi"))]
    pub min_rssi: Option<f64>,
    /// Run the scenario with this reader model (`ideal`, `impinj-r420`; docs/measurement.md
    /// "Reader models"); default: the scenario's own.
    #[arg(long)]
    pub reader_model: Option<String>,
}

/// The scenario `name` (a fixture's name or a file).
pub fn scenario(name: &str) -> Result<Scenario, String> {
    scenario_with(name, None)
}

/// The scenario `name` (a fixture's name or a file), run with the reader model `model` when
/// given (docs/measurement.md "Reader models").
pub fn scenario_with(name: &str, model: Option<&str>) -> Result<Scenario, String> {
    let embedded = match name.to_ascii_uppercase().as_str() {
        "S1" => return Scenario::default_s1_with(model).map_err(|e| format!("{name}: {e}")),
        "S2" => include_str!("../../fixtures/scenarios/s2-side-by-side.json"),
        "S2-BACK-TO-BACK" => include_str!("../../fixtures/scenarios/s2-back-to-back.json"),
        "S3" => include_str!("../../fixtures/scenarios/s3.json"),
        _ => {
            return Scenario::load_with(std::path::Path::new(name), model)
                .map_err(|e| format!("{name}: {e}"))
        }
    };
    Scenario::from_json_with(embedded, std::path::Path::new("."), model)
        .map_err(|e| format!("{name}: {e}"))
}

/// Runs `bench localize`.
pub fn run(args: BenchLocalizeArgs) -> ExitCode {
    let s = match scenario_with(&args.scenario, args.reader_model.as_deref()) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("llrp-gateway bench localize: {e}");
            return ExitCode::FAILURE;
        }
    };
    if let Some(m) = args.mode {
        if !crate::reader::caps::RF_MODES.contains(&u32::from(m)) {
            eprintln!(
                "llrp-gateway bench localize: --mode {m}: not in the reader's RF mode table {:?}",
                crate::reader::caps::RF_MODES
            );
            return ExitCode::FAILURE;
        }
    }
    if let Some(v) = args.min_rssi.filter(|v| !v.is_finite()) {
        eprintln!("llrp-gateway bench localize: --min-rssi {v}: not a finite number");
        return ExitCode::FAILURE;
    }
    let seconds = args.seconds.unwrap_or_else(|| duration_s(&s));
    eprintln!(
        "llrp-gateway bench localize: scenario '{}', {seconds:.0} s simulated...",
        s.name
    );
    let started = std::time::Instant::now();
    let inventory = Inventory {
        mode: args.mode,
        session: args.session,
    };
    let mut run = simulate_with(&s, seconds, inventory);
    run.settings.min_rssi_dbm = args.min_rssi;
    let tags = run.truth.iter().filter(|t| !t.2).count();
    println!(
        "Scenario '{}': {} reads of {} tags ({} reference tags) in {seconds:.0} s simulated ({:.1} s to simulate)\n",
        s.name,
        run.reads.len(),
        tags,
        run.truth.len() - tags,
        started.elapsed().as_secs_f64()
    );
    if let Some(floor) = args.min_rssi {
        let weak = run
            .reads
            .iter()
            .filter(|r| crate::localize::ingest::under_floor(r, Some(floor)))
            .count();
        println!(
            "Reads weaker than {floor} dBm set aside: {weak} of {}\n",
            run.reads.len()
        );
    }
    for &e in &args.estimators {
        if let Some(why) = why_not(&run, e) {
            eprintln!(
                "llrp-gateway bench localize: {e} does not apply to '{}': {why}",
                s.name
            );
        }
    }
    if !args.estimators.is_empty() && args.estimators.iter().all(|&e| why_not(&run, e).is_some()) {
        return ExitCode::FAILURE;
    }
    println!("| estimator | poses | located | mean (mm) | median (mm) | max (mm) | std (mm) | 95 % ellipse holds | compute (ms) |");
    println!("|---|---|---|---|---|---|---|---|---|");
    let mut relock: Vec<Scores> = Vec::new();
    let references = !run.settings.geometry.references.is_empty();
    let mut rows: Vec<(Estimator, bool)> = applicable(&run)
        .into_iter()
        .filter(|e| args.estimators.is_empty() || args.estimators.contains(e))
        .map(|e| (e, true))
        .collect();
    if references {
        // relock also without the antenna calibration the references give it.
        if let Some(i) = rows.iter().position(|r| r.0 == Estimator::Relock) {
            rows.insert(i + 1, (Estimator::Relock, false));
        }
    }
    let mut sources = vec![PoseSource::True, PoseSource::Estimated];
    if run.pose_error.is_some() {
        sources.push(PoseSource::Refined);
    }
    for (e, told) in rows {
        for &source in &sources {
            let mut sc = score_on(&run, e, source, told);
            for _ in 1..args.repeat {
                sc.seconds = sc.seconds.min(score_on(&run, e, source, told).seconds);
            }
            let mm = |v: f64| {
                if v.is_finite() {
                    format!("{:.1}", v * 1e3)
                } else {
                    "–".into()
                }
            };
            let name = match (e, told) {
                (Estimator::Relock, true) if references => "relock (calibrated)".to_string(),
                (Estimator::Relock, false) => "relock (not calibrated)".to_string(),
                _ => e.to_string(),
            };
            println!(
                "| {} | {} | {}/{} | {} | {} | {} | {} | {}/{} | {:.1} |",
                name,
                sc.poses,
                sc.located,
                sc.read,
                mm(sc.mean),
                mm(sc.median),
                mm(sc.max),
                mm(sc.std),
                sc.covered,
                sc.with_covariance,
                sc.seconds * 1e3
            );
            if e == Estimator::Relock && told && source != PoseSource::Refined {
                relock.push(sc);
            }
        }
    }
    println!("\nError in (x, y, z) for 3D estimates (loci3d, fingerprint, and relock with antennas at several heights), in (x, y) for 2D ones (the tags at the height assumed). Compute: filing the reads into series and estimating every tag, reads in memory, one core.");
    if references {
        println!("relock (calibrated): the offsets between antennas measured on the reference tags; (not calibrated): the references not told to relock.");
    }
    if args.live_speed > 0.0 {
        match super::live::measure(&run, args.live_speed) {
            Ok(l) => println!(
                "\nLive (relock, true poses, the reads offered at {}x real time, {:.0} reads/s): {} estimate updates over HTTP (/api/events); read-to-HTTP latency p50 {:.1} ms, p99 {:.1} ms, max {:.1} ms; {} inputs dropped.",
                args.live_speed,
                run.reads.len() as f64 / run.seconds * args.live_speed,
                l.updates,
                l.p50 * 1e3,
                l.p99 * 1e3,
                l.max * 1e3,
                l.dropped
            ),
            Err(e) => {
                eprintln!("llrp-gateway bench localize: live: {e}");
                return ExitCode::FAILURE;
            }
        }
    }
    if args.scenario.eq_ignore_ascii_case("S3") && args.runs > 0 {
        println!(
            "\nS3 Monte-Carlo variants ({} runs each: own random paths and noise seed per run; odometry-only poses; error of the final estimate):\n",
            args.runs
        );
        println!(
            "| variant | estimator | located | mean (mm) | median (mm) | 95 % ellipse holds |"
        );
        println!("|---|---|---|---|---|---|");
        let base = include_str!("../../fixtures/scenarios/s3.json");
        for v in super::montecarlo::variants() {
            match super::montecarlo::run_variant(base, &v, args.runs) {
                Ok(o) => println!(
                    "| {} | {} | {}/{} | {:.1} | {:.1} | {}/{} |",
                    v.name,
                    o.estimator,
                    o.located,
                    o.runs,
                    o.mean * 1e3,
                    o.median * 1e3,
                    o.covered,
                    o.with_covariance
                ),
                Err(e) => {
                    eprintln!("llrp-gateway bench localize: S3 {}: {e}", v.name);
                    return ExitCode::FAILURE;
                }
            }
        }
    }
    if let (Some(path), [t, e]) = (&args.plot, relock.as_slice()) {
        let title = format!("{}: truth and relock estimates", s.name);
        if let Err(err) = super::plot::plot(path, &title, &run, t, e) {
            eprintln!("llrp-gateway bench localize: {}: {err}", path.display());
            return ExitCode::FAILURE;
        }
        eprintln!(
            "llrp-gateway bench localize: plot written to {}",
            path.display()
        );
    }
    ExitCode::SUCCESS
}
