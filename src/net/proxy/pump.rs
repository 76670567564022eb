//! One direction of a proxy session: the pump that copies a stream chunk by chunk, and the
//! tee that splits a copy of it into frames for the recording and the tap.

use std::io;
use std::time::Duration;

use bytes::{Bytes, BytesMut};
use llrp::enums::KeepaliveTriggerType;
use llrp::message::{CloseConnection, Keepalive, MessageBody, MessageDef, ReaderEventNotification};
use llrp::{FrameError, FrameHeader, FrameSplitter, Inbound, Message, Split};
use std::sync::atomic::Ordering;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::sync::watch;

use super::keepalive::LinkNote;
use super::{Session, Tapped, CHUNK};
use crate::reads::{Read, ReadDecoder};
use crate::record::{Direction, Entry, ReaderInfo, Recorder};
use crate::utc::now_us as utc_now_us;

/// How a forwarding direction ended.
pub(super) enum End {
    /// Its source closed the stream.
    Eof,
    /// Reading its source failed.
    ReadError(io::Error),
    /// Writing to its destination failed.
    WriteError(io::Error),
    /// The stop signal came.
    Stopped,
}

/// How a forwarding direction ended, and its parts back.
pub(super) type PumpDone<'a, R, W> = (End, R, W, Tee<'a>);

/// Writes all of `bytes` and flushes (so that TLS sends its records now; nothing for TCP).
pub(super) async fn write_flushed<W: AsyncWrite + Unpin>(
    wr: &mut W,
    bytes: &[u8],
) -> io::Result<()> {
    wr.write_all(bytes).await?;
    wr.flush().await
}

/// Copies `rd` to `wr` chunk by chunk, showing each chunk to `tee` after it is written (and
/// flushed); with `stop`, also ends once it turns true: between chunks, or in the middle of
/// a write that does not complete (the tee then knows the stream was cut).
pub(super) async fn pump<'a, R, W>(
    mut rd: R,
    mut wr: W,
    mut tee: Tee<'a>,
    mut stop: Option<watch::Receiver<bool>>,
) -> PumpDone<'a, R, W>
where
    R: AsyncRead + Unpin,
    W: AsyncWrite + Unpin,
{
    let mut buf = vec![0u8; CHUNK];
    loop {
        let read = match &mut stop {
            Some(stop) => tokio::select! {
                // Reading is cancel-safe: nothing is lost when the stop wins.
                r = rd.read(&mut buf) => r,
                _ = wait_true(stop) => {
                    tee.finish().await;
                    return (End::Stopped, rd, wr, tee);
                }
            },
            None => rd.read(&mut buf).await,
        };
        let n = match read {
            Ok(0) => {
                tee.finish().await;
                return (End::Eof, rd, wr, tee);
            }
            Ok(n) => n,
            Err(e) => {
                tee.finish().await;
                return (End::ReadError(e), rd, wr, tee);
            }
        };
        let written = match &mut stop {
            Some(stop) => tokio::select! {
                w = write_flushed(&mut wr, &buf[..n]) => w,
                _ = wait_true(stop) => {
                    // Part of the chunk may have gone out (how much is unknown, so it is not
                    // recorded): the stream is cut.
                    tee.cut = true;
                    tee.finish().await;
                    return (End::Stopped, rd, wr, tee);
                }
            },
            None => write_flushed(&mut wr, &buf[..n]).await,
        };
        if let Err(e) = written {
            tee.cut = true;
            return (End::WriteError(e), rd, wr, tee);
        }
        tee.saw(&buf[..n]).await;
    }
}

async fn wait_true(rx: &mut watch::Receiver<bool>) {
    while !*rx.borrow() {
        if rx.changed().await.is_err() {
            // The sender is gone: nobody can ask for a shutdown any more.
            std::future::pending::<()>().await;
        }
    }
}

/// One direction's copy of the stream, split into frames for the recording and the tap.
pub(super) struct Tee<'a> {
    session: &'a Session,
    dir: Direction,
    /// Bytes of a frame not yet complete.
    buf: BytesMut,
    splitter: FrameSplitter,
    /// The stream stopped being LLRP: the rest is recorded as bytes.
    unsynced: bool,
    reads: ReadDecoder,
    scratch: Vec<Read>,
    reader: ReaderInfo,
    /// The client sent CLOSE_CONNECTION.
    pub(super) saw_close: bool,
    /// The reader sent CLOSE_CONNECTION_RESPONSE.
    pub(super) saw_close_response: bool,
    /// A frame of this direction could not be decoded (and was logged).
    saw_undecodable: bool,
    /// A write of this direction was abandoned part-way: where the stream stands is unknown.
    cut: bool,
    /// Recording entries of the chunk being looked at.
    pending: Vec<Entry>,
}

impl<'a> Tee<'a> {
    pub(super) fn new(session: &'a Session, dir: Direction) -> Self {
        Tee {
            session,
            dir,
            buf: BytesMut::new(),
            splitter: FrameSplitter::default(),
            unsynced: false,
            reads: ReadDecoder::new(Some(session.config.name.clone()))
                .with_fallback_table(session.config.region.clone()),
            scratch: Vec::new(),
            reader: ReaderInfo::default(),
            saw_close: false,
            saw_close_response: false,
            saw_undecodable: false,
            cut: false,
            pending: Vec::new(),
        }
    }

    async fn saw(&mut self, chunk: &[u8]) {
        let recorder = self.session.recorder.as_ref();
        if recorder.is_none() && self.session.tap.is_none() && self.dir == Direction::FromReader {
            // Nothing to record or tap; only the close handshake is tracked.
            self.track_close_only(chunk);
            return;
        }
        let at = recorder.map(Recorder::now).unwrap_or_default();
        if self.unsynced {
            self.record(Entry::Bytes {
                at,
                conn: self.session.conn,
                dir: self.dir,
                bytes: Bytes::copy_from_slice(chunk),
            });
            self.send_records().await;
            return;
        }
        self.buf.extend_from_slice(chunk);
        while let Some(inbound) = self.next_frame() {
            match inbound {
                Inbound::Frame(frame) => {
                    let undecodable = self.look(&frame);
                    self.record(Entry::Frame {
                        at,
                        conn: self.session.conn,
                        dir: self.dir,
                        frame,
                        undecodable,
                    });
                }
                Inbound::Unsynced(e) => {
                    tracing::warn!(
                        proxy = %self.session.config.name,
                        client = %self.session.peer,
                        "{} stream is not LLRP any more ({e}); forwarding it unchanged",
                        match self.dir { Direction::ToReader => "the client's", Direction::FromReader => "the reader's" }
                    );
                    self.unsynced = true;
                    let rest = std::mem::take(&mut self.buf).freeze();
                    self.record(Entry::Bytes {
                        at,
                        conn: self.session.conn,
                        dir: self.dir,
                        bytes: rest,
                    });
                    break;
                }
            }
        }
        self.send_records().await;
    }

    /// Whether everything seen so far was whole frames (so a frame may follow).
    pub(super) fn at_frame_boundary(&self) -> bool {
        !self.cut && !self.unsynced && self.buf.is_empty()
    }

    /// At the end of the stream: bytes left over that never made a whole frame are recorded
    /// as bytes.
    async fn finish(&mut self) {
        if !self.buf.is_empty() {
            // The stream ended inside a frame.
            self.cut = true;
        }
        if self.buf.is_empty() || self.session.recorder.is_none() {
            return;
        }
        let at = self
            .session
            .recorder
            .as_ref()
            .map(Recorder::now)
            .unwrap_or_default();
        let rest = std::mem::take(&mut self.buf).freeze();
        self.record(Entry::Bytes {
            at,
            conn: self.session.conn,
            dir: self.dir,
            bytes: rest,
        });
        self.send_records().await;
    }

    /// Keeps just enough framing to see the CLOSE_CONNECTION handshake.
    fn track_close_only(&mut self, chunk: &[u8]) {
        if self.unsynced {
            return;
        }
        self.buf.extend_from_slice(chunk);
        while let Some(inbound) = self.next_frame() {
            match inbound {
                Inbound::Frame(frame) => {
                    self.look(&frame);
                }
                Inbound::Unsynced(_) => {
                    self.unsynced = true;
                    self.buf.clear();
                    break;
                }
            }
        }
    }

    /// The next whole frame in the buffer (of any header version, as the codec's
    /// [`llrp::Deframer`] yields them), or the framing error, leaving the bytes that are not
    /// a frame in the buffer for the recording.
    fn next_frame(&mut self) -> Option<Inbound> {
        let len = match self.splitter.split(&self.buf) {
            Ok(Split::Frame(h)) | Err(FrameError::UnsupportedVersion(h)) => h.length as usize,
            Ok(Split::Incomplete(_)) => return None,
            Err(e) => return Some(Inbound::Unsynced(e)),
        };
        if self.buf.len() < len {
            return None;
        }
        self.session
            .stats
            .frames(self.dir)
            .fetch_add(1, Ordering::Relaxed);
        Some(Inbound::Frame(self.buf.split_to(len).freeze()))
    }

    /// Notes what matters in a frame: the close handshake, tag reads and events for the tap,
    /// the reader's identity for the recording. Where a recording or the tap takes a copy,
    /// the frame is decoded once, and why it could not be is returned (and counted).
    fn look(&mut self, frame: &Bytes) -> Option<String> {
        let h = FrameHeader::peek(frame)?;
        let copies = self.session.recorder.is_some() || self.session.tap.is_some();
        let mut undecodable = None;
        let message = if copies {
            match Message::decode(frame) {
                Ok(m) => Some(m),
                Err(e) => {
                    undecodable = Some(e.to_string());
                    self.undecodable(frame, &h, &e);
                    None
                }
            }
        } else {
            None
        };
        match self.dir {
            Direction::ToReader => {
                if h.msg_type == CloseConnection::TYPE {
                    self.saw_close = true;
                }
                if let (Some(m), Some(_)) = (&message, &self.session.tap) {
                    if let MessageBody::SetReaderConfig(c) = &m.body {
                        if let Some(k) = &c.keepalive_spec {
                            let period =
                                (k.keepalive_trigger_type == KeepaliveTriggerType::Periodic).then(
                                    || Duration::from_millis(u64::from(k.periodic_trigger_value)),
                                );
                            self.session.link(LinkNote::Spec(period));
                        }
                    }
                }
            }
            Direction::FromReader => {
                if h.msg_type == llrp::message::CloseConnectionResponse::TYPE {
                    self.saw_close_response = true;
                }
                if h.msg_type == Keepalive::TYPE {
                    self.session.link(LinkNote::Keepalive);
                }
                if let Some(tap) = &self.session.tap {
                    let now = utc_now_us();
                    self.scratch.clear();
                    if self.reads.frame(frame, now, &mut self.scratch).is_ok()
                        && !self.scratch.is_empty()
                    {
                        tap.offer(Tapped::Reads(std::mem::take(&mut self.scratch)));
                    }
                    if let Some(m) = message.filter(|_| h.msg_type == ReaderEventNotification::TYPE)
                    {
                        tap.offer(Tapped::Event {
                            reader: self.session.config.name.clone(),
                            conn: self.session.conn,
                            message: Box::new(m),
                        });
                    }
                }
            }
        }
        undecodable
    }

    /// Counts a frame the codec refused; the first of each direction and session is logged.
    fn undecodable(&mut self, frame: &[u8], h: &FrameHeader, e: &llrp::DecodeError) {
        let n = self
            .session
            .stats
            .undecodable(self.dir)
            .fetch_add(1, Ordering::Relaxed);
        let first = !self.saw_undecodable;
        self.saw_undecodable = true;
        let from = match self.dir {
            Direction::ToReader => "the client",
            Direction::FromReader => "the reader",
        };
        if first {
            tracing::warn!(
                proxy = %self.session.config.name,
                client = %self.session.peer,
                "a {} (id {}) from {from} cannot be decoded ({e}); forwarded unchanged, recorded as undecodable ({} such frames so far)",
                llrp::message::message_name(h.msg_type, frame),
                h.id,
                n + 1
            );
        } else {
            tracing::debug!(proxy = %self.session.config.name, "undecodable frame from {from}: {e}");
        }
    }

    /// Queues an entry for the recording (sent, with the rest of the chunk's, by
    /// [`Tee::send_records`]); adds a reader line when the frame tells something new of the
    /// reader.
    fn record(&mut self, entry: Entry) {
        if self.session.recorder.is_none() {
            return;
        }
        let info = match &entry {
            Entry::Frame { frame, .. } if self.dir == Direction::FromReader => {
                reader_info(frame, &self.reader)
            }
            _ => None,
        };
        let at = entry.at();
        self.pending.push(entry);
        if let Some(info) = info {
            self.reader = info.clone();
            self.pending.push(Entry::Reader {
                at,
                conn: self.session.conn,
                reader: info,
            });
        }
    }

    /// Hands the queued entries to the recorder in one batch (waiting while it is behind).
    async fn send_records(&mut self) {
        if let (Some(r), false) = (&self.session.recorder, self.pending.is_empty()) {
            let batch = std::mem::take(&mut self.pending);
            if r.entries(batch).await.is_err() {
                tracing::error!(proxy = %self.session.config.name, "the recording has stopped");
            }
        }
    }
}

/// What `frame` adds to `known` of the reader's identity (capabilities or Identification),
/// if anything.
fn reader_info(frame: &[u8], known: &ReaderInfo) -> Option<ReaderInfo> {
    use llrp::message::{GetReaderCapabilitiesResponse, GetReaderConfigResponse};
    let h = FrameHeader::peek(frame)?;
    if h.msg_type != GetReaderCapabilitiesResponse::TYPE
        && h.msg_type != GetReaderConfigResponse::TYPE
    {
        return None;
    }
    let mut info = known.clone();
    match Message::decode(frame).ok()?.body {
        MessageBody::GetReaderCapabilitiesResponse(r) => {
            let g = r.general_device_capabilities?;
            info.manufacturer = Some(g.device_manufacturer_name);
            info.model = Some(g.model_name);
            info.firmware = Some(g.reader_firmware_version);
        }
        MessageBody::GetReaderConfigResponse(r) => {
            let id = r.identification?;
            info.id_type = Some(
                match id.id_type {
                    llrp::enums::IdentificationType::MacAddress => "mac",
                    llrp::enums::IdentificationType::Epc => "epc",
                    llrp::enums::IdentificationType::Unknown(_) => "unknown",
                }
                .into(),
            );
            info.reader_id = Some(crate::reads::hex_upper(&id.reader_id));
        }
        _ => return None,
    }
    (info != *known).then_some(info)
}
