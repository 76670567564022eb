//! Writing a recording while sessions run: connections hand entries to a [`Recorder`] (a
//! queue bounded in bytes, so a disk that cannot keep up slows the sessions instead of losing
//! lines), and one thread of its own per recording formats them and appends them to the
//! recording's [`Files`] (or any other [`Sink`]), flushing at most [`FLUSH_MS`] after a line
//! was queued and at every marker, rotating to a numbered next file past `max_bytes`.
//!
//! The file work (`std::fs`: writes, `fsync`, opening the next part) never runs on an async
//! worker: `sim` serves every socket from one, and a disk that stalls (a hung network mount, a
//! dying card) would stall them all. On its own thread it stalls only the recording; the
//! sessions go on until [`QUEUE_BYTES`] of entries wait, and then wait for room (an `await`,
//! which holds no thread) rather than lose a line.

use std::fs::{File, OpenOptions};
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, Sender};
use std::sync::Arc;
use std::time::{Duration, Instant};

use bytes::Bytes;
use tokio::sync::{oneshot, OwnedSemaphorePermit, Semaphore};

use super::format::{encode_entry, encode_header, Direction, Entry, Event, Header, Stamp};

/// Longest a queued line waits before it is written to the file.
pub const FLUSH_MS: u64 = 10;

/// Bytes of entries (their frames, plus a fixed cost for each entry) that may wait for the
/// writer before senders wait: the recorder's memory, however far behind the disk is.
pub const QUEUE_BYTES: usize = 16 << 20;
/// What an entry costs in the queue besides its frame's bytes.
const ENTRY_COST: usize = 96;

/// Buffered bytes that are written at once, whatever the time.
const FLUSH_BYTES: usize = 256 * 1024;

/// Options of a recording.
#[derive(Clone, Debug, Default)]
pub struct RecordOptions {
    /// Rotate to the next numbered file once a file would grow past this many bytes.
    pub max_bytes: Option<u64>,
    /// Hand every entry to this MCAP file too (on the recorder's thread; docs/robotics.md).
    pub mcap: Option<super::mcap::McapTee>,
}

use crate::utc::now_us as utc_now_us;

/// Where a recording's bytes go: its [`Files`], or in tests any writer (one that stalls, to
/// show that the sessions do not).
pub trait Sink: Send + 'static {
    /// One file of the recording.
    type Part: Write + Send;
    /// Opens part `part`: 0 when the recording starts (on the caller's thread, so that a file
    /// that exists is refused at once), 1, 2, … at each rotation (on the writer's thread).
    fn open(&mut self, part: u32) -> io::Result<Self::Part>;
    /// Makes what was written to `file` durable: at each rotation and at the end.
    fn sync(&mut self, file: &mut Self::Part) -> io::Result<()>;
    /// Part `part`'s name, for the log.
    fn name(&self, part: u32) -> String;
}

/// The files of a recording at a path: the path itself, then `NAME.1.EXT`, `NAME.2.EXT`, …
/// ([`part_path`]); none may exist before (an earlier recording is never overwritten).
#[derive(Clone, Debug)]
pub struct Files {
    path: PathBuf,
}

impl Files {
    /// The files of a recording at `path`.
    pub fn new(path: &Path) -> Files {
        Files {
            path: path.to_owned(),
        }
    }
}

impl Sink for Files {
    type Part = File;

    fn open(&mut self, part: u32) -> io::Result<File> {
        let first_part = part_path(&self.path, 1);
        if part == 0 && first_part.exists() {
            return Err(io::Error::new(
                io::ErrorKind::AlreadyExists,
                format!(
                    "{} exists (part of an earlier recording): choose another name or remove it",
                    first_part.display()
                ),
            ));
        }
        create_new(&part_path(&self.path, part))
    }

    fn sync(&mut self, file: &mut File) -> io::Result<()> {
        file.sync_data()
    }

    fn name(&self, part: u32) -> String {
        part_path(&self.path, part).display().to_string()
    }
}

/// One message to the writer: entries in order, holding their share of the queue's room
/// until they are written.
type Batch = (Vec<Entry>, OwnedSemaphorePermit);

/// A handle to a running recording; cheap to clone, one per connection.
#[derive(Clone, Debug)]
pub struct Recorder {
    tx: Sender<Batch>,
    /// Bytes of queue left ([`QUEUE_BYTES`]); a batch holds its share until it is written.
    room: Arc<Semaphore>,
    start: Instant,
    start_utc_us: u64,
    next_conn: Arc<AtomicU32>,
}

/// Resolves when the writer has finished (after the last [`Recorder`] is dropped): await it
/// to know everything is on disk; its error is the writer's.
pub type RecorderTask = tokio::task::JoinHandle<io::Result<()>>;

impl Recorder {
    /// Creates `path` (which must not exist, nor its numbered parts: an earlier recording is
    /// never overwritten) and starts the writer, which writes `header` first (its
    /// `start_utc_us` is set to now). Needs a tokio runtime (for the [`RecorderTask`]).
    pub fn create(
        path: &Path,
        header: Header,
        options: RecordOptions,
    ) -> io::Result<(Recorder, RecorderTask)> {
        Recorder::start(Files::new(path), header, options)
    }

    /// As [`create`](Recorder::create), into `sink`: opens its first part here, then writes
    /// on a thread of its own.
    pub fn start<S: Sink>(
        mut sink: S,
        mut header: Header,
        options: RecordOptions,
    ) -> io::Result<(Recorder, RecorderTask)> {
        let start = Instant::now();
        let start_utc_us = utc_now_us();
        header.start_utc_us = start_utc_us;
        let first = sink.open(0)?;
        let files = FileSet {
            sink,
            header,
            max_bytes: options.max_bytes,
            file: first,
            written: 0,
            mcap: options.mcap,
        };
        // Unbounded as a channel, bounded in bytes by `room`.
        let (tx, rx) = std::sync::mpsc::channel::<Batch>();
        let (done, finished) = oneshot::channel();
        std::thread::Builder::new()
            .name("recorder".into())
            .spawn(move || {
                let _ = done.send(write_loop(files, &rx));
            })?;
        let task = tokio::spawn(async move {
            finished
                .await
                .unwrap_or_else(|_| Err(io::Error::other("the recording's writer thread panicked")))
        });
        Ok((
            Recorder {
                tx,
                room: Arc::new(Semaphore::new(QUEUE_BYTES)),
                start,
                start_utc_us,
                next_conn: Arc::new(AtomicU32::new(1)),
            },
            task,
        ))
    }

    /// A new connection number (1, 2, …).
    pub fn next_conn(&self) -> u32 {
        self.next_conn.fetch_add(1, Ordering::Relaxed)
    }

    /// The stamp of now.
    pub fn now(&self) -> Stamp {
        let t_us = self.start.elapsed().as_micros() as u64;
        Stamp {
            t_us,
            utc_us: self.start_utc_us + t_us,
        }
    }

    /// Records an entry; waits while the writer is behind. Fails only if the writer has
    /// stopped (its task's result says why).
    pub async fn entry(&self, entry: Entry) -> Result<(), RecorderGone> {
        self.entries(vec![entry]).await
    }

    /// Records several entries in order (one channel message for all).
    pub async fn entries(&self, entries: Vec<Entry>) -> Result<(), RecorderGone> {
        let cost: usize = entries
            .iter()
            .map(|e| {
                ENTRY_COST
                    + match e {
                        Entry::Frame { frame, .. } => frame.len(),
                        Entry::Bytes { bytes, .. } => bytes.len(),
                        _ => 0,
                    }
            })
            .sum();
        // A batch larger than the whole queue waits for all of it.
        let permits = u32::try_from(cost.min(QUEUE_BYTES)).unwrap_or(u32::MAX);
        let room = Arc::clone(&self.room)
            .acquire_many_owned(permits)
            .await
            .map_err(|_| RecorderGone)?;
        self.tx.send((entries, room)).map_err(|_| RecorderGone)
    }

    /// Records a frame.
    pub async fn frame(
        &self,
        at: Stamp,
        conn: u32,
        dir: Direction,
        frame: Bytes,
    ) -> Result<(), RecorderGone> {
        self.entry(Entry::Frame {
            at,
            conn,
            dir,
            frame,
            undecodable: None,
        })
        .await
    }

    /// Records a marker (written to the file at once).
    pub async fn marker(
        &self,
        conn: u32,
        event: Event,
        reason: impl Into<String>,
    ) -> Result<(), RecorderGone> {
        self.entry(Entry::Marker {
            at: self.now(),
            conn,
            event,
            reason: reason.into(),
        })
        .await
    }
}

/// The recording's writer has stopped (a write failed); nothing more is recorded.
#[derive(Clone, Copy, Debug, thiserror::Error)]
#[error("the recording's writer has stopped")]
pub struct RecorderGone;

/// The writer's thread: the header, then every batch in order, written at most [`FLUSH_MS`]
/// after a line was queued and at once at a marker or [`FLUSH_BYTES`]; at the end (every
/// [`Recorder`] dropped) what is left, made durable.
fn write_loop<S: Sink>(mut files: FileSet<S>, rx: &Receiver<Batch>) -> io::Result<()> {
    files.write_header()?;
    let mut buf = Vec::with_capacity(FLUSH_BYTES);
    let mut due: Option<Instant> = None;
    loop {
        let next = match due {
            Some(at) => rx.recv_timeout(at.saturating_duration_since(Instant::now())),
            None => rx.recv().map_err(|_| RecvTimeoutError::Disconnected),
        };
        let (batch, _room) = match next {
            Ok(b) => b,
            Err(RecvTimeoutError::Timeout) => {
                files.write(&mut buf)?;
                due = None;
                continue;
            }
            Err(RecvTimeoutError::Disconnected) => break,
        };
        let mut marker = false;
        for entry in &batch {
            marker |= matches!(entry, Entry::Marker { .. });
            let before = buf.len();
            encode_entry(entry, &mut buf);
            files.rotate_if_full(&mut buf, before)?;
        }
        files.tee(batch);
        if marker || buf.len() >= FLUSH_BYTES {
            files.write(&mut buf)?;
            due = None;
        } else if due.is_none() {
            due = Some(Instant::now() + Duration::from_millis(FLUSH_MS));
        }
    }
    files.write(&mut buf)?;
    files.sink.sync(&mut files.file)
}

/// The current file of a recording and how to open the next.
struct FileSet<S: Sink> {
    sink: S,
    header: Header,
    max_bytes: Option<u64>,
    file: S::Part,
    /// Bytes in the current file (written or buffered) at the last rotation check.
    written: u64,
    /// Where the entries go on to, until that writer is gone.
    mcap: Option<super::mcap::McapTee>,
}

impl<S: Sink> FileSet<S> {
    /// Hands `batch` on to the MCAP file, if any; once that writer is gone (it logged why),
    /// the recording goes on without it.
    fn tee(&mut self, batch: Vec<Entry>) {
        if let Some(tee) = &self.mcap {
            if !tee.send_blocking(batch) {
                tracing::warn!(reader = %tee.reader, "the MCAP file is gone: the recording goes on without it");
                self.mcap = None;
            }
        }
    }

    fn write_header(&mut self) -> io::Result<()> {
        let mut line = Vec::new();
        encode_header(&self.header, &mut line);
        self.file.write_all(&line)?;
        self.written = line.len() as u64;
        Ok(())
    }

    /// Writes and empties `buf` (on the writer's thread, which may block on a slow disk).
    fn write(&mut self, buf: &mut Vec<u8>) -> io::Result<()> {
        if !buf.is_empty() {
            self.file.write_all(buf)?;
            self.file.flush()?;
            self.written += buf.len() as u64;
            buf.clear();
        }
        Ok(())
    }

    /// If the line just appended to `buf` (from `line_start`) would take the file past
    /// `max_bytes`, writes what came before it, opens the next numbered file and keeps the
    /// line for that one.
    fn rotate_if_full(&mut self, buf: &mut Vec<u8>, line_start: usize) -> io::Result<()> {
        let Some(max) = self.max_bytes else {
            return Ok(());
        };
        let header_only = self.written <= header_len(&self.header) && line_start == 0;
        if header_only || self.written + buf.len() as u64 <= max {
            return Ok(());
        }
        let line = buf.split_off(line_start);
        self.write(buf)?;
        self.sink.sync(&mut self.file)?;
        self.header.part += 1;
        self.file = self.sink.open(self.header.part)?;
        tracing::info!(file = %self.sink.name(self.header.part), "recording continues in the next file");
        self.write_header()?;
        *buf = line;
        Ok(())
    }
}

/// Opens a new file for writing; an existing one is an error that names it.
fn create_new(path: &Path) -> io::Result<File> {
    OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(path)
        .map_err(|e| {
            if e.kind() == io::ErrorKind::AlreadyExists {
                io::Error::new(
                    e.kind(),
                    format!(
                        "{} exists: a recording is never overwritten; choose another name or remove it",
                        path.display()
                    ),
                )
            } else {
                e
            }
        })
}

fn header_len(header: &Header) -> u64 {
    let mut line = Vec::new();
    encode_header(header, &mut line);
    line.len() as u64
}

/// The file of part `part` of a recording at `path`: `rec.jsonl` → `rec.1.jsonl`, `rec.2.jsonl`.
pub fn part_path(path: &Path, part: u32) -> PathBuf {
    if part == 0 {
        return path.to_owned();
    }
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let name = match path.extension() {
        Some(ext) => format!("{stem}.{part}.{}", ext.to_string_lossy()),
        None => format!("{stem}.{part}"),
    };
    path.with_file_name(name)
}

#[cfg(test)]
mod tests {
    use super::super::format::Recording;
    use super::*;
    use llrp::message::KeepaliveAck;
    use llrp::Message;

    fn frame() -> Bytes {
        Message::new(1, KeepaliveAck::default()).to_bytes().freeze()
    }

    #[tokio::test]
    async fn lines_reach_the_file_within_the_flush_interval_without_closing() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("rec.jsonl");
        let (rec, task) = Recorder::create(&path, Header::new("up", 0), RecordOptions::default())
            .expect("create");
        let conn = rec.next_conn();
        rec.frame(rec.now(), conn, Direction::ToReader, frame())
            .await
            .expect("queued");
        // The recorder is still open: the line must be on disk once the flush interval has
        // passed (plus scheduling slack), not only at the end.
        let mut seen = 0;
        for _ in 0..200 {
            tokio::time::sleep(Duration::from_millis(FLUSH_MS)).await;
            let r = Recording::open(&path).expect("readable while open");
            seen = r.entries.len();
            if seen == 1 {
                break;
            }
        }
        assert_eq!(seen, 1);
        drop(rec);
        task.await.expect("joined").expect("written");
    }

    #[tokio::test]
    async fn an_existing_recording_is_never_overwritten() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("rec.jsonl");
        std::fs::write(&path, "earlier\n").expect("write");
        let e = Recorder::create(&path, Header::new("up", 0), RecordOptions::default())
            .expect_err("exists");
        assert!(e.to_string().contains("never overwritten"), "{e}");
        assert_eq!(std::fs::read_to_string(&path).expect("read"), "earlier\n");
        std::fs::remove_file(&path).expect("remove");
        std::fs::write(part_path(&path, 1), "earlier part\n").expect("write");
        let e = Recorder::create(&path, Header::new("up", 0), RecordOptions::default())
            .expect_err("a part exists");
        assert!(e.to_string().contains("rec.1.jsonl"), "{e}");
    }

    #[tokio::test]
    async fn a_marker_is_on_disk_when_its_send_returns_and_the_writer_ran() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("rec.jsonl");
        let (rec, task) = Recorder::create(&path, Header::new("up", 0), RecordOptions::default())
            .expect("create");
        rec.marker(1, Event::Connect, "client x")
            .await
            .expect("queued");
        drop(rec);
        task.await.expect("joined").expect("written");
        let r = Recording::open(&path).expect("reads");
        assert!(matches!(
            r.entries[..],
            [Entry::Marker {
                event: Event::Connect,
                ..
            }]
        ));
    }

    #[tokio::test]
    async fn past_max_bytes_the_recording_goes_on_in_numbered_files_each_with_a_header() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("rec.jsonl");
        let options = RecordOptions {
            max_bytes: Some(600),
            ..RecordOptions::default()
        };
        let (rec, task) = Recorder::create(&path, Header::new("up", 0), options).expect("create");
        for _ in 0..20 {
            rec.frame(rec.now(), 1, Direction::FromReader, frame())
                .await
                .expect("queued");
        }
        drop(rec);
        task.await.expect("joined").expect("written");
        let mut total = 0;
        let mut part = 0;
        while part_path(&path, part).exists() {
            let p = part_path(&path, part);
            let len = std::fs::metadata(&p).expect("stat").len();
            assert!(len <= 600, "{} is {len} bytes", p.display());
            let r = Recording::open(&p).expect("each part reads alone");
            assert_eq!(r.header.part, part);
            total += r.entries.len();
            part += 1;
        }
        assert!(part >= 3, "only {part} files");
        assert_eq!(total, 20, "no line lost or doubled across the rotation");
        assert_eq!(
            part_path(&path, 2).file_name().expect("name"),
            "rec.2.jsonl"
        );
    }

    /// A sink whose writes wait until `open` is set; what gets through is kept.
    #[derive(Clone, Default)]
    struct Held {
        open: Arc<(std::sync::Mutex<bool>, std::sync::Condvar)>,
        through: Arc<std::sync::Mutex<Vec<u8>>>,
    }

    impl Write for Held {
        fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
            let (lock, wake) = &*self.open;
            let mut open = lock.lock().expect("lock");
            while !*open {
                open = wake.wait(open).expect("lock");
            }
            self.through.lock().expect("lock").extend_from_slice(buf);
            Ok(buf.len())
        }

        fn flush(&mut self) -> io::Result<()> {
            Ok(())
        }
    }

    impl Sink for Held {
        type Part = Held;
        fn open(&mut self, _part: u32) -> io::Result<Held> {
            Ok(self.clone())
        }
        fn sync(&mut self, _file: &mut Held) -> io::Result<()> {
            Ok(())
        }
        fn name(&self, part: u32) -> String {
            format!("held {part}")
        }
    }

    #[tokio::test]
    async fn a_stalled_sink_holds_no_sender_and_gets_every_line_in_order_once_it_goes() {
        let sink = Held::default();
        let (rec, task) =
            Recorder::start(sink.clone(), Header::new("up", 0), RecordOptions::default())
                .expect("start");
        // On this runtime's only thread: each send returns although nothing can be written.
        for conn in 1..=50 {
            rec.marker(conn, Event::Connect, format!("client {conn}"))
                .await
                .expect("queued");
        }
        assert!(sink.through.lock().expect("lock").is_empty());
        {
            let (lock, wake) = &*sink.open;
            *lock.lock().expect("lock") = true;
            wake.notify_all();
        }
        drop(rec);
        task.await.expect("joined").expect("written");
        let bytes = sink.through.lock().expect("lock").clone();
        let r = Recording::read(&bytes[..]).expect("a recording");
        let conns: Vec<u32> = r.entries.iter().map(Entry::conn).collect();
        assert_eq!(conns, (1..=50).collect::<Vec<_>>());
    }
}
