//! Unit tests of the field: every classification, fast-test decision and kept decision
//! against the exact evaluation, on the fixtures and on a scenario where everything moves.

use super::near::Near;
use super::{amplitude_threshold, reach_m, Bucket, GainTable, MAX_SPAN_US};
use crate::physics::antenna::{Lobe, Pattern};
use crate::physics::geometry::{distance, norm};
use crate::physics::multipath::{power_gain_with, Aim, Plane};
use crate::physics::Model;
use crate::scenario::Scenario;

/// Exact membership of `tag` at `t_us` on a wavelength, as listing the field in full does.
fn exact(m: &Model, antenna: u16, tx: f64, t_us: u64, lambda: f64, tag: usize) -> bool {
    let spec = &m.antennas[usize::from(antenna) - 1].spec;
    let aim = Aim::new(&m.antenna_pose(antenna, t_us));
    let position = m.tag_position(tag, t_us);
    let by_margin = distance(aim.position, position) <= reach_m(spec)
        && m.margin_with(antenna, tag, &aim, position, lambda, tx, true)
            .1
            >= 0.0;
    let mut b = Bucket {
        antenna,
        t_us,
        wavelength_m: lambda,
        threshold: (amplitude_threshold(spec, tx) / lambda).powi(2),
        amplitude: amplitude_threshold(spec, tx) / lambda,
        reach: reach_m(spec),
        ..Default::default()
    };
    // The linear test agrees with the margin in dB.
    assert_eq!(m.in_field(&mut b, tag), by_margin, "tag {tag} at {t_us} µs");
    by_margin
}

/// Every tag a classification calls in (out) is in (out of) the field at every bucket
/// start of its interval, on the first, last and middle channel; returns how many tags
/// were decided and how many left undecided.
fn check(m: &Model, tx: f64, starts: impl Iterator<Item = u64>) -> (usize, usize) {
    let (mut decided, mut undecided) = (0, 0);
    let table = m.frequencies_khz().len().max(1) as u16;
    for t in starts {
        for antenna in 1..=m.antenna_count() {
            let c = m.classify(antenna, tx, t);
            assert!(c.t0_us <= t && t < c.t1_us);
            undecided += c.undecided.len();
            let bucket = crate::physics::inventory::FIELD_BUCKET_US;
            // An interval that never ends is probed an hour on.
            let end = c.t1_us.min(c.t0_us + 3_600_000_000);
            let probes = [
                c.t0_us,
                t,
                (c.t0_us + end) / 2 / bucket * bucket,
                end - bucket,
            ];
            for probe in probes {
                for ch in [1, table / 2 + 1, table] {
                    let lambda = m.wavelength_m(ch);
                    if let Some(field) = c.at_rest.get(usize::from(ch) - 1) {
                        let exact: Vec<usize> = (0..m.tag_count())
                            .filter(|&tag| exact(m, antenna, tx, probe, lambda, tag))
                            .collect();
                        assert_eq!(field, &exact, "antenna {antenna} at rest, t {probe}");
                    }
                    for tag in 0..m.tag_count() {
                        let inside = c.inside.binary_search(&tag).is_ok();
                        let maybe = c.undecided.binary_search(&tag).is_ok();
                        if maybe {
                            continue;
                        }
                        decided += 1;
                        assert_eq!(
                            exact(m, antenna, tx, probe, lambda, tag),
                            inside,
                            "antenna {antenna}, tag {tag}, t {probe} µs, channel {ch}"
                        );
                    }
                }
            }
        }
    }
    (decided, undecided)
}

fn fixture(name: &str) -> Scenario {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/scenarios")
        .join(format!("{name}.json"));
    Scenario::load(&path).expect("fixture loads")
}

#[test]
fn classification_agrees_with_exact_evaluation_on_the_fixtures() {
    for (name, horizon_s, tx) in [("s1", 50, 30.0), ("s2", 250, 27.0), ("s2", 120, 20.0)] {
        let s = fixture(name);
        let m = Model::new(&s, 0);
        let (decided, undecided) = check(&m, tx, (0..horizon_s).map(|k| k * 1_000_000));
        // The bounds must decide most tags, or they save nothing.
        assert!(decided > 4 * undecided, "{name}: {decided} vs {undecided}");
    }
    let s = fixture("s3");
    let m = Model::new(&s, 0);
    check(&m, 30.0, (0..300).map(|k| k * 1_370_000));
}

#[test]
fn fields_at_rest_are_exact() {
    // S2's robot stops after 240 s; S1's after 44 s.
    for (name, from_s) in [("s2", 245), ("s1", 40)] {
        let m = Model::new(&fixture(name), 0);
        check(&m, 27.0, (from_s..from_s + 20).map(|k| k * 1_000_000));
        let late = 10_000_000_000;
        for antenna in 1..=m.antenna_count() {
            let c = m.classify(antenna, 27.0, late);
            assert_eq!(c.t1_us, u64::MAX, "{name}: the robot rests");
            assert_eq!(c.at_rest.len(), m.frequencies_khz().len());
            // Links served from the classification are those computed afresh.
            let (mut held, mut bucket) = (None, Bucket::default());
            m.open_bucket(antenna, 27.0, late, 1, &mut held, &mut bucket);
            assert!(bucket.rest.is_some());
            let lambda = m.wavelength_m(1);
            for tag in 0..m.tag_count() {
                for t in [late + 1234, 2 * late] {
                    let aim = Aim::new(&m.antenna_pose(antenna, t));
                    let fresh = m.margin_with(
                        antenna,
                        tag,
                        &aim,
                        m.tag_position(tag, t),
                        lambda,
                        27.0,
                        true,
                    );
                    assert_eq!(m.link(&bucket, antenna, tag, t, 1, 27.0, true), fresh);
                }
                // The Doppler shortcut gives what the central difference gives.
                let range = |t| distance(m.antenna_position(antenna, t), m.tag_position(tag, t));
                let v_r = (range(late + 10_000) - range(late - 10_000)) / 0.02;
                assert_eq!(
                    m.doppler_hz(antenna, tag, late, lambda).to_bits(),
                    crate::physics::phase::doppler_hz(v_r, lambda).to_bits()
                );
            }
        }
    }
    // A fixed antenna and still tags rest from the start; a looping tag never does.
    let v = |looping: bool| {
        serde_json::json!({
            "name": "fixed",
            "seed": 5,
            "world": { "min": [-5, -5, 0], "max": [5, 5, 3] },
            "reflectors": [ { "point": [0, 0, 0], "normal": [0, 0, 1], "coefficient": 0.5 } ],
            "tags": [
                { "epc": "E20000000000000000000001", "position": [2, 0, 1] },
                { "epc": "E20000000000000000000002", "position": [3, 1, 1],
                  "path": { "waypoints": [[3, -1, 1]], "speed": 0.5, "loop_path": looping } }
            ],
            "readers": [ { "name": "r", "region": "etsi", "antennas": [
                { "mount": { "type": "fixed", "pose": { "position": [0, 0, 1] } } } ] } ]
        })
    };
    let m = Model::new(
        &Scenario::from_json(&v(false).to_string()).expect("valid"),
        0,
    );
    assert_eq!(
        m.classify(1, 30.0, 0).t1_us,
        MAX_SPAN_US,
        "the tag still moves at 0 s"
    );
    assert_eq!(m.classify(1, 30.0, 9_000_000).t1_us, u64::MAX);
    check(&m, 30.0, [0, 2_000_000, 5_000_000, 9_000_000].into_iter());
    let m = Model::new(
        &Scenario::from_json(&v(true).to_string()).expect("valid"),
        0,
    );
    assert!(m.classify(1, 30.0, 900_000_000).t1_us < u64::MAX);
}

/// A turning robot on a lift with a tilted, wide antenna; moving tags; a sloped and a
/// vertical reflector close to the path.
fn everything_moves() -> Scenario {
    let mut tags = Vec::new();
    for i in 0..40 {
        let x = 0.5 + 0.25 * f64::from(i);
        tags.push(serde_json::json!({
            "epc": format!("E2000000000000000000{i:04X}"),
            "position": [x, 2.0 + 0.1 * f64::from(i % 7), 0.3 + 0.05 * f64::from(i % 11)],
            "path": if i % 3 == 0 {
                serde_json::json!({ "waypoints": [[x, 0.5, 1.0], [x + 1.0, 3.0, 1.5]],
                                    "speed": 0.3, "loop_path": true })
            } else {
                serde_json::Value::Null
            },
            // Every fifth tag oriented (its own pattern, never bounded in), others with
            // the scenario's sensitivity spread.
            "orientation": if i % 5 == 0 {
                serde_json::json!([f64::from(i % 3), 1.0, f64::from(i % 2)])
            } else {
                serde_json::Value::Null
            }
        }));
    }
    for t in &mut tags {
        if let Some(o) = t.as_object_mut() {
            o.retain(|_, v| !v.is_null());
        }
    }
    let antenna = |yaw: f64, pitch: f64, bw: f64| {
        serde_json::json!({
            "mount": { "type": "robot", "robot": {
                "start": [1, 1, 0], "waypoints": [[6, 1], [6, 3], [2, 2.5], [9, 1]],
                "speed": 0.8, "loop_path": true,
                "vertical": { "min_z": 0.3, "max_z": 1.8, "speed": 0.4 } },
              "offset": { "position": [0.2, 0.3, 0.5], "yaw_deg": yaw, "pitch_deg": pitch } },
            "beamwidth_deg": bw, "gain_dbi": 7.0, "tx_power_dbm": 26, "range_m": 4
        })
    };
    let v = serde_json::json!({
        "name": "everything-moves",
        "seed": 11,
        "world": { "min": [-1, -1, -1], "max": [12, 6, 4] },
        "reflectors": [
            { "point": [0, 0, 0], "normal": [0, 0, 1], "coefficient": 0.6 },
            { "point": [0, 4, 0], "normal": [0, -1, 0.3], "coefficient": 0.5 },
            { "point": [10, 0, 0], "normal": [-1, 0, 0], "coefficient": 0.4 }
        ],
        "tags": tags,
        "tag_variation": { "sensitivity_sigma_db": 2.0 },
        "readers": [ { "name": "r", "region": "fcc", "antennas": [
            antenna(90.0, 0.0, 65.0), antenna(45.0, 20.0, 240.0), antenna(-30.0, -15.0, 30.0)
        ] } ]
    });
    Scenario::from_json(&v.to_string()).expect("valid scenario")
}

#[test]
fn classification_agrees_with_exact_evaluation_when_everything_moves() {
    let m = Model::new(&everything_moves(), 0);
    for tx in [30.0, 22.0] {
        check(&m, tx, (0..120).map(|k| k * 470_000));
    }
}

/// Every decision a bucket keeps agrees with the exact evaluation at bucket starts up to
/// its expiry (the first, second and last, and every 7th); returns how many were kept,
/// and how many decisions were made.
fn check_kept(m: &Model, tx: f64, starts: impl Iterator<Item = u64>) -> (usize, usize) {
    let bucket_us = crate::physics::inventory::FIELD_BUCKET_US;
    let table = m.frequencies_khz().len().max(1) as u16;
    let (mut kept, mut made) = (0, 0);
    for t in starts {
        for antenna in 1..=m.antenna_count() {
            for ch in [1, table / 2 + 1, table] {
                let mut b = Bucket::default();
                b.memo.fit(m.tag_count(), tx);
                b.memo.exhaustive = true;
                m.prepare(&mut b, antenna, tx, t, ch);
                for tag in 0..m.tag_count() {
                    m.in_field(&mut b, tag);
                }
                let lambda = m.wavelength_m(ch);
                for (tag, k) in b.memo.kept.iter().enumerate() {
                    made += 1;
                    if k.channel == 0 {
                        continue;
                    }
                    kept += 1;
                    assert_eq!((k.channel, k.from_us), (ch, t));
                    let steps = (k.until_us - k.from_us) / bucket_us;
                    let probes = (0..=steps)
                        .filter(|j| *j < 2 || j % 7 == 0)
                        .map(|j| t + j * bucket_us)
                        .chain([k.until_us]);
                    for probe in probes {
                        assert_eq!(
                            exact(m, antenna, tx, probe, lambda, tag),
                            k.inside,
                            "antenna {antenna}, tag {tag}, kept from {t} to {} µs, \
                             probe {probe}, channel {ch}",
                            k.until_us
                        );
                    }
                }
            }
        }
    }
    (kept, made)
}

#[test]
fn kept_decisions_hold_until_they_expire() {
    let s2 = fixture("s2");
    let m = Model::new(&s2, 0);
    let (kept, made) = check_kept(&m, 27.0, (0..40).map(|k| k * 5_010_000));
    // Most decisions on a slow robot are kept, or keeping saves nothing.
    assert!(2 * kept > made, "S2: {kept} of {made}");
    let m = Model::new(&everything_moves(), 0);
    for tx in [30.0, 22.0] {
        let (kept, _) = check_kept(&m, tx, (0..60).map(|k| k * 930_000));
        assert!(kept > 0, "the fast robot keeps some decisions too");
    }
}

#[test]
fn fast_field_test_agrees_with_the_phasor_sum() {
    // Antennas of several lobes at several poses, tags all around them, sloped and
    // axis-aligned reflectors; thresholds at and around each tag's exact amplitude.
    let reflectors = [
        ([0.0, 0.0, 0.0], [0.0, 0.0, 1.0], 0.6),
        ([0.0, 4.0, 0.0], [0.0, -1.0, 0.3], 0.5),
        ([9.0, 0.0, 0.0], [-1.0, 0.2, 0.0], 0.3),
    ];
    let planes: Vec<Plane> = reflectors
        .iter()
        .map(|&(point, normal, coefficient)| {
            let n = norm(normal);
            Plane {
                point,
                unit: [normal[0] / n, normal[1] / n, normal[2] / n],
                coefficient,
            }
        })
        .collect();
    let (mut decided, mut total) = (0, 0);
    for (gain_dbi, bw) in [(6.0, 65.0), (4.77, 70.0), (7.0, 30.0), (3.0, 240.0)] {
        let lobe = Lobe::new(gain_dbi, bw);
        let gains = GainTable::new(&lobe);
        let pattern = Pattern::new(&lobe);
        for (k, yaw) in [0.0f64, 1.3, -2.2, 3.0].into_iter().enumerate() {
            let k = k as f64;
            let pose = crate::physics::AntennaPose {
                position: [1.0 + k, 1.5 + 0.4 * k, 0.3 + 0.5 * k],
                yaw_rad: yaw,
                pitch_rad: 0.2 * k - 0.3,
            };
            let aim = Aim::new(&pose);
            for lambda in [0.3275, 0.3463] {
                let mut near = Near::default();
                near.prepare(&aim, &planes, lambda);
                for i in 0..400 {
                    let f = f64::from(i);
                    let q = [
                        0.5 + (f * 0.731) % 8.0,
                        0.2 + (f * 0.377) % 3.7,
                        0.05 + (f * 0.193) % 2.5,
                    ];
                    let dist = distance(aim.position, q);
                    let power = power_gain_with(&aim, &pattern, q, &planes, lambda);
                    let amplitude = power.sqrt();
                    for factor in [0.3, 0.9, 0.99, 0.999, 1.0, 1.001, 1.01, 1.1, 3.0] {
                        let threshold = amplitude * factor;
                        total += 1;
                        if let Some((known, _)) = near.decide(&gains, q, dist, threshold) {
                            decided += 1;
                            assert_eq!(
                                known,
                                power >= threshold * threshold,
                                "lobe {bw}, pose {k}, tag {q:?}, factor {factor}"
                            );
                        }
                    }
                }
            }
        }
    }
    // Thresholds a few per cent away from the amplitude are decided without the exact sum.
    assert!(decided > total / 2, "{decided} of {total}");
}
