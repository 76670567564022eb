//! The HTTP API over loopback: a real server over a real live localizer fed a synthetic tag,
//! queried with a plain HTTP/1.1 client (tests/http_support), every route and its bad input.

mod http_support;

use std::collections::BTreeSet;
use std::time::{Duration, Instant};

use http_support::{
    pose, post_poses, read, request, truth, Events, Server, EPC, PATIENCE, READER, TAG,
};
use llrp_gateway::http::HttpOptions;
use llrp_gateway::localize::live::{Input, Settings};

fn open() -> Server {
    Server::start(HttpOptions::default())
}

fn with_token(token_everywhere: bool) -> Server {
    Server::start(HttpOptions {
        token: Some("s3cret".into()),
        token_everywhere,
        ..HttpOptions::default()
    })
}

fn pose_json(t_us: u64, x: f64) -> String {
    let mut p = pose(t_us);
    p.reader = "posted".parse().ok();
    p.antenna = 2;
    p.pose.position[0] = x;
    serde_json::to_string(&p).expect("serialises")
}

#[test]
fn tags_list_the_converged_tag_in_the_issue_shape_within_a_centimetre() {
    let server = open();
    server.feed_tag();
    server.converged();
    let r = server.get("/api/tags");
    assert_eq!(r.status, 200);
    assert!(r
        .header("content-type")
        .is_some_and(|c| c.starts_with("application/json")));
    let v = r.json();
    let tags = v["tags"].as_array().expect("tags is an array");
    assert_eq!(tags.len(), 1, "{v}");
    let t = &tags[0];
    let keys: BTreeSet<&str> = t
        .as_object()
        .expect("an object")
        .keys()
        .map(String::as_str)
        .collect();
    let want: BTreeSet<&str> = [
        "epc",
        "estimate",
        "covariance",
        "estimator",
        "state",
        "samples",
        "last_seen",
        "reads_per_s",
        "reason",
    ]
    .into();
    assert_eq!(keys, want);
    assert!(
        t["reason"].is_null(),
        "a converged tag needs no reason: {t}"
    );
    assert_eq!(t["epc"], EPC);
    assert_eq!(t["estimator"], "relock");
    assert_eq!(t["state"], "converged");
    assert_eq!(t["samples"], 301);
    assert_eq!(t["last_seen"], 3_000_000);
    assert_eq!(t["covariance"].as_array().map(Vec::len), Some(9));
    let e = &t["estimate"];
    let [x, y, z] = ["x", "y", "z"].map(|k| e[k].as_f64().expect("a number"));
    let off = ((x - TAG[0]).powi(2) + (y - TAG[1]).powi(2) + (z - TAG[2]).powi(2)).sqrt();
    assert!(off < 0.01, "estimate {e} is {off} m from the truth");
}

/// A tag read from one place only is `insufficient_geometry` with a sentence saying why.
#[test]
fn a_tag_read_from_one_place_says_why_it_has_no_position() {
    let server = open();
    let mut reads = Vec::new();
    for k in 0..50u64 {
        let mut r = read(1_000 + k * 1_000);
        r.epc = llrp_gateway::reads::Epc::parse("BEEF").expect("hex");
        // Every read from the same place.
        r.antenna_pose = Some(llrp_gateway::reads::Pose::from_degrees(
            [0.5, 0.0, 0.5],
            90.0,
            0.0,
        ));
        reads.push(r);
    }
    server
        .live
        .tap
        .offer(llrp_gateway::localize::live::Input::Reads(reads));
    let deadline = Instant::now() + PATIENCE;
    let t = loop {
        let v = server.get("/api/tags/BEEF").json();
        if v["samples"].as_u64().is_some_and(|n| n > 0) {
            break v;
        }
        assert!(Instant::now() < deadline, "the reads never showed: {v}");
        std::thread::sleep(Duration::from_millis(20));
    };
    assert_eq!(t["state"], "insufficient_geometry", "{t}");
    let why = t["reason"].as_str().expect("a reason");
    assert!(why.contains("has not passed the tag"), "{why}");
}

#[test]
fn one_tag_by_lower_case_epc_with_its_recent_reads() {
    let server = open();
    server.feed_tag();
    let converged = server.converged();
    let r = server.get(&format!("/api/tags/{}", EPC.to_ascii_lowercase()));
    assert_eq!(r.status, 200, "{}", r.text());
    let v = r.json();
    assert_eq!(v["epc"], EPC);
    assert_eq!(v["estimate"], converged["estimate"]);
    let recent = v["recent_reads"].as_array().expect("recent_reads");
    assert_eq!(recent.len(), 32, "the newest 32 reads");
    let newest = recent.last().expect("a read");
    assert_eq!(newest["t_us"], 3_000_000);
    assert_eq!(newest["epc"], EPC);
    assert_eq!(newest["reader"], READER);
}

#[test]
fn an_unknown_epc_is_404_and_a_non_hex_one_400_naming_why() {
    let server = open();
    let r = server.get("/api/tags/ABCD");
    assert_eq!(r.status, 404);
    assert_eq!(r.error(), "no tag ABCD was read");
    let r = server.get("/api/tags/ABC");
    assert_eq!(r.status, 400);
    assert!(r.error().contains("odd number of digits"), "{}", r.text());
    let r = server.get("/api/tags/E2XY");
    assert_eq!(r.status, 400);
    assert!(r.error().contains("'X'"), "{}", r.text());
    // Not even UTF-8: still a JSON error.
    let r = server.get("/api/tags/%FF%FE");
    assert_eq!(r.status, 400);
    assert!(!r.error().is_empty());
}

#[test]
fn readers_show_the_reader_its_reads_and_its_antennas_pose() {
    let server = open();
    server.feed_tag();
    server.converged();
    let r = server.get("/api/readers");
    assert_eq!(r.status, 200);
    let v = r.json();
    let readers = v["readers"].as_array().expect("readers");
    assert_eq!(readers.len(), 1, "{v}");
    let reader = &readers[0];
    assert_eq!(reader["name"], READER);
    assert_eq!(reader["reads"], 301);
    assert_eq!(reader["connected"], false);
    assert_eq!(reader["inventory"], "idle");
    let antenna = &reader["antennas"][0];
    assert_eq!(antenna["antenna"], 1);
    assert_eq!(antenna["pose"]["t_us"], 3_000_000, "the newest pose: {v}");
    assert!((antenna["pose"]["x"].as_f64().expect("x") - 2.0).abs() < 1e-9);
}

#[test]
fn truth_is_404_outside_a_simulation_even_when_set() {
    let server = open();
    server.live.shared.set_truth(truth());
    let r = server.get("/api/truth");
    assert_eq!(r.status, 404);
    assert!(r.error().contains("not a simulation"));
}

#[test]
fn truth_is_served_in_a_simulation_with_xyz_positions() {
    let server = Server::start(HttpOptions {
        simulation: true,
        ..HttpOptions::default()
    });
    assert_eq!(server.get("/api/truth").status, 404, "no truth set yet");
    server.live.shared.set_truth(truth());
    let r = server.get("/api/truth");
    assert_eq!(r.status, 200, "{}", r.text());
    let v = r.json();
    let tag = &v["tags"][0];
    assert_eq!(tag["epc"], EPC);
    assert_eq!(
        tag["position"],
        serde_json::json!({"x": TAG[0], "y": TAG[1], "z": TAG[2]})
    );
    assert_eq!(tag["reference"], false);
    assert_eq!(v["antennas"][0]["reader"], READER);
    assert_eq!(v["antennas"][0]["yaw_deg"], 90.0);
}

#[test]
fn events_deliver_an_estimate_after_a_new_read() {
    let server = open();
    server.feed_tag();
    let before = server.converged();
    let mut events = Events::open(server.addr);
    // One more pose and read, 10 ms on: the tag is estimated again.
    let t = 3_010_000;
    assert!(server.live.tap.offer(Input::Poses(vec![pose(t)])));
    assert!(server.live.tap.offer(Input::Reads(vec![read(t)])));
    let before = before["samples"].as_u64().expect("samples");
    // An update of the state `before` saw may still be on its way to a subscriber that came
    // in after it (on a busy machine): the estimate of the new read is the first with more.
    let mut seen = 0;
    let v = loop {
        seen += 1;
        assert!(seen <= 50, "no estimate with the new read among 50");
        let block = events.next_block(|b| b.contains("event: estimate"));
        let data = block
            .lines()
            .find_map(|l| l.strip_prefix("data: "))
            .expect("a data line");
        let v: serde_json::Value = serde_json::from_str(data).expect("JSON data");
        if v["samples"].as_u64().is_some_and(|n| n > before) {
            break v;
        }
    };
    assert_eq!(v["epc"], EPC);
    assert_eq!(v["samples"], before + 1);
    assert_eq!(v["last_seen"], t);
}

#[test]
fn posted_poses_are_accepted_and_show_in_readers() {
    let server = open();
    let body = format!("[{}, {}]", pose_json(1_000, 0.25), pose_json(2_000, 0.5));
    let r = post_poses(server.addr, &[], body.as_bytes());
    assert_eq!(r.status, 202, "{}", r.text());
    assert_eq!(r.json(), serde_json::json!({"accepted": 2}));
    // One object alone and JSON Lines are taken too.
    let r = post_poses(
        server.addr,
        &[("Content-Type", "application/json")],
        pose_json(3_000, 0.75).as_bytes(),
    );
    assert_eq!(r.json(), serde_json::json!({"accepted": 1}));
    let lines = format!("{}\n{}\n", pose_json(4_000, 1.0), pose_json(5_000, 1.25));
    let r = post_poses(server.addr, &[], lines.as_bytes());
    assert_eq!(r.json(), serde_json::json!({"accepted": 2}));
    let deadline = Instant::now() + PATIENCE;
    loop {
        let v = server.get("/api/readers").json();
        let posted = v["readers"]
            .as_array()
            .and_then(|rs| rs.iter().find(|r| r["name"] == "posted"))
            .cloned();
        if let Some(p) = posted {
            let pose = &p["antennas"][0]["pose"];
            if pose["t_us"] == 5_000 {
                assert_eq!(p["antennas"][0]["antenna"], 2);
                assert_eq!(pose["x"], 1.25);
                break;
            }
        }
        assert!(
            Instant::now() < deadline,
            "the posted poses never showed: {v}"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn a_bad_pose_is_400_naming_index_and_field_and_nothing_is_taken() {
    let server = open();
    let bad = pose_json(2_000, 0.5).replace("\"antenna\":2", "\"antenna\":0");
    let body = format!("[{}, {bad}]", pose_json(1_000, 0.25));
    let r = post_poses(server.addr, &[], body.as_bytes());
    assert_eq!(r.status, 400);
    assert_eq!(r.error(), "pose 1: antenna: must be a port number from 1");
    let wrong_type = pose_json(1_000, 0.25).replace("\"y\":0.0", "\"y\":\"zero\"");
    let r = post_poses(server.addr, &[], wrong_type.as_bytes());
    assert_eq!(r.status, 400);
    assert!(
        r.error().starts_with("pose 0: y: invalid type"),
        "{}",
        r.text()
    );
    let r = post_poses(server.addr, &[], b"{not json");
    assert_eq!(r.status, 400);
    assert!(r.error().starts_with("pose 0: not JSON"), "{}", r.text());
    // Nothing of the bad bodies reached the localizer.
    let metrics = server.live.shared.metrics.render();
    assert!(
        metrics.lines().any(|l| l == "llrp_gateway_poses_total 0"),
        "{metrics}"
    );
    assert!(server.live.shared.readers().is_empty());
}

#[test]
fn posted_poses_are_503_while_the_localizer_is_behind() {
    // A tap of one input, kept full by large inputs the worker takes a while over.
    let server = Server::start_with(
        HttpOptions::default(),
        Settings {
            tap_capacity: 1,
            ..Settings::default()
        },
    );
    let filler = || {
        let poses = (0..20_000u64)
            .map(|k| {
                let mut p = pose(k * 1_000);
                p.reader = "filler".parse().ok();
                p
            })
            .collect();
        Input::Poses(poses)
    };
    let body = pose_json(1_000, 0.25);
    let deadline = Instant::now() + PATIENCE;
    let refused = loop {
        // Fill the tap until it refuses, then post at once.
        while server.live.tap.offer(filler()) {}
        let r = post_poses(server.addr, &[], body.as_bytes());
        if r.status == 503 {
            break r;
        }
        assert_eq!(r.status, 202, "{}", r.text());
        assert!(Instant::now() < deadline, "the tap never refused a post");
    };
    assert!(refused.error().contains("behind"), "{}", refused.text());
}

#[test]
fn a_body_over_the_limit_is_413() {
    let server = Server::start(HttpOptions {
        body_limit: 1000,
        ..HttpOptions::default()
    });
    let one = pose_json(1_000, 0.25);
    let many = format!("[{}]", vec![one.as_str(); 20].join(","));
    assert!(many.len() > 1000);
    let r = post_poses(server.addr, &[], many.as_bytes());
    assert_eq!(r.status, 413);
    assert!(!r.error().is_empty());
    let r = post_poses(server.addr, &[], one.as_bytes());
    assert_eq!(r.status, 202, "under the limit: {}", r.text());
}

#[test]
fn with_a_token_posts_need_the_bearer_and_reads_on_loopback_do_not() {
    let server = with_token(false);
    let body = pose_json(1_000, 0.25);
    let r = post_poses(server.addr, &[], body.as_bytes());
    assert_eq!(r.status, 401);
    assert_eq!(r.header("www-authenticate"), Some("Bearer"));
    assert!(r.error().contains("Authorization: Bearer"), "{}", r.text());
    let wrong = [("Authorization", "Bearer nope")];
    let r = post_poses(server.addr, &wrong, body.as_bytes());
    assert_eq!(r.status, 401);
    assert_eq!(r.error(), "wrong bearer token");
    let right = [("Authorization", "Bearer s3cret")];
    let r = post_poses(server.addr, &right, body.as_bytes());
    assert_eq!(r.status, 202, "{}", r.text());
    assert_eq!(server.get("/api/tags").status, 200);
    assert_eq!(server.get("/healthz").status, 200);
}

#[test]
fn with_token_everywhere_reads_need_it_too() {
    let server = with_token(true);
    for path in [
        "/api/tags",
        "/api/readers",
        "/metrics",
        "/",
        "/no/such/route",
    ] {
        let r = server.get(path);
        assert_eq!(r.status, 401, "{path}");
        assert!(!r.error().is_empty());
    }
    let right = [("Authorization", "Bearer s3cret")];
    let r = request(server.addr, "GET", "/api/tags", &right, b"");
    assert_eq!(r.status, 200);
    assert_eq!(r.json(), serde_json::json!({"tags": []}));
}

#[test]
fn metrics_are_prometheus_text_or_openmetrics_as_asked_with_the_read_counter() {
    let server = open();
    server.feed_tag();
    server.converged();
    let r = server.get("/metrics");
    assert_eq!(r.status, 200);
    assert!(
        r.header("content-type")
            .is_some_and(|c| c.starts_with("text/plain; version=0.0.4")),
        "{:?}",
        r.headers
    );
    assert_eq!(r.header("vary"), Some("Accept"));
    let text = r.text();
    assert!(
        text.lines().any(|l| l == "llrp_gateway_reads_total 301"),
        "{text}"
    );
    // The classic format names a counter's family after its sample.
    assert!(
        text.contains("# TYPE llrp_gateway_reads_total counter"),
        "{text}"
    );
    assert!(text.contains("# TYPE llrp_gateway_estimator_seconds histogram"));
    assert!(!text.contains("# EOF"), "{text}");

    // A client asking for OpenMetrics (Prometheus does) gets it, said so.
    let om = [(
        "Accept",
        "application/openmetrics-text;version=1.0.0,*/*;q=0.1",
    )];
    let r = request(server.addr, "GET", "/metrics", &om, b"");
    assert_eq!(
        r.header("content-type"),
        Some("application/openmetrics-text; version=1.0.0; charset=utf-8")
    );
    let text = r.text();
    assert!(text.contains("# TYPE llrp_gateway_reads counter"), "{text}");
    assert!(text.contains("# UNIT llrp_gateway_estimator_seconds seconds"));
    assert!(text.ends_with("# EOF\n"), "{text}");
}

#[test]
fn healthz_says_ok() {
    let r = open().get("/healthz");
    assert_eq!((r.status, r.text().as_str()), (200, "ok"));
}

#[test]
fn unknown_routes_and_methods_are_json_errors() {
    let server = open();
    let r = server.get("/api/nothing");
    assert_eq!(r.status, 404);
    assert_eq!(r.error(), "no route GET /api/nothing");
    let r = request(server.addr, "POST", "/api/tags", &[], b"{}");
    assert_eq!(r.status, 405);
    assert!(r.error().contains("/api/tags"), "{}", r.text());
}

#[test]
fn gpio_is_404_outside_a_simulation() {
    let server = open();
    let r = server.get("/api/gpio");
    assert_eq!(r.status, 404);
    assert!(r.error().contains("not a simulation"), "{}", r.text());
    let r = request(
        server.addr,
        "POST",
        "/api/readers/r/gpi/1",
        &[("Content-Type", "application/json")],
        br#"{"state": "high"}"#,
    );
    assert_eq!(r.status, 404);
    assert!(r.error().contains("not a simulation"), "{}", r.text());
}

#[test]
fn faults_are_404_outside_a_simulation() {
    let server = open();
    let r = request(
        server.addr,
        "POST",
        "/api/readers/r/faults",
        &[("Content-Type", "application/json")],
        br#"{"fault": "reboot"}"#,
    );
    assert_eq!(r.status, 404);
    assert!(r.error().contains("not a simulation"), "{}", r.text());
}

/// Every route of issue 18 (and issue 43's GPIO and faults), with its method.
const ROUTES: &[(&str, &str)] = &[
    ("get", "/"),
    ("get", "/healthz"),
    ("get", "/metrics"),
    ("get", "/api/openapi.json"),
    ("get", "/api/tags"),
    ("get", "/api/tags/{epc}"),
    ("get", "/api/readers"),
    ("get", "/api/truth"),
    ("get", "/api/events"),
    ("post", "/api/poses"),
    ("get", "/api/gpio"),
    ("post", "/api/readers/{reader}/gpi/{port}"),
    ("post", "/api/readers/{reader}/faults"),
];

#[test]
fn openapi_lists_every_route_and_the_router_serves_every_listed_one() {
    let server = open();
    let r = server.get("/api/openapi.json");
    assert_eq!(r.status, 200);
    let doc = r.json();
    assert!(doc["openapi"].as_str().is_some_and(|v| v.starts_with("3.")));
    let paths = doc["paths"].as_object().expect("paths");
    let mut listed = BTreeSet::new();
    for (path, item) in paths {
        for method in item.as_object().expect("a path item").keys() {
            listed.insert((method.clone(), path.clone()));
        }
    }
    let want: BTreeSet<(String, String)> = ROUTES
        .iter()
        .map(|(m, p)| (m.to_string(), p.to_string()))
        .collect();
    assert_eq!(listed, want, "the document's operations");
    assert!(doc["components"]["schemas"]["Tags"].is_object());
    // The document is the router's: every operation in it is served (no 404 or 405 of the
    // fallbacks).
    for (method, path) in &listed {
        if path == "/api/events" {
            continue; // A stream: tests/http.rs opens it in its own test.
        }
        let concrete = path
            .replace("{epc}", "ABCD")
            .replace("{reader}", "r")
            .replace("{port}", "1");
        let r = request(
            server.addr,
            &method.to_ascii_uppercase(),
            &concrete,
            &[],
            b"",
        );
        assert_ne!(r.status, 405, "{method} {path}");
        if r.status == 404 {
            assert!(!r.error().starts_with("no route"), "{method} {path}");
        }
    }
    Events::open(server.addr);
}

#[test]
fn the_map_page_is_html_with_the_event_source_and_no_outside_assets() {
    let r = open().get("/");
    assert_eq!(r.status, 200);
    assert!(r
        .header("content-type")
        .is_some_and(|c| c.starts_with("text/html")));
    let html = r.text();
    assert!(html.contains("new EventSource(") && html.contains("\"/api/events\""));
    assert!(html.contains("fetch(url)") && html.contains("\"/api/tags\""));
    assert!(
        !html.contains(" src=") && !html.contains("<link") && !html.contains("https://"),
        "no outside assets"
    );
}
