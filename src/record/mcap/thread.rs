//! [`McapThread`]: an [`McapOut`] on a thread of its own. Running commands hand it what
//! they see through a bounded queue (an `await` when it is full, which holds no thread);
//! every write of the file happens on that thread, never on an async worker.

use std::io::Write;
use std::thread::JoinHandle;

use bytes::Bytes;
use tokio::sync::mpsc;

use super::{McapError, McapOut, Summary};
use crate::reads::Read;
use crate::record::Direction;

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
        let mcap = McapOut::new(out)?;
        let (tx, rx) = mpsc::channel(QUEUE);
        let handle = std::thread::Builder::new()
            .name("mcap-writer".into())
            .spawn(move || write_all(mcap, rx))
            .map_err(|e| McapError::Mcap { error: e.into() })?;
        Ok(McapThread { tx, handle })
    }

    /// Hands `item` to the writer, waiting for room in the queue.
    pub async fn send(&self, item: McapItem) -> Result<(), McapError> {
        self.tx.send(item).await.map_err(|_| McapError::ThreadGone)
    }

    /// Closes the queue and waits (blocking) for the file to be finished; what it holds.
    /// Call it from outside the async runtime, or through `spawn_blocking`.
    pub fn finish(self) -> Result<Summary, McapError> {
        drop(self.tx);
        self.handle.join().map_err(|_| McapError::ThreadGone)?
    }
}

/// The thread: writes every item until the queue closes, then finishes the file.
fn write_all<W: Write>(
    mut mcap: McapOut<W>,
    mut rx: mpsc::Receiver<McapItem>,
) -> Result<Summary, McapError> {
    while let Some(item) = rx.blocking_recv() {
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
        }
    }
    Ok(mcap.finish()?.0)
}
