//! The one rule for every file a command writes: an existing file is not replaced unless the
//! user says `--force`, a command never writes over one of its own inputs, and a file written
//! in one go appears whole or not at all.
//!
//! - [`Output::create`] for a file written in one go (`export`, `import`, `localize`):
//!   the bytes go to a hidden temporary file beside the target, and [`Output::commit`] moves
//!   it into place (without `--force`, by a hard link that fails if the target appeared in the
//!   meantime). Dropped before the commit (an error, a panic), the temporary file is removed
//!   and the target is untouched.
//! - [`create_stream`] for a file written as things happen and read while it grows (the
//!   inventory's reads, the simulator's truth): created new (or truncated with `--force`) in
//!   place, like the recorder's files, so what was written survives an abrupt end.
//!
//! A target that exists and is not a regular file (`/dev/null`, a FIFO, a terminal) is
//! written directly: there is nothing there to destroy.

use std::fs::{File, OpenOptions};
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// Why an output file cannot be written.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// The target exists and `--force` was not given.
    #[error("{0}: the file exists; give --force to replace it")]
    Exists(PathBuf),
    /// The target is one of the command's inputs.
    #[error("{0}: this is the input; writing it would destroy it")]
    IsInput(PathBuf),
    /// The file system refused.
    #[error("{path}: {source}")]
    Io {
        /// The target.
        path: PathBuf,
        /// What went wrong.
        source: io::Error,
    },
}

impl OutputError {
    /// The error without the file's name, for callers that name it themselves.
    pub fn into_io(self) -> io::Error {
        match self {
            OutputError::Exists(_) => io::Error::new(
                io::ErrorKind::AlreadyExists,
                "the file exists; give --force to replace it",
            ),
            OutputError::IsInput(_) => io::Error::new(
                io::ErrorKind::InvalidInput,
                "this is the input; writing it would destroy it",
            ),
            OutputError::Io { source, .. } => source,
        }
    }

    fn io(path: &Path, source: io::Error) -> Self {
        OutputError::Io {
            path: path.to_owned(),
            source,
        }
    }
}

/// Refuses `target` when it is one of `inputs` (the same file, by any name) or, without
/// `force`, when it exists as a regular file. `Ok(true)`: the target is a special file (a
/// device, a FIFO) to be written directly.
fn check(target: &Path, inputs: &[&Path], force: bool) -> Result<bool, OutputError> {
    let meta = match std::fs::metadata(target) {
        Ok(m) => m,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(false),
        Err(e) => return Err(OutputError::io(target, e)),
    };
    for input in inputs {
        if same_file(&meta, input) {
            return Err(OutputError::IsInput(target.to_owned()));
        }
    }
    if !meta.is_file() {
        return Ok(true);
    }
    if !force {
        return Err(OutputError::Exists(target.to_owned()));
    }
    Ok(false)
}

/// Whether `path` names the file `meta` describes (same device and inode).
fn same_file(meta: &std::fs::Metadata, path: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    std::fs::metadata(path).is_ok_and(|m| m.dev() == meta.dev() && m.ino() == meta.ino())
}

/// Opens a file that is written as things happen: new, or (with `force`) truncated; never one
/// of `inputs`.
pub fn create_stream(target: &Path, inputs: &[&Path], force: bool) -> Result<File, OutputError> {
    let special = check(target, inputs, force)?;
    let mut options = OpenOptions::new();
    options.write(true);
    if special {
        // A device or FIFO: opened as it is.
    } else if force {
        options.create(true).truncate(true);
    } else {
        options.create_new(true);
    }
    options.open(target).map_err(|e| match e.kind() {
        io::ErrorKind::AlreadyExists => OutputError::Exists(target.to_owned()),
        _ => OutputError::io(target, e),
    })
}

/// A file written in one go: whole once committed, absent otherwise.
#[derive(Debug)]
pub struct Output {
    target: PathBuf,
    /// The temporary file beside the target (none for a special file written directly).
    temp: Option<PathBuf>,
    file: Option<io::BufWriter<File>>,
    force: bool,
}

/// Tells apart the temporary files of one process.
static TEMP_SERIAL: AtomicU64 = AtomicU64::new(0);

impl Output {
    /// Starts writing `target`, refusing it as [`create_stream`] does.
    pub fn create(target: &Path, inputs: &[&Path], force: bool) -> Result<Output, OutputError> {
        if check(target, inputs, force)? {
            let file = OpenOptions::new()
                .write(true)
                .open(target)
                .map_err(|e| OutputError::io(target, e))?;
            return Ok(Output {
                target: target.to_owned(),
                temp: None,
                file: Some(io::BufWriter::new(file)),
                force,
            });
        }
        let name = target
            .file_name()
            .ok_or_else(|| OutputError::io(target, io::Error::other("not a file name")))?;
        let serial = TEMP_SERIAL.fetch_add(1, Ordering::Relaxed);
        let mut temp_name = std::ffi::OsString::from(".");
        temp_name.push(name);
        temp_name.push(format!(".{}.{serial}.partial", std::process::id()));
        let temp = target.with_file_name(temp_name);
        let file = OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&temp)
            .map_err(|e| OutputError::io(target, e))?;
        Ok(Output {
            target: target.to_owned(),
            temp: Some(temp),
            file: Some(io::BufWriter::new(file)),
            force,
        })
    }

    /// The file's final name.
    pub fn path(&self) -> &Path {
        &self.target
    }

    /// Moves the whole file into place.
    pub fn commit(mut self) -> Result<(), OutputError> {
        let target = self.target.clone();
        let file = self.file.take().map(io::BufWriter::into_inner);
        let Some(file) = file else {
            return Ok(());
        };
        let file = file.map_err(|e| OutputError::io(&target, e.into_error()))?;
        let Some(temp) = self.temp.clone() else {
            return Ok(());
        };
        file.sync_all().map_err(|e| OutputError::io(&target, e))?;
        drop(file);
        if self.force {
            std::fs::rename(&temp, &target).map_err(|e| OutputError::io(&target, e))?;
        } else {
            // A link fails if the target appeared since the check: nothing is replaced.
            match std::fs::hard_link(&temp, &target) {
                Ok(()) => {}
                Err(e) if e.kind() == io::ErrorKind::AlreadyExists => {
                    return Err(OutputError::Exists(target));
                }
                Err(e) => return Err(OutputError::io(&target, e)),
            }
            let _ = std::fs::remove_file(&temp);
        }
        self.temp = None;
        Ok(())
    }
}

impl Write for Output {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        match &mut self.file {
            Some(f) => f.write(buf),
            None => Err(io::Error::other("the output is committed")),
        }
    }

    fn flush(&mut self) -> io::Result<()> {
        match &mut self.file {
            Some(f) => f.flush(),
            None => Ok(()),
        }
    }
}

impl Drop for Output {
    fn drop(&mut self) {
        self.file = None;
        if let Some(temp) = self.temp.take() {
            let _ = std::fs::remove_file(temp);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .expect("dir")
            .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn a_committed_output_appears_whole_and_an_uncommitted_one_leaves_nothing() {
        let dir = tempfile::tempdir().expect("dir");
        let target = dir.path().join("out.pcapng");
        let mut o = Output::create(&target, &[], false).expect("creates");
        o.write_all(b"half").expect("writes");
        assert!(!target.exists(), "nothing at the target before the commit");
        drop(o);
        assert!(names(dir.path()).is_empty(), "{:?}", names(dir.path()));
        let mut o = Output::create(&target, &[], false).expect("creates");
        o.write_all(b"whole").expect("writes");
        o.commit().expect("commits");
        assert_eq!(std::fs::read(&target).expect("reads"), b"whole");
        assert_eq!(names(dir.path()), ["out.pcapng"]);
    }

    #[test]
    fn an_existing_file_is_kept_unless_forced_and_an_input_never_written() {
        let dir = tempfile::tempdir().expect("dir");
        let input = dir.path().join("rec.jsonl");
        std::fs::write(&input, "recording").expect("write");
        let other = dir.path().join("old.csv");
        std::fs::write(&other, "old").expect("write");
        let e = Output::create(&other, &[&input], false).expect_err("exists");
        assert!(matches!(e, OutputError::Exists(_)), "{e}");
        assert!(e.to_string().contains("--force"), "{e}");
        let e = create_stream(&other, &[], false).expect_err("exists");
        assert!(matches!(e, OutputError::Exists(_)), "{e}");
        // The input by another name, even with --force.
        let alias = dir.path().join("sub/../rec.jsonl");
        std::fs::create_dir(dir.path().join("sub")).expect("dir");
        for force in [false, true] {
            let e = Output::create(&alias, &[&input], force).expect_err("input");
            assert!(matches!(e, OutputError::IsInput(_)), "{e}");
            let e = create_stream(&input, &[&input], force).expect_err("input");
            assert!(matches!(e, OutputError::IsInput(_)), "{e}");
        }
        assert_eq!(std::fs::read(&input).expect("reads"), b"recording");
        let mut o = Output::create(&other, &[&input], true).expect("forced");
        o.write_all(b"new").expect("writes");
        o.commit().expect("commits");
        assert_eq!(std::fs::read(&other).expect("reads"), b"new");
    }

    #[test]
    fn a_target_that_appears_before_the_commit_is_not_replaced() {
        let dir = tempfile::tempdir().expect("dir");
        let target = dir.path().join("out");
        let mut o = Output::create(&target, &[], false).expect("creates");
        o.write_all(b"mine").expect("writes");
        std::fs::write(&target, "theirs").expect("write");
        let e = o.commit().expect_err("appeared");
        assert!(matches!(e, OutputError::Exists(_)), "{e}");
        assert_eq!(std::fs::read(&target).expect("reads"), b"theirs");
        assert_eq!(names(dir.path()), ["out"]);
    }

    #[test]
    fn a_special_file_is_written_directly() {
        let mut o = Output::create(Path::new("/dev/null"), &[], false).expect("dev null");
        o.write_all(b"gone").expect("writes");
        o.commit().expect("commits");
        create_stream(Path::new("/dev/null"), &[], false).expect("dev null");
    }
}
