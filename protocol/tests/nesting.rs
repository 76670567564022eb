//! Property tests on hostile shapes: ParameterErrors nested as deep as a TLV allows, and very
//! wide messages. Decoding stays within a small stack (each case runs on a thread with
//! [`STACK`] bytes of it), deeper nesting than [`MAX_NESTING`] is refused with the LLRP error
//! a reader gives, and whatever decodes round-trips.

use llrp::codec::MAX_NESTING;
use llrp::sample::{benchmark_report, nested_status_frame, MAX_FITTING_NESTING};
use llrp::{ErrorKind, Message, StatusCode};
use proptest::prelude::*;

/// Stack of each case's thread: ample for [`MAX_NESTING`] levels even in a debug build, far
/// too small for the thousands of levels a 64 KiB TLV can hold if decoding were unbounded.
const STACK: usize = 512 * 1024;

/// Runs `f` on a thread with [`STACK`] bytes of stack (a stack overflow aborts the test).
fn on_small_stack<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> T {
    std::thread::Builder::new()
        .stack_size(STACK)
        .spawn(f)
        .expect("thread starts")
        .join()
        .expect("no panic")
}

/// Message types whose body starts with an LLRPStatus, as readers and clients send them.
const WITH_STATUS: [u16; 4] = [100, 4, 12, 30];

/// How a frame with a chain of `depth` ParameterErrors decodes, checked in depth.
fn check_chain(msg_type: u16, depth: usize) -> Result<(), String> {
    let frame = nested_status_frame(msg_type, 9, depth);
    // The LLRPStatus holds the first ParameterError directly; each further one is nested.
    let nested = depth.saturating_sub(1);
    match Message::decode(&frame) {
        Ok(m) if nested <= MAX_NESTING as usize => {
            if m.to_bytes()[..] != frame[..] {
                return Err(format!("depth {depth}: re-encoded bytes differ"));
            }
            serde_json::to_string(&m).map_err(|e| e.to_string())?;
            let _ = format!("{m:?}");
            Ok(())
        }
        Ok(_) => Err(format!("depth {depth} decoded past the limit")),
        Err(e) if nested > MAX_NESTING as usize => {
            if e.kind
                != (ErrorKind::TooDeep {
                    ty: 289,
                    limit: MAX_NESTING,
                })
            {
                return Err(format!("depth {depth}: {e}"));
            }
            if e.offset >= frame.len() {
                return Err(format!("depth {depth}: offset {} past the frame", e.offset));
            }
            let status = e.to_status();
            if status.status_code != StatusCode::M_ParameterError {
                return Err(format!("depth {depth}: status {}", status.status_code));
            }
            // The answer a reader sends decodes again (it does not echo the whole chain).
            let answer = Message::new(
                9,
                llrp::message::ErrorMessage {
                    llrp_status: status,
                    ..Default::default()
                },
            );
            Message::decode(&answer.to_bytes()).map_err(|e| format!("the answer: {e}"))?;
            Ok(())
        }
        Err(e) => Err(format!("depth {depth} refused: {e}")),
    }
}

#[test]
fn parameter_errors_nested_to_the_limit_decode_and_one_more_is_refused() {
    for ty in WITH_STATUS {
        let depth = MAX_NESTING as usize + 1;
        on_small_stack(move || check_chain(ty, depth)).expect("at the limit");
        on_small_stack(move || check_chain(ty, depth + 1)).expect("one past it");
    }
}

#[test]
fn parameter_errors_nested_as_deep_as_a_tlv_allows_are_refused_on_a_small_stack() {
    for ty in WITH_STATUS {
        on_small_stack(move || check_chain(ty, MAX_FITTING_NESTING)).expect("deepest");
    }
}

#[test]
fn a_refused_deep_frame_leaves_the_next_decode_on_the_thread_unaffected() {
    on_small_stack(|| {
        for _ in 0..200 {
            check_chain(100, MAX_FITTING_NESTING)?;
            check_chain(100, MAX_NESTING as usize + 1)?;
        }
        Ok::<_, String>(())
    })
    .expect("the nesting count is released after an error");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn any_nesting_depth_is_decoded_or_refused_within_a_small_stack(
        k in 0usize..WITH_STATUS.len(),
        depth in 0usize..=MAX_FITTING_NESTING,
    ) {
        let ty = WITH_STATUS[k];
        on_small_stack(move || check_chain(ty, depth)).map_err(TestCaseError::fail)?;
    }

    #[test]
    fn very_wide_reports_round_trip(n in 0usize..20_000, seed in any::<u64>()) {
        let m = benchmark_report(n, seed);
        let bytes = m.to_bytes();
        let back = Message::decode(&bytes).map_err(|e| TestCaseError::fail(e.to_string()))?;
        let llrp::MessageBody::RoAccessReport(r) = &back.body else {
            return Err(TestCaseError::fail("not a report"));
        };
        prop_assert_eq!(r.tag_report_data.len(), n);
        prop_assert_eq!(&back.to_bytes()[..], &bytes[..]);
    }

    #[test]
    fn a_list_field_as_long_as_its_tlv_allows_round_trips(n in 0usize..=32_700) {
        use llrp::enums::*;
        use llrp::params::*;
        let spec = AiSpec {
            antenna_ids: (0..n).map(|k| k as u16).collect(),
            ai_spec_stop_trigger: AiSpecStopTrigger::default(),
            inventory_parameter_specs: vec![InventoryParameterSpec {
                inventory_parameter_spec_id: 1,
                protocol_id: AirProtocol::EpcGlobalClass1Gen2,
                ..Default::default()
            }],
            ..Default::default()
        };
        let m = Message::new(3, llrp::message::AddRospec {
            ro_spec: RoSpec {
                ro_spec_id: 1,
                specs: vec![SpecParameter::AiSpec(spec)],
                ..Default::default()
            },
            ..Default::default()
        });
        let bytes = m.to_bytes();
        let back = Message::decode(&bytes).map_err(|e| TestCaseError::fail(e.to_string()))?;
        prop_assert_eq!(&back, &m);
    }
}

/// An ERROR_MESSAGE whose LLRPStatus holds `depth` nested ParameterErrors, the innermost
/// holding `innermost` (bytes of a fault: an unexpected parameter, a cut field).
fn chain_around(depth: usize, innermost: &[u8]) -> Vec<u8> {
    let mut inner = innermost.to_vec();
    for _ in 0..depth {
        let mut pe = Vec::with_capacity(inner.len() + 8);
        pe.extend_from_slice(&289u16.to_be_bytes());
        pe.extend_from_slice(&((8 + inner.len()) as u16).to_be_bytes());
        pe.extend_from_slice(&287u16.to_be_bytes());
        pe.extend_from_slice(&200u16.to_be_bytes());
        pe.extend_from_slice(&inner);
        inner = pe;
    }
    let mut status = Vec::with_capacity(inner.len() + 8);
    status.extend_from_slice(&287u16.to_be_bytes());
    status.extend_from_slice(&((8 + inner.len()) as u16).to_be_bytes());
    status.extend_from_slice(&100u16.to_be_bytes());
    status.extend_from_slice(&0u16.to_be_bytes());
    status.extend_from_slice(&inner);
    let mut f = Vec::with_capacity(status.len() + 10);
    f.extend_from_slice(&(0x400u16 | 100).to_be_bytes());
    f.extend_from_slice(&((10 + status.len()) as u32).to_be_bytes());
    f.extend_from_slice(&1u32.to_be_bytes());
    f.extend_from_slice(&status);
    f
}

#[test]
fn the_answer_to_a_fault_at_any_depth_is_itself_decodable() {
    // Faults found by the structured fuzz target's hand-made inputs: an unexpected TV
    // parameter, and a ParameterError cut inside its ErrorCode field, at every depth.
    let unexpected: &[u8] = &[0x81, 0, 0];
    let cut_field: &[u8] = &[0x01, 0x21, 0x00, 0x06, 0x01, 0x1f];
    on_small_stack(move || {
        for depth in (0..=MAX_NESTING as usize + 4).chain([MAX_FITTING_NESTING - 1]) {
            for fault in [unexpected, cut_field] {
                let frame = chain_around(depth, fault);
                let e = Message::decode(&frame).expect_err("a fault");
                let answer = Message::new(
                    1,
                    llrp::message::ErrorMessage {
                        llrp_status: e.to_status(),
                        ..Default::default()
                    },
                );
                Message::decode(&answer.to_bytes())
                    .map_err(|a| format!("depth {depth}, {e}: the answer: {a}"))?;
            }
        }
        Ok::<_, String>(())
    })
    .expect("every answer decodes");
}

#[test]
fn an_unknown_parameter_after_more_than_65535_typed_ones_keeps_its_place() {
    // RO_ACCESS_REPORT: n TagReportData (EPC-96 only), then an unknown TLV 900, then one more.
    let tag: [u8; 17] = [
        0x00, 0xf0, 0x00, 0x11, 0x8d, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11,
    ];
    for n in [65_535usize, 65_536, 65_537] {
        let mut body = Vec::with_capacity((n + 1) * 17 + 4);
        for _ in 0..n {
            body.extend_from_slice(&tag);
        }
        body.extend_from_slice(&[0x03, 0x84, 0x00, 0x04]);
        body.extend_from_slice(&tag);
        let mut frame = Vec::with_capacity(body.len() + 10);
        frame.extend_from_slice(&(0x400u16 | 61).to_be_bytes());
        frame.extend_from_slice(&((10 + body.len()) as u32).to_be_bytes());
        frame.extend_from_slice(&1u32.to_be_bytes());
        frame.extend_from_slice(&body);
        let m = Message::decode(&frame).expect("decodes");
        assert!(
            m.to_bytes()[..] == frame[..],
            "{n} typed: re-encoded bytes differ"
        );
    }
}
