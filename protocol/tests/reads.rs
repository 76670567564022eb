//! The borrowed tag-read path agrees with the full typed decoder: same values on valid
//! reports, same error (offset, path, status) on broken ones.

use llrp::message::{MessageBody, RoAccessReport};
use llrp::params::TagReportData;
use llrp::reads::{tag_reads, TagRead};
use llrp::sample::{benchmark_report, Gen};
use llrp::Message;
use proptest::prelude::*;

/// What `tag_reads` must yield for one typed TagReportData.
fn expected(t: &TagReportData) -> TagRead<'_> {
    let epc_bits = match &t.epc {
        llrp::params::Epc::Epc96(_) => 96,
        llrp::params::Epc::EpcData(d) => d.epc.bits,
    };
    TagRead {
        epc: t.epc_bytes(),
        epc_bits,
        ro_spec_id: t.ro_spec_id.map(|v| v.0),
        spec_index: t.spec_index.map(|v| v.0),
        inventory_parameter_spec_id: t.inventory_parameter_spec_id.map(|v| v.0),
        antenna_id: t.antenna_id.map(|v| v.0),
        peak_rssi: t.peak_rssi.map(|v| v.0),
        channel_index: t.channel_index.map(|v| v.0),
        first_seen_utc: t.first_seen_timestamp_utc.map(|v| v.0),
        first_seen_uptime: t.first_seen_timestamp_uptime.map(|v| v.0),
        last_seen_utc: t.last_seen_timestamp_utc.map(|v| v.0),
        last_seen_uptime: t.last_seen_timestamp_uptime.map(|v| v.0),
        tag_seen_count: t.tag_seen_count.map(|v| v.0),
        access_spec_id: t.access_spec_id.map(|v| v.0),
        phase_angle: t.impinj_phase_angle(),
        impinj_peak_rssi: t.impinj_peak_rssi(),
        doppler_frequency: t.impinj_doppler(),
    }
}

fn report_index() -> usize {
    MessageBody::TYPED
        .iter()
        .position(|t| t.3 == "RO_ACCESS_REPORT")
        .expect("RO_ACCESS_REPORT is typed")
}

fn check_agrees(frame: &[u8]) -> Result<usize, TestCaseError> {
    let msg = Message::decode(frame).map_err(|e| TestCaseError::fail(e.to_string()))?;
    let MessageBody::RoAccessReport(RoAccessReport {
        tag_report_data, ..
    }) = &msg.body
    else {
        return Err(TestCaseError::fail("not an RO_ACCESS_REPORT"));
    };
    let got: Vec<TagRead> = tag_reads(frame)
        .map_err(|e| TestCaseError::fail(e.to_string()))?
        .collect::<Result<_, _>>()
        .map_err(|e| TestCaseError::fail(e.to_string()))?;
    let want: Vec<TagRead> = tag_report_data.iter().map(expected).collect();
    prop_assert_eq!(got, want);
    Ok(tag_report_data.len())
}

#[test]
fn benchmark_reports_read_the_same_both_ways() {
    for n in [1, 10, 100] {
        let frame = benchmark_report(n, 3).to_bytes();
        let count = check_agrees(&frame).expect("agrees");
        assert_eq!(count, n);
        let first = tag_reads(&frame).unwrap().next().unwrap().unwrap();
        assert!(first.phase_angle.is_some() && first.impinj_peak_rssi.is_some());
        assert_eq!(first.epc.len(), 12);
    }
}

#[test]
fn other_messages_are_refused_with_the_decoder_error() {
    let frame = Message {
        version: 1,
        id: 9,
        body: MessageBody::Keepalive(Default::default()),
    }
    .to_bytes();
    let err = tag_reads(&frame).expect_err("KEEPALIVE has no tag reads");
    assert_eq!(err.path_string(), "KEEPALIVE");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn random_reports_read_the_same_both_ways(seed in any::<u64>()) {
        let mut g = Gen::new(seed);
        let body = MessageBody::sample_typed(report_index(), &mut g);
        let frame = Message { version: 1, id: 1, body }.to_bytes();
        check_agrees(&frame)?;
    }

    #[test]
    fn broken_reports_fail_like_the_decoder(seed in any::<u64>(), cut in any::<usize>(), pos in any::<usize>(), val in any::<u8>()) {
        let mut frame = benchmark_report(1 + seed as usize % 5, seed).to_bytes().to_vec();
        let p = 10 + pos % (frame.len() - 10);
        frame[p] = val;
        let cut = 10 + cut % (frame.len() - 10);
        frame.truncate(cut);
        let len = (frame.len() as u32).to_be_bytes();
        frame[2..6].copy_from_slice(&len);
        let full = Message::decode(&frame);
        let fast: Result<Vec<TagRead>, _> = tag_reads(&frame).and_then(|r| r.collect());
        match (full, fast) {
            (Err(a), Err(b)) => prop_assert_eq!(a, b),
            (Ok(_), Ok(_)) => {}
            // The fast path skips what it has no field for, so it may accept what the full
            // decoder refuses (never the other way round).
            (Err(_), Ok(_)) => {}
            (Ok(m), Err(e)) => prop_assert!(false, "fast path refused a valid frame: {e} ({m:?})"),
        }
    }
}
