//! `llrp-gateway sim`: the simulated readers of a scenario, the localizer they feed with its
//! HTTP API and live map, and the MQTT publisher, until Ctrl-C or SIGTERM.

use std::path::PathBuf;

use super::root::{Consumers, ConsumersError, Plan};
use crate::localize::live::Settings;
use crate::scenario::Scenario;
use crate::sim::{self, SimOptions};
use crate::stop::StopSignal;

/// Why `sim` could not run.
#[derive(Debug, thiserror::Error)]
pub enum SimCommandError {
    /// The scenario could not be loaded (the message names the file, the field and why).
    #[error("{0}")]
    Scenario(String),
    /// The async runtime could not be started.
    #[error("cannot start the async runtime: {0}")]
    Runtime(std::io::Error),
    /// A secret's file (`--http-token-file`, `--mqtt-password-file`) gave no secret.
    #[error("{0}")]
    Secret(#[from] super::args::SecretOptionError),
    /// The localizer, its API or the MQTT publisher could not be started.
    #[error("{0}")]
    Consumers(#[from] ConsumersError),
    /// A reader could not be served.
    #[error("{0}")]
    Start(crate::sim::SimError),
}

/// The localizer, HTTP and MQTT side of `sim`.
pub struct SimLocalize {
    /// Where the HTTP API and live map are served.
    pub http: super::args::HttpArgs,
    /// The antenna poses the localizer is given.
    pub poses: crate::sim::PoseSource,
    /// Time between two pose samples of an antenna (ms).
    pub pose_interval_ms: u64,
    /// Each read is stamped with its antenna's pose.
    pub read_poses: bool,
    /// The localizer's estimator.
    pub estimator: crate::localize::estimate::Estimator,
    /// Publishing to an MQTT broker.
    pub publish: super::args::PublishArgs,
}

/// The EPCs of `scenario`'s reference tags.
fn scenario_references(scenario: &Scenario) -> std::collections::BTreeSet<String> {
    let world = crate::physics::World::new(scenario);
    let model = crate::physics::Model::in_world(&world, scenario, 0);
    (0..model.tag_count())
        .filter(|&k| scenario.tags.get(k).is_some_and(|t| t.reference))
        .map(|k| crate::reads::hex_upper(model.tag_epc(k).as_bytes()))
        .collect()
}

/// The scenario at `path` (the embedded S1 without one), read as `reader_model` when given.
fn load(
    path: Option<&std::path::Path>,
    reader_model: Option<&str>,
) -> Result<Scenario, SimCommandError> {
    let loaded = match path {
        Some(path) => {
            Scenario::load_with(path, reader_model).map_err(|e| format!("{}: {e}", path.display()))
        }
        None => Scenario::default_s1_with(reader_model).map_err(|e| format!("S1: {e}")),
    };
    loaded.map_err(SimCommandError::Scenario)
}

/// Runs the simulated readers until Ctrl-C or SIGTERM.
pub fn run(
    scenario: Option<PathBuf>,
    reader_model: Option<&str>,
    localize: SimLocalize,
    mut opts: SimOptions,
) -> Result<(), SimCommandError> {
    crate::stop::init_logging();
    let http = crate::http::launch::LaunchOptions::try_from(localize.http)?;
    let publish = crate::fleet::args::PublishConfig::try_from(localize.publish)?;
    let scenario = load(scenario.as_deref(), reader_model)?;
    for notice in &scenario.notices {
        tracing::info!("scenario: {notice}");
    }
    // One async worker: it only moves bytes between the sockets and the readers (whose work
    // runs on the readers' pool and whose look-ahead physics on the physics pool, one thread
    // per core each), so the process has 2 × cores threads plus this one and main.
    let workers = 1;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(workers)
        .enable_all()
        .build()
        .map_err(SimCommandError::Runtime)?;
    runtime.block_on(async move {
        let stop = StopSignal::watch();
        // The robot's own poses come with the error its scenario states: the estimates'
        // covariance takes it in.
        let mut settings = sim::feed::settings(
            &scenario,
            Settings {
                estimator: localize.estimator,
                ..Settings::default()
            },
        );
        if localize.poses == sim::PoseSource::Estimated {
            settings.geometry.pose_error = sim::feed::pose_error(&scenario);
        }
        // The localizer and its HTTP API (the simulator only feeds a localizer someone can
        // ask: with --no-http neither runs); the MQTT publisher takes a copy of everything
        // the localizer is offered (with --no-http, of what it would be offered).
        let gpio = std::sync::Arc::new(super::gpio::SimGpio::default());
        let faults = std::sync::Arc::new(super::faults::SimFaults::default());
        let consumers = Consumers::start(Plan {
            command: "sim",
            http: http.address(Some("127.0.0.1:8080")),
            http_args: &http,
            simulation: true,
            settings,
            prime: Vec::new(),
            publish: &publish,
            references: scenario_references(&scenario),
            headless: false,
            gpio: Some(gpio.clone()),
            faults: Some(faults.clone()),
        })
        .await?;
        opts.frames_in = consumers.frames_in();
        let changes = gpio.changes();
        let fault_counts = sim::FaultCounts::default();
        consumers.metrics().register(|r| {
            r.register(
                "gpi_changes",
                "GPI changes handed to the simulated readers through the HTTP API",
                changes,
            );
            r.register(
                "faults",
                "Faults the simulated readers applied (the scenario's and the HTTP API's), \
                 by reader and fault",
                fault_counts.clone(),
            );
        });
        opts.fault_counts = Some(fault_counts);
        opts.localize = consumers.tap().map(|tap| sim::LocalizeFeed {
            tap,
            poses: localize.poses,
            pose_interval_us: localize.pose_interval_ms * 1000,
            read_poses: localize.read_poses,
        });
        let running = sim::start(&scenario, &opts)
            .await
            .map_err(SimCommandError::Start)?;
        if let Some(live) = consumers.live() {
            running.estimates_to_mcap(&live.shared);
        }
        gpio.attach(&running.names, &running.gpio);
        faults.attach(&running.names, &running.faults);
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
        consumers.stop().await;
        eprintln!("llrp-gateway sim: stopped");
        Ok(())
    })
}
