//! The clap side of options the subsystems take as plain types: the HTTP API's and the MQTT
//! publisher's option groups and the value enums, each converted to its subsystem's type.

use std::path::{Path, PathBuf};

use crate::fleet::args::PublishConfig;
use crate::fleet::url::BrokerAddress;
use crate::http::launch::LaunchOptions;
use crate::secret::{Secret, SecretFileError};

/// The environment variable that gives `--http-token`.
pub const HTTP_TOKEN_ENV: &str = "LLRP_GATEWAY_HTTP_TOKEN";
/// The environment variable that gives `--mqtt-password`.
pub const MQTT_PASSWORD_ENV: &str = "LLRP_GATEWAY_MQTT_PASSWORD";

/// The `--http` options of a command (the HTTP API beside it).
#[derive(Clone, Debug, Default, PartialEq, clap::Args)]
pub struct HttpArgs {
    /// Serve the HTTP API and live map here (`127.0.0.1:0` picks a free port; the bound
    /// address is printed). Beyond loopback it needs a token (`--http-token`).
    #[arg(long, value_name = "ADDR")]
    pub http: Option<String>,
    /// No HTTP API.
    #[arg(long, conflicts_with = "http")]
    pub no_http: bool,
    /// Bearer token the write routes need (every route when bound beyond loopback). On the
    /// command line every local user sees it: prefer the environment variable or
    /// `--http-token-file`.
    #[arg(long, value_name = "TOKEN", env = HTTP_TOKEN_ENV, hide_env_values = true, value_parser = secret_value)]
    pub http_token: Option<Secret>,
    /// Read the bearer token from this file (its line end stripped; an empty file is an
    /// error).
    #[arg(long, value_name = "FILE", conflicts_with = "http_token")]
    pub http_token_file: Option<PathBuf>,
    /// A host name the loopback HTTP API also answers to (beside localhost, 127.0.0.1 and
    /// `[::1]`); `.example.lan` takes a domain and its subdomains. Repeatable.
    #[arg(long, value_name = "HOST")]
    pub http_allowed_host: Vec<String>,
    /// An origin whose pages may call the HTTP API, writes included (CORS), e.g.
    /// `http://dashboard.lan:3000`. Repeatable.
    #[arg(long, value_name = "ORIGIN")]
    pub http_allowed_origin: Vec<String>,
}

/// A secret option's value: anything but empty (an empty environment variable included). A
/// refused value is never printed, as it is empty.
fn secret_value(value: &str) -> Result<Secret, &'static str> {
    if value.is_empty() {
        Err("must not be empty")
    } else {
        Ok(Secret::new(value))
    }
}

/// A secret's file (`--http-token-file`, `--mqtt-password-file`) gave no secret.
#[derive(Debug, thiserror::Error)]
#[error("{option} {}: {source}", path.display())]
pub struct SecretOptionError {
    /// The option.
    pub option: &'static str,
    /// Its file.
    pub path: PathBuf,
    /// Why.
    pub source: SecretFileError,
}

/// The secret of `value` or, when given, of the file at `file` (option `option`).
fn secret_of(
    value: Option<Secret>,
    file: Option<&Path>,
    option: &'static str,
) -> Result<Option<Secret>, SecretOptionError> {
    match file {
        Some(path) => Secret::from_file(path)
            .map(Some)
            .map_err(|source| SecretOptionError {
                option,
                path: path.to_owned(),
                source,
            }),
        None => Ok(value),
    }
}

impl TryFrom<HttpArgs> for LaunchOptions {
    type Error = SecretOptionError;

    /// The options, with the token read from `--http-token-file` when given.
    fn try_from(a: HttpArgs) -> Result<LaunchOptions, SecretOptionError> {
        Ok(LaunchOptions {
            http_token: secret_of(
                a.http_token,
                a.http_token_file.as_deref(),
                "--http-token-file",
            )?,
            http: a.http,
            no_http: a.no_http,
            http_allowed_host: a.http_allowed_host,
            http_allowed_origin: a.http_allowed_origin,
        })
    }
}

/// The broker password of a command (`--publish`'s or `--subscribe`'s), apart from the URL.
#[derive(Clone, Debug, Default, PartialEq, clap::Args)]
pub struct MqttPasswordArgs {
    /// The broker password, for a URL that names the user only (`mqtt://USER@HOST`). On the
    /// command line every local user sees it: prefer the environment variable or
    /// `--mqtt-password-file`.
    #[arg(long, value_name = "PASS", env = MQTT_PASSWORD_ENV, hide_env_values = true, value_parser = secret_value)]
    pub mqtt_password: Option<Secret>,
    /// Read the broker password from this file (its line end stripped; an empty file is an
    /// error).
    #[arg(long, value_name = "FILE", conflicts_with = "mqtt_password")]
    pub mqtt_password_file: Option<PathBuf>,
}

impl MqttPasswordArgs {
    /// The password given apart from the URL, read from its file when that was given.
    pub fn password(&self) -> Result<Option<Secret>, SecretOptionError> {
        secret_of(
            self.mqtt_password.clone(),
            self.mqtt_password_file.as_deref(),
            "--mqtt-password-file",
        )
    }
}

/// Publishing to an MQTT broker (docs/fleet.md).
#[derive(Clone, Debug, Default, PartialEq, clap::Args)]
pub struct PublishArgs {
    /// Publish reads, poses, reader events and statuses to this MQTT broker:
    /// `mqtt://[USER[:PASS]@]HOST[:PORT][/PREFIX]` (the password better apart:
    /// `--mqtt-password-file` or the environment variable).
    #[arg(long, value_name = "URL")]
    pub publish: Option<BrokerAddress>,
    /// The broker's password apart from the URL.
    #[command(flatten)]
    pub password: MqttPasswordArgs,
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

impl TryFrom<PublishArgs> for PublishConfig {
    type Error = SecretOptionError;

    /// The options, with the password read from `--mqtt-password-file` when given.
    fn try_from(a: PublishArgs) -> Result<PublishConfig, SecretOptionError> {
        Ok(PublishConfig {
            password: a.password.password()?,
            publish: a.publish,
            shard_count: a.shard_count,
            publish_queue: a.publish_queue,
            publish_window_ms: a.publish_window_ms,
            gateway_name: a.gateway_name,
            mqtt_ca: a.mqtt_ca,
        })
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

#[cfg(test)]
mod tests {
    use clap::Parser;

    use super::*;

    /// The option groups that carry secrets, as a command flattens them.
    #[derive(Debug, Parser)]
    struct Command {
        #[command(flatten)]
        http: HttpArgs,
        #[command(flatten)]
        publish: PublishArgs,
    }

    #[test]
    fn no_debug_of_the_options_shows_a_secret() {
        let c = Command::try_parse_from([
            "x",
            "--http-token",
            "tok-SECRET",
            "--publish",
            "mqtt://gw:url-SECRET@h/p",
        ])
        .expect("parses");
        let launch = LaunchOptions::try_from(c.http.clone()).expect("converts");
        let publish = PublishConfig::try_from(c.publish.clone()).expect("converts");
        assert_eq!(
            launch.http_token.as_ref().map(Secret::expose),
            Some("tok-SECRET")
        );
        for shown in [
            format!("{c:?}"),
            format!("{c:#?}"),
            format!("{launch:?}"),
            format!("{publish:?}"),
            publish.shown(),
        ] {
            assert!(!shown.contains("SECRET"), "{shown}");
        }
        assert_eq!(publish.shown(), "mqtt://gw:***@h:1883/p");
        let c = Command::try_parse_from([
            "x",
            "--publish",
            "mqtt://gw@h",
            "--mqtt-password",
            "pw-SECRET",
        ])
        .expect("parses");
        let publish = PublishConfig::try_from(c.publish.clone()).expect("converts");
        assert!(!format!("{c:?} {publish:?}").contains("SECRET"));
        assert_eq!(publish.shown(), "mqtt://gw:***@h:1883");
    }

    #[test]
    fn a_secret_and_its_file_together_are_refused() {
        let both = Command::try_parse_from(["x", "--http-token", "t", "--http-token-file", "f"]);
        assert!(both.is_err());
        let both =
            Command::try_parse_from(["x", "--mqtt-password", "p", "--mqtt-password-file", "f"]);
        assert!(both.is_err());
        let empty = Command::try_parse_from(["x", "--http-token", ""]);
        assert!(empty.is_err());
    }
}
