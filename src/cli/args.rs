//! The clap side of options the subsystems take as plain types: the HTTP API's and the MQTT
//! publisher's option groups and the value enums, each converted to its subsystem's type.

use crate::fleet::args::PublishConfig;
use crate::http::launch::LaunchOptions;

/// The `--http` options of a command (the HTTP API beside it).
#[derive(Clone, Debug, Default, PartialEq, clap::Args)]
pub struct HttpArgs {
    /// Serve the HTTP API and live map here (`127.0.0.1:0` picks a free port; the bound
    /// address is printed). Beyond loopback it needs `--http-token`.
    #[arg(long, value_name = "ADDR")]
    pub http: Option<String>,
    /// No HTTP API.
    #[arg(long, conflicts_with = "http")]
    pub no_http: bool,
    /// Bearer token the write routes need (every route when bound beyond loopback).
    #[arg(long, value_name = "TOKEN")]
    pub http_token: Option<String>,
    /// A host name the loopback HTTP API also answers to (beside localhost, 127.0.0.1 and
    /// `[::1]`); `.example.lan` takes a domain and its subdomains. Repeatable.
    #[arg(long, value_name = "HOST")]
    pub http_allowed_host: Vec<String>,
    /// An origin whose pages may call the HTTP API, writes included (CORS), e.g.
    /// `http://dashboard.lan:3000`. Repeatable.
    #[arg(long, value_name = "ORIGIN")]
    pub http_allowed_origin: Vec<String>,
}

impl From<HttpArgs> for LaunchOptions {
    fn from(a: HttpArgs) -> LaunchOptions {
        LaunchOptions {
            http: a.http,
            no_http: a.no_http,
            http_token: a.http_token,
            http_allowed_host: a.http_allowed_host,
            http_allowed_origin: a.http_allowed_origin,
        }
    }
}

/// Publishing to an MQTT broker (docs/fleet.md).
#[derive(Clone, Debug, Default, PartialEq, clap::Args)]
pub struct PublishArgs {
    /// Publish reads, poses, reader events and statuses to this MQTT broker:
    /// `mqtt://[USER:PASS@]HOST[:PORT][/PREFIX]`.
    #[arg(long, value_name = "URL")]
    pub publish: Option<String>,
    /// Read shards: a tag's reads go to `PREFIX/v1/reads/{FNV-1a(EPC) % N}`.
    #[arg(long, value_name = "N", default_value_t = crate::fleet::schema::DEFAULT_SHARDS, value_parser = crate::cli::options::parser::<u16>("shard-count"))]
    pub shard_count: u16,
    /// Messages held while the broker is away; beyond it they are dropped and counted.
    #[arg(long, value_name = "N", default_value_t = 10_000, value_parser = crate::cli::options::parser::<usize>("publish-queue"))]
    pub publish_queue: usize,
    /// Batch each topic's reads over this window (ms); 0: a message per RO_ACCESS_REPORT.
    #[arg(long, value_name = "MS", default_value_t = 0, value_parser = crate::cli::options::parser::<u64>("publish-window-ms"))]
    pub publish_window_ms: u64,
    /// This gateway's name on the broker (its status topic and MQTT client id).
    #[arg(long, value_name = "NAME", default_value = "llrp-gateway")]
    pub gateway_name: String,
    /// For `mqtts://`: the CA certificate (PEM) that signed the broker's.
    #[arg(long, value_name = "FILE")]
    pub mqtt_ca: Option<std::path::PathBuf>,
}

impl From<PublishArgs> for PublishConfig {
    fn from(a: PublishArgs) -> PublishConfig {
        PublishConfig {
            publish: a.publish,
            shard_count: a.shard_count,
            publish_queue: a.publish_queue,
            publish_window_ms: a.publish_window_ms,
            gateway_name: a.gateway_name,
            mqtt_ca: a.mqtt_ca,
        }
    }
}

/// A regulatory region's channel table (`proxy --region`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum RegionArg {
    /// FCC Part 15, 50 channels (902.75..927.25 MHz).
    Fcc,
    /// ETSI EN 302 208, 4 channels (865.7..867.5 MHz).
    Etsi,
}

impl From<RegionArg> for crate::gateway::Region {
    fn from(r: RegionArg) -> crate::gateway::Region {
        match r {
            RegionArg::Fcc => crate::gateway::Region::Fcc,
            RegionArg::Etsi => crate::gateway::Region::Etsi,
        }
    }
}

/// Which poses the simulator gives the localizer (`sim --poses`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum PoseSourceArg {
    /// The true antenna poses.
    Truth,
    /// What the robot itself would report: odometry, or the localization-like error of the
    /// scenario's `pose_estimate`.
    #[default]
    Estimated,
}

impl From<PoseSourceArg> for crate::sim::PoseSource {
    fn from(p: PoseSourceArg) -> crate::sim::PoseSource {
        match p {
            PoseSourceArg::Truth => crate::sim::PoseSource::Truth,
            PoseSourceArg::Estimated => crate::sim::PoseSource::Estimated,
        }
    }
}

/// How log lines are written (`--log-format`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum LogFormatArg {
    /// One line of text an event; coloured on a terminal unless `NO_COLOR` is set.
    #[default]
    Text,
    /// One JSON object an event (for services and log collectors); never coloured.
    Json,
}

impl From<LogFormatArg> for crate::stop::LogFormat {
    fn from(f: LogFormatArg) -> crate::stop::LogFormat {
        match f {
            LogFormatArg::Text => crate::stop::LogFormat::Text,
            LogFormatArg::Json => crate::stop::LogFormat::Json,
        }
    }
}
