//! Interop with sllurp 2.0.1: the frames sllurp's own encoder sends during `sllurp inventory`
//! (captured by `scripts/interop/sllurp_encode.py`, path in `LLRP_SLLURP_FRAMES`) must decode
//! into typed messages and re-encode byte for byte. Run by `./scripts/test`.

use llrp::enums::{AiSpecStopTriggerType, RoReportTriggerType, RoSpecStartTriggerType};
use llrp::message::MessageBody;
use llrp::params::{Custom, SpecParameter};
use llrp::raw::from_hex;
use llrp::Message;

fn frames() -> Vec<(String, Vec<u8>)> {
    let path = std::env::var("LLRP_SLLURP_FRAMES").expect(
        "LLRP_SLLURP_FRAMES must name the file written by scripts/interop/sllurp_encode.py",
    );
    let text = std::fs::read_to_string(&path).expect("read sllurp frames");
    text.lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let (label, hex) = l.split_once(' ').expect("label and hex");
            (label.to_string(), from_hex(hex).expect("hex"))
        })
        .collect()
}

fn add_rospec<'a>(all: &'a [(String, Message)], label: &str) -> &'a llrp::params::RoSpec {
    let (_, m) = all
        .iter()
        .find(|(l, _)| l == label)
        .unwrap_or_else(|| panic!("no frame {label}"));
    match &m.body {
        MessageBody::AddRospec(a) => &a.ro_spec,
        other => panic!("{label} is {}", other.name()),
    }
}

#[test]
#[ignore = "needs frames captured from sllurp; run by ./scripts/test"]
fn sllurp_frames_decode_typed_and_reencode_identically() {
    let frames = frames();
    assert!(frames.len() >= 20, "only {} frames captured", frames.len());
    let mut decoded = Vec::new();
    for (label, bytes) in &frames {
        let msg = Message::decode(bytes).unwrap_or_else(|e| panic!("{label}: {e}"));
        let expected_name = label.rsplit('/').next().unwrap();
        assert_eq!(msg.name(), expected_name, "{label}");
        assert!(
            !matches!(msg.body, MessageBody::Unknown(_) | MessageBody::Custom(_)),
            "{label} decoded generically"
        );
        let json = serde_json::to_string(&msg).unwrap();
        assert!(
            !json.contains("\"extra\""),
            "{label}: untyped parameters in {json}"
        );
        let again = msg.to_bytes();
        assert_eq!(&again[..], &bytes[..], "{label}: re-encoded bytes differ");
        decoded.push((label.clone(), msg));
    }

    // Spot-check decoded values against the options each variant was run with.
    let plain = add_rospec(&decoded, "plain/ADD_ROSPEC");
    assert_eq!(plain.ro_spec_id, 1);
    assert_eq!(
        plain
            .ro_boundary_spec
            .ro_spec_start_trigger
            .ro_spec_start_trigger_type,
        RoSpecStartTriggerType::Immediate
    );
    let report = plain.ro_report_spec.as_ref().expect("ROReportSpec");
    assert_eq!(
        (report.ro_report_trigger, report.n),
        (RoReportTriggerType::UponNTagsOrEndOfAiSpec, 0)
    );
    let sel = &report.tag_report_content_selector;
    assert!(
        sel.enable_channel_index && sel.enable_last_seen_timestamp && sel.enable_tag_seen_count
    );
    assert!(!sel.enable_peak_rssi && !sel.enable_antenna_id);

    let ai = |r: &llrp::params::RoSpec| match &r.specs[0] {
        SpecParameter::AiSpec(a) => a.clone(),
        other => panic!("not an AISpec: {other:?}"),
    };
    assert_eq!(ai(plain).antenna_ids, vec![1]);
    assert_eq!(
        ai(add_rospec(&decoded, "a0/ADD_ROSPEC")).antenna_ids,
        vec![0]
    );
    assert_eq!(
        ai(add_rospec(&decoded, "a12/ADD_ROSPEC")).antenna_ids,
        vec![1, 2]
    );
    let n1 = ai(add_rospec(&decoded, "n1/ADD_ROSPEC"));
    assert_eq!(
        n1.ai_spec_stop_trigger.ai_spec_stop_trigger_type,
        AiSpecStopTriggerType::TagObservation
    );
    assert_eq!(
        n1.ai_spec_stop_trigger
            .tag_observation_trigger
            .as_ref()
            .expect("TagObservationTrigger")
            .number_of_tags,
        1
    );

    let impinj = add_rospec(&decoded, "impinj/ADD_ROSPEC");
    let custom = &impinj.ro_report_spec.as_ref().unwrap().custom;
    let Some(Custom::ImpinjTagReportContentSelector(s)) = custom.first() else {
        panic!("no Impinj content selector: {custom:?}");
    };
    assert_eq!(
        s.enable_rf_phase_angle
            .as_ref()
            .map(|p| p.rf_phase_angle_mode),
        Some(1)
    );
    assert_eq!(
        s.enable_peak_rssi.as_ref().map(|p| p.peak_rssi_mode),
        Some(1)
    );

    let search = ai(add_rospec(&decoded, "search2/ADD_ROSPEC"));
    let cmd =
        &search.inventory_parameter_specs[0].antenna_configuration[0].c1g2_inventory_command[0];
    assert!(cmd.custom.iter().any(
        |c| matches!(c, Custom::ImpinjInventorySearchMode(m) if m.inventory_search_mode == 2)
    ));
}
