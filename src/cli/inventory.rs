//! `llrp-gateway inventory HOST[:PORT]`: its options ([`InventoryArgs`]), checked and turned
//! into the run's settings, the localizer and publisher of [`super::live`] started beside the
//! run, and the run's error said at the exit. The inventory itself: [`crate::inventory`].

use crate::reads::{ReaderName, ReaderNameError};
use std::path::PathBuf;

use super::live::{start_sinks, LiveArgs, SinksError};
use crate::inventory::{Inventory, InventoryError, InventoryOptions, Output, Retries};
use crate::net::client::InventorySpec;
use crate::net::tls::{Connector, TlsError, Verify};

/// Command-line options of `llrp-gateway inventory`.
#[derive(Clone, Debug, PartialEq, clap::Args)]
pub struct InventoryArgs {
    /// The reader: HOST or HOST:PORT (port 5084 when none is given); IPv6 as `[ADDR]:PORT`.
    pub reader: String,
    /// Stop after this many seconds (default: run until Ctrl-C or SIGTERM).
    #[arg(long, value_parser = crate::cli::options::parser::<f64>("seconds"))]
    pub seconds: Option<f64>,
    /// Antenna ports to inventory, comma-separated (default: all the reader has).
    #[arg(long, value_delimiter = ',', value_parser = crate::cli::options::parser::<u16>("antennas"))]
    pub antennas: Vec<u16>,
    /// Enable the Impinj extensions and ask for Impinj RF phase, peak RSSI and Doppler.
    #[arg(long)]
    pub impinj: bool,
    /// The reader sends a report every N tag entries (a reader may fold a tag's repeated
    /// reads into one entry; reads not yet reported come when the inventory stops).
    #[arg(long, value_name = "N", default_value_t = 1, value_parser = crate::cli::options::parser::<u16>("report-every"))]
    pub report_every: u16,
    /// Gen2 session, 0-3 (default: the reader's).
    #[arg(long, value_parser = crate::cli::options::parser::<u8>("session"))]
    pub session: Option<u8>,
    /// Impinj inventory search mode (0 reader selected, 1 single target, 2 dual target,
    /// 3 single target with suppression, ...; default: the reader's).
    #[arg(long, value_name = "M", value_parser = crate::cli::options::parser::<u16>("search-mode"))]
    pub search_mode: Option<u16>,
    /// RF mode: a ModeIdentifier of the reader's RF mode table (default: the reader's).
    #[arg(long, value_name = "ID", value_parser = crate::cli::options::parser::<u16>("mode"))]
    pub mode: Option<u16>,
    /// Write the reads here: a `.jsonl` file (the reads file), a `.csv` file, or `-` for
    /// JSON Lines on standard output; any other name (`/dev/null`, a FIFO) with `--format`.
    #[arg(long, value_parser = parse_output)]
    pub output: Option<Output>,
    /// The output's format, when its name does not say it (or to override what it says).
    #[arg(long, value_enum, requires = "output")]
    pub format: Option<Format>,
    /// Write the tag reads to this MCAP file too (ROS 2 messages; docs/robotics.md).
    #[arg(long, value_name = "FILE")]
    pub mcap: Option<PathBuf>,
    /// Replace an existing output file (without it, an existing file is refused).
    #[arg(long)]
    pub force: bool,
    /// Reader name written in each read (default: the reader address as given).
    #[arg(long)]
    pub name: Option<ReaderName>,
    /// Keepalive interval asked of the reader, ms (0: none). A reader silent for three
    /// intervals and 5 s more is taken for lost and reconnected.
    #[arg(long, value_name = "MS", default_value_t = 5000, value_parser = crate::cli::options::parser::<u32>("keepalive-ms"))]
    pub keepalive_ms: u32,
    /// Retries after failed connection attempts in a row: a number, or `forever`.
    #[arg(long, default_value = "5", value_parser = parse_retries)]
    pub retries: Retries,
    /// First wait before a retry, ms; it doubles with each failure in a row.
    #[arg(long, value_name = "MS", default_value_t = 500, value_parser = crate::cli::options::parser::<u64>("backoff-ms"))]
    pub backoff_ms: u64,
    /// Longest wait before a retry, ms.
    #[arg(long, value_name = "MS", default_value_t = 30_000, value_parser = crate::cli::options::parser::<u64>("backoff-max-ms"))]
    pub backoff_max_ms: u64,
    /// LLRP over TLS (port 5085 when HOST has none), with --tls-ca or --tls-insecure.
    #[arg(long)]
    pub tls: bool,
    /// With --tls: CA certificates (PEM) the reader's certificate must be issued by.
    #[arg(
        long,
        value_name = "FILE",
        requires = "tls",
        conflicts_with = "tls_insecure"
    )]
    pub tls_ca: Option<PathBuf>,
    /// With --tls: accept any reader certificate (encrypted, but not authenticated).
    #[arg(long, requires = "tls")]
    pub tls_insecure: bool,
    /// With --tls: the name the reader's certificate must carry (default: HOST).
    #[arg(long, value_name = "NAME", requires = "tls")]
    pub tls_server_name: Option<String>,
    /// The live localizer and its HTTP API (`--http ADDR`) and the MQTT publisher
    /// (`--publish URL`), fed with the reads.
    #[command(flatten)]
    pub live: LiveArgs,
}

/// The format of the reads written (`--format`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// JSON Lines, the reads file.
    Jsonl,
    /// CSV with a header row.
    Csv,
}

fn parse_retries(s: &str) -> Result<Retries, String> {
    if s == "forever" {
        return Ok(Retries::Forever);
    }
    s.parse::<u32>()
        .map(Retries::Limit)
        .map_err(|_| format!("`{s}` is neither a number of retries nor `forever`"))
}

fn parse_output(s: &str) -> Result<Output, String> {
    if s == "-" {
        return Ok(Output::Stdout);
    }
    let path = PathBuf::from(s);
    match path.extension().and_then(|e| e.to_str()) {
        Some("jsonl") | Some("ndjson") => Ok(Output::Jsonl(path)),
        Some("csv") => Ok(Output::Csv(path)),
        _ => Ok(Output::Unnamed(path)),
    }
}

/// Why `--output` and `--format` do not settle the reads' format.
#[derive(Debug, PartialEq, Eq, thiserror::Error)]
pub enum OutputFormatError {
    /// The name says no format and `--format` is not given.
    #[error(
        "--output {}: the name does not say the format: add --format jsonl or --format csv \
         (or name the file .jsonl or .csv)",
        .0.display()
    )]
    Unsaid(PathBuf),
    /// CSV asked for on standard output.
    #[error("--output -: standard output takes JSON Lines only")]
    StdoutCsv,
}

/// Why `inventory` failed.
#[derive(Debug, thiserror::Error)]
pub enum InventoryCommandError {
    /// `--output` and `--format` do not settle the format.
    #[error("{0}")]
    OutputFormat(#[from] OutputFormatError),
    /// `--tls` without saying which certificates to trust.
    #[error("--tls needs --tls-ca FILE (the CA, or the reader's own self-signed certificate) or --tls-insecure (accept any certificate)")]
    TlsTrust,
    /// The TLS settings cannot be used.
    #[error("TLS: {0}")]
    Tls(#[from] TlsError),
    /// The async runtime could not be started.
    #[error("cannot start the async runtime: {0}")]
    Runtime(std::io::Error),
    /// The localizer, its API or the publisher could not be started.
    #[error("{0}")]
    Sinks(#[from] SinksError),
    /// The inventory failed (the reader, the connection, the output).
    #[error("{0}")]
    Inventory(#[from] InventoryError),
    /// No `--name`, and the reader address is no reader name to stand for one.
    #[error("the reader address {address:?} cannot name the reader ({source}): give --name")]
    Name {
        /// The reader address.
        address: String,
        /// Why it is no name.
        source: ReaderNameError,
    },
}

impl InventoryArgs {
    /// The output with its format settled by `--format`; why not, when neither the name nor
    /// the flag says it.
    pub fn resolved_output(&self) -> Result<Option<Output>, OutputFormatError> {
        let Some(out) = &self.output else {
            return Ok(None);
        };
        Ok(Some(match (out, self.format) {
            (Output::Unnamed(p), None) => return Err(OutputFormatError::Unsaid(p.clone())),
            (Output::Stdout, Some(Format::Csv)) => return Err(OutputFormatError::StdoutCsv),
            (Output::Stdout, _) => Output::Stdout,
            (Output::Jsonl(p) | Output::Csv(p) | Output::Unnamed(p), Some(Format::Jsonl)) => {
                Output::Jsonl(p.clone())
            }
            (Output::Jsonl(p) | Output::Csv(p) | Output::Unnamed(p), Some(Format::Csv)) => {
                Output::Csv(p.clone())
            }
            (named, None) => named.clone(),
        }))
    }

    /// The TLS client of `--tls`, if asked for: `--tls-ca` or (with a warning)
    /// `--tls-insecure`.
    fn connector(&self) -> Result<Option<Connector>, InventoryCommandError> {
        if !self.tls {
            return Ok(None);
        }
        let verify = match (&self.tls_ca, self.tls_insecure) {
            (Some(ca), _) => Verify::Ca(ca.clone()),
            (None, true) => {
                eprintln!(
                    "llrp-gateway inventory: warning: --tls-insecure: the reader's certificate is \
                     not checked (the connection is encrypted, not authenticated)"
                );
                Verify::Insecure
            }
            (None, false) => return Err(InventoryCommandError::TlsTrust),
        };
        Ok(Some(Connector::new(
            &verify,
            self.tls_server_name.as_deref(),
        )?))
    }

    /// The run's settings.
    fn options(&self) -> Result<InventoryOptions, InventoryCommandError> {
        let output = self.resolved_output()?;
        Ok(InventoryOptions {
            reader: self.reader.clone(),
            tls: self.connector()?,
            spec: InventorySpec {
                antennas: self.antennas.clone(),
                impinj: self.impinj,
                report_every: self.report_every,
                session: self.session,
                search_mode: self.search_mode,
                mode: self.mode,
                keepalive_ms: self.keepalive_ms,
                ..InventorySpec::default()
            },
            name: match &self.name {
                Some(name) => name.clone(),
                None => ReaderName::parse(&self.reader).map_err(|source| {
                    InventoryCommandError::Name {
                        address: self.reader.clone(),
                        source,
                    }
                })?,
            },
            seconds: self.seconds,
            output,
            mcap: self.mcap.clone(),
            force: self.force,
            retries: self.retries,
            backoff_ms: self.backoff_ms,
            backoff_max_ms: self.backoff_max_ms,
        })
    }
}

/// Runs `llrp-gateway inventory`: the output is opened first, then the localizer and
/// publisher start, then the run; at its end they stop and the summary is printed.
pub fn run(args: InventoryArgs) -> Result<(), InventoryCommandError> {
    let options = args.options()?;
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(InventoryCommandError::Runtime)?;
    runtime.block_on(async move {
        let inventory = Inventory::open(options)?;
        let sinks = start_sinks(&args.live, "inventory").await?;
        let mut ended = inventory.run(sinks.tap()).await?;
        sinks.stop().await;
        ended.finish_mcap().await?;
        Ok(ended.report()?)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        args: InventoryArgs,
    }

    fn parse(args: &[&str]) -> Result<InventoryArgs, clap::Error> {
        Cli::try_parse_from(std::iter::once("inventory").chain(args.iter().copied()))
            .map(|c| c.args)
    }

    #[test]
    fn the_antenna_list_is_comma_separated_and_one_based() {
        let a = parse(&["reader", "--antennas", "1,2,8"]).expect("parses");
        assert_eq!(a.antennas, [1, 2, 8]);
        assert!(parse(&["reader"]).expect("parses").antennas.is_empty());
        assert!(parse(&["reader", "--antennas", "0"]).is_err(), "antenna 0");
        assert!(
            parse(&["reader", "--antennas", "1,x"]).is_err(),
            "not a number"
        );
    }

    #[test]
    fn the_reader_name_is_given_or_the_address_and_keeps_the_rule() {
        let named = parse(&["10.0.0.5", "--name", "dock 1"]).expect("parses");
        assert_eq!(named.options().expect("options").name, "dock 1");
        let unnamed = parse(&["10.0.0.5:5084"]).expect("parses");
        assert_eq!(unnamed.options().expect("options").name, "10.0.0.5:5084");
        let Err(e) = parse(&["r", "--name", "dock\t1"]) else {
            panic!("a tab in --name is refused");
        };
        assert!(e.to_string().contains("control character"), "{e}");
        let blank = parse(&[" "]).expect("parses");
        assert!(matches!(
            blank.options(),
            Err(InventoryCommandError::Name { .. })
        ));
    }

    #[test]
    fn the_session_is_zero_to_three() {
        for s in 0..=3u8 {
            let a = parse(&["r", "--session", &s.to_string()]).expect("parses");
            assert_eq!(a.session, Some(s));
        }
        let e = parse(&["r", "--session", "4"]).expect_err("session 4");
        assert!(e.to_string().contains("from 0 to 3"), "{e}");
    }

    #[test]
    fn every_option_parses_and_bad_values_are_refused() {
        let a = parse(&[
            "10.0.0.7:5085",
            "--seconds",
            "2.5",
            "--impinj",
            "--report-every",
            "10",
            "--search-mode",
            "2",
            "--mode",
            "1002",
            "--output",
            "reads.csv",
            "--retries",
            "forever",
            "--keepalive-ms",
            "0",
        ])
        .expect("parses");
        assert_eq!(a.seconds, Some(2.5));
        assert!(a.impinj);
        assert_eq!(a.report_every, 10);
        assert_eq!(a.search_mode, Some(2));
        assert_eq!(a.mode, Some(1002));
        assert_eq!(a.output, Some(Output::Csv("reads.csv".into())));
        assert_eq!(a.retries, Retries::Forever);
        assert_eq!(a.keepalive_ms, 0);
        let d = parse(&["r"]).expect("parses");
        assert_eq!(d.retries, Retries::Limit(5));
        assert_eq!(d.output, None);
        assert_eq!(
            parse(&["r", "--output", "x.jsonl"]).expect("parses").output,
            Some(Output::Jsonl("x.jsonl".into()))
        );
        assert_eq!(
            parse(&["r", "--output", "-"]).expect("parses").output,
            Some(Output::Stdout)
        );
        for bad in [
            &["r", "--seconds", "0"][..],
            &["r", "--seconds", "-1"],
            &["r", "--seconds", "soon"],
            &["r", "--report-every", "0"],
            &["r", "--retries", "many"],
        ] {
            assert!(parse(bad).is_err(), "{bad:?} is refused");
        }
    }

    #[test]
    fn an_output_whose_name_says_no_format_takes_it_from_the_flag() {
        let out = |args: &[&str]| parse(args).expect("parses").resolved_output();
        assert_eq!(
            out(&["r", "--output", "/dev/null", "--format", "csv"]),
            Ok(Some(Output::Csv("/dev/null".into())))
        );
        assert_eq!(
            out(&["r", "--output", "reads.txt", "--format", "jsonl"]),
            Ok(Some(Output::Jsonl("reads.txt".into())))
        );
        let e = out(&["r", "--output", "/dev/null"]).expect_err("no format");
        assert!(e.to_string().contains("--format jsonl"), "{e}");
        assert!(out(&["r", "--output", "-", "--format", "csv"]).is_err());
        assert_eq!(
            out(&["r", "--output", "x.csv"]),
            Ok(Some(Output::Csv("x.csv".into())))
        );
        assert!(
            parse(&["r", "--format", "csv"]).is_err(),
            "--format needs --output"
        );
    }
}
