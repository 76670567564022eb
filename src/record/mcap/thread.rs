//! [`McapThread`]: an [`McapOut`] on a thread of its own. Running commands hand it what
//! they see through a bounded queue (an `await` when it is full, which holds no thread);
//! every write of the file happens on that thread, never on an async worker.

use std::io::Write;
use std::thread::JoinHandle;

use bytes::Bytes;
use tokio::sync::mpsc;

use super::{McapError, McapOut, Summary};
use crate::reads::Read;
use crate::record::{Direction, Entry};

/// Items that may wait for the writer before senders wait.
const QUEUE: usize = 1024;

/// What a running command hands the MCAP writer.
#[derive(Clone, Debug)]
pub enum McapItem {
    /// Tag reads received at `received_us` (UTC µs).
    Reads {
        /// When the gateway received them.
        received_us: u64,
        /// The reads.
        reads: Vec<Read>,
    },
    /// One frame of a reader's connection.
    Frame {
        /// The reader's name.
        reader: String,
        /// Connection number.
        conn: u32,
        /// Which way it went.
        dir: Direction,
        /// When it was received, UTC µs.
        received_us: u64,
        /// The frame.
        frame: Bytes,
    },
    /// Entries of a recording of a reader's sessions, in order (what a [`crate::record::Recorder`]
    /// with a [`McapTee`] hands on).
    Entries {
        /// The reader's name.
        reader: String,
        /// The entries.
        entries: Vec<Entry>,
    },
    /// What a simulation knows of a reader at one instant: poses and ground truth.
    Truth(super::geo::Truth),
    /// Antenna poses a running gateway received from outside.
    Poses(super::geo::ReceivedPoses),
    /// Write the scene as it stands, stamped at this instant (UTC µs): where no simulation's
    /// truth paces it.
    Scene(u64),
    /// One estimate the live localizer published.
    Estimate(super::estimates::EstimateItem),
    /// What the scene shows of the world that does not move.
    SceneWorld(super::scene::SceneWorld),
    /// Ends the file, whoever else still holds a sender ([`McapThread::finish`] sends it).
    Close,
}

/// Where a recorder hands its entries on, besides its file: the MCAP writer's queue and the
/// reader's name in the MCAP file. Its sends block (the recorder runs on a thread of its own).
#[derive(Clone, Debug)]
pub struct McapTee {
    /// The reader's name (its topics' token, the messages' `reader`).
    pub reader: String,
    tx: mpsc::Sender<McapItem>,
}

impl McapTee {
    /// The same queue, for reader `reader`.
    pub fn named(&self, reader: &str) -> McapTee {
        McapTee {
            reader: reader.to_string(),
            tx: self.tx.clone(),
        }
    }

    /// Hands `entries` to the MCAP writer, waiting (blocking the calling thread, which must
    /// not be an async worker) for room; false if the writer is gone.
    pub fn send_blocking(&self, entries: Vec<Entry>) -> bool {
        let item = McapItem::Entries {
            reader: self.reader.clone(),
            entries,
        };
        self.tx.blocking_send(item).is_ok()
    }
}

/// The MCAP writer's thread and the queue to it.
pub struct McapThread {
    tx: mpsc::Sender<McapItem>,
    handle: JoinHandle<Result<Summary, McapError>>,
}

impl McapThread {
    /// Starts the file on `out` (on the caller's thread, so that an error shows at once) and
    /// the thread that writes it.
    pub fn start<W: Write + Send + 'static>(out: W) -> Result<McapThread, McapError> {
        McapThread::start_out(McapOut::new(out)?)
    }

    /// Starts the thread that writes `mcap` (a file already started, perhaps with a tap).
    pub fn start_out<W: Write + Send + 'static>(mcap: McapOut<W>) -> Result<McapThread, McapError> {
        let (tx, rx) = mpsc::channel(QUEUE);
        let handle = std::thread::Builder::new()
            .name("mcap-writer".into())
            .spawn(move || write_all(mcap, rx))
            .map_err(|e| McapError::Mcap { error: e.into() })?;
        Ok(McapThread { tx, handle })
    }

    /// Creates the file at `path` (an existing one is refused unless `force`) and starts its
    /// writer. Opening the file is blocking IO: call it before the async work starts.
    pub fn create(path: &std::path::Path, force: bool) -> Result<McapThread, McapError> {
        let file = crate::files::create_stream(path, &[], force)?;
        McapThread::start(std::io::BufWriter::new(file))
    }

    /// [`finish`](McapThread::finish) on a blocking thread, from async code.
    pub async fn finish_async(self) -> Result<Summary, McapError> {
        tokio::task::spawn_blocking(move || self.finish())
            .await
            .unwrap_or(Err(McapError::ThreadGone))
    }

    /// Hands `item` to the writer, waiting for room in the queue.
    pub async fn send(&self, item: McapItem) -> Result<(), McapError> {
        self.tx.send(item).await.map_err(|_| McapError::ThreadGone)
    }

    /// A tee for a recorder of `reader`'s sessions into this file.
    pub fn tee(&self, reader: &str) -> McapTee {
        McapTee {
            reader: reader.to_string(),
            tx: self.tx.clone(),
        }
    }

    /// A sender into the queue (for tasks that outlive a borrow of this thread).
    pub fn sender(&self) -> McapSender {
        McapSender(self.tx.clone())
    }

    /// Closes the queue and waits (blocking) for the file to be finished; what it holds.
    /// Call it from outside the async runtime, or through `spawn_blocking`.
    pub fn finish(self) -> Result<Summary, McapError> {
        // A sender left in a task that did not end must not keep the file open.
        let _ = self.tx.blocking_send(McapItem::Close);
        drop(self.tx);
        self.handle.join().map_err(|_| McapError::ThreadGone)?
    }
}

/// A handle on the MCAP writer's queue; cheap to clone.
#[derive(Clone, Debug)]
pub struct McapSender(mpsc::Sender<McapItem>);

impl McapSender {
    /// Hands `item` to the writer, waiting for room in the queue.
    pub async fn send(&self, item: McapItem) -> Result<(), McapError> {
        self.0.send(item).await.map_err(|_| McapError::ThreadGone)
    }

    /// Hands `item` to the writer if there is room; false if not (or the writer is gone).
    pub fn try_send(&self, item: McapItem) -> bool {
        self.0.try_send(item).is_ok()
    }

    /// The file is finished (or its writer gone): nothing sent is written any more.
    pub fn is_closed(&self) -> bool {
        self.0.is_closed()
    }
}

/// The thread: writes every item until the queue closes, then finishes the file. A failed
/// write is logged and ends the file (the senders see the writer gone).
fn write_all<W: Write>(
    mut mcap: McapOut<W>,
    mut rx: mpsc::Receiver<McapItem>,
) -> Result<Summary, McapError> {
    while let Some(item) = rx.blocking_recv() {
        if matches!(item, McapItem::Close) {
            break;
        }
        if let Err(e) = write_item(&mut mcap, item) {
            tracing::error!(error = %e, "the MCAP file has stopped: nothing more is written to it");
            return Err(e);
        }
    }
    Ok(mcap.finish()?.0)
}

/// Writes one item.
fn write_item<W: Write>(mcap: &mut McapOut<W>, item: McapItem) -> Result<(), McapError> {
    match item {
        McapItem::Reads { received_us, reads } => {
            for r in &reads {
                mcap.read(received_us.saturating_mul(1000), r)?;
            }
        }
        McapItem::Frame {
            reader,
            conn,
            dir,
            received_us,
            frame,
        } => mcap.frame(
            &reader,
            conn,
            dir,
            true,
            received_us.saturating_mul(1000),
            &frame,
        )?,
        McapItem::Entries { reader, entries } => {
            for e in &entries {
                mcap.entry(&reader, e)?;
            }
        }
        McapItem::Truth(t) => mcap.truth(&t)?,
        McapItem::Poses(p) => mcap.received_poses(&p)?,
        McapItem::Estimate(e) => mcap.estimate(&e)?,
        McapItem::SceneWorld(w) => mcap.scene_world(&w),
        McapItem::Scene(utc_us) => mcap.scene_at(utc_us)?,
        McapItem::Close => {}
    }
    Ok(())
}
