//! `sim --tag-memory FILE`: the tags' memory read from the file at the start (when it
//! exists) and written back whenever operations changed it (checked every second) and once
//! more at the end, so a run begins where the last ended. The file's format is
//! `reader::memory_file`'s; each write goes to a temporary file renamed over the old one, so
//! a crash leaves the last whole state, never half a file.

use std::io;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use tokio::sync::watch;
use tokio::task::JoinHandle;

use crate::physics::Model;
use crate::reader::memory::TagMemory;
use crate::reader::memory_file;

/// How often the saver looks whether the memory changed.
pub const SAVE_EVERY: Duration = Duration::from_secs(1);

/// Why the tag memory file could not be used.
#[derive(Debug, thiserror::Error)]
pub enum TagMemoryError {
    /// It could not be read.
    #[error("tag memory {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: io::Error,
    },
    /// Its content is not a tag memory of this scenario.
    #[error("tag memory {path}: {source}")]
    Content {
        /// The file.
        path: PathBuf,
        /// The field and why.
        source: memory_file::MemoryFileError,
    },
}

/// Writes the run's tag memory to its file when it changed.
pub struct Saver {
    path: PathBuf,
    model: Arc<Model>,
    memory: Arc<TagMemory>,
    /// The memory's generation when it was last written (or read).
    saved: AtomicU64,
}

impl Saver {
    /// A saver of `memory` to `path`, after putting the file's tags into `memory` when it
    /// exists; `model` names the scenario's tags.
    pub fn open(
        path: &Path,
        model: Arc<Model>,
        memory: Arc<TagMemory>,
    ) -> Result<Saver, TagMemoryError> {
        match std::fs::read_to_string(path) {
            Ok(text) => {
                let n = memory_file::restore(&model, &memory, &text).map_err(|source| {
                    TagMemoryError::Content {
                        path: path.to_owned(),
                        source,
                    }
                })?;
                tracing::info!("tag memory: {n} tags as {} left them", path.display());
            }
            Err(e) if e.kind() == io::ErrorKind::NotFound => {}
            Err(source) => {
                return Err(TagMemoryError::Read {
                    path: path.to_owned(),
                    source,
                })
            }
        }
        let saved = AtomicU64::new(memory.generation());
        Ok(Saver {
            path: path.to_owned(),
            model,
            memory,
            saved,
        })
    }

    /// Writes the memory out if it may have changed since the last write.
    pub fn save_if_changed(&self) -> io::Result<()> {
        let now = self.memory.generation();
        if now == self.saved.load(Ordering::Acquire) {
            return Ok(());
        }
        let text = memory_file::to_json(&self.model, &self.memory);
        let mut tmp = self.path.clone().into_os_string();
        tmp.push(".tmp");
        let tmp = PathBuf::from(tmp);
        std::fs::write(&tmp, text)?;
        std::fs::rename(&tmp, &self.path)?;
        self.saved.store(now, Ordering::Release);
        Ok(())
    }

    /// [`Saver::save_if_changed`] off the async workers, the failure logged.
    pub async fn save(self: &Arc<Self>) {
        let me = self.clone();
        match tokio::task::spawn_blocking(move || me.save_if_changed()).await {
            Ok(Ok(())) => {}
            Ok(Err(e)) => tracing::error!("writing the tag memory {}: {e}", self.path.display()),
            Err(e) => tracing::error!("the tag memory's writer failed: {e}"),
        }
    }

    /// Saves every [`SAVE_EVERY`] until `shutdown` asks to stop (the last save is the
    /// shutdown's, once the readers have stopped).
    pub fn spawn(self: &Arc<Self>, mut shutdown: watch::Receiver<bool>) -> JoinHandle<()> {
        let me = self.clone();
        tokio::spawn(async move {
            loop {
                tokio::select! {
                    _ = tokio::time::sleep(SAVE_EVERY) => me.save().await,
                    changed = shutdown.changed() => {
                        if crate::net::serve::stopping(changed, &shutdown) {
                            return;
                        }
                    }
                }
            }
        })
    }
}
