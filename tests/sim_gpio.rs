//! The simulated readers' GPIO over HTTP on a running `llrp-gateway sim`: `GET /api/gpio`,
//! `POST /api/readers/{reader}/gpi/{port}` (levels and pulses), its errors naming the field,
//! its counter in `/metrics`; and a GPI-gated conveyor application on llrpkit 0.3.0's
//! library (unmodified, scripts/interop/llrpkit_gpio.py) whose reads start only after a
//! GPI is toggled through the API (needs llrpkit: `LLRP_LLRPKIT`, set by ./scripts/test).

mod http_support;

use std::io::{BufRead, BufReader, Write};
use std::net::SocketAddr;
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use http_support::{request, Proc, PATIENCE};

/// `POST /api/readers/{reader}/gpi/{port}` with a JSON `body`: (status, body).
fn post_gpi(http: SocketAddr, reader: &str, port: &str, body: &str) -> (u16, String) {
    let path = format!("/api/readers/{reader}/gpi/{port}");
    let r = request(
        http,
        "POST",
        &path,
        &[("Content-Type", "application/json")],
        body.as_bytes(),
    );
    (r.status, String::from_utf8_lossy(&r.body).into_owned())
}

/// `GET /api/gpio` as JSON.
fn gpio(http: SocketAddr) -> serde_json::Value {
    let r = request(http, "GET", "/api/gpio", &[], b"");
    assert_eq!(r.status, 200);
    serde_json::from_slice(&r.body).expect("JSON")
}

/// GPI `port`'s state as `GET /api/gpio` gives it for the first reader, once it is `want`
/// (the reader applies a change on its own loop); panics after [`PATIENCE`].
fn wait_gpi(http: SocketAddr, port: usize, want: &str) {
    let until = Instant::now() + PATIENCE;
    loop {
        let v = gpio(http);
        if v["readers"][0]["gpis"][port - 1]["state"] == want {
            return;
        }
        assert!(
            Instant::now() < until,
            "GPI {port} never became {want}: {v}"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn the_gpio_routes_set_pulse_and_read_the_lines_and_name_what_is_wrong() {
    let (mut sim, http) = Proc::sim(&[]);
    // The readers are on the API once they listen.
    sim.address("listening on ");
    let v = gpio(http);
    let reader = &v["readers"][0];
    assert_eq!(reader["reader"], "s1-reader");
    assert_eq!(reader["gpis"].as_array().map(Vec::len), Some(4));
    assert_eq!(reader["gpos"].as_array().map(Vec::len), Some(4));
    assert_eq!(
        reader["gpis"][1],
        serde_json::json!({"port": 2, "state": "low", "enabled": true})
    );

    let (status, body) = post_gpi(http, "s1-reader", "2", r#"{"state": "high"}"#);
    assert_eq!(status, 202, "{body}");
    wait_gpi(http, 2, "high");
    // A pulse: high for 2 s of simulated time (real time at the default speed), then low.
    let (status, body) = post_gpi(
        http,
        "s1-reader",
        "3",
        r#"{"state": "high", "pulse_ms": 2000}"#,
    );
    assert_eq!(status, 202, "{body}");
    wait_gpi(http, 3, "high");
    wait_gpi(http, 3, "low");

    let cases = [
        (
            "s1-reader",
            "2",
            r#"{"state": "up"}"#,
            400,
            "state: unknown variant `up`",
        ),
        (
            "s1-reader",
            "2",
            r#"{"state": "high", "pulse_ms": 0}"#,
            400,
            "pulse_ms: must be in",
        ),
        (
            "s1-reader",
            "2",
            r#"{"level": "high"}"#,
            400,
            "unknown field `level`",
        ),
        (
            "s1-reader",
            "9",
            r#"{"state": "high"}"#,
            400,
            "port: no GPI port 9",
        ),
        (
            "s1-reader",
            "x",
            r#"{"state": "high"}"#,
            400,
            "port: must be a GPI port number",
        ),
        (
            "nobody",
            "1",
            r#"{"state": "high"}"#,
            404,
            "no reader named",
        ),
    ];
    for (reader, port, body, status, says) in cases {
        let (got, text) = post_gpi(http, reader, port, body);
        assert_eq!(got, status, "{reader} {port} {body}: {text}");
        assert!(text.contains(says), "{reader} {port} {body}: {text}");
    }
    let r = request(
        http,
        "POST",
        "/api/readers/s1-reader/gpi/1",
        &[("Content-Type", "text/plain")],
        br#"{"state": "high"}"#,
    );
    assert_eq!(r.status, 415);
    let metrics = request(http, "GET", "/metrics", &[], b"");
    let text = String::from_utf8_lossy(&metrics.body);
    assert!(
        text.lines()
            .any(|l| l == "llrp_gateway_gpi_changes_total 2"),
        "two changes were handed to the reader:\n{text}"
    );
    assert!(sim.stop().success());
}

/// The Python of llrpkit's virtual environment (beside its `llrpkit` command).
fn llrpkit_python() -> std::path::PathBuf {
    let llrpkit = std::env::var("LLRP_LLRPKIT")
        .expect("LLRP_LLRPKIT must name the llrpkit command (set by ./scripts/test)");
    std::path::Path::new(&llrpkit)
        .with_file_name("python")
        .to_path_buf()
}

/// The script's JSON lines as they come, and its standard input (closing it ends the script).
struct Conveyor {
    child: std::process::Child,
    lines: mpsc::Receiver<serde_json::Value>,
}

impl Conveyor {
    fn start(llrp: &str) -> Conveyor {
        let (host, port) = llrp.rsplit_once(':').expect("HOST:PORT");
        let script = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/scripts/interop/llrpkit_gpio.py"
        );
        let mut child = Command::new(llrpkit_python())
            .args([script, host, port, "--gpi", "1", "--seconds", "120"])
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("the llrpkit script runs");
        let stdout = child.stdout.take().expect("piped");
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if let Ok(v) = serde_json::from_str(&line) {
                    let _ = tx.send(v);
                }
            }
        });
        Conveyor { child, lines }
    }

    /// The next line, waiting at most [`PATIENCE`].
    fn next(&self) -> serde_json::Value {
        let v = self
            .lines
            .recv_timeout(PATIENCE)
            .expect("the script says something");
        assert!(v.get("error").is_none(), "the script failed: {v}");
        v
    }

    /// Every line said so far.
    fn said(&self) -> Vec<serde_json::Value> {
        self.lines.try_iter().collect()
    }

    fn stop(mut self) {
        if let Some(mut stdin) = self.child.stdin.take() {
            let _ = stdin.write_all(b"\n");
        }
        let until = Instant::now() + PATIENCE;
        while matches!(self.child.try_wait(), Ok(None)) && Instant::now() < until {
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

#[test]
#[ignore = "needs llrpkit 0.3.0 (LLRP_LLRPKIT, set by ./scripts/test)"]
fn llrpkit_gated_on_a_gpi_reads_only_after_the_line_goes_high_through_the_api() {
    let (mut sim, http) = Proc::sim(&[]);
    let llrp = sim.address("listening on ");
    let conveyor = Conveyor::start(&llrp);
    assert_eq!(conveyor.next(), serde_json::json!({"armed": true}));
    // The ROSpec waits for GPI 1: a second of the reader's time without a read.
    std::thread::sleep(Duration::from_secs(1));
    let before = conveyor.said();
    assert!(
        before.is_empty(),
        "nothing before the line goes high: {before:?}"
    );

    let (status, body) = post_gpi(http, "s1-reader", "1", r#"{"state": "high"}"#);
    assert_eq!(status, 202, "{body}");
    assert_eq!(
        conveyor.next(),
        serde_json::json!({"gpi": 1, "high": true}),
        "the GPIEvent comes first"
    );
    assert!(conveyor.next().get("tag").is_some(), "then the reads");

    let (status, body) = post_gpi(http, "s1-reader", "1", r#"{"state": "low"}"#);
    assert_eq!(status, 202, "{body}");
    let until = Instant::now() + PATIENCE;
    loop {
        let v = conveyor.next();
        if v == serde_json::json!({"gpi": 1, "high": false}) {
            break;
        }
        assert!(
            v.get("tag").is_some(),
            "only reads until the line drops: {v}"
        );
        assert!(Instant::now() < until, "the line never dropped");
    }
    conveyor.stop();
    assert!(sim.stop().success());
}
