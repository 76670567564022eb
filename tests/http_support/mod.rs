//! For the HTTP API's tests: a live localizer fed a synthetic tag seen from an antenna moving
//! along x, the API served on loopback in its own thread, a small blocking HTTP/1.1 client
//! (requests with `Connection: close`, chunked bodies decoded), and a child process of the
//! binary that prints its addresses ([`Proc`]).
#![allow(dead_code)]

use std::io::{BufRead, BufReader, Read as _, Write};
use std::net::{SocketAddr, TcpStream};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use llrp_gateway::http::{self, HttpOptions};
use llrp_gateway::localize::live::{Input, Live, Settings};
use llrp_gateway::localize::poses::{Pose, PoseSample};
use llrp_gateway::localize::shared::{Truth, TruthTag};
use llrp_gateway::reads::Read;

/// The synthetic tag's EPC and true position (m); the tag height the localizer assumes.
pub const EPC: &str = "E2801160600002054CC2A1B7";
pub const TAG: [f64; 3] = [0.5, 1.5, 0.5];
/// The synthetic reader.
pub const READER: &str = "sim-0";
/// Longest any wait of the tests lasts.
pub const PATIENCE: Duration = Duration::from_secs(60);

const FREQUENCY_HZ: u64 = 865_700_000;

/// The antenna's pose at `t_us`: along x from −1 m at 1 m/s, at y = 0, facing +y.
pub fn pose(t_us: u64) -> PoseSample {
    PoseSample {
        t_us,
        reader: Some(READER.parse().expect("a reader name")),
        antenna: 1,
        pose: Pose::from_degrees([-1.0 + t_us as f64 * 1e-6, 0.0, 0.5], 90.0, 0.0),
    }
}

/// A read of the tag at `t_us` with the phase of the antenna's pose then (no pose of its
/// own: the localizer takes it from the poses).
pub fn read(t_us: u64) -> Read {
    let [x, y, z] = pose(t_us).pose.position;
    let lambda = llrp_gateway::localize::SPEED_OF_LIGHT / FREQUENCY_HZ as f64;
    let d = ((TAG[0] - x).powi(2) + (TAG[1] - y).powi(2) + (TAG[2] - z).powi(2)).sqrt();
    Read {
        epc: llrp_gateway::reads::Epc::parse(EPC).expect("hex"),
        reader: Some(READER.parse().expect("a reader name")),
        antenna: 1,
        t_us,
        phase_rad: Some((0.9 + 4.0 * std::f64::consts::PI * d / lambda) % std::f64::consts::TAU),
        rssi_dbm: Some(-55.0),
        channel_index: Some(1),
        channel_frequency_hz: Some(FREQUENCY_HZ),
        doppler_hz: None,
        antenna_pose: None,
        last_seen_us: None,
    }
}

/// The simulation's truth for the synthetic tag.
pub fn truth() -> Truth {
    Truth {
        tags: vec![TruthTag {
            epc: llrp_gateway::reads::Epc::parse(EPC).expect("hex"),
            position: TAG,
            reference: false,
        }],
        antennas: vec![pose(3_000_000)],
    }
}

/// A live localizer and the API over it on 127.0.0.1.
pub struct Server {
    /// The localizer (its tap and state).
    pub live: Live,
    /// Where the API listens.
    pub addr: SocketAddr,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    thread: Option<JoinHandle<std::io::Result<()>>>,
}

impl Server {
    /// Starts a localizer and serves the API over it with `options`.
    pub fn start(options: HttpOptions) -> Server {
        Server::start_with(options, Settings::default())
    }

    /// Starts a localizer with `settings` and serves the API over it with `options`.
    pub fn start_with(options: HttpOptions, settings: Settings) -> Server {
        let live = Live::start(settings).expect("localizer starts");
        let limits = options.limits;
        let router = http::router(live.shared.clone(), live.tap.clone(), options);
        let std_listener = std::net::TcpListener::bind("127.0.0.1:0").expect("binds loopback");
        let addr = std_listener.local_addr().expect("an address");
        std_listener.set_nonblocking(true).expect("nonblocking");
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        let thread = std::thread::spawn(move || {
            let rt = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()?;
            rt.block_on(async move {
                let listener = tokio::net::TcpListener::from_std(std_listener)?;
                http::serve(listener, router, limits, async move {
                    let _ = stopped.await;
                })
                .await
            })
        });
        Server {
            live,
            addr,
            stop: Some(stop),
            thread: Some(thread),
        }
    }

    /// Offers the antenna's poses and the tag's reads from 0 to 3 s every 10 ms (the
    /// aperture and density the estimator converges on).
    pub fn feed_tag(&self) {
        let times: Vec<u64> = (0..=300).map(|k| k * 10_000).collect();
        let poses = times.iter().map(|&t| pose(t)).collect();
        assert!(self.live.tap.offer(Input::Poses(poses)), "tap takes poses");
        let reads = times.iter().map(|&t| read(t)).collect();
        assert!(self.live.tap.offer(Input::Reads(reads)), "tap takes reads");
    }

    /// GET `path`.
    pub fn get(&self, path: &str) -> Response {
        request(self.addr, "GET", path, &[], b"")
    }

    /// Polls GET /api/tags/{EPC} until the tag is converged; its JSON.
    pub fn converged(&self) -> serde_json::Value {
        let deadline = Instant::now() + PATIENCE;
        loop {
            let r = self.get(&format!("/api/tags/{EPC}"));
            if r.status == 200 {
                let v = r.json();
                if v["state"] == "converged" {
                    return v;
                }
            }
            assert!(
                Instant::now() < deadline,
                "the tag did not converge: {} {}",
                r.status,
                r.text()
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        if let Some(thread) = self.thread.take() {
            let done = thread.join().expect("the server thread did not panic");
            if !std::thread::panicking() {
                done.expect("the server ran and stopped cleanly");
            }
        }
    }
}

/// An HTTP response.
#[derive(Debug)]
pub struct Response {
    /// Status code.
    pub status: u16,
    /// Headers, names lower-case.
    pub headers: Vec<(String, String)>,
    /// The body, de-chunked.
    pub body: Vec<u8>,
}

impl Response {
    /// The header `name` (lower-case), if present.
    pub fn header(&self, name: &str) -> Option<&str> {
        self.headers
            .iter()
            .find(|(k, _)| k == name)
            .map(|(_, v)| v.as_str())
    }

    /// The body as text.
    pub fn text(&self) -> String {
        String::from_utf8_lossy(&self.body).into_owned()
    }

    /// The body as JSON.
    pub fn json(&self) -> serde_json::Value {
        serde_json::from_slice(&self.body)
            .unwrap_or_else(|e| panic!("not JSON ({e}): {}", self.text()))
    }

    /// The `error` of a JSON error body.
    pub fn error(&self) -> String {
        let v = self.json();
        v["error"]
            .as_str()
            .unwrap_or_else(|| panic!("no error string: {v}"))
            .to_string()
    }
}

fn write_request(
    stream: &mut TcpStream,
    addr: SocketAddr,
    method: &str,
    path: &str,
    headers: &[(&str, &str)],
    body: &[u8],
) {
    // The address as Host unless the caller gives one.
    let mut head = format!("{method} {path} HTTP/1.1\r\nConnection: close\r\n");
    if !headers.iter().any(|(k, _)| k.eq_ignore_ascii_case("host")) {
        head.push_str(&format!("Host: {addr}\r\n"));
    }
    for (k, v) in headers {
        head.push_str(&format!("{k}: {v}\r\n"));
    }
    if !body.is_empty() || method == "POST" {
        head.push_str(&format!("Content-Length: {}\r\n", body.len()));
    }
    head.push_str("\r\n");
    stream.write_all(head.as_bytes()).expect("writes the head");
    // The server may answer (413) before it read all: a failed write is no failure here.
    let _ = stream.write_all(body);
}

fn read_head(reader: &mut impl BufRead) -> (u16, Vec<(String, String)>) {
    let mut line = String::new();
    reader.read_line(&mut line).expect("a status line");
    let status = line
        .split_whitespace()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("no status in {line:?}"));
    let mut headers = Vec::new();
    loop {
        line.clear();
        reader.read_line(&mut line).expect("a header line");
        let l = line.trim_end();
        if l.is_empty() {
            break;
        }
        if let Some((k, v)) = l.split_once(':') {
            headers.push((k.trim().to_ascii_lowercase(), v.trim().to_string()));
        }
    }
    (status, headers)
}

/// `POST /api/poses` with `body` sent as JSON: `Content-Type: application/json` unless
/// `headers` names a content type.
pub fn post_poses(addr: SocketAddr, headers: &[(&str, &str)], body: &[u8]) -> Response {
    let mut all = headers.to_vec();
    if !all
        .iter()
        .any(|(k, _)| k.eq_ignore_ascii_case("content-type"))
    {
        all.push(("Content-Type", "application/json"));
    }
    request(addr, "POST", "/api/poses", &all, body)
}

/// One request; the whole response.
pub fn request(
    addr: SocketAddr,
    method: &str,
    path: &str,
    headers: &[(&str, &str)],
    body: &[u8],
) -> Response {
    let mut stream = TcpStream::connect(addr).expect("connects");
    stream.set_read_timeout(Some(PATIENCE)).expect("timeout");
    write_request(&mut stream, addr, method, path, headers, body);
    let mut reader = BufReader::new(stream);
    let (status, headers) = read_head(&mut reader);
    let chunked = headers
        .iter()
        .any(|(k, v)| k == "transfer-encoding" && v.contains("chunked"));
    let mut body = Vec::new();
    if chunked {
        while let Some(chunk) = read_chunk(&mut reader) {
            body.extend(chunk);
        }
    } else {
        let _ = reader.read_to_end(&mut body);
    }
    Response {
        status,
        headers,
        body,
    }
}

fn read_chunk(reader: &mut impl BufRead) -> Option<Vec<u8>> {
    let mut line = String::new();
    reader.read_line(&mut line).ok()?;
    let size = usize::from_str_radix(line.trim().split(';').next()?, 16).ok()?;
    if size == 0 {
        return None;
    }
    let mut chunk = vec![0; size + 2];
    reader.read_exact(&mut chunk).ok()?;
    chunk.truncate(size);
    Some(chunk)
}

/// An open `GET /api/events` stream.
pub struct Events {
    reader: BufReader<TcpStream>,
    buffer: String,
}

impl Events {
    /// Opens the stream; returns once the server said it is subscribed.
    pub fn open(addr: SocketAddr) -> Events {
        let mut stream = TcpStream::connect(addr).expect("connects");
        stream.set_read_timeout(Some(PATIENCE)).expect("timeout");
        write_request(&mut stream, addr, "GET", "/api/events", &[], b"");
        let mut reader = BufReader::new(stream);
        let (status, headers) = read_head(&mut reader);
        assert_eq!(status, 200);
        let kind = headers.iter().find(|(k, _)| k == "content-type");
        assert_eq!(
            kind.map(|(_, v)| v.as_str()),
            Some("text/event-stream"),
            "{headers:?}"
        );
        let mut events = Events {
            reader,
            buffer: String::new(),
        };
        events.next_block(|b| b.contains(": subscribed"));
        events
    }

    /// The next blank-line-separated block that `want` accepts (others skipped).
    pub fn next_block(&mut self, want: impl Fn(&str) -> bool) -> String {
        let deadline = Instant::now() + PATIENCE;
        loop {
            while let Some(end) = self.buffer.find("\n\n") {
                let block: String = self.buffer.drain(..end + 2).collect();
                if want(&block) {
                    return block;
                }
            }
            assert!(Instant::now() < deadline, "no such event in time");
            let chunk = read_chunk(&mut self.reader).expect("the stream goes on");
            self.buffer.push_str(&String::from_utf8_lossy(&chunk));
        }
    }
}

/// The value of counter `name` (`llrp_gateway_NAME_total`) in `GET /metrics`.
pub fn counter(http: SocketAddr, name: &str) -> f64 {
    let text = request(http, "GET", "/metrics", &[], b"").text();
    text.lines()
        .find_map(|l| l.strip_prefix(&format!("llrp_gateway_{name}_total ")))
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or_else(|| panic!("no {name} in {text}"))
}

/// The first reader of `GET /api/readers`.
pub fn first_reader(http: SocketAddr) -> serde_json::Value {
    request(http, "GET", "/api/readers", &[], b"").json()["readers"][0].clone()
}

/// A running child with the addresses it printed; SIGTERM and a wait when dropped.
pub struct Proc {
    child: std::process::Child,
    lines: std::sync::mpsc::Receiver<String>,
    log: Vec<String>,
}

impl Proc {
    /// Starts the binary with `args`, its standard error collected line by line.
    pub fn spawn(args: &[&str]) -> Proc {
        Proc::spawn_env(args, &[])
    }

    /// [`Proc::spawn`] with the environment variables `env` set too.
    pub fn spawn_env(args: &[&str], env: &[(&str, &str)]) -> Proc {
        let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_llrp-gateway"))
            .args(args)
            .envs(env.iter().copied())
            .stdin(std::process::Stdio::null())
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .expect("runs");
        let stderr = child.stderr.take().expect("piped");
        let (tx, lines) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                let _ = tx.send(line);
            }
        });
        Proc {
            child,
            lines,
            log: Vec::new(),
        }
    }

    /// Starts `sim` with `extra` options, its LLRP listener and HTTP API on free loopback
    /// ports; the child and the API's address.
    pub fn sim(extra: &[&str]) -> (Proc, SocketAddr) {
        let mut args = vec!["sim", "--listen", "127.0.0.1:0", "--http", "127.0.0.1:0"];
        args.extend_from_slice(extra);
        let mut sim = Proc::spawn(&args);
        let http = sim
            .address("live map on http://")
            .parse()
            .expect("an HTTP address");
        (sim, http)
    }

    /// The child's process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Whether the child is still running.
    pub fn running(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(None))
    }

    /// Asks the child to stop (SIGTERM) and waits for its exit (SIGKILL after 10 s).
    pub fn stop(&mut self) -> std::process::ExitStatus {
        let _ = std::process::Command::new("kill")
            .arg(self.child.id().to_string())
            .status();
        let deadline = Instant::now() + Duration::from_secs(10);
        while Instant::now() < deadline {
            if let Ok(Some(status)) = self.child.try_wait() {
                return status;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        let _ = self.child.kill();
        self.child.wait().expect("the child is waited for")
    }

    /// Stops the child ([`Proc::stop`]) and gives every line it wrote to standard error.
    pub fn stop_and_log(&mut self) -> Vec<String> {
        self.stop();
        // The reader thread ends at the end of the stream, which the exit closed.
        while let Ok(line) = self.lines.recv_timeout(PATIENCE) {
            self.log.push(line);
        }
        self.log.clone()
    }

    /// Kills the child at once (SIGKILL: no clean exit) and waits for it.
    pub fn kill_hard(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    /// The first `n` lines of the log that hold `marker`, waiting for them at most 30 s;
    /// fewer if they do not come.
    pub fn lines_with(&mut self, marker: &str, n: usize) -> Vec<String> {
        let deadline = Instant::now() + Duration::from_secs(30);
        loop {
            let found: Vec<String> = self
                .log
                .iter()
                .filter(|l| l.contains(marker))
                .take(n)
                .cloned()
                .collect();
            if found.len() >= n {
                return found;
            }
            let left = deadline.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(line) => self.log.push(line),
                Err(_) => return found,
            }
        }
    }

    /// The address after `marker` in the first line of the log that has it.
    pub fn address(&mut self, marker: &str) -> String {
        let mut seen = 0;
        loop {
            if seen == self.log.len() {
                let line = self
                    .lines
                    .recv_timeout(Duration::from_secs(30))
                    .unwrap_or_else(|_| panic!("no line with {marker:?} in {:?}", self.log));
                self.log.push(line);
            }
            let line = &self.log[seen];
            seen += 1;
            if let Some(rest) = line.split(marker).nth(1) {
                return rest
                    .split([',', ' '])
                    .next()
                    .unwrap_or_default()
                    .trim_end_matches('/')
                    .to_string();
            }
        }
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        if self.running() {
            self.stop();
        }
    }
}
