//! Unit tests of the parent module.

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
        epc: Epc::parse("3034F8").expect("hex"),
        reader: Some("dock".parse().expect("a reader name")),
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
        (antenna == 1).then(|| {
            let x = t_us.saturating_sub(1_000_000) as f64 * 1e-6;
            Pose::from_degrees([x, 2.0, 0.5], 90.0, 0.0)
        })
    });
    let mut d = ReadDecoder::new("r".parse().ok()).with_poses(Some(poses));
    let mut out = Vec::new();
    d.frame(&report(1, 3_500_000), 0, &mut out)
        .expect("decodes");
    d.frame(&report(2, 3_500_000), 0, &mut out)
        .expect("decodes");
    let p = out[0].antenna_pose.expect("antenna 1's pose");
    assert_eq!(
        (p.position[0], p.position[1], p.yaw_deg()),
        (2.5, 2.0, 90.0)
    );
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
fn a_read_naming_no_antenna_is_the_sole_antennas_and_gets_its_pose() {
    use llrp::params::FirstSeenTimestampUtc;
    // As sllurp's `inventory` asks: AntennaID off.
    let frame = report(llrp::params::TagReportData {
        antenna_id: None,
        first_seen_timestamp_utc: Some(FirstSeenTimestampUtc(2_000_000)),
        ..tag_ab()
    });
    let poses = || {
        Some(PoseAt::new(|antenna, _| {
            (antenna == 3).then_some(Pose::from_degrees([1.0, 2.0, 0.5], 90.0, 0.0))
        }))
    };
    let mut out = Vec::new();
    let mut sole = ReadDecoder::new("r".parse().ok())
        .with_antennas(&[3])
        .with_poses(poses());
    sole.frame(&frame, 0, &mut out).expect("decodes");
    assert_eq!(out[0].antenna, 3);
    assert!(out[0].antenna_pose.is_some(), "{:?}", out[0]);
    // A reader of several antennas: which one is unknown.
    let mut several = ReadDecoder::new("r".parse().ok())
        .with_antennas(&[1, 3])
        .with_poses(poses());
    out.clear();
    several.frame(&frame, 0, &mut out).expect("decodes");
    assert_eq!((out[0].antenna, out[0].antenna_pose), (0, None));
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
fn a_truncated_epc_of_any_bit_length_is_its_bytes_with_the_spare_bits_cleared() {
    use llrp::codec::BitVec;
    use llrp::message::RoAccessReport;
    use llrp::params::{Epc, EpcData, TagReportData};
    // A reader may leave anything in the bits past the count: they are not the EPC's.
    let data = |bits: u16, bytes: &[u8]| TagReportData {
        epc: Epc::EpcData(EpcData {
            epc: BitVec {
                bits,
                bytes: bytes.to_vec(),
            },
            ..Default::default()
        }),
        ..Default::default()
    };
    let frame = Message::new(
        1,
        RoAccessReport {
            tag_report_data: vec![
                // 76 bits (an EPC-96 truncated after 20): 10 bytes, the last 4 bits spare.
                data(76, &[0, 0, 0, 0, 0, 0, 0, 0, 0, 0x7F]),
                // 13 bits: 2 bytes, 3 spare; 8 bits: 1 byte, none.
                data(13, &[0xAB, 0xFF]),
                data(8, &[0xAB]),
            ],
            ..Default::default()
        },
    )
    .to_bytes();
    let mut out = Vec::new();
    ReadDecoder::new(None)
        .frame(&frame, 0, &mut out)
        .expect("decodes");
    let epcs: Vec<&str> = out.iter().map(|r| r.epc.as_str()).collect();
    assert_eq!(epcs, ["00000000000000000070", "ABF8", "AB"]);
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
    assert_eq!(p, Pose::from_degrees([1.0, 2.0, 0.5], 90.0, 0.0));
    assert_eq!((p.yaw_rad, p.pitch_rad), (std::f64::consts::FRAC_PI_2, 0.0));
    let bad = br#"{"epc":"AB","antenna":1,"t_us":5,"phase_rad":0.5,"rssi_dbm":null,"antenna_pose":{"x":1,"y":2}}"#;
    let e = read_jsonl(&bad[..]).expect_err("z missing");
    assert!(
        e.message.contains("antenna_pose") && e.message.contains('z'),
        "{}",
        e.message
    );
}

#[test]
fn a_reads_file_reader_is_a_reader_name_or_none() {
    let line = |reader: &str| {
        format!(
            r#"{{"epc":"AB","reader":{reader},"antenna":1,"t_us":5,"phase_rad":0.5,"rssi_dbm":null}}"#
        )
    };
    let r = read_jsonl(line(r#""dock 1""#).as_bytes()).expect("parses");
    assert_eq!(r[0].reader.as_deref(), Some("dock 1"));
    let r = read_jsonl(line(r#""""#).as_bytes()).expect("parses");
    assert_eq!(r[0].reader, None, "empty: unknown");
    let e = read_jsonl(line(r#"" dock""#).as_bytes()).expect_err("white space");
    assert!(
        e.message
            .starts_with("reader: reader name \" dock\" starts or ends with white space"),
        "{}",
        e.message
    );
}
