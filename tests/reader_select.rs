//! C1G2Filter (the Gen2 Select) on the simulated reader, in process on a virtual clock: only
//! the tags the filters leave take part in the rounds, so in a crowd the matching tag is read
//! more often than without a filter; masks on the EPC, TID and user banks against the tags'
//! memory as written; the state-unaware and state-aware actions; two filters in order; the
//! reader configuration's filters; the filters echoed by GET_ROSPECS and GET_READER_CONFIG;
//! truncation (T = 2): the EPC bits after the mask in EPCData, shorter replies; and the
//! status each kind of bad filter gets.

mod common;

use std::collections::BTreeMap;

use common::virtual_reader::VirtualReader;
use common::*;
use llrp::codec::BitVec;
use llrp::message::*;
use llrp::params::*;
use llrp_gateway::scenario::Scenario;

/// `n` tags 1.0–1.6 m before the antenna (EPCs E200…01 to E200…`n`), each with user memory
/// 00`k` 0000 and TID E280 1160 0000 00`k`.
fn crowd(n: usize) -> Scenario {
    let distances: Vec<f64> = (0..n).map(|k| 1.0 + 0.6 * k as f64 / n as f64).collect();
    let mut s = line_scenario(&distances);
    for (k, t) in s.tags.iter_mut().enumerate() {
        t.user = Some(format!("{:04X}0000", k + 1));
        t.tid = Some(format!("E28011600000{:04X}", k + 1));
    }
    s
}

fn mask(mb: u8, pointer: u16, bytes: &[u8]) -> C1g2TagInventoryMask {
    C1g2TagInventoryMask {
        mb,
        pointer,
        tag_mask: BitVec::from_bytes(bytes),
        ..Default::default()
    }
}

/// The EPC's last byte is `last`: bits 20h + 88 to 20h + 95 of the EPC bank.
fn last_is(last: u8) -> C1g2TagInventoryMask {
    mask(1, 0x20 + 88, &[last])
}

/// A state-unaware filter (`None`: no action parameter, as sllurp sends it).
fn unaware(m: C1g2TagInventoryMask, action: Option<u8>) -> C1g2Filter {
    C1g2Filter {
        c1g2_tag_inventory_mask: m,
        state_unaware_action: action.map(|action| C1g2TagInventoryStateUnawareFilterAction {
            action,
            ..Default::default()
        }),
        ..Default::default()
    }
}

fn aware(m: C1g2TagInventoryMask, target: u8, action: u8) -> C1g2Filter {
    C1g2Filter {
        c1g2_tag_inventory_mask: m,
        state_aware_action: Some(C1g2TagInventoryStateAwareFilterAction {
            target,
            action,
            ..Default::default()
        }),
        ..Default::default()
    }
}

/// `f` truncating (C1G2Filter T = 2).
fn truncating(f: C1g2Filter) -> C1g2Filter {
    C1g2Filter { t: 2, ..f }
}

fn command(filters: Vec<C1g2Filter>) -> C1g2InventoryCommand {
    C1g2InventoryCommand {
        c1g2_filter: filters,
        ..Default::default()
    }
}

fn on_all_antennas(cmd: C1g2InventoryCommand) -> Vec<AntennaConfiguration> {
    vec![AntennaConfiguration {
        antenna_id: 0,
        c1g2_inventory_command: vec![cmd],
        ..Default::default()
    }]
}

/// ROSpec 1 on antenna 1 for `ms` (reported once at its end), with `cmd` when given.
fn spec(ms: u32, cmd: Option<C1g2InventoryCommand>) -> RoSpec {
    let report = full_report(RoReportTriggerType::UponNTagsOrEndOfRoSpec, 0);
    let s = rospec(1, vec![1], ro_duration(ms), ai_null(), report);
    match cmd {
        Some(c) => s.with_antenna_configuration(on_all_antennas(c)),
        None => s,
    }
}

/// Adds and enables `spec`, runs it once and deletes it: the reads per EPC's last byte.
fn run(v: &mut VirtualReader, spec: RoSpec) -> BTreeMap<u8, u32> {
    // The ROSpec's end report comes at its end; it restarts at once (Immediate), so it is
    // deleted after its first report.
    let tags = v.run_rospec(spec, 5_000_000, |t| !t.is_empty());
    let mut counts = BTreeMap::new();
    for t in &tags {
        let last = t.epc_bytes().last().copied().unwrap_or(0);
        let n = t.tag_seen_count.map_or(1, |c| u32::from(c.0));
        *counts.entry(last).or_insert(0) += n;
    }
    counts
}

#[test]
fn a_filter_leaves_only_the_matching_tag_in_the_rounds_and_its_read_rate_rises() {
    let s = crowd(30);
    let all = run(&mut VirtualReader::new(&s), spec(2000, None));
    assert_eq!(all.len(), 30, "every tag is read without a filter: {all:?}");
    // sllurp's filter: the EPC bank from 20h, no action parameter (Select/Unselect).
    let filter = command(vec![unaware(last_is(5), None)]);
    let one = run(&mut VirtualReader::new(&s), spec(2000, Some(filter)));
    assert_eq!(one.keys().copied().collect::<Vec<_>>(), [5], "{one:?}");
    // Alone in its rounds it gets far more of them than among thirty.
    assert!(
        one[&5] > 5 * all[&5],
        "{} filtered vs {} not",
        one[&5],
        all[&5]
    );
}

#[test]
fn masks_on_the_tid_and_user_banks_select_by_that_memory() {
    let s = crowd(6);
    let mut v = VirtualReader::new(&s);
    let tid = command(vec![unaware(mask(2, 48, &[0, 3]), Some(0))]);
    assert_eq!(
        run(&mut v, spec(500, Some(tid))).keys().collect::<Vec<_>>(),
        [&3]
    );
    let user = command(vec![unaware(mask(3, 0, &[0, 4]), Some(0))]);
    assert_eq!(
        run(&mut v, spec(500, Some(user)))
            .keys()
            .collect::<Vec<_>>(),
        [&4]
    );
    // The PC word at 10h (3000h for every EPC-96): every tag.
    let pc = command(vec![unaware(mask(1, 0x10, &[0x30, 0x00]), Some(0))]);
    assert_eq!(run(&mut v, spec(500, Some(pc))).len(), 6);
    // A mask past the end of user memory (64 bits here): no tag matches, none is read.
    let past = command(vec![unaware(mask(3, 56, &[0, 0]), Some(0))]);
    assert!(run(&mut v, spec(500, Some(past))).is_empty());
}

#[test]
fn an_epc_written_earlier_filters_as_written() {
    let s = crowd(4);
    let mut v = VirtualReader::new(&s);
    // Tag 2's EPC becomes E200…AA (its last word 00AA), through an AccessSpec on its read.
    let access = AccessSpec {
        access_spec_id: 9,
        protocol_id: AirProtocol::EpcGlobalClass1Gen2,
        access_spec_stop_trigger: AccessSpecStopTrigger {
            access_spec_stop_trigger_type: AccessSpecStopTriggerType::OperationCount,
            operation_count_value: 1,
            ..Default::default()
        },
        access_command: AccessCommand {
            c1g2_tag_spec: C1g2TagSpec {
                c1g2_target_tag: vec![C1g2TargetTag {
                    mb: 1,
                    is_match: true,
                    pointer: 0x20 + 88,
                    tag_mask: BitVec::from_bytes(&[0xFF]),
                    tag_data: BitVec::from_bytes(&[2]),
                    ..Default::default()
                }],
                ..Default::default()
            },
            op_specs: vec![OpSpec::C1g2Write(C1g2Write {
                op_spec_id: 1,
                mb: 1,
                word_pointer: 7,
                write_data: vec![0x00AA],
                ..Default::default()
            })],
            ..Default::default()
        },
        ..Default::default()
    };
    v.add_access_spec(access);
    let before = run(&mut v, spec(500, None));
    assert!(before.contains_key(&0xAA), "the write took: {before:?}");
    let new = command(vec![unaware(last_is(0xAA), Some(0))]);
    assert_eq!(
        run(&mut v, spec(500, Some(new))).keys().collect::<Vec<_>>(),
        [&0xAA]
    );
    let old = command(vec![unaware(last_is(2), Some(0))]);
    assert!(run(&mut v, spec(500, Some(old))).is_empty());
}

#[test]
fn state_unaware_and_state_aware_actions_decide_who_answers() {
    let s = crowd(5);
    let mut v = VirtualReader::new(&s);
    let keys = |m: BTreeMap<u8, u32>| m.into_keys().collect::<Vec<_>>();
    // Unselect/Select: every tag but the matching one (llrpkit's "exclude").
    let exclude = command(vec![unaware(last_is(3), Some(4))]);
    assert_eq!(keys(run(&mut v, spec(500, Some(exclude)))), [1, 2, 4, 5]);
    // Two filters: the EPC's last byte odd AND with bit 2 set (Select/Unselect, then
    // DoNothing/Unselect); OR: Select/DoNothing second.
    let bit = |b: u16| C1g2TagInventoryMask {
        tag_mask: BitVec {
            bits: 1,
            bytes: vec![0x80],
        },
        ..mask(1, 0x20 + 95 - b, &[])
    };
    let and = command(vec![unaware(bit(0), Some(0)), unaware(bit(2), Some(2))]);
    assert_eq!(keys(run(&mut v, spec(500, Some(and)))), [5]);
    let or = command(vec![unaware(bit(0), Some(0)), unaware(bit(2), Some(1))]);
    assert_eq!(keys(run(&mut v, spec(500, Some(or)))), [1, 3, 4, 5]);
    // State-aware on SL (LLRP target 0), Query Sel = SL from the singulation action.
    let singulation = |s: bool, i: bool| C1g2SingulationControl {
        session: 2,
        state_aware_singulation_action: Some(C1g2TagInventoryStateAwareSingulationAction {
            i,
            s,
            ..Default::default()
        }),
        ..Default::default()
    };
    let sl = C1g2InventoryCommand {
        tag_inventory_state_aware: true,
        c1g2_singulation_control: Some(singulation(false, false)),
        ..command(vec![aware(last_is(2), 0, 0)])
    };
    assert_eq!(keys(run(&mut v, spec(500, Some(sl.clone())))), [2]);
    // Sel = not SL: the others.
    let not_sl = C1g2InventoryCommand {
        c1g2_singulation_control: Some(singulation(true, false)),
        ..sl
    };
    assert_eq!(keys(run(&mut v, spec(500, Some(not_sl)))), [1, 3, 4, 5]);
    // On session 2's inventoried flag (LLRP target 3): the matching tag to B, the others to A (action 4), a
    // single-target Query for A in session 2 (Impinj search mode 1).
    let flag = C1g2InventoryCommand {
        tag_inventory_state_aware: true,
        c1g2_singulation_control: Some(singulation(false, false)),
        custom: vec![Custom::ImpinjInventorySearchMode(
            ImpinjInventorySearchMode {
                inventory_search_mode: 1,
                ..Default::default()
            },
        )],
        ..command(vec![aware(last_is(4), 3, 4)])
    };
    // Sel = SL would take none (no tag's SL is asserted): Sel = All instead.
    let flag_all = C1g2InventoryCommand {
        c1g2_singulation_control: Some(C1g2SingulationControl {
            session: 2,
            ..Default::default()
        }),
        ..flag.clone()
    };
    assert!(run(&mut v, spec(500, Some(flag))).is_empty());
    assert_eq!(keys(run(&mut v, spec(500, Some(flag_all)))), [1, 2, 3, 5]);
}

#[test]
fn the_reader_configurations_filter_applies_and_both_echo_it() {
    let s = crowd(4);
    let mut v = VirtualReader::new(&s);
    let cmd = command(vec![unaware(last_is(3), Some(0))]);
    let set = SetReaderConfig {
        antenna_configuration: on_all_antennas(cmd.clone()),
        ..Default::default()
    };
    assert_eq!(v.status(set), StatusCode::M_Success);
    let get = GetReaderConfig {
        requested_data: ConfigRequest::AntennaConfiguration,
        ..Default::default()
    };
    let MessageBody::GetReaderConfigResponse(r) = v.request(get).body else {
        panic!("GET_READER_CONFIG_RESPONSE")
    };
    assert!(!r.antenna_configuration.is_empty());
    for a in &r.antenna_configuration {
        assert_eq!(
            a.c1g2_inventory_command,
            std::slice::from_ref(&cmd),
            "antenna {}",
            a.antenna_id
        );
    }
    // A ROSpec without filters inventories under the reader's.
    assert_eq!(
        run(&mut v, spec(500, None)).into_keys().collect::<Vec<_>>(),
        [3]
    );
    // GET_ROSPECS gives a ROSpec's filters back as added.
    let two = command(vec![unaware(last_is(1), Some(1)), aware(last_is(2), 4, 7)]);
    let added = spec(500, Some(two));
    let add = AddRospec {
        ro_spec: added.clone(),
        ..Default::default()
    };
    assert_eq!(v.status(add), StatusCode::M_Success);
    let MessageBody::GetRospecsResponse(r) = v.request(GetRospecs::default()).body else {
        panic!("GET_ROSPECS_RESPONSE")
    };
    assert_eq!(r.ro_specs, [added]);
}

/// A ParameterError's type, status and field error (its field number and code).
type Fault = (u16, StatusCode, Option<(u16, StatusCode)>);

/// The innermost ParameterError of a status.
fn innermost(s: &LlrpStatus) -> Fault {
    let mut p = s.parameter_error.as_ref().expect("a parameter error");
    while let Some(inner) = p.parameter_error.as_deref() {
        p = inner;
    }
    let field = p.field_error.as_ref().map(|f| (f.field_num, f.error_code));
    (p.parameter_type, p.error_code, field)
}

#[test]
fn bad_filters_get_the_status_a_reader_gives_and_change_nothing() {
    use StatusCode::*;
    let mut v = VirtualReader::new(&crowd(2));
    let good = unaware(last_is(1), Some(0));
    let cases: Vec<(C1g2InventoryCommand, Fault)> = vec![
        (
            command(vec![good.clone(); 3]),
            (331, P_OverflowParameter, None),
        ),
        // Truncation off the EPC bank, and on a filter other than the last (Gen2: only the
        // last Select before the Query, only on the EPC bank).
        (
            command(vec![truncating(unaware(mask(2, 0, &[0xE2]), Some(0)))]),
            (331, P_FieldError, Some((0, A_Invalid))),
        ),
        (
            command(vec![truncating(good.clone()), good.clone()]),
            (331, P_FieldError, Some((0, A_Invalid))),
        ),
        (
            command(vec![unaware(mask(0, 0, &[0]), None)]),
            (332, P_FieldError, Some((0, A_Invalid))),
        ),
        (
            command(vec![unaware(mask(1, 0x20, &[0xE2; 33]), None)]),
            (332, P_FieldError, Some((2, A_OutOfRange))),
        ),
        (
            command(vec![unaware(last_is(1), Some(9))]),
            (334, P_FieldError, Some((0, A_OutOfRange))),
        ),
        (
            command(vec![aware(last_is(1), 7, 0)]),
            (333, P_FieldError, Some((0, A_OutOfRange))),
        ),
        (
            command(vec![aware(last_is(1), 4, 200)]),
            (333, P_FieldError, Some((1, A_OutOfRange))),
        ),
    ];
    for (cmd, want) in cases {
        let add = AddRospec {
            ro_spec: spec(500, Some(cmd.clone())),
            ..Default::default()
        };
        let MessageBody::AddRospecResponse(r) = v.request(add).body else {
            panic!("ADD_ROSPEC_RESPONSE")
        };
        assert_eq!(r.llrp_status.status_code, M_ParameterError, "{cmd:?}");
        assert_eq!(innermost(&r.llrp_status), want, "{cmd:?}");
        let set = SetReaderConfig {
            antenna_configuration: on_all_antennas(cmd.clone()),
            ..Default::default()
        };
        let MessageBody::SetReaderConfigResponse(r) = v.request(set).body else {
            panic!("SET_READER_CONFIG_RESPONSE")
        };
        assert_eq!(innermost(&r.llrp_status), want, "{cmd:?}");
    }
    // Nothing was added or configured: both tags are read.
    let MessageBody::GetRospecsResponse(r) = v.request(GetRospecs::default()).body else {
        panic!("GET_ROSPECS_RESPONSE")
    };
    assert!(r.ro_specs.is_empty());
    assert_eq!(run(&mut v, spec(500, None)).len(), 2);
    // A pointer past every tag's memory is accepted; no tag matches it.
    let far = command(vec![unaware(mask(3, u16::MAX, &[0xFF]), Some(0))]);
    assert!(run(&mut v, spec(500, Some(far))).is_empty());
}

/// ROSpec 1 on antenna 1 for half a second with `cmd`, reporting every field and the PC word.
fn spec_with_pc(cmd: C1g2InventoryCommand) -> RoSpec {
    let mut report = full_report(RoReportTriggerType::UponNTagsOrEndOfRoSpec, 0);
    report
        .tag_report_content_selector
        .air_protocol_epc_memory_selector = vec![C1g2EpcMemorySelector {
        enable_crc: true,
        enable_pc_bits: true,
        ..Default::default()
    }];
    rospec(1, vec![1], ro_duration(500), ai_null(), report)
        .with_antenna_configuration(on_all_antennas(cmd))
}

/// The EPC bank's first `bits` bits of EPC (from 20h) equal those of `bytes`.
fn epc_prefix(bytes: &[u8], bits: u16) -> C1g2TagInventoryMask {
    C1g2TagInventoryMask {
        tag_mask: BitVec {
            bits,
            bytes: bytes.to_vec(),
        },
        ..mask(1, 0x20, &[])
    }
}

#[test]
fn a_truncating_filter_reports_the_epc_bits_after_the_mask_in_epcdata() {
    let s = crowd(4);
    let mut v = VirtualReader::new(&s);
    // The EPCs are E200 0000 … 00kk: a 20-bit mask E2000 on them, truncating.
    let filter = command(vec![truncating(unaware(
        epc_prefix(&[0xE2, 0x00, 0x00], 20),
        Some(0),
    ))]);
    let tags = v.run_rospec(spec_with_pc(filter), 5_000_000, |t| !t.is_empty());
    let mut lasts = Vec::new();
    for t in &tags {
        let Epc::EpcData(d) = &t.epc else {
            panic!("a truncated EPC is sent in EPCData: {:?}", t.epc)
        };
        // 96 - 20 bits: 0 0000 0000 0000 0000 00kk, packed from the first byte.
        assert_eq!(d.epc.bits, 76, "{d:?}");
        assert_eq!(d.epc.bytes.len(), 10);
        assert!(d.epc.bytes[..8].iter().all(|&b| b == 0), "{d:?}");
        lasts.push(d.epc.bytes[8] << 4 | d.epc.bytes[9] >> 4);
        // A truncated reply has no PC word (nor CRC) to report, though the selector asks.
        assert!(
            t.air_protocol_tag_data.is_empty(),
            "{:?}",
            t.air_protocol_tag_data
        );
    }
    lasts.sort();
    lasts.dedup();
    assert_eq!(lasts, [1, 2, 3, 4]);
    // The same filter without truncation reports the EPC-96 and its PC.
    let plain = command(vec![unaware(epc_prefix(&[0xE2, 0x00, 0x00], 20), Some(0))]);
    let tags = v.run_rospec(spec_with_pc(plain), 5_000_000, |t| !t.is_empty());
    assert!(!tags.is_empty());
    for t in &tags {
        assert!(matches!(t.epc, Epc::Epc96(_)), "{:?}", t.epc);
        assert!(t
            .air_protocol_tag_data
            .iter()
            .any(|p| matches!(p, AirProtocolTagData::C1g2Pc(_))));
    }
}

#[test]
fn truncated_replies_are_shorter_so_the_same_time_gives_more_reads() {
    let s = crowd(6);
    let prefix = || unaware(epc_prefix(&[0xE2, 0x00], 16), Some(0));
    let full = run(
        &mut VirtualReader::new(&s),
        spec(2000, Some(command(vec![prefix()]))),
    );
    let short = run(
        &mut VirtualReader::new(&s),
        spec(2000, Some(command(vec![truncating(prefix())]))),
    );
    let (n_full, n_short): (u32, u32) = (full.values().sum(), short.values().sum());
    assert_eq!(full.len(), 6, "{full:?}");
    assert_eq!(short.len(), 6, "{short:?}");
    // 80 of 96 EPC bits and no PC (5 + 80 + 16 bits instead of 128): a shorter successful
    // slot, so more of them in two seconds.
    assert!(n_short > n_full, "{n_short} truncated vs {n_full} in full");
}
