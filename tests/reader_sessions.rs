//! Gen2 sessions, search targets, RF modes and tag population as the simulated reader honours
//! them (docs/measurement.md, "Read rate"): driven in process with a virtual clock, with the
//! ROSpecs the project's client builds (`InventorySpec`).

mod common;

use std::collections::BTreeMap;

use common::virtual_reader::VirtualReader;
use common::*;
use llrp::message::*;
use llrp_gateway::net::client::InventorySpec;
use llrp_gateway::scenario::Scenario;

/// `n` static tags on a 1 m grid facing one fixed antenna, 2–4 m out.
fn field(n: usize) -> Scenario {
    let tags: Vec<String> = (0..n)
        .map(|i| {
            let (x, y, z) = (
                2.0 + (i % 3) as f64 * 0.6,
                -1.0 + ((i / 3) % 5) as f64 * 0.5,
                0.6 + (i / 15) as f64 * 0.02,
            );
            format!(r#"{{"epc": "E2000000000000000000{i:04X}", "position": [{x}, {y}, {z}]}}"#)
        })
        .collect();
    let json = format!(
        r#"{{
      "name": "field", "seed": 4,
      "world": {{ "min": [-2, -5, 0], "max": [10, 5, 3] }},
      "tags": [{}],
      "readers": [{{ "name": "r", "listen": "127.0.0.1:0", "region": "etsi",
        "antennas": [{{ "mount": {{ "type": "fixed", "pose": {{ "position": [0, 0, 1] }} }},
                       "beamwidth_deg": 120 }}] }}]
    }}"#,
        tags.join(",")
    );
    Scenario::from_json(&json).expect("field scenario is valid")
}

/// A virtual reader running an inventory with `spec` (ADD, ENABLE and START_ROSPEC, each
/// answered with Success), `antennas` antennas for its antenna configuration.
fn started(scenario: &Scenario, spec: InventorySpec, antennas: u16) -> VirtualReader {
    let mut v = VirtualReader::new(scenario);
    let rospec = spec.rospec(antennas);
    let id = rospec.ro_spec_id;
    let add = AddRospec {
        ro_spec: rospec,
        ..Default::default()
    };
    assert_eq!(v.status(add), StatusCode::M_Success);
    for body in [
        MessageBody::from(EnableRospec {
            ro_spec_id: id,
            ..Default::default()
        }),
        MessageBody::from(StartRospec {
            ro_spec_id: id,
            ..Default::default()
        }),
    ] {
        assert_eq!(v.status(body), StatusCode::M_Success);
    }
    v
}

/// Per tag (EPC's last two bytes), the FirstSeenTimestampUTC of every read of an inventory
/// with `spec` over `seconds` of simulated time.
fn reads(scenario: &Scenario, spec: InventorySpec, seconds: u64) -> BTreeMap<u16, Vec<u64>> {
    let mut v = started(scenario, spec, 1);
    let (tags, _) = v.collect_reports(seconds * 1_000_000, |_| false);
    let mut per: BTreeMap<u16, Vec<u64>> = BTreeMap::new();
    for t in &tags {
        let e = t.epc_bytes();
        let key = u16::from_be_bytes([e[e.len() - 2], e[e.len() - 1]]);
        per.entry(key)
            .or_default()
            .push(t.first_seen_timestamp_utc.expect("timestamp").0);
    }
    per
}

fn spec(session: u8, search_mode: Option<u16>, mode: Option<u16>) -> InventorySpec {
    InventorySpec {
        session: Some(session),
        search_mode,
        mode,
        report_every: 1,
        keepalive_ms: 0,
        ..Default::default()
    }
}

#[test]
fn session_2_single_target_reads_each_tag_once_while_it_stays_powered() {
    let per = reads(&field(6), spec(2, Some(1), None), 60);
    assert_eq!(per.len(), 6, "every tag read: {per:?}");
    assert!(per.values().all(|v| v.len() == 1), "{per:?}");
}

#[test]
fn session_1_single_target_rereads_after_the_persistence() {
    let per = reads(&field(3), spec(1, Some(1), None), 60);
    assert_eq!(per.len(), 3);
    for (tag, times) in &per {
        assert!(
            times.len() >= 10,
            "tag {tag}: {} reads in 60 s",
            times.len()
        );
        for w in times.windows(2) {
            let gap = w[1] - w[0];
            // Gen2 session 1: 0.5 s < persistence < 5 s (plus up to an epoch to be read).
            assert!(
                (500_000..=5_100_000).contains(&gap),
                "tag {tag}: reads {gap} µs apart"
            );
        }
    }
}

#[test]
fn dual_target_session_0_and_the_readers_own_choice_stream() {
    for (session, search) in [(2, Some(2)), (2, None), (0, Some(1)), (1, Some(0))] {
        let per = reads(&field(3), spec(session, search, None), 5);
        assert_eq!(per.len(), 3, "session {session} {search:?}");
        for (tag, times) in &per {
            assert!(
                times.len() >= 100,
                "session {session} {search:?}, tag {tag}: {} reads in 5 s",
                times.len()
            );
        }
    }
}

#[test]
fn a_faster_rf_mode_reads_more() {
    let total = |mode| -> usize {
        reads(&field(10), spec(0, None, Some(mode)), 3)
            .values()
            .map(Vec::len)
            .sum()
    };
    let (fm0, m4, m8) = (total(0), total(2), total(3));
    assert!(fm0 > 3 * m4, "mode 0 {fm0}, mode 2 {m4}");
    assert!(m4 > m8, "mode 2 {m4}, mode 3 {m8}");
}

#[test]
fn reads_per_second_follow_the_documented_population_curve() {
    // docs/measurement.md, Mode 2: 244 reads/s for one tag, 217 for 10 and 100 tags; per tag
    // 1/n of that. One antenna, so the reader's time is all this antenna's.
    for (n, documented) in [(1usize, 244.0), (10, 217.0), (100, 217.0)] {
        let seconds = 10;
        let per = reads(&field(n), spec(0, None, Some(2)), seconds);
        assert_eq!(per.len(), n, "{n} tags: every tag read");
        let total: usize = per.values().map(Vec::len).sum();
        let rate = total as f64 / seconds as f64;
        assert!(
            (rate - documented).abs() < 0.1 * documented,
            "{n} tags: {rate} reads/s, documented {documented}"
        );
        let fewest = per.values().map(Vec::len).min().unwrap_or(0) as f64 / seconds as f64;
        // Each 25 ms dwell reads a few of 100 tags: per tag about Poisson, so the fewest
        // gets well under the mean, yet nobody is starved.
        assert!(
            fewest > 0.3 * rate / n as f64,
            "{n} tags: fewest {fewest}/s"
        );
    }
}

#[test]
fn session_2_single_target_reads_a_tag_again_after_it_was_away() {
    // A tag on a conveyor loop: in the field for a few seconds, then 20 m away and back.
    let json = r#"{
      "name": "loop", "seed": 5,
      "world": { "min": [-2, -5, 0], "max": [30, 5, 3] },
      "tags": [ { "epc": "E20000000000000000000001", "position": [2, 0, 1],
                  "path": { "waypoints": [[2, 0, 1], [25, 0, 1], [2, 0, 1]], "speed": 2.0,
                            "loop_path": true } } ],
      "readers": [{ "name": "r", "listen": "127.0.0.1:0", "region": "etsi",
        "antennas": [{ "mount": { "type": "fixed", "pose": { "position": [0, 0, 1] } } }] }]
    }"#;
    let s = Scenario::from_json(json).expect("valid");
    let per = reads(&s, spec(2, Some(1), None), 60);
    let times = &per[&1];
    // One lap is 23 s: read once per visit, not on every round while it stays in the field.
    assert!((2..=4).contains(&times.len()), "{times:?}");
    assert!(
        times.windows(2).all(|w| w[1] - w[0] > 10_000_000),
        "{times:?}"
    );
}

#[test]
fn an_antenna_facing_no_tag_moves_on_after_one_empty_round() {
    // Antenna 1 faces three tags; antenna 2 looks the other way at nothing.
    let json = r#"{
      "name": "two", "seed": 6,
      "world": { "min": [-10, -5, 0], "max": [10, 5, 3] },
      "tags": [ { "epc": "E20000000000000000000001", "position": [2, 0, 1] },
                { "epc": "E20000000000000000000002", "position": [2.5, 0.4, 1] },
                { "epc": "E20000000000000000000003", "position": [3, -0.4, 1] } ],
      "readers": [{ "name": "r", "listen": "127.0.0.1:0", "region": "etsi", "antennas": [
        { "mount": { "type": "fixed", "pose": { "position": [0, 0, 1], "yaw_deg": 0 } } },
        { "mount": { "type": "fixed", "pose": { "position": [0, 0, 1], "yaw_deg": 180 } } } ] }]
    }"#;
    let s = Scenario::from_json(json).expect("valid");
    let count = |antennas: Vec<u16>| -> usize {
        let spec = InventorySpec {
            antennas,
            keepalive_ms: 0,
            ..Default::default()
        };
        reads(&s, spec, 10).values().map(Vec::len).sum()
    };
    let (alone, with_empty) = (count(vec![1]), count(vec![1, 2]));
    // A fixed 25 ms dwell on the empty antenna would halve the reads. One empty round (about
    // a millisecond in the default mode) costs a few per cent, and leaving antenna 1 cuts its
    // round in progress at every dwell's end (alone, its rounds run on): about a tenth.
    assert!(
        with_empty as f64 > 0.8 * alone as f64 && with_empty <= alone,
        "antenna 1 alone {alone}, with the empty antenna 2 {with_empty}"
    );
}

#[test]
fn a_tari_outside_the_modes_range_is_refused() {
    let mut v = VirtualReader::new(&field(1));
    for (tari, ok) in [(1u16, false), (20_000, true), (26_000, false), (0, true)] {
        let mut rospec = spec(0, None, Some(1000)).rospec(1);
        rospec.ro_spec_id = u32::from(tari) + 1;
        for spec in &mut rospec.specs {
            let llrp::params::SpecParameter::AiSpec(ai) = spec else {
                continue;
            };
            for ips in &mut ai.inventory_parameter_specs {
                for c in &mut ips.antenna_configuration {
                    for cmd in &mut c.c1g2_inventory_command {
                        if let Some(rf) = cmd.c1g2_rf_control.as_mut() {
                            rf.tari = tari;
                        }
                    }
                }
            }
        }
        let code = v.status(AddRospec {
            ro_spec: rospec,
            ..Default::default()
        });
        assert_eq!(code == StatusCode::M_Success, ok, "Tari {tari}: {code:?}");
    }
}

/// Every read (EPC's last byte, antenna, first-seen µs) of 4 s of inventory with `spec` on a
/// reader advanced in steps of `step_us` of simulated time.
fn stepped(s: &Scenario, spec: InventorySpec, step_us: u64) -> Vec<(u8, u16, u64)> {
    let mut v = started(s, spec, 2);
    let end = v.now_us() + 4_000_000;
    while v.now_us() < end {
        v.run_for(step_us.min(end - v.now_us()));
    }
    v.take_reports()
        .into_iter()
        .flatten()
        .map(|t| {
            (
                *t.epc_bytes().last().expect("EPC"),
                t.antenna_id.map_or(0, |a| a.0),
                t.first_seen_timestamp_utc.map_or(0, |u| u.0),
            )
        })
        .collect()
}

#[test]
fn reads_do_not_depend_on_how_the_reader_is_stepped() {
    // Antenna 2 faces nothing (it moves on after an empty round); session 1 single target
    // carries flags from epoch to epoch; dual target is the pure, look-ahead path.
    let json = r#"{
      "name": "steps", "seed": 8,
      "world": { "min": [-10, -5, 0], "max": [10, 5, 3] },
      "tags": [ { "epc": "E20000000000000000000001", "position": [2, 0, 1] },
                { "epc": "E20000000000000000000002", "position": [2.5, 0.4, 1] },
                { "epc": "E20000000000000000000003", "position": [3, -0.4, 1] } ],
      "readers": [{ "name": "r", "listen": "127.0.0.1:0", "region": "etsi", "antennas": [
        { "mount": { "type": "fixed", "pose": { "position": [0, 0, 1], "yaw_deg": 0 } } },
        { "mount": { "type": "fixed", "pose": { "position": [0, 0, 1], "yaw_deg": 180 } } } ] }]
    }"#;
    let s = Scenario::from_json(json).expect("valid");
    for (session, search) in [(1, Some(1)), (2, Some(2))] {
        let make = || InventorySpec {
            session: Some(session),
            search_mode: search,
            keepalive_ms: 0,
            ..Default::default()
        };
        let coarse = stepped(&s, make(), 100_000);
        let fine = stepped(&s, make(), 1_234);
        assert!(
            coarse.len() > 3,
            "session {session}: {} reads",
            coarse.len()
        );
        assert_eq!(coarse, fine, "session {session} {search:?}");
    }
}
