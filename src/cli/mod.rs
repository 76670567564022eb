//! The command line: its arguments ([`Cli`]), the dispatch to each command, and the one place a
//! command's error is said and the process exits ([`main`], [`exit`]: `llrp-gateway COMMAND:
//! MESSAGE` on standard error, exit status 1). Every command's arguments and runner live here,
//! and the subsystems below take options and library calls and name no clap type (the HTTP
//! and MQTT option groups and the value enums are [`args`], converted to the subsystems' plain
//! types; `tests/architecture.rs` checks it): `sim` ([`sim`]), `proxy` ([`proxy`]), `replay` ([`replay`]), `inventory`
//! ([`inventory`]), `export` and `import` ([`capture`]), `localize` and its MQTT worker
//! ([`localize`], [`worker`]), `decode` ([`decode`]), `bench localize`, `realism` and
//! `readrate` ([`mod@bench`]). Each runner returns a typed error (`SimCommandError`,
//! `ProxyCommandError`, `LocalizeCommandError`, `WorkerCommandError`, ...); what the
//! reads of `sim`, `proxy`, `replay` and `inventory` go to is built in [`root`], with the
//! localizer options of the last three in [`live`].

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

use crate::decode::DecodeOptions;
use crate::net::clock::Speed;
use crate::sim::SimOptions;

pub mod args;
pub mod bag_poses;
pub mod bench;
pub mod capture;
pub mod decode;
pub mod faults;
pub mod gpio;
pub mod inventory;
pub mod live;
pub mod localize;
pub mod localize_bag;
pub mod localize_mcap;
pub mod options;
pub mod proxy;
pub mod replay;
pub mod root;
pub mod sim;
pub mod worker;

#[derive(Parser)]
#[command(
    name = "llrp-gateway",
    version,
    about = "Point your LLRP reader software here: a simulated Impinj-class reader (sim), a \
             gateway to real readers (proxy, replay, inventory, export, import) and a tag \
             localizer (localize), with a live map over HTTP",
    long_about = None
)]
pub struct Cli {
    /// Log lines as text (coloured on a terminal unless NO_COLOR is set) or as JSON objects.
    #[arg(long, global = true, value_enum, default_value_t = args::LogFormatArg::Text)]
    log_format: args::LogFormatArg,
    /// The command.
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
pub enum Command {
    /// Simulated reader: serve LLRP for a scenario's readers (default: the embedded
    /// warehouse S1), with a live map of the tags it localizes.
    Sim {
        /// Scenario file (JSON); without it the embedded default scenario S1 runs.
        #[arg(long)]
        scenario: Option<PathBuf>,
        /// Read as this reader model does (`ideal`, `impinj-r420`: as a real Impinj reader;
        /// `impinj-r420-stationary`: that model before each tag's curvature;
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
        /// Write every reader's sessions (frames, tag reads, events), its antennas' poses, the
        /// ground truth, the live localizer's estimates and the 3D scene to this MCAP file
        /// (ROS 2 messages; docs/robotics.md).
        #[arg(long, value_name = "FILE")]
        mcap: Option<PathBuf>,
        /// Serve the same messages live to Foxglove on this address (its WebSocket protocol,
        /// e.g. 127.0.0.1:8765; docs/robotics.md "Live in Foxglove").
        #[arg(long, value_name = "ADDR")]
        foxglove: Option<String>,
        /// Replace an existing truth or MCAP file (without it, an existing file is refused).
        #[arg(long)]
        force: bool,
        /// Keep the tags' memory (what clients wrote, locked and killed) in this file: read at
        /// the start when it exists, written back as it changes (docs/simulator.md).
        #[arg(long, value_name = "FILE")]
        tag_memory: Option<PathBuf>,
        /// Record every session to this file (one file per reader, `FILE-NAME`, when the
        /// scenario has several), as the proxy does (docs/recordings.md).
        #[arg(long)]
        record: Option<PathBuf>,
        /// Start a numbered next recording file once a file would pass this many bytes.
        #[arg(long, value_name = "BYTES", value_parser = crate::cli::options::parser::<u64>("record-max-bytes"))]
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
        http: args::HttpArgs,
        /// Antenna poses the localizer is given: `truth`, or `estimated` (what the robot
        /// itself would report).
        #[arg(long, value_enum, default_value_t = args::PoseSourceArg::Estimated)]
        poses: args::PoseSourceArg,
        /// Time between two pose samples of each antenna, as a robot publishes its pose
        /// (ms; 100 is 10 Hz).
        #[arg(long, value_name = "MS", default_value_t = 100, value_parser = crate::cli::options::parser::<u64>("pose-interval-ms"))]
        pose_interval_ms: u64,
        /// Do not stamp each read with its antenna's pose at the read (the localizer and
        /// MQTT workers then wait for a pose sample at or after each read).
        #[arg(long)]
        no_read_poses: bool,
        /// The localizer's estimator (docs/localize.md).
        #[arg(long, default_value = "relock")]
        estimator: crate::localize::estimate::Estimator,
        /// Publishing to an MQTT broker (docs/fleet.md).
        #[command(flatten)]
        publish: args::PublishArgs,
    },
    /// Gateway: forward clients to a real reader byte for byte, recording the sessions.
    Proxy(proxy::ProxyArgs),
    /// Gateway: serve a recording to a client as the reader did.
    Replay(replay::ReplayArgs),
    /// Gateway: inventory an LLRP reader and write its tag reads (docs/client.md).
    Inventory(inventory::InventoryArgs),
    /// Gateway: write a recording as a pcapng capture that Wireshark dissects as LLRP.
    Export(capture::ExportArgs),
    /// Gateway: turn the LLRP streams of a pcap or pcapng capture into a recording.
    Import(capture::ImportArgs),
    /// Localizer: locate every tag of a recording or a reads file (docs/localize.md).
    Localize(localize::LocalizeArgs),
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
    Bench(bench::BenchCommand),
}

/// Says `command`'s error, if any, as every command's is said, and gives the exit status.
pub fn exit<E: std::fmt::Display>(command: &str, result: Result<(), E>) -> ExitCode {
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("llrp-gateway {command}: {e}");
            ExitCode::FAILURE
        }
    }
}

/// Parses the command line, runs the command, and exits: the one place a command's error is
/// said (`llrp-gateway COMMAND: MESSAGE` on standard error, exit status 1).
pub fn main() -> ExitCode {
    let cli = Cli::parse();
    crate::stop::set_log_format(cli.log_format.into());
    match cli.command {
        Command::Inventory(args) => exit("inventory", inventory::run(args)),
        Command::Export(args) => exit("export", capture::run_export(&args)),
        Command::Import(args) => exit("import", capture::run_import(&args)),
        // The worker's errors are said as `localize`'s.
        Command::Localize(args) if args.worker.subscribe.is_some() => {
            exit("localize", worker::run(&args))
        }
        Command::Localize(args) => exit("localize", localize::run(&args)),
        Command::Bench(bench::BenchCommand::Localize(args)) => {
            exit("bench localize", bench::localize(args))
        }
        Command::Bench(bench::BenchCommand::Realism(args)) => {
            exit("bench realism", bench::realism(args))
        }
        Command::Bench(bench::BenchCommand::Readrate(args)) => {
            exit("bench readrate", bench::readrate(args))
        }
        Command::Sim {
            scenario,
            reader_model,
            listen,
            speed,
            truth,
            mcap,
            foxglove,
            force,
            tag_memory,
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
        } => exit(
            "sim",
            sim::run(
                scenario,
                reader_model.as_deref(),
                sim::SimLocalize {
                    http,
                    poses: poses.into(),
                    pose_interval_ms,
                    read_poses: !no_read_poses,
                    estimator,
                    publish,
                },
                SimOptions {
                    listen,
                    speed,
                    truth,
                    mcap,
                    foxglove,
                    force,
                    record,
                    record_options: crate::record::RecordOptions {
                        max_bytes: record_max_bytes,
                        ..Default::default()
                    },
                    tls: tls_cert
                        .zip(tls_key)
                        .map(|(cert, key)| crate::net::tls::ServerFiles { cert, key }),
                    localize: None,
                    tag_memory,
                    ..SimOptions::default()
                },
            ),
        ),
        Command::Proxy(args) => exit("proxy", proxy::run(args)),
        Command::Replay(args) => exit("replay", replay::run(args)),
        Command::Decode {
            file,
            hex,
            roundtrip,
        } => exit(
            "decode",
            decode::run(file.as_deref(), DecodeOptions { hex, roundtrip }),
        ),
    }
}

#[cfg(test)]
mod tests {
    use std::any::TypeId;
    use std::ffi::OsStr;

    use crate::cli::options::{range, RANGES};
    use clap::CommandFactory;

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
