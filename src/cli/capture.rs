//! `llrp-gateway export` (a recording as a pcapng capture that Wireshark dissects as LLRP, and
//! as an MCAP file of ROS 2 messages) and `llrp-gateway import` (the LLRP streams of a pcap or
//! pcapng capture as a recording): their arguments and runners. The conversions themselves:
//! [`crate::record::pcapng`], [`crate::record::mcap`].

use std::io::Write;
use std::path::{Path, PathBuf};

use crate::files::{Output, OutputError};
use crate::record::mcap::{self as mcap_out, McapError};
use crate::record::pcapng::{
    export, import_into, ExportError, ExportOptions, ImportError, JsonLines, DEFAULT_MSS,
};
use crate::record::{RecordError, Recording};

/// `llrp-gateway export`: a recording as a pcapng capture, an MCAP file, or both.
#[derive(Clone, Debug, clap::Args)]
#[command(group = clap::ArgGroup::new("out").required(true).multiple(true).args(["pcapng", "mcap"]))]
pub struct ExportArgs {
    /// The recording (JSON Lines) to export.
    pub file: PathBuf,
    /// The pcapng capture to write.
    #[arg(long, value_name = "OUT")]
    pub pcapng: Option<PathBuf>,
    /// The MCAP file to write (ROS 2 messages: frames, tag reads, reader events;
    /// docs/robotics.md).
    #[arg(long, value_name = "OUT")]
    pub mcap: Option<PathBuf>,
    /// Largest TCP payload of a packet; longer frames are split into several segments.
    #[arg(long, default_value_t = DEFAULT_MSS,
          value_parser = crate::cli::options::parser::<u16>("mss"))]
    pub mss: u16,
    /// Replace an existing capture (without it, an existing file is refused).
    #[arg(long)]
    pub force: bool,
}

/// `llrp-gateway import`: the LLRP streams of a capture as a recording.
#[derive(Clone, Debug, clap::Args)]
pub struct ImportArgs {
    /// The capture (pcap or pcapng) to read.
    pub capture: PathBuf,
    /// The recording to write.
    #[arg(long, value_name = "RECORDING")]
    pub output: PathBuf,
    /// Replace an existing recording (without it, an existing file is refused).
    #[arg(long)]
    pub force: bool,
}

/// Why `export` failed.
#[derive(Debug, thiserror::Error)]
pub enum ExportCommandError {
    /// The capture cannot be written there (it exists, it is the input, or the file system
    /// refused), or it could not be put in place at the end.
    #[error("{0}")]
    Output(#[from] OutputError),
    /// The recording cannot be read.
    #[error("{}: {source}", path.display())]
    Recording {
        /// The recording.
        path: PathBuf,
        /// Why.
        source: RecordError,
    },
    /// The recording cannot be exported (an MSS out of range, a write that failed).
    #[error("{}: {source}", out.display())]
    Export {
        /// The capture.
        out: PathBuf,
        /// Why.
        source: ExportError,
    },
    /// The capture's last bytes could not be written.
    #[error("writing {}: {source}", out.display())]
    Write {
        /// The capture.
        out: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The MCAP file could not be written.
    #[error("{}: {source}", out.display())]
    Mcap {
        /// The MCAP file.
        out: PathBuf,
        /// Why.
        source: McapError,
    },
}

/// Why `import` failed.
#[derive(Debug, thiserror::Error)]
pub enum ImportCommandError {
    /// The recording cannot be written there (it exists, it is the input, or the file system
    /// refused), or it could not be put in place at the end.
    #[error("{0}")]
    Output(#[from] OutputError),
    /// The capture cannot be read.
    #[error("cannot read {}: {source}", path.display())]
    Read {
        /// The capture.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The capture is not one, or holds no LLRP stream.
    #[error("{}: {source}", path.display())]
    Import {
        /// The capture.
        path: PathBuf,
        /// Why.
        source: ImportError,
    },
    /// The capture's LLRP streams hold no whole frame.
    #[error("{}: no LLRP frame could be read (see the warnings above); {} not written", path.display(), out.display())]
    NoFrames {
        /// The capture.
        path: PathBuf,
        /// The recording not written.
        out: PathBuf,
    },
    /// The recording could not be written.
    #[error("cannot write {}: {source}", out.display())]
    Write {
        /// The recording.
        out: PathBuf,
        /// Why.
        source: std::io::Error,
    },
}

/// Runs `llrp-gateway export`; warnings and a summary go to standard error.
pub fn run_export(args: &ExportArgs) -> Result<(), ExportCommandError> {
    // The outputs are checked (not the input, not an existing file) before anything is read.
    let pcapng = match &args.pcapng {
        Some(p) => Some((p, Output::create(p, &[&args.file], args.force)?)),
        None => None,
    };
    let mcap = match &args.mcap {
        Some(p) => Some((p, Output::create(p, &[&args.file], args.force)?)),
        None => None,
    };
    let recording = open_recording(&args.file)?;
    if let Some((path, output)) = pcapng {
        export_pcapng(&recording, args.mss, path, output)?;
    }
    if let Some((path, output)) = mcap {
        export_mcap(&recording, path, output)?;
    }
    Ok(())
}

/// The recording as a pcapng capture at `path`.
fn export_pcapng(
    recording: &Recording,
    mss: u16,
    path: &Path,
    mut output: Output,
) -> Result<(), ExportCommandError> {
    let summary = export(recording, &ExportOptions { mss }, &mut output).map_err(|source| {
        ExportCommandError::Export {
            out: path.to_owned(),
            source,
        }
    })?;
    output.flush().map_err(|source| ExportCommandError::Write {
        out: path.to_owned(),
        source,
    })?;
    output.commit()?;
    eprintln!(
        "llrp-gateway export: {} TCP streams, {} frames, {} bytes entries: {} packets in {}",
        summary.streams,
        summary.frames,
        summary.bytes_entries,
        summary.packets,
        path.display()
    );
    Ok(())
}

/// The recording as an MCAP file at `path`.
fn export_mcap(
    recording: &Recording,
    path: &Path,
    output: Output,
) -> Result<(), ExportCommandError> {
    let mcap_error = |source| ExportCommandError::Mcap {
        out: path.to_owned(),
        source,
    };
    let (summary, mut output) = mcap_out::export(recording, output).map_err(mcap_error)?;
    output.flush().map_err(|source| ExportCommandError::Write {
        out: path.to_owned(),
        source,
    })?;
    output.commit()?;
    eprintln!(
        "llrp-gateway export: {} frames, {} tag reads, {} reader events: {} messages on {} \
         channels in {}",
        summary.frames,
        summary.reads,
        summary.events,
        summary.messages,
        summary.channels,
        path.display()
    );
    if summary.undecodable_reports > 0 {
        eprintln!(
            "llrp-gateway export: warning: {} RO_ACCESS_REPORTs did not decode (kept as frames, \
             no reads from them)",
            summary.undecodable_reports
        );
    }
    Ok(())
}

/// The recording at `path`, its warnings said on standard error.
fn open_recording(path: &Path) -> Result<Recording, ExportCommandError> {
    let recording = Recording::open(path).map_err(|source| ExportCommandError::Recording {
        path: path.to_owned(),
        source,
    })?;
    for w in &recording.warnings {
        eprintln!("llrp-gateway export: warning: {}: {w}", path.display());
    }
    Ok(recording)
}

/// Runs `llrp-gateway import`: the capture is read and the recording written as they go
/// (bounded memory); warnings and a summary go to standard error.
pub fn run_import(args: &ImportArgs) -> Result<(), ImportCommandError> {
    let name = args.capture.display();
    let mut output = Output::create(&args.output, &[&args.capture], args.force)?;
    let file = std::fs::File::open(&args.capture).map_err(|source| ImportCommandError::Read {
        path: args.capture.clone(),
        source,
    })?;
    let summary = import_into(file, &mut JsonLines(&mut output)).map_err(|source| {
        ImportCommandError::Import {
            path: args.capture.clone(),
            source,
        }
    })?;
    for w in &summary.warnings {
        eprintln!("llrp-gateway import: warning: {name}: {w}");
    }
    if summary.frames == 0 {
        // The partial recording is removed when `output` is dropped uncommitted.
        return Err(ImportCommandError::NoFrames {
            path: args.capture.clone(),
            out: args.output.clone(),
        });
    }
    output.flush().map_err(|source| ImportCommandError::Write {
        out: args.output.clone(),
        source,
    })?;
    output.commit()?;
    eprintln!(
        "llrp-gateway import: {} connections, {} frames, reader {}: {}",
        summary.connections,
        summary.frames,
        summary.upstream,
        args.output.display()
    );
    Ok(())
}
