//! Reader-level checks that need the whole state machine.

use std::sync::Arc;

use llrp::enums::*;
use llrp::message::*;
use llrp::params::*;
use llrp::Message;

use super::{Output, Reader, ReaderProfile};
use crate::physics::Model;
use crate::scenario::Scenario;

const ON_AI_END: RoReportTriggerType = RoReportTriggerType::UponNTagsOrEndOfAiSpec;
const ON_RO_END: RoReportTriggerType = RoReportTriggerType::UponNTagsOrEndOfRoSpec;

fn s2_reader() -> Reader {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../fixtures/scenarios/s2.json"
    );
    let s = Scenario::load(std::path::Path::new(path)).expect("S2 loads");
    let model = Arc::new(Model::new(&s, 0));
    let profile = ReaderProfile::from_scenario(&s, 0, &model);
    Reader::new(profile, model, 1_700_000_000_000_000)
}

fn add_rospec(
    antennas: Vec<u16>,
    ai_stop: AiSpecStopTrigger,
    power_index: u16,
    trigger: RoReportTriggerType,
    n: u16,
) -> Message {
    let spec = RoSpec::immediate(1, antennas)
        .with_ai_stop(ai_stop)
        .with_antenna_configuration(vec![AntennaConfiguration {
            antenna_id: 3,
            rf_transmitter: Some(RfTransmitter {
                hop_table_id: 1,
                channel_index: 1,
                transmit_power: power_index,
                ..Default::default()
            }),
            ..Default::default()
        }])
        .with_report(
            RoReportSpec::new(trigger, n).with_content(TagReportContentSelector {
                enable_antenna_id: true,
                enable_channel_index: true,
                enable_peak_rssi: true,
                enable_first_seen_timestamp: true,
                enable_last_seen_timestamp: true,
                enable_tag_seen_count: true,
                ..Default::default()
            }),
        );
    Message {
        version: 1,
        id: 10,
        body: AddRospec {
            ro_spec: spec,
            ..Default::default()
        }
        .into(),
    }
}

/// Everything a reader sends over `until_us` of simulated time, advanced in uneven steps.
fn session(prefetch: bool, spec: Message, until_us: u64) -> Vec<Output> {
    let mut r = s2_reader();
    r.specs.set_prefetch(prefetch);
    let mut out = r.connect(0, 0);
    out.extend(r.handle(spec, 0, 0));
    let enable = Message {
        version: 1,
        id: 11,
        body: MessageBody::EnableRospec(EnableRospec {
            ro_spec_id: 1,
            ..Default::default()
        }),
    };
    out.extend(r.handle(enable, 0, 0));
    let steps = [37_000, 100_000, 3_000, 250_000, 24_999, 1_000_000];
    let mut t = 0;
    let mut k = 0;
    while t < until_us {
        t += steps[k % steps.len()];
        k += 1;
        out.extend(r.advance(t, 0));
    }
    out
}

fn reads(out: &[Output]) -> usize {
    out.iter()
        .map(|o| match o {
            Output::Send(Message {
                body: MessageBody::RoAccessReport(r),
                ..
            }) => r.tag_report_data.len(),
            _ => 0,
        })
        .sum()
}

#[test]
fn prefetched_physics_sends_exactly_what_direct_physics_sends() {
    // All antennas with a per-antenna power (antenna 3 at index 1, the lowest), one report per
    // read; N = 100 on two antennas; an AISpec that ends at its first tag and restarts (what
    // sllurp's -n 1 asks for). The robot drives past the banners meanwhile.
    let first_tag = AiSpecStopTrigger::n_tags(1, 0);
    for spec in [
        add_rospec(vec![0], AiSpecStopTrigger::null(), 1, ON_RO_END, 1),
        add_rospec(vec![2, 3], AiSpecStopTrigger::null(), 1, ON_AI_END, 100),
        add_rospec(vec![0], first_tag, 1, ON_RO_END, 1),
    ] {
        let direct = session(false, spec.clone(), 120_000_000);
        let prefetched = session(true, spec, 120_000_000);
        assert!(reads(&direct) > 1_000, "{} reads", reads(&direct));
        assert_eq!(direct.len(), prefetched.len());
        assert!(
            direct == prefetched,
            "the prefetch changed what the reader sends"
        );
    }
}

/// For every region, `llrp::units::HopTable` (the crate's helper) and the table the reader
/// advertises in its RegulatoryCapabilities give the same frequency for every ChannelIndex,
/// and so does the table the physics reports reads in.
#[test]
fn units_helper_and_advertised_hop_table_agree_in_every_region() {
    use crate::scenario::Region;
    use llrp::units::HopTable;

    let custom = vec![915_250, 902_750, 927_250];
    let cases = [
        (Region::Fcc, Some(HopTable::fcc())),
        (Region::Etsi, Some(HopTable::etsi())),
        (
            Region::Custom {
                hop_table_khz: custom.clone(),
            },
            None,
        ),
    ];
    for (region, helper) in cases {
        let mut s = Scenario::default_s1();
        s.readers[0].region = region.clone();
        let model = Arc::new(Model::new(&s, 0));
        let profile = ReaderProfile::from_scenario(&s, 0, &model);
        let caps = super::caps::capabilities(&profile, CapabilitiesRequest::RegulatoryCapabilities)
            .expect("RequestedData 3 is valid");
        let regulatory = caps
            .regulatory_capabilities
            .expect("regulatory capabilities requested");
        let advertised =
            HopTable::from_capabilities(&regulatory, 1).expect("the reader advertises a table");
        let expected = helper.unwrap_or(HopTable {
            id: 1,
            frequencies_khz: custom.clone(),
        });
        assert!(!expected.frequencies_khz.is_empty());
        for k in 1..=expected.frequencies_khz.len() as u16 {
            let f = expected.frequency_khz(k);
            assert_eq!(
                advertised.frequency_khz(k),
                f,
                "{region:?}: ChannelIndex {k}"
            );
            let physics = model.frequencies_khz().get(usize::from(k) - 1).copied();
            assert_eq!(physics, f, "{region:?}: physics, ChannelIndex {k}");
        }
        assert_eq!(
            advertised.frequency_khz(expected.frequencies_khz.len() as u16 + 1),
            None
        );
    }
}
