//! MCAP in (docs/robotics.md): `localize READS --poses BAG --pose-topic TOPIC` with bags made
//! as a robot records them, by Python's `rosbags` 0.11.9 (`scripts/interop/make_pose_bag.py`
//! in the venv of `scripts/venv-mcap.sh`, named by `LLRP_MCAP_PYTHON`) from the S1 fixture's
//! antenna poses, the robot's pose being the antenna's less a mounting offset: every kind of
//! pose topic, on the reads' clock or another, gives the estimates of the pose file itself.
//! And `localize FILE.mcap` of an exported recording gives the recording's estimates; bad
//! bags are refused naming the file, the topic and why.

use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::Value;

/// The antenna's mounting on the robot the bags are made with.
const OFFSET: &str = "0.1,0.2,0.3,90";
/// The S1 fixture's clock offset (reader time − pose file time, µs).
const S1_OFFSET_US: i64 = 1_796_166_070_735_126;

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fixtures/localize")
        .join(name)
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8")
}

/// A bag of `kind` (amcl, pose, odom, tf) of the S1 poses with the robot's clock `shift_us`
/// ahead of the pose file's; the bag's directory.
fn make_bag(dir: &Path, kind: &str, shift_us: i64) -> PathBuf {
    let python = std::env::var("LLRP_MCAP_PYTHON").expect(
        "LLRP_MCAP_PYTHON must name the python of scripts/venv-mcap.sh (set by ./scripts/test)",
    );
    let out = dir.join(format!("{kind}-{shift_us}"));
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/interop/make_pose_bag.py");
    let run = Command::new(python)
        .arg(script)
        .arg(fixture("s1-report-per-read.poses.jsonl"))
        .arg(&out)
        .args(["--kind", kind, "--offset", OFFSET])
        .arg(format!("--shift-us={shift_us}"))
        .output()
        .expect("the script runs");
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    out
}

/// A settings file of S1's phase sign and `clock_offset_us` (and `extra` keys).
fn settings(dir: &Path, clock_offset_us: i64, extra: &str) -> PathBuf {
    let path = dir.join(format!("settings-{clock_offset_us}.json"));
    let text = format!(
        r#"{{"phase_sign": 1, "clock_offsets_us": {{"s1-reader": {clock_offset_us}}}{extra}}}"#
    );
    std::fs::write(&path, text).expect("written");
    path
}

/// `localize INPUT ARGS --output OUT`: its status, the estimates and its stderr.
fn localize(input: &Path, args: &[&str], out: &Path) -> (bool, Option<Value>, String) {
    let run = Command::new(env!("CARGO_BIN_EXE_llrp-gateway"))
        .arg("localize")
        .arg(input)
        .args(args)
        .arg("--force")
        .arg("--output")
        .arg(out)
        .output()
        .expect("runs");
    let json = if run.status.success() {
        let text = std::fs::read_to_string(out).expect("the estimates");
        Some(serde_json::from_str(&text).expect("JSON"))
    } else {
        None
    };
    (
        run.status.success(),
        json,
        String::from_utf8_lossy(&run.stderr).into_owned(),
    )
}

/// The estimates of the S1 recording with its pose file.
fn reference(dir: &Path) -> Value {
    let settings = fixture("s1-report-per-read.settings.json");
    let poses = fixture("s1-report-per-read.poses.jsonl");
    let (ok, json, err) = localize(
        &fixture("s1-report-per-read.jsonl"),
        &["--poses", s(&poses), "--settings", s(&settings)],
        &dir.join("reference.json"),
    );
    assert!(ok, "{err}");
    json.expect("estimates")
}

/// Asserts `got` has `want`'s tags, each in the same state and within a micrometre.
fn assert_same_estimates(want: &Value, got: &Value, what: &str) {
    let tags = |v: &Value| v["tags"].as_array().expect("tags").clone();
    let (want, got) = (tags(want), tags(got));
    assert_eq!(want.len(), got.len(), "{what}: tag count");
    assert!(!want.is_empty());
    for w in &want {
        let g = got
            .iter()
            .find(|g| g["epc"] == w["epc"])
            .unwrap_or_else(|| panic!("{what}: {} not localized", w["epc"]));
        assert_eq!(w["state"], g["state"], "{what}: {}", w["epc"]);
        for k in ["x", "y"] {
            let (a, b) = (&w["estimate"][k], &g["estimate"][k]);
            let d = (a.as_f64().expect("a number") - b.as_f64().expect("a number")).abs();
            assert!(d < 1e-6, "{what}: {} {k}: {a} vs {b}", w["epc"]);
        }
    }
}

#[test]
#[ignore = "needs LLRP_MCAP_PYTHON (scripts/venv-mcap.sh)"]
fn an_amcl_pose_bag_with_the_antenna_offset_localizes_as_the_pose_file() {
    let dir = tempfile::tempdir().expect("temp dir");
    let want = reference(dir.path());
    let bag = make_bag(dir.path(), "amcl", 0);
    let settings = settings(dir.path(), S1_OFFSET_US, "");
    let args = [
        "--poses",
        s(&bag),
        "--pose-topic",
        "/amcl_pose",
        "--antenna-offset",
        OFFSET,
        "--settings",
        s(&settings),
    ];
    let (ok, got, err) = localize(
        &fixture("s1-report-per-read.jsonl"),
        &args,
        &dir.path().join("o.json"),
    );
    assert!(ok, "{err}");
    assert_same_estimates(&want, &got.expect("estimates"), "/amcl_pose");
}

#[test]
#[ignore = "needs LLRP_MCAP_PYTHON (scripts/venv-mcap.sh)"]
fn a_bag_on_another_clock_with_its_stated_offset_and_the_settings_mounting_localizes_alike() {
    let dir = tempfile::tempdir().expect("temp dir");
    let want = reference(dir.path());
    // The robot's clock: 2023-11-14, not the reader's.
    let shift = 1_700_000_000_000_000;
    let bag = make_bag(dir.path(), "amcl", shift);
    let mounting =
        r#", "antenna_offsets": [{"antenna": 1, "x": 0.1, "y": 0.2, "z": 0.3, "yaw_deg": 90}]"#;
    let settings = settings(dir.path(), S1_OFFSET_US - shift, mounting);
    let bag_file = bag.join(format!("amcl-{shift}.mcap"));
    for poses in [&bag, &bag_file] {
        let args = ["--poses", s(poses), "--settings", s(&settings)];
        let (ok, got, err) = localize(
            &fixture("s1-report-per-read.jsonl"),
            &args,
            &dir.path().join("o.json"),
        );
        assert!(ok, "{err}");
        assert_same_estimates(&want, &got.expect("estimates"), s(poses));
    }
}

#[test]
#[ignore = "needs LLRP_MCAP_PYTHON (scripts/venv-mcap.sh)"]
fn pose_stamped_odometry_and_a_tf_chain_give_the_pose_file_s_estimates() {
    let dir = tempfile::tempdir().expect("temp dir");
    let want = reference(dir.path());
    let settings = settings(dir.path(), S1_OFFSET_US, "");
    for (kind, topic, frames) in [
        ("pose", "/robot_pose", None),
        ("odom", "/odom", None),
        ("tf", "/tf", Some("map,odom,base_link")),
    ] {
        let bag = make_bag(dir.path(), kind, 0);
        let mut args = vec!["--poses", s(&bag), "--pose-topic", topic];
        args.extend(["--antenna-offset", OFFSET, "--settings", s(&settings)]);
        if let Some(f) = frames {
            args.extend(["--frames", f]);
        }
        let (ok, got, err) = localize(
            &fixture("s1-report-per-read.jsonl"),
            &args,
            &dir.path().join("o.json"),
        );
        assert!(ok, "{kind}: {err}");
        assert_same_estimates(&want, &got.expect("estimates"), kind);
    }
}

#[test]
#[ignore = "needs LLRP_MCAP_PYTHON (scripts/venv-mcap.sh)"]
fn a_bag_without_the_topic_of_another_type_or_a_broken_chain_is_refused_by_name() {
    let dir = tempfile::tempdir().expect("temp dir");
    let amcl = make_bag(dir.path(), "amcl", 0);
    let tf = make_bag(dir.path(), "tf", 0);
    let reads = fixture("s1-report-per-read.jsonl");
    let out = dir.path().join("o.json");
    let refused = |bag: &Path, more: &[&str], says: &[&str]| {
        let mut args = vec!["--poses", s(bag)];
        args.extend(more);
        let (ok, _, err) = localize(&reads, &args, &out);
        assert!(!ok, "{more:?} was taken");
        for w in says {
            assert!(err.contains(w), "{more:?}: {w:?} not in {err}");
        }
    };
    refused(
        &amcl,
        &["--pose-topic", "/odom"],
        &[
            s(&amcl),
            "topic /odom",
            "no such topic",
            "/amcl_pose (geometry_msgs/msg/PoseWithCovarianceStamped)",
        ],
    );
    refused(
        &amcl,
        &["--pose-topic", "/amcl_pose", "--frames", "map,base_link"],
        &["topic /amcl_pose", "TFMessage"],
    );
    refused(
        &tf,
        &["--pose-topic", "/tf", "--frames", "map,base_link"],
        &[
            "topic /tf",
            "does not connect",
            "no transform from map to base_link",
            "map -> odom",
        ],
    );
    refused(
        &tf,
        &["--pose-topic", "/tf"],
        &["topic /tf", "needs the frame chain"],
    );
    let broken = dir.path().join("broken.mcap");
    let mut bytes = std::fs::read(amcl.join("amcl-0.mcap")).expect("the bag");
    bytes.truncate(200);
    std::fs::write(&broken, bytes).expect("written");
    refused(&broken, &[], &[s(&broken), "MCAP"]);
    // A bag of no TagRead as localize's input.
    let (ok, _, err) = localize(&amcl, &[], &out);
    assert!(
        !ok && err.contains("no llrp_gateway_msgs/msg/TagRead messages"),
        "{err}"
    );
    assert!(
        err.contains(s(&amcl)) && err.contains("/amcl_pose"),
        "{err}"
    );
}

#[test]
fn an_exported_recording_localizes_from_its_mcap_file_as_from_the_recording() {
    let dir = tempfile::tempdir().expect("temp dir");
    let want = reference(dir.path());
    let mcap = dir.path().join("s1.mcap");
    let export = Command::new(env!("CARGO_BIN_EXE_llrp-gateway"))
        .arg("export")
        .arg(fixture("s1-report-per-read.jsonl"))
        .arg("--mcap")
        .arg(&mcap)
        .output()
        .expect("runs");
    assert!(
        export.status.success(),
        "{}",
        String::from_utf8_lossy(&export.stderr)
    );
    let settings = fixture("s1-report-per-read.settings.json");
    let poses = fixture("s1-report-per-read.poses.jsonl");
    let args = ["--poses", s(&poses), "--settings", s(&settings)];
    let (ok, got, err) = localize(&mcap, &args, &dir.path().join("o.json"));
    assert!(ok, "{err}");
    assert_same_estimates(&want, &got.expect("estimates"), "localize s1.mcap");
}

/// `inventory` for 3 s against `replay FILE --speed max`: its reads.
fn inventory_of_replay(file: &Path, out: &Path) -> Vec<llrp_gateway::reads::Read> {
    use std::io::{BufRead, BufReader};
    let mut child = Command::new(env!("CARGO_BIN_EXE_llrp-gateway"))
        .arg("replay")
        .arg(file)
        .args(["--listen", "127.0.0.1:0", "--speed", "max"])
        .stderr(std::process::Stdio::piped())
        .stdout(std::process::Stdio::null())
        .spawn()
        .expect("runs");
    let stderr = child.stderr.take().expect("piped");
    let mut lines = BufReader::new(stderr).lines();
    let addr = lines.by_ref().map_while(Result::ok).find_map(|l| {
        l.split("listening on ")
            .nth(1)
            .map(|a| a.trim().to_string())
    });
    // Drain the rest so the replay never blocks on a full pipe.
    std::thread::spawn(move || lines.for_each(drop));
    let Some(addr) = addr else {
        let _ = child.kill();
        panic!("{}: no listening line", file.display());
    };
    let status = Command::new(env!("CARGO_BIN_EXE_llrp-gateway"))
        .args([
            "inventory",
            &addr,
            "--name",
            "dock",
            "--seconds",
            "3",
            "--impinj",
        ])
        .arg("--output")
        .arg(out)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .status()
        .expect("inventory runs");
    let _ = child.kill();
    let _ = child.wait();
    assert!(status.success(), "inventory against {}", file.display());
    llrp_gateway::reads::read_jsonl(BufReader::new(std::fs::File::open(out).expect("reads")))
        .expect("parses")
}

#[test]
fn a_replay_of_an_exported_mcap_file_gives_the_inventory_the_recording_s_reads() {
    let dir = tempfile::tempdir().expect("temp dir");
    let rec =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/sessions/dock-door-inventory.jsonl");
    let mcap = dir.path().join("dock.mcap");
    let export = Command::new(env!("CARGO_BIN_EXE_llrp-gateway"))
        .arg("export")
        .arg(&rec)
        .arg("--mcap")
        .arg(&mcap)
        .output()
        .expect("runs");
    assert!(
        export.status.success(),
        "{}",
        String::from_utf8_lossy(&export.stderr)
    );
    let want = inventory_of_replay(&rec, &dir.path().join("jsonl.jsonl"));
    let got = inventory_of_replay(&mcap, &dir.path().join("mcap.jsonl"));
    assert!(!want.is_empty());
    assert_eq!(want.len(), got.len(), "reads");
    if let Some(i) = (0..want.len()).find(|&i| want[i] != got[i]) {
        panic!(
            "read {i}: {:?} from the JSON Lines, {:?} from the MCAP",
            want[i], got[i]
        );
    }
}

#[test]
fn an_mcap_file_cut_after_its_magic_is_not_replayed_and_is_named() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mcap = dir.path().join("cut.mcap");
    std::fs::write(&mcap, b"\x89MCAP0\r\n").expect("written");
    let out = Command::new(env!("CARGO_BIN_EXE_llrp-gateway"))
        .arg("replay")
        .arg(&mcap)
        .args(["--listen", "127.0.0.1:0"])
        .output()
        .expect("runs");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains(s(&mcap)) && err.contains("MCAP"), "{err}");
}
