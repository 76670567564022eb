//! `llrp-gateway localize --subscribe URL --shards LIST`: a localizer worker until Ctrl-C or
//! SIGTERM, with the HTTP API for its shards when given `--http ADDR`.

use std::process::ExitCode;

use super::localize::LocalizeArgs;
use crate::fleet::schema::DEFAULT_SHARDS;
use crate::fleet::url::BrokerUrl;
use crate::fleet::worker::{parse_shards, Worker, WorkerOptions};
use crate::localize::offline::SettingsFile;
use crate::localize::poses::Poses;

/// The worker options of `localize`.
#[derive(Clone, Debug, Default, PartialEq, clap::Args)]
pub struct WorkerArgs {
    /// Run as a localizer worker on this MQTT broker's reads instead of a file
    /// (`mqtt://[USER:PASS@]HOST[:PORT][/PREFIX]`; docs/fleet.md).
    #[arg(long, value_name = "URL")]
    pub subscribe: Option<String>,
    /// The read shards this worker owns: `0-7`, `0,3,8-11`, … (default: all).
    #[arg(long, value_name = "LIST", requires = "subscribe")]
    pub shards: Option<String>,
    /// How many shards the publishers split reads into (their `--shard-count`).
    #[arg(long, value_name = "N", default_value_t = DEFAULT_SHARDS, value_parser = crate::options::parser::<u16>("shard-count"))]
    pub shard_count: u16,
    /// MQTT client id, which names the worker's persistent session (default: from its
    /// shards, so a restarted worker resumes its session).
    #[arg(long, value_name = "ID", requires = "subscribe")]
    pub client_id: Option<String>,
    /// Derive the localizer's settings from this scenario file, as `sim` does, instead of a
    /// settings file.
    #[arg(
        long,
        value_name = "FILE",
        requires = "subscribe",
        conflicts_with = "settings"
    )]
    pub scenario: Option<std::path::PathBuf>,
    /// For `mqtts://`: the CA certificate (PEM) that signed the broker's.
    #[arg(long, value_name = "FILE", requires = "subscribe")]
    pub mqtt_ca: Option<std::path::PathBuf>,
    /// A tag has departed (presence event) after this many seconds without a read.
    #[arg(long, value_name = "S", default_value_t = 10.0, requires = "subscribe", value_parser = crate::options::parser::<f64>("presence-silence-s"))]
    pub presence_silence_s: f64,
    /// A `moved` presence event when the estimate moves more than this (m).
    #[arg(long, value_name = "M", default_value_t = crate::fleet::presence::DEFAULT_MOVE_M, requires = "subscribe", value_parser = crate::options::parser::<f64>("presence-move-m"))]
    pub presence_move_m: f64,
    /// The HTTP API and live map for the worker's shards (off unless given).
    #[command(flatten)]
    pub http: crate::http::launch::HttpArgs,
}

/// Runs the worker of `args` (which has `--subscribe`).
pub fn run(args: &LocalizeArgs) -> ExitCode {
    crate::stop::init_logging();
    match execute(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("llrp-gateway localize: {e}");
            ExitCode::FAILURE
        }
    }
}

fn execute(args: &LocalizeArgs) -> Result<(), String> {
    let w = &args.worker;
    let url = w.subscribe.as_deref().unwrap_or_default();
    let url = BrokerUrl::parse(url).map_err(|e| format!("--subscribe {e}"))?;
    let shards = match &w.shards {
        Some(list) => parse_shards(list, w.shard_count)?,
        None => (0..w.shard_count).collect(),
    };
    let file = match &args.settings {
        Some(p) => SettingsFile::load(p).map_err(|e| e.to_string())?,
        None => SettingsFile::default(),
    };
    let settings = match &w.scenario {
        Some(p) => {
            let s =
                crate::scenario::Scenario::load(p).map_err(|e| format!("{}: {e}", p.display()))?;
            let base = crate::localize::live::Settings {
                estimator: args.estimator,
                ..Default::default()
            };
            crate::sim::feed::settings(&s, base)
        }
        None => crate::gateway::live::settings_from(&file, &Poses::new(), args.estimator),
    };
    let first = shards.first().copied().unwrap_or(0);
    let last = shards.last().copied().unwrap_or(0);
    let client_id = w
        .client_id
        .clone()
        .unwrap_or_else(|| format!("llrp-gateway-worker-{first}-{last}-of-{}", w.shard_count));
    let opts = WorkerOptions {
        url: url.clone(),
        shards: shards.clone(),
        shard_count: w.shard_count,
        client_id,
        settings,
        clock_offsets_us: file.clock_offsets_us.clone().into_iter().collect(),
        tls: crate::fleet::args::tls_config(w.mqtt_ca.as_deref())?,
        presence_silence: positive("--presence-silence-s", w.presence_silence_s)
            .map(std::time::Duration::from_secs_f64)?,
        presence_move_m: positive("--presence-move-m", w.presence_move_m)?,
    };
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| format!("cannot start the async runtime: {e}"))?;
    runtime.block_on(async move {
        let stop = crate::stop::StopSignal::watch();
        let worker = Worker::start(opts).map_err(|e| e.to_string())?;
        let http = match w.http.address(None) {
            Some((addr, chosen)) => {
                // The localizer's metrics and the worker's MQTT counters.
                let metrics = crate::metrics::Metrics::of_localizer(&worker.live.shared);
                metrics.register(|r| worker.metrics.register(r));
                let h = crate::http::launch::launch(
                    &addr,
                    chosen,
                    &w.http,
                    false,
                    worker.live.shared.clone(),
                    worker.live.tap.clone(),
                    metrics,
                )
                .await
                .map_err(|e| e.to_string())?
                .ok_or_else(|| format!("--http {addr}: cannot listen"))?;
                eprintln!(
                    "llrp-gateway localize: HTTP API and live map on http://{}/",
                    h.addr
                );
                Some(h)
            }
            None => None,
        };
        eprintln!(
            "llrp-gateway localize: worker on {url}, shards {} of {}, subscribed",
            list(&shards),
            w.shard_count
        );
        stop.wait().await;
        if let Some(h) = http {
            h.stop().await;
        }
        worker.stop();
        eprintln!("llrp-gateway localize: stopped");
        Ok(())
    })
}

/// `v` when it is a positive finite number, else why not, naming the option.
fn positive(option: &str, v: f64) -> Result<f64, String> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(format!("{option} {v}: must be a positive number"))
    }
}

/// `shards` as ranges: `0-7,9`.
fn list(shards: &std::collections::BTreeSet<u16>) -> String {
    let mut out: Vec<String> = Vec::new();
    let mut run: Option<(u16, u16)> = None;
    for &s in shards {
        run = match run {
            Some((a, b)) if s == b + 1 => Some((a, s)),
            Some((a, b)) => {
                out.push(if a == b {
                    a.to_string()
                } else {
                    format!("{a}-{b}")
                });
                Some((s, s))
            }
            None => Some((s, s)),
        };
    }
    if let Some((a, b)) = run {
        out.push(if a == b {
            a.to_string()
        } else {
            format!("{a}-{b}")
        });
    }
    out.join(",")
}
