//! The Select semantics: masks on each bank, every action of both kinds, several filters in
//! order, the Query's Sel and Target, and what validation refuses.

use super::*;
use crate::physics::gen2::Air;
use crate::reader::memory::{Lock, EPC_MEMORY_WORDS, LOCK_FIELDS};

/// An EPC-96 tag (3000 PC) whose EPC is E200 0000 … 00`last`, TID E280 1160 0000 00`last`, and
/// four words of user memory 0xBEEF, 0, 0, `last`.
fn chip(last: u8) -> Chip {
    let mut epc = vec![0x3000, 0xE200, 0, 0, 0, 0, u16::from(last)];
    epc.resize(1 + EPC_MEMORY_WORDS, 0);
    Chip {
        reserved: [0; 4],
        epc,
        tid: vec![0xE280, 0x1160, 0, u16::from(last)],
        user: vec![0xBEEF, 0, 0, u16::from(last)],
        locks: [Lock::default(); LOCK_FIELDS],
        killed: false,
    }
}

fn mask(mb: u8, pointer: u16, bytes: &[u8]) -> C1g2TagInventoryMask {
    C1g2TagInventoryMask {
        mb,
        pointer,
        tag_mask: BitVec::from_bytes(bytes),
        ..Default::default()
    }
}

/// A state-unaware filter with action `action` (`None`: no action parameter, as sllurp sends).
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

/// The EPC's last byte is `last` (bits 20h + 88 to 20h + 95 of the EPC bank).
fn last_is(last: u8) -> C1g2TagInventoryMask {
    mask(1, 0x20 + 88, &[last])
}

fn unaware_query(filters: &[C1g2Filter]) -> Query<'_> {
    Query {
        filters,
        state_aware: false,
        sel: None,
        target_b: false,
        session: 2,
        dual: true,
    }
}

#[test]
fn masks_match_each_bank_at_its_bit_address() {
    let c = chip(7);
    // EPC bank: StoredCRC at 00h, PC at 10h, EPC from 20h.
    let crc = c.bank(1)[0].to_be_bytes();
    assert!(matches(&mask(1, 0x00, &crc), &c));
    assert!(matches(&mask(1, 0x10, &[0x30, 0x00]), &c));
    assert!(!matches(&mask(1, 0x10, &[0x34]), &c));
    assert!(matches(&mask(1, 0x20, &[0xE2]), &c));
    assert!(matches(&last_is(7), &c) && !matches(&last_is(8), &c));
    // Not on a byte boundary: the four bits 0010 at 20h + 4.
    let nibble = C1g2TagInventoryMask {
        tag_mask: BitVec {
            bits: 4,
            bytes: vec![0x20],
        },
        ..mask(1, 0x24, &[])
    };
    assert!(matches(&nibble, &c));
    // TID and user memory.
    assert!(matches(&mask(2, 0, &[0xE2, 0x80, 0x11, 0x60]), &c));
    assert!(matches(&mask(2, 48, &[0, 7]), &c) && !matches(&mask(2, 48, &[0, 8]), &c));
    assert!(matches(&mask(3, 0, &[0xBE, 0xEF]), &c) && !matches(&mask(3, 0, &[0xBE, 0xEE]), &c));
    // An empty mask matches every tag.
    assert!(matches(&mask(3, 0, &[]), &c));
}

#[test]
fn a_mask_running_past_the_end_of_the_bank_matches_no_tag() {
    let c = chip(0);
    // User memory is 64 bits of which the last 16 are 0: a mask over 48..64 matches, one
    // over 56..72 (zeros as well, but past the end) does not, nor one beyond it.
    assert!(matches(&mask(3, 48, &[0, 0]), &c));
    assert!(!matches(&mask(3, 56, &[0, 0]), &c));
    assert!(!matches(&mask(3, 1000, &[0]), &c));
    assert!(!matches(&mask(2, u16::MAX, &[0]), &c));
}

#[test]
fn state_unaware_actions_select_and_unselect_as_llrp_names_them() {
    let (hit, miss) = (chip(1), chip(2));
    // (action, matching tag takes part, non-matching tag takes part) from SL deasserted.
    let table = [
        (Some(0), true, false),
        (None, true, false),
        (Some(1), true, false),
        (Some(2), false, false),
        (Some(3), false, false),
        (Some(4), false, true),
        (Some(5), false, true),
    ];
    for (action, on_hit, on_miss) in table {
        let filters = [unaware(last_is(1), action)];
        let q = unaware_query(&filters);
        assert_eq!(q.takes_part(&hit), on_hit, "action {action:?} on a match");
        assert_eq!(
            q.takes_part(&miss),
            on_miss,
            "action {action:?} on a non-match"
        );
    }
}

#[test]
fn two_filters_act_in_order_and_combine_as_and_or_or() {
    // Tags 1..=4; filter A: last byte has bit 0 set (1, 3); filter B: bit 1 set (2, 3).
    let bit = |b: u8| C1g2TagInventoryMask {
        tag_mask: BitVec {
            bits: 1,
            bytes: vec![0x80],
        },
        ..mask(1, 0x20 + 95 - u16::from(b), &[])
    };
    let taking = |filters: &[C1g2Filter]| -> Vec<u8> {
        let q = unaware_query(filters);
        (1..=4u8).filter(|&t| q.takes_part(&chip(t))).collect()
    };
    // Select/Unselect then DoNothing/Unselect: A and B.
    let and = [unaware(bit(0), Some(0)), unaware(bit(1), Some(2))];
    assert_eq!(taking(&and), vec![3]);
    // Select/Unselect then Select/DoNothing: A or B.
    let or = [unaware(bit(0), Some(0)), unaware(bit(1), Some(1))];
    assert_eq!(taking(&or), vec![1, 2, 3]);
    // Order matters: DoNothing/Unselect first acts on SL still deasserted.
    let reversed = [unaware(bit(1), Some(2)), unaware(bit(0), Some(0))];
    assert_eq!(taking(&reversed), vec![1, 3]);
}

#[test]
fn state_aware_actions_follow_gen2_table_6_30_on_sl_and_on_the_sessions_flag() {
    let (hit, miss) = (chip(1), chip(2));
    // (action, SL of a matching tag, SL of a non-matching one) from SL deasserted.
    let on_sl = [
        (0, true, false),
        (1, true, false),
        (2, false, false),
        (3, true, false),
        (4, false, true),
        (5, false, false),
        (6, false, true),
        (7, false, true),
    ];
    for (action, sl_hit, sl_miss) in on_sl {
        let filters = [aware(last_is(1), 0, action)];
        // Sel = SL (S = 0) in a state-aware inventory: the tags with SL asserted answer.
        let q = Query {
            state_aware: true,
            sel: Some(true),
            ..unaware_query(&filters)
        };
        assert_eq!(q.takes_part(&hit), sl_hit, "SL action {action}, match");
        assert_eq!(
            q.takes_part(&miss),
            sl_miss,
            "SL action {action}, non-match"
        );
        // Sel = not SL takes the others.
        let not_sl = Query {
            sel: Some(false),
            ..q
        };
        assert_eq!(not_sl.takes_part(&hit), !sl_hit, "~SL action {action}");
    }
    // The same actions on S2's flag, which starts at A; single target A in session 2.
    for action in 0..8u8 {
        let filters = [aware(last_is(1), 3, action)];
        let q = Query {
            state_aware: true,
            dual: false,
            ..unaware_query(&filters)
        };
        // "Assert" is A: a tag left in A answers a Query for A; from A, negate gives B.
        let a_hit = [true, true, true, false, false, false, true, true][usize::from(action)];
        let a_miss = [false, true, false, true, true, true, true, false][usize::from(action)];
        assert_eq!(q.takes_part(&hit), a_hit, "S2 action {action}, match");
        assert_eq!(q.takes_part(&miss), a_miss, "S2 action {action}, non-match");
        // Target B takes the others; dual target flips its target and takes everyone.
        let b = Query {
            target_b: true,
            ..q
        };
        assert_eq!(b.takes_part(&hit), !a_hit, "S2 action {action}, target B");
        let dual = Query { dual: true, ..q };
        assert!(dual.takes_part(&hit) && dual.takes_part(&miss));
        // Another session's flag does not matter to a session-2 Query.
        let other = [aware(last_is(1), 2, action)];
        let q1 = Query {
            filters: &other,
            ..q
        };
        assert!(q1.takes_part(&hit) && q1.takes_part(&miss));
    }
}

#[test]
fn a_state_aware_query_reads_from_the_singulation_action_and_the_air() {
    let cmd = C1g2InventoryCommand {
        tag_inventory_state_aware: true,
        c1g2_filter: vec![aware(last_is(1), 0, 0)],
        ..Default::default()
    };
    let sing = C1g2TagInventoryStateAwareSingulationAction {
        i: true,
        s: true,
        ..Default::default()
    };
    let air = Air {
        session: 1,
        target: Target::Single,
        ..Air::default()
    };
    let q = Query::of(Some(&cmd), Some(&sing), &air).expect("a query");
    assert_eq!(
        (q.sel, q.target_b, q.session, q.dual),
        (Some(false), true, 1, false)
    );
    // Without a singulation action: Sel = All, target A.
    let q = Query::of(Some(&cmd), None, &Air::default()).expect("a query");
    assert_eq!((q.sel, q.target_b, q.dual), (None, false, true));
    // A state-unaware command without filters selects nothing: everyone takes part.
    assert!(Query::of(Some(&C1g2InventoryCommand::default()), None, &air).is_none());
    assert!(Query::of(None, Some(&sing), &air).is_none());
}

#[test]
fn a_killed_tag_takes_no_part() {
    let mut c = chip(1);
    c.killed = true;
    let filters = [unaware(last_is(1), Some(0))];
    assert!(!unaware_query(&filters).takes_part(&c));
}

/// The field error of a status: the innermost parameter type, its field and code.
fn innermost(s: &LlrpStatus) -> (u16, StatusCode, Option<(u16, StatusCode)>) {
    let mut p = s.parameter_error.as_ref().expect("a parameter error");
    while let Some(inner) = p.parameter_error.as_deref() {
        assert_eq!(p.error_code, StatusCode::P_ParameterError);
        p = inner;
    }
    let field = p.field_error.as_ref().map(|f| (f.field_num, f.error_code));
    (p.parameter_type, p.error_code, field)
}

fn refused(cmd: C1g2InventoryCommand) -> (u16, StatusCode, Option<(u16, StatusCode)>) {
    let e = validate(&cmd).expect_err("refused");
    assert_eq!(e.status_code, StatusCode::M_ParameterError);
    assert_eq!(
        e.parameter_error.as_ref().map(|p| p.parameter_type),
        Some(330)
    );
    innermost(&e)
}

fn with(filters: Vec<C1g2Filter>) -> C1g2InventoryCommand {
    C1g2InventoryCommand {
        c1g2_filter: filters,
        ..Default::default()
    }
}

#[test]
fn validation_refuses_what_the_reader_cannot_send_naming_the_field() {
    use StatusCode::*;
    let good = unaware(last_is(1), Some(0));
    assert!(validate(&with(vec![good.clone(), good.clone()])).is_ok());
    // Past the end of every tag's bank: accepted (the tags do not match).
    assert!(validate(&with(vec![unaware(mask(3, 60_000, &[1]), None)])).is_ok());
    assert_eq!(
        refused(with(vec![good.clone(); 3])),
        (331, P_OverflowParameter, None)
    );
    let t = |t| C1g2Filter { t, ..good.clone() };
    // Truncation on the EPC bank's last filter is sent; its refusals are tested below.
    assert!(validate(&with(vec![t(2)])).is_ok());
    assert_eq!(
        refused(with(vec![t(3)])),
        (331, P_FieldError, Some((0, A_OutOfRange)))
    );
    assert!(validate(&with(vec![t(1)])).is_ok());
    let reserved = unaware(mask(0, 32, &[0]), None);
    assert_eq!(
        refused(with(vec![reserved])),
        (332, P_FieldError, Some((0, A_Invalid)))
    );
    let long = unaware(mask(1, 32, &[0xAA; 32]), None);
    assert_eq!(
        refused(with(vec![long])),
        (332, P_FieldError, Some((2, A_OutOfRange)))
    );
    let longest = C1g2TagInventoryMask {
        tag_mask: BitVec {
            bits: MAX_MASK_BITS,
            bytes: vec![0; 32],
        },
        ..mask(1, 32, &[])
    };
    assert!(validate(&with(vec![unaware(longest, None)])).is_ok());
    let action = unaware(last_is(1), Some(6));
    assert_eq!(
        refused(with(vec![action])),
        (334, P_FieldError, Some((0, A_OutOfRange)))
    );
    let target = aware(last_is(1), 5, 0);
    assert_eq!(
        refused(with(vec![target])),
        (333, P_FieldError, Some((0, A_OutOfRange)))
    );
    let action = aware(last_is(1), 4, 8);
    assert_eq!(
        refused(with(vec![action])),
        (333, P_FieldError, Some((1, A_OutOfRange)))
    );
    let missing = C1g2InventoryCommand {
        tag_inventory_state_aware: true,
        ..with(vec![good])
    };
    assert_eq!(refused(missing), (333, P_MissingParameter, None));
}

/// `f` truncating (T = 2).
fn truncating(f: C1g2Filter) -> C1g2Filter {
    C1g2Filter { t: TRUNCATE, ..f }
}

#[test]
fn a_tag_matching_a_truncating_filter_replies_with_its_epc_after_the_mask() {
    // Mask: the EPC's first 20 bits (E2000): the tags reply with the EPC's last 76 bits.
    let filters = [truncating(unaware(
        C1g2TagInventoryMask {
            tag_mask: BitVec {
                bits: 20,
                bytes: vec![0xE2, 0x00, 0x00],
            },
            ..mask(1, 0x20, &[])
        },
        Some(0),
    ))];
    let q = unaware_query(&filters);
    let (c, other) = (chip(7), chip(7));
    assert_eq!(q.reply(&c), Some(Reply::Truncated { skip: 20, bits: 76 }));
    let epc = c.reported_epc();
    let sent = truncated_epc(&epc, 20);
    assert_eq!(sent.bits, 76);
    // E200 0000 … 0007 from bit 20: 0 0000 … 0007, packed from the first byte, 4 pad bits.
    assert_eq!(sent.bytes, vec![0, 0, 0, 0, 0, 0, 0, 0, 0, 0x70]);
    assert_eq!(truncated_epc(&epc, 96).bits, 0);
    // Without T = 2 (or with T = 0, the reader's choice) the same tag replies in full.
    let plain = [unaware(filters[0].c1g2_tag_inventory_mask.clone(), Some(0))];
    assert_eq!(unaware_query(&plain).reply(&other), Some(Reply::Full));
    // A tag the filter leaves out does not reply at all.
    let mut miss = chip(7);
    miss.epc[1] = 0x3000;
    assert_eq!(q.reply(&miss), None);
}

#[test]
fn only_tags_matching_the_last_filter_truncate_and_only_under_sel_sl() {
    // Select the tags ending in 1 or 2, truncating on "ends in 2" (DoNothing/... keeps SL).
    let ends_in = |b| unaware(last_is(b), Some(0));
    let filters = [ends_in(1), truncating(unaware(last_is(2), Some(1)))];
    let q = unaware_query(&filters);
    assert_eq!(q.reply(&chip(1)), Some(Reply::Full));
    // The mask ends at the EPC's end: nothing of the EPC is left to send.
    assert_eq!(
        q.reply(&chip(2)),
        Some(Reply::Truncated { skip: 96, bits: 0 })
    );
    assert_eq!(q.reply(&chip(3)), None);
    // State-aware on SL: truncated under Sel = SL, not under Sel = All (Gen2: Sel 10 or 11).
    let aware_filters = [truncating(aware(last_is(2), 0, 0))];
    let sl = Query {
        state_aware: true,
        sel: Some(true),
        ..unaware_query(&aware_filters)
    };
    assert!(matches!(sl.reply(&chip(2)), Some(Reply::Truncated { .. })));
    let all = Query { sel: None, ..sl };
    assert_eq!(all.reply(&chip(2)), Some(Reply::Full));
}

#[test]
fn truncation_gen2_does_not_allow_is_refused_on_t() {
    use StatusCode::*;
    let on_t = (331, P_FieldError, Some((0, A_Invalid)));
    // On the TID bank (MB 2) and on User memory (MB 3).
    let tid = truncating(unaware(mask(2, 0, &[0xE2]), Some(0)));
    assert_eq!(refused(with(vec![tid])), on_t);
    let user = truncating(unaware(mask(3, 0, &[0xBE]), Some(0)));
    assert_eq!(refused(with(vec![user])), on_t);
    // Not the last filter (the Select before the Query).
    let first = truncating(unaware(last_is(1), Some(0)));
    let second = unaware(last_is(1), Some(1));
    assert_eq!(refused(with(vec![first.clone(), second.clone()])), on_t);
    // The same filters the other way round are sent.
    assert!(validate(&with(vec![second, first])).is_ok());
    // A mask ending in the PC, before the EPC.
    let pc = truncating(unaware(mask(1, 0x10, &[0x30]), Some(0)));
    assert_eq!(refused(with(vec![pc])), on_t);
    // A state-aware filter on an inventoried flag (S2) rather than SL.
    let s2 = C1g2InventoryCommand {
        tag_inventory_state_aware: true,
        ..with(vec![truncating(aware(last_is(1), 3, 0))])
    };
    assert_eq!(refused(s2), on_t);
    let sl = C1g2InventoryCommand {
        tag_inventory_state_aware: true,
        ..with(vec![truncating(aware(last_is(1), 0, 0))])
    };
    assert!(validate(&sl).is_ok());
}

#[test]
fn llrp_state_aware_targets_are_sl_0_then_the_sessions_flags_1_to_4() {
    let (hit, miss) = (chip(1), chip(2));
    // Action 4 (matching: deassert SL / B; others: assert SL / A), single target A.
    let query = |filters: &[C1g2Filter], session: u8, sel: Option<bool>| {
        let q = Query {
            state_aware: true,
            sel,
            dual: false,
            session,
            ..unaware_query(filters)
        };
        (q.takes_part(&hit), q.takes_part(&miss))
    };
    // Target 0 is SL: under Sel = SL only the non-matching tag answers.
    let sl = [aware(last_is(1), 0, 4)];
    assert_eq!(query(&sl, 0, Some(true)), (false, true));
    // Target 1 is S0's flag: under Sel = All in session 0, the matching tag is in B.
    let s0 = [aware(last_is(1), 1, 4)];
    assert_eq!(query(&s0, 0, None), (false, true));
    // ... and it leaves session 3's flag alone, which target 4 sets.
    assert_eq!(query(&s0, 3, None), (true, true));
    let s3 = [aware(last_is(1), 4, 4)];
    assert_eq!(query(&s3, 3, None), (false, true));
}
