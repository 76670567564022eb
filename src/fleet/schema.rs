//! The messages on the broker (schema version 1, topics under `PREFIX/v1/`): tag reads in
//! batches, antenna poses, estimates and statuses. Per-read field names and units are the
//! Impinj R700 IoT device interface's `tagInventoryEvent` where it has the field (`epcHex`,
//! `antennaPort`, `peakRssiCdbm` in centi-dBm, `frequency` in kHz, `phaseAngle` in degrees,
//! `lastSeenTime` as RFC 3339); the rest are ours, in the same camelCase (docs/fleet.md).

use llrp_gateway_vocab::reader_name::{empty_is_none, none_as_empty};
use serde::{Deserialize, Serialize};

use crate::reads::{Epc, Pose, Read, ReaderName};

/// The schema version in every message's `v` and in the topics (`v1`).
pub const VERSION: u32 = 1;

/// Default number of read shards (`--shard-count`).
pub const DEFAULT_SHARDS: u16 = 16;

/// The shard of an EPC: FNV-1a (64-bit) of its bytes (the hex decoded; the text's bytes
/// when it is not whole bytes of hex) modulo `count`.
pub fn shard(epc_hex: &str, count: u16) -> u16 {
    const OFFSET: u64 = 0xcbf2_9ce4_8422_2325;
    const PRIME: u64 = 0x0000_0100_0000_01b3;
    let fold = |h: u64, b: u8| (h ^ u64::from(b)).wrapping_mul(PRIME);
    let digits = epc_hex.as_bytes();
    let hex = !digits.is_empty()
        && digits.len().is_multiple_of(2)
        && digits.iter().all(u8::is_ascii_hexdigit);
    let hash = if hex {
        digits
            .chunks_exact(2)
            .map(|pair| (nibble(pair[0]) << 4) | nibble(pair[1]))
            .fold(OFFSET, fold)
    } else {
        digits.iter().copied().fold(OFFSET, fold)
    };
    (hash % u64::from(count.max(1))) as u16
}

/// The value of a hex digit (0 for anything else).
fn nibble(d: u8) -> u8 {
    match d {
        b'0'..=b'9' => d - b'0',
        b'a'..=b'f' => d - b'a' + 10,
        b'A'..=b'F' => d - b'A' + 10,
        _ => 0,
    }
}

/// One tag read on the broker.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct TagRead {
    /// EPC, upper-case hex (R700 `epcHex`).
    pub epc_hex: String,
    /// Antenna port, 1-based (R700 `antennaPort`).
    pub antenna_port: u16,
    /// Peak RSSI in centi-dBm (R700 `peakRssiCdbm`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub peak_rssi_cdbm: Option<i32>,
    /// RF phase in degrees, 0–360 (R700 `phaseAngle`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub phase_angle: Option<f64>,
    /// Channel frequency in kHz (R700 `frequency`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frequency: Option<u32>,
    /// When the tag was last seen, RFC 3339 UTC with microseconds (R700 `lastSeenTime`).
    pub last_seen_time: String,
    /// When the tag was first seen in this read, UTC µs since the Unix epoch (ours: the
    /// LLRP FirstSeenTimestampUTC, exact).
    pub first_seen_us: u64,
    /// 1-based channel index into the reader's hop table (ours).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub channel_index: Option<u16>,
    /// Doppler frequency in Hz (ours: ImpinjRFDopplerFrequency).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub doppler_hz: Option<f64>,
    /// The antenna's pose at the read, where the publisher knows it (ours; metres to the µm,
    /// degrees to 1e-4).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub antenna_pose: Option<Pose>,
}

impl TagRead {
    /// The broker's form of `r`.
    pub fn from_read(r: &Read) -> TagRead {
        let last_seen_time = rfc3339(r.last_seen_us.unwrap_or(r.t_us));
        TagRead::with_epc(r, r.epc.to_string(), last_seen_time)
    }

    /// The broker's form of `r`, its EPC moved rather than copied and its time written by
    /// `clock`.
    pub fn from_owned(mut r: Read, clock: &mut Rfc3339Clock) -> TagRead {
        let epc = std::mem::take(&mut r.epc).into_string();
        let last_seen_time = clock.format(r.last_seen_us.unwrap_or(r.t_us));
        TagRead::with_epc(&r, epc, last_seen_time)
    }

    fn with_epc(r: &Read, epc_hex: String, last_seen_time: String) -> TagRead {
        TagRead {
            epc_hex,
            antenna_port: r.antenna,
            peak_rssi_cdbm: r.rssi_dbm.map(|d| (d * 100.0).round() as i32),
            phase_angle: r.phase_rad.map(f64::to_degrees),
            frequency: r
                .channel_frequency_hz
                .and_then(|hz| u32::try_from(hz / 1000).ok()),
            last_seen_time,
            first_seen_us: r.t_us,
            channel_index: r.channel_index,
            doppler_hz: r.doppler_hz,
            antenna_pose: r.antenna_pose.map(|p| {
                Pose::from_degrees(
                    p.position.map(|v| round_to(v, 1e6)),
                    round_to(p.yaw_deg(), 1e4),
                    round_to(p.pitch_deg(), 1e4),
                )
            }),
        }
    }

    /// The read of reader `reader` this stands for; `None` when its EPC is not hex bytes.
    pub fn to_read(&self, reader: Option<&ReaderName>) -> Option<Read> {
        Some(Read {
            epc: Epc::parse(&self.epc_hex).ok()?,
            reader: reader.cloned(),
            antenna: self.antenna_port,
            t_us: self.first_seen_us,
            phase_rad: self.phase_angle.map(f64::to_radians),
            rssi_dbm: self.peak_rssi_cdbm.map(|c| f64::from(c) / 100.0),
            channel_index: self.channel_index,
            channel_frequency_hz: self.frequency.map(|k| u64::from(k) * 1000),
            doppler_hz: self.doppler_hz,
            antenna_pose: self.antenna_pose,
            last_seen_us: None,
        })
    }
}

/// A batch of one reader's reads (`PREFIX/v1/reads/{shard}` and `PREFIX/v1/refs`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct ReadBatch {
    /// Schema version ([`VERSION`]).
    pub v: u32,
    /// The publishing gateway's name.
    pub gateway: String,
    /// The reader that read them (`""` for reads that name none).
    #[serde(deserialize_with = "empty_is_none", serialize_with = "none_as_empty")]
    pub reader: Option<ReaderName>,
    /// The gateway's run: when it started, UTC µs since the Unix epoch (0 or absent: not
    /// named).
    #[serde(default)]
    pub run: u64,
    /// This reader's message number on this topic, from 1 in each gateway run: a gap is a
    /// lost message, a repeat a redelivery.
    pub seq: u64,
    /// The reads, in the reader's order.
    pub reads: Vec<TagRead>,
}

/// A reader's or gateway's status (`PREFIX/v1/status/{reader}`,
/// `PREFIX/v1/status/gateway/{name}`; retained).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Status {
    /// Schema version ([`VERSION`]).
    pub v: u32,
    /// `online` or `offline`.
    pub status: String,
    /// The gateway the status comes from.
    pub gateway: String,
    /// The reader, for a reader's status: its name (a [`ReaderName`]), or `""` for the reads
    /// that name none (kept as the text the message carries).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reader: Option<String>,
    /// The gateway's run (as in [`ReadBatch::run`]), which `last_seq` counts in.
    #[serde(default)]
    pub run: u64,
    /// On a reader's clean `offline`: the last `seq` it published on each topic (the topic
    /// under `PREFIX/v1/`), so a subscriber can tell it has everything.
    #[serde(default, skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub last_seq: std::collections::BTreeMap<String, u64>,
}

/// A proxied reader's keepalive link lost or restored: the `keepalive` field of a message
/// on `PREFIX/v1/events/{reader}` (beside `v`, `gateway`, `reader` and `seq`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct KeepaliveEvent {
    /// `lost` (no KEEPALIVE for three periods) or `restored` (one came again).
    pub state: String,
    /// The period expected: the client's KeepaliveSpec, or the interval seen (ms).
    pub period_ms: u64,
    /// Time without a KEEPALIVE (ms).
    pub silent_ms: u64,
}

/// `v` rounded to a multiple of `1 / per`: shorter JSON, far below any pose's precision.
fn round_to(v: f64, per: f64) -> f64 {
    (v * per).round() / per
}

/// `us` (UTC µs since the Unix epoch) as RFC 3339 with microseconds
/// ([`crate::utc::rfc3339_micros`]: every `u64`, a year past 9999 expanded).
pub fn rfc3339(us: u64) -> String {
    crate::utc::rfc3339_micros(us)
}

/// [`rfc3339`] for times that come in order: the date and time of day made once a second.
#[derive(Debug, Default)]
pub struct Rfc3339Clock {
    /// The second `prefix` is of.
    second: Option<u64>,
    /// Its RFC 3339 text up to the fraction.
    prefix: String,
}

impl Rfc3339Clock {
    /// `us` (UTC µs since the Unix epoch) as [`rfc3339`] writes it.
    pub fn format(&mut self, us: u64) -> String {
        let second = us / 1_000_000;
        if self.second != Some(second) {
            let whole = rfc3339(second * 1_000_000);
            let Some(dot) = whole.rfind('.') else {
                return rfc3339(us);
            };
            self.prefix = whole[..dot].to_owned();
            self.second = Some(second);
        }
        let mut text = String::with_capacity(self.prefix.len() + 8);
        text.push_str(&self.prefix);
        text.push('.');
        let micros = us % 1_000_000;
        for place in [100_000, 10_000, 1_000, 100, 10, 1] {
            text.push(char::from(b'0' + (micros / place % 10) as u8));
        }
        text.push('Z');
        text
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_clock_writes_what_rfc3339_writes() {
        let mut clock = Rfc3339Clock::default();
        for us in [
            0,
            1,
            999_999,
            1_000_000,
            951_782_399_999_999, // 2000-02-28T23:59:59.999999Z
            951_782_400_000_000,
            951_868_800_123_456, // 2000-03-01 (2000 was a leap year)
            1_764_633_600_000_001,
            1_764_633_600_999_999,
            1_764_633_601_000_000,
            1_764_633_600_000_002,   // back a second
            253_402_300_799_999_999, // 9999-12-31T23:59:59.999999Z
            253_402_300_800_000_001, // +10000-01-01: humantime failed here and panicked
            u64::MAX,
        ] {
            assert_eq!(clock.format(us), rfc3339(us), "{us}");
        }
    }

    #[test]
    fn shards_by_fnv1a_64_of_the_epc_bytes() {
        // FNV-1a 64 reference values (the FNV authors' test suite): "" and "a", "foobar".
        assert_eq!(
            shard("", u16::MAX),
            (0xcbf2_9ce4_8422_2325u64 % 65535) as u16
        );
        assert_eq!(
            shard("61", u16::MAX),
            (0xaf63_dc4c_8601_ec8cu64 % 65535) as u16
        );
        assert_eq!(
            shard("666F6F626172", u16::MAX),
            (0x8594_4171_f739_67e8u64 % 65535) as u16
        );
        // Case does not matter (the bytes do); a non-hex EPC hashes its text.
        assert_eq!(shard("666f6f626172", 16), shard("666F6F626172", 16));
        assert_eq!(shard("foobar", u16::MAX), shard("666F6F626172", u16::MAX));
        // Every shard gets some of 1000 EPCs.
        let mut seen = [0; 16];
        for k in 0..1000u32 {
            seen[usize::from(shard(&format!("E280{k:020X}"), 16))] += 1;
        }
        assert!(seen.iter().all(|&n| n > 30), "{seen:?}");
    }

    #[test]
    fn a_read_goes_to_the_broker_and_back_unchanged() {
        let r = Read {
            epc: crate::reads::Epc::parse("E2801160600002049ACB0065").expect("hex"),
            reader: Some("r1".parse().expect("a reader name")),
            antenna: 3,
            t_us: 1_764_633_600_123_456,
            phase_rad: Some(1.25),
            rssi_dbm: Some(-53.25),
            channel_index: Some(2),
            channel_frequency_hz: Some(866_300_000),
            doppler_hz: Some(-4.5),
            antenna_pose: None,
            last_seen_us: None,
        };
        let t = TagRead::from_read(&r);
        assert_eq!(t.peak_rssi_cdbm, Some(-5325));
        assert_eq!(t.frequency, Some(866_300));
        assert_eq!(t.last_seen_time, "2025-12-02T00:00:00.123456Z");
        let json = serde_json::to_value(&t).expect("serializes");
        for key in [
            "epcHex",
            "antennaPort",
            "peakRssiCdbm",
            "phaseAngle",
            "frequency",
        ] {
            assert!(json.get(key).is_some(), "{key} in {json}");
        }
        let back: TagRead = serde_json::from_value(json).expect("parses");
        let r1 = "r1".parse().ok();
        let again = back.to_read(r1.as_ref()).expect("an EPC");
        assert!((again.phase_rad.expect("phase") - 1.25).abs() < 1e-12);
        assert_eq!(
            Read {
                phase_rad: r.phase_rad,
                ..again
            },
            r
        );
    }

    #[test]
    fn an_antenna_pose_goes_to_the_broker_to_the_micrometre() {
        let r = Read {
            epc: crate::reads::Epc::parse("AB").expect("hex"),
            reader: None,
            antenna: 1,
            t_us: 1,
            phase_rad: None,
            rssi_dbm: None,
            channel_index: None,
            channel_frequency_hz: None,
            doppler_hz: None,
            antenna_pose: Some(Pose::from_degrees(
                [
                    12.345_678_901_234_567,
                    -3.000_000_4,
                    1.000_000_000_000_000_2,
                ],
                89.999_999_999_999_99,
                -10.123_456,
            )),
            last_seen_us: None,
        };
        let json = serde_json::to_string(&TagRead::from_read(&r)).expect("serializes");
        assert!(
            json.contains(r#""antennaPose":{"x":12.345679,"y":-3.0,"z":1.0,"yaw_deg":90.0,"pitch_deg":-10.1235}"#),
            "{json}"
        );
    }

    #[test]
    fn a_batch_that_names_no_run_parses_as_run_zero() {
        let b: ReadBatch = serde_json::from_str(
            r#"{"v": 1, "gateway": "g", "reader": "r", "seq": 3, "reads": []}"#,
        )
        .expect("parses");
        assert_eq!((b.run, b.seq), (0, 3));
    }
}
