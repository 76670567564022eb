//! `llrp-gateway bench`: `localize` (a scenario simulated faster than real time, localized by
//! every applicable estimator, scored against the truth), `realism` (the parked-rail replica
//! of a real Impinj measurement) and `readrate` (the read rate against the tags in the field):
//! their arguments, the tables they print on standard output, and their errors. The
//! evaluations themselves: [`crate::eval`], [`crate::realism`].

use std::path::PathBuf;

use clap::Subcommand;

use crate::eval::bench::{
    applicable, duration_s, scenario_with, score_on, simulate_with, why_not, Inventory, PoseSource,
    Run, Scores,
};
use crate::eval::readrate::{rate, MODES, POPULATIONS, PUBLISHED};
use crate::localize::estimate::Estimator;
use crate::realism::DISTANCES;
use crate::scenario::Scenario;

/// `llrp-gateway bench`'s commands.
#[derive(Subcommand)]
pub enum BenchCommand {
    /// Simulate a scenario faster than real time and localize it with every applicable
    /// estimator: errors against the truth and compute times.
    Localize(BenchLocalizeArgs),
    /// Run the parked-rail replica of a real Impinj measurement and print its reads'
    /// statistics beside the real ones (docs/measurement.md "Validation").
    Realism(BenchRealismArgs),
    /// The simulated reader's read rate against the tags in the field, per RF mode, beside
    /// published measurements (docs/measurement.md "Read rate against population").
    Readrate(BenchReadRateArgs),
}

/// `llrp-gateway bench localize`.
#[derive(Clone, Debug, clap::Args)]
pub struct BenchLocalizeArgs {
    /// `S1` (the embedded default), `S2` (\[A\]'s side-by-side banners), `S2-back-to-back`,
    /// `S3`, or a scenario file.
    #[arg(long, default_value = "S1")]
    pub scenario: String,
    /// Simulated seconds (default: until the slowest robot has driven its path, + 2 s).
    #[arg(long, value_parser = crate::cli::options::parser::<f64>("seconds"))]
    pub seconds: Option<f64>,
    /// Write the plot of truth against the `relock` estimates here (PNG).
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Offer the reads to a live localizer with its HTTP API at this multiple of real time
    /// and measure the read-to-HTTP latency of its updates; 0 skips it.
    #[arg(long, default_value = "10", value_parser = crate::cli::options::parser::<f64>("live-speed"))]
    pub live_speed: f64,
    /// Runs per Monte-Carlo variant of S3 (σ_φ, odometry K, swarm size); 0 skips them.
    #[arg(long, default_value = "20", value_parser = crate::cli::options::parser::<usize>("runs"))]
    pub runs: usize,
    /// RF mode (ModeIndex of the reader's mode table) the benchmark's client asks for;
    /// default: the reader's own (1000).
    #[arg(long, value_parser = crate::cli::options::parser::<u16>("mode"))]
    pub mode: Option<u16>,
    /// Gen2 session (0–3) the benchmark's client asks for; default: the reader's own (2).
    #[arg(long, value_parser = crate::cli::options::parser::<u8>("session"))]
    pub session: Option<u8>,
    /// Runs of each row's localization; the compute time is the best of them (a shared
    /// host's noise).
    #[arg(long, default_value = "1", value_parser = crate::cli::options::parser::<u32>("repeat"))]
    pub repeat: u32,
    /// Only these estimators (repeatable; default: every one that applies).
    #[arg(long = "estimator")]
    pub estimators: Vec<Estimator>,
    /// Set aside reads weaker than this (dBm), as the settings file's `min_rssi_dbm` does.
    #[arg(long, allow_hyphen_values = true, value_parser = crate::cli::options::parser::<f64>("min-rssi"))]
    pub min_rssi: Option<f64>,
    /// Run the scenario with this reader model (`ideal`, `impinj-r420`,
    /// `impinj-r420-stationary`; docs/measurement.md "Reader models"); default: the
    /// scenario's own.
    #[arg(long)]
    pub reader_model: Option<String>,
}

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
    /// Run this parked-aperture scenario instead of the three rail setups (its tags' own
    /// positions taken as nominal).
    #[arg(long, conflicts_with = "reads")]
    pub scenario: Option<PathBuf>,
    /// Score this reads file (JSON Lines, as `inventory` writes) instead of simulating: the
    /// statistics of real reads of a parked aperture, with `--layout`.
    #[arg(long, requires = "layout")]
    pub reads: Option<PathBuf>,
    /// The reads file's geometry: `{"parks": [{"from_us", "to_us", "at"}], "tags": [["EPC",
    /// [x, y, z]]], "boresight": [x, y, z]}`.
    #[arg(long, requires = "reads")]
    pub layout: Option<PathBuf>,
}

/// Arguments of `bench readrate`.
#[derive(clap::Args, Debug)]
pub struct BenchReadRateArgs {
    /// Simulated seconds per point.
    #[arg(long, default_value_t = 10.0, value_parser = crate::cli::options::parser::<f64>("seconds"))]
    pub seconds: f64,
    /// Reader model the field is read with (docs/measurement.md "Reader models").
    #[arg(long, default_value = "impinj-r420")]
    pub reader_model: String,
    /// Also draw the curves and the published points to this PNG.
    #[arg(long)]
    pub plot: Option<PathBuf>,
}

/// Why `bench localize` failed.
#[derive(Debug, thiserror::Error)]
pub enum BenchLocalizeError {
    /// The scenario cannot be had (the message names it and why).
    #[error("{0}")]
    Scenario(String),
    /// `--mode` is not one of the simulated reader's RF modes.
    #[error("--mode {0}: not in the reader's RF mode table {modes:?}", modes = crate::reader::caps::RF_MODES)]
    Mode(u16),
    /// `--min-rssi` is not a finite number.
    #[error("--min-rssi {0}: not a finite number")]
    MinRssi(f64),
    /// None of the `--estimator`s applies to the scenario: why each does not (`; ` between
    /// them).
    #[error("{}", .0.join("; "))]
    NotApplicable(Vec<String>),
    /// The live measurement failed.
    #[error("live: {0}")]
    Live(String),
    /// A Monte-Carlo variant of S3 failed.
    #[error("S3 {variant}: {message}")]
    Variant {
        /// The variant.
        variant: String,
        /// Why.
        message: String,
    },
    /// The plot could not be written.
    #[error("{}: {message}", path.display())]
    Plot {
        /// `--plot`.
        path: PathBuf,
        /// Why.
        message: String,
    },
}

/// Runs `bench localize`: the table of errors and compute times, the live latency, the S3
/// Monte-Carlo variants and the plot, each as asked.
pub fn localize(args: BenchLocalizeArgs) -> Result<(), BenchLocalizeError> {
    let s = checked_scenario(&args)?;
    let seconds = args.seconds.unwrap_or_else(|| duration_s(&s));
    eprintln!(
        "llrp-gateway bench localize: scenario '{}', {seconds:.0} s simulated...",
        s.name
    );
    let run = simulate(&args, &s, seconds);
    estimators_apply(&args, &run, &s)?;
    let relock = table(&args, &run);
    if args.live_speed > 0.0 {
        live(&args, &run)?;
    }
    if args.scenario.eq_ignore_ascii_case("S3") && args.runs > 0 {
        variants(args.runs)?;
    }
    if let (Some(path), [t, e]) = (&args.plot, relock.as_slice()) {
        let title = format!("{}: truth and relock estimates", s.name);
        crate::eval::plot::plot(path, &title, &run, t, e).map_err(|message| {
            BenchLocalizeError::Plot {
                path: path.clone(),
                message,
            }
        })?;
        eprintln!(
            "llrp-gateway bench localize: plot written to {}",
            path.display()
        );
    }
    Ok(())
}

/// The scenario, `--mode` and `--min-rssi` checked.
fn checked_scenario(args: &BenchLocalizeArgs) -> Result<Scenario, BenchLocalizeError> {
    let s = scenario_with(&args.scenario, args.reader_model.as_deref())
        .map_err(BenchLocalizeError::Scenario)?;
    if let Some(m) = args.mode {
        if !crate::reader::caps::RF_MODES.contains(&u32::from(m)) {
            return Err(BenchLocalizeError::Mode(m));
        }
    }
    if let Some(v) = args.min_rssi.filter(|v| !v.is_finite()) {
        return Err(BenchLocalizeError::MinRssi(v));
    }
    Ok(s)
}

/// Simulates `s` for `seconds`, printing what was read.
fn simulate(args: &BenchLocalizeArgs, s: &Scenario, seconds: f64) -> Run {
    let started = std::time::Instant::now();
    let inventory = Inventory {
        mode: args.mode,
        session: args.session,
    };
    let mut run = simulate_with(s, seconds, inventory);
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
    run
}

/// Says which `--estimator`s do not apply to the scenario, and why; an error when none does.
fn estimators_apply(
    args: &BenchLocalizeArgs,
    run: &Run,
    s: &Scenario,
) -> Result<(), BenchLocalizeError> {
    let reasons: Vec<String> = args
        .estimators
        .iter()
        .filter_map(|&e| {
            why_not(run, e).map(|why| format!("{e} does not apply to '{}': {why}", s.name))
        })
        .collect();
    if !args.estimators.is_empty() && reasons.len() == args.estimators.len() {
        return Err(BenchLocalizeError::NotApplicable(reasons));
    }
    for r in reasons {
        eprintln!("llrp-gateway bench localize: {r}");
    }
    Ok(())
}

/// Prints the table (a row per estimator and pose source) and its notes; the `relock` rows
/// with true and estimated poses, for the plot.
fn table(args: &BenchLocalizeArgs, run: &Run) -> Vec<Scores> {
    println!("| estimator | poses | located | mean (mm) | median (mm) | max (mm) | std (mm) | 95 % ellipse holds | compute (ms) |");
    println!("|---|---|---|---|---|---|---|---|---|");
    let mut relock: Vec<Scores> = Vec::new();
    let references = !run.settings.geometry.references.is_empty();
    let mut rows: Vec<(Estimator, bool)> = applicable(run)
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
            let mut sc = score_on(run, e, source, told);
            for _ in 1..args.repeat {
                sc.seconds = sc.seconds.min(score_on(run, e, source, told).seconds);
            }
            row(e, told, references, &sc);
            if e == Estimator::Relock && told && source != PoseSource::Refined {
                relock.push(sc);
            }
        }
    }
    println!("\nError in (x, y, z) for 3D estimates (loci3d, fingerprint, and relock with antennas at several heights), in (x, y) for 2D ones (the tags at the height assumed). Compute: filing the reads into series and estimating every tag, reads in memory, one core.");
    if references {
        println!("relock (calibrated): the offsets between antennas measured on the reference tags; (not calibrated): the references not told to relock.");
    }
    relock
}

/// Prints one row of the table: `e` (`told`: with the reference tags' calibration) scored.
fn row(e: Estimator, told: bool, references: bool, sc: &Scores) {
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
}

/// The live localizer's read-to-HTTP latency on `run` at `speed`: the localizer and its API
/// on a loopback port built by the composition root, the measurement by `eval::live`.
fn live_latency(run: &Run, speed: f64) -> Result<crate::eval::live::Latency, String> {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .map_err(|e| e.to_string())?;
    rt.block_on(async {
        let consumers = super::root::Consumers::start(super::root::Plan {
            command: "bench localize",
            http: Some(("127.0.0.1:0".into(), true)),
            http_args: &crate::http::launch::LaunchOptions::default(),
            simulation: false,
            settings: crate::eval::live::settings(run),
            prime: Vec::new(),
            publish: &crate::fleet::args::PublishConfig::default(),
            references: Default::default(),
            headless: false,
            gpio: None,
            faults: None,
        })
        .await
        .map_err(|e| e.to_string())?;
        let measured = match (consumers.live(), consumers.http_addr()) {
            (Some(live), Some(addr)) => crate::eval::live::measure(run, speed, live, addr).await,
            _ => Err("no HTTP port".to_string()),
        };
        consumers.stop().await;
        measured
    })
}

/// Measures and prints the live localizer's read-to-HTTP latency.
fn live(args: &BenchLocalizeArgs, run: &Run) -> Result<(), BenchLocalizeError> {
    let l = live_latency(run, args.live_speed).map_err(BenchLocalizeError::Live)?;
    println!(
        "\nLive (relock, true poses, the reads offered at {}x real time, {:.0} reads/s): {} estimate updates over HTTP (/api/events); read-to-HTTP latency p50 {:.1} ms, p99 {:.1} ms, max {:.1} ms; {} inputs dropped.",
        args.live_speed,
        run.reads.len() as f64 / run.seconds * args.live_speed,
        l.updates,
        l.p50 * 1e3,
        l.p99 * 1e3,
        l.max * 1e3,
        l.dropped
    );
    Ok(())
}

/// Runs and prints the Monte-Carlo variants of S3, `runs` runs each.
fn variants(runs: usize) -> Result<(), BenchLocalizeError> {
    use crate::eval::montecarlo;
    println!(
        "\nS3 Monte-Carlo variants ({runs} runs each: own random paths and noise seed per run; odometry-only poses; error of the final estimate):\n"
    );
    println!("| variant | estimator | located | mean (mm) | median (mm) | 95 % ellipse holds |");
    println!("|---|---|---|---|---|---|");
    let base = include_str!("../../fixtures/scenarios/s3.json");
    for v in montecarlo::variants() {
        let o = montecarlo::run_variant(base, &v, runs).map_err(|message| {
            BenchLocalizeError::Variant {
                variant: v.name.to_string(),
                message,
            }
        })?;
        println!(
            "| {} | {} | {}/{} | {:.1} | {:.1} | {}/{} |",
            v.name,
            o.estimator,
            o.located,
            o.runs,
            o.mean * 1e3,
            o.median * 1e3,
            o.covered,
            o.with_covariance
        );
    }
    Ok(())
}

/// Why `bench realism` failed.
#[derive(Debug, thiserror::Error)]
pub enum BenchRealismError {
    /// The reads file or its layout cannot be read (the message names the file).
    #[error("{0}")]
    Reads(String),
    /// The scenario of `--scenario` or of a rail setup cannot be run (the message names the
    /// file).
    #[error("{0}")]
    Scenario(String),
}

/// Runs `bench realism`: the table of the reads file, the scenario, or every rail setup.
pub fn realism(args: BenchRealismArgs) -> Result<(), BenchRealismError> {
    use crate::realism::{run_scenario, run_setup, score_file, table};
    let model = args.reader_model.as_deref();
    let outcomes = if let (Some(reads), Some(layout)) = (&args.reads, &args.layout) {
        vec![score_file(reads, layout).map_err(BenchRealismError::Reads)?]
    } else if let Some(path) = &args.scenario {
        vec![run_scenario(path, model).map_err(BenchRealismError::Scenario)?]
    } else {
        DISTANCES
            .iter()
            .map(|&d| run_setup(&args.dir, d, model))
            .collect::<Result<_, _>>()
            .map_err(BenchRealismError::Scenario)?
    };
    print!("{}", table(&outcomes));
    Ok(())
}

/// Why `bench readrate` failed.
#[derive(Debug, thiserror::Error)]
pub enum BenchReadRateError {
    /// A field of tags could not be made into a scenario.
    #[error("{0}")]
    Field(String),
    /// The plot could not be written.
    #[error("{0}")]
    Plot(String),
}

/// Runs `bench readrate`: the rate per mode and tag count beside the published ones.
pub fn readrate(args: BenchReadRateArgs) -> Result<(), BenchReadRateError> {
    let mut curves = Vec::new();
    for (mode, _) in MODES {
        let mut points = Vec::new();
        for n in POPULATIONS {
            let r = rate(n, mode, &args.reader_model, args.seconds)
                .map_err(BenchReadRateError::Field)?;
            points.push((n, r));
        }
        curves.push(points);
    }
    println!(
        "Reads/s of all tags together (and of each tag), one antenna, a continuous AISpec, \
         reader model {}, {} s simulated a point:\n",
        args.reader_model, args.seconds
    );
    let head: Vec<&str> = MODES.iter().map(|m| m.1).collect();
    println!("| tags | {} |", head.join(" | "));
    println!("|---:|{}", "---:|".repeat(MODES.len()));
    for (k, n) in POPULATIONS.iter().enumerate() {
        let cells: Vec<String> = curves
            .iter()
            .map(|c| format!("{:.0} ({:.1})", c[k].1, c[k].1 / *n as f64))
            .collect();
        println!("| {n} | {} |", cells.join(" | "));
    }
    println!("\nPublished (conditions differ; docs/measurement.md):\n");
    println!("| tags | reads/s (a tag) | reader, conditions, source |\n|---:|---:|---|");
    for p in &PUBLISHED {
        println!(
            "| {} | {:.0} ({:.1}) | {} |",
            p.tags,
            p.reads_per_s,
            p.reads_per_s / p.tags as f64,
            p.source
        );
    }
    if let Some(path) = &args.plot {
        crate::eval::readrate::plot(path, &curves).map_err(BenchReadRateError::Plot)?;
        println!("\nPlot: {}", path.display());
    }
    Ok(())
}
