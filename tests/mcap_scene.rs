//! `sim --mcap FILE` with the live localizer (docs/robotics.md): its estimates on
//! `/estimates/tags` (`llrp_gateway_msgs/msg/TagEstimate`) and its scene on `/scene`
//! (`foxglove_msgs/msg/SceneUpdate`), read by the independent readers of
//! `scripts/interop/mcap_check.py` (`LLRP_MCAP_PYTHON`) and compared with the simulator's
//! ground truth file.

use std::collections::{BTreeMap, BTreeSet};
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::Stdio;
use std::time::{Duration, Instant};

use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use serde_json::Value;

mod mcap_support;
use mcap_support::*;

/// The 95 % quantile of χ² with 3 degrees of freedom.
const CHI2_95_3DOF: f64 = 7.814_727_903_251_178;

/// Tags whose estimate must be this sure (σ along the worse axis, m) before the run stops.
const SURE_M: f64 = 0.1;

/// `sim` at ten times real time with its localizer and HTTP API on free loopback ports,
/// writing `mcap` and the truth file `truth`; it and its HTTP address. Clean reads
/// (`--reader-model ideal`): S1's own `impinj-r420` gives each tag a phase curvature worth
/// ±12 cm in range, which the covariance owns up to, so no estimate gets as sure as
/// [`SURE_M`]; this test is about the scene and the estimates' messages, not accuracy.
fn sim(mcap: &Path, truth: &Path) -> (Proc, String) {
    let mut child = bin()
        .args(["sim", "--listen", "127.0.0.1:0", "--http", "127.0.0.1:0"])
        .args(["--speed", "10", "--reader-model", "ideal", "--mcap"])
        .arg(mcap)
        .arg("--truth")
        .arg(truth)
        .stderr(Stdio::piped())
        .stdout(Stdio::null())
        .spawn()
        .expect("it starts");
    let mut lines = BufReader::new(child.stderr.take().expect("piped")).lines();
    let until = Instant::now() + GUARD;
    let (mut http, mut reader) = (None, false);
    while http.is_none() || !reader {
        assert!(Instant::now() < until, "sim did not listen");
        let line = lines.next().expect("a line").expect("utf-8");
        if let Some(rest) = line.split("live map on http://").nth(1) {
            http = Some(rest.trim_end_matches('/').to_string());
        }
        reader |= line.contains("listening on");
    }
    std::thread::spawn(move || for _ in lines {});
    (Proc(child), http.expect("an HTTP address"))
}

/// σ along the worse axis of a 3×3 covariance (JSON numbers or nulls), m.
fn worse_sigma(c: &Value) -> Option<f64> {
    let c: Vec<f64> = c
        .as_array()?
        .iter()
        .map(Value::as_f64)
        .collect::<Option<_>>()?;
    Some(c[0].max(c[4]).max(c[8]).sqrt())
}

/// Waits (a hang guard, not a measurement) until the localizer is sure of three tags.
fn wait_for_sure_estimates(http: &str) {
    let until = Instant::now() + 3 * GUARD;
    loop {
        let tags = get_json(http, "/api/tags");
        let sure = (tags["tags"].as_array().expect("tags").iter())
            .filter(|t| worse_sigma(&t["covariance"]).is_some_and(|s| s <= SURE_M))
            .count();
        if sure >= 3 {
            return;
        }
        assert!(Instant::now() < until, "the localizer is not sure: {tags}");
        std::thread::sleep(Duration::from_millis(200));
    }
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("a number: {v}"))
}

fn vec3(v: &Value) -> [f64; 3] {
    [f(&v[0]), f(&v[1]), f(&v[2])]
}

fn covariance(v: &Value) -> Option<Matrix3<f64>> {
    let c: Vec<f64> = v
        .as_array()?
        .iter()
        .map(Value::as_f64)
        .collect::<Option<_>>()?;
    Some(Matrix3::from_row_slice(&c))
}

/// The unit vector `axis` (0: x, ...) of the frame rotated by `q` (x, y, z, w).
fn axis_of(q: &Value, axis: usize) -> Vector3<f64> {
    let [x, y, z, w] = [f(&q[0]), f(&q[1]), f(&q[2]), f(&q[3])];
    let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
    q * Vector3::ith(axis, 1.0)
}

#[test]
#[ignore = "needs the MCAP readers (LLRP_MCAP_PYTHON: scripts/venv-mcap.sh, set by ./scripts/test)"]
fn a_simulation_s_scene_and_estimates_decode_and_the_sure_estimates_lie_near_the_truth() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (mcap, truth) = (dir.path().join("sim.mcap"), dir.path().join("truth.jsonl"));
    let (mut sim, http) = sim(&mcap, &truth);
    wait_for_sure_estimates(&http);
    terminate(&mut sim);
    let v = check(&mcap);
    let truth: Vec<Value> = std::fs::read_to_string(&truth)
        .expect("the truth file")
        .lines()
        .map(|l| serde_json::from_str(l).expect("a truth line"))
        .collect();

    let ch = channels(&v);
    assert_eq!(ch["/scene"].0, "foxglove_msgs/msg/SceneUpdate");
    assert_eq!(ch["/estimates/tags"].0, "llrp_gateway_msgs/msg/TagEstimate");
    for decoder in ["mcap_ros2", "rosbags"] {
        assert_eq!(v[decoder]["scenes"], v["mcap_ros2"]["scenes"], "{decoder}");
        assert_eq!(
            v[decoder]["estimates"], v["mcap_ros2"]["estimates"],
            "{decoder}"
        );
    }
    let estimates = v["mcap_ros2"]["estimates"].as_array().expect("estimates");
    assert_estimates(estimates, &truth[0]);
    let scenes = v["mcap_ros2"]["scenes"].as_array().expect("scenes");
    assert_scenes(scenes, &truth, estimates);
    assert_robot(scenes);
    assert_robot_frames(&v["mcap_ros2"]);
}

/// The S1 scenario's robot: its start `[x, y]` and its antenna's offset (position, yaw).
fn s1_robot() -> ([f64; 2], [f64; 3], f64) {
    let s: Value = serde_json::from_str(
        &std::fs::read_to_string(root().join("fixtures/scenarios/s1.json")).expect("S1"),
    )
    .expect("JSON");
    let mount = &s["readers"][0]["antennas"][0]["mount"];
    let start = &mount["robot"]["start"];
    let offset = &mount["offset"];
    (
        [f(&start[0]), f(&start[1])],
        vec3(&offset["position"]),
        f(&offset["yaw_deg"]).to_radians(),
    )
}

/// Every scene draws S1's robot as a box standing on the floor; in the last one its antenna's
/// arrow is where the scenario mounts it on the box (its offset turned by the box's heading,
/// its boresight the box's +x turned by the mount's yaw), and the robot's path starts at the
/// scenario's start and ends under the box.
fn assert_robot(scenes: &[Value]) {
    let (start, offset, yaw) = s1_robot();
    let by_id = |s: &Value, id: &str| {
        (s["entities"].as_array().expect("entities").iter())
            .find(|e| e["id"] == id)
            .cloned()
    };
    for s in scenes {
        let robot = by_id(s, "robot/robot_1").expect("the robot in every scene");
        let cube = &robot["cubes"][0];
        assert!((f(&cube["position"][2]) - f(&cube["size"][2]) / 2.0).abs() < 1e-9);
    }
    let last = scenes.last().expect("a scene");
    let cube = &by_id(last, "robot/robot_1").expect("the robot")["cubes"][0];
    let arrow = &by_id(last, "antenna/s1_reader/antenna_1").expect("the antenna")["arrows"][0];
    let p = vec3(&cube["position"]);
    let (x, y) = (
        axis_of(&cube["orientation"], 0),
        axis_of(&cube["orientation"], 1),
    );
    assert!(x.z.abs() < 1e-9, "the box is not level: {x}");
    let want = [
        p[0] + x.x * offset[0] + y.x * offset[1],
        p[1] + x.y * offset[0] + y.y * offset[1],
        offset[2],
    ];
    let got = vec3(&arrow["position"]);
    assert!(
        (0..3).all(|i| (got[i] - want[i]).abs() < 1e-6),
        "{got:?} vs {want:?}"
    );
    let bore = x * yaw.cos() + y * yaw.sin();
    assert!((axis_of(&arrow["orientation"], 0) - bore).norm() < 1e-6);
    let path = &by_id(last, "path/robot_1").expect("the robot's path")["lines"][0];
    assert_eq!(path["type"], 0, "a line strip");
    let points = path["points"].as_array().expect("points");
    assert!(points.len() >= 2, "{path}");
    let first = vec3(&points[0]);
    assert!(
        (first[0] - start[0]).hypot(first[1] - start[1]) < 1e-9,
        "{first:?}"
    );
    let end = vec3(points.last().expect("a point"));
    assert!(
        (end[0] - p[0]).hypot(end[1] - p[1]) <= 0.011,
        "{end:?} vs {p:?}"
    );
}

/// The transform's rotation and translation: `(q, t)`.
fn transform(t: &Value) -> (UnitQuaternion<f64>, Vector3<f64>) {
    let q = nalgebra::Quaternion::new(f(&t["qw"]), f(&t["qx"]), f(&t["qy"]), f(&t["qz"]));
    let v = Vector3::new(f(&t["x"]), f(&t["y"]), f(&t["z"]));
    (UnitQuaternion::from_quaternion(q), v)
}

/// On `/tf` the robot's frame hangs from `map` and the antenna's from the robot's; at every
/// instant the two compose to the pose the antenna reports on its pose topic.
fn assert_robot_frames(decoded: &Value) {
    let tf = decoded["tf"].as_array().expect("tf");
    let poses = decoded["poses"].as_array().expect("poses");
    let mut checked = 0;
    for a in tf.iter().filter(|t| t["child"] == "s1_reader/antenna_1") {
        assert_eq!(a["parent"], "robot_1", "{a}");
        let r = (tf.iter())
            .find(|t| t["child"] == "robot_1" && t["stamp_ns"] == a["stamp_ns"])
            .unwrap_or_else(|| panic!("no robot frame at {}", a["stamp_ns"]));
        assert_eq!(r["parent"], "map");
        let ((qr, tr), (qa, ta)) = (transform(r), transform(a));
        let (q, t) = (qr * qa, tr + qr * ta);
        let reported = (poses.iter())
            .find(|p| {
                p["topic"] == "/llrp/s1_reader/antenna_1/pose" && p["stamp_ns"] == a["stamp_ns"]
            })
            .expect("the reported pose at that instant");
        let (qp, tp) = transform(reported);
        assert!((t - tp).norm() < 1e-9, "{t} vs {tp}");
        assert!(q.angle_to(&qp) < 1e-9, "{q} vs {qp}");
        checked += 1;
    }
    assert!(checked >= 2, "antenna frames: {checked}");
}

/// Every estimate is in `map`, with a position exactly when its state has one and a
/// symmetric positive semi-definite covariance; the newest of each tag the localizer is sure
/// of lies within 30 cm of the truth (`first`, the truth file's first line), for three tags
/// at least.
fn assert_estimates(estimates: &[Value], first: &Value) {
    assert!(!estimates.is_empty());
    let mut newest = BTreeMap::new();
    for e in estimates {
        assert_eq!(e["frame_id"], "map", "{e}");
        let has_position = e["position"][0].is_number();
        assert_eq!(has_position, e["state"] != 2, "{e}");
        if let Some(c) = covariance(&e["covariance"]) {
            let scale = c.abs().max().max(1e-12);
            assert!((c - c.transpose()).abs().max() <= 1e-9 * scale, "{e}");
            let min = c.symmetric_eigen().eigenvalues.min();
            assert!(min >= -1e-9 * scale, "eigenvalue {min}: {e}");
        } else {
            assert!(!has_position, "a position without covariance: {e}");
        }
        newest.insert(e["epc"].as_str().expect("epc").to_string(), e);
    }
    let truth: BTreeMap<String, [f64; 3]> = (first["tags"].as_array().expect("tags").iter())
        .map(|t| {
            (
                t["epc"].as_str().expect("epc").to_uppercase(),
                vec3(&t["position"]),
            )
        })
        .collect();
    let mut sure = 0;
    for (epc, e) in newest {
        if !worse_sigma(&e["covariance"]).is_some_and(|s| s <= SURE_M) {
            continue;
        }
        let (p, t) = (vec3(&e["position"]), truth[&epc]);
        let off = (p[0] - t[0]).hypot(p[1] - t[1]);
        assert!(off < 0.3, "{epc}: {off} m from the truth: {e}");
        sure += 1;
    }
    assert!(sure >= 3, "tags the localizer is sure of: {sure}");
}

/// Every scene holds the world's bounds, each tag's truth and each antenna under ids that
/// stay the same, 500 ms of simulated time apart at least; the last one's tags and antennas
/// are the truth file's at its instant, and its estimates an estimate of the file each, with
/// the 95 % ellipsoid of its covariance.
fn assert_scenes(scenes: &[Value], truth: &[Value], estimates: &[Value]) {
    assert!(scenes.len() >= 2, "scenes: {}", scenes.len());
    let first = &truth[0];
    let mut want: BTreeSet<String> = (first["tags"].as_array().expect("tags").iter())
        .map(|t| {
            format!(
                "truth/tag/{}",
                t["epc"].as_str().expect("epc").to_uppercase()
            )
        })
        .collect();
    for a in first["antennas"].as_array().expect("antennas") {
        want.insert(format!("antenna/s1_reader/antenna_{}", a["antenna"]));
    }
    want.insert("world/bounds".into());
    let stamp = |s: &Value| s["entities"][0]["stamp_ns"].as_u64().expect("a stamp");
    for pair in scenes.windows(2) {
        assert!(stamp(&pair[1]) >= stamp(&pair[0]) + 500_000_000);
    }
    for s in scenes {
        let ids: Vec<&str> = (s["entities"].as_array().expect("entities").iter())
            .map(|e| e["id"].as_str().expect("an id"))
            .collect();
        let unique: BTreeSet<String> = ids.iter().map(|s| s.to_string()).collect();
        assert_eq!(unique.len(), ids.len(), "ids repeat: {ids:?}");
        assert!(unique.is_superset(&want), "{ids:?}");
    }
    let last = scenes.last().expect("a scene");
    let line = (truth.iter())
        .find(|l| l["utc_us"].as_u64().map(|u| u * 1000) == Some(stamp(last)))
        .expect("the truth at the last scene's instant");
    let by_id: BTreeMap<&str, &Value> = (last["entities"].as_array().expect("entities").iter())
        .map(|e| (e["id"].as_str().expect("an id"), e))
        .collect();
    for t in first["tags"].as_array().expect("tags") {
        let id = format!(
            "truth/tag/{}",
            t["epc"].as_str().expect("epc").to_uppercase()
        );
        assert_eq!(
            vec3(&by_id[id.as_str()]["cubes"][0]["position"]),
            vec3(&t["position"])
        );
    }
    for a in line["antennas"].as_array().expect("antennas") {
        let arrow =
            &by_id[format!("antenna/s1_reader/antenna_{}", a["antenna"]).as_str()]["arrows"][0];
        assert_eq!(vec3(&arrow["position"]), vec3(&a["pose"]["position"]));
        let (yaw, pitch) = (f(&a["pose"]["yaw_rad"]), f(&a["pose"]["pitch_rad"]));
        let want = Vector3::new(
            yaw.cos() * pitch.cos(),
            yaw.sin() * pitch.cos(),
            pitch.sin(),
        );
        assert!((axis_of(&arrow["orientation"], 0) - want).norm() < 1e-9);
    }
    let mut drawn = 0;
    for (id, e) in by_id.iter().filter(|(id, _)| id.starts_with("estimate/")) {
        let epc = &id["estimate/".len()..];
        let center = &e["spheres"][0]["position"];
        let m = (estimates.iter())
            .rfind(|m| m["epc"] == epc && m["position"] == *center)
            .unwrap_or_else(|| panic!("{id}: no estimate at {center}"));
        assert_ellipsoid(
            &e["spheres"][1],
            &covariance(&m["covariance"]).expect("one"),
        );
        drawn += 1;
    }
    assert!(drawn >= 3, "estimates drawn: {drawn}");
}

/// `sphere`'s axes (its orientation's x, y, z) have the half-sizes `sqrt(χ² uᵀ Σ u)` of
/// covariance `c` (a flat axis drawn 1 cm), and are `c`'s principal axes (uᵢᵀ Σ uⱼ = 0).
fn assert_ellipsoid(sphere: &Value, c: &Matrix3<f64>) {
    let scale = c.abs().max();
    for i in 0..3 {
        let u = axis_of(&sphere["orientation"], i);
        let half = (CHI2_95_3DOF * (u.transpose() * c * u)[(0, 0)])
            .max(0.0)
            .sqrt();
        let size = f(&sphere["size"][i]);
        assert!(
            (size - (2.0 * half).max(0.01)).abs() < 1e-6,
            "axis {i}: size {size}, 2 × {half}"
        );
        for j in 0..i {
            let w = axis_of(&sphere["orientation"], j);
            assert!((u.transpose() * c * w)[(0, 0)].abs() < 1e-9 * scale.max(1e-12));
        }
    }
}

#[test]
#[ignore = "needs the MCAP readers (LLRP_MCAP_PYTHON: scripts/venv-mcap.sh, set by ./scripts/test)"]
fn localize_s_mcap_file_holds_its_output_s_estimates_and_their_scene() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (json, mcap) = (dir.path().join("est.json"), dir.path().join("est.mcap"));
    let fixture = |ext: &str| {
        let p = root().join(format!("fixtures/localize/s1-report-per-read{ext}"));
        p.to_str().expect("utf-8").to_string()
    };
    run(&[
        "localize",
        &fixture(".jsonl"),
        "--poses",
        &fixture(".poses.jsonl"),
        "--settings",
        &fixture(".settings.json"),
        "--output",
        json.to_str().expect("utf-8"),
        "--mcap",
        mcap.to_str().expect("utf-8"),
    ]);
    let output: Value =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("the output")).expect("JSON");
    let tags = output["tags"].as_array().expect("tags");
    assert!(tags.len() >= 3, "{output}");
    let v = check(&mcap);
    let ch = channels(&v);
    assert_eq!(ch["/estimates/tags"].1, tags.len() as u64);
    assert_eq!(ch["/scene"].1, 1);
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * a.abs().max(b.abs()).max(1.0);
    for decoder in ["mcap_ros2", "rosbags"] {
        let estimates = v[decoder]["estimates"].as_array().expect("estimates");
        let scene = &v[decoder]["scenes"][0]["entities"];
        for (t, e) in tags.iter().zip(estimates) {
            assert_eq!(e["epc"], t["epc"], "{decoder}");
            let state = ["converging", "converged", "insufficient_geometry"]
                [e["state"].as_u64().expect("a state") as usize];
            assert_eq!(t["state"], state, "{decoder}");
            assert_eq!(e["samples"], t["samples"], "{decoder}");
            assert_eq!(
                e["stamp_ns"].as_u64(),
                t["last_seen"].as_u64().map(|u| u * 1000)
            );
            let Some(c) = covariance(&t["covariance"]) else {
                assert!(e["position"][0].is_null(), "{decoder}: {e}");
                continue;
            };
            let (p, want) = (vec3(&e["position"]), &t["estimate"]);
            for (got, k) in p.iter().zip(["x", "y", "z"]) {
                assert!(close(*got, f(&want[k])), "{decoder}: {k} {got} vs {want}");
            }
            let got = covariance(&e["covariance"]).expect("a covariance");
            assert!(got.iter().zip(c.iter()).all(|(a, b)| close(*a, *b)));
            let id = format!("estimate/{}", t["epc"].as_str().expect("epc"));
            let entity = (scene.as_array().expect("entities").iter())
                .find(|x| x["id"] == id)
                .unwrap_or_else(|| panic!("{decoder}: no {id}"));
            assert_eq!(vec3(&entity["spheres"][0]["position"]), p);
            assert_ellipsoid(&entity["spheres"][1], &got);
        }
    }
}
