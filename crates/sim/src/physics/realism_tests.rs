//! Model-level tests of the measurement model: structured phase offsets, the π ambiguity,
//! tag orientation, per-tag sensitivity and the growth of the angle-dependent phase error off
//! boresight, each against its closed form.

use std::f64::consts::{PI, TAU};

use super::*;
use crate::scenario::Scenario;

/// One fixed antenna at the origin facing +x, FCC, and the given tags (JSON objects); the
/// antenna gets `antenna` merged in.
fn scene(tags: serde_json::Value, antenna: serde_json::Value, variation: f64) -> Model {
    let mut a = serde_json::json!({
        "mount": { "type": "fixed", "pose": { "position": [0, 0, 1] } }
    });
    if let (Some(a), Some(extra)) = (a.as_object_mut(), antenna.as_object()) {
        a.extend(extra.clone());
    }
    let v = serde_json::json!({
        "name": "realism",
        "seed": 3,
        "world": { "min": [-10, -10, 0], "max": [10, 10, 3] },
        "tags": tags,
        "tag_variation": { "sensitivity_sigma_db": variation, "backscatter_sigma_db": variation },
        "readers": [ { "name": "r", "region": "fcc", "antennas": [a] } ]
    });
    Model::new(&Scenario::from_json(&v.to_string()).expect("valid"), 0)
}

fn tag(i: u32, position: [f64; 3]) -> serde_json::Value {
    serde_json::json!({ "epc": format!("E2000000000000000000{i:04X}"), "position": position })
}

#[test]
fn structured_offsets_are_linear_in_frequency_and_calibrate_out() {
    let m = scene(
        serde_json::json!([tag(1, [2.0, 0.0, 1.0]), tag(2, [3.0, 0.0, 1.0])]),
        serde_json::json!({ "cable_delay_ns": 20.0 }),
        1.0,
    );
    let table = m.frequencies_khz().to_vec();
    // φ0(tag 0) − φ0(tag 1) is the same on every channel: the tags' own parts only.
    let diff = |c: u16| (m.phase_offset(1, 0, c) - m.phase_offset(1, 1, c)).rem_euclid(TAU);
    let d1 = diff(1);
    assert!((2..=50).all(|c| (diff(c) - d1).abs() < 1e-9 || (diff(c) - d1).abs() > TAU - 1e-9));
    // Across channels φ0 moves by 4π·Δf·τ: 20 ns of cable.
    for c in 2..=50u16 {
        let df = (f64::from(table[usize::from(c) - 1]) - f64::from(table[0])) * 1e3;
        let expected = (4.0 * PI * df * 20e-9).rem_euclid(TAU);
        let got = (m.phase_offset(1, 0, c) - m.phase_offset(1, 0, 1)).rem_euclid(TAU);
        let err = (got - expected).abs();
        assert!(
            err.min(TAU - err) < 1e-9,
            "channel {c}: {got} vs {expected}"
        );
    }
    // Frequency-domain ranging: with the cable's delay known, the phase slope over the
    // channels gives the distance (noise-free reads on two channels 10 MHz apart).
    let quiet = scene(
        serde_json::json!([tag(1, [2.0, 0.0, 1.0])]),
        serde_json::json!({ "cable_delay_ns": 20.0, "phase_noise_rad": 0.0 }),
        0.0,
    );
    let read_on = |c: u16| quiet.inventory_on(1, 0, 50_000, None, Some(c))[0];
    let channel_of = |khz: u32| {
        1 + table
            .iter()
            .position(|&f| f == khz)
            .expect("an FCC channel") as u16
    };
    let (a, b) = (channel_of(902_750), channel_of(912_750));
    let (ra, rb) = (read_on(a), read_on(b));
    let df = f64::from(rb.frequency_khz - ra.frequency_khz) * 1e3;
    let slope = (rb.phase_rad - ra.phase_rad).rem_euclid(TAU);
    // dφ/df = 4π(D/c + τ); 10 MHz keeps it within one turn for D + cτ < 15 m.
    let d = slope / (4.0 * PI * df) * phase::SPEED_OF_LIGHT - 20e-9 * phase::SPEED_OF_LIGHT;
    assert!((d - 2.0).abs() < 1e-6, "{d}");
}

#[test]
fn random_per_channel_offsets_stay_available() {
    let m = scene(
        serde_json::json!([tag(1, [2.0, 0.0, 1.0])]),
        serde_json::json!({ "phase_offsets": "random_per_channel" }),
        1.0,
    );
    let offsets: Vec<f64> = (1..=50).map(|c| m.phase_offset(1, 0, c)).collect();
    assert!(offsets.iter().all(|o| (0.0..TAU).contains(o)));
    // No linear structure: second differences are not all ~0.
    let curved = offsets
        .windows(3)
        .filter(|w| (w[2] - 2.0 * w[1] + w[0]).abs() > 0.01)
        .count();
    assert!(curved > 40, "{curved}");
}

#[test]
fn pi_ambiguity_flips_about_half_of_the_reads() {
    let antenna = |flip: bool| serde_json::json!({ "phase_noise_rad": 0.0, "phase_pi_ambiguity": flip, "fixed": 0 });
    let make = |flip: bool| {
        let mut a = antenna(flip);
        a.as_object_mut().map(|o| o.remove("fixed"));
        scene(serde_json::json!([tag(1, [2.0, 0.0, 1.0])]), a, 0.0)
    };
    let (plain, flipped) = (make(false), make(true));
    let a = plain.inventory_on(1, 0, 4_000_000, None, Some(1));
    let b = flipped.inventory_on(1, 0, 4_000_000, None, Some(1));
    assert_eq!(a.len(), b.len());
    assert!(a.len() > 500, "{}", a.len());
    let mut shifted = 0;
    for (x, y) in a.iter().zip(&b) {
        let d = (y.phase_rad - x.phase_rad).rem_euclid(TAU);
        let (zero, pi) = (d.min(TAU - d), (d - PI).abs());
        assert!(zero < 1e-9 || pi < 1e-9, "{d}");
        shifted += usize::from(pi < 1e-9);
    }
    let share = shifted as f64 / a.len() as f64;
    assert!((share - 0.5).abs() < 0.06, "{share}");
}

#[test]
fn orientation_nulls_end_on_tags_and_costs_the_polarisation_loss() {
    // Two tags 3 m out: one with its dipole vertical (broadside to the antenna), one along
    // the line of sight (end-on: the dipole's null), and one without orientation.
    let tags = serde_json::json!([
        { "epc": "E20000000000000000000001", "position": [3.0, 0.5, 1.0], "orientation": [0, 0, 1] },
        { "epc": "E20000000000000000000002", "position": [3.0, 0.0, 1.0], "orientation": [1, 0, 0] },
        { "epc": "E20000000000000000000003", "position": [3.0, -0.5, 1.0] }
    ]);
    let quiet = serde_json::json!({ "rssi_sigma_db": 0.0, "rssi_resolution_db": 0.0 });
    let m = scene(tags, quiet, 0.0);
    let reads = m.inventory_on(1, 0, 3_000_000, None, Some(1));
    let of = |t: usize| reads.iter().filter(|r| r.tag == t).collect::<Vec<_>>();
    assert!(of(1).is_empty(), "an end-on dipole was read");
    let (broadside, aligned) = (of(0), of(2));
    assert!(!broadside.is_empty() && !aligned.is_empty());
    // Broadside: the pattern's peak, minus 3 dB of polarisation on each link (6 dB of RSSI)
    // against the aligned tag at the mirror position.
    let gap = aligned[0].rssi_dbm - broadside[0].rssi_dbm;
    assert!((gap - 20.0 * 2f64.log10()).abs() < 1e-6, "{gap}");
}

#[test]
fn less_sensitive_tags_drop_out_first() {
    // Ten tags side by side at the same distance, each 1 dB less sensitive than the last:
    // lowering the power drops them in that order.
    let tags: Vec<serde_json::Value> = (0..10)
        .map(|i| {
            let mut t = tag(i + 1, [4.0, -0.45 + 0.1 * f64::from(i), 1.0]);
            t["sensitivity_offset_db"] = serde_json::json!(f64::from(i));
            t
        })
        .collect();
    let m = scene(serde_json::Value::Array(tags), serde_json::json!({}), 0.0);
    let mut last_count = usize::MAX;
    for power in [30.0, 26.0, 22.0, 18.0] {
        let reads = m.inventory_on(1, 0, 2_000_000, Some(power), Some(1));
        let read: Vec<usize> = (0..10)
            .filter(|&t| reads.iter().any(|r| r.tag == t))
            .collect();
        // Those read are a prefix of the sensitivity order.
        assert_eq!(read, (0..read.len()).collect::<Vec<_>>(), "{power} dBm");
        assert!(read.len() <= last_count);
        last_count = read.len();
    }
    assert!(last_count < 10);
}

#[test]
fn the_angle_dependent_phase_error_grows_off_the_antennas_boresight() {
    // Tags 2 m from an antenna facing +x, every 10° from −70° to +70°; noise-free reads.
    let tags: Vec<serde_json::Value> = (0..15u32)
        .map(|i| {
            let a = (f64::from(i) * 10.0 - 70.0).to_radians();
            tag(i, [2.0 * a.cos(), 2.0 * a.sin(), 1.0])
        })
        .collect();
    let phase_of = |pattern: f64, growth_deg: f64| -> Vec<f64> {
        let a = serde_json::json!({
            "phase_noise_rad": 0.0, "phase_resolution_bits": 16, "beamwidth_deg": 170.0,
            "phase_pattern_rad": pattern, "phase_pattern_growth_deg": growth_deg
        });
        let m = scene(serde_json::json!(tags), a, 0.0);
        let reads = m.inventory_on(1, 0, 2_000_000, None, Some(1));
        (0..tags.len())
            .map(|t| match reads.iter().find(|r| r.tag == t) {
                Some(r) => r.phase_rad,
                None => panic!("tag {t} was not read"),
            })
            .collect()
    };
    let wrap = |x: f64| (x + PI).rem_euclid(TAU) - PI;
    let (none, flat, grown) = (phase_of(0.0, 0.0), phase_of(0.3, 0.0), phase_of(0.3, 25.0));
    let mut checked = 0;
    for t in 0..tags.len() {
        // The same seeded pattern, with and without the growth.
        let p = wrap(flat[t] - none[t]);
        let g = wrap(grown[t] - none[t]);
        let theta = (f64::from(t as u32) * 10.0 - 70.0).to_radians();
        let expected = hardware::pattern_growth(theta, 25f64.to_radians());
        if p.abs() > 0.02 && (p * expected).abs() < PI {
            assert!(
                (g / p - expected).abs() < 1e-3,
                "tag {t}: {} vs {expected}",
                g / p
            );
            checked += 1;
        }
    }
    assert!(checked >= 8, "{checked}");
}

#[test]
fn each_tag_adds_its_own_curvature_times_the_squared_angle_off_boresight() {
    // Tags 2 m from an antenna facing +x, every 10° from −60° to +60°; noise-free reads.
    let tags: Vec<serde_json::Value> = (0..13u32)
        .map(|i| {
            let a = (f64::from(i) * 10.0 - 60.0).to_radians();
            tag(i, [2.0 * a.cos(), 2.0 * a.sin(), 1.0])
        })
        .collect();
    let a = serde_json::json!({
        "phase_noise_rad": 0.0, "phase_resolution_bits": 16, "beamwidth_deg": 170.0
    });
    let model_of = |sigma: f64| {
        let mut v: serde_json::Value = serde_json::json!({
            "name": "realism", "seed": 3,
            "world": { "min": [-10, -10, 0], "max": [10, 10, 3] },
            "tags": tags,
            "tag_variation": { "phase_curvature_sigma_rad": sigma },
            "readers": [ { "name": "r", "region": "fcc", "antennas": [ {
                "mount": { "type": "fixed", "pose": { "position": [0, 0, 1] } } } ] } ]
        });
        if let (Some(ant), Some(extra)) = (
            v["readers"][0]["antennas"][0].as_object_mut(),
            a.as_object(),
        ) {
            ant.extend(extra.clone());
        }
        Model::new(&Scenario::from_json(&v.to_string()).expect("valid"), 0)
    };
    let phases = |m: &Model| -> Vec<f64> {
        let reads = m.inventory_on(1, 0, 2_000_000, None, Some(1));
        (0..tags.len())
            .map(|t| match reads.iter().find(|r| r.tag == t) {
                Some(r) => r.phase_rad,
                None => panic!("tag {t} was not read"),
            })
            .collect()
    };
    let (flat, curved) = (model_of(0.0), model_of(2.0));
    let (p0, p1) = (phases(&flat), phases(&curved));
    let wrap = |x: f64| (x + PI).rem_euclid(TAU) - PI;
    let mut drawn = Vec::new();
    for t in 0..tags.len() {
        let a = curved.tags[t].radio.phase_curvature_rad;
        // Without curvature nothing else of the tag changed.
        assert_eq!(
            flat.tags[t].radio.sensitivity_db,
            curved.tags[t].radio.sensitivity_db
        );
        assert_eq!(flat.tags[t].radio.phase_curvature_rad, 0.0);
        let theta = (f64::from(t as u32) * 10.0 - 60.0).to_radians();
        let expected = wrap(a * theta * theta);
        assert!(
            (wrap(p1[t] - p0[t]) - expected).abs() < 1e-6,
            "tag {t}: {} vs {expected}",
            wrap(p1[t] - p0[t])
        );
        drawn.push(a);
    }
    // Drawn per tag: they differ, with about the σ asked for (13 draws).
    let rms = (drawn.iter().map(|a| a * a).sum::<f64>() / drawn.len() as f64).sqrt();
    assert!(rms > 1.0 && rms < 3.5, "{rms}");
    assert!(drawn.windows(2).all(|w| w[0] != w[1]));
}
