//! The recording format, version [`VERSION`]: JSON Lines, a header line then one line per
//! frame, marker or reader identification. See `docs/recordings.md`.
//!
//! ```text
//! {"llrp_recording":1,"gateway":"llrp-gateway 0.1.0","upstream":"10.0.0.5:5084","start_utc_us":…}
//! {"t_us":0,"utc_us":…,"conn":1,"event":"connect","reason":"client 127.0.0.1:50312"}
//! {"t_us":812,"utc_us":…,"conn":1,"dir":"from_reader","frame":"BD8AAAAg…"}
//! {"t_us":1210,"utc_us":…,"conn":1,"reader":{"manufacturer":25882,"model":2001002,…}}
//! {"t_us":9000,"utc_us":…,"conn":1,"event":"disconnect","reason":"client closed"}
//! ```

use crate::reads::ReaderName;
use std::io::{self, BufRead};

use base64::engine::general_purpose::STANDARD as BASE64;
use base64::Engine as _;
use bytes::Bytes;
use llrp::message::MessageDef as _;
use serde::{Deserialize, Serialize};

/// The format version this build writes and reads.
pub const VERSION: u32 = 1;

/// The first line of a recording.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// Format version ([`VERSION`]).
    pub llrp_recording: u32,
    /// The program that wrote it, e.g. `llrp-gateway 0.1.0`.
    pub gateway: String,
    /// The reader the frames came from: `HOST:PORT` of the upstream, or `sim:NAME`.
    pub upstream: String,
    /// The scenario a simulated reader ran, if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scenario: Option<String>,
    /// Wall-clock time of `t_us` = 0, UTC µs since the Unix epoch.
    pub start_utc_us: u64,
    /// Which part of a rotated recording this file is (0 = the first).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub part: u32,
}

fn is_zero(n: &u32) -> bool {
    *n == 0
}

impl Header {
    /// A header of this version for `upstream`, starting at `start_utc_us`.
    pub fn new(upstream: impl Into<String>, start_utc_us: u64) -> Self {
        Header {
            llrp_recording: VERSION,
            gateway: format!("llrp-gateway {}", env!("CARGO_PKG_VERSION")),
            upstream: upstream.into(),
            scenario: None,
            start_utc_us,
            part: 0,
        }
    }

    /// The name of the reader the frames came from: `upstream` without its `sim:`.
    pub fn reader_name(&self) -> Result<ReaderName, RecordError> {
        let name = self.upstream.strip_prefix("sim:").unwrap_or(&self.upstream);
        ReaderName::parse(name).map_err(|e| RecordError::Header(format!("upstream: {e}")))
    }
}

/// Which way a frame went.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Direction {
    /// From the client to the reader.
    ToReader,
    /// From the reader to the client.
    FromReader,
}

/// What a marker line marks.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Event {
    /// A client connected (and, through a proxy, its upstream connection was attempted).
    Connect,
    /// The connection ended; the reason says who ended it and why.
    Disconnect,
}

/// When a line happened: monotonic offset from the recording's start, and wall-clock time.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Stamp {
    /// Microseconds since the recording started (monotonic clock).
    pub t_us: u64,
    /// UTC µs since the Unix epoch.
    pub utc_us: u64,
}

/// What the gateway learnt of the reader (from its capabilities and configuration).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ReaderInfo {
    /// DeviceManufacturerName (IANA enterprise number; 25882 is Impinj).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub manufacturer: Option<u32>,
    /// ModelName.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model: Option<u32>,
    /// ReaderFirmwareVersion.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub firmware: Option<String>,
    /// Identification's IDType: `mac` or `epc`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub id_type: Option<String>,
    /// Identification's ReaderID, upper-case hex.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reader_id: Option<String>,
}

/// One line after the header.
#[derive(Clone, Debug, PartialEq)]
pub enum Entry {
    /// One whole LLRP frame, byte for byte.
    Frame {
        /// When the frame was read (its first byte's read completed the frame).
        at: Stamp,
        /// Connection number, 1 for the first client of the recording.
        conn: u32,
        /// Which way it went.
        dir: Direction,
        /// The frame.
        frame: Bytes,
        /// Why the codec could not decode it, where the writer tried (the proxy does for
        /// its recording); the frame is kept byte for byte all the same.
        undecodable: Option<String>,
    },
    /// Bytes that are not LLRP frames (after a length field that cannot be resynchronised),
    /// as they were read.
    Bytes {
        /// When they were read.
        at: Stamp,
        /// Connection number.
        conn: u32,
        /// Which way they went.
        dir: Direction,
        /// The bytes.
        bytes: Bytes,
    },
    /// A connection began or ended.
    Marker {
        /// When.
        at: Stamp,
        /// Connection number.
        conn: u32,
        /// Connect or disconnect.
        event: Event,
        /// Why, in words (peer address, who closed, the error).
        reason: String,
    },
    /// The reader's identity, once seen.
    Reader {
        /// When it was seen.
        at: Stamp,
        /// Connection number.
        conn: u32,
        /// What was learnt.
        reader: ReaderInfo,
    },
}

impl Entry {
    /// When the line happened.
    pub fn at(&self) -> Stamp {
        match self {
            Entry::Frame { at, .. }
            | Entry::Bytes { at, .. }
            | Entry::Marker { at, .. }
            | Entry::Reader { at, .. } => *at,
        }
    }

    /// Its connection number.
    pub fn conn(&self) -> u32 {
        match self {
            Entry::Frame { conn, .. }
            | Entry::Bytes { conn, .. }
            | Entry::Marker { conn, .. }
            | Entry::Reader { conn, .. } => *conn,
        }
    }
}

/// The JSON shape of an entry line (all variants' fields, each optional).
#[derive(Default, Serialize, Deserialize)]
struct Line {
    t_us: u64,
    utc_us: u64,
    conn: u32,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    dir: Option<Direction>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    frame: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    undecodable: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    bytes: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    event: Option<Event>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    reason: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    reader: Option<ReaderInfo>,
}

/// Appends `header` as a JSON line to `out`.
pub fn encode_header(header: &Header, out: &mut Vec<u8>) {
    // Serialising plain structs of strings and numbers to memory cannot fail.
    let _ = serde_json::to_writer(&mut *out, header);
    out.push(b'\n');
}

/// Appends `entry` as a JSON line to `out`.
pub fn encode_entry(entry: &Entry, out: &mut Vec<u8>) {
    match entry {
        // The hot path (every frame): written directly, the base64 straight into `out`.
        Entry::Frame {
            at,
            conn,
            dir,
            frame,
            undecodable: None,
        } => return encode_data(*at, *conn, *dir, "frame", frame, out),
        Entry::Bytes {
            at,
            conn,
            dir,
            bytes,
        } => return encode_data(*at, *conn, *dir, "bytes", bytes, out),
        _ => {}
    }
    let (at, conn) = (entry.at(), entry.conn());
    let mut line = Line {
        t_us: at.t_us,
        utc_us: at.utc_us,
        conn,
        ..Line::default()
    };
    match entry {
        Entry::Frame {
            dir,
            frame,
            undecodable,
            ..
        } => {
            line.dir = Some(*dir);
            line.frame = Some(BASE64.encode(frame));
            line.undecodable.clone_from(undecodable);
        }
        Entry::Bytes { dir, bytes, .. } => {
            line.dir = Some(*dir);
            line.bytes = Some(BASE64.encode(bytes));
        }
        Entry::Marker { event, reason, .. } => {
            line.event = Some(*event);
            line.reason = Some(reason.clone());
        }
        Entry::Reader { reader, .. } => line.reader = Some(reader.clone()),
    }
    // As above: to memory, no maps with non-string keys.
    let _ = serde_json::to_writer(&mut *out, &line);
    out.push(b'\n');
}

/// A frame or bytes line: `{"t_us":…,"utc_us":…,"conn":…,"dir":"…","KEY":"BASE64"}`, the
/// same JSON serde writes for [`Line`].
fn encode_data(at: Stamp, conn: u32, dir: Direction, key: &str, data: &[u8], out: &mut Vec<u8>) {
    use std::io::Write as _;
    let dir = match dir {
        Direction::ToReader => "to_reader",
        Direction::FromReader => "from_reader",
    };
    // Writing to a Vec cannot fail.
    let _ = write!(
        out,
        "{{\"t_us\":{},\"utc_us\":{},\"conn\":{conn},\"dir\":\"{dir}\",\"{key}\":\"",
        at.t_us, at.utc_us
    );
    let start = out.len();
    let len = base64::encoded_len(data.len(), true).unwrap_or(0);
    out.resize(start + len, 0);
    if BASE64.encode_slice(data, &mut out[start..]).is_err() {
        // The slice is exactly encoded_len long, so this cannot happen; stay valid JSON.
        out.truncate(start);
    }
    out.extend_from_slice(b"\"}\n");
}

/// Why a recording cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// The file cannot be read.
    #[error("{0}")]
    Io(#[from] io::Error),
    /// The file is empty.
    #[error("empty file: a recording starts with its header line")]
    Empty,
    /// The first line is not a recording header.
    #[error("line 1 is not a recording header: {0}")]
    Header(String),
    /// The recording is of another format version.
    #[error(
        "recording format version {found} is not supported: this llrp-gateway reads version {}",
        VERSION
    )]
    Version {
        /// The version in the header, as written there.
        found: String,
    },
    /// A line (not the last) does not parse.
    #[error("line {line}: {message}")]
    Line {
        /// 1-based line number.
        line: usize,
        /// What is wrong, naming the field.
        message: String,
    },
}

/// A whole recording in memory.
#[derive(Clone, Debug, PartialEq)]
pub struct Recording {
    /// Its header.
    pub header: Header,
    /// The lines after the header, in file order.
    pub entries: Vec<Entry>,
    /// Problems tolerated while reading (a truncated last line).
    pub warnings: Vec<String>,
}

impl Recording {
    /// Reads a recording file.
    pub fn open(path: &std::path::Path) -> Result<Recording, RecordError> {
        let file = std::fs::File::open(path)?;
        Recording::read(io::BufReader::new(file))
    }

    /// Reads a recording: the header must be of this [`VERSION`]; a last line without its
    /// line end that does not parse (a writer stopped mid-line) is dropped with a warning;
    /// any other bad line is an error naming its line and field.
    pub fn read(mut input: impl BufRead) -> Result<Recording, RecordError> {
        let mut text = String::new();
        if input.read_line(&mut text)? == 0 {
            return Err(RecordError::Empty);
        }
        let value: serde_json::Value =
            serde_json::from_str(&text).map_err(|e| RecordError::Header(e.to_string()))?;
        match value.get("llrp_recording") {
            None => {
                return Err(RecordError::Header(
                    "llrp_recording: missing (not an llrp-gateway recording)".into(),
                ))
            }
            // Any other number (beyond u64, negative, fractional) is another version.
            Some(serde_json::Value::Number(n)) if n.as_u64() != Some(u64::from(VERSION)) => {
                return Err(RecordError::Version {
                    found: number_as_written(&text, "llrp_recording").unwrap_or(n.to_string()),
                })
            }
            Some(serde_json::Value::Number(_)) => {}
            Some(other) => {
                return Err(RecordError::Header(format!(
                    "llrp_recording: {other} is not a format version (a number; this \
                     llrp-gateway reads version {VERSION})"
                )))
            }
        }
        let header: Header = serde_path_to_error::deserialize(value)
            .map_err(|e| RecordError::Header(format!("{}: {}", e.path(), e.inner())))?;
        let mut entries = Vec::new();
        let mut warnings = Vec::new();
        let mut number = 1;
        loop {
            text.clear();
            if input.read_line(&mut text)? == 0 {
                break;
            }
            number += 1;
            if text.trim().is_empty() {
                continue;
            }
            match parse_entry(&text) {
                Ok(e) => entries.push(e),
                Err(message) if !text.ends_with('\n') => {
                    warnings.push(format!(
                        "line {number}: truncated last line dropped ({message})"
                    ));
                }
                Err(message) => {
                    return Err(RecordError::Line {
                        line: number,
                        message,
                    })
                }
            }
        }
        Ok(Recording {
            header,
            entries,
            warnings,
        })
    }

    /// The frames of connection `conn` in order, with their direction and stamp.
    pub fn frames(&self, conn: u32) -> impl Iterator<Item = (Stamp, Direction, &Bytes)> {
        self.entries.iter().filter_map(move |e| match e {
            Entry::Frame {
                at,
                conn: c,
                dir,
                frame,
                ..
            } if *c == conn => Some((*at, *dir, frame)),
            _ => None,
        })
    }

    /// What each connection holds, in order of first appearance.
    pub fn summaries(&self) -> Vec<ConnSummary> {
        let report = llrp::message::RoAccessReport::TYPE;
        self.connections()
            .into_iter()
            .map(|conn| {
                let mut s = ConnSummary {
                    conn,
                    ..ConnSummary::default()
                };
                for e in self.entries.iter().filter(|e| e.conn() == conn) {
                    s.start.get_or_insert(e.at());
                    match e {
                        Entry::Frame { dir, frame, .. } => match dir {
                            Direction::ToReader => s.to_reader += 1,
                            Direction::FromReader => {
                                s.from_reader += 1;
                                if llrp::FrameHeader::peek(frame).map(|h| h.msg_type)
                                    == Some(report)
                                {
                                    s.reports += 1;
                                }
                            }
                        },
                        Entry::Marker { event, reason, .. } => match event {
                            Event::Connect => s.client = Some(reason.clone()),
                            Event::Disconnect => s.end = Some(reason.clone()),
                        },
                        Entry::Bytes { .. } | Entry::Reader { .. } => {}
                    }
                }
                s
            })
            .collect()
    }

    /// The connection numbers in order of first appearance.
    pub fn connections(&self) -> Vec<u32> {
        let mut seen = Vec::new();
        for e in &self.entries {
            if !seen.contains(&e.conn()) {
                seen.push(e.conn());
            }
        }
        seen
    }
}

/// One recorded connection at a glance (`replay --list`).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ConnSummary {
    /// Connection number.
    pub conn: u32,
    /// When its first line happened.
    pub start: Option<Stamp>,
    /// Its connect marker's words (the client's address).
    pub client: Option<String>,
    /// Frames the client sent.
    pub to_reader: usize,
    /// Frames the reader sent.
    pub from_reader: usize,
    /// RO_ACCESS_REPORTs among them.
    pub reports: usize,
    /// Its disconnect marker's words.
    pub end: Option<String>,
}

impl ConnSummary {
    /// Whether it carries an LLRP session: the client sent a frame and the reader answered
    /// (a port probe or health check gets the reader's greeting and sends nothing).
    pub fn has_session(&self) -> bool {
        self.to_reader > 0 && self.from_reader > 0
    }
}

/// The number after `"key":` in a JSON line, as written (serde_json reads integers past u64
/// as floats, which would misname them).
fn number_as_written(line: &str, key: &str) -> Option<String> {
    let at = line.find(&format!("\"{key}\""))? + key.len() + 2;
    let rest = line[at..].trim_start().strip_prefix(':')?.trim_start();
    let end = rest
        .find(|c: char| !(c.is_ascii_digit() || "+-.eE".contains(c)))
        .unwrap_or(rest.len());
    (end > 0).then(|| rest[..end].to_string())
}

fn parse_entry(text: &str) -> Result<Entry, String> {
    let mut de = serde_json::Deserializer::from_str(text);
    let line: Line = serde_path_to_error::deserialize(&mut de)
        .map_err(|e| format!("{}: {}", e.path(), e.inner()))?;
    let at = Stamp {
        t_us: line.t_us,
        utc_us: line.utc_us,
    };
    let conn = line.conn;
    let b64 = |field: &str, s: &str| {
        BASE64
            .decode(s)
            .map(Bytes::from)
            .map_err(|e| format!("{field}: not base64: {e}"))
    };
    let dir = || line.dir.ok_or_else(|| "dir: missing".to_string());
    if let Some(f) = &line.frame {
        let frame = b64("frame", f)?;
        let ok = llrp::FrameHeader::peek(&frame).is_some_and(|h| h.length as usize == frame.len());
        if !ok {
            return Err(format!(
                "frame: {} bytes that are not one whole LLRP frame",
                frame.len()
            ));
        }
        return Ok(Entry::Frame {
            at,
            conn,
            dir: dir()?,
            frame,
            undecodable: line.undecodable.clone(),
        });
    }
    if let Some(b) = &line.bytes {
        return Ok(Entry::Bytes {
            at,
            conn,
            dir: dir()?,
            bytes: b64("bytes", b)?,
        });
    }
    if let Some(event) = line.event {
        return Ok(Entry::Marker {
            at,
            conn,
            event,
            reason: line.reason.unwrap_or_default(),
        });
    }
    if let Some(reader) = line.reader {
        return Ok(Entry::Reader { at, conn, reader });
    }
    Err("the line has none of frame, bytes, event, reader".into())
}

#[cfg(test)]
mod tests;
