//! The live map in a real browser: headless Chromium loads `GET /` from a server over a
//! converged synthetic tag with the simulation's truth set, and the page it renders shows the
//! tag's row (converged) and its estimated marker; a screenshot is taken too.
//!
//! `#[ignore]`d in a plain `cargo test`: it needs Debian's `chromium` (`scripts/install-chromium`,
//! which `./scripts/test` runs before the ignored tests). `LLRP_CHROMIUM` names another
//! binary; `LLRP_MAP_SCREENSHOT=path` keeps the screenshot (how `docs/img/map.png` is made).

mod http_support;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use http_support::{Server, EPC};
use llrp_gateway::http::HttpOptions;

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
fn the_map_shows_the_converged_tag_in_a_headless_browser() {
    let server = Server::start(HttpOptions {
        simulation: true,
        ..HttpOptions::default()
    });
    server.feed_tag();
    server.converged();
    server.live.shared.set_truth(http_support::truth());
    let url = format!("http://{}/", server.addr);
    let dir = tempfile::tempdir().expect("a temp dir");

    let dom = run_chromium(&dir.path().join("profile-dom"), &url, &["--dump-dom"]);
    let row = element(&dom, &format!("tag-{EPC}"))
        .unwrap_or_else(|| panic!("no row tag-{EPC} in the page:\n{dom}"));
    assert!(row.contains("data-state=\"converged\""), "{row}");
    assert!(
        dom.contains("class=\"estimated"),
        "no estimated marker:\n{dom}"
    );
    assert!(dom.contains("class=\"truth\""), "no truth marker:\n{dom}");

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
