//! `llrp-gateway localize --subscribe URL --shards LIST`: a localizer worker until Ctrl-C or
//! SIGTERM, with the HTTP API for its shards when given `--http ADDR`.

use crate::reads::ReaderName;
use std::path::PathBuf;

use super::localize::LocalizeArgs;
use super::root::{Consumers, Plan};
use crate::fleet::args::PublishConfig;
use crate::fleet::schema::DEFAULT_SHARDS;
use crate::fleet::url::{BrokerAddress, BrokerUrl};
use crate::fleet::worker::{parse_shards, Worker, WorkerOptions};
use crate::foxglove::LiveServer;
use crate::http::launch::LaunchOptions;
use crate::localize::live::Input;
use crate::localize::offline::SettingsFile;
use crate::localize::poses::Poses;
use crate::record::mcap::McapThread;

/// The worker options of `localize`.
#[derive(Clone, Debug, Default, PartialEq, clap::Args)]
pub struct WorkerArgs {
    /// Run as a localizer worker on this MQTT broker's reads instead of a file
    /// (`mqtt://[USER[:PASS]@]HOST[:PORT][/PREFIX]`, the password better apart:
    /// `--mqtt-password-file` or the environment variable; docs/fleet.md).
    #[arg(long, value_name = "URL")]
    pub subscribe: Option<BrokerAddress>,
    /// The broker's password apart from the URL.
    #[command(flatten)]
    pub password: super::args::MqttPasswordArgs,
    /// The read shards this worker owns: `0-7`, `0,3,8-11`, … (default: all).
    #[arg(long, value_name = "LIST", requires = "subscribe")]
    pub shards: Option<String>,
    /// How many shards the publishers split reads into (their `--shard-count`).
    #[arg(long, value_name = "N", default_value_t = DEFAULT_SHARDS, value_parser = crate::cli::options::parser::<u16>("shard-count"))]
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
    #[arg(long, value_name = "S", default_value_t = 10.0, requires = "subscribe", value_parser = crate::cli::options::parser::<f64>("presence-silence-s"))]
    pub presence_silence_s: f64,
    /// A `moved` presence event when the estimate moves more than this (m).
    #[arg(long, value_name = "M", default_value_t = crate::fleet::presence::DEFAULT_MOVE_M, requires = "subscribe", value_parser = crate::cli::options::parser::<f64>("presence-move-m"))]
    pub presence_move_m: f64,
    /// The HTTP API and live map for the worker's shards (off unless given).
    #[command(flatten)]
    pub http: super::args::HttpArgs,
    /// Serve the worker's estimates and their scene live to Foxglove on this address (its
    /// WebSocket protocol; docs/robotics.md "Live in Foxglove").
    #[arg(long, value_name = "ADDR", requires = "subscribe")]
    pub foxglove: Option<String>,
}

/// Why the worker of `localize --subscribe` could not run.
#[derive(Debug, thiserror::Error)]
pub enum WorkerCommandError {
    /// `--subscribe` is not a broker address (or a password apart does not fit it).
    #[error("--subscribe {0}")]
    Subscribe(crate::fleet::url::UrlError),
    /// A secret's file (`--http-token-file`, `--mqtt-password-file`) gave no secret.
    #[error("{0}")]
    Secret(#[from] super::args::SecretOptionError),
    /// `--shards` is not a list of shards below `--shard-count` (the message says why).
    #[error("{0}")]
    Shards(String),
    /// The settings file could not be loaded (the message names the file and why).
    #[error("{source}")]
    Settings {
        /// The file.
        path: PathBuf,
        /// Why.
        source: crate::localize::offline::SettingsError,
    },
    /// The `--scenario` file could not be loaded.
    #[error("{}: {source}", path.display())]
    Scenario {
        /// The file.
        path: PathBuf,
        /// Why.
        source: crate::scenario::ScenarioError,
    },
    /// The `--mqtt-ca` certificate could not be loaded (the message names the file and why).
    #[error("{0}")]
    MqttCa(String),
    /// A presence option is not a positive number.
    #[error("{option} {value}: must be a positive number")]
    NotPositive {
        /// The option, `--presence-silence-s` or `--presence-move-m`.
        option: &'static str,
        /// Its value.
        value: f64,
    },
    /// The async runtime could not be started.
    #[error("cannot start the async runtime: {0}")]
    Runtime(std::io::Error),
    /// The worker could not connect to the broker.
    #[error("{0}")]
    Start(crate::fleet::publish::PublishError),
    /// The localizer or its HTTP API could not be started.
    #[error("{0}")]
    Consumers(#[from] super::root::ConsumersError),
    /// The Foxglove live view could not listen.
    #[error("{0}")]
    Live(#[from] crate::foxglove::LiveError),
    /// The `--mcap` file could not be written.
    #[error("cannot write the MCAP file: {0}")]
    Mcap(crate::record::mcap::McapError),
}

/// What the worker's options ask for: the worker, and the localizer it feeds.
struct WorkerPlan {
    worker: WorkerOptions,
    /// The HTTP API's options (its token read).
    http: LaunchOptions,
    /// The localizer's settings.
    settings: crate::localize::live::Settings,
    /// Per reader, reader time − robot time of the poses robots publish (µs).
    clock_offsets_us: Vec<(ReaderName, i64)>,
    /// `--mcap`: the file the worker's estimates and their scene go to.
    mcap: Option<PathBuf>,
    /// `--force`: an existing `--mcap` file is replaced.
    force: bool,
}

/// Runs the worker of `args` (which has `--subscribe`) until Ctrl-C or SIGTERM.
pub fn run(args: &LocalizeArgs) -> Result<(), WorkerCommandError> {
    crate::stop::init_logging();
    let opts = options(args)?;
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(WorkerCommandError::Runtime)?;
    runtime.block_on(serve(opts, &args.worker))
}

/// The worker's options from `args`.
fn options(args: &LocalizeArgs) -> Result<WorkerPlan, WorkerCommandError> {
    type E = WorkerCommandError;
    let w = &args.worker;
    let url = w.subscribe.as_ref().map_or("", BrokerAddress::as_str);
    let password = w.password.password()?;
    let url = BrokerUrl::parse(url)
        .and_then(|u| u.with_password(password))
        .map_err(E::Subscribe)?;
    let shards = match &w.shards {
        Some(list) => parse_shards(list, w.shard_count).map_err(E::Shards)?,
        None => (0..w.shard_count).collect(),
    };
    let file = match &args.settings {
        Some(p) => SettingsFile::load(p).map_err(|source| E::Settings {
            path: p.clone(),
            source,
        })?,
        None => SettingsFile::default(),
    };
    let settings = match &w.scenario {
        Some(p) => {
            let s = crate::scenario::Scenario::load(p).map_err(|source| E::Scenario {
                path: p.clone(),
                source,
            })?;
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
    let worker = WorkerOptions {
        url,
        shards,
        shard_count: w.shard_count,
        client_id,
        tls: crate::fleet::args::tls_config(w.mqtt_ca.as_deref()).map_err(E::MqttCa)?,
        presence_silence: positive("--presence-silence-s", w.presence_silence_s)
            .map(std::time::Duration::from_secs_f64)?,
        presence_move_m: positive("--presence-move-m", w.presence_move_m)?,
    };
    Ok(WorkerPlan {
        worker,
        http: LaunchOptions::try_from(w.http.clone())?,
        settings,
        clock_offsets_us: file.clock_offsets_us.clone().into_iter().collect(),
        mcap: args.mcap.clone(),
        force: args.force,
    })
}

/// Runs the worker of `plan` and the localizer it feeds, with the HTTP API of `w` if asked
/// for, until Ctrl-C or SIGTERM.
async fn serve(plan: WorkerPlan, w: &WorkerArgs) -> Result<(), WorkerCommandError> {
    let stop = crate::stop::StopSignal::watch();
    let view = match &w.foxglove {
        Some(addr) => Some(LiveServer::bind(addr).await?),
        None => None,
    };
    let mcap = McapThread::open(
        plan.mcap.as_deref(),
        plan.force,
        view.as_ref().map(LiveServer::tap),
    )
    .map_err(WorkerCommandError::Mcap)?;
    let http_options = plan.http;
    // Each reader's clock offset, before anything else reaches the localizer.
    let prime = (plan.clock_offsets_us.iter())
        .map(|(reader, offset)| Input::Reader {
            name: reader.clone(),
            hop_table: None,
            antennas: Vec::new(),
            clock_offset_us: *offset,
            poses: None,
        })
        .collect();
    let consumers = Consumers::start(Plan {
        command: "localize",
        http: http_options.address(None),
        http_args: &http_options,
        simulation: false,
        settings: plan.settings,
        prime,
        publish: &PublishConfig::default(),
        references: Default::default(),
        headless: true,
        gpio: None,
        faults: None,
    })
    .await?;
    // A headless plan always runs its localizer (`root::localizer` returns one for it on
    // every path that is not an error).
    let live = consumers
        .live()
        .expect("a headless plan runs its localizer");
    crate::mcap_estimates::by_wall_clock(Some(&live.shared), mcap.as_ref());
    let (url, shards) = (plan.worker.url.clone(), plan.worker.shards.clone());
    let started = Worker::start(
        plan.worker,
        live.tap.clone(),
        live.shared.clone(),
        consumers.mqtt_metrics(),
    );
    let worker = match started {
        Ok(w) => w,
        Err(e) => {
            consumers.stop().await;
            return Err(WorkerCommandError::Start(e));
        }
    };
    eprintln!(
        "llrp-gateway localize: worker on {url}, shards {} of {}, subscribed",
        list(&shards),
        w.shard_count
    );
    stop.wait().await;
    worker.stop();
    crate::mcap_estimates::last_scene(Some(&live.shared), mcap.as_ref());
    if let Some(mcap) = mcap {
        match mcap.finish_async().await {
            Ok(s) => tracing::info!(
                messages = s.messages,
                channels = s.channels,
                "the MCAP output is finished"
            ),
            Err(e) => tracing::error!(error = %e, "the MCAP file was not finished"),
        }
    }
    if let Some(view) = view {
        view.shutdown().await;
    }
    consumers.stop().await;
    eprintln!("llrp-gateway localize: stopped");
    Ok(())
}

/// `v` when it is a positive finite number, else why not, naming the option.
fn positive(option: &'static str, v: f64) -> Result<f64, WorkerCommandError> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(WorkerCommandError::NotPositive { option, value: v })
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
