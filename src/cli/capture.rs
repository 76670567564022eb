//! `llrp-gateway export` (a recording as a pcapng capture that Wireshark dissects as LLRP) and
//! `llrp-gateway import` (the LLRP streams of a pcap or pcapng capture as a recording): their
//! arguments and runners. The conversions themselves: [`crate::record::pcapng`].

use std::io::Write;
use std::path::{Path, PathBuf};

use crate::files::{Output, OutputError};
use crate::record::pcapng::{
    export, import_into, ExportError, ExportOptions, ImportError, JsonLines, DEFAULT_MSS,
};
use crate::record::{RecordError, Recording};

/// `llrp-gateway export`: a recording as a pcapng capture.
#[derive(Clone, Debug, clap::Args)]
pub struct ExportArgs {
    /// The recording (JSON Lines) to export.
    pub file: PathBuf,
    /// The pcapng capture to write.
    #[arg(long, value_name = "OUT")]
    pub pcapng: PathBuf,
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
    // The output is checked (not the input, not an existing file) before anything is read.
    let mut output = Output::create(&args.pcapng, &[&args.file], args.force)?;
    let recording = open_recording(&args.file)?;
    let summary =
        export(&recording, &ExportOptions { mss: args.mss }, &mut output).map_err(|source| {
            ExportCommandError::Export {
                out: args.pcapng.clone(),
                source,
            }
        })?;
    output.flush().map_err(|source| ExportCommandError::Write {
        out: args.pcapng.clone(),
        source,
    })?;
    output.commit()?;
    eprintln!(
        "llrp-gateway export: {} TCP streams, {} frames, {} bytes entries: {} packets in {}",
        summary.streams,
        summary.frames,
        summary.bytes_entries,
        summary.packets,
        args.pcapng.display()
    );
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
