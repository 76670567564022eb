//! The composition root of every command that runs the live localizer or publishes reads
//! (`sim`, `proxy`, `replay`, `inventory`, the MQTT worker of `localize --subscribe`, `bench
//! localize --live-speed`): what their reads go to, built once here. Sources (the simulated
//! readers, the proxy, a replay, the inventory client, the worker's broker subscription, the
//! benchmark's run) offer the feed's [`Tap`]; behind it run the localizer with its HTTP API,
//! an MQTT publisher, both or neither; every subsystem's metrics go into one registry, which
//! the API serves.

use std::collections::BTreeSet;
use std::net::SocketAddr;
use std::sync::Arc;

use prometheus_client::metrics::counter::Counter;

use crate::fleet::args::PublishConfig;
use crate::fleet::metrics::MqttMetrics;
use crate::fleet::publish::Publisher;
use crate::http::launch::{launch, LaunchError, LaunchOptions, Launched};
use crate::localize::live::{Input, Live, Settings, Tap};
use crate::metrics::{LinkMetrics, Metrics};

/// What a command asks its reads to go to.
pub struct Plan<'a> {
    /// The command's name in messages.
    pub command: &'a str,
    /// Where the HTTP API is served, and whether the user chose the address (a default that
    /// is taken is skipped, and no localizer runs); `None`: no localizer.
    pub http: Option<(String, bool)>,
    /// The API's token and browser rules.
    pub http_args: &'a LaunchOptions,
    /// A simulation: `GET /api/truth` is served.
    pub simulation: bool,
    /// The localizer's settings.
    pub settings: Settings,
    /// What the localizer is given before its API is served (readers' clock offsets, a pose
    /// file), in order; waited for where the tap is full.
    pub prime: Vec<Input>,
    /// Publishing to an MQTT broker.
    pub publish: &'a PublishConfig,
    /// The reference tags' EPCs, for the publisher.
    pub references: BTreeSet<String>,
    /// Run the localizer even where its API is not served (the MQTT worker, which publishes
    /// its estimates to the broker).
    pub headless: bool,
    /// The simulated readers' GPIO, for the API (`sim`); `None`: no simulated readers.
    pub gpio: Option<Arc<dyn crate::http::gpio::GpioControl>>,
    /// The simulated readers' faults, for the API (`sim`); `None`: no simulated readers.
    pub faults: Option<Arc<dyn crate::http::faults::FaultControl>>,
}

/// Why the consumers could not be started.
#[derive(Debug, thiserror::Error)]
pub enum ConsumersError {
    /// The localizer's thread could not be started.
    #[error("cannot start the localizer: {0}")]
    Localizer(std::io::Error),
    /// The HTTP API could not be served where asked.
    #[error("{0}")]
    Http(LaunchError),
    /// The MQTT publisher could not be started (the message names the option).
    #[error("{0}")]
    Publish(String),
}

/// The localizer and its API, an MQTT publisher, both or neither (the process's metrics are
/// in the API's state, which serves them).
pub struct Consumers {
    localizer: Option<(Live, Option<Launched>)>,
    publisher: Option<Publisher>,
    tap: Option<Tap>,
    links: LinkMetrics,
    mqtt: MqttMetrics,
    metrics: Arc<Metrics>,
}

impl Consumers {
    /// Starts what `plan` asks for: the localizer (primed) and its API, then the publisher.
    pub async fn start(plan: Plan<'_>) -> Result<Consumers, ConsumersError> {
        let metrics = Metrics::new();
        let links = LinkMetrics::default();
        metrics.register(|r| links.register(r));
        let localizer = localizer(&plan, &metrics).await?;
        let mqtt = MqttMetrics::default();
        metrics.register(|r| mqtt.register(r));
        let publisher = plan
            .publish
            .start(mqtt.clone(), plan.references)
            .map_err(ConsumersError::Publish)?;
        let tap = match (&localizer, &publisher) {
            (None, None) => None,
            (l, p) => {
                // Without a localizer, a tap for the publisher alone (the readers' links
                // still kept).
                let tap = l.as_ref().map_or_else(
                    || Tap::detached(Arc::default()),
                    |(live, _)| live.tap.clone(),
                );
                Some(match p {
                    Some(p) => {
                        eprintln!(
                            "llrp-gateway {}: publishing to {}",
                            plan.command,
                            plan.publish.shown()
                        );
                        tap.with_mirror(p.mirror())
                    }
                    None => tap,
                })
            }
        };
        Ok(Consumers {
            localizer,
            publisher,
            tap,
            links,
            mqtt,
            metrics,
        })
    }

    /// The localizer, when one runs.
    pub fn live(&self) -> Option<&Live> {
        self.localizer.as_ref().map(|(live, _)| live)
    }

    /// Where the HTTP API is served, when it is.
    pub fn http_addr(&self) -> Option<SocketAddr> {
        self.localizer.as_ref()?.1.as_ref().map(|h| h.addr)
    }

    /// The one registry `GET /metrics` serves, for a part started after the consumers.
    pub fn metrics(&self) -> &Arc<Metrics> {
        &self.metrics
    }

    /// The MQTT counters in the registry, for the part that talks to the broker.
    pub fn mqtt_metrics(&self) -> MqttMetrics {
        self.mqtt.clone()
    }

    /// Where the sources offer their reads, when anything takes them.
    pub fn tap(&self) -> Option<Tap> {
        self.tap.clone()
    }

    /// Where the simulated readers count the frames their clients send.
    pub fn frames_in(&self) -> Counter {
        self.links.frames_in.clone()
    }

    /// Where proxied readers' lost keepalive links are counted.
    pub fn keepalive_losses(&self) -> Counter {
        self.links.keepalive_losses.clone()
    }

    /// Stops the publisher (its readers' and gateway's `offline` published, the broker's
    /// acknowledgements waited for a few seconds), then the API, then the localizer. The
    /// sources' taps are to be dropped first.
    pub async fn stop(self) {
        drop(self.tap);
        if let Some(p) = self.publisher {
            let _ = tokio::task::spawn_blocking(move || p.stop()).await;
        }
        if let Some((live, http)) = self.localizer {
            if let Some(http) = http {
                http.stop().await;
            }
            live.stop();
        }
    }
}

/// The localizer `plan` asks for (primed), with its API where it is served; `None` when no
/// localizer is asked for, or only for an API whose default address is taken.
async fn localizer(
    plan: &Plan<'_>,
    metrics: &Arc<Metrics>,
) -> Result<Option<(Live, Option<Launched>)>, ConsumersError> {
    if plan.http.is_none() && !plan.headless {
        return Ok(None);
    }
    let settings = Settings {
        release_memory: Some(crate::alloc::release_free),
        ..plan.settings.clone()
    };
    let live = Live::start(settings).map_err(ConsumersError::Localizer)?;
    metrics.register(|r| live.shared.metrics.register(r));
    for input in plan.prime.iter().cloned() {
        offer_waiting(&live.tap, input).await;
    }
    let Some((addr, chosen)) = &plan.http else {
        return Ok(Some((live, None)));
    };
    let launched = launch(
        addr,
        *chosen,
        plan.http_args,
        plan.simulation,
        live.shared.clone(),
        live.tap.clone(),
        metrics.clone(),
        plan.gpio.clone(),
        plan.faults.clone(),
    )
    .await
    .map_err(ConsumersError::Http)?;
    match launched {
        Some(http) => {
            eprintln!(
                "llrp-gateway {}: HTTP API and live map on http://{}/",
                plan.command, http.addr
            );
            Ok(Some((live, Some(http))))
        }
        None if plan.headless => {
            eprintln!(
                "llrp-gateway {}: {addr} is taken: running without the HTTP API (choose one with --http ADDR)",
                plan.command
            );
            Ok(Some((live, None)))
        }
        None => {
            eprintln!(
                "llrp-gateway {}: {addr} is taken: running without the HTTP API (choose one with --http ADDR)",
                plan.command
            );
            live.stop();
            Ok(None)
        }
    }
}

/// Hands `input` to the localizer, waiting while its tap is full (a pose file larger than
/// the tap holds goes in as the localizer takes it).
async fn offer_waiting(tap: &Tap, mut input: Input) {
    while let Err(back) = tap.try_offer(input) {
        input = back;
        tokio::time::sleep(std::time::Duration::from_millis(1)).await;
    }
}
