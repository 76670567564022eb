//! Model-level tests: scheduling, range, determinism, phase and Doppler through `Model`.

use std::f64::consts::{PI, TAU};

use super::*;
use crate::scenario::Scenario;

/// A scenario with a fixed antenna at the origin facing +x and tags at the given positions.
pub(super) fn fixed_scenario(tags: &[[f64; 3]], antenna: serde_json::Value) -> Scenario {
    let tags: Vec<_> = tags
        .iter()
        .enumerate()
        .map(|(i, p)| serde_json::json!({ "epc": format!("E2000000000000000000{:04X}", i), "position": p }))
        .collect();
    let mut a = serde_json::json!({
        "mount": { "type": "fixed", "pose": { "position": [0, 0, 1], "yaw_deg": 0 } }
    });
    if let (Some(a), Some(extra)) = (a.as_object_mut(), antenna.as_object()) {
        a.extend(extra.clone());
    }
    let v = serde_json::json!({
        "name": "test",
        "seed": 42,
        "world": { "min": [-20, -20, 0], "max": [20, 20, 5] },
        "tags": tags,
        "readers": [ { "name": "r", "region": "fcc", "antennas": [a] } ]
    });
    Scenario::from_json(&v.to_string()).expect("test scenario is valid")
}

fn angle_diff(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(TAU);
    d.min(TAU - d)
}

#[test]
fn total_reads_follow_the_air_interface_when_tags_are_in_range() {
    let tags = [
        [2.0, 0.0, 1.0],
        [2.5, 0.5, 1.0],
        [3.0, -0.5, 1.0],
        [2.0, 0.3, 1.2],
    ];
    let m = Model::new(&fixed_scenario(&tags, serde_json::json!({})), 0);
    let reads = m.inventory(1, 0, 10_000_000, None);
    // At most one read per successful slot of the reader's default mode, and most of the
    // time spent reading: four tags in a frame of four slots.
    let slot = gen2::Air::default().mode.slot_times(96).success_us;
    let most = 10e6 / slot;
    let n = reads.len() as f64;
    assert!(n <= most && n >= 0.6 * most, "{n} reads, at most {most}");
    // Every tag gets a fair share.
    for t in 0..tags.len() {
        let k = reads.iter().filter(|r| r.tag == t).count() as f64;
        assert!(k > 0.15 * n && k < 0.35 * n, "tag {t}: {k} of {n}");
    }
    assert!(reads.windows(2).all(|w| w[0].time_us <= w[1].time_us));
    assert!(reads
        .iter()
        .all(|r| r.time_us < 10_000_000 && r.antenna == 1));
}

#[test]
fn no_reads_beyond_range_and_lower_power_shrinks_the_range() {
    // Range 7 m: a tag at 9 m is never read.
    let m = Model::new(
        &fixed_scenario(&[[9.0, 0.0, 1.0]], serde_json::json!({})),
        0,
    );
    assert!(m.inventory(1, 0, 5_000_000, None).is_empty());
    // A tag at 6 m is read at 30 dBm but not at 15 dBm (forward link too weak).
    let m = Model::new(
        &fixed_scenario(&[[6.0, 0.0, 1.0]], serde_json::json!({})),
        0,
    );
    let strong = m.inventory(1, 0, 5_000_000, Some(30.0)).len();
    let weak = m.inventory(1, 0, 5_000_000, Some(15.0)).len();
    assert!(strong > 500, "{strong}");
    assert_eq!(weak, 0);
    // Reads near the power edge are fewer than well inside it.
    let middle = m.inventory(1, 0, 5_000_000, Some(21.5)).len();
    assert!(middle < strong, "{middle} vs {strong}");
    // Without RSSI noise, RSSI follows the configured power dB for dB.
    let quiet = serde_json::json!({ "rssi_sigma_db": 0.0, "rssi_resolution_db": 0.0 });
    let m = Model::new(&fixed_scenario(&[[6.0, 0.0, 1.0]], quiet), 0);
    let at = |p: f64| {
        let r = m.inventory(1, 0, 2_000_000, Some(p));
        r.iter().map(|r| r.rssi_dbm).sum::<f64>() / r.len() as f64
    };
    let (a, b) = (at(30.0), at(27.0));
    // (Up to the mix of channels, whose wavelengths differ by 3 %.)
    assert!((a - b - 3.0).abs() < 0.05, "{a} {b}");
    // A tag behind the antenna is out of the lobe at 6 m.
    let m = Model::new(
        &fixed_scenario(&[[-6.0, 0.0, 1.0]], serde_json::json!({})),
        0,
    );
    assert!(m.inventory(1, 0, 2_000_000, None).is_empty());
}

#[test]
fn same_call_twice_gives_identical_reads_and_splits_agree() {
    let s = Scenario::default_s1();
    let m = Model::new(&s, 0);
    let a = m.inventory(1, 10_000_000, 20_000_000, None);
    let b = m.inventory(1, 10_000_000, 20_000_000, None);
    assert!(!a.is_empty());
    assert_eq!(a, b);
    let mut split = m.inventory(1, 10_000_000, 13_333_333, None);
    split.extend(m.inventory(1, 13_333_333, 20_000_000, None));
    assert_eq!(a, split);
    // A second model of the same scenario agrees too.
    assert_eq!(
        Model::new(&s, 0).inventory(1, 10_000_000, 20_000_000, None),
        a
    );
}

#[test]
fn no_nan_at_the_edge_of_range() {
    let antenna = serde_json::json!({
        "extra_phase_noise": { "cauchy": { "median": 0.0, "scale": 0.05 } }
    });
    let tags = [
        [6.9, 0.0, 1.0],
        [7.1, 0.0, 1.0],
        [7.3, 0.2, 1.0],
        [6.5, 2.5, 1.0],
    ];
    let m = Model::new(&fixed_scenario(&tags, antenna), 0);
    let reads = m.inventory(1, 0, 60_000_000, None);
    assert!(reads.len() > 1000, "{}", reads.len());
    for r in &reads {
        assert!(r.rssi_dbm.is_finite() && r.rssi_dbm >= rssi::READER_SENSITIVITY_DBM);
        assert!((0.0..TAU).contains(&r.phase_rad));
        assert!(r.doppler_hz.is_finite());
    }
}

#[test]
fn phase_difference_between_two_antennas_is_4_pi_delta_d_over_lambda() {
    let v = serde_json::json!({
        "name": "two antennas",
        "seed": 3,
        "world": { "min": [-5, -5, 0], "max": [5, 5, 3] },
        "tags": [ { "epc": "E20000000000000000000001", "position": [0, 2, 1] } ],
        "readers": [ {
            "name": "r",
            "region": { "hop_table_khz": [866300] },
            "antennas": [
                { "mount": { "type": "fixed", "pose": { "position": [0, 0, 1], "yaw_deg": 90 } },
                  "phase_offset_rad": [0.7], "phase_noise_rad": 0.0 },
                { "mount": { "type": "fixed", "pose": { "position": [0.37, 0, 1], "yaw_deg": 90 } },
                  "phase_offset_rad": [0.7], "phase_noise_rad": 0.0 }
            ]
        } ]
    });
    let m = Model::new(&Scenario::from_json(&v.to_string()).expect("valid"), 0);
    let p1 = m.inventory(1, 0, 100_000, None)[0].phase_rad;
    let p2 = m.inventory(2, 0, 100_000, None)[0].phase_rad;
    let lambda = phase::wavelength_m(866_300);
    let delta_d = (0.37f64 * 0.37 + 4.0).sqrt() - 2.0;
    let expected = 4.0 * PI * delta_d / lambda;
    assert!(
        angle_diff(p2 - p1, expected) < 1e-9,
        "{} vs {expected}",
        p2 - p1
    );
    // Absolute phase: φ0 + 4πD/λ.
    assert!(angle_diff(p1, 0.7 + 4.0 * PI * 2.0 / lambda) < 1e-9);
}

#[test]
fn reads_follow_the_hop_table_and_phase_offsets_differ_per_channel() {
    let m = Model::new(
        &fixed_scenario(&[[2.0, 0.0, 1.0]], serde_json::json!({})),
        0,
    );
    assert_eq!(m.frequencies_khz().len(), 50);
    let reads = m.inventory(1, 0, 30_000_000, None);
    let mut channels: Vec<u16> = reads.iter().map(|r| r.channel_index).collect();
    channels.dedup();
    assert!(channels.len() >= 70, "{}", channels.len());
    for r in &reads {
        assert_eq!(r.channel_index, m.channel_at(r.time_us));
        assert_eq!(
            r.frequency_khz,
            m.frequencies_khz()[usize::from(r.channel_index) - 1]
        );
    }
    // A pinned channel overrides the hop schedule; an impossible one is ignored.
    let pinned = m.inventory_on(1, 0, 2_000_000, None, Some(7));
    assert!(!pinned.is_empty());
    assert!(pinned
        .iter()
        .all(|r| r.channel_index == 7 && r.frequency_khz == m.frequencies_khz()[6]));
    assert_eq!(
        m.inventory_on(1, 0, 2_000_000, None, Some(0)),
        m.inventory(1, 0, 2_000_000, None)
    );
    let offsets: Vec<f64> = (1..=50).map(|c| m.phase_offset(1, 0, c)).collect();
    assert!(offsets.iter().all(|o| (0.0..TAU).contains(o)));
    assert!(offsets.windows(2).all(|w| w[0] != w[1]));
}

#[test]
fn doppler_of_a_tag_approaching_a_fixed_antenna() {
    let v = serde_json::json!({
        "name": "conveyor",
        "seed": 5,
        "world": { "min": [-1, -1, 0], "max": [10, 1, 3] },
        "tags": [ { "epc": "E20000000000000000000001", "position": [6, 0, 1],
                    "path": { "waypoints": [[1, 0, 1]], "speed": 1.5 } } ],
        "readers": [ { "name": "r", "region": "etsi", "fixed_channel": 2, "antennas": [
            { "mount": { "type": "fixed", "pose": { "position": [0, 0, 1] } },
              "doppler_sigma_hz": 0 } ] } ]
    });
    let m = Model::new(&Scenario::from_json(&v.to_string()).expect("valid"), 0);
    let reads = m.inventory(1, 200_000, 3_000_000, None);
    assert!(!reads.is_empty());
    let lambda = phase::wavelength_m(866_300);
    for r in &reads {
        assert_eq!(r.frequency_khz, 866_300);
        // Approaching at 1.5 m/s: +2·1.5/λ.
        assert!(
            (r.doppler_hz - 3.0 / lambda).abs() < 1e-6,
            "{}",
            r.doppler_hz
        );
    }
    assert_eq!(m.tag_position(0, 2_000_000), [3.0, 0.0, 1.0]);
    // Once the tag stops there is no shift.
    assert!(m.doppler_hz(1, 0, 5_000_000, lambda).abs() < 1e-9);
}

#[test]
fn robot_antenna_pose_odometry_and_doppler() {
    let s = Scenario::default_s1();
    let m = Model::new(&s, 0);
    let start = m.antenna_pose(1, 0);
    // Offset (0, 0.2, 0.5) in the robot frame, facing +y, robot at (1, 5) heading +x.
    assert!((start.position[0] - 1.0).abs() < 1e-9);
    assert!((start.position[1] - 5.2).abs() < 1e-9);
    assert!((start.position[2] - 0.5).abs() < 1e-9);
    assert!((start.yaw_rad - PI / 2.0).abs() < 1e-9);
    let end = m.antenna_pose(1, 200_000_000);
    assert!((end.position[0] - 23.0).abs() < 0.1, "{:?}", end.position);
    // Odometry starts exact and drifts a little (K = 1e-5 over 22 m: millimetres to cm).
    assert_eq!(m.odometry_pose(1, 0), start);
    let odo = m.odometry_pose(1, 200_000_000);
    let drift = (odo.position[0] - end.position[0]).hypot(odo.position[1] - end.position[1]);
    assert!(drift > 0.0 && drift < 0.5, "{drift}");
    // Mid-path at 0.5 m/s along +x, tag 1 (x = 5, y = 7.6) ahead: positive Doppler.
    let t = 4_000_000;
    let p = m.antenna_pose(1, t).position;
    assert!(p[0] < 5.0);
    let lambda = m.wavelength_m(1);
    let d = [5.0 - p[0], 7.6 - p[1], 0.0];
    let cos = d[0] / (d[0].hypot(d[1]));
    let expected = 2.0 * 0.5 * cos / lambda;
    let got = m.doppler_hz(1, 1, t, lambda);
    assert!(
        (got - expected).abs() < 0.05 * expected,
        "{got} vs {expected}"
    );
}

#[test]
fn multipath_changes_rssi_and_phase_consistently() {
    let base = |coefficient: Option<f64>| {
        let v = serde_json::json!({
            "name": "floor",
            "seed": 9,
            "world": { "min": [-1, -3, 0], "max": [10, 3, 3] },
            "reflectors": match coefficient {
                Some(c) => serde_json::json!([{ "point": [0, 0, 0], "normal": [0, 0, 1], "coefficient": c }]),
                None => serde_json::json!([]),
            },
            "tag_variation": { "sensitivity_sigma_db": 0, "backscatter_sigma_db": 0 },
            "tags": [ { "epc": "E20000000000000000000001", "position": [3, 0, 0.4] } ],
            "readers": [ { "name": "r", "region": { "hop_table_khz": [915000] }, "antennas": [
                { "mount": { "type": "fixed", "pose": { "position": [0, 0, 1.2] } },
                  "phase_noise_rad": 0.0, "rssi_sigma_db": 0.0, "rssi_resolution_db": 0.0,
                  "phase_offset_rad": [0.0], "beamwidth_deg": 360, "gain_dbi": 0.0 } ] } ]
        });
        Model::new(&Scenario::from_json(&v.to_string()).expect("valid"), 0)
    };
    let (free, floor, black) = (base(None), base(Some(0.5)), base(Some(0.0)));
    let rf = free.inventory(1, 0, 10_000, None)[0];
    let rm = floor.inventory(1, 0, 10_000, None)[0];
    // A reflector that reflects nothing changes nothing: one gain convention for both.
    let rb = black.inventory(1, 0, 10_000, None)[0];
    assert!(
        (rb.rssi_dbm - rf.rssi_dbm).abs() < 1e-9,
        "{} {}",
        rb.rssi_dbm,
        rf.rssi_dbm
    );
    assert!(angle_diff(rb.phase_rad, rf.phase_rad) < 1e-9);
    let lambda = phase::wavelength_m(915_000);
    let (d, dr) = ((9.0f64 + 0.64).sqrt(), (9.0f64 + 2.56).sqrt());
    let k = TAU / lambda;
    // Two-ray one-way factor 1 − ρ·(D/d_r)·e^{−jk(d_r − D)}.
    let h_re = 1.0 - 0.5 * d / dr * (-k * (dr - d)).cos();
    let h_im = -0.5 * d / dr * (-k * (dr - d)).sin();
    let factor = h_re.hypot(h_im);
    let g_t = rssi::db_to_linear(rssi::TAG_GAIN_DBI);
    let free_full = rssi::full_model(30.0, 1.0, 1.0, g_t, lambda, d, 1.0, 0.0).expect("positive");
    assert!((rf.rssi_dbm - free_full).abs() < 1e-9);
    assert!((rm.rssi_dbm - free_full - 40.0 * factor.log10()).abs() < 1e-6);
    assert!(angle_diff(rf.phase_rad, 4.0 * PI * d / lambda) < 1e-9);
    assert!(angle_diff(rm.phase_rad, 4.0 * PI * d / lambda - 2.0 * h_im.atan2(h_re)) < 1e-9);
}

#[test]
fn every_scenario_fixture_loads_without_notices_and_produces_reads() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/scenarios");
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .expect("fixtures/scenarios lists")
        .map(|e| e.expect("directory entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "json"))
        .collect();
    files.sort();
    assert!(files.len() >= 6, "{files:?}");
    for path in &files {
        let name = path.display();
        let s = Scenario::load(path).expect("fixture loads");
        assert!(s.notices.is_empty(), "{name}: {:?}", s.notices);
        let m = Model::new(&s, 0);
        // Some 2 s window of the first 240 s gives a read on some antenna.
        let read = (0..120u64).any(|w| {
            let t0 = w * 2_000_000;
            (1..=m.antenna_count()).any(|a| !m.inventory(a, t0, t0 + 2_000_000, None).is_empty())
        });
        assert!(read, "{name}: no reads");
        assert_eq!(m.tag_count(), s.tags.len());
        assert_eq!(m.tag_tid(0).len(), 6);
        // No fixture gives user memory: the default chip's 512 bits of zeros.
        assert_eq!(m.tag_user(0), vec![0; 32]);
    }
}

#[test]
fn tag_memory_and_bad_indices() {
    let m = Model::new(&Scenario::default_s1(), 0);
    assert_eq!(m.antenna_count(), 1);
    assert_eq!(m.tag_epc(0).as_bytes()[11], 0x01);
    assert_eq!(m.tag_epc(99).as_bytes(), [0; 12]);
    assert!(m.inventory(0, 0, 1_000_000, None).is_empty());
    assert!(m.inventory(2, 0, 1_000_000, None).is_empty());
    let none = Model::new(&Scenario::default_s1(), 5);
    assert_eq!(none.antenna_count(), 0);
    assert!(none.inventory(1, 0, 1_000_000, None).is_empty());
}

#[test]
fn vertical_axis_moves_a_robot_antenna_up_and_down() {
    let v = serde_json::json!({
        "name": "lift",
        "seed": 2,
        "world": { "min": [0, 0, 0], "max": [10, 10, 3] },
        "tags": [],
        "readers": [ { "name": "r", "region": "etsi", "antennas": [ { "mount": {
            "type": "robot",
            "robot": { "start": [1, 1, 0], "waypoints": [[2, 1]], "speed": 0.5,
                       "vertical": { "min_z": 0.5, "max_z": 2.0, "speed": 0.5 } },
            "offset": { "position": [0.1, 0, 1], "pitch_deg": 10 } } } ] } ]
    });
    let m = Model::new(&Scenario::from_json(&v.to_string()).expect("valid"), 0);
    let z = |s: f64| m.antenna_pose(1, (s * 1e6) as u64).position[2];
    assert!((z(0.0) - 0.5).abs() < 1e-9);
    assert!((z(3.0) - 2.0).abs() < 1e-9);
    assert!((z(4.0) - 1.5).abs() < 1e-9);
    assert!((m.antenna_pose(1, 0).pitch_rad - 10f64.to_radians()).abs() < 1e-12);
    assert_eq!(m.tag_count(), 0);
    assert!(m.inventory(1, 0, 1_000_000, None).is_empty());
}

#[test]
fn model_can_be_shared_between_threads() {
    fn shareable<T: Send + Sync + Clone>() {}
    shareable::<Model>();
}

#[test]
fn aim_is_that_of_the_true_pose() {
    // The shortcut for robot mounts gives the numbers of `Aim::new(antenna_pose)` up to
    // rounding (its trigonometry is within 1e-15), and `antenna_position` its position.
    let close = |a: [f64; 3], b: [f64; 3]| a.iter().zip(b).all(|(x, y)| (x - y).abs() <= 1e-13);
    for name in ["s1", "s2", "s3"] {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../fixtures/scenarios")
            .join(format!("{name}.json"));
        let m = Model::new(&Scenario::load(&path).expect("fixture loads"), 0);
        for antenna in 0..=m.antenna_count() + 1 {
            for t in (0..400).map(|k| k * 612_345) {
                let (fast, exact) = (
                    m.aim(antenna, t),
                    multipath::Aim::new(&m.antenna_pose(antenna, t)),
                );
                assert!(
                    close(fast.position, exact.position)
                        && close(fast.boresight, exact.boresight)
                        && (fast.boresight_norm - exact.boresight_norm).abs() <= 1e-13
                        && close(m.antenna_position(antenna, t), exact.position),
                    "{name}: antenna {antenna} at {t} µs: {fast:?} vs {exact:?}"
                );
            }
        }
    }
}

#[test]
fn leaving_out_phase_and_doppler_changes_nothing_else() {
    // S2 while the robot passes the first banner: extra phase noise from the scenario too.
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../fixtures/scenarios/s2.json"
    );
    let mut s = Scenario::load(std::path::Path::new(path)).expect("S2 loads");
    s.readers[0].antennas[0].extra_phase_noise = Some(crate::scenario::NoiseDist::Gamma {
        shape: 2.0,
        scale: 0.05,
    });
    let m = Model::new(&s, 0);
    let mut compared = 0;
    for antenna in [1, 2, 5] {
        let all = m.inventory(antenna, 60_000_000, 70_000_000, None);
        for want in [
            Want {
                phase: false,
                doppler: false,
            },
            Want {
                phase: true,
                doppler: false,
            },
            Want {
                phase: false,
                doppler: true,
            },
        ] {
            let some = m.inventory_with(
                antenna,
                60_000_000,
                70_000_000,
                None,
                None,
                want,
                &Default::default(),
            );
            assert_eq!(some.len(), all.len(), "antenna {antenna}, {want:?}");
            for (a, b) in all.iter().zip(&some) {
                let expect = Read {
                    phase_rad: if want.phase { a.phase_rad } else { 0.0 },
                    doppler_hz: if want.doppler { a.doppler_hz } else { 0.0 },
                    ..*a
                };
                assert_eq!(*b, expect);
                compared += 1;
            }
        }
    }
    assert!(compared > 1000, "{compared} reads compared");
    assert!(Want::ALL.covers(Want {
        phase: true,
        doppler: false
    }));
    assert!(!Want {
        phase: true,
        doppler: false
    }
    .covers(Want::ALL));
}

/// Readers of one scenario share its tags, reflectors and robots instead of each holding a
/// copy, and read exactly what a model built alone reads.
#[test]
fn readers_in_one_world_share_its_data_and_read_the_same() {
    let mut s = Scenario::default_s1();
    let mut second = s.readers[0].clone();
    second.name = "second".parse().expect("a reader name");
    s.readers.push(second);
    let world = World::new(&s);
    let a = Model::in_world(&world, &s, 0);
    let b = Model::in_world(&world, &s, 1);
    assert!(Arc::ptr_eq(&a.tags, &b.tags));
    assert!(Arc::ptr_eq(&a.robots, &b.robots));
    assert!(Arc::ptr_eq(&a.planes, &b.planes));
    for reader in [0, 1] {
        let shared = Model::in_world(&world, &s, reader);
        let alone = Model::new(&s, reader);
        let run = |m: &Model| {
            m.inventory_with(1, 0, 5_000_000, None, None, Want::ALL, &Default::default())
        };
        let reads = run(&shared);
        assert!(!reads.is_empty(), "S1's robot passes its tags in 5 s");
        assert_eq!(reads, run(&alone), "reader {reader}");
    }
}

#[test]
fn pose_estimates_change_neither_odometry_nor_reads() {
    let localized = Scenario::default_s1();
    let mut odometry = localized.clone();
    let Mount::Robot { robot, .. } = &mut odometry.readers[0].antennas[0].mount else {
        panic!("S1's antenna rides a robot");
    };
    assert_eq!(
        robot.pose_estimate.kind,
        crate::scenario::PoseEstimateKind::Localized
    );
    robot.pose_estimate = crate::scenario::PoseEstimate::default();
    let (ml, mo) = (Model::new(&localized, 0), Model::new(&odometry, 0));
    // S1's odometry (position, yaw) before pose estimates existed, same seed.
    let before: [(u64, [f64; 2], f64); 3] = [
        (
            10_000_000,
            [5.996485266262976, 5.196826997277829],
            1.5778700312235368,
        ),
        (
            44_000_000,
            [22.817212849864447, 4.975067304790823],
            1.5517057116800277,
        ),
        (
            200_000_000,
            [22.949126698155528, 4.973007710581807],
            1.5580416955600724,
        ),
    ];
    for (t, xy, yaw) in before {
        for m in [&ml, &mo] {
            let p = m.odometry_pose(1, t);
            assert!((p.position[0] - xy[0]).abs() < 1e-9, "{t}: {p:?}");
            assert!((p.position[1] - xy[1]).abs() < 1e-9, "{t}: {p:?}");
            assert!((p.yaw_rad - yaw).abs() < 1e-9, "{t}: {p:?}");
        }
        assert_eq!(mo.estimated_pose(1, t), mo.odometry_pose(1, t));
    }
    // Localized: within 4σ of the truth (plus the heading error's swing of the 0.2 m arm).
    let (sigma, heading) = (0.015, 0.5f64.to_radians());
    let reach = 4.0 * sigma + 0.2 * 4.0 * heading + 1e-9;
    for t in (0..500).map(|i| i * 100_000) {
        let (p, e) = (ml.antenna_pose(1, t), ml.estimated_pose(1, t));
        assert_eq!(p, mo.antenna_pose(1, t));
        assert!(
            (e.position[0] - p.position[0]).abs() <= reach,
            "{t}: {e:?} {p:?}"
        );
        assert!(
            (e.position[1] - p.position[1]).abs() <= reach,
            "{t}: {e:?} {p:?}"
        );
        assert_eq!((e.position[2], e.pitch_rad), (p.position[2], p.pitch_rad));
        assert!(
            angle_diff(e.yaw_rad, p.yaw_rad) <= 4.0 * heading + 1e-9,
            "{t}"
        );
    }
    assert_ne!(ml.estimated_pose(1, 0), ml.antenna_pose(1, 0));
    // What is read depends on the true pose only.
    let reads = |m: &Model| m.inventory(1, 0, 20_000_000, None);
    assert!(!reads(&ml).is_empty());
    assert_eq!(reads(&ml), reads(&mo));
}

#[test]
fn fixed_antennas_estimate_their_true_pose() {
    let s = fixed_scenario(&[[3.0, 0.0, 1.0]], serde_json::json!({}));
    let m = Model::new(&s, 0);
    assert_eq!(m.estimated_pose(1, 5_000_000), m.antenna_pose(1, 5_000_000));
    assert_eq!(m.estimated_pose(1, 0).position, [0.0, 0.0, 1.0]);
}
