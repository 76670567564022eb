//! Tag reads as the gateway hands them on: one [`Read`] per TagReportData, in SI units, and
//! the project's **reads file** (JSON Lines, one read a line), which the inventory client
//! writes and the localizer reads.
//!
//! [`ReadDecoder`] turns the RO_ACCESS_REPORT frames of one reader connection into reads; it
//! learns the reader's hop table from a GET_READER_CAPABILITIES_RESPONSE seen on the same
//! connection (or is given one, e.g. from a `--region`), so a read's channel index becomes a
//! frequency without guessing. It sees only LLRP frames, so it works the same on a real reader.

use std::io::{self, BufRead, Write};

use llrp::message::MessageBody;
use llrp::message::{GetReaderCapabilitiesResponse, MessageDef, RoAccessReport};
use llrp::units::{self, HopTable};
use llrp::Message;
use serde::{Deserialize, Serialize};

pub use crate::epc::{Epc, EpcError};
pub use crate::pose::Pose;
pub use crate::reader_name::{ReaderName, ReaderNameError};

/// One tag read (one TagReportData), in SI units; a line of the reads file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Read {
    /// EPC, upper-case hex (any case in a reads file).
    pub epc: Epc,
    /// Name of the reader that reported it (absent, or `""` in a reads file, when unknown).
    #[serde(
        default,
        deserialize_with = "crate::reader_name::empty_is_none",
        skip_serializing_if = "Option::is_none"
    )]
    pub reader: Option<ReaderName>,
    /// Antenna port (1-based AntennaID); 0 when the report carried none.
    pub antenna: u16,
    /// First-seen time, UTC microseconds since the Unix epoch (FirstSeenTimestampUTC; a
    /// read without it, e.g. with only the uptime timestamp, gets the time its report
    /// arrived).
    pub t_us: u64,
    /// RF phase in radians, 0..2π (ImpinjRFPhaseAngle); null when the reader sent none.
    pub phase_rad: Option<f64>,
    /// Peak RSSI in dBm: ImpinjPeakRSSI (hundredths) when present, else PeakRSSI (whole dBm);
    /// null when the reader sent neither.
    pub rssi_dbm: Option<f64>,
    /// 1-based ChannelIndex into the reader's hop table.
    #[serde(default)]
    pub channel_index: Option<u16>,
    /// The channel's frequency in Hz, from the reader's hop table; null when unknown.
    #[serde(default)]
    pub channel_frequency_hz: Option<u64>,
    /// Doppler frequency in Hz (ImpinjRFDopplerFrequency).
    #[serde(default)]
    pub doppler_hz: Option<f64>,
    /// Pose of the antenna at the read, where the source knows it (stands in for a pose
    /// file); in the reads file `{"x", "y", "z"[, "yaw_deg", "pitch_deg"]}` (metres, degrees).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub antenna_pose: Option<Pose>,
    /// Last-seen time, UTC µs (not a reads-file field: the CSV output carries it).
    #[serde(skip)]
    pub last_seen_us: Option<u64>,
}

/// Where a reader's source knows them (a simulator), the pose of each antenna at a read's
/// time: `(antenna, read time in UTC µs) → pose`.
#[derive(Clone)]
pub struct PoseAt(std::sync::Arc<dyn Fn(u16, u64) -> Option<Pose> + Send + Sync>);

impl PoseAt {
    /// Poses from `f`.
    pub fn new(f: impl Fn(u16, u64) -> Option<Pose> + Send + Sync + 'static) -> PoseAt {
        PoseAt(std::sync::Arc::new(f))
    }

    /// The pose of `antenna` at `t_us` (UTC µs), if known.
    pub fn at(&self, antenna: u16, t_us: u64) -> Option<Pose> {
        (self.0)(antenna, t_us)
    }
}

impl std::fmt::Debug for PoseAt {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("PoseAt(..)")
    }
}

/// The columns of the CSV output, in order.
pub const CSV_HEADER: &str = "epc,reader,antenna,t_us,last_seen_us,phase_rad,rssi_dbm,channel_index,channel_frequency_hz,doppler_hz";

impl Read {
    /// The cells of one CSV row in the order of [`CSV_HEADER`]; absent values are empty.
    /// Written through [`crate::table::CsvWriter`], which quotes a reader name that needs it.
    pub fn csv_cells(&self) -> [String; 10] {
        fn opt<T: ToString>(v: &Option<T>) -> String {
            v.as_ref().map(ToString::to_string).unwrap_or_default()
        }
        [
            self.epc.to_string(),
            self.reader.as_deref().unwrap_or("").to_string(),
            self.antenna.to_string(),
            self.t_us.to_string(),
            opt(&self.last_seen_us),
            opt(&self.phase_rad),
            opt(&self.rssi_dbm),
            opt(&self.channel_index),
            opt(&self.channel_frequency_hz),
            opt(&self.doppler_hz),
        ]
    }
}

/// Turns one connection's LLRP frames into [`Read`]s.
#[derive(Clone, Debug, Default)]
pub struct ReadDecoder {
    reader: Option<ReaderName>,
    hop_table: Option<HopTable>,
    /// The hop table came from the reader's capabilities (not overridden by a fallback).
    from_reader: bool,
    /// Stamps each read with its antenna's pose.
    poses: Option<PoseAt>,
    /// Takes only the reads of this ROSpec (those that carry another ROSpecID are counted
    /// in `foreign` and dropped).
    only_rospec: Option<u32>,
    foreign: u64,
    /// The reader's only antenna, when it has one: a read that names none is its.
    sole_antenna: Option<u16>,
}

/// Why a frame gave no reads.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// The RO_ACCESS_REPORT does not decode.
    #[error("undecodable RO_ACCESS_REPORT: {0}")]
    Decode(#[from] llrp::DecodeError),
}

impl ReadDecoder {
    /// A decoder labelling its reads with `reader` (if given), with no hop table yet.
    pub fn new(reader: Option<ReaderName>) -> Self {
        ReadDecoder {
            reader,
            ..ReadDecoder::default()
        }
    }

    /// Uses `table` until the reader's own capabilities are seen.
    pub fn with_fallback_table(mut self, table: Option<HopTable>) -> Self {
        if !self.from_reader {
            self.hop_table = table;
        }
        self
    }

    /// Stamps each read with its antenna's pose from `poses` (where the source knows it).
    pub fn with_poses(mut self, poses: Option<PoseAt>) -> Self {
        self.poses = poses;
        self
    }

    /// The reader's antenna ports: when there is one, a read that names no antenna (its
    /// client turned AntennaID off, as sllurp's `inventory` does) is taken as that antenna's.
    pub fn with_antennas(mut self, antennas: &[u16]) -> Self {
        self.sole_antenna = match antennas {
            [one] => Some(*one),
            _ => None,
        };
        self
    }

    /// Takes only the reads of ROSpec `id`: a read whose ROSpecID is another's (a ROSpec an
    /// earlier client left running) is dropped and counted ([`Self::foreign_reads`]).
    pub fn with_only_rospec(mut self, id: u32) -> Self {
        self.only_rospec = Some(id);
        self
    }

    /// Reads dropped because they carried another ROSpec's ID.
    pub fn foreign_reads(&self) -> u64 {
        self.foreign
    }

    /// The hop table in use, if any.
    pub fn hop_table(&self) -> Option<&HopTable> {
        self.hop_table.as_ref()
    }

    /// Learns from a decoded message (the hop table of a capabilities response).
    pub fn observe(&mut self, message: &Message) {
        if let MessageBody::GetReaderCapabilitiesResponse(r) = &message.body {
            if let Some(caps) = &r.regulatory_capabilities {
                // Readers hop by table 1 unless configured otherwise; a fixed-frequency
                // region reports its table as 0.
                let table = HopTable::from_capabilities(caps, 1).or_else(|| {
                    caps.uhf_band_capabilities.as_ref().and_then(|u| {
                        u.frequency_information
                            .frequency_hop_table
                            .first()
                            .and_then(|t| HopTable::from_capabilities(caps, t.hop_table_id))
                    })
                });
                if table.is_some() {
                    self.hop_table = table;
                    self.from_reader = true;
                }
            }
        }
    }

    /// Looks at one frame from the reader: learns from capabilities responses, and appends
    /// the reads of an RO_ACCESS_REPORT to `out`; `now_utc_us` stamps reads that carry no
    /// timestamp. Other frames are ignored.
    pub fn frame(
        &mut self,
        frame: &[u8],
        now_utc_us: u64,
        out: &mut Vec<Read>,
    ) -> Result<(), ReadError> {
        let Some(h) = llrp::FrameHeader::peek(frame) else {
            return Ok(());
        };
        if h.msg_type == GetReaderCapabilitiesResponse::TYPE {
            if let Ok(m) = Message::decode(frame) {
                self.observe(&m);
            }
            return Ok(());
        }
        if h.msg_type != RoAccessReport::TYPE {
            return Ok(());
        }
        for r in llrp::reads::tag_reads(frame)? {
            let r = r?;
            if let (Some(want), Some(got)) = (self.only_rospec, r.ro_spec_id) {
                if got != want {
                    self.foreign += 1;
                    continue;
                }
            }
            out.push(self.read(&r, now_utc_us));
        }
        Ok(())
    }

    /// One read from a walked TagReportData.
    pub fn read(&self, r: &llrp::reads::TagRead<'_>, now_utc_us: u64) -> Read {
        // An uptime timestamp alone cannot be placed on the UTC axis without knowing when the
        // reader booted, which LLRP does not say: such reads take the arrival time.
        let t_us = r.first_seen_utc.unwrap_or(now_utc_us);
        let last_seen_us = r.last_seen_utc;
        let rssi_dbm = r
            .impinj_peak_rssi
            .map(units::centi_dbm_to_dbm)
            .or(r.peak_rssi.map(f64::from));
        let channel_frequency_hz = r
            .channel_index
            .zip(self.hop_table.as_ref())
            .and_then(|(c, t)| t.frequency_khz(c))
            .map(|khz| u64::from(khz) * 1000);
        let antenna = r.antenna_id.or(self.sole_antenna).unwrap_or(0);
        Read {
            epc: Epc::from_bits(r.epc, r.epc_bits),
            reader: self.reader.clone(),
            antenna,
            t_us,
            phase_rad: r.phase_angle.map(units::phase_to_radians),
            rssi_dbm,
            channel_index: r.channel_index,
            channel_frequency_hz,
            doppler_hz: r.doppler_frequency.map(units::doppler_to_hz),
            antenna_pose: self.poses.as_ref().and_then(|p| p.at(antenna, t_us)),
            last_seen_us,
        }
    }
}

/// One [`ReadDecoder`] per reader, by name.
#[derive(Debug, Default)]
pub struct Decoders(std::collections::HashMap<ReaderName, ReadDecoder>);

impl Decoders {
    /// Reader `name` advertises `hop_table` and has antenna ports `antennas`, and its source
    /// knows its antennas' poses where `poses` is given (its decoder keeps what it has learnt).
    pub fn register(
        &mut self,
        name: &ReaderName,
        hop_table: Option<llrp::units::HopTable>,
        antennas: &[u16],
        poses: Option<PoseAt>,
    ) {
        let d = self
            .0
            .remove(name.as_str())
            .unwrap_or_else(|| ReadDecoder::new(Some(name.clone())))
            .with_fallback_table(hop_table)
            .with_antennas(antennas)
            .with_poses(poses);
        self.0.insert(name.clone(), d);
    }

    /// Reader `name`'s decoder, made when first asked for.
    pub fn of(&mut self, name: &ReaderName) -> &mut ReadDecoder {
        self.0
            .entry(name.clone())
            .or_insert_with(|| ReadDecoder::new(Some(name.clone())))
    }
}

/// The LLRP frames of `bytes`, back to back as a reader writes them: each whole frame, then
/// `Err(())` once if what is left is a frame cut short (a length field past the end or under
/// a header's); a tail shorter than a header ends it quietly.
pub fn frames(bytes: &[u8]) -> impl Iterator<Item = Result<&[u8], ()>> + '_ {
    let mut at = 0;
    std::iter::from_fn(move || {
        let h = llrp::FrameHeader::peek(bytes.get(at..)?)?;
        let len = h.length as usize;
        if len < llrp::frame::HEADER_LEN || at + len > bytes.len() {
            at = bytes.len();
            return Some(Err(()));
        }
        let frame = &bytes[at..at + len];
        at += len;
        Some(Ok(frame))
    })
}

/// Upper-case hex of `bytes`.
pub fn hex_upper(bytes: &[u8]) -> String {
    const DIGITS: &[u8; 16] = b"0123456789ABCDEF";
    let mut s = String::with_capacity(bytes.len() * 2);
    for &b in bytes {
        s.push(char::from(DIGITS[usize::from(b >> 4)]));
        s.push(char::from(DIGITS[usize::from(b & 0x0f)]));
    }
    s
}

/// Why `epc` is no EPC in hex, if it is not ([`Epc::parse`]'s reason).
pub fn check_epc(epc: &str) -> Result<(), String> {
    Epc::parse(epc).map(drop).map_err(|e| e.to_string())
}

/// Writes one read as a reads-file line.
pub fn write_jsonl(out: &mut impl Write, read: &Read) -> io::Result<()> {
    serde_json::to_writer(&mut *out, read)?;
    out.write_all(b"\n")
}

/// A reads-file line that does not parse.
#[derive(Debug, thiserror::Error)]
#[error("reads file line {line}: {message}")]
pub struct ReadsFileError {
    /// 1-based line number.
    pub line: usize,
    /// What is wrong, naming the field.
    pub message: String,
}

/// Reads a whole reads file; blank lines are skipped.
pub fn read_jsonl(input: impl BufRead) -> Result<Vec<Read>, ReadsFileError> {
    let mut reads = Vec::new();
    for (i, line) in input.lines().enumerate() {
        let line = line.map_err(|e| ReadsFileError {
            line: i + 1,
            message: e.to_string(),
        })?;
        if line.trim().is_empty() {
            continue;
        }
        let mut de = serde_json::Deserializer::from_str(&line);
        let read: Read = serde_path_to_error::deserialize(&mut de).map_err(|e| ReadsFileError {
            line: i + 1,
            message: format!("{}: {}", e.path(), e.inner()),
        })?;
        // (A read with no EPC, or one that is not hex, would make a tag of nothing: the
        // `Epc` it deserializes into refuses it.)
        reads.push(read);
    }
    Ok(reads)
}

#[cfg(test)]
mod tests;
