//! The publisher's hot path: read batches written as JSON by hand, byte for byte what
//! serde_json writes for a [`ReadBatch`](super::schema::ReadBatch) (its tests compare the
//! two), without serde_json's escaping of every key and of strings that need none, and
//! each read appended to its topic's buffer as it comes.

use serde_json::ser::{CompactFormatter, Formatter};

use super::schema::TagRead;

// Writing into a `Vec<u8>` cannot fail: the `io::Result`s of the formatter below are
// always `Ok`, and are dropped.

/// `s` as a JSON string: copied between quotes where it needs no escape, else escaped by
/// serde_json.
fn string(out: &mut Vec<u8>, s: &str) {
    if s.bytes().all(|b| b >= 0x20 && b != b'"' && b != b'\\') {
        out.push(b'"');
        out.extend_from_slice(s.as_bytes());
        out.push(b'"');
    } else {
        let _ = serde_json::to_writer(&mut *out, s);
    }
}

/// `v` as serde_json writes an `f64`: `null` where it is not finite.
fn float(out: &mut Vec<u8>, v: f64) {
    if v.is_finite() {
        let _ = CompactFormatter.write_f64(out, v);
    } else {
        out.extend_from_slice(b"null");
    }
}

fn unsigned(out: &mut Vec<u8>, v: u64) {
    let _ = CompactFormatter.write_u64(out, v);
}

/// Appends `r` as the JSON object serde_json writes for it.
pub(super) fn tag_read(out: &mut Vec<u8>, r: &TagRead) {
    out.extend_from_slice(b"{\"epcHex\":");
    string(out, &r.epc_hex);
    out.extend_from_slice(b",\"antennaPort\":");
    unsigned(out, u64::from(r.antenna_port));
    if let Some(v) = r.peak_rssi_cdbm {
        out.extend_from_slice(b",\"peakRssiCdbm\":");
        let _ = CompactFormatter.write_i32(out, v);
    }
    if let Some(v) = r.phase_angle {
        out.extend_from_slice(b",\"phaseAngle\":");
        float(out, v);
    }
    if let Some(v) = r.frequency {
        out.extend_from_slice(b",\"frequency\":");
        unsigned(out, u64::from(v));
    }
    out.extend_from_slice(b",\"lastSeenTime\":");
    string(out, &r.last_seen_time);
    out.extend_from_slice(b",\"firstSeenUs\":");
    unsigned(out, r.first_seen_us);
    if let Some(v) = r.channel_index {
        out.extend_from_slice(b",\"channelIndex\":");
        unsigned(out, u64::from(v));
    }
    if let Some(v) = r.doppler_hz {
        out.extend_from_slice(b",\"dopplerHz\":");
        float(out, v);
    }
    if let Some(p) = &r.antenna_pose {
        let [x, y, z] = p.position;
        out.extend_from_slice(b",\"antennaPose\":{\"x\":");
        float(out, x);
        out.extend_from_slice(b",\"y\":");
        float(out, y);
        out.extend_from_slice(b",\"z\":");
        float(out, z);
        out.extend_from_slice(b",\"yaw_deg\":");
        float(out, p.yaw_deg());
        out.extend_from_slice(b",\"pitch_deg\":");
        float(out, p.pitch_deg());
        out.push(b'}');
    }
    out.push(b'}');
}

/// The fields of a batch before its reads, as serde_json writes them.
pub(super) struct Head<'a> {
    /// Schema version.
    pub v: u32,
    /// The publishing gateway.
    pub gateway: &'a str,
    /// The reader.
    pub reader: &'a str,
    /// The gateway's run.
    pub run: u64,
    /// The message's sequence number.
    pub seq: u64,
}

/// A batch message: `head`, then `reads` (reads as [`tag_read`] wrote them, `count` of them,
/// comma-separated).
pub(super) fn batch(head: &Head<'_>, reads: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(reads.len() + 128 + head.gateway.len() + head.reader.len());
    out.extend_from_slice(b"{\"v\":");
    unsigned(&mut out, u64::from(head.v));
    out.extend_from_slice(b",\"gateway\":");
    string(&mut out, head.gateway);
    out.extend_from_slice(b",\"reader\":");
    string(&mut out, head.reader);
    out.extend_from_slice(b",\"run\":");
    unsigned(&mut out, head.run);
    out.extend_from_slice(b",\"seq\":");
    unsigned(&mut out, head.seq);
    out.extend_from_slice(b",\"reads\":[");
    out.extend_from_slice(reads);
    out.extend_from_slice(b"]}");
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fleet::schema::{ReadBatch, VERSION};
    use crate::reads::Pose;

    fn read(epc: &str) -> TagRead {
        TagRead {
            epc_hex: epc.into(),
            antenna_port: 65535,
            peak_rssi_cdbm: Some(-6_512),
            phase_angle: Some(359.999_999_999),
            frequency: Some(u32::MAX),
            last_seen_time: "2026-12-03T13:00:00.000001Z".into(),
            first_seen_us: u64::MAX,
            channel_index: Some(0),
            doppler_hz: Some(-1.5e-7),
            antenna_pose: Some(Pose::from_degrees([1.0, -0.000_001, 1e21], -179.9999, 0.0)),
        }
    }

    #[test]
    fn a_batch_written_by_hand_is_the_bytes_serde_json_writes() {
        let bare = TagRead {
            peak_rssi_cdbm: None,
            phase_angle: None,
            frequency: None,
            channel_index: None,
            doppler_hz: None,
            antenna_pose: None,
            ..read("E2801160600002049ACB0065")
        };
        let odd = TagRead {
            phase_angle: Some(f64::NAN),
            doppler_hz: Some(f64::INFINITY),
            ..read("quote \" backslash \\ tab \t bell \u{7} é ✓")
        };
        let cases: Vec<(&str, &str, Vec<TagRead>)> = vec![
            ("gw", "r1", vec![]),
            ("gw", "r1", vec![read("E280")]),
            (
                "g\"w",
                "réader \"q\" \\",
                vec![bare.clone(), read("E280"), odd.clone()],
            ),
            ("", "", vec![odd, bare]),
        ];
        for (gateway, reader, reads) in cases {
            let want = serde_json::to_vec(&ReadBatch {
                v: VERSION,
                gateway: gateway.into(),
                // "" is the reads that name no reader.
                reader: reader.parse().ok(),
                run: 1_764_633_000_000_000,
                seq: 7,
                reads: reads.clone(),
            })
            .expect("serializes");
            let mut body = Vec::new();
            for (i, r) in reads.iter().enumerate() {
                if i > 0 {
                    body.push(b',');
                }
                tag_read(&mut body, r);
            }
            let head = Head {
                v: VERSION,
                gateway,
                reader,
                run: 1_764_633_000_000_000,
                seq: 7,
            };
            let got = batch(&head, &body);
            assert_eq!(
                String::from_utf8_lossy(&got),
                String::from_utf8_lossy(&want),
                "{gateway:?} {reader:?}"
            );
        }
    }
}
