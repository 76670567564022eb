//! Tag memory access as an encoding station uses it: C1G2 Write, BlockWrite, BlockErase, Lock
//! and Kill on the simulated reader, with the result codes of LLRP 1.0.1 and 1.1 for every
//! failure, what later inventories report after an EPC write or a kill, and the status a bad
//! Lock payload gets. Driven in process with a virtual clock (tests/common/virtual_reader.rs).

mod common;

use common::virtual_reader::VirtualReader;
use common::*;
use llrp::codec::BitVec;
use llrp::params::*;
use llrp_gateway::scenario::Scenario;

/// Runs an inventory on antenna 1 with an AccessSpec (ID `id`, deleted after one execution)
/// of `ops` on the tags whose EPC ends in `last` (their last EPC byte); gives the results of
/// the first tag report that carries any, then stops and deletes the ROSpec.
fn access(v: &mut VirtualReader, id: u32, last: u8, ops: Vec<OpSpec>) -> Vec<OpSpecResult> {
    let access = AccessSpec {
        access_spec_id: id,
        protocol_id: AirProtocol::EpcGlobalClass1Gen2,
        access_spec_stop_trigger: AccessSpecStopTrigger {
            access_spec_stop_trigger_type: AccessSpecStopTriggerType::OperationCount,
            operation_count_value: 1,
            ..Default::default()
        },
        access_command: AccessCommand {
            c1g2_tag_spec: last_byte_is(last),
            op_specs: ops,
            ..Default::default()
        },
        ..Default::default()
    };
    v.add_access_spec(access);
    let tags = inventory(v, |t| t.iter().any(|t| !t.op_spec_results.is_empty()));
    tags.into_iter()
        .find(|t| !t.op_spec_results.is_empty())
        .map(|t| t.op_spec_results)
        .expect("a tag report with the operations' results")
}

/// A C1G2TagSpec matching EPC-96s whose last byte is `last` (bits 168–175 of EPC memory).
fn last_byte_is(last: u8) -> C1g2TagSpec {
    C1g2TagSpec {
        c1g2_target_tag: vec![C1g2TargetTag {
            mb: 1,
            is_match: true,
            pointer: 32 + 88,
            tag_mask: BitVec::from_bytes(&[0xFF]),
            tag_data: BitVec::from_bytes(&[last]),
            ..Default::default()
        }],
        ..Default::default()
    }
}

/// Runs ROSpec 1 on antenna 1 until `done` (at most 10 simulated seconds), then deletes it;
/// its reports carry every field, the PC word too.
fn inventory(
    v: &mut VirtualReader,
    done: impl FnMut(&[TagReportData]) -> bool,
) -> Vec<TagReportData> {
    let mut report = full_report(RoReportTriggerType::UponNTagsOrEndOfAiSpec, 1);
    report
        .tag_report_content_selector
        .air_protocol_epc_memory_selector = vec![C1g2EpcMemorySelector {
        enable_crc: true,
        enable_pc_bits: true,
        ..Default::default()
    }];
    let spec = rospec(1, vec![1], ro_null(), ai_null(), report);
    v.run_rospec(spec, 10_000_000, done)
}

/// Two tags 1 and 1.2 m in front of the antenna (EPCs ending 01 and 02); the first with kill
/// password 12345678 and access password 0000ABCD.
fn scenario() -> Scenario {
    let mut s = line_scenario(&[1.0, 1.2]);
    s.tags[0].kill_password = Some("12345678".into());
    s.tags[0].access_password = Some("0000ABCD".into());
    s
}

fn write(op_spec_id: u16, mb: u8, word_pointer: u16, data: &[u16], password: u32) -> OpSpec {
    OpSpec::C1g2Write(C1g2Write {
        op_spec_id,
        access_password: password,
        mb,
        word_pointer,
        write_data: data.to_vec(),
        ..Default::default()
    })
}

fn read(op_spec_id: u16, mb: u8, word_pointer: u16, word_count: u16, password: u32) -> OpSpec {
    OpSpec::C1g2Read(C1g2Read {
        op_spec_id,
        access_password: password,
        mb,
        word_pointer,
        word_count,
        ..Default::default()
    })
}

fn lock(privilege: u8, data_field: u8, password: u32) -> OpSpec {
    OpSpec::C1g2Lock(C1g2Lock {
        op_spec_id: 3,
        access_password: password,
        c1g2_lock_payload: vec![C1g2LockPayload {
            privilege,
            data_field,
            ..Default::default()
        }],
        ..Default::default()
    })
}

/// (result, words written) of a Write result; (result, data) of a Read's, as text.
fn outcome(r: &OpSpecResult) -> String {
    match r {
        OpSpecResult::C1g2Write(w) => format!("write {} {}", w.result, w.num_words_written),
        OpSpecResult::C1g2BlockWrite(w) => {
            format!("blockwrite {} {}", w.result, w.num_words_written)
        }
        OpSpecResult::C1g2Read(r) => format!("read {} {:04X?}", r.result, r.read_data),
        OpSpecResult::C1g2Lock(l) => format!("lock {}", l.result),
        OpSpecResult::C1g2Kill(k) => format!("kill {}", k.result),
        OpSpecResult::C1g2BlockErase(e) => format!("erase {}", e.result),
        other => format!("{other:?}"),
    }
}

fn outcomes(r: &[OpSpecResult]) -> Vec<String> {
    r.iter().map(outcome).collect()
}

#[test]
fn user_memory_written_once_reads_back_in_a_later_inventory() {
    let mut v = VirtualReader::new(&scenario());
    let w = access(&mut v, 1, 2, vec![write(1, 3, 0, &[0xBEEF, 0xCAFE], 0)]);
    assert_eq!(outcomes(&w), ["write 0 2"]);
    let r = access(&mut v, 2, 2, vec![read(2, 3, 0, 3, 0)]);
    assert_eq!(outcomes(&r), ["read 0 [BEEF, CAFE, 0000]"]);
    // The other tag's memory is its own.
    let r = access(&mut v, 3, 1, vec![read(2, 3, 0, 2, 0)]);
    assert_eq!(outcomes(&r), ["read 0 [0000, 0000]"]);
}

#[test]
fn writing_the_epc_bank_changes_what_later_inventories_report() {
    let mut v = VirtualReader::new(&scenario());
    // PC word: 4 words of EPC; then the new 64-bit EPC.
    // (The user-memory indicator, bit 10, set too: the PC is reported as written.)
    let data = [0x2400, 0x1111, 0x2222, 0x3333, 0x4444];
    let w = access(&mut v, 1, 2, vec![write(1, 1, 1, &data, 0)]);
    assert_eq!(outcomes(&w), ["write 0 5"]);
    let tags = inventory(&mut v, |t| t.len() >= 20);
    let epcs: std::collections::BTreeSet<Vec<u8>> =
        tags.iter().map(|t| t.epc_bytes().to_vec()).collect();
    let new = vec![0x11, 0x11, 0x22, 0x22, 0x33, 0x33, 0x44, 0x44];
    assert!(epcs.contains(&new), "{epcs:02X?}");
    assert!(
        !epcs.iter().any(|e| e.last() == Some(&2) && e.len() == 12),
        "{epcs:02X?}"
    );
    // The PC word reported is the one written.
    let pc = tags
        .iter()
        .find(|t| t.epc_bytes() == new.as_slice())
        .and_then(|t| {
            t.air_protocol_tag_data.iter().find_map(|d| match d {
                AirProtocolTagData::C1g2Pc(p) => Some(p.0),
                _ => None,
            })
        });
    assert_eq!(pc, Some(0x2400));
    // Writing the StoredCRC is refused by the tag.
    let w = access(&mut v, 2, 1, vec![write(1, 1, 0, &[0], 0)]);
    assert_eq!(outcomes(&w), ["write 4 0"]);
}

#[test]
fn a_killed_tag_is_never_reported_again() {
    let mut v = VirtualReader::new(&scenario());
    let kill = |password| {
        OpSpec::C1g2Kill(C1g2Kill {
            op_spec_id: 4,
            kill_password: password,
            ..Default::default()
        })
    };
    // A wrong kill password: the tag does not reply (LLRP 1.0.1 has no password code).
    assert_eq!(
        outcomes(&access(&mut v, 1, 1, vec![kill(0x1234_0000)])),
        ["kill 4"]
    );
    // The second tag's kill password is 0: it does not kill.
    assert_eq!(
        outcomes(&access(&mut v, 2, 2, vec![kill(0x1234_5678)])),
        ["kill 1"]
    );
    assert_eq!(
        outcomes(&access(&mut v, 3, 1, vec![kill(0x1234_5678)])),
        ["kill 0"]
    );
    let tags = inventory(&mut v, |t| t.len() >= 30);
    assert!(tags.len() >= 30);
    assert!(
        tags.iter().all(|t| t.epc_bytes().last() == Some(&2)),
        "the killed tag answered"
    );
}

#[test]
fn a_locked_bank_needs_the_access_password_and_says_why_in_llrp_1_1() {
    let mut v = VirtualReader::new(&scenario());
    v.set_version(2);
    // Tag 1 has access password 0000ABCD: without it the tag stays open and ignores Lock.
    assert_eq!(
        outcomes(&access(&mut v, 1, 1, vec![lock(0, 4, 0)])),
        ["lock 3"]
    );
    assert_eq!(
        outcomes(&access(&mut v, 2, 1, vec![lock(0, 4, 0x1111)])),
        ["lock 5"]
    );
    assert_eq!(
        outcomes(&access(&mut v, 3, 1, vec![lock(0, 4, 0xABCD)])),
        ["lock 0"]
    );
    let r = access(
        &mut v,
        4,
        1,
        vec![write(1, 3, 0, &[1], 0), write(2, 3, 0, &[1], 0xABCD)],
    );
    // The first write fails on the locked bank, which ends the sequence.
    assert_eq!(outcomes(&r), ["write 2 0"]);
    let r = access(&mut v, 5, 1, vec![write(2, 3, 0, &[1], 0xABCD)]);
    assert_eq!(outcomes(&r), ["write 0 1"]);
    let r = access(&mut v, 6, 1, vec![write(2, 3, 0, &[1], 0x1111)]);
    assert_eq!(outcomes(&r), ["write 7 0"]);
    // The access password itself, read-locked, reads only with it.
    assert_eq!(
        outcomes(&access(&mut v, 7, 1, vec![lock(0, 1, 0xABCD)])),
        ["lock 0"]
    );
    assert_eq!(
        outcomes(&access(&mut v, 8, 1, vec![read(1, 0, 2, 2, 0)])),
        ["read 5 []"]
    );
    let r = access(&mut v, 9, 1, vec![read(1, 0, 0, 4, 0xABCD)]);
    assert_eq!(outcomes(&r), ["read 0 [1234, 5678, 0000, ABCD]"]);
}

#[test]
fn permalocked_memory_stays_locked() {
    let mut v = VirtualReader::new(&scenario());
    v.set_version(2);
    assert_eq!(
        outcomes(&access(&mut v, 1, 2, vec![lock(1, 4, 0)])),
        ["lock 0"]
    );
    assert_eq!(
        outcomes(&access(&mut v, 2, 2, vec![lock(3, 4, 0)])),
        ["lock 7"]
    );
    assert_eq!(
        outcomes(&access(&mut v, 3, 2, vec![write(1, 3, 0, &[1], 0)])),
        ["write 2 0"]
    );
    // TID memory ships permalocked.
    assert_eq!(
        outcomes(&access(&mut v, 4, 2, vec![write(1, 2, 0, &[1], 0)])),
        ["write 2 0"]
    );
}

#[test]
fn words_beyond_a_bank_overrun_in_both_versions() {
    let mut v = VirtualReader::new(&scenario());
    // 32 words of user memory (the default chip): the last word is 31.
    let r = access(&mut v, 1, 2, vec![write(1, 3, 31, &[7, 8], 0)]);
    assert_eq!(outcomes(&r), ["write 1 1"]);
    let r = access(&mut v, 2, 2, vec![read(1, 3, 40, 1, 0)]);
    assert_eq!(outcomes(&r), ["read 1 []"]);
    v.set_version(2);
    let r = access(&mut v, 3, 2, vec![read(1, 3, 40, 1, 0)]);
    assert_eq!(outcomes(&r), ["read 4 []"]);
    let erase = OpSpec::C1g2BlockErase(C1g2BlockErase {
        op_spec_id: 1,
        mb: 3,
        word_pointer: 30,
        word_count: 4,
        ..Default::default()
    });
    assert_eq!(outcomes(&access(&mut v, 4, 2, vec![erase])), ["erase 1"]);
    let block = OpSpec::C1g2BlockWrite(C1g2BlockWrite {
        op_spec_id: 1,
        mb: 3,
        word_pointer: 0,
        write_data: vec![9, 9, 9],
        ..Default::default()
    });
    let r = access(&mut v, 5, 2, vec![block, read(2, 3, 0, 3, 0)]);
    assert_eq!(
        outcomes(&r),
        ["blockwrite 0 3", "read 0 [0009, 0009, 0009]"]
    );
}

#[test]
fn a_lock_payload_out_of_range_is_refused_with_the_field_named() {
    let mut v = VirtualReader::new(&scenario());
    for (payload, field) in [(lock(4, 2, 0), 0), (lock(0, 5, 0), 1)] {
        let add = llrp::message::AddAccessspec {
            access_spec: AccessSpec {
                access_spec_id: 1,
                protocol_id: AirProtocol::EpcGlobalClass1Gen2,
                access_command: AccessCommand {
                    c1g2_tag_spec: last_byte_is(1),
                    op_specs: vec![payload],
                    ..Default::default()
                },
                ..Default::default()
            },
            ..Default::default()
        };
        let answer = v.request(add);
        let status = answer.body.status().expect("a response");
        assert_eq!(status.status_code, StatusCode::M_ParameterError);
        // AccessSpec → AccessCommand → C1G2Lock → C1G2LockPayload, field `field` out of range.
        let mut chain = Vec::new();
        let mut pe = status.parameter_error.as_ref();
        while let Some(p) = pe {
            chain.push(p.parameter_type);
            if let Some(fe) = &p.field_error {
                assert_eq!(
                    (fe.field_num, fe.error_code),
                    (field, StatusCode::A_OutOfRange)
                );
            }
            pe = p.parameter_error.as_deref();
        }
        assert_eq!(chain, [207, 209, 344, 345]);
    }
}

#[test]
fn a_marginal_tag_reads_but_fails_writes_for_want_of_power() {
    // At 15 dBm: 1 m is well inside the read zone; 2 m reads with a margin short of the
    // 2.8 dB more a write needs (Monza 4: −19.5 dBm to read, −16.7 dBm to write).
    let mut s = line_scenario(&[1.0, 2.0]);
    s.readers[0].antennas[0].tx_power_dbm = 15.0;
    let mut v = VirtualReader::new(&s);
    let every_tag = C1g2TagSpec {
        c1g2_target_tag: vec![C1g2TargetTag {
            mb: 1,
            is_match: true,
            ..Default::default()
        }],
        ..Default::default()
    };
    v.add_access_spec(AccessSpec {
        access_spec_id: 9,
        protocol_id: AirProtocol::EpcGlobalClass1Gen2,
        access_command: AccessCommand {
            c1g2_tag_spec: every_tag,
            op_specs: vec![write(1, 3, 0, &[0x1234, 0x5678], 0)],
            ..Default::default()
        },
        ..Default::default()
    });
    let mut seen = 0;
    let tags = inventory(&mut v, |t| {
        seen += t.len();
        seen >= 150
    });
    let results = |last: u8| -> Vec<String> {
        tags.iter()
            .filter(|t| t.epc_bytes().last() == Some(&last))
            .flat_map(|t| outcomes(&t.op_spec_results))
            .collect()
    };
    let near = results(1);
    assert!(near.len() >= 20, "{near:?}");
    assert!(near.iter().all(|o| o == "write 0 2"), "{near:?}");
    let far = results(2);
    assert!(far.len() >= 20, "the far tag reads: {far:?}");
    let short = far.iter().filter(|o| o.starts_with("write 3 ")).count();
    let done = far.iter().filter(|o| *o == "write 0 2").count();
    assert!(
        short > 2 * done,
        "Insufficient_Power {short}, Success {done}: {far:?}"
    );
    // A failed Write has written the words before the failure only; a lost tag gives
    // No_Response_From_Tag; no other code.
    assert!(
        far.iter().all(|o| [
            "write 0 2",
            "write 3 0",
            "write 3 1",
            "write 5 0",
            "write 5 1"
        ]
        .contains(&o.as_str())),
        "{far:?}"
    );
}

/// Runs ROSpec 1 on antenna 1 with report trigger None (reads wait for GET_REPORT) for one
/// simulated second with AccessSpec 5 (a Read of user word 0 on every tag, its own
/// AccessReportSpec `own`, the reader's default `default`); gives the RO_ACCESS_REPORTs'
/// tag reports that arrived meanwhile.
fn unasked_reports(
    own: Option<AccessReportTriggerType>,
    default: AccessReportTriggerType,
) -> Vec<TagReportData> {
    let mut v = VirtualReader::new(&scenario());
    let config = llrp::message::SetReaderConfig {
        access_report_spec: Some(AccessReportSpec {
            access_report_trigger: default,
            ..Default::default()
        }),
        ..Default::default()
    };
    assert_eq!(v.status(config), StatusCode::M_Success);
    v.add_access_spec(AccessSpec {
        access_spec_id: 5,
        protocol_id: AirProtocol::EpcGlobalClass1Gen2,
        access_command: AccessCommand {
            c1g2_tag_spec: last_byte_is(1),
            op_specs: vec![read(1, 3, 0, 1, 0)],
            ..Default::default()
        },
        access_report_spec: own.map(|t| AccessReportSpec {
            access_report_trigger: t,
            ..Default::default()
        }),
        ..Default::default()
    });
    let report = full_report(RoReportTriggerType::None, 0);
    v.run_rospec(
        rospec(1, vec![1], ro_null(), ai_null(), report),
        1_000_000,
        |_| false,
    )
}

#[test]
fn access_results_are_reported_at_once_with_end_of_accessspec() {
    use AccessReportTriggerType::{EndOfAccessSpec, WheneverRoReportIsGenerated};
    // The reader's default: with the ROSpec's reports, which wait for GET_REPORT here.
    assert!(unasked_reports(None, WheneverRoReportIsGenerated).is_empty());
    // End of AccessSpec, set on the reader or on the AccessSpec: each tag's results come at
    // once, in a report of their own, carrying only the accessed tag and its results.
    for (own, default) in [
        (None, EndOfAccessSpec),
        (Some(EndOfAccessSpec), WheneverRoReportIsGenerated),
    ] {
        let tags = unasked_reports(own, default);
        assert!(tags.len() >= 5, "{} reports", tags.len());
        assert!(tags.iter().all(|t| t.epc_bytes().last() == Some(&1)
            && t.access_spec_id == Some(AccessSpecId(5))
            && outcomes(&t.op_spec_results) == ["read 0 [0000]"]));
    }
    // The AccessSpec's own spec wins over the reader's.
    assert!(unasked_reports(Some(WheneverRoReportIsGenerated), EndOfAccessSpec).is_empty());
}

/// Reads of the tag whose EPC ends in `last` in two simulated seconds of ROSpec 1 on
/// antenna 1 (a report per read).
fn reads_in_two_seconds(v: &mut VirtualReader, last: u8) -> usize {
    let report = full_report(RoReportTriggerType::UponNTagsOrEndOfAiSpec, 1);
    let spec = rospec(1, vec![1], ro_null(), ai_null(), report);
    v.run_rospec(spec, 2_000_000, |_| false)
        .iter()
        .filter(|t| t.epc_bytes().last() == Some(&last))
        .count()
}

#[test]
fn killed_tags_spend_no_air_time_so_the_rest_are_read_more_often() {
    let distances: Vec<f64> = (0..12).map(|i| 1.0 + 0.05 * f64::from(i)).collect();
    let mut s = line_scenario(&distances);
    for t in &mut s.tags {
        t.kill_password = Some("12345678".into());
    }
    let mut v = VirtualReader::new(&s);
    let crowded = reads_in_two_seconds(&mut v, 1);
    // Kill the other eleven: an AccessSpec on every tag but the first, eleven times.
    let mut others = last_byte_is(1);
    others.c1g2_target_tag[0].is_match = false;
    v.add_access_spec(AccessSpec {
        access_spec_id: 7,
        protocol_id: AirProtocol::EpcGlobalClass1Gen2,
        access_spec_stop_trigger: AccessSpecStopTrigger {
            access_spec_stop_trigger_type: AccessSpecStopTriggerType::OperationCount,
            operation_count_value: 11,
            ..Default::default()
        },
        access_command: AccessCommand {
            c1g2_tag_spec: others,
            op_specs: vec![OpSpec::C1g2Kill(C1g2Kill {
                op_spec_id: 1,
                kill_password: 0x1234_5678,
                ..Default::default()
            })],
            ..Default::default()
        },
        ..Default::default()
    });
    let mut killed = 0;
    inventory(&mut v, |t| {
        killed = t
            .iter()
            .flat_map(|t| outcomes(&t.op_spec_results))
            .filter(|o| o == "kill 0")
            .count();
        killed >= 11
    });
    assert_eq!(killed, 11);
    let alone = reads_in_two_seconds(&mut v, 1);
    assert!(
        alone * 10 > crowded * 15,
        "the last live tag: {crowded} reads among 12, {alone} once the rest are killed"
    );
}

/// With an AccessSpec reading user word 0 of the tag whose EPC ends in 01, stopped by
/// `trigger` (OperationCountValue `count`): the reads of that tag that carry its results in
/// 40 reads of the tag, and the AccessSpecs left afterwards.
fn with_stop_trigger(trigger: AccessSpecStopTriggerType, count: u16) -> (usize, usize) {
    let mut v = VirtualReader::new(&scenario());
    v.add_access_spec(AccessSpec {
        access_spec_id: 4,
        protocol_id: AirProtocol::EpcGlobalClass1Gen2,
        access_spec_stop_trigger: AccessSpecStopTrigger {
            access_spec_stop_trigger_type: trigger,
            operation_count_value: count,
            ..Default::default()
        },
        access_command: AccessCommand {
            c1g2_tag_spec: last_byte_is(1),
            op_specs: vec![read(1, 3, 0, 1, 0)],
            ..Default::default()
        },
        ..Default::default()
    });
    let first = |t: &&TagReportData| t.epc_bytes().last() == Some(&1);
    let tags = inventory(&mut v, |t| t.iter().filter(first).count() >= 40);
    let carried = tags
        .iter()
        .filter(first)
        .filter(|t| !t.op_spec_results.is_empty())
        .count();
    let m = v.request(llrp::message::GetAccessspecs::default());
    let llrp::MessageBody::GetAccessspecsResponse(r) = &m.body else {
        panic!("expected GET_ACCESSSPECS_RESPONSE, got {m:?}")
    };
    (carried, r.access_specs.len())
}

#[test]
fn an_operation_count_stop_trigger_runs_the_accessspec_that_often_then_deletes_it() {
    use AccessSpecStopTriggerType::{Null, OperationCount};
    assert_eq!(with_stop_trigger(OperationCount, 3), (3, 0));
    // No stop trigger: every read of the tag runs it, and it stays.
    let (carried, left) = with_stop_trigger(Null, 3);
    assert!(carried >= 40, "{carried} of 40 reads ran it");
    assert_eq!(left, 1);
}
