//! `llrp-gateway replay`: a recording served as a reader until Ctrl-C or SIGTERM.

use std::path::PathBuf;
use std::process::ExitCode;

use tokio::sync::watch;

use crate::stop::StopSignal;

/// Arguments of `llrp-gateway replay`.
#[derive(clap::Args, Debug)]
pub struct ReplayArgs {
    /// The recording (JSON Lines, docs/recordings.md).
    pub file: PathBuf,
    /// Where clients connect.
    #[arg(long, default_value = "0.0.0.0:5084")]
    pub listen: String,
    /// Recorded time per real time: a factor (1 = as recorded) or `max` (no waiting).
    #[arg(long, default_value = "1")]
    pub speed: crate::net::clock::Speed,
    /// Start the reports stream over when it ends, timestamps shifted.
    #[arg(long = "loop")]
    pub looped: bool,
    /// Replay this recorded connection (default: the first that carries an LLRP session,
    /// see `--list`).
    #[arg(long, value_parser = crate::options::parser::<u32>("conn"))]
    pub conn: Option<u32>,
    /// List the recording's connections (what each holds, which one is replayed by
    /// default) and exit.
    #[arg(long)]
    pub list: bool,
    /// Serve LLRP over TLS with this certificate chain (PEM), as readers do on port 5085.
    #[arg(long, requires = "tls_key")]
    pub tls_cert: Option<PathBuf>,
    /// The private key (PEM) of `--tls-cert`.
    #[arg(long, requires = "tls_cert")]
    pub tls_key: Option<PathBuf>,
    /// The live localizer and its HTTP API (`--http ADDR`), fed with what is replayed.
    #[command(flatten)]
    pub live: super::live::LiveArgs,
}

/// Runs `llrp-gateway replay`.
pub fn run_replay(args: ReplayArgs) -> ExitCode {
    use crate::record::replay::{ReplayOptions, Script};
    use crate::record::Recording;
    crate::stop::init_logging();
    let recording = match Recording::open(&args.file) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("llrp-gateway replay: {}: {e}", args.file.display());
            return ExitCode::FAILURE;
        }
    };
    for w in &recording.warnings {
        eprintln!("llrp-gateway replay: {}: warning: {w}", args.file.display());
    }
    if args.list {
        print!("{}", list(&recording));
        return ExitCode::SUCCESS;
    }
    let script = match Script::new(&recording, args.conn) {
        Ok(s) => std::sync::Arc::new(s),
        Err(e) => {
            eprintln!("llrp-gateway replay: {}: {e}", args.file.display());
            return ExitCode::FAILURE;
        }
    };
    let options = ReplayOptions {
        speed: match args.speed {
            crate::net::clock::Speed::Max => None,
            crate::net::clock::Speed::Factor(x) => Some(x),
        },
        looped: args.looped,
    };
    let tls = match args.tls_cert.clone().zip(args.tls_key.clone()) {
        Some((cert, key)) => match (crate::net::tls::ServerFiles { cert, key }).acceptor() {
            Ok(a) => Some(a),
            Err(e) => {
                eprintln!("llrp-gateway replay: {e}");
                return ExitCode::FAILURE;
            }
        },
        None => None,
    };
    let runtime = match tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
    {
        Ok(r) => r,
        Err(e) => {
            eprintln!("llrp-gateway replay: cannot start the async runtime: {e}");
            return ExitCode::FAILURE;
        }
    };
    runtime.block_on(async move {
        let stop = StopSignal::watch();
        let listener = match tokio::net::TcpListener::bind(&args.listen).await {
            Ok(l) => l,
            Err(e) => {
                eprintln!("llrp-gateway replay: cannot listen on {}: {e}", args.listen);
                return ExitCode::FAILURE;
            }
        };
        match listener.local_addr() {
            Ok(addr) => eprintln!(
                "llrp-gateway replay: {} (connection {}: {} responses, {} reports and events) listening on {addr}",
                args.file.display(),
                script.conn(),
                script.responses(),
                script.unsolicited()
            ),
            Err(e) => eprintln!("llrp-gateway replay: {e}"),
        }
        let sinks = match super::live::start_sinks(&args.live, "replay").await {
            Ok(l) => l,
            Err(e) => {
                eprintln!("llrp-gateway replay: {e}");
                return ExitCode::FAILURE;
            }
        };
        let upstream = &recording.header.upstream;
        let name = upstream.strip_prefix("sim:").unwrap_or(upstream).to_string();
        let tap = sinks.tap().map(|t| (name, t));
        let (tx, rx) = watch::channel(false);
        let task = tokio::spawn(crate::net::replay::serve_tapped(
            listener, script, options, tls, rx, tap,
        ));
        stop.wait().await;
        let _ = tx.send(true);
        let _ = task.await;
        sinks.stop().await;
        eprintln!("llrp-gateway replay: stopped");
        ExitCode::SUCCESS
    })
}

/// The table `replay --list` prints: a line per connection, the default one marked.
fn list(recording: &crate::record::Recording) -> String {
    use std::fmt::Write as _;
    let default = crate::record::replay::Script::new(recording, None)
        .ok()
        .map(|s| s.conn());
    let mut out =
        String::from("conn  start_s  client_frames  reader_frames  reports  client / end\n");
    for s in recording.summaries() {
        let start = s.start.map_or(0.0, |t| t.t_us as f64 / 1e6);
        let mark = if Some(s.conn) == default {
            "  (replayed by default)"
        } else if !s.has_session() {
            "  (no LLRP session)"
        } else {
            ""
        };
        let _ = writeln!(
            out,
            "{:>4}  {start:>7.3}  {:>13}  {:>13}  {:>7}  {} / {}{mark}",
            s.conn,
            s.to_reader,
            s.from_reader,
            s.reports,
            s.client.as_deref().unwrap_or("-"),
            s.end.as_deref().unwrap_or("-"),
        );
    }
    out
}
