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

/// One tag read (one TagReportData), in SI units; a line of the reads file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Read {
    /// EPC, upper-case hex.
    pub epc: String,
    /// Name of the reader that reported it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reader: Option<String>,
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
    /// file).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub antenna_pose: Option<AntennaPose>,
    /// Last-seen time, UTC µs (not a reads-file field: the CSV output carries it).
    #[serde(skip)]
    pub last_seen_us: Option<u64>,
}

/// The antenna's pose at a read, in the reads file: `{"x", "y", "z"[, "yaw_deg", "pitch_deg"]}`
/// (metres, degrees).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AntennaPose {
    /// Position (m).
    pub x: f64,
    /// Position (m).
    pub y: f64,
    /// Position (m).
    pub z: f64,
    /// Boresight azimuth about +z (degrees, 0 = +x).
    #[serde(default)]
    pub yaw_deg: f64,
    /// Boresight elevation (degrees, positive up).
    #[serde(default)]
    pub pitch_deg: f64,
}

/// Where a reader's source knows them (a simulator), the pose of each antenna at a read's
/// time: `(antenna, read time in UTC µs) → pose`.
#[derive(Clone)]
pub struct PoseAt(std::sync::Arc<dyn Fn(u16, u64) -> Option<AntennaPose> + Send + Sync>);

impl PoseAt {
    /// Poses from `f`.
    pub fn new(f: impl Fn(u16, u64) -> Option<AntennaPose> + Send + Sync + 'static) -> PoseAt {
        PoseAt(std::sync::Arc::new(f))
    }

    /// The pose of `antenna` at `t_us` (UTC µs), if known.
    pub fn at(&self, antenna: u16, t_us: u64) -> Option<AntennaPose> {
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
    /// One CSV row (no line end) in the order of [`CSV_HEADER`]; absent values are empty.
    pub fn csv_row(&self) -> String {
        fn opt<T: ToString>(v: &Option<T>) -> String {
            v.as_ref().map(ToString::to_string).unwrap_or_default()
        }
        format!(
            "{},{},{},{},{},{},{},{},{},{}",
            self.epc,
            self.reader.as_deref().unwrap_or(""),
            self.antenna,
            self.t_us,
            opt(&self.last_seen_us),
            opt(&self.phase_rad),
            opt(&self.rssi_dbm),
            opt(&self.channel_index),
            opt(&self.channel_frequency_hz),
            opt(&self.doppler_hz),
        )
    }
}

/// Turns one connection's LLRP frames into [`Read`]s.
#[derive(Clone, Debug, Default)]
pub struct ReadDecoder {
    reader: Option<String>,
    hop_table: Option<HopTable>,
    /// The hop table came from the reader's capabilities (not overridden by a fallback).
    from_reader: bool,
    /// Stamps each read with its antenna's pose.
    poses: Option<PoseAt>,
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
    pub fn new(reader: Option<String>) -> Self {
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
        let antenna = r.antenna_id.unwrap_or(0);
        Read {
            epc: hex_upper(r.epc),
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
pub struct Decoders(std::collections::HashMap<String, ReadDecoder>);

impl Decoders {
    /// Reader `name` advertises `hop_table`, and its source knows its antennas' poses where
    /// `poses` is given (its decoder keeps what it has learnt).
    pub fn register(
        &mut self,
        name: &str,
        hop_table: Option<llrp::units::HopTable>,
        poses: Option<PoseAt>,
    ) {
        let d = self
            .0
            .remove(name)
            .unwrap_or_else(|| ReadDecoder::new(Some(name.to_owned())))
            .with_fallback_table(hop_table)
            .with_poses(poses);
        self.0.insert(name.to_owned(), d);
    }

    /// Reader `name`'s decoder, made when first asked for.
    pub fn of(&mut self, name: &str) -> &mut ReadDecoder {
        self.0
            .entry(name.to_owned())
            .or_insert_with(|| ReadDecoder::new(Some(name.to_owned())))
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

/// Why `epc` is no EPC in hex, if it is not.
pub fn check_epc(epc: &str) -> Result<(), String> {
    if epc.is_empty() {
        return Err("the EPC is empty".into());
    }
    if let Some((i, c)) = epc.char_indices().find(|(_, c)| !c.is_ascii_hexdigit()) {
        return Err(format!(
            "EPC {epc:?} is not hex: {c:?} at offset {i} is no hex digit"
        ));
    }
    if epc.len() % 2 != 0 {
        return Err(format!(
            "EPC {epc:?} is not hex bytes: an odd number of digits ({})",
            epc.len()
        ));
    }
    Ok(())
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
        // A read with no EPC, or one that is not hex, would make a tag of nothing.
        check_epc(&read.epc).map_err(|reason| ReadsFileError {
            line: i + 1,
            message: format!("epc: {reason}"),
        })?;
        reads.push(read);
    }
    Ok(reads)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_splits_back_to_back_frames_and_flags_one_cut_short() {
        let one = llrp::Message::new(1, llrp::message::Keepalive::default()).to_bytes();
        let mut bytes = [one.as_ref(), one.as_ref()].concat();
        let whole: Vec<_> = frames(&bytes).collect();
        assert_eq!(whole, [Ok(one.as_ref()), Ok(one.as_ref())]);
        // A header whose length runs past the end: 20 bytes said, 12 there.
        let mut short = one.to_vec();
        short[2..6].copy_from_slice(&20u32.to_be_bytes());
        short.extend_from_slice(&[0, 0]);
        bytes.extend_from_slice(&short);
        let cut: Vec<_> = frames(&bytes).collect();
        assert_eq!(cut.len(), 3);
        assert_eq!(cut[2], Err(()));
        assert_eq!(frames(&bytes[..4]).count(), 0);
    }

    #[test]
    fn an_epc_is_even_hex_and_the_reason_is_named() {
        assert!(check_epc("E200ab").is_ok());
        assert!(check_epc("").is_err());
        let e = check_epc("E20").expect_err("odd");
        assert!(e.contains("odd"), "{e}");
        let e = check_epc("E2G0").expect_err("G");
        assert!(e.contains("'G'") && e.contains("offset 2"), "{e}");
        // Not ASCII: a char, not a byte, is named.
        let e = check_epc("é0").expect_err("é");
        assert!(e.contains("'é'"), "{e}");
    }

    #[test]
    fn a_reads_file_line_with_an_empty_or_non_hex_epc_is_refused_by_number() {
        let good = r#"{"epc":"3034F8","antenna":1,"t_us":1,"phase_rad":null,"rssi_dbm":null}"#;
        for (epc, why) in [("", "empty"), ("30G4", "'G'"), ("303", "odd")] {
            let bad = good.replace("3034F8", epc);
            let text = format!("{good}\n{good}\n{bad}\n");
            let e = read_jsonl(text.as_bytes()).expect_err("refused");
            assert_eq!(e.line, 3, "{e}");
            assert!(
                e.message.starts_with("epc: ") && e.message.contains(why),
                "{e}"
            );
        }
        assert_eq!(
            read_jsonl(format!("{good}\n").as_bytes())
                .expect("parses")
                .len(),
            1
        );
    }

    #[test]
    fn a_read_round_trips_through_the_reads_file() {
        let read = Read {
            epc: "3034F8".into(),
            reader: Some("dock".into()),
            antenna: 2,
            t_us: 1_700_000_000_000_000,
            phase_rad: Some(1.5),
            rssi_dbm: Some(-55.25),
            channel_index: Some(7),
            channel_frequency_hz: Some(915_250_000),
            doppler_hz: None,
            antenna_pose: None,
            last_seen_us: None,
        };
        let mut buf = Vec::new();
        write_jsonl(&mut buf, &read).expect("to memory");
        let text = String::from_utf8(buf.clone()).expect("utf-8");
        assert!(text.contains("\"doppler_hz\":null"), "{text}");
        assert_eq!(read_jsonl(&buf[..]).expect("parses"), vec![read]);
    }

    fn report_on_channel(channel: u16) -> Vec<u8> {
        report(llrp::params::TagReportData {
            channel_index: Some(llrp::params::ChannelIndex(channel)),
            ..tag_ab()
        })
    }

    /// A TagReportData of EPC AB…AB and nothing else.
    fn tag_ab() -> llrp::params::TagReportData {
        llrp::params::TagReportData {
            epc: llrp::params::Epc::Epc96(llrp::params::Epc96([0xAB; 12])),
            ..Default::default()
        }
    }

    /// An RO_ACCESS_REPORT frame of `data`.
    fn report(data: llrp::params::TagReportData) -> Vec<u8> {
        Message::new(
            1,
            RoAccessReport {
                tag_report_data: vec![data],
                ..Default::default()
            },
        )
        .to_bytes()
        .to_vec()
    }

    #[test]
    fn the_frequency_comes_from_the_readers_table_else_the_fallback_else_none() {
        let frame = report_on_channel(2);
        let mut out = Vec::new();
        let mut none = ReadDecoder::new(None);
        none.frame(&frame, 0, &mut out).expect("decodes");
        assert_eq!(out[0].channel_frequency_hz, None);
        assert_eq!(out[0].epc, "AB".repeat(12));
        let mut d = ReadDecoder::new(None).with_fallback_table(Some(HopTable::etsi()));
        out.clear();
        d.frame(&frame, 0, &mut out).expect("decodes");
        assert_eq!(out[0].channel_frequency_hz, Some(866_300_000));
        // The reader's own capabilities win over the fallback.
        use llrp::message::GetReaderCapabilitiesResponse;
        use llrp::params::{
            FrequencyHopTable, FrequencyInformation, RegulatoryCapabilities, UhfBandCapabilities,
        };
        let caps = GetReaderCapabilitiesResponse {
            regulatory_capabilities: Some(RegulatoryCapabilities {
                uhf_band_capabilities: Some(UhfBandCapabilities {
                    frequency_information: FrequencyInformation {
                        hopping: true,
                        frequency_hop_table: vec![FrequencyHopTable {
                            hop_table_id: 1,
                            frequencies: HopTable::fcc().frequencies_khz,
                            ..Default::default()
                        }],
                        ..Default::default()
                    },
                    ..Default::default()
                }),
                ..Default::default()
            }),
            ..Default::default()
        };
        d.observe(&Message::new(2, caps));
        out.clear();
        d.frame(&frame, 0, &mut out).expect("decodes");
        let fcc = HopTable::fcc();
        assert_eq!(
            out[0].channel_frequency_hz,
            fcc.frequency_khz(2).map(|k| u64::from(k) * 1000)
        );
    }

    #[test]
    fn a_decoder_given_poses_stamps_each_read_with_its_antennas_pose_at_the_read() {
        use llrp::params::{AntennaId, FirstSeenTimestampUtc};
        let report = |antenna: u16, t_us: u64| {
            report(llrp::params::TagReportData {
                antenna_id: Some(AntennaId(antenna)),
                first_seen_timestamp_utc: Some(FirstSeenTimestampUtc(t_us)),
                ..tag_ab()
            })
        };
        // Antenna 1 moves along x at 1 m/s from t = 1 s; there is no antenna 2.
        let poses = PoseAt::new(|antenna, t_us| {
            (antenna == 1).then(|| AntennaPose {
                x: t_us.saturating_sub(1_000_000) as f64 * 1e-6,
                y: 2.0,
                z: 0.5,
                yaw_deg: 90.0,
                pitch_deg: 0.0,
            })
        });
        let mut d = ReadDecoder::new(Some("r".into())).with_poses(Some(poses));
        let mut out = Vec::new();
        d.frame(&report(1, 3_500_000), 0, &mut out)
            .expect("decodes");
        d.frame(&report(2, 3_500_000), 0, &mut out)
            .expect("decodes");
        let p = out[0].antenna_pose.expect("antenna 1's pose");
        assert_eq!((p.x, p.y, p.yaw_deg), (2.5, 2.0, 90.0));
        assert_eq!(out[1].antenna_pose, None, "no pose known for antenna 2");
        // Without poses, none.
        let mut plain = ReadDecoder::new(None);
        out.clear();
        plain
            .frame(&report(1, 3_500_000), 0, &mut out)
            .expect("decodes");
        assert_eq!(out[0].antenna_pose, None);
    }

    #[test]
    fn an_epc_of_other_than_96_bits_is_read_from_epc_data() {
        use llrp::codec::BitVec;
        use llrp::message::RoAccessReport;
        use llrp::params::{Epc, EpcData, TagReportData};
        let epc128: Vec<u8> = (1..=16).collect();
        let data = |bytes: &[u8]| TagReportData {
            epc: Epc::EpcData(EpcData {
                epc: BitVec::from_bytes(bytes),
                ..Default::default()
            }),
            ..Default::default()
        };
        let frame = Message::new(
            1,
            RoAccessReport {
                tag_report_data: vec![data(&epc128), data(&[0xE2, 0x00, 0xAB, 0xCD])],
                ..Default::default()
            },
        )
        .to_bytes();
        let mut out = Vec::new();
        ReadDecoder::new(None)
            .frame(&frame, 0, &mut out)
            .expect("decodes");
        let epcs: Vec<&str> = out.iter().map(|r| r.epc.as_str()).collect();
        assert_eq!(epcs, ["0102030405060708090A0B0C0D0E0F10", "E200ABCD"]);
    }

    #[test]
    fn optional_fields_may_be_absent_and_a_bad_field_is_named() {
        let ok = br#"{"epc":"AB","antenna":1,"t_us":5,"phase_rad":0.5,"rssi_dbm":-60}"#;
        let r = read_jsonl(&ok[..]).expect("parses");
        assert_eq!(r[0].reader, None);
        assert_eq!(r[0].channel_index, None);
        let bad =
            b"\n{\"epc\":\"AB\",\"antenna\":\"one\",\"t_us\":5,\"phase_rad\":0.5,\"rssi_dbm\":-60}";
        let e = read_jsonl(&bad[..]).expect_err("antenna is a string");
        assert_eq!(e.line, 2);
        assert!(e.message.starts_with("antenna:"), "{}", e.message);
    }

    #[test]
    fn an_antenna_pose_stands_in_for_a_pose_file() {
        let line = br#"{"epc":"AB","antenna":1,"t_us":5,"phase_rad":0.5,"rssi_dbm":null,"antenna_pose":{"x":1,"y":2,"z":0.5,"yaw_deg":90}}"#;
        let r = read_jsonl(&line[..]).expect("parses");
        let p = r[0].antenna_pose.expect("a pose");
        assert_eq!(
            (p.x, p.y, p.z, p.yaw_deg, p.pitch_deg),
            (1.0, 2.0, 0.5, 90.0, 0.0)
        );
        let bad = br#"{"epc":"AB","antenna":1,"t_us":5,"phase_rad":0.5,"rssi_dbm":null,"antenna_pose":{"x":1,"y":2}}"#;
        let e = read_jsonl(&bad[..]).expect_err("z missing");
        assert!(
            e.message.contains("antenna_pose") && e.message.contains('z'),
            "{}",
            e.message
        );
    }
}
