//! Replaying recordings as a reader: the shipped fixtures served to the client that made them
//! (sllurp 2.0.1, llrpkit 0.3.0, llrp-gateway inventory) and to a client that sends the
//! recorded requests with other message IDs; a second client refused; `--loop`.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};

use llrp::enums::ConnectionAttemptStatus;
use llrp::{FrameHeader, MessageKind};
use llrp_gateway::net::client::Client;
use llrp_gateway::record::replay::{ReplayOptions, Script};
use llrp_gateway::record::{Direction, Recording};
use tokio::net::TcpListener;
use tokio::sync::watch;

const T: Duration = Duration::from_secs(10);

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn fixture(name: &str) -> PathBuf {
    root().join("fixtures/sessions").join(name)
}

fn fixtures() -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(root().join("fixtures/sessions"))
        .expect("fixtures/sessions")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "jsonl"))
        .collect();
    v.sort();
    v
}

/// Serves `path` in process on a free port.
async fn serve(path: &Path, options: ReplayOptions) -> (std::net::SocketAddr, watch::Sender<bool>) {
    let recording = Recording::open(path).expect("fixture reads");
    let script = Arc::new(Script::new(&recording, None).expect("script"));
    let l = TcpListener::bind("127.0.0.1:0").await.expect("bind");
    let addr = l.local_addr().expect("bound");
    let (tx, rx) = watch::channel(false);
    tokio::spawn(llrp_gateway::net::replay::serve(
        l, script, options, None, rx,
    ));
    (addr, tx)
}

const MAX: ReplayOptions = ReplayOptions {
    speed: None,
    looped: false,
};

#[tokio::test]
async fn every_fixture_replays_its_reader_frames_to_the_recorded_requests_with_the_clients_ids() {
    let all = fixtures();
    assert!(all.len() >= 3, "fixtures: {all:?}");
    for path in all {
        let recording = Recording::open(&path).expect("fixture reads");
        assert!(
            recording.warnings.is_empty(),
            "{}: {:?}",
            path.display(),
            recording.warnings
        );
        let script = Script::new(&recording, None).expect("script");
        let conn = script.conn();
        let (addr, stop) = serve(&path, MAX).await;
        let mut c = Client::connect(addr).await.expect("connects");
        let frames: Vec<_> = recording.frames(conn).collect();
        // What the reader sent, in order, with each response's ID moved as the client's is.
        let mut expected = Vec::new();
        let mut got = Vec::new();
        for (_, dir, frame) in &frames {
            match dir {
                Direction::ToReader => {
                    let mut f = frame.to_vec();
                    let h = FrameHeader::peek(&f).expect("header");
                    let id = h.id.wrapping_add(5_000);
                    f[6..10].copy_from_slice(&id.to_be_bytes());
                    c.send_raw(&f).await.expect("send");
                }
                Direction::FromReader => {
                    let mut f = frame.to_vec();
                    let kind = MessageKind::of_frame(&f).expect("kind");
                    let unsolicited = [61u16, 62, 63].contains(&kind.msg_type);
                    if !unsolicited {
                        let id = FrameHeader::peek(&f)
                            .expect("header")
                            .id
                            .wrapping_add(5_000);
                        f[6..10].copy_from_slice(&id.to_be_bytes());
                    }
                    expected.push(f);
                    got.push(c.recv_raw(T).await.expect("a frame").to_vec());
                }
            }
        }
        // Order between a response and a report sent at the same time may differ: compare
        // each kind of frame in order.
        let by_kind = |v: &[Vec<u8>]| {
            let mut m: std::collections::BTreeMap<u16, Vec<Vec<u8>>> = Default::default();
            for f in v {
                m.entry(FrameHeader::peek(f).expect("header").msg_type)
                    .or_default()
                    .push(f.clone());
            }
            m
        };
        assert_eq!(
            by_kind(&got),
            by_kind(&expected),
            "{}: the replayed frames differ",
            path.display()
        );
        let _ = stop.send(true);
    }
}

#[tokio::test]
async fn a_second_client_is_refused_while_one_is_replayed() {
    let (addr, stop) = serve(&fixture("llrpkit-emulator.jsonl"), MAX).await;
    let mut first = Client::connect(addr).await.expect("connects");
    let greeting = first.recv(T).await.expect("greeting");
    assert_eq!(
        greeting.body.connection_attempt(),
        Some(ConnectionAttemptStatus::Success)
    );
    let mut second = Client::connect(addr).await.expect("connects");
    let m = second.recv(T).await.expect("refusal");
    assert_eq!(
        m.body.connection_attempt(),
        Some(ConnectionAttemptStatus::FailedClientInitiatedConnectionExists)
    );
    second.until_closed(T).await.expect("closed");
    let _ = stop.send(true);
}

/// A running `llrp-gateway replay`.
struct Replay {
    child: std::process::Child,
    port: u16,
}

impl Drop for Replay {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Starts `llrp-gateway replay FILE ARGS` on a free port and waits for its listening line.
fn spawn_replay(file: &Path, args: &[&str]) -> Replay {
    let mut child = Command::new(env!("CARGO_BIN_EXE_llrp-gateway"))
        .arg("replay")
        .arg(file)
        .args(["--listen", "127.0.0.1:0"])
        .args(args)
        .stderr(Stdio::piped())
        .stdout(Stdio::null())
        .spawn()
        .expect("runs");
    let stderr = child.stderr.take().expect("piped");
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            if let Some(addr) = line.split("listening on ").nth(1) {
                let _ = tx.send(addr.trim().to_string());
            }
        }
    });
    let addr = rx
        .recv_timeout(Duration::from_secs(30))
        .expect("listening line");
    let port = addr
        .rsplit(':')
        .next()
        .and_then(|p| p.parse().ok())
        .expect("port");
    Replay { child, port }
}

/// EPCs of the RO_ACCESS_REPORTs of a recording, upper-case hex.
fn recorded_epcs(path: &Path) -> std::collections::BTreeSet<String> {
    let r = Recording::open(path).expect("reads");
    let mut epcs = std::collections::BTreeSet::new();
    for (_, dir, frame) in r.frames(r.connections()[0]) {
        if dir != Direction::FromReader {
            continue;
        }
        if let Ok(reads) = llrp::reads::tag_reads(frame) {
            for read in reads.flatten() {
                epcs.insert(llrp_gateway::reads::hex_upper(read.epc));
            }
        }
    }
    epcs
}

#[test]
fn the_inventory_client_reads_a_looped_replay_of_its_own_session() {
    let path = fixture("dock-door-inventory.jsonl");
    let recorded = recorded_epcs(&path);
    let r = Recording::open(&path).expect("reads");
    let recorded_reads: usize = r
        .frames(r.connections()[0])
        .filter_map(|(_, _, f)| llrp::reads::tag_reads(f).ok())
        .map(|it| it.count())
        .sum();
    let replay = spawn_replay(&path, &["--speed", "max", "--loop"]);
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("reads.jsonl");
    let status = Command::new(env!("CARGO_BIN_EXE_llrp-gateway"))
        .args(["inventory", &format!("127.0.0.1:{}", replay.port)])
        .args(["--seconds", "3", "--impinj", "--output"])
        .arg(&out)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .expect("inventory runs");
    assert!(status.success());
    let reads = llrp_gateway::reads::read_jsonl(BufReader::new(
        std::fs::File::open(&out).expect("reads file"),
    ))
    .expect("parses");
    assert!(
        reads.len() > 2 * recorded_reads,
        "{} reads from a looped replay of {recorded_reads}",
        reads.len()
    );
    for read in &reads {
        assert!(
            recorded.contains(read.epc.as_str()),
            "{} is not in the recording",
            read.epc
        );
        assert!(read.phase_rad.is_some() && read.channel_frequency_hz.is_some());
    }
    // Each round's timestamps are shifted past the one before.
    let first_round_max = r
        .frames(r.connections()[0])
        .filter_map(|(_, _, f)| llrp::reads::tag_reads(f).ok())
        .flat_map(|it| {
            it.flatten()
                .filter_map(|t| t.first_seen_utc)
                .collect::<Vec<_>>()
        })
        .max()
        .expect("timestamps");
    let latest = reads.iter().map(|r| r.t_us).max().expect("reads");
    assert!(latest > first_round_max, "timestamps were not shifted");
}

fn venv(var: &str) -> PathBuf {
    PathBuf::from(
        std::env::var_os(var).unwrap_or_else(|| panic!("{var} must be set (by ./scripts/test)")),
    )
}

#[test]
#[ignore = "needs the sllurp venv; run by ./scripts/test"]
fn sllurp_inventories_a_replay_of_its_own_session() {
    let path = fixture("s1-sllurp-impinj.jsonl");
    let recorded = recorded_epcs(&path);
    let replay = spawn_replay(&path, &[]);
    let dir = tempfile::tempdir().expect("temp dir");
    let log = dir.path().join("sllurp.log");
    let mut child = Command::new(venv("LLRP_VENV").join("bin/sllurp"))
        .arg("-l")
        .arg(&log)
        .args([
            "inventory",
            "-p",
            &replay.port.to_string(),
            "--impinj-reports",
            "-a",
            "0",
            "127.0.0.1",
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("sllurp runs");
    // A hang guard, not a measurement: the recording's four reports come within seconds.
    let guard = Instant::now() + Duration::from_secs(60);
    let mut text = String::new();
    while Instant::now() < guard {
        text = std::fs::read_to_string(&log).unwrap_or_default();
        if text.matches("saw tag(s)").count() >= 4 || child.try_wait().ok().flatten().is_some() {
            break;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let _ = child.kill();
    let _ = child.wait();
    assert!(
        text.matches("saw tag(s)").count() >= 4,
        "sllurp log:\n{text}"
    );
    let lower: Vec<String> = recorded.iter().map(|e| e.to_lowercase()).collect();
    let seen = lower.iter().filter(|e| text.contains(e.as_str())).count();
    assert!(seen > 0, "sllurp saw none of the recorded EPCs:\n{text}");
    drop(replay);
}

#[test]
#[ignore = "needs the llrpkit venv; run by ./scripts/test"]
fn llrpkit_inventories_a_replay_of_its_own_session() {
    let path = fixture("llrpkit-emulator.jsonl");
    let recorded = recorded_epcs(&path);
    let replay = spawn_replay(&path, &[]);
    let out = Command::new(venv("LLRP_LLRPKIT"))
        .args(["inventory", "127.0.0.1", "--port", &replay.port.to_string()])
        .args(["--phase", "--duration", "3"])
        .output()
        .expect("llrpkit runs");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "llrpkit failed: {text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let lines: Vec<&str> = text.lines().filter(|l| l.contains(" ant ")).collect();
    assert!(lines.len() >= 20, "llrpkit printed:\n{text}");
    for l in &lines {
        let epc = l.split_whitespace().next().expect("epc").to_uppercase();
        assert!(recorded.contains(&epc), "{epc} is not in the recording");
        assert!(l.contains("phase"), "{l}");
    }
    drop(replay);
}

#[test]
fn replay_list_shows_each_connection_and_which_one_is_replayed() {
    let out = Command::new(env!("CARGO_BIN_EXE_llrp-gateway"))
        .arg("replay")
        .arg(fixture("s1-sllurp-impinj.jsonl"))
        .arg("--list")
        .output()
        .expect("runs");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let lines: Vec<&str> = text.lines().collect();
    assert!(lines[0].starts_with("conn  start_s"), "{text}");
    let rec = Recording::open(&fixture("s1-sllurp-impinj.jsonl")).expect("opens");
    assert_eq!(lines.len(), 1 + rec.connections().len(), "{text}");
    assert_eq!(
        lines
            .iter()
            .filter(|l| l.ends_with("(replayed by default)"))
            .count(),
        1,
        "{text}"
    );
}
