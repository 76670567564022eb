//! `llrp-gateway localize` over the shipped S1 recording (a report per read) with the robot's
//! own pose file and its settings file: every tag converges, within the figures
//! docs/localize.md gives; a reads file carrying each read's `antenna_pose` gives the same
//! estimates; bad files are refused naming the line or field. And `bench localize` names an
//! estimator asked for that does not apply to its scenario, and why.

use std::path::{Path, PathBuf};
use std::process::Command;

use llrp_gateway::cli::localize::load_reads;
use llrp_gateway::localize::offline::SettingsFile;
use llrp_gateway::localize::poses::Poses;
use llrp_gateway::reads::write_jsonl;

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fixtures/localize")
        .join(name)
}

/// Runs `localize` with `args`; its exit status, the estimates (when written) and stderr.
fn localize(args: &[&str], output: &Path) -> (bool, Option<serde_json::Value>, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_llrp-gateway"))
        .arg("localize")
        .args(args)
        .arg("--force")
        .arg("--output")
        .arg(output)
        .output()
        .expect("runs");
    let json = std::fs::read_to_string(output)
        .ok()
        .map(|t| serde_json::from_str(&t).expect("the output is JSON"));
    (
        out.status.success(),
        json,
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Runs `localize` on the shipped S1 recording with its pose file and the settings file
/// `settings`.
fn localize_s1(settings: &Path, output: &Path) -> (bool, Option<serde_json::Value>, String) {
    let rec = fixture("s1-report-per-read.jsonl");
    let poses = fixture("s1-report-per-read.poses.jsonl");
    localize(
        &[
            rec.to_str().expect("utf-8"),
            "--poses",
            poses.to_str().expect("utf-8"),
            "--settings",
            settings.to_str().expect("utf-8"),
        ],
        output,
    )
}

/// S1's true tag positions, by EPC.
fn truth() -> Vec<(String, [f64; 3])> {
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/scenarios/s1.json"),
    )
    .expect("s1.json");
    let v: serde_json::Value = serde_json::from_str(&text).expect("JSON");
    v["tags"]
        .as_array()
        .expect("tags")
        .iter()
        .map(|t| {
            let p = &t["position"];
            (
                t["epc"].as_str().expect("epc").to_string(),
                [0, 1, 2].map(|i| p[i].as_f64().expect("a number")),
            )
        })
        .collect()
}

/// Each S1 tag's 2D error (m) in `estimates`, every tag in one of the states `states`.
fn errors(estimates: &serde_json::Value, states: &[&str]) -> Vec<f64> {
    let tags = estimates["tags"].as_array().expect("tags");
    truth()
        .iter()
        .map(|(epc, p)| {
            let t = tags
                .iter()
                .find(|t| t["epc"] == epc.as_str())
                .unwrap_or_else(|| panic!("{epc} was not localized"));
            assert!(states.iter().any(|s| t["state"] == *s), "{t}");
            let e = &t["estimate"];
            let (x, y) = (e["x"].as_f64().expect("x"), e["y"].as_f64().expect("y"));
            (x - p[0]).hypot(y - p[1])
        })
        .collect()
}

/// Whether every S1 tag's true position lies inside its estimate's 95 % ellipse.
fn ellipses_hold_the_truth(estimates: &serde_json::Value) -> Result<(), String> {
    let tags = estimates["tags"].as_array().expect("tags");
    for (epc, p) in truth() {
        let t = tags
            .iter()
            .find(|t| t["epc"] == epc.as_str())
            .ok_or_else(|| format!("{epc} was not localized"))?;
        let c: Vec<f64> = t["covariance"]
            .as_array()
            .expect("a covariance")
            .iter()
            .map(|v| v.as_f64().expect("a number"))
            .collect();
        let e = &t["estimate"];
        let (dx, dy) = (
            p[0] - e["x"].as_f64().expect("x"),
            p[1] - e["y"].as_f64().expect("y"),
        );
        // The squared Mahalanobis distance against χ²(2) at 95 %.
        let det = c[0] * c[4] - c[1] * c[3];
        let m2 = (c[4] * dx * dx - (c[1] + c[3]) * dx * dy + c[0] * dy * dy) / det;
        if m2.is_nan() || m2 > 5.991 {
            return Err(format!("{epc}: Mahalanobis² {m2:.1}: {t}"));
        }
    }
    Ok(())
}

#[test]
fn the_s1_recording_with_the_robots_poses_localizes_every_tag_as_documented() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("estimates.json");
    let settings = fixture("s1-report-per-read.settings.json");
    let (ok, json, stderr) = localize_s1(&settings, &out);
    assert!(ok, "{stderr}");
    assert!(stderr.contains("10 tags from"), "{stderr}");
    let json = json.expect("estimates written");
    // relock's covariance counts its residuals' correlation along the pass (the poses' own
    // error here), so a tag whose fix that error moved says "converging", not "converged".
    let errors = errors(&json, &["converged", "converging"]);
    let mean = errors.iter().sum::<f64>() / errors.len() as f64;
    let max = errors.iter().cloned().fold(0.0, f64::max);
    // docs/localize.md: 32.5 mm mean, 71 mm max with the robot's own (localized) poses.
    assert!(mean < 0.040 && max < 0.090, "mean {mean} m, max {max} m");
    // The same keys as GET /api/tags.
    let t = &json["tags"][0];
    for key in [
        "epc",
        "estimate",
        "covariance",
        "estimator",
        "state",
        "samples",
        "last_seen",
        "reads_per_s",
    ] {
        assert!(t.get(key).is_some(), "no {key} in {t}");
    }
    assert_eq!(t["estimator"], "relock");
}

#[test]
fn a_reads_file_with_antenna_poses_gives_the_recordings_estimates() {
    let dir = tempfile::tempdir().expect("temp dir");
    let rec = fixture("s1-report-per-read.jsonl");
    let pose_file = fixture("s1-report-per-read.poses.jsonl");
    let settings_file = fixture("s1-report-per-read.settings.json");
    // The reads, each with the pose it would be given, as one JSON read a line.
    let settings = SettingsFile::load(&settings_file).expect("settings");
    let mut poses = Poses::read(std::io::BufReader::new(
        std::fs::File::open(&pose_file).expect("poses"),
    ))
    .expect("a pose file");
    for (reader, offset) in &settings.clock_offsets_us {
        poses.set_offset(reader, *offset);
    }
    let reads_path = dir.path().join("reads.jsonl");
    let mut file = std::io::BufWriter::new(std::fs::File::create(&reads_path).expect("creates"));
    for mut r in load_reads(&rec).expect("reads") {
        let reader = r.reader.as_deref().unwrap_or_default();
        let Some(p) = poses.at(reader, r.antenna, r.t_us) else {
            continue;
        };
        r.antenna_pose = Some(p.pose);
        write_jsonl(&mut file, &r).expect("writes");
    }
    drop(file);
    let a = dir.path().join("a.json");
    let b = dir.path().join("b.json");
    let (ok, from_recording, stderr) = localize(
        &[
            rec.to_str().expect("utf-8"),
            "--poses",
            pose_file.to_str().expect("utf-8"),
            "--settings",
            settings_file.to_str().expect("utf-8"),
        ],
        &a,
    );
    assert!(ok, "{stderr}");
    let (ok, from_reads, stderr) = localize(&[reads_path.to_str().expect("utf-8")], &b);
    assert!(ok, "{stderr}");
    let (a, b) = (from_recording.expect("a"), from_reads.expect("b"));
    let (ta, tb) = (
        a["tags"].as_array().expect("a"),
        b["tags"].as_array().expect("b"),
    );
    assert_eq!(ta.len(), tb.len());
    for (x, y) in ta.iter().zip(tb) {
        assert_eq!(x["epc"], y["epc"]);
        for k in ["x", "y"] {
            let (p, q) = (
                x["estimate"][k].as_f64().expect("p"),
                y["estimate"][k].as_f64().expect("q"),
            );
            assert!((p - q).abs() < 1e-6, "{k}: {p} vs {q}");
        }
    }
}

#[test]
fn the_robots_pose_error_in_the_settings_brings_the_tags_closer_and_ellipses_that_hold_them() {
    let dir = tempfile::tempdir().expect("temp dir");
    let rec = fixture("s1-report-per-read.jsonl");
    let poses = fixture("s1-report-per-read.poses.jsonl");
    let plain = fixture("s1-report-per-read.settings.json");
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&plain).expect("settings")).expect("JSON");
    // S1's own pose estimate (docs/scenarios.md): σ 15 mm, correlated over 2 s.
    v["pose_error"] = serde_json::json!({"sigma_m": 0.015, "correlation_s": 2.0});
    let refined = dir.path().join("refined.json");
    std::fs::write(&refined, v.to_string()).expect("writes");
    let mean = |settings: &Path, estimator: &str| {
        let out = dir.path().join("estimates.json");
        let (ok, json, stderr) = localize(
            &[
                rec.to_str().expect("utf-8"),
                "--poses",
                poses.to_str().expect("utf-8"),
                "--settings",
                settings.to_str().expect("utf-8"),
                "--estimator",
                estimator,
            ],
            &out,
        );
        assert!(ok, "{stderr}");
        let json = json.expect("estimates written");
        if settings == refined.as_path() {
            // The stated pose error is in every covariance: honest ellipses, no tag
            // "converged" at its σ from the phases alone.
            ellipses_hold_the_truth(&json).unwrap_or_else(|e| panic!("{estimator}: {e}"));
            let e = errors(&json, &["converging"]);
            e.iter().sum::<f64>() / e.len() as f64
        } else {
            let e = errors(&json, &["converged", "converging"]);
            e.iter().sum::<f64>() / e.len() as f64
        }
    };
    // docs/localize.md: relock 32.5 → 16.8 mm, linear 16.5 → 13.9 mm.
    let (relock, relock_refined) = (mean(&plain, "relock"), mean(&refined, "relock"));
    assert!(
        relock_refined < 0.020 && relock_refined < 0.6 * relock,
        "relock {relock} → {relock_refined} m"
    );
    let (linear, linear_refined) = (mean(&plain, "linear"), mean(&refined, "linear"));
    assert!(
        linear_refined < 0.015 && linear_refined < linear,
        "linear {linear} → {linear_refined} m"
    );
}

#[test]
fn bad_settings_and_reads_files_are_refused_naming_what_is_wrong() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("out.json");
    let rec = fixture("s1-report-per-read.jsonl");
    let settings = dir.path().join("settings.json");
    std::fs::write(&settings, r#"{"phase_sign": 1, "facing": [0, "up"]}"#).expect("writes");
    let (ok, _, stderr) = localize(
        &[
            rec.to_str().expect("utf-8"),
            "--settings",
            settings.to_str().expect("utf-8"),
        ],
        &out,
    );
    assert!(!ok);
    assert!(stderr.contains("facing"), "{stderr}");
    std::fs::write(&settings, r#"{"phase_sign": 2}"#).expect("writes");
    let (ok, _, stderr) = localize(
        &[
            rec.to_str().expect("utf-8"),
            "--settings",
            settings.to_str().expect("utf-8"),
        ],
        &out,
    );
    assert!(
        !ok && stderr.contains("phase_sign: must be 1 or -1"),
        "{stderr}"
    );
    // A reader's own settings are checked as the defaults are, named by the reader.
    for (body, want) in [
        (
            r#"{"readers": {"left": {"phase_sign": 0}}}"#,
            "readers.left.phase_sign: must be 1 or -1",
        ),
        (
            r#"{"readers": {"left": {"facing": [0, 0]}}}"#,
            "readers.left.facing: must be a non-zero direction",
        ),
        (r#"{"readers": {"left": {"gain": 1}}}"#, "gain"),
        (r#"{"min_rssi_dbm": "weak"}"#, "min_rssi_dbm"),
        (
            r#"{"pose_error": {"sigma_m": -0.01, "correlation_s": 2}}"#,
            "pose_error.sigma_m: must be a positive number",
        ),
        (
            r#"{"pose_error": {"sigma_m": 0.01, "correlation_s": 0}}"#,
            "pose_error.correlation_s: must be a positive number",
        ),
    ] {
        std::fs::write(&settings, body).expect("writes");
        let (ok, _, stderr) = localize(
            &[
                rec.to_str().expect("utf-8"),
                "--settings",
                settings.to_str().expect("utf-8"),
            ],
            &out,
        );
        assert!(!ok && stderr.contains(want), "{body}: {stderr}");
    }
    let reads = dir.path().join("reads.jsonl");
    std::fs::write(
        &reads,
        "{\"epc\":\"AA\",\"antenna\":1,\"t_us\":1,\"phase_rad\":1.0,\"channel_frequency_hz\":866000000}\n{\"epc\":\"AA\",\"antenna\":\"one\"}\n",
    )
    .expect("writes");
    let (ok, _, stderr) = localize(&[reads.to_str().expect("utf-8")], &out);
    assert!(!ok && stderr.contains("line 2"), "{stderr}");
    assert!(!out.exists(), "nothing is written for a bad input");
}

/// Reads set aside for want of a pose or a phase: the summary says what to give.
#[test]
fn reads_set_aside_come_with_the_remedy() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("out.json");
    let reads = dir.path().join("reads.jsonl");
    std::fs::write(
        &reads,
        "{\"epc\":\"AA\",\"antenna\":1,\"t_us\":1,\"phase_rad\":1.0,\"channel_frequency_hz\":866000000}\n\
         {\"epc\":\"AB\",\"antenna\":1,\"t_us\":2,\"channel_frequency_hz\":866000000}\n",
    )
    .expect("writes");
    let (ok, _, stderr) = localize(&[reads.to_str().expect("utf-8")], &out);
    assert!(ok, "{stderr}");
    assert!(
        stderr.contains("1 reads have no antenna pose: give one with --poses FILE"),
        "{stderr}"
    );
    assert!(stderr.contains("antenna_pose"), "{stderr}");
    assert!(
        stderr.contains("1 reads have no phase") && stderr.contains("--impinj"),
        "{stderr}"
    );
}

#[test]
fn reads_under_the_settings_rssi_floor_are_set_aside_and_counted() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("out.json");
    let settings = dir.path().join("settings.json");
    let run = |floor: f64| {
        std::fs::write(
            &settings,
            format!(
                r#"{{"phase_sign": 1, "clock_offsets_us": {{"s1-reader": 1796166070735126}}, "min_rssi_dbm": {floor}}}"#
            ),
        )
        .expect("writes");
        let (ok, json, stderr) = localize_s1(&settings, &out);
        assert!(ok, "{stderr}");
        // Tags located: a tag all of whose reads were set aside is listed without a position.
        let tags = json.expect("estimates")["tags"]
            .as_array()
            .expect("tags")
            .iter()
            .filter(|t| !t["estimate"].is_null())
            .count();
        // "… from N reads (M set aside: … K under the RSSI floor)"
        let number_before = |what: &str| -> u64 {
            let head = &stderr[..stderr.find(what).expect(what)];
            let word = head.split_whitespace().last().expect("a number");
            word.parse().expect("a number")
        };
        (
            tags,
            number_before(" reads ("),
            number_before(" under the RSSI floor"),
        )
    };
    // No S1 read is as strong as 0 dBm: every one is set aside, and no tag is located.
    let (tags, taken, weak) = run(0.0);
    assert_eq!((tags, taken), (0, 0));
    assert!(weak > 0);
    // A floor under every read sets none aside: the same reads are filed, every tag located.
    let (tags, taken, none) = run(-200.0);
    assert_eq!((tags, none), (10, 0));
    assert!(taken > 0 && taken <= weak, "{taken} of {weak}");
}

#[test]
fn bench_localize_names_an_estimator_that_does_not_apply() {
    let bench = |estimators: &[&str]| {
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_llrp-gateway"));
        cmd.args(["bench", "localize", "--scenario", "S1", "--live-speed", "0"]);
        for e in estimators {
            cmd.args(["--estimator", e]);
        }
        let out = cmd.output().expect("runs");
        let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
        let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
        (out.status.success(), stdout, stderr)
    };
    // S1's reader is not calibrated: mhekf alone is refused, saying why, with no table.
    let (ok, stdout, stderr) = bench(&["mhekf"]);
    assert!(!ok, "{stdout}");
    assert!(
        stderr.contains("mhekf does not apply to") && stderr.contains("not calibrated"),
        "{stderr}"
    );
    assert!(!stdout.contains("| estimator |"), "{stdout}");
    // Beside one that applies, it is named and the other's rows are there.
    let (ok, stdout, stderr) = bench(&["mhekf", "linear"]);
    assert!(ok, "{stderr}");
    assert!(stderr.contains("mhekf does not apply to"), "{stderr}");
    assert!(stdout.contains("| linear | true | 10/10 |"), "{stdout}");
    assert!(!stdout.contains("| mhekf"), "{stdout}");
}
