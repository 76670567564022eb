use super::*;
use std::f64::consts::TAU;

#[test]
fn a_kept_window_drops_what_is_older_on_each_track() {
    let mut p = Poses::new().with_keep(Some(1_000_000));
    for k in 0..1000u64 {
        p.add(PoseSample {
            t_us: k * 10_000,
            reader: Some("r".parse().expect("a reader name")),
            antenna: 1,
            pose: Pose::from_degrees([0.0, 0.0, 0.0], 0.0, 0.0),
        });
    }
    let first = p.first().expect("samples").t_us;
    // 10 s of samples at 100 Hz, a 1 s window: the oldest left is within 1 s (and the
    // 64 samples dropped at a time) of the newest.
    assert!(first >= 9_990_000 - 1_000_000 - 640_000, "{first}");
    assert!(p.samples().len() <= 100 + 64, "{}", p.samples().len());
}

fn sample(t_us: u64, x: f64, yaw_deg: f64) -> PoseSample {
    PoseSample {
        t_us,
        reader: Some("r".parse().expect("a reader name")),
        antenna: 1,
        pose: Pose::from_degrees([x, 2.0, 0.5], yaw_deg, 0.0),
    }
}

#[test]
fn the_guessed_sample_is_the_one_a_binary_search_finds_whatever_the_hint() {
    // Steady (100 ms), jittered, with a long gap, and with repeated times.
    let steady: Vec<u64> = (0..50).map(|k| 1_000 + k * 100_000).collect();
    let jittered: Vec<u64> = (0..50).map(|k| k * 100_000 + (k * 7919) % 40_000).collect();
    let mut gapped = steady.clone();
    gapped.extend((0..10).map(|k| 60_000_000 + k * 50_000));
    let repeated = vec![0, 0, 10, 10, 10, 20, 50, 50];
    for times in [steady, jittered, gapped, repeated, vec![5], vec![]] {
        let track: Vec<PoseSample> = times.iter().map(|&t| sample(t, 0.0, 0.0)).collect();
        let end = times.last().copied().unwrap_or(0) + 200_000;
        for t in (0..end).step_by(997).chain(times.iter().copied()) {
            let want = track.partition_point(|s| s.t_us <= t);
            for hint in [0, want.saturating_sub(1), want, want + 1, track.len() + 1] {
                let got = at_or_before(&track, t, hint);
                assert_eq!(got, want, "t {t} hint {hint} in {times:?}");
            }
        }
    }
}

#[test]
fn the_yaw_wrap_is_rem_euclid() {
    for x in [
        -725.5, -360.0, -0.0, 0.0, 1e-12, 359.999, 360.0, 500.0, 720.0, 1e6,
    ] {
        assert_eq!(
            fold(x, 360.0).to_bits(),
            x.rem_euclid(360.0).to_bits(),
            "{x}"
        );
        let rad = x.to_radians();
        assert_eq!(
            fold(rad, TAU).to_bits(),
            rad.rem_euclid(TAU).to_bits(),
            "{rad}"
        );
    }
}

#[test]
fn interpolates_between_samples_and_the_short_way_round() {
    let mut p = Poses::new();
    p.add(sample(1_000_000, 0.0, 170.0));
    p.add(sample(1_100_000, 1.0, -170.0));
    let mid = p.at("r", 1, 1_050_000).expect("between two samples");
    assert!((mid.pose.position[0] - 0.5).abs() < 1e-12);
    // 170° to −170° is 20° through 180°, not 340° back through 0°.
    let yaw = mid.pose.yaw_rad;
    assert!((yaw.abs() - std::f64::consts::PI).abs() < 1e-12, "{yaw}");
    // A quarter of the way from 170°: 175°, in radians; a quarter from −170°: −175°.
    let quarter = |t| p.at("r", 1, t).expect("between two samples").pose.yaw_rad;
    assert!((quarter(1_025_000) - 175f64.to_radians()).abs() < 1e-12);
    assert!((quarter(1_075_000) + 175f64.to_radians()).abs() < 1e-12);
    assert_eq!(
        p.at("r", 1, 1_000_000).map(|s| s.pose.position[0]),
        Some(0.0)
    );
    // Outside the track, another antenna or reader: no pose.
    assert!(p.at("r", 1, 999_999).is_none());
    assert!(p.at("r", 1, 1_100_001).is_none());
    assert!(p.at("r", 2, 1_050_000).is_none());
    assert!(p.at("q", 1, 1_050_000).is_none());
}

#[test]
fn a_gap_beyond_the_reach_is_no_pose_and_offsets_shift_the_clock() {
    let mut p = Poses::new().with_reach(200_000);
    p.add(sample(0, 0.0, 0.0));
    p.add(sample(100_000, 1.0, 0.0));
    p.add(sample(1_000_000, 2.0, 0.0));
    assert!(p.at("r", 1, 50_000).is_some());
    assert!(p.at("r", 1, 500_000).is_none(), "900 ms between samples");
    // The reader's clock runs 30 ms ahead of the robot's.
    p.set_offset("r", 30_000);
    let shifted = p.at("r", 1, 80_000).expect("robot time 50 ms");
    assert!((shifted.pose.position[0] - 0.5).abs() < 1e-12);
    assert!(
        p.at("r", 1, 10_000).is_none(),
        "before the robot's first sample"
    );
}

#[test]
fn reads_jsonl_and_csv_alike_and_names_bad_fields() {
    let jsonl = concat!(
        r#"{"t_us": 0, "reader": "r", "antenna": 1, "x": 0, "y": 2, "z": 0.5, "yaw_deg": 0, "pitch_deg": 0}"#,
        "\n",
        r#"{"t_us": 100000, "reader": "r", "antenna": 1, "x": 1, "y": 2, "z": 0.5, "yaw_deg": 0, "pitch_deg": 0}"#,
        "\n"
    );
    let csv =
        "t_us,reader,antenna,x,y,z,yaw_deg,pitch_deg\n0,r,1,0,2,0.5,0,0\n100000,r,1,1,2,0.5,0,0\n";
    let a = Poses::read(jsonl.as_bytes()).expect("JSON Lines");
    let b = Poses::read(csv.as_bytes()).expect("CSV");
    assert_eq!(a.len(), 2);
    assert_eq!(a.at("r", 1, 25_000), b.at("r", 1, 25_000));
    let bad = "t_us,reader,antenna,x,y,z,yaw_deg,pitch_deg\n0,r,1,0,two,0.5,0,0\n";
    let e = Poses::read(bad.as_bytes()).expect_err("y is not a number");
    assert_eq!(e.to_string(), "line 2: y: not a number: \"two\"");
    let e = Poses::read("t_us,reader,x\n".as_bytes()).expect_err("columns missing");
    assert!(e
        .to_string()
        .starts_with("line 1: CSV header lacks the column \"antenna\""));
    let e = Poses::read(r#"{"t_us": 0, "antenna": 1, "x": 0, "y": 0}"#.as_bytes())
        .expect_err("z missing");
    assert!(e.to_string().contains("z"), "{e}");
    let e = Poses::read(r#"{"t_us": 0, "antenna": 0, "x": 0, "y": 0, "z": 0}"#.as_bytes())
        .expect_err("port 0");
    assert_eq!(
        e.to_string(),
        "line 1: antenna: must be a port number from 1"
    );
}

#[test]
fn a_pose_file_is_loaded_by_its_path_and_its_errors_name_the_file_and_the_line() {
    let dir = std::env::temp_dir().join(format!("llrp-gateway-poses-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("a temporary folder");
    let good = dir.join("good.csv");
    std::fs::write(
        &good,
        "t_us,reader,antenna,x,y,z,yaw_deg,pitch_deg\n0,r,1,0,2,0.5,0,0\n",
    )
    .expect("written");
    assert_eq!(Poses::load(&good).expect("loads").len(), 1);
    let bad = dir.join("bad.csv");
    std::fs::write(
        &bad,
        "t_us,reader,antenna,x,y,z,yaw_deg,pitch_deg\n0,r,1,0,two,0.5,0,0\n",
    )
    .expect("written");
    let e = Poses::load(&bad)
        .expect_err("y is not a number")
        .to_string();
    assert_eq!(
        e,
        format!("{}: line 2: y: not a number: \"two\"", bad.display())
    );
    let missing = dir.join("missing.csv");
    let e = Poses::load(&missing).expect_err("no such file").to_string();
    assert!(e.starts_with(&format!("{}: ", missing.display())), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_spreadsheets_csv_reads_as_the_plain_one() {
    // Excel's "CSV UTF-8": a byte-order mark, CRLF line ends, and a reader name with a comma
    // quoted.
    let excel = "\u{feff}t_us,reader,antenna,x,y,z,yaw_deg,pitch_deg\r\n\
                 0,\"dock, north\",1,0,2,0.5,90,0\r\n\
                 1000,\"dock, north\",1,0.1,2,0.5,90,0\r\n";
    let poses = Poses::read(excel.as_bytes()).expect("reads");
    assert_eq!(poses.len(), 2);
    let p = poses
        .at("dock, north", 1, 500)
        .expect("between the two samples");
    assert!((p.pose.position[0] - 0.05).abs() < 1e-12, "{p:?}");
    let err = Poses::read(
        "\u{feff}t_us,reader,antenna,x,y,z,yaw_deg,pitch_deg\r\n\r\n0,r,1,0,two,0.5,0,0\r\n"
            .as_bytes(),
    )
    .expect_err("y is not a number")
    .to_string();
    assert_eq!(err, "line 3: y: not a number: \"two\"");
    let jsonl = "\u{feff}{\"t_us\":0,\"reader\":\"r\",\"antenna\":1,\"x\":0,\"y\":0,\"z\":0,\"yaw_deg\":0}\r\n";
    assert_eq!(Poses::read(jsonl.as_bytes()).expect("JSON Lines").len(), 1);
}
