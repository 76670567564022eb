//! The `llrp-gateway` command line.

use std::io::{Read, Write};
use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use llrp_gateway::decode::{decode_stream, DecodeOptions};
use llrp_gateway::net::clock::Speed;
use llrp_gateway::scenario::Scenario;
use llrp_gateway::sim::{self, SimOptions};
use llrp_gateway::stop::StopSignal;

#[derive(Parser)]
#[command(
    name = "llrp-gateway",
    version,
    about = "Point your LLRP reader software here: a simulated Impinj-class reader (sim), a \
             gateway to real readers (proxy, replay, inventory, export, import) and a tag \
             localizer (localize), with a live map over HTTP",
    long_about = None
)]
struct Cli {
    /// Log lines as text (coloured on a terminal unless NO_COLOR is set) or as JSON objects.
    #[arg(long, global = true, value_enum, default_value_t = llrp_gateway::stop::LogFormat::Text)]
    log_format: llrp_gateway::stop::LogFormat,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Simulated reader: serve LLRP for a scenario's readers (default: the embedded
    /// warehouse S1), with a live map of the tags it localizes.
    Sim {
        /// Scenario file (JSON); without it the embedded default scenario S1 runs.
        #[arg(long)]
        scenario: Option<PathBuf>,
        /// Read as this reader model does (`ideal`, `impinj-r420`: as a real Impinj reader;
        /// docs/measurement.md "Reader models"), in place of the scenario's own.
        #[arg(long)]
        reader_model: Option<String>,
        /// Listen address, overriding the scenario's; repeat for each reader in order.
        #[arg(long)]
        listen: Vec<String>,
        /// Simulated time per real time: a factor (1 = real time) or `max` (as fast as the
        /// client takes reports).
        #[arg(long, default_value = "1")]
        speed: Speed,
        /// Write ground truth (tag positions, antenna poses over time) to this JSONL file.
        #[arg(long)]
        truth: Option<PathBuf>,
        /// Replace an existing truth file (without it, an existing file is refused).
        #[arg(long, requires = "truth")]
        force: bool,
        /// Record every session to this file (one file per reader, `FILE-NAME`, when the
        /// scenario has several), as the proxy does (docs/recordings.md).
        #[arg(long)]
        record: Option<PathBuf>,
        /// Start a numbered next recording file once a file would pass this many bytes.
        #[arg(long, value_name = "BYTES", value_parser = llrp_gateway::options::parser::<u64>("record-max-bytes"))]
        record_max_bytes: Option<u64>,
        /// Serve LLRP over TLS with this certificate chain (PEM) on every reader's address
        /// (port 5085 by convention: choose it with --listen); see docs/tls.md.
        #[arg(long, requires = "tls_key")]
        tls_cert: Option<PathBuf>,
        /// The TLS certificate's private key (PEM).
        #[arg(long, requires = "tls_cert")]
        tls_key: Option<PathBuf>,
        /// The HTTP API and live map (default 127.0.0.1:8080; docs/http.md).
        #[command(flatten)]
        http: llrp_gateway::http::launch::HttpArgs,
        /// Antenna poses the localizer is given: `truth`, or `estimated` (what the robot
        /// itself would report).
        #[arg(long, value_enum, default_value_t = llrp_gateway::sim::PoseSource::Estimated)]
        poses: llrp_gateway::sim::PoseSource,
        /// Time between two pose samples of each antenna, as a robot publishes its pose
        /// (ms; 100 is 10 Hz).
        #[arg(long, value_name = "MS", default_value_t = 100, value_parser = llrp_gateway::options::parser::<u64>("pose-interval-ms"))]
        pose_interval_ms: u64,
        /// Do not stamp each read with its antenna's pose at the read (the localizer and
        /// MQTT workers then wait for a pose sample at or after each read).
        #[arg(long)]
        no_read_poses: bool,
        /// The localizer's estimator (docs/localize.md).
        #[arg(long, default_value = "relock")]
        estimator: llrp_gateway::localize::estimate::Estimator,
        /// Publishing to an MQTT broker (docs/fleet.md).
        #[command(flatten)]
        publish: llrp_gateway::fleet::args::PublishArgs,
    },
    /// Gateway: forward clients to a real reader byte for byte, recording the sessions.
    Proxy(llrp_gateway::gateway::ProxyArgs),
    /// Gateway: serve a recording to a client as the reader did.
    Replay(llrp_gateway::gateway::ReplayArgs),
    /// Gateway: inventory an LLRP reader and write its tag reads (docs/client.md).
    Inventory(llrp_gateway::inventory::InventoryArgs),
    /// Gateway: write a recording as a pcapng capture that Wireshark dissects as LLRP.
    Export(llrp_gateway::record::pcapng::ExportArgs),
    /// Gateway: turn the LLRP streams of a pcap or pcapng capture into a recording.
    Import(llrp_gateway::record::pcapng::ImportArgs),
    /// Localizer: locate every tag of a recording or a reads file (docs/localize.md).
    Localize(llrp_gateway::cli::localize::LocalizeArgs),
    /// Tool: decode LLRP frames and print one JSON object per message (docs/codec.md).
    Decode {
        /// Input file with LLRP frames; `-` or nothing reads standard input.
        file: Option<PathBuf>,
        /// The input is hex text (whitespace allowed) instead of raw bytes.
        #[arg(long)]
        hex: bool,
        /// Re-encode each message and fail if the bytes differ from the input.
        #[arg(long)]
        roundtrip: bool,
    },
    /// Benchmarks (docs/benchmarks.md).
    #[command(subcommand)]
    Bench(BenchCommand),
}

#[derive(Subcommand)]
enum BenchCommand {
    /// Simulate a scenario faster than real time and localize it with every applicable
    /// estimator: errors against the truth and compute times.
    Localize(llrp_gateway::eval::cli::BenchLocalizeArgs),
    /// Run the parked-rail replica of a real Impinj measurement and print its reads'
    /// statistics beside the real ones (docs/measurement.md "Validation").
    Realism(llrp_gateway::realism::BenchRealismArgs),
    /// The simulated reader's read rate against the tags in the field, per RF mode, beside
    /// published measurements (docs/measurement.md "Read rate against population").
    Readrate(llrp_gateway::eval::readrate::BenchReadRateArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    llrp_gateway::stop::set_log_format(cli.log_format);
    match cli.command {
        Command::Inventory(args) => llrp_gateway::inventory::run(args),
        Command::Export(args) => llrp_gateway::record::pcapng::run_export(&args),
        Command::Import(args) => llrp_gateway::record::pcapng::run_import(&args),
        Command::Localize(args) => llrp_gateway::cli::localize::run(args),
        Command::Bench(BenchCommand::Localize(args)) => llrp_gateway::eval::cli::run(args),
        Command::Bench(BenchCommand::Realism(args)) => llrp_gateway::realism::run(args),
        Command::Bench(BenchCommand::Readrate(args)) => llrp_gateway::eval::readrate::run(args),
        Command::Sim {
            scenario,
            reader_model,
            listen,
            speed,
            truth,
            force,
            record,
            record_max_bytes,
            tls_cert,
            tls_key,
            http,
            poses,
            pose_interval_ms,
            no_read_poses,
            estimator,
            publish,
        } => run_sim(
            scenario,
            reader_model.as_deref(),
            SimLocalize {
                http,
                poses,
                pose_interval_ms,
                read_poses: !no_read_poses,
                estimator,
                publish,
            },
            SimOptions {
                listen,
                speed,
                truth,
                force,
                record,
                record_options: llrp_gateway::record::RecordOptions {
                    max_bytes: record_max_bytes,
                },
                tls: tls_cert
                    .zip(tls_key)
                    .map(|(cert, key)| llrp_gateway::net::tls::ServerFiles { cert, key }),
                localize: None,
                ..SimOptions::default()
            },
        ),
        Command::Proxy(args) => llrp_gateway::gateway::run(args),
        Command::Replay(args) => llrp_gateway::gateway::run_replay(args),
        Command::Decode {
            file,
            hex,
            roundtrip,
        } => {
            let mut input = Vec::new();
            let read = match file.as_deref() {
                None => std::io::stdin().read_to_end(&mut input),
                Some(p) if p.as_os_str() == "-" => std::io::stdin().read_to_end(&mut input),
                Some(p) => std::fs::File::open(p).and_then(|mut f| f.read_to_end(&mut input)),
            };
            if let Err(e) = read {
                eprintln!("llrp-gateway decode: cannot read input: {e}");
                return ExitCode::FAILURE;
            }
            let stdout = std::io::stdout();
            let mut out = std::io::BufWriter::new(stdout.lock());
            let result = decode_stream(&input, DecodeOptions { hex, roundtrip }, &mut out);
            let flushed = out.flush();
            match (result, flushed) {
                (Ok(_), Ok(())) => ExitCode::SUCCESS,
                (Err(e), _) => {
                    eprintln!("llrp-gateway decode: {e}");
                    ExitCode::FAILURE
                }
                (_, Err(e)) => {
                    eprintln!("llrp-gateway decode: writing output: {e}");
                    ExitCode::FAILURE
                }
            }
        }
    }
}

/// The localizer and HTTP side of `sim`.
struct SimLocalize {
    http: llrp_gateway::http::launch::HttpArgs,
    poses: llrp_gateway::sim::PoseSource,
    pose_interval_ms: u64,
    read_poses: bool,
    estimator: llrp_gateway::localize::estimate::Estimator,
    publish: llrp_gateway::fleet::args::PublishArgs,
}

/// The EPCs of `scenario`'s reference tags.
fn scenario_references(scenario: &Scenario) -> std::collections::BTreeSet<String> {
    let world = llrp_gateway::physics::World::new(scenario);
    let model = llrp_gateway::physics::Model::in_world(&world, scenario, 0);
    (0..model.tag_count())
        .filter(|&k| scenario.tags.get(k).is_some_and(|t| t.reference))
        .map(|k| llrp_gateway::reads::hex_upper(model.tag_epc(k).as_bytes()))
        .collect()
}

/// Runs the simulated readers until Ctrl-C or SIGTERM.
fn run_sim(
    scenario: Option<PathBuf>,
    reader_model: Option<&str>,
    localize: SimLocalize,
    mut opts: SimOptions,
) -> ExitCode {
    llrp_gateway::stop::init_logging();
    let loaded = match &scenario {
        Some(path) => {
            Scenario::load_with(path, reader_model).map_err(|e| format!("{}: {e}", path.display()))
        }
        None => Scenario::default_s1_with(reader_model).map_err(|e| format!("S1: {e}")),
    };
    let scenario = match loaded {
        Ok(s) => s,
        Err(e) => {
            eprintln!("llrp-gateway sim: {e}");
            return ExitCode::FAILURE;
        }
    };
    for notice in &scenario.notices {
        tracing::info!("scenario: {notice}");
    }
    // One async worker: it only moves bytes between the sockets and the readers (whose work
    // runs on the readers' pool and whose look-ahead physics on the physics pool, one thread
    // per core each), so the process has 2 × cores threads plus this one and main.
    let workers = 1;
    let runtime = match tokio::runtime::Builder::new_multi_thread()
        .worker_threads(workers)
        .enable_all()
        .build()
    {
        Ok(r) => r,
        Err(e) => {
            eprintln!("llrp-gateway sim: cannot start the async runtime: {e}");
            return ExitCode::FAILURE;
        }
    };
    runtime.block_on(async move {
        let stop = StopSignal::watch();
        // The localizer and its HTTP API (the simulator only feeds a localizer someone can
        // ask: with --no-http neither runs).
        let mut live = None;
        let mut http = None;
        // One registry for what runs: the readers' links, the localizer, the publisher.
        let metrics = llrp_gateway::metrics::Metrics::new();
        let links = llrp_gateway::metrics::LinkMetrics::default();
        metrics.register(|r| links.register(r));
        opts.frames_in = links.frames_in.clone();
        if let Some((addr, chosen)) = localize.http.address(Some("127.0.0.1:8080")) {
            let settings = llrp_gateway::localize::live::Settings {
                estimator: localize.estimator,
                release_memory: Some(llrp_gateway::alloc::release_free),
                ..Default::default()
            };
            let mut settings = sim::feed::settings(&scenario, settings);
            // The robot's own poses come with the error its scenario states: the estimates'
            // covariance takes it in.
            if localize.poses == sim::PoseSource::Estimated {
                settings.geometry.pose_error = sim::feed::pose_error(&scenario);
            }
            let l = match llrp_gateway::localize::live::Live::start(settings) {
                Ok(l) => l,
                Err(e) => {
                    eprintln!("llrp-gateway sim: cannot start the localizer: {e}");
                    return ExitCode::FAILURE;
                }
            };
            metrics.register(|r| l.shared.metrics.register(r));
            match llrp_gateway::http::launch::launch(
                &addr,
                chosen,
                &localize.http,
                true,
                l.shared.clone(),
                l.tap.clone(),
                metrics.clone(),
            )
            .await
            {
                Ok(Some(h)) => {
                    eprintln!("llrp-gateway sim: HTTP API and live map on http://{}/", h.addr);
                    opts.localize = Some(sim::LocalizeFeed {
                        tap: l.tap.clone(),
                        poses: localize.poses,
                        pose_interval_us: localize.pose_interval_ms * 1000,
                        read_poses: localize.read_poses,
                    });
                    http = Some(h);
                    live = Some(l);
                }
                Ok(None) => eprintln!(
                    "llrp-gateway sim: {addr} is taken: running without the HTTP API (choose one with --http ADDR)"
                ),
                Err(e) => {
                    eprintln!("llrp-gateway sim: {e}");
                    return ExitCode::FAILURE;
                }
            }
        }
        // The MQTT publisher takes a copy of everything the localizer is offered (with
        // --no-http, of what it would be offered).
        let shared = live
            .as_ref()
            .map(|l: &llrp_gateway::localize::live::Live| l.shared.clone())
            .unwrap_or_default();
        let references = scenario_references(&scenario);
        let mqtt = llrp_gateway::fleet::metrics::MqttMetrics::default();
        metrics.register(|r| mqtt.register(r));
        let publisher = match localize.publish.start(mqtt, references) {
            Ok(p) => p,
            Err(e) => {
                eprintln!("llrp-gateway sim: {e}");
                return ExitCode::FAILURE;
            }
        };
        if let Some(p) = &publisher {
            let tap = match &opts.localize {
                Some(l) => l.tap.clone(),
                None => llrp_gateway::localize::live::Tap::detached(shared.links().clone()),
            };
            opts.localize = Some(sim::LocalizeFeed {
                tap: tap.with_mirror(p.mirror()),
                poses: localize.poses,
                pose_interval_us: localize.pose_interval_ms * 1000,
                read_poses: localize.read_poses,
            });
            eprintln!(
                "llrp-gateway sim: publishing to {}",
                localize.publish.shown()
            );
        }
        let running = match sim::start(&scenario, &opts).await {
            Ok(r) => r,
            Err(e) => {
                eprintln!("llrp-gateway sim: {e}");
                return ExitCode::FAILURE;
            }
        };
        let tls = if opts.tls.is_some() { " (TLS)" } else { "" };
        for (name, addr) in running.names.iter().zip(&running.addrs) {
            eprintln!(
                "llrp-gateway sim: scenario '{}': reader '{name}' listening on {addr}{tls}",
                scenario.name
            );
        }
        stop.wait().await;
        // Each client gets its ConnectionCloseEvent and the ground truth is flushed, within
        // a second: a client that does not take its last bytes does not hold the exit up.
        running.shutdown().await;
        drop(opts);
        if let Some(p) = publisher {
            p.stop();
        }
        if let Some(h) = http {
            h.stop().await;
        }
        if let Some(l) = live {
            l.stop();
        }
        eprintln!("llrp-gateway sim: stopped");
        ExitCode::SUCCESS
    })
}

#[cfg(test)]
mod tests {
    use std::any::TypeId;
    use std::ffi::OsStr;

    use clap::CommandFactory;
    use llrp_gateway::options::{range, RANGES};

    use super::Cli;

    /// The numeric types an option may give, with their bounds.
    fn numeric(id: &clap::builder::ValueParser) -> Option<(&'static str, f64, f64)> {
        let t = id.type_id();
        [
            (TypeId::of::<u8>(), "u8", 0.0, u8::MAX as f64),
            (TypeId::of::<u16>(), "u16", 0.0, u16::MAX as f64),
            (TypeId::of::<u32>(), "u32", 0.0, u32::MAX as f64),
            (TypeId::of::<u64>(), "u64", 0.0, u64::MAX as f64),
            (TypeId::of::<usize>(), "usize", 0.0, usize::MAX as f64),
            (TypeId::of::<i64>(), "i64", i64::MIN as f64, i64::MAX as f64),
            (TypeId::of::<f64>(), "f64", f64::MIN, f64::MAX),
        ]
        .into_iter()
        .find(|(id, ..)| t == *id)
        .map(|(_, name, lo, hi)| (name, lo, hi))
    }

    /// Every (command path, command, option) of the CLI, subcommands included.
    fn all_args(
        cmd: &clap::Command,
        path: String,
        out: &mut Vec<(String, clap::Command, clap::Arg)>,
    ) {
        for a in cmd.get_arguments() {
            out.push((path.clone(), cmd.clone(), a.clone()));
        }
        for sub in cmd.get_subcommands() {
            all_args(sub, format!("{path} {}", sub.get_name()), out);
        }
    }

    #[test]
    fn every_numeric_option_of_every_command_is_checked_against_its_range() {
        let cli = Cli::command();
        let mut args = Vec::new();
        all_args(&cli, "llrp-gateway".into(), &mut args);
        let mut seen = std::collections::BTreeSet::new();
        for (path, cmd, arg) in &args {
            let parser = arg.get_value_parser();
            let Some((ty, lo, hi)) = numeric(parser) else {
                continue;
            };
            let name = arg
                .get_long()
                .unwrap_or_else(|| panic!("{path}: a numeric option without a long name"));
            let r = range(name);
            seen.insert(name);
            assert!(
                r.min >= lo && r.max <= hi,
                "{path} --{name}: range {}..={} does not fit {ty}",
                r.min,
                r.max
            );
            // The command parsed with just this option: a value out of range is a
            // ValueValidation error (found as the value is parsed, before any check of the
            // command's other required arguments, which may fail next).
            let parse = |v: String| -> Result<(), ()> {
                // `--name=value`, so that a negative value is not taken for a flag.
                let flag = format!("--{name}={v}");
                let line = [OsStr::new("x"), OsStr::new(&flag)];
                match cmd.clone().try_get_matches_from(line) {
                    Err(e) if e.kind() == clap::error::ErrorKind::ValueValidation => Err(()),
                    _ => Ok(()),
                }
            };
            let text = |v: f64| {
                if r.integer {
                    format!("{}", v as i128)
                } else {
                    format!("{v}")
                }
            };
            // The bounds pass; just outside them, nonsense and NaN do not.
            assert!(parse(text(r.min)).is_ok(), "{path} --{name} {}", r.min);
            if r.max < 1e15 {
                assert!(parse(text(r.max)).is_ok(), "{path} --{name} {}", r.max);
                let over = if r.integer {
                    r.max + 1.0
                } else {
                    r.max * 2.0 + 1.0
                };
                assert!(parse(text(over)).is_err(), "{path} --{name} {over} taken");
            }
            let under = if r.integer {
                r.min - 1.0
            } else if r.min > 0.0 {
                r.min / 2.0
            } else {
                r.min - 1.0
            };
            assert!(parse(text(under)).is_err(), "{path} --{name} {under} taken");
            for bad in ["many", "NaN", ""] {
                assert!(parse(bad.into()).is_err(), "{path} --{name} {bad:?} taken");
            }
            if r.integer {
                assert!(
                    parse(format!("{}.5", r.min as i128)).is_err(),
                    "{path} --{name} x.5"
                );
            }
        }
        // Every range is some option's (no stale entries).
        for r in RANGES {
            assert!(seen.contains(r.name), "--{} in RANGES is no option", r.name);
        }
        // The ones the issue named are among them.
        for name in ["record-max-bytes", "connect-timeout-ms", "seconds", "mss"] {
            assert!(seen.contains(name), "{name}");
        }
    }
}
