//! `GET /metrics` read by a real Prometheus: Debian's `prometheus` package
//! (`scripts/install-prometheus`) scrapes a running `llrp-gateway sim` every second from a
//! free loopback port with its own storage in a temporary directory, and the test reads the
//! counters and their types back through Prometheus's HTTP API. Prometheus asks for
//! OpenMetrics first, so this checks that the text it gets parses as OpenMetrics with the
//! families' types and units; `promtool check metrics` (same package) lints the classic text
//! served to a client that names no format.
//!
//! `#[ignore]`d in a plain `cargo test`, like the other tests of a third-party server:
//! `./scripts/test` installs Prometheus and runs them. Without it they fail, saying so.

mod http_support;

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use http_support::{request, Proc, PATIENCE};

/// What Prometheus 2.42 (Debian 12's) sends with every scrape.
const PROMETHEUS_ACCEPT: &str = "application/openmetrics-text;version=1.0.0,\
    application/openmetrics-text;version=0.0.1;q=0.75,text/plain;version=0.0.4;q=0.5,*/*;q=0.1";

/// The program `name` of Debian's `prometheus` package.
fn binary(name: &str) -> PathBuf {
    for dir in ["/usr/bin", "/usr/sbin", "/usr/local/bin"] {
        let p = Path::new(dir).join(name);
        if p.is_file() {
            return p;
        }
    }
    panic!("{name} is not installed: run scripts/install-prometheus (./scripts/test does)");
}

/// `sim` on S1 at 4× real time, inventorying by itself, with its HTTP API on a free port.
fn sim() -> (Proc, SocketAddr) {
    let mut sim = Proc::spawn(&[
        "sim",
        "--listen",
        "127.0.0.1:0",
        "--http",
        "127.0.0.1:0",
        "--speed",
        "4",
    ]);
    let http = sim.address("live map on http://").parse().expect("addr");
    (sim, http)
}

/// A running Prometheus, stopped by PID when dropped.
struct Prometheus {
    child: Option<Child>,
    addr: SocketAddr,
    dir: tempfile::TempDir,
}

impl Prometheus {
    /// Starts Prometheus scraping `target`'s `/metrics` every second, on a free loopback
    /// port; again on another if the port was taken before Prometheus bound it.
    fn start(target: SocketAddr) -> Prometheus {
        let mut dir = tempfile::tempdir().expect("temp dir");
        for _ in 0..5 {
            let port = std::net::TcpListener::bind("127.0.0.1:0")
                .and_then(|l| l.local_addr())
                .expect("a free port")
                .port();
            let addr = SocketAddr::from(([127, 0, 0, 1], port));
            let child = Prometheus::spawn(dir.path(), target, addr);
            let mut p = Prometheus {
                child: Some(child),
                addr,
                dir,
            };
            if p.ready() {
                return p;
            }
            dir = p.take_dir();
        }
        panic!("prometheus did not start on five ports");
    }

    /// Starts Prometheus on `addr` with its configuration, storage and log in `dir`.
    fn spawn(dir: &Path, target: SocketAddr, addr: SocketAddr) -> Child {
        let config = dir.join("prometheus.yml");
        std::fs::write(
            &config,
            format!(
                "global:\n  scrape_interval: 1s\n  scrape_timeout: 1s\n\
                 scrape_configs:\n  - job_name: llrp-gateway\n    static_configs:\n\
                 \x20     - targets: ['{target}']\n"
            ),
        )
        .expect("writes the configuration");
        let log = std::fs::File::create(dir.join("prometheus.log")).expect("log");
        Command::new(binary("prometheus"))
            .arg(format!("--config.file={}", config.display()))
            .arg(format!(
                "--storage.tsdb.path={}",
                dir.join("data").display()
            ))
            .arg(format!("--web.listen-address={addr}"))
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(log)
            .spawn()
            .expect("prometheus starts")
    }

    /// Waits until `/-/ready` answers 200; false if Prometheus exited first.
    fn ready(&mut self) -> bool {
        let deadline = Instant::now() + PATIENCE;
        loop {
            if let Some(Ok(Some(_))) = self.child.as_mut().map(|c| c.try_wait()) {
                self.child = None;
                return false;
            }
            let up = std::net::TcpStream::connect(self.addr).is_ok()
                && request(self.addr, "GET", "/-/ready", &[], b"").status == 200;
            if up {
                return true;
            }
            assert!(
                Instant::now() < deadline,
                "prometheus not ready: {}",
                self.log()
            );
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// Its temporary directory, for another try.
    fn take_dir(mut self) -> tempfile::TempDir {
        self.stop();
        std::mem::replace(&mut self.dir, tempfile::tempdir().expect("temp dir"))
    }

    fn log(&self) -> String {
        std::fs::read_to_string(self.dir.path().join("prometheus.log")).unwrap_or_default()
    }

    /// `GET path` of its HTTP API: the `data` of a successful answer.
    fn api(&self, path: &str) -> serde_json::Value {
        let r = request(self.addr, "GET", path, &[], b"");
        assert_eq!(r.status, 200, "{path}: {}", r.text());
        let v = r.json();
        assert_eq!(v["status"], "success", "{path}: {v}");
        v["data"].clone()
    }

    /// Polls `path` until `found` takes its data; what it returned.
    fn until<T>(&self, path: &str, found: impl Fn(&serde_json::Value) -> Option<T>) -> T {
        let deadline = Instant::now() + PATIENCE;
        loop {
            let data = self.api(path);
            if let Some(t) = found(&data) {
                return t;
            }
            assert!(
                Instant::now() < deadline,
                "{path} never had it: {data}\n{}",
                self.log()
            );
            std::thread::sleep(Duration::from_millis(200));
        }
    }

    /// Stops it (SIGTERM) and waits.
    fn stop(&mut self) {
        let Some(mut child) = self.child.take() else {
            return;
        };
        let _ = Command::new("kill").arg(child.id().to_string()).status();
        let deadline = Instant::now() + Duration::from_secs(10);
        while Instant::now() < deadline {
            if let Ok(Some(_)) = child.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = child.kill();
        let _ = child.wait();
    }
}

impl Drop for Prometheus {
    fn drop(&mut self) {
        self.stop();
    }
}

/// The one metadata entry of `family` in `/api/v1/metadata`, once scraped.
fn metadata(prometheus: &Prometheus, family: &str) -> serde_json::Value {
    prometheus.until(&format!("/api/v1/metadata?metric={family}"), |d| {
        d[family].as_array().and_then(|a| a.first()).cloned()
    })
}

#[test]
#[ignore = "needs prometheus: scripts/install-prometheus (./scripts/test runs it)"]
fn a_real_prometheus_scrapes_the_counters_with_their_types() {
    let (_sim, http) = sim();
    // The response Prometheus gets: OpenMetrics, said so.
    let r = request(
        http,
        "GET",
        "/metrics",
        &[("Accept", PROMETHEUS_ACCEPT)],
        b"",
    );
    assert_eq!(
        r.header("content-type"),
        Some("application/openmetrics-text; version=1.0.0; charset=utf-8")
    );
    assert!(r.text().ends_with("# EOF\n"), "{}", r.text());

    let prometheus = Prometheus::start(http);
    // The sample, once scraped with a value: the reader inventories by itself.
    let frames = prometheus.until("/api/v1/query?query=llrp_gateway_frames_out_total", |d| {
        let value = d["result"].as_array()?.first()?["value"][1].as_str()?;
        value.parse::<f64>().ok().filter(|v| *v > 0.0)
    });
    let now = http_support::counter(http, "frames_out");
    assert!(frames <= now, "Prometheus has {frames}, the gateway {now}");

    // The types and units come from the text's own lines, as OpenMetrics: a counter family
    // named without `_total`, and the histograms' UNIT (a classic parser skips that line).
    for counter in ["llrp_gateway_frames_out", "llrp_gateway_reads"] {
        let m = metadata(&prometheus, counter);
        assert_eq!(m["type"], "counter", "{counter}: {m}");
        assert!(
            !m["help"].as_str().unwrap_or("").is_empty(),
            "{counter}: {m}"
        );
    }
    let m = metadata(&prometheus, "llrp_gateway_estimator_seconds");
    assert_eq!(m["type"], "histogram", "{m}");
    assert_eq!(m["unit"], "seconds", "{m}");

    // Every scrape went through: the target is up, with no parse error.
    let target = prometheus.api("/api/v1/targets")["activeTargets"][0].clone();
    assert_eq!(target["health"], "up", "{target}");
    assert_eq!(target["lastError"], "", "{target}");
}

#[test]
#[ignore = "needs prometheus (promtool): scripts/install-prometheus (./scripts/test runs it)"]
fn promtool_passes_the_text_served_to_a_client_that_names_no_format() {
    let (_sim, http) = sim();
    for accept in [None, Some("text/plain;version=0.0.4")] {
        let headers: Vec<(&str, &str)> = accept.iter().map(|a| ("Accept", *a)).collect();
        let r = request(http, "GET", "/metrics", &headers, b"");
        assert_eq!(
            r.header("content-type"),
            Some("text/plain; version=0.0.4; charset=utf-8"),
            "{accept:?}"
        );
        let text = r.text();
        assert!(
            text.lines()
                .any(|l| l == "# TYPE llrp_gateway_frames_out_total counter"),
            "{text}"
        );
        let mut promtool = Command::new(binary("promtool"))
            .args(["check", "metrics"])
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("promtool starts");
        std::io::Write::write_all(&mut promtool.stdin.take().expect("stdin"), text.as_bytes())
            .expect("writes the metrics");
        let out = promtool.wait_with_output().expect("promtool runs");
        assert!(
            out.status.success(),
            "promtool check metrics: {}{}\n{text}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
    }
}
