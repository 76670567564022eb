//! Tests of scenario loading and validation.

use super::*;

const FIXTURES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../fixtures/scenarios");

/// A small valid scenario as JSON, to be broken by the tests.
fn base() -> serde_json::Value {
    serde_json::json!({
        "name": "t",
        "seed": 1,
        "world": { "min": [0, 0, 0], "max": [10, 10, 3] },
        "tags": [ { "epc": "300833B2DDD9014000000001", "position": [5, 5, 1] } ],
        "readers": [ {
            "name": "r",
            "region": "fcc",
            "antennas": [
                { "mount": { "type": "fixed", "pose": { "position": [1, 5, 1] } } },
                { "mount": { "type": "robot",
                             "robot": { "start": [1, 1, 0], "waypoints": [[9, 1]], "speed": 1.0 },
                             "offset": { "position": [0, 0, 1], "yaw_deg": 90 } } }
            ]
        } ]
    })
}

/// Loads `v` and returns the error message (panics if it loads).
fn error_of(v: &serde_json::Value) -> String {
    match Scenario::from_json(&v.to_string()) {
        Ok(_) => panic!("scenario should have been refused: {v}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn default_s1_is_valid() {
    let s = Scenario::from_json(include_str!("../../../../fixtures/scenarios/s1.json"));
    assert!(s.is_ok(), "{:?}", s.err());
}

#[test]
fn fixtures_load_and_default_s1_equals_the_file() {
    let dir = std::path::Path::new(FIXTURES);
    let s1 = Scenario::load(&dir.join("s1.json")).expect("s1 loads");
    assert_eq!(Scenario::default_s1(), s1);
    assert_eq!(s1.tags.len(), 10);
    assert_eq!(s1.readers[0].antennas.len(), 1);
    assert_eq!(s1.readers[0].listen, "127.0.0.1:5084");
    let s2 = Scenario::load(&dir.join("s2.json")).expect("s2 loads");
    assert_eq!(s2.tags.len(), 100);
    assert_eq!(s2.readers[0].antennas.len(), 8);
    assert!(!s2.reflectors.is_empty());
    let s3 = Scenario::load(&dir.join("s3.json")).expect("s3 loads");
    assert_eq!(s3.tags.len(), 1);
    assert!(s3.reflectors.is_empty());
    assert_eq!(s3.readers[0].region.frequencies_khz(), vec![867_000]);
    assert_eq!(s3.readers[0].antennas[0].phase_noise_rad, 0.2);
}

#[test]
fn defaults_are_filled_and_round_trip_through_json() {
    let s = Scenario::from_json(&base().to_string()).expect("base is valid");
    let r = &s.readers[0];
    assert_eq!(r.listen, "127.0.0.1:5084");
    assert_eq!(r.hop_dwell_ms, 400.0);
    assert_eq!(r.reads_per_second, None);
    assert_eq!(r.report_interval_ms, 1000);
    let a = &r.antennas[0];
    assert_eq!(
        (a.phase_noise_rad, a.rssi_noise, a.range_m),
        (0.025, None, 7.0)
    );
    let mut etsi = base();
    etsi["readers"][0]["region"] = "etsi".into();
    let s_etsi = Scenario::from_json(&etsi.to_string()).expect("valid");
    assert_eq!(s_etsi.readers[0].hop_dwell_ms, 4000.0);
    let again = Scenario::from_json(&serde_json::to_string(&s).expect("serializable"))
        .expect("serialized scenario loads");
    assert_eq!(again, s);
}

/// A change that breaks the base scenario.
type Edit = Box<dyn Fn(&mut serde_json::Value)>;

#[test]
fn errors_name_the_field_path_and_the_reason() {
    let cases: Vec<(Edit, &str, &str)> = vec![
        (
            Box::new(|v| v["readers"][0]["antennas"][1]["beamwidth_deg"] = (-5).into()),
            "readers[0].antennas[1].beamwidth_deg: must be in (0, 360], got -5",
            "",
        ),
        (
            Box::new(|v| v["tags"][0]["colour"] = "red".into()),
            "tags[0].colour: unknown field `colour`",
            "",
        ),
        (
            Box::new(|v| v["tags"][0]["epc"] = "300833B2DDD90140000000".into()),
            "tags[0].epc: must be whole 16-bit words (a multiple of 4 hex digits), got 22 digits",
            "",
        ),
        (
            Box::new(|v| v["tags"][0]["epc"] = "".into()),
            "tags[0].epc: must not be empty",
            "",
        ),
        (
            Box::new(|v| v["tags"][0]["epc"] = "ABCD".repeat(32).into()),
            "tags[0].epc: must be at most 31 16-bit words (496 bits), got 32 words",
            "",
        ),
        (
            Box::new(|v| v["readers"][0]["name"] = "".into()),
            "readers[0].name: the reader name is empty",
            "",
        ),
        (
            Box::new(|v| v["readers"][0]["name"] = "dock\n1".into()),
            "readers[0].name: reader name \"dock\\n1\" holds a control character",
            "",
        ),
        (
            Box::new(|v| v["readers"][0]["antennas"] = serde_json::json!([])),
            "readers[0].antennas: must list at least one antenna",
            "",
        ),
        (
            Box::new(|v| v["readers"][0]["antennas"][1]["mount"]["robot"]["speed"] = 2.5.into()),
            "readers[0].antennas[1].mount.robot.speed: must be in (0, 2], got 2.5",
            "",
        ),
        (
            Box::new(|v| v["readers"][0]["antennas"][1]["mount"]["robot"]["sped"] = 1.into()),
            "readers[0].antennas[1].mount.robot.sped: unknown field `sped`",
            "",
        ),
        (
            Box::new(|v| v["readers"][0]["antennas"][0]["gain_dbi"] = "high".into()),
            "readers[0].antennas[0].gain_dbi",
            "invalid type",
        ),
        (
            Box::new(|v| v["readers"][0]["region"] = "mars".into()),
            "readers[0].region",
            "unknown region",
        ),
        (
            Box::new(|v| v["readers"][0]["antennas"][0]["mount"]["type"] = "ceiling".into()),
            "readers[0].antennas[0].mount.type: unknown mount type \"ceiling\"",
            "",
        ),
        (
            Box::new(|v| v["tags"][0]["position"] = serde_json::json!([50, 5, 1])),
            "tags[0].position: must be inside the world box",
            "",
        ),
        (
            Box::new(|v| v["readers"][0]["antennas"][0]["phase_sign"] = 0.5.into()),
            "readers[0].antennas[0].phase_sign: must be 1 or -1, got 0.5",
            "",
        ),
        (
            Box::new(|v| {
                v["readers"][0]["antennas"][0]["extra_phase_noise"] =
                    serde_json::json!({ "gamma": { "shape": -1, "scale": 1 } })
            }),
            "readers[0].antennas[0].extra_phase_noise: shape must be > 0, got -1",
            "",
        ),
        (
            Box::new(|v| v["readers"][0]["fixed_channel"] = 51.into()),
            "readers[0].fixed_channel: must be a channel index in [1, 50], got 51",
            "",
        ),
        (
            Box::new(|v| v["readers"][0]["report_interval_ms"] = 3_600_001.into()),
            "readers[0].report_interval_ms: must be at most 3600000",
            "",
        ),
        (
            Box::new(|v| v["readers"][0]["aispec_setup_ms"] = (-1.5).into()),
            "readers[0].aispec_setup_ms: must be in [0, 10000], got -1.5",
            "",
        ),
        (
            Box::new(|v| v["readers"][0]["round_gap_ms"] = 2000.0.into()),
            "readers[0].round_gap_ms: must be in [0, 1000], got 2000",
            "",
        ),
        (
            Box::new(|v| v["tags"][0]["tid"] = "E28011".into()),
            "tags[0].tid: must be whole 16-bit words",
            "",
        ),
        (
            Box::new(|v| v["tags"][0]["kill_password"] = "1234".into()),
            "tags[0].kill_password: must be 8 hex digits (32 bits), got \"1234\"",
            "",
        ),
        (
            Box::new(|v| v["tags"][0]["access_password"] = "0000ABCG".into()),
            "tags[0].access_password: must be 8 hex digits",
            "",
        ),
        (
            Box::new(|v| v["readers"][0]["listen"] = "localhost".into()),
            "readers[0].listen: must be an IP address and port",
            "",
        ),
        (
            Box::new(|v| {
                v["tags"].as_array_mut().expect("tags is an array").push(
                    serde_json::json!({ "epc": "300833B2DDD9014000000001", "position": [1, 1, 1] }),
                )
            }),
            "tags[1].epc: duplicate EPC",
            "",
        ),
        (
            Box::new(|v| v["readers"][0]["antennas"][1]["mount"]["robot"]["speed"] = "fast".into()),
            "readers[0].antennas[1].mount.robot.speed: invalid type: string \"fast\", expected f64",
            "",
        ),
        (
            Box::new(|v| v["seed"] = (-1).into()),
            "seed",
            "invalid value",
        ),
    ];
    for (edit, prefix, contains) in cases {
        let mut v = base();
        edit(&mut v);
        let msg = error_of(&v);
        assert!(msg.starts_with(prefix), "expected `{prefix}…`, got `{msg}`");
        assert!(msg.contains(contains), "expected `{contains}` in `{msg}`");
    }
}

#[test]
fn recorded_mount_resolves_against_the_scenario_directory() {
    let dir = tempfile::tempdir().expect("temporary directory");
    std::fs::write(
        dir.path().join("poses.csv"),
        "t_s,x,y,z,yaw_deg,pitch_deg\n0,1,1,1,0,0\n10,9,1,1,0,0\n",
    )
    .expect("write poses");
    let mut v = base();
    v["readers"][0]["antennas"][0]["mount"] =
        serde_json::json!({ "type": "recorded", "file": "poses.csv" });
    let path = dir.path().join("scenario.json");
    std::fs::write(&path, v.to_string()).expect("write scenario");
    let s = Scenario::load(&path).expect("loads with the relative pose file");
    match &s.readers[0].antennas[0].mount {
        Mount::Recorded { poses, .. } => assert_eq!(poses.len(), 2),
        other => panic!("expected a recorded mount, got {other:?}"),
    }
    // From a string, the same relative name resolves against the current directory: missing.
    let err = Scenario::from_json(&v.to_string()).unwrap_err().to_string();
    assert!(
        err.starts_with("readers[0].antennas[0].mount.file: cannot read"),
        "{err}"
    );
    let missing = Scenario::load(&dir.path().join("nope.json"))
        .unwrap_err()
        .to_string();
    assert!(missing.contains("nope.json"), "{missing}");
}

#[test]
fn trailing_garbage_and_bad_json_are_errors() {
    let text = format!("{} x", base());
    assert!(Scenario::from_json(&text).is_err());
    let err = Scenario::from_json("{").unwrap_err().to_string();
    assert!(err.contains("EOF"), "{err}");
}

#[test]
fn bad_noise_parameters_are_refused() {
    use super::validate::check_noise;
    assert!(check_noise(&NoiseDist::Gamma {
        shape: -1.0,
        scale: 1.0
    })
    .is_err());
    assert!(check_noise(&NoiseDist::Uniform {
        low: 1.0,
        high: 1.0
    })
    .is_err());
    assert!(check_noise(&NoiseDist::Normal {
        mean: 0.0,
        std: 0.1
    })
    .is_ok());
}

#[test]
fn s2_configurations_hold_44_references_and_their_tags_on_the_antennas_side() {
    // [A]'s two layouts: one straight drive, every antenna facing left of it (robot frame y is
    // left), every tag other than a reference left of the path.
    for name in ["s2-side-by-side.json", "s2-back-to-back.json"] {
        let s = Scenario::load(&std::path::Path::new(FIXTURES).join(name)).expect("loads");
        assert_eq!(s.tags.len(), 100, "{name}");
        assert_eq!(s.tags.iter().filter(|t| t.reference).count(), 44, "{name}");
        let antennas = &s.readers[0].antennas;
        assert_eq!(antennas.len(), 4, "{name}");
        for antenna in antennas {
            let Mount::Robot { robot, offset } = &antenna.mount else {
                panic!("{name}: an antenna not on the robot");
            };
            assert_eq!(robot.waypoints.len(), 1, "{name}: not one straight drive");
            let (a, b) = (robot.start, robot.waypoints[0]);
            let along = (b[1] - a[1]).atan2(b[0] - a[0]);
            assert!(
                (along - a[2]).cos() > 0.99,
                "{name}: robot not heading along the drive"
            );
            assert!(
                offset.yaw_rad.sin() > 0.5,
                "{name}: antenna not facing left"
            );
            for t in s.tags.iter().filter(|t| !t.reference) {
                let p = t.position;
                let left = (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]);
                assert!(left > 0.0, "{name}: {} is not left of the path", t.epc);
            }
        }
    }
}

#[test]
fn old_fields_load_with_a_notice_naming_what_replaced_them() {
    // A file written before the reader model: [G]'s RSS noise on the first antenna.
    let mut old = base();
    old["readers"][0]["antennas"][0]["rssi_noise"] = serde_json::json!(0.01);
    old["readers"][0]["reads_per_second"] = serde_json::json!(750);
    let s = Scenario::from_json(&old.to_string()).expect("an old file still loads");
    assert_eq!(s.notices.len(), 2, "{:?}", s.notices);
    let rate = &s.notices[0];
    assert!(
        rate.starts_with("readers[0].reads_per_second (750)"),
        "{rate}"
    );
    assert!(rate.contains("Gen2"), "{rate}");
    old["readers"][0]
        .as_object_mut()
        .map(|r| r.remove("reads_per_second"));
    let n = &s.notices[1];
    assert!(n.starts_with("readers[0].antennas[0].rssi_noise"), "{n}");
    assert!(
        n.contains("gazebo_eq5") && n.contains("rssi_sigma_db"),
        "{n}"
    );
    assert!(!n.contains('\n'));
    let a = &s.readers[0].antennas[0];
    assert_eq!((a.rssi_model, a.eq5_noise()), (RssiModel::Reader, 0.01));
    // With [G] eq. 5 asked for, the field is used and nothing is said.
    old["readers"][0]["antennas"][0]["rssi_model"] = serde_json::json!("gazebo_eq5");
    let s = Scenario::from_json(&old.to_string()).expect("loads");
    assert!(s.notices.is_empty(), "{:?}", s.notices);
    // The new fields are checked like the old ones.
    let mut bad = base();
    bad["readers"][0]["antennas"][0]["rssi_sigma_db"] = serde_json::json!(-1);
    assert!(error_of(&bad).starts_with("readers[0].antennas[0].rssi_sigma_db: must be in"));
    let mut bad = base();
    bad["tags"][0]["orientation"] = serde_json::json!([0, 0, 0]);
    assert!(error_of(&bad).starts_with("tags[0].orientation: must not be the zero vector"));
    let mut bad = base();
    bad["readers"][0]["antennas"][0]["rssi_model"] = serde_json::json!("friis");
    assert!(error_of(&bad).contains("rssi_model"), "{}", error_of(&bad));
}

#[test]
fn pose_estimate_defaults_and_errors_name_the_field() {
    let robot = |s: &Scenario| match &s.readers[0].antennas[1].mount {
        Mount::Robot { robot, .. } => robot.pose_estimate.clone(),
        other => panic!("antenna 2 of the base rides a robot, got {other:?}"),
    };
    let s = Scenario::from_json(&base().to_string()).expect("base is valid");
    assert_eq!(robot(&s), PoseEstimate::default());
    assert_eq!(robot(&s).kind, PoseEstimateKind::Odometry);
    let with = |estimate: serde_json::Value| {
        let mut v = base();
        v["readers"][0]["antennas"][1]["mount"]["robot"]["pose_estimate"] = estimate;
        v
    };
    let localized = with(serde_json::json!({ "kind": "localized" }));
    let s = Scenario::from_json(&localized.to_string()).expect("valid");
    let e = robot(&s);
    assert_eq!(e.kind, PoseEstimateKind::Localized);
    assert_eq!(
        (e.position_sigma_m, e.heading_sigma_deg, e.correlation_s),
        (0.015, 0.5, 2.0)
    );
    let p = "readers[0].antennas[1].mount.robot.pose_estimate";
    let cases = [
        (
            serde_json::json!({ "kind": "localized", "position_sigma_m": -0.01 }),
            format!("{p}.position_sigma_m: must be finite and >= 0, got -0.01"),
        ),
        (
            serde_json::json!({ "kind": "localized", "heading_sigma_deg": -1 }),
            format!("{p}.heading_sigma_deg: must be finite and >= 0, got -1"),
        ),
        (
            serde_json::json!({ "kind": "localized", "correlation_s": 0 }),
            format!("{p}.correlation_s: must be finite and > 0, got 0"),
        ),
        (
            serde_json::json!({ "kind": "gps" }),
            format!("{p}.kind: unknown variant `gps`"),
        ),
        (
            serde_json::json!({ "position_sigma_m": 0.01 }),
            format!("{p}: missing field `kind`"),
        ),
        (
            serde_json::json!({ "kind": "localized", "sigma": 0.01 }),
            format!("{p}.sigma: unknown field `sigma`"),
        ),
    ];
    for (estimate, prefix) in cases {
        let msg = error_of(&with(estimate));
        assert!(
            msg.starts_with(&prefix),
            "expected `{prefix}…`, got `{msg}`"
        );
    }
}

#[test]
fn a_reader_model_sets_defaults_the_file_can_override() {
    let mut v = base();
    v["reader_model"] = "impinj-r420".into();
    v["readers"][0]["antennas"][0]["cable_delay_ns"] = 20.0.into();
    let s = Scenario::from_json(&v.to_string()).expect("valid");
    let [given, filled] = [&s.readers[0].antennas[0], &s.readers[0].antennas[1]];
    assert_eq!(given.cable_delay_ns, 20.0);
    assert_eq!(filled.cable_delay_ns, 35.0);
    assert_eq!(filled.phase_resolution_bits, 10);
    assert_eq!(s.tag_variation.backscatter_sigma_db, 2.8);
    // Without a model every field keeps its built-in default, and the model's name survives
    // a round trip through JSON.
    let plain = Scenario::from_json(&base().to_string()).expect("valid");
    assert_eq!(plain.readers[0].antennas[1].phase_resolution_bits, 12);
    assert_eq!(plain.readers[0].antennas[1].backscatter_compression, 0.0);
    let again = Scenario::from_json(&serde_json::to_string(&s).expect("json")).expect("valid");
    assert_eq!(again.reader_model.as_deref(), Some("impinj-r420"));
}

#[test]
fn hardware_fields_out_of_range_name_the_field() {
    let cases: [(&str, serde_json::Value, &str); 6] = [
        (
            "phase_noise_dof",
            1.5.into(),
            "must be 0 (Gaussian) or above 2",
        ),
        ("phase_resolution_bits", 0.into(), "must be 1 to 16, got 0"),
        (
            "backscatter_compression",
            1.5.into(),
            "must be in [0, 1], got 1.5",
        ),
        (
            "phase_outlier_rate",
            (-0.1).into(),
            "must be in [0, 0.5], got -0.1",
        ),
        ("phase_pattern_deg", 0.into(), "must be in (0, 360], got 0"),
        (
            "phase_pattern_growth_deg",
            (-5.0).into(),
            "must be in [0, 180], got -5",
        ),
    ];
    for (field, value, reason) in cases {
        let mut v = base();
        v["readers"][0]["antennas"][1][field] = value;
        let e = error_of(&v);
        assert!(
            e.starts_with(&format!("readers[0].antennas[1].{field}: {reason}")),
            "{e}"
        );
    }
    let mut v = base();
    v["tag_variation"] = serde_json::json!({"delay_sigma_ns": -1});
    assert!(error_of(&v).starts_with("tag_variation.delay_sigma_ns: must be in [0, 100]"));
    let mut v = base();
    v["reader_model"] = "acme".into();
    assert!(error_of(&v).starts_with("reader_model: unknown reader model `acme`; known: ideal"));
}

#[test]
fn gpio_defaults_to_the_devices_ports_and_errors_name_the_field() {
    let s = Scenario::from_json(&base().to_string()).expect("base is valid");
    assert_eq!(
        s.readers[0].gpio.ports(s.readers[0].device.as_deref()),
        (4, 4)
    );
    // An R700 has two inputs: a timeline on input 3 is refused, on input 2 accepted.
    let mut r700 = base();
    r700["readers"][0]["device"] = "impinj-r700".into();
    r700["readers"][0]["gpio"] =
        serde_json::json!({ "gpi_timeline": [ { "t_ms": 1, "port": 3, "state": "high" } ] });
    assert!(error_of(&r700)
        .starts_with("readers[0].gpio.gpi_timeline[0].port: must be a GPI port in [1, 2]"));
    r700["readers"][0]["gpio"]["gpi_timeline"][0]["port"] = 2.into();
    let s = Scenario::from_json(&r700.to_string()).expect("input 2 of an R700");
    assert_eq!(
        s.readers[0].gpio.ports(s.readers[0].device.as_deref()),
        (2, 3)
    );
    let mut v = base();
    v["readers"][0]["gpio"] = serde_json::json!({
        "gpis": 2,
        "gpi_timeline": [ { "t_ms": 500, "port": 1, "state": "high" },
                          { "t_ms": 900, "port": 1, "state": "low" } ],
        "photo_eyes": [ { "port": 2, "period_ms": 1000, "width_ms": 200, "count": 3 } ]
    });
    let s = Scenario::from_json(&v.to_string()).expect("a conveyor's GPIO is valid");
    assert_eq!(s.readers[0].gpio.photo_eyes[0].active, gpio::Level::High);
    let cases = [
        (
            serde_json::json!({ "gpis": 65 }),
            "readers[0].gpio.gpis: at most 64 ports, got 65",
        ),
        (
            serde_json::json!({ "gpis": 2, "gpi_timeline": [ { "t_ms": 1, "port": 3, "state": "high" } ] }),
            "readers[0].gpio.gpi_timeline[0].port: must be a GPI port in [1, 2]",
        ),
        (
            serde_json::json!({ "gpi_timeline": [ { "t_ms": 9, "port": 1, "state": "high" },
                                                  { "t_ms": 5, "port": 1, "state": "low" } ] }),
            "readers[0].gpio.gpi_timeline[1].t_ms: the timeline must be in time order",
        ),
        (
            serde_json::json!({ "photo_eyes": [ { "port": 1, "period_ms": 100, "width_ms": 100 } ] }),
            "readers[0].gpio.photo_eyes[0].width_ms: must be at least 1 ms and less than period_ms",
        ),
        (
            serde_json::json!({ "photo_eyes": [ { "port": 1, "period_ms": 0, "width_ms": 1 } ] }),
            "readers[0].gpio.photo_eyes[0].period_ms: must be in [1, ",
        ),
        (
            serde_json::json!({ "gpi_timeline": [ { "t_ms": 1, "port": 1, "state": "low" } ],
                                "photo_eyes": [ { "port": 1, "period_ms": 10, "width_ms": 1 } ] }),
            "readers[0].gpio.photo_eyes[0].port: GPI 1 is already driven",
        ),
    ];
    for (gpio, expected) in cases {
        let mut v = base();
        v["readers"][0]["gpio"] = gpio;
        let e = error_of(&v);
        assert!(e.starts_with(expected), "{e}");
    }
    let mut v = base();
    v["readers"][0]["gpio"] =
        serde_json::json!({ "gpi_timeline": [ { "t_ms": 1, "port": 1, "state": "up" } ] });
    assert!(
        error_of(&v).contains("unknown variant `up`"),
        "{}",
        error_of(&v)
    );
}
