//! [`McapOut`]: an MCAP file of ROS 2 messages being written: its schemas and channels, added
//! as they are first needed, and the LLRP sessions' frames turned into frames, tag reads and
//! reader events.

use std::collections::{BTreeMap, HashMap};
use std::io::Write;

use ::mcap::records::MessageHeader;
use ::mcap::write::NoSeek;
use llrp::message::{MessageBody, MessageDef as _, ReaderEventNotification};
use llrp::params::Timestamp;

use super::cdr::Cdr;
use super::msgs::{self, EventMsg, FrameMsg, MsgType};
use super::tap::{McapTap, TapMessage};
use super::{topic_token, McapError, Summary};
use crate::reads::{Read, ReadDecoder};
use crate::record::{Direction, Entry, Event};

/// The QoS profile each channel offers (the `offered_qos_profiles` the ROS 2 profile of MCAP
/// requires): reliable, volatile, keep last 100, no deadline, lifespan or lease (0 = the
/// default); rosbag2's YAML with the rmw enum values as numbers, which every ROS 2 release
/// since Humble reads.
const QOS: &str = "- history: 1\n  depth: 100\n  reliability: 1\n  durability: 2\n  \
deadline:\n    sec: 0\n    nsec: 0\n  lifespan:\n    sec: 0\n    nsec: 0\n  liveliness: 1\n  \
liveliness_lease_duration:\n    sec: 0\n    nsec: 0\n  avoid_ros_namespace_conventions: false\n";

/// One channel: its id and the sequence number of its next message.
#[derive(Clone, Copy, Debug)]
struct Channel {
    id: u16,
    sequence: u32,
}

/// An MCAP file being written (profile `ros2`, zstd chunks), to any writer: seeking is not
/// needed, so a pipe or the commands' all-or-nothing output works.
pub struct McapOut<W: Write> {
    writer: ::mcap::Writer<NoSeek<W>>,
    schemas: HashMap<MsgType, u16>,
    channels: HashMap<String, Channel>,
    /// The topic token of each reader name, and the names of each token taken.
    tokens: HashMap<String, String>,
    /// One read decoder per reader and connection (each learns its connection's hop table).
    decoders: HashMap<(String, u32), ReadDecoder>,
    pub(super) cdr: Cdr,
    /// What the `/scene` topic shows.
    pub(super) scene: super::scene::Scene,
    reads: Vec<Read>,
    /// Each tag stream's phase unwrapped so far.
    phases: super::phase::Unwrapper,
    summary: Summary,
    /// Where every message is also handed (the live view), if anywhere.
    tap: Option<Box<dyn McapTap>>,
}

impl<W: Write> McapOut<W> {
    /// Starts the file on `out`.
    pub fn new(out: W) -> Result<McapOut<W>, McapError> {
        let writer = ::mcap::WriteOptions::new()
            .profile("ros2")
            .library(format!("llrp-gateway {}", env!("CARGO_PKG_VERSION")))
            .compression(Some(::mcap::Compression::Zstd))
            .disable_seeking(true)
            .create(NoSeek::new(out))?;
        Ok(McapOut::with_writer(writer))
    }

    /// Around an MCAP writer already started.
    pub(super) fn with_writer(writer: ::mcap::Writer<NoSeek<W>>) -> McapOut<W> {
        McapOut {
            writer,
            schemas: HashMap::new(),
            channels: HashMap::new(),
            tokens: HashMap::new(),
            decoders: HashMap::new(),
            cdr: Cdr::new(),
            scene: Default::default(),
            reads: Vec::new(),
            phases: Default::default(),
            summary: Summary::default(),
            tap: None,
        }
    }

    /// Hands every message written from now on to `tap` as well.
    pub fn with_tap(mut self, tap: Box<dyn McapTap>) -> McapOut<W> {
        self.tap = Some(tap);
        self
    }

    /// The topic token of `reader` (unique in this file: a second name that cleans to the same
    /// token gets `_2`, `_3`, ...).
    pub(super) fn token(&mut self, reader: &str) -> String {
        if let Some(t) = self.tokens.get(reader) {
            return t.clone();
        }
        let base = topic_token(reader);
        let mut token = base.clone();
        let mut n = 1;
        while self.tokens.values().any(|t| *t == token) {
            n += 1;
            token = format!("{base}_{n}");
        }
        self.tokens.insert(reader.to_string(), token.clone());
        token
    }

    /// Writes one message on `topic` (added with `ty`'s schema when new).
    pub(super) fn write(
        &mut self,
        topic: &str,
        ty: MsgType,
        log_ns: u64,
        publish_ns: u64,
        data: &[u8],
    ) -> Result<(), McapError> {
        if let Some(tap) = &mut self.tap {
            tap.message(&TapMessage {
                topic,
                ty,
                log_ns,
                publish_ns,
                data,
            });
        }
        let channel = match self.channels.get_mut(topic) {
            Some(c) => c,
            None => {
                let schema = match self.schemas.get(&ty) {
                    Some(id) => *id,
                    None => {
                        let id =
                            self.writer
                                .add_schema(ty.name(), "ros2msg", ty.schema().as_bytes())?;
                        self.schemas.insert(ty, id);
                        id
                    }
                };
                let meta = BTreeMap::from([("offered_qos_profiles".into(), QOS.into())]);
                let id = self.writer.add_channel(schema, topic, "cdr", &meta)?;
                self.channels
                    .entry(topic.to_string())
                    .or_insert(Channel { id, sequence: 0 })
            }
        };
        let header = MessageHeader {
            channel_id: channel.id,
            sequence: channel.sequence,
            log_time: log_ns,
            publish_time: publish_ns,
        };
        channel.sequence = channel.sequence.wrapping_add(1);
        self.writer.write_to_known_channel(&header, data)?;
        self.summary.messages += 1;
        Ok(())
    }

    /// One frame (or, `whole_frame` false, bytes that are not frames) of `reader`'s
    /// connection `conn`, received at `received_ns` (UTC ns), on its connection and direction's
    /// channel; a frame from the reader also gives its tag reads and its event notification.
    pub fn frame(
        &mut self,
        reader: &str,
        conn: u32,
        dir: Direction,
        whole_frame: bool,
        received_ns: u64,
        data: &[u8],
    ) -> Result<(), McapError> {
        let token = self.token(reader);
        let side = match dir {
            Direction::ToReader => "to_reader",
            Direction::FromReader => "from_reader",
        };
        let topic = format!("/llrp/{token}/conn_{conn}/{side}");
        let m = FrameMsg {
            received_ns,
            reader,
            frame_id: &token,
            conn,
            dir,
            whole_frame,
            data,
        };
        let bytes = msgs::llrp_frame(&mut self.cdr, &m);
        self.write(&topic, MsgType::LlrpFrame, received_ns, received_ns, &bytes)?;
        self.summary.frames += 1;
        if dir == Direction::FromReader && whole_frame {
            self.reader_frame(reader, conn, received_ns, data)?;
        }
        Ok(())
    }

    /// The reads and the event notification of a frame from the reader.
    fn reader_frame(
        &mut self,
        reader: &str,
        conn: u32,
        received_ns: u64,
        data: &[u8],
    ) -> Result<(), McapError> {
        let decoder = self
            .decoders
            .entry((reader.to_string(), conn))
            .or_insert_with(|| ReadDecoder::new(crate::reads::ReaderName::parse(reader).ok()));
        let mut reads = std::mem::take(&mut self.reads);
        if decoder.frame(data, received_ns / 1000, &mut reads).is_err() {
            self.summary.undecodable_reports += 1;
        }
        for r in reads.drain(..) {
            self.read(received_ns, &r)?;
        }
        self.reads = reads;
        if llrp::FrameHeader::peek(data).map(|h| h.msg_type) == Some(ReaderEventNotification::TYPE)
        {
            if let Ok(m) = llrp::Message::decode(data) {
                if let MessageBody::ReaderEventNotification(n) = &m.body {
                    let d = &n.reader_event_notification_data;
                    let stamp_ns = match &d.timestamp {
                        Timestamp::Utc(t) => t.microseconds.saturating_mul(1000),
                        Timestamp::Uptime(_) => received_ns,
                    };
                    let detail = serde_json::to_string(d).unwrap_or_default();
                    self.event(reader, conn, "notification", &detail, received_ns, stamp_ns)?;
                }
            }
        }
        Ok(())
    }

    /// One tag read, received at `received_ns` (the MCAP log time; its publish time and
    /// header stamp are the reader's first-seen time), on its reader's reads channel; with a
    /// phase, its phase unwrapped along its stream on its reader's `phase_unwrapped` channel.
    pub fn read(&mut self, received_ns: u64, r: &Read) -> Result<(), McapError> {
        let token = self.token(r.reader.as_deref().unwrap_or(""));
        let frame_id = format!("{token}/antenna_{}", r.antenna);
        let bytes = msgs::tag_read(&mut self.cdr, r, &frame_id);
        let publish_ns = r.t_us.saturating_mul(1000);
        self.write(
            &format!("/llrp/{token}/reads"),
            MsgType::TagRead,
            received_ns,
            publish_ns,
            &bytes,
        )?;
        if let Some(unwrapped) = self.phases.unwrap(&token, r) {
            let bytes = msgs::tag_phase(&mut self.cdr, r, &frame_id, unwrapped);
            self.write(
                &format!("/llrp/{token}/phase_unwrapped"),
                MsgType::TagPhase,
                received_ns,
                publish_ns,
                &bytes,
            )?;
        }
        self.summary.reads += 1;
        Ok(())
    }

    /// A reader event seen at `received_ns` and stamped `stamp_ns` (the reader's time, else
    /// `received_ns`): on its reader's events channel and, as a Foxglove log line, on `/log`.
    pub fn event(
        &mut self,
        reader: &str,
        conn: u32,
        kind: &str,
        detail: &str,
        received_ns: u64,
        stamp_ns: u64,
    ) -> Result<(), McapError> {
        let token = self.token(reader);
        let e = EventMsg {
            stamp_ns,
            reader,
            frame_id: &token,
            conn,
            kind,
            detail,
        };
        let bytes = msgs::reader_event(&mut self.cdr, &e);
        let topic = format!("/llrp/{token}/events");
        self.write(&topic, MsgType::ReaderEvent, received_ns, stamp_ns, &bytes)?;
        let bytes = msgs::log(&mut self.cdr, &e);
        self.write("/log", MsgType::Log, received_ns, stamp_ns, &bytes)?;
        self.summary.events += 1;
        Ok(())
    }

    /// One entry of a recording of `reader`'s sessions, at its recorded UTC time: a frame or
    /// non-frame byte run on its channel (with the reads and notification of a reader's
    /// frame), a connect or disconnect marker as a reader event.
    pub fn entry(&mut self, reader: &str, entry: &Entry) -> Result<(), McapError> {
        let ns = entry.at().utc_us.saturating_mul(1000);
        match entry {
            Entry::Frame {
                conn, dir, frame, ..
            } => self.frame(reader, *conn, *dir, true, ns, frame),
            Entry::Bytes {
                conn, dir, bytes, ..
            } => self.frame(reader, *conn, *dir, false, ns, bytes),
            Entry::Marker {
                conn,
                event,
                reason,
                ..
            } => {
                let kind = match event {
                    Event::Connect => "connect",
                    Event::Disconnect => "disconnect",
                };
                self.event(reader, *conn, kind, reason, ns, ns)
            }
            // What was learnt of the reader is in its frames (capabilities, configuration).
            Entry::Reader { .. } => Ok(()),
        }
    }

    /// Writes the summary section and the footer; what was written, and the writer.
    pub fn finish(mut self) -> Result<(Summary, W), McapError> {
        self.writer.finish()?;
        self.summary.channels = self.channels.len();
        Ok((self.summary, self.writer.into_inner().into_inner()))
    }
}
