//! The `localize` command line: reads a recording or a reads file, localizes every tag and
//! writes the estimates as `GET /api/tags` does, with a progress bar on long inputs.

use std::io::BufRead;
use std::path::{Path, PathBuf};

use crate::localize::estimate::Estimator;
use crate::localize::offline::{self, Progress, SettingsFile};
use crate::localize::poses::Poses;
use crate::reads::{Read, ReadDecoder};
use crate::record::{Direction, RecordError, Recording};

/// Inputs this long (reads) get a progress bar on a terminal.
const PROGRESS_FROM: usize = 100_000;

/// `llrp-gateway localize`.
#[derive(Clone, Debug, clap::Args)]
pub struct LocalizeArgs {
    /// A recording (docs/recordings.md), a reads file (one JSON read a line, as
    /// `inventory --output` writes), or an MCAP file of this project's TagRead messages
    /// (docs/robotics.md).
    #[arg(required_unless_present = "subscribe", conflicts_with = "subscribe")]
    pub input: Option<PathBuf>,
    /// Antenna poses: JSON Lines or CSV with `t_us, reader, antenna, x, y, z, yaw_deg,
    /// pitch_deg` (reads with their own `antenna_pose` need none), or a robot's ROS 2 bag
    /// (MCAP file or rosbag2 directory) with `--pose-topic`.
    #[arg(long)]
    pub poses: Option<PathBuf>,
    /// The robot's poses in the `--poses` bag: a PoseStamped, PoseWithCovarianceStamped
    /// (`/amcl_pose`) or Odometry topic, or `/tf` with `--frames`.
    #[arg(long, default_value = "/amcl_pose")]
    pub pose_topic: String,
    /// The frame chain from the map to the robot on `/tf` (`map,odom,base_link`).
    #[arg(long, value_delimiter = ',')]
    pub frames: Vec<String>,
    /// An antenna's offset in the robot frame for bag poses: `[ANTENNA=]X,Y,Z,YAW_DEG` (m and
    /// degrees; without ANTENNA= for every antenna); repeatable; adds to the settings'
    /// `antenna_offsets`.
    #[arg(long, value_parser = crate::cli::localize_bag::parse_offset)]
    pub antenna_offset: Vec<crate::localize::offline::AntennaOffset>,
    /// The estimator (docs/localize.md).
    #[arg(long, default_value = "relock")]
    pub estimator: Estimator,
    /// Per-reader settings (JSON: phase sign, facing side, tag height, reference tags, clock
    /// offsets; docs/localize.md).
    #[arg(long)]
    pub settings: Option<PathBuf>,
    /// Where to write the estimates (`-` for standard output).
    #[arg(
        long,
        required_unless_present = "subscribe",
        conflicts_with = "subscribe"
    )]
    pub output: Option<PathBuf>,
    /// Replace an existing output file (without it, an existing file is refused).
    #[arg(long)]
    pub force: bool,
    /// Also write the estimates, and a 3D scene of them, to this MCAP file (ROS 2 messages;
    /// a worker writes them as it computes them; docs/robotics.md).
    #[arg(long, value_name = "FILE")]
    pub mcap: Option<PathBuf>,
    /// Run as a localizer worker on this MQTT broker's reads instead
    /// (`mqtt://[USER:PASS@]HOST[:PORT][/PREFIX]`; docs/fleet.md).
    #[command(flatten)]
    pub worker: crate::cli::worker::WorkerArgs,
}

/// Why `localize` could not localize its input.
#[derive(Debug, thiserror::Error)]
pub enum LocalizeCommandError {
    /// The settings file could not be loaded (the message names the file and why).
    #[error("{source}")]
    Settings {
        /// The file.
        path: PathBuf,
        /// Why.
        source: crate::localize::offline::SettingsError,
    },
    /// The pose file could not be loaded (the message names the file and why).
    #[error("{source}")]
    Poses {
        /// The file.
        path: PathBuf,
        /// Why.
        source: crate::localize::poses::PoseFileError,
    },
    /// An MCAP file could not be used (the message names the file, the topic and why).
    #[error("{0}")]
    Bag(#[from] crate::record::mcap::read::BagError),
    /// INPUT or `--output` is missing (clap requires both without `--subscribe`).
    #[error("INPUT and --output are needed (or --subscribe)")]
    Missing,
    /// The output file could not be created, or not put in place.
    #[error("{source}")]
    Output {
        /// The file.
        path: PathBuf,
        /// Why.
        source: crate::files::OutputError,
    },
    /// The input's reads could not be had.
    #[error("{0}")]
    Reads(#[from] ReadsError),
    /// The MCAP file could not be written.
    #[error("{}: {source}", path.display())]
    Mcap {
        /// The file.
        path: PathBuf,
        /// Why.
        source: crate::record::mcap::McapError,
    },
    /// The estimates could not be written as JSON.
    #[error("{0}")]
    Json(serde_json::Error),
    /// The estimates could not be written to the output file.
    #[error("{}: {source}", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
}

/// Runs `localize` on a file (the worker, with `--subscribe`, is [`crate::cli::worker::run`]).
pub fn run(args: &LocalizeArgs) -> Result<(), LocalizeCommandError> {
    type E = LocalizeCommandError;
    let settings = match &args.settings {
        Some(p) => SettingsFile::load(p).map_err(|source| E::Settings {
            path: p.clone(),
            source,
        })?,
        None => SettingsFile::default(),
    };
    // clap requires both without --subscribe.
    let (Some(input), Some(output)) = (&args.input, &args.output) else {
        return Err(E::Missing);
    };
    let output_error = |source| E::Output {
        path: output.clone(),
        source,
    };
    // The output is checked before the work: not an input, not an existing file.
    let mut out = if output.as_os_str() == "-" {
        None
    } else {
        let mut inputs: Vec<&std::path::Path> = vec![input];
        inputs.extend(args.poses.as_deref());
        inputs.extend(args.settings.as_deref());
        Some(crate::files::Output::create(output, &inputs, args.force).map_err(output_error)?)
    };
    let mut inputs: Vec<&std::path::Path> = vec![input, output];
    inputs.extend(args.poses.as_deref());
    inputs.extend(args.settings.as_deref());
    let mcap = match &args.mcap {
        Some(path) => Some(
            crate::files::Output::create(path, &inputs, args.force).map_err(|e| E::Mcap {
                path: path.clone(),
                source: e.into(),
            })?,
        ),
        None => None,
    };
    let reads = if crate::record::mcap::read::is_mcap(input) {
        crate::cli::localize_bag::bag_reads(input)?
    } else {
        load_reads(input)?
    };
    let poses = match &args.poses {
        Some(p) if crate::record::mcap::read::is_mcap(p) => {
            let mut offsets = settings.antenna_offsets.clone();
            offsets.extend(args.antenna_offset.iter().cloned());
            let topic = &args.pose_topic;
            crate::cli::localize_bag::bag_poses(p, topic, &args.frames, &offsets, &reads)?
        }
        Some(p) => Poses::load(p).map_err(|source| E::Poses {
            path: p.clone(),
            source,
        })?,
        None => Poses::new(),
    };
    let outcome = localize_with_progress(reads, poses, &settings, args.estimator);
    if let (Some(file), Some(path)) = (mcap, &args.mcap) {
        crate::cli::localize_mcap::write(file, &outcome.tags.tags).map_err(|source| E::Mcap {
            path: path.clone(),
            source,
        })?;
    }
    let json = serde_json::to_string_pretty(&outcome.tags).map_err(E::Json)?;
    match out.take() {
        None => println!("{json}"),
        Some(mut file) => {
            use std::io::Write;
            file.write_all((json + "\n").as_bytes())
                .and_then(|()| file.flush())
                .map_err(|source| E::Write {
                    path: output.clone(),
                    source,
                })?;
            file.commit().map_err(output_error)?;
        }
    }
    let a = outcome.set_aside;
    eprintln!(
        "llrp-gateway localize: {} tags from {} reads ({} set aside: {} without phase, {} without channel frequency, {} without a pose, {} under the RSSI floor)",
        outcome.tags.tags.len(),
        outcome.taken,
        a.total(),
        a.no_phase,
        a.no_frequency,
        a.no_pose,
        a.weak
    );
    for hint in set_aside_hints(&a, args.poses.is_some()) {
        eprintln!("llrp-gateway localize: {hint}");
    }
    Ok(())
}

/// Localizes `reads` as `localize` does, with a progress bar on long inputs.
fn localize_with_progress(
    reads: Vec<Read>,
    poses: Poses,
    settings: &SettingsFile,
    estimator: Estimator,
) -> offline::Outcome {
    let bar = if reads.len() >= PROGRESS_FROM {
        indicatif::ProgressBar::new(reads.len() as u64)
    } else {
        indicatif::ProgressBar::hidden()
    };
    bar.set_style(
        indicatif::ProgressStyle::with_template("{msg:>9} [{bar:40}] {pos}/{len} ({eta})")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    bar.set_message("reads");
    let mut tags_started = false;
    let outcome = offline::localize(reads, poses, settings, estimator, &mut |p| match p {
        Progress::Read => bar.inc(1),
        Progress::Tag => {
            if !tags_started {
                tags_started = true;
                bar.set_message("tags");
                bar.set_position(0);
                bar.set_length(0);
            }
            bar.inc_length(1);
            bar.inc(1);
        }
    });
    bar.finish_and_clear();
    outcome
}

/// What to do about the reads set aside, one sentence per cause that set some aside.
fn set_aside_hints(a: &crate::localize::ingest::SetAside, have_poses: bool) -> Vec<String> {
    let mut hints = Vec::new();
    if a.no_pose > 0 {
        hints.push(if have_poses {
            format!(
                "{} reads fall outside the pose file's time span (or name a reader or antenna it \
                 lacks): its t_us must be on the reads' clock (settings' clock_offsets_us)",
                a.no_pose
            )
        } else {
            format!(
                "{} reads have no antenna pose: give one with --poses FILE (JSON Lines or CSV of \
                 t_us, reader, antenna, x, y, z, yaw_deg; `jq -c '.antennas[].estimated' \
                 truth.jsonl` makes one from `sim --truth`), or localize reads that carry their \
                 own antenna_pose",
                a.no_pose
            )
        });
    }
    if a.no_phase > 0 {
        hints.push(format!(
            "{} reads have no phase: the localizer needs the Impinj RF phase \
             (`llrp-gateway inventory --impinj`, sllurp --impinj-reports)",
            a.no_phase
        ));
    }
    if a.no_frequency > 0 {
        hints.push(format!(
            "{} reads have no channel frequency: a read needs channel_frequency_hz, written \
             when the reader's hop table is known (`inventory` reads it from the reader's \
             capabilities, `proxy` from the session or --region)",
            a.no_frequency
        ));
    }
    hints
}

/// Why the reads of `localize`'s input could not be had.
#[derive(Debug, thiserror::Error)]
pub enum ReadsError {
    /// The file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The recording is bad.
    #[error("{path}: {source}")]
    Recording {
        /// The file.
        path: PathBuf,
        /// Why.
        source: RecordError,
    },
    /// A line of the reads file is bad.
    #[error("{path}: line {line}: {message}")]
    Reads {
        /// The file.
        path: PathBuf,
        /// The line.
        line: usize,
        /// Why.
        message: String,
    },
}

/// The reads of a recording (every connection's frames from the reader) or a reads file
/// (one JSON read a line), told apart by the first line.
pub fn load_reads(path: &Path) -> Result<Vec<Read>, ReadsError> {
    let io = |source| ReadsError::Io {
        path: path.to_owned(),
        source,
    };
    let file = std::fs::File::open(path).map_err(io)?;
    let mut input = std::io::BufReader::new(file);
    let first = input.fill_buf().map_err(io)?;
    if !first.starts_with(b"{\"llrp_recording\"") {
        return crate::reads::read_jsonl(input).map_err(|e| ReadsError::Reads {
            path: path.to_owned(),
            line: e.line,
            message: e.message,
        });
    }
    let recording = Recording::read(input).map_err(|source| ReadsError::Recording {
        path: path.to_owned(),
        source,
    })?;
    let reader = recording
        .header
        .reader_name()
        .map_err(|source| ReadsError::Recording {
            path: path.to_owned(),
            source,
        })?;
    let mut reads = Vec::new();
    for conn in recording.connections() {
        let mut decoder = ReadDecoder::new(Some(reader.clone()));
        for (at, dir, frame) in recording.frames(conn) {
            // An RO_ACCESS_REPORT that does not decode is skipped: its reads are lost, the
            // others are not.
            if dir == Direction::FromReader {
                let _ = decoder.frame(frame, at.utc_us, &mut reads);
            }
        }
    }
    Ok(reads)
}
