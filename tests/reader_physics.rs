//! Reads from the simulated reader are physically consistent and follow the client's
//! settings: RSSI falls with distance (−40 dB/decade in free space), the phase difference of
//! two tags is 4πΔD/λ, channels come from the region's table, tx power changes range, the
//! content selector is honoured field by field, report and stop triggers, events, GET_REPORT
//! and AccessSpec reads of TID memory. Driven in process with a virtual clock
//! (tests/common/virtual_reader.rs).

mod common;

use std::collections::HashMap;

use common::virtual_reader::VirtualReader;
use common::*;
use llrp::message::*;
use llrp::params::*;
use llrp_gateway::scenario::Scenario;

const LAMBDA_CH1: f64 = 299_792_458.0 / 865_700_000.0;

/// Per EPC (last byte), the reads collected.
fn by_tag(tags: &[TagReportData]) -> HashMap<u8, Vec<&TagReportData>> {
    let mut m: HashMap<u8, Vec<&TagReportData>> = HashMap::new();
    for t in tags {
        m.entry(*t.epc_bytes().last().expect("EPC"))
            .or_default()
            .push(t);
    }
    m
}

fn mean(v: impl Iterator<Item = f64>) -> f64 {
    let v: Vec<f64> = v.collect();
    v.iter().sum::<f64>() / v.len() as f64
}

#[test]
fn rssi_and_phase_follow_the_closed_forms() {
    // Tags 1 and 2 a decade apart in distance-ratio terms (1 m, 2 m), tag 3 at 2.1 m for the
    // phase, tag 4 far beyond the 7 m range.
    let s = line_scenario(&[1.0, 2.0, 2.1, 40.0]);
    let mut v = VirtualReader::new(&s);
    v.request(ImpinjEnableExtensions::default());
    let spec = rospec(
        1,
        vec![1],
        ro_null(),
        ai_null(),
        full_report(RoReportTriggerType::UponNTagsOrEndOfAiSpec, 1),
    );
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
    let (tags, _) = v.collect_reports(600_000_000, |t| t.len() >= 600);
    assert!(tags.len() >= 300, "only {} reads", tags.len());
    let per = by_tag(&tags);
    assert!(!per.contains_key(&4), "a tag 40 m away was read");
    for t in &tags {
        assert_eq!(t.channel_index.map(|c| c.0), Some(1), "fixed channel 1");
        assert_eq!(t.antenna_id.map(|a| a.0), Some(1));
        assert_eq!(
            t.tag_seen_count.map(|n| n.0),
            Some(1),
            "N = 1 reports every read"
        );
    }
    let rssi = |k: u8| {
        mean(
            per[&k]
                .iter()
                .map(|t| f64::from(t.impinj_peak_rssi().expect("impinj rssi")) / 100.0),
        )
    };
    let (r1, r2) = (rssi(1), rssi(2));
    // Free space, two-way: 40·log10(2) ≈ 12.04 dB between 1 m and 2 m.
    assert!(
        (r1 - r2 - 40.0 * 2f64.log10()).abs() < 0.5,
        "RSSI 1 m {r1:.2} dBm, 2 m {r2:.2} dBm"
    );
    // Whole-dBm PeakRSSI agrees with the hundredths.
    for t in &tags {
        let whole = t.peak_rssi.expect("PeakRSSI").0;
        let centi = t.impinj_peak_rssi().expect("Impinj RSSI");
        assert_eq!(i32::from(whole), i32::from(centi) / 100);
    }
    // Phase difference of tags at 2.0 m and 2.1 m: 4π·0.1/λ mod 2π.
    let phase = |k: u8| {
        f64::from(per[&k][0].impinj_phase_angle().expect("phase")) * std::f64::consts::TAU / 4096.0
    };
    let measured = (phase(3) - phase(2)).rem_euclid(std::f64::consts::TAU);
    let expected =
        (4.0 * std::f64::consts::PI * 0.1 / LAMBDA_CH1).rem_euclid(std::f64::consts::TAU);
    let err = (measured - expected)
        .abs()
        .min(std::f64::consts::TAU - (measured - expected).abs());
    assert!(
        err < 0.01,
        "phase difference {measured:.4} rad, expected {expected:.4} rad"
    );
}

/// Reads of the near and far tag in 5 s at transmit power index `power`.
fn count_reads(s: &Scenario, power: u16) -> (u32, u32) {
    let mut v = VirtualReader::new(s);
    let set = SetReaderConfig {
        antenna_configuration: vec![AntennaConfiguration {
            antenna_id: 1,
            rf_transmitter: Some(RfTransmitter {
                hop_table_id: 1,
                channel_index: 1,
                transmit_power: power,
                ..Default::default()
            }),
            ..Default::default()
        }],
        ..Default::default()
    };
    assert_eq!(v.status(set), StatusCode::M_Success);
    let spec = rospec(
        1,
        vec![1],
        ro_duration(5_000),
        ai_null(),
        full_report(RoReportTriggerType::UponNTagsOrEndOfRoSpec, 0),
    );
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
    let (tags, _) = v.collect_reports(600_000_000, |t| !t.is_empty());
    let per = by_tag(&tags);
    let near = per.get(&1).map_or(0, |v| {
        v.iter()
            .map(|t| u32::from(t.tag_seen_count.map_or(0, |n| n.0)))
            .sum()
    });
    let far = per.get(&2).map_or(0, |v| {
        v.iter()
            .map(|t| u32::from(t.tag_seen_count.map_or(0, |n| n.0)))
            .sum()
    });
    (near, far)
}

#[test]
fn tx_power_changes_the_read_range() {
    let s = line_scenario(&[1.0, 6.0]);
    let (near_hi, far_hi) = count_reads(&s, llrp_gateway::reader::caps::POWER_LEVELS);
    let (near_lo, far_lo) = count_reads(&s, 1);
    assert!(
        near_hi > 0 && near_lo > 0,
        "the near tag is read at any power ({near_hi}, {near_lo})"
    );
    assert!(far_hi > 0, "the far tag is read at full power");
    assert!(
        far_lo < far_hi / 2,
        "at 10 dBm the 6 m tag is read less ({far_lo} vs {far_hi})"
    );
}

#[test]
fn content_selector_is_honoured_field_by_field() {
    let s = line_scenario(&[1.5]);
    let mut v = VirtualReader::new(&s);
    let report = RoReportSpec {
        ro_report_trigger: RoReportTriggerType::UponNTagsOrEndOfAiSpec,
        n: 1,
        tag_report_content_selector: TagReportContentSelector {
            enable_antenna_id: true,
            enable_first_seen_timestamp: true,
            air_protocol_epc_memory_selector: vec![C1g2EpcMemorySelector {
                enable_pc_bits: true,
                enable_crc: true,
                ..Default::default()
            }],
            ..Default::default()
        },
        ..Default::default()
    };
    let spec = rospec(1, vec![0], ro_null(), ai_null(), report);
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
    let (tags, _) = v.collect_reports(600_000_000, |t| t.len() >= 5);
    assert!(tags.len() >= 5);
    for t in &tags {
        assert!(t.antenna_id.is_some() && t.first_seen_timestamp_utc.is_some());
        assert!(
            t.peak_rssi.is_none()
                && t.channel_index.is_none()
                && t.last_seen_timestamp_utc.is_none()
        );
        assert!(t.tag_seen_count.is_none() && t.ro_spec_id.is_none() && t.spec_index.is_none());
        assert!(
            t.custom.is_empty(),
            "no Impinj fields without IMPINJ_ENABLE_EXTENSIONS"
        );
        assert_eq!(t.air_protocol_tag_data.len(), 2, "PC and CRC");
    }
}

#[test]
fn triggers_events_and_get_report() {
    let s = line_scenario(&[1.0, 2.0, 3.0]);
    let mut v = VirtualReader::new(&s);
    let events = SetReaderConfig {
        reader_event_notification_spec: Some(ReaderEventNotificationSpec {
            event_notification_state: vec![
                EventNotificationState {
                    event_type: NotificationEventType::RoSpecEvent,
                    notification_state: true,
                    ..Default::default()
                },
                EventNotificationState {
                    event_type: NotificationEventType::AiSpecEvent,
                    notification_state: true,
                    ..Default::default()
                },
            ],
            ..Default::default()
        }),
        ..Default::default()
    };
    assert_eq!(v.status(events), StatusCode::M_Success);
    // AISpec ends after seeing 2 distinct tags; reports at the end of the AISpec; the
    // Immediate ROSpec then runs again.
    let ai = AiSpecStopTrigger {
        ai_spec_stop_trigger_type: AiSpecStopTriggerType::TagObservation,
        tag_observation_trigger: Some(TagObservationTrigger {
            trigger_type: TagObservationTriggerType::UponSeeingNTagsOrTimeout,
            number_of_tags: 2,
            ..Default::default()
        }),
        ..Default::default()
    };
    let spec = rospec(
        3,
        vec![1],
        ro_null(),
        ai,
        full_report(RoReportTriggerType::UponNTagsOrEndOfAiSpec, 0),
    );
    assert_eq!(
        v.status(AddRospec {
            ro_spec: spec,
            ..Default::default()
        }),
        StatusCode::M_Success
    );
    assert_eq!(
        v.status(EnableRospec {
            ro_spec_id: 3,
            ..Default::default()
        }),
        StatusCode::M_Success
    );
    let mut reports = Vec::new();
    let mut starts = 0;
    let mut ai_ends = 0;
    while reports.len() < 3 {
        let m = v.next_message(600_000_000);
        match m.body {
            MessageBody::RoAccessReport(r) => reports.push(r.tag_report_data),
            MessageBody::ReaderEventNotification(n) => {
                let d = n.reader_event_notification_data;
                if d.ro_spec_event.as_ref().is_some_and(|e| {
                    e.event_type == RoSpecEventType::StartOfRoSpec && e.ro_spec_id == 3
                }) {
                    starts += 1;
                }
                if d.ai_spec_event.is_some() {
                    ai_ends += 1;
                }
            }
            _ => {}
        }
    }
    for r in &reports {
        let distinct: std::collections::HashSet<Vec<u8>> =
            r.iter().map(|t| t.epc_bytes().to_vec()).collect();
        assert_eq!(
            distinct.len(),
            2,
            "each AISpec run ends at its second distinct tag"
        );
    }
    assert!(
        starts >= 2 && ai_ends >= 2,
        "events: {starts} starts, {ai_ends} AISpec ends"
    );
    assert_eq!(
        v.status(DeleteRospec {
            ro_spec_id: 3,
            ..Default::default()
        }),
        StatusCode::M_Success
    );
    v.take();

    // Trigger None: nothing arrives until GET_REPORT.
    let spec = rospec(
        4,
        vec![1],
        ro_null(),
        ai_null(),
        full_report(RoReportTriggerType::None, 0),
    );
    assert_eq!(
        v.status(AddRospec {
            ro_spec: spec,
            ..Default::default()
        }),
        StatusCode::M_Success
    );
    assert_eq!(
        v.status(EnableRospec {
            ro_spec_id: 4,
            ..Default::default()
        }),
        StatusCode::M_Success
    );
    let (early, _) = v.collect_reports(5_000_000, |_| false);
    assert!(early.is_empty(), "no report before GET_REPORT");
    // The reader is alive and inventorying: it answers, and nothing came before its answer.
    let r = v.request(GetRospecs::default());
    let MessageBody::GetRospecsResponse(list) = r.body else {
        panic!("{r:?}")
    };
    assert!(list
        .ro_specs
        .iter()
        .any(|s| s.current_state == RoSpecState::Active));
    assert!(
        v.take()
            .iter()
            .all(|m| !matches!(m.body, MessageBody::RoAccessReport(_))),
        "no report before GET_REPORT"
    );
    v.send(GetReport::default());
    let (tags, _) = v.collect_reports(600_000_000, |t| !t.is_empty());
    assert!(!tags.is_empty());
}

/// The first TagReportData of an inventory of `s` on antenna 1 with an AccessSpec (ID 9)
/// reading `word_count` words of memory bank `mb` (OpSpec ID 5) from every tag.
fn read_by_access_spec(s: &Scenario, mb: u8, word_count: u16) -> TagReportData {
    let mut v = VirtualReader::new(s);
    let access = AccessSpec {
        access_spec_id: 9,
        antenna_id: 0,
        protocol_id: AirProtocol::EpcGlobalClass1Gen2,
        current_state: false,
        ro_spec_id: 0,
        access_spec_stop_trigger: AccessSpecStopTrigger::default(),
        access_command: AccessCommand {
            c1g2_tag_spec: C1g2TagSpec {
                c1g2_target_tag: vec![C1g2TargetTag {
                    mb: 1,
                    is_match: true,
                    pointer: 32,
                    ..Default::default()
                }],
                ..Default::default()
            },
            op_specs: vec![OpSpec::C1g2Read(C1g2Read {
                op_spec_id: 5,
                mb,
                word_pointer: 0,
                word_count,
                ..Default::default()
            })],
            ..Default::default()
        },
        ..Default::default()
    };
    v.add_access_spec(access);
    let spec = rospec(
        1,
        vec![1],
        ro_null(),
        ai_null(),
        full_report(RoReportTriggerType::UponNTagsOrEndOfAiSpec, 1),
    );
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
    let (tags, _) = v.collect_reports(600_000_000, |t| !t.is_empty());
    tags.into_iter().next().expect("a tag report")
}

#[test]
fn access_spec_reads_tid_memory() {
    let s = line_scenario(&[1.0]);
    let t = read_by_access_spec(&s, 2, 2);
    assert_eq!(t.access_spec_id.map(|a| a.0), Some(9));
    let Some(OpSpecResult::C1g2Read(r)) = t.op_spec_results.first() else {
        panic!("no read result in {t:?}")
    };
    assert_eq!((r.result, r.op_spec_id), (0, 5));
    // The default TID of a scenario tag starts with Impinj's class and vendor words E280 1160.
    assert_eq!(r.read_data, vec![0xE280, 0x1160]);
}

#[test]
fn access_spec_reads_user_memory_from_the_scenario() {
    let mut s = line_scenario(&[1.0]);
    s.tags[0].user = Some("CAFEF00D1234".into());
    let t = read_by_access_spec(&s, 3, 3);
    assert_eq!(t.access_spec_id.map(|a| a.0), Some(9));
    let Some(OpSpecResult::C1g2Read(r)) = t.op_spec_results.first() else {
        panic!("no read result in {t:?}")
    };
    assert_eq!((r.result, r.op_spec_id), (0, 5));
    assert_eq!(r.read_data, vec![0xCAFE, 0xF00D, 0x1234]);
}

#[test]
fn impinj_fixed_frequency_list_pins_the_channels() {
    let s = line_scenario(&[1.0, 2.0]);
    let mut v = VirtualReader::new(&s);
    let mut spec = rospec(
        1,
        vec![1],
        ro_null(),
        ai_null(),
        full_report(RoReportTriggerType::UponNTagsOrEndOfAiSpec, 1),
    );
    let list = |channels: Vec<u16>| {
        vec![AntennaConfiguration {
            antenna_id: 1,
            c1g2_inventory_command: vec![C1g2InventoryCommand {
                custom: vec![Custom::ImpinjFixedFrequencyList(ImpinjFixedFrequencyList {
                    fixed_frequency_mode: 2,
                    channel_list: channels,
                    ..Default::default()
                })],
                ..Default::default()
            }],
            ..Default::default()
        }]
    };
    // Channel 9 does not exist in the 4-channel ETSI table.
    let mut bad = spec.clone();
    if let SpecParameter::AiSpec(ai) = &mut bad.specs[0] {
        ai.inventory_parameter_specs[0].antenna_configuration = list(vec![9]);
    }
    let add = AddRospec {
        ro_spec: bad,
        ..Default::default()
    };
    assert_eq!(v.status(add), llrp::StatusCode::M_ParameterError);
    if let SpecParameter::AiSpec(ai) = &mut spec.specs[0] {
        ai.inventory_parameter_specs[0].antenna_configuration = list(vec![3]);
    }
    let add = AddRospec {
        ro_spec: spec,
        ..Default::default()
    };
    assert_eq!(v.status(add), StatusCode::M_Success);
    let enable = EnableRospec {
        ro_spec_id: 1,
        ..Default::default()
    };
    assert_eq!(v.status(enable), StatusCode::M_Success);
    let (tags, _) = v.collect_reports(600_000_000, |t| t.len() >= 50);
    assert!(tags.len() >= 50);
    assert!(tags.iter().all(|t| t.channel_index.map(|c| c.0) == Some(3)));
}
