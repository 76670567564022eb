//! The localizer and MQTT options of `proxy`, `replay` and `inventory` ([`LiveArgs`]) and what
//! they start beside the LLRP client ([`start_sinks`]): the localizer with its HTTP API when
//! `--http ADDR` is given, the publisher when `--publish URL` is, through
//! [`super::root::Consumers`].

use std::path::PathBuf;

use super::args::HttpArgs;
use super::root::{Consumers, ConsumersError, Plan};
use crate::gateway::live::settings_from;
use crate::http::launch::LaunchOptions;
use crate::localize::estimate::Estimator;
use crate::localize::live::{Input, Settings};
use crate::localize::offline::SettingsFile;
use crate::localize::poses::{PoseFileError, Poses};
use crate::localize::settings::SettingsError;

/// The localizer options of `proxy`, `replay` and `inventory`.
#[derive(clap::Args, Clone, Debug, PartialEq)]
pub struct LiveArgs {
    /// The HTTP API and live map (off unless `--http ADDR`; docs/http.md).
    #[command(flatten)]
    pub http: HttpArgs,
    /// Antenna poses for the localizer: JSON Lines or CSV with `t_us, reader, antenna, x, y,
    /// z, yaw_deg, pitch_deg` (robots may also POST them to /api/poses).
    #[arg(long, value_name = "FILE")]
    pub poses: Option<PathBuf>,
    /// The localizer's per-reader settings (JSON; docs/localize.md).
    #[arg(long, value_name = "FILE")]
    pub localize_settings: Option<PathBuf>,
    /// The localizer's estimator.
    #[arg(long, default_value = "relock")]
    pub estimator: Estimator,
    /// Publishing to an MQTT broker (docs/fleet.md).
    #[command(flatten)]
    pub publish: super::args::PublishArgs,
}

/// Why the localizer, its API or the publisher could not be started.
#[derive(Debug, thiserror::Error)]
pub enum SinksError {
    /// The settings file is bad (the message names the file and the field).
    #[error("{0}")]
    Settings(#[from] SettingsError),
    /// The pose file is bad (the message names the file and the line).
    #[error("{0}")]
    Poses(#[from] PoseFileError),
    /// A secret's file (`--http-token-file`, `--mqtt-password-file`) gave no secret.
    #[error("{0}")]
    Secret(#[from] super::args::SecretOptionError),
    /// The localizer, its API or the publisher did not start.
    #[error("{0}")]
    Consumers(#[from] ConsumersError),
}

/// Starts what the reads go to beside the LLRP client (the localizer and its API when
/// `--http` was given, the publisher when `--publish` was; [`super::root`]), with the
/// settings and pose files of `args`; `command` names the command in messages.
pub async fn start_sinks(args: &LiveArgs, command: &str) -> Result<Consumers, SinksError> {
    let http_options = LaunchOptions::try_from(args.http.clone())?;
    let publish = crate::fleet::args::PublishConfig::try_from(args.publish.clone())?;
    let http = http_options.address(None);
    let file = match &args.localize_settings {
        Some(p) if http.is_some() || args.publish.publish.is_some() => SettingsFile::load(p)?,
        _ => SettingsFile::default(),
    };
    let mut settings = Settings::default();
    let mut prime = Vec::new();
    if http.is_some() {
        let poses = match &args.poses {
            Some(p) => Poses::load(p)?,
            None => Poses::new(),
        };
        settings = settings_from(&file, &poses, args.estimator);
        for (reader, offset) in &file.clock_offsets_us {
            prime.push(Input::Reader {
                name: reader.clone(),
                hop_table: None,
                antennas: Vec::new(),
                clock_offset_us: *offset,
                poses: None,
            });
        }
        let samples = poses.samples();
        prime.extend(samples.chunks(1024).map(|c| Input::Poses(c.to_vec())));
    }
    let references = file.references.iter().map(|r| r.epc.to_string()).collect();
    Ok(Consumers::start(Plan {
        command,
        http,
        http_args: &http_options,
        simulation: false,
        settings,
        prime,
        publish: &publish,
        references,
        headless: false,
        gpio: None,
        faults: None,
    })
    .await?)
}
