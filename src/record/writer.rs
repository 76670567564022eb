//! Writing a recording while sessions run: connections hand entries to a [`Recorder`] (a
//! bounded channel, so a disk that cannot keep up slows the sessions instead of losing
//! lines), and one task formats and appends them, flushing at most [`FLUSH_MS`] after a line
//! was queued and at every marker, rotating to a numbered next file past `max_bytes`.

use std::fs::{File, OpenOptions};
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use bytes::Bytes;
use tokio::sync::{mpsc, OwnedSemaphorePermit, Semaphore};

use super::format::{encode_entry, encode_header, Direction, Entry, Event, Header, Stamp};

/// Longest a queued line waits before it is written to the file.
pub const FLUSH_MS: u64 = 10;

/// Bytes of entries (their frames, plus [`ENTRY_COST`] each) that may wait for the writer
/// before senders wait: the recorder's memory, however far behind the disk is.
const QUEUE_BYTES: usize = 16 << 20;
/// What an entry costs in the queue besides its frame's bytes.
const ENTRY_COST: usize = 96;

/// Buffered bytes that are written at once, whatever the time.
const FLUSH_BYTES: usize = 256 * 1024;

/// Options of a recording.
#[derive(Clone, Debug, Default)]
pub struct RecordOptions {
    /// Rotate to the next numbered file once a file would grow past this many bytes.
    pub max_bytes: Option<u64>,
}

use crate::utc::now_us as utc_now_us;

/// A handle to a running recording; cheap to clone, one per connection.
#[derive(Clone, Debug)]
pub struct Recorder {
    tx: mpsc::UnboundedSender<(Vec<Entry>, OwnedSemaphorePermit)>,
    /// Bytes of queue left ([`QUEUE_BYTES`]); a batch holds its share until it is written.
    room: Arc<Semaphore>,
    start: Instant,
    start_utc_us: u64,
    next_conn: Arc<AtomicU32>,
}

/// The task that writes the file; await it after the last [`Recorder`] is dropped to know
/// everything is on disk.
pub type RecorderTask = tokio::task::JoinHandle<io::Result<()>>;

impl Recorder {
    /// Creates `path` (which must not exist, nor its numbered parts: an earlier recording is
    /// never overwritten), writes `header` (its `start_utc_us` is set to now) and starts the
    /// writing task on the current runtime.
    pub fn create(
        path: &Path,
        mut header: Header,
        options: RecordOptions,
    ) -> io::Result<(Recorder, RecorderTask)> {
        let start = Instant::now();
        let start_utc_us = utc_now_us();
        header.start_utc_us = start_utc_us;
        let mut file = FileSet::create(path, header, options.max_bytes)?;
        // Unbounded as a channel, bounded in bytes by `room`.
        let (tx, mut rx) = mpsc::unbounded_channel::<(Vec<Entry>, OwnedSemaphorePermit)>();
        let task = tokio::spawn(async move {
            let mut buf = Vec::with_capacity(FLUSH_BYTES);
            let mut due: Option<tokio::time::Instant> = None;
            loop {
                let entry = match due {
                    Some(at) => tokio::select! {
                        e = rx.recv() => e,
                        _ = tokio::time::sleep_until(at) => {
                            file.write(&mut buf)?;
                            due = None;
                            continue;
                        }
                    },
                    None => rx.recv().await,
                };
                let Some((batch, _room)) = entry else { break };
                let mut marker = false;
                for entry in &batch {
                    marker |= matches!(entry, Entry::Marker { .. });
                    let before = buf.len();
                    encode_entry(entry, &mut buf);
                    file.rotate_if_full(&mut buf, before)?;
                }
                if marker || buf.len() >= FLUSH_BYTES {
                    file.write(&mut buf)?;
                    due = None;
                } else if due.is_none() {
                    due = Some(tokio::time::Instant::now() + Duration::from_millis(FLUSH_MS));
                }
            }
            file.write(&mut buf)?;
            file.file.sync_data()
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

/// The current file of a recording and how to open the next.
struct FileSet {
    path: PathBuf,
    header: Header,
    max_bytes: Option<u64>,
    file: File,
    /// Bytes in the current file (written or buffered) at the last rotation check.
    written: u64,
}

impl FileSet {
    fn create(path: &Path, header: Header, max_bytes: Option<u64>) -> io::Result<Self> {
        if part_path(path, 1).exists() {
            return Err(io::Error::new(
                io::ErrorKind::AlreadyExists,
                format!(
                    "{} exists (part of an earlier recording): choose another name or remove it",
                    part_path(path, 1).display()
                ),
            ));
        }
        let mut set = FileSet {
            path: path.to_owned(),
            file: create_new(path)?,
            header,
            max_bytes,
            written: 0,
        };
        set.write_header()?;
        Ok(set)
    }

    fn write_header(&mut self) -> io::Result<()> {
        let mut line = Vec::new();
        encode_header(&self.header, &mut line);
        self.file.write_all(&line)?;
        self.written = line.len() as u64;
        Ok(())
    }

    /// Writes and empties `buf`.
    ///
    /// A blocking write on the async worker: appends to the page cache take microseconds,
    /// and the lines are batched (at most every [`FLUSH_MS`] or [`FLUSH_BYTES`]).
    fn write(&mut self, buf: &mut Vec<u8>) -> io::Result<()> {
        if !buf.is_empty() {
            self.file.write_all(buf)?;
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
        self.file.sync_data()?;
        self.header.part += 1;
        let next = part_path(&self.path, self.header.part);
        self.file = create_new(&next)?;
        tracing::info!(file = %next.display(), "recording continues in the next file");
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
}
