//! EPCs of any Gen2 length: a 96-bit tag is reported with the EPC-96 parameter, a 128-bit and
//! a 64-bit one with EPCData of their bit count; the C1G2-PC word carries each EPC's length in
//! words and the C1G2-CRC covers the whole EPC; C1G2TagSpec matching and C1G2Read work on the
//! EPC bank of a 128-bit tag; the project's read decoder prints the long EPCs. Driven in
//! process with a virtual clock (tests/common/virtual_reader.rs).

mod common;

use common::virtual_reader::VirtualReader;
use common::*;
use llrp::codec::BitVec;
use llrp::message::*;
use llrp::params::*;
use llrp::Message;
use llrp_gateway::reader::report::gen2_crc;
use llrp_gateway::reads::ReadDecoder;
use llrp_gateway::scenario::Scenario;

/// The 96-bit tag's EPC.
const EPC96: &str = "E20000000000000000000001";
/// The 128-bit tag's EPC.
const EPC128: &str = "E2801160600002093F4A3B1C0000AA02";
/// The 64-bit tag's EPC.
const EPC64: &str = "E2000000000000B3";

fn bytes(hex: &str) -> Vec<u8> {
    (0..hex.len() / 2)
        .map(|i| u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).expect("hex"))
        .collect()
}

/// [`line_scenario`]'s antenna with a 96-, a 128- and a 64-bit tag at 1.0, 1.2 and 1.4 m,
/// passed through the scenario loader (and so its validator) again.
fn mixed_lengths() -> Scenario {
    let mut s = line_scenario(&[1.0, 1.2, 1.4]);
    for (t, epc) in s.tags.iter_mut().zip([EPC96, EPC128, EPC64]) {
        t.epc = epc.into();
    }
    let json = serde_json::to_string(&s).expect("a scenario serialises");
    Scenario::from_json(&json).expect("EPCs of 64, 96 and 128 bits are valid")
}

/// Starts an inventory on antenna 1 reporting every read (N = 1) with the given standard
/// selector.
fn start_inventory(v: &mut VirtualReader, selector: TagReportContentSelector) {
    let report =
        RoReportSpec::new(RoReportTriggerType::UponNTagsOrEndOfAiSpec, 1).with_content(selector);
    let spec = rospec(1, vec![1], ro_null(), ai_null(), report);
    assert_eq!(
        v.status(AddRospec {
            ro_spec: spec,
            ..Default::default()
        }),
        StatusCode::M_Success
    );
    assert_eq!(
        v.status(EnableRospec {
            ro_spec_id: 1,
            ..Default::default()
        }),
        StatusCode::M_Success
    );
}

/// The first report of each of the three tags, in the order 96, 128, 64 bits.
fn one_of_each(tags: &[TagReportData]) -> [&TagReportData; 3] {
    [EPC96, EPC128, EPC64].map(|hex| {
        let epc = bytes(hex);
        tags.iter()
            .find(|t| t.epc_bytes() == epc.as_slice())
            .unwrap_or_else(|| panic!("no read of {hex} in {} reads", tags.len()))
    })
}

fn seen_all(tags: &[TagReportData]) -> bool {
    [EPC96, EPC128, EPC64]
        .iter()
        .all(|hex| tags.iter().any(|t| t.epc_bytes() == bytes(hex).as_slice()))
}

#[test]
fn a_96_bit_epc_goes_out_as_epc_96_and_others_as_epc_data_with_pc_and_crc() {
    let mut v = VirtualReader::new(&mixed_lengths());
    start_inventory(
        &mut v,
        TagReportContentSelector {
            air_protocol_epc_memory_selector: vec![C1g2EpcMemorySelector {
                enable_pc_bits: true,
                enable_crc: true,
                ..Default::default()
            }],
            ..Default::default()
        },
    );
    let (tags, _) = v.collect_reports(600_000_000, seen_all);
    let [t96, t128, t64] = one_of_each(&tags);
    assert_eq!(
        t96.epc,
        Epc::Epc96(Epc96(bytes(EPC96).try_into().expect("12 bytes")))
    );
    for (t, hex, bits) in [(t128, EPC128, 128), (t64, EPC64, 64)] {
        let Epc::EpcData(d) = &t.epc else {
            panic!("{hex} was not reported as EPCData: {:?}", t.epc)
        };
        assert_eq!((d.epc.bits, &d.epc.bytes), (bits, &bytes(hex)), "{hex}");
    }
    // PC bits 15–11 are the length in words: 6, 8 and 4.
    for (t, hex, want_pc) in [
        (t96, EPC96, 0x3000),
        (t128, EPC128, 0x4000),
        (t64, EPC64, 0x2000),
    ] {
        let pc = t.air_protocol_tag_data.iter().find_map(|p| match p {
            AirProtocolTagData::C1g2Pc(pc) => Some(pc.0),
            _ => None,
        });
        let crc = t.air_protocol_tag_data.iter().find_map(|p| match p {
            AirProtocolTagData::C1g2Crc(crc) => Some(crc.0),
            _ => None,
        });
        assert_eq!(pc, Some(want_pc), "{hex}: the PC's length field");
        assert_eq!(
            crc,
            Some(gen2_crc(want_pc, &bytes(hex))),
            "{hex}: CRC of PC and EPC"
        );
    }
}

#[test]
fn the_read_decoder_prints_epcs_of_every_length() {
    let mut v = VirtualReader::new(&mixed_lengths());
    start_inventory(&mut v, TagReportContentSelector::all());
    let (tags, _) = v.collect_reports(600_000_000, seen_all);
    let frame = Message::new(
        1,
        RoAccessReport {
            tag_report_data: tags,
            ..Default::default()
        },
    )
    .to_bytes();
    let mut reads = Vec::new();
    ReadDecoder::new(None)
        .frame(&frame, 0, &mut reads)
        .expect("the reader's report decodes");
    for hex in [EPC96, EPC128, EPC64] {
        assert!(reads.iter().any(|r| r.epc == hex), "no read of {hex}");
    }
}

/// The first TagReportData with access results of an inventory on antenna 1 with an
/// AccessSpec (ID 9) that reads the whole EPC bank (OpSpec ID 5) of the tags `target` selects.
fn read_epc_bank(s: &Scenario, target: C1g2TargetTag) -> (TagReportData, Vec<TagReportData>) {
    let mut v = VirtualReader::new(s);
    let access = AccessSpec {
        access_spec_id: 9,
        protocol_id: AirProtocol::EpcGlobalClass1Gen2,
        access_command: AccessCommand {
            c1g2_tag_spec: C1g2TagSpec {
                c1g2_target_tag: vec![target],
                ..Default::default()
            },
            op_specs: vec![OpSpec::C1g2Read(C1g2Read {
                op_spec_id: 5,
                mb: 1,
                word_pointer: 0,
                word_count: 0,
                ..Default::default()
            })],
            ..Default::default()
        },
        ..Default::default()
    };
    v.add_access_spec(access);
    start_inventory(&mut v, TagReportContentSelector::all());
    let (tags, _) = v.collect_reports(600_000_000, |t| {
        seen_all(t) && t.iter().any(|r| !r.op_spec_results.is_empty())
    });
    let hit = tags
        .iter()
        .find(|t| !t.op_spec_results.is_empty())
        .cloned()
        .expect("the tag spec selected no tag: no access results");
    (hit, tags)
}

#[test]
fn a_c1g2_read_of_the_epc_bank_of_a_128_bit_tag_gives_crc_pc_and_eight_words() {
    // Select by the last 32 bits of the 128-bit EPC: EPC bank bits 32 + 96 onwards, beyond
    // where a 96-bit EPC ends.
    let target = C1g2TargetTag {
        mb: 1,
        is_match: true,
        pointer: 32 + 96,
        tag_mask: BitVec::from_bytes(&[0xFF; 4]),
        tag_data: BitVec::from_bytes(&[0x00, 0x00, 0xAA, 0x02]),
        ..Default::default()
    };
    let (t, tags) = read_epc_bank(&mixed_lengths(), target);
    assert_eq!(t.epc_bytes(), bytes(EPC128).as_slice());
    for other in tags.iter().filter(|t| t.epc_bytes() != bytes(EPC128)) {
        assert!(
            other.op_spec_results.is_empty(),
            "the tag spec selected {:?}",
            other.epc
        );
    }
    let Some(OpSpecResult::C1g2Read(r)) = t.op_spec_results.first() else {
        panic!("no read result in {t:?}")
    };
    assert_eq!((r.result, r.op_spec_id), (0, 5));
    let epc = bytes(EPC128);
    let pc = 0x4000; // 8 words
    let mut want = vec![gen2_crc(pc, &epc), pc];
    want.extend(epc.chunks(2).map(|c| u16::from_be_bytes([c[0], c[1]])));
    assert_eq!(r.read_data, want, "CRC, PC, then the EPC's 8 words");
}
