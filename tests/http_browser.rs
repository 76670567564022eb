//! The live map in a real browser: headless Chromium loads `GET /` from a running
//! `llrp-gateway sim` (no LLRP client: the reader inventories by itself), and the page it
//! renders shows a row per estimated tag in its state (a reason under each not converged),
//! their markers and the true positions; a screenshot is taken too.
//!
//! `#[ignore]`d in a plain `cargo test`: it needs Debian's `chromium` (`scripts/install-chromium`,
//! which `./scripts/test` runs before the ignored tests). `LLRP_CHROMIUM` names another
//! binary; `LLRP_MAP_SCREENSHOT=path` keeps the screenshot (how `docs/img/map.png` is made).

mod http_support;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Longest one Chromium run may take.
const BROWSER_PATIENCE: Duration = Duration::from_secs(90);

fn chromium() -> PathBuf {
    if let Some(p) = std::env::var_os("LLRP_CHROMIUM") {
        return PathBuf::from(p);
    }
    let path = std::env::var_os("PATH").unwrap_or_default();
    std::env::split_paths(&path)
        .map(|d| d.join("chromium"))
        .find(|p| p.is_file())
        .unwrap_or_else(|| {
            panic!("chromium is not on PATH: run scripts/install-chromium (./scripts/test does)")
        })
}

/// Runs headless Chromium on `url` with `args`; its standard output.
fn run_chromium(profile: &Path, url: &str, args: &[&str]) -> String {
    let mut child = Command::new(chromium())
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--no-first-run",
            "--disable-dev-shm-usage",
            "--virtual-time-budget=8000",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .args(args)
        .arg(url)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("chromium starts");
    let stdout = child.stdout.take().expect("piped stdout");
    let reader = std::thread::spawn(move || {
        let mut out = String::new();
        let _ = std::io::Read::read_to_string(&mut { stdout }, &mut out);
        out
    });
    let deadline = Instant::now() + BROWSER_PATIENCE;
    loop {
        if let Some(status) = child.try_wait().expect("waits for chromium") {
            assert!(status.success(), "chromium failed: {status}");
            break;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            panic!("chromium took over {BROWSER_PATIENCE:?}");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    reader.join().expect("the reader thread")
}

/// The opening tag of the element whose `id` is `id` in `dom`.
fn element<'a>(dom: &'a str, id: &str) -> Option<&'a str> {
    let at = dom.find(&format!("id=\"{id}\""))?;
    let start = dom[..at].rfind('<')?;
    let end = at + dom[at..].find('>')?;
    Some(&dom[start..=end])
}

#[test]
#[ignore = "needs chromium: scripts/install-chromium (./scripts/test runs it)"]
fn the_map_of_a_running_simulation_shows_its_tags_localized_in_a_headless_browser() {
    // The embedded S1, its own inventory at 16× real time, the HTTP API on a free port.
    let mut sim = http_support::Proc::spawn(&[
        "sim",
        "--listen",
        "127.0.0.1:0",
        "--http",
        "127.0.0.1:0",
        "--speed",
        "16",
    ]);
    let http: std::net::SocketAddr = sim.address("live map on http://").parse().expect("addr");
    // Until the localizer has estimated tags (bounded: S1's pass takes under 3 s at 16×).
    // With the robot's own poses (the default) their covariance takes the poses' error in,
    // so they may stay `converging`: the page shows each in the API's state, with its reason.
    let deadline = Instant::now() + Duration::from_secs(90);
    let estimated = loop {
        let tags = http_support::request(http, "GET", "/api/tags", &[], b"").json();
        let estimated: Vec<(String, String)> = tags["tags"]
            .as_array()
            .into_iter()
            .flatten()
            .filter(|t| t["state"] == "converged" || t["state"] == "converging")
            .filter_map(|t| Some((t["epc"].as_str()?.into(), t["state"].as_str()?.into())))
            .collect();
        if estimated.len() >= 5 || Instant::now() > deadline {
            break estimated;
        }
        std::thread::sleep(Duration::from_millis(200));
    };
    assert!(
        estimated.len() >= 5,
        "too few estimated tags: {estimated:?}"
    );
    let url = format!("http://{}/", http);
    let dir = tempfile::tempdir().expect("a temp dir");

    let dom = run_chromium(&dir.path().join("profile-dom"), &url, &["--dump-dom"]);
    for (epc, state) in &estimated {
        let row = element(&dom, &format!("tag-{epc}"))
            .unwrap_or_else(|| panic!("no row tag-{epc} in the page:\n{dom}"));
        // A tag may have converged between the API's answer and the page's.
        assert!(
            row.contains(&format!("data-state=\"{state}\""))
                || row.contains("data-state=\"converged\""),
            "{epc} is {state} in the API: {row}"
        );
        if row.contains("data-state=\"converging\"") {
            assert!(
                element(&dom, &format!("why-{epc}")).is_some(),
                "no reason under the converging {epc}:\n{dom}"
            );
        }
    }
    let markers = dom.matches("class=\"estimated").count();
    assert!(
        markers >= estimated.len(),
        "{markers} estimated markers:\n{dom}"
    );
    assert!(dom.contains("class=\"truth\""), "no truth marker:\n{dom}");
    // The event stream's worker ran under the page's Content-Security-Policy.
    let status = element(&dom, "status").unwrap_or_default();
    let shown = dom
        .split_once("id=\"status\">")
        .and_then(|(_, rest)| rest.split_once('<'))
        .map(|(text, _)| text);
    assert_eq!(shown, Some("live"), "{status}");

    let png = dir.path().join("map.png");
    run_chromium(
        &dir.path().join("profile-shot"),
        &url,
        &[
            &format!("--screenshot={}", png.display()),
            "--window-size=1200,800",
            "--hide-scrollbars",
        ],
    );
    let bytes = std::fs::read(&png).expect("chromium wrote the screenshot");
    assert!(bytes.starts_with(b"\x89PNG\r\n\x1a\n"), "not a PNG");
    if let Some(keep) = std::env::var_os("LLRP_MAP_SCREENSHOT") {
        std::fs::write(&keep, &bytes).expect("keeps the screenshot");
    }
}

/// Serves `page` (HTML) to every request on a loopback port of its own: another origin than
/// the API's. Returns the port.
fn serve_page(page: String) -> u16 {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").expect("binds");
    let port = listener.local_addr().expect("bound").port();
    std::thread::spawn(move || {
        for stream in listener.incoming() {
            let Ok(mut stream) = stream else { continue };
            let mut head = [0u8; 4096];
            let _ = std::io::Read::read(&mut stream, &mut head);
            let answer = format!(
                "HTTP/1.1 200 OK\r\nContent-Type: text/html\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{page}",
                page.len()
            );
            let _ = std::io::Write::write_all(&mut stream, answer.as_bytes());
        }
    });
    port
}

#[test]
#[ignore = "needs chromium: scripts/install-chromium (./scripts/test runs it)"]
fn a_page_of_another_origin_cannot_post_poses_by_fetch_or_by_form() {
    let mut sim = http_support::Proc::spawn(&[
        "sim",
        "--listen",
        "127.0.0.1:0",
        "--http",
        "127.0.0.1:0",
        "--speed",
        "4",
    ]);
    let http: std::net::SocketAddr = sim.address("live map on http://").parse().expect("addr");
    // What any page can send without a preflight: a no-cors fetch of text/plain, then a form
    // of enctype text/plain (into a frame of the page) whose one field makes the body a valid
    // pose (`{"t_us":1,…,"reader":"evil-form=x"}`). The page logs each step as it happens.
    let pose = |reader: &str| {
        format!(r#"{{"t_us":1,"antenna":1,"x":0,"y":0,"z":0.5,"yaw_deg":0,"reader":"{reader}"}}"#)
    };
    let field = pose("evil-form").replace("evil-form\"}", "evil-form");
    let dir = tempfile::tempdir().expect("a temp dir");
    // The page on 127.0.0.1 at another port: to the API at 127.0.0.1 it is the same site, to
    // the API called localhost another site.
    for api_host in ["127.0.0.1", "localhost"] {
        let api = format!("http://{api_host}:{}/api/poses", http.port());
        let page = format!(
            r#"<!doctype html><html><body>
<iframe name="sink"></iframe>
<form id="f" method="POST" enctype="text/plain" target="sink" action="{api}"><input type="hidden" name='{field}' value='x"}}'></form>
<p id="log"></p>
<script>
const log = (t) => document.getElementById("log").textContent += t + ";";
fetch("{api}", {{ method: "POST", mode: "no-cors", headers: {{ "Content-Type": "text/plain" }}, body: '{fetch_body}' }})
  .then(() => log("fetch answered"), () => log("fetch failed"))
  .finally(() => {{
    document.querySelector("iframe").onload = () => log("form answered");
    document.getElementById("f").submit();
  }});
</script></body></html>"#,
            fetch_body = pose("evil-fetch"),
        );
        let port = serve_page(page);
        let url = format!("http://127.0.0.1:{port}/");
        let dom = run_chromium(
            &dir.path().join(format!("profile-{api_host}")),
            &url,
            &["--dump-dom"],
        );
        let log = dom
            .split_once("id=\"log\">")
            .and_then(|(_, rest)| rest.split_once('<'))
            .map_or("", |(text, _)| text);
        assert!(
            log.contains("fetch"),
            "the page ran (API at {api_host}): {log:?}\n{dom}"
        );
    }
    // Each of the four requests reached the API and was refused.
    let refused = sim.lines_with("HTTP: refused POST /api/poses", 4);
    let sites = |s: &str| refused.iter().filter(|l| l.contains(s)).count();
    assert_eq!(
        (
            sites("Sec-Fetch-Site: same-site"),
            sites("Sec-Fetch-Site: cross-site")
        ),
        (2, 2),
        "fetch and form, same site and cross site, refused: {refused:#?}"
    );
    let readers = http_support::request(http, "GET", "/api/readers", &[], b"").json();
    let names: Vec<&str> = readers["readers"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(|r| r["name"].as_str())
        .collect();
    assert!(
        names.iter().all(|n| !n.starts_with("evil")),
        "a page of another origin moved the localizer: {names:?}"
    );
    assert!(names.contains(&"s1-reader"), "{names:?}");
    // The map's own page still loads and its stream runs.
    let dom = run_chromium(
        &dir.path().join("profile-map"),
        &format!("http://{http}/"),
        &["--dump-dom"],
    );
    assert!(dom.contains("id=\"status\">live<"), "{dom}");
    sim.stop();
}
