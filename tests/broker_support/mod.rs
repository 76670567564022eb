//! A real mosquitto for the fleet tests: started on a free loopback port with its own
//! configuration in a temporary directory, stopped by PID when dropped.

#![allow(dead_code)]

pub mod agree;

use std::net::TcpListener;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// A localizer worker on `url` (`localize --subscribe URL` and `extra`) with its HTTP API on
/// a free port, once subscribed. (Needs the test's `mod http_support;`.)
pub fn worker(url: &str, extra: &[&str]) -> (crate::http_support::Proc, std::net::SocketAddr) {
    let mut args = vec!["localize", "--subscribe", url, "--http", "127.0.0.1:0"];
    args.extend_from_slice(extra);
    let mut p = crate::http_support::Proc::spawn(&args);
    let addr = p.address("live map on http://").parse().expect("address");
    p.address(", subscribed");
    (p, addr)
}

/// `sim --no-http --speed 20 --publish URL` and `extra` on S1, once it listens; SIGTERM (a
/// clean exit) when dropped. (Needs the test's `mod http_support;`.)
pub fn publishing_sim(url: &str, extra: &[&str]) -> crate::http_support::Proc {
    let mut args = vec![
        "sim",
        "--no-http",
        "--listen",
        "127.0.0.1:0",
        "--speed",
        "20",
        "--publish",
        url,
    ];
    args.extend_from_slice(extra);
    let mut p = crate::http_support::Proc::spawn(&args);
    p.address("listening on ");
    p
}

/// A running mosquitto.
pub struct Mosquitto {
    /// Its loopback port.
    pub port: u16,
    child: Option<Child>,
    conf: PathBuf,
    /// Its configuration, log and persistence.
    pub dir: tempfile::TempDir,
}

/// The broker binary `name` (Debian puts mosquitto and nats-server in /usr/sbin, which a
/// user's PATH may lack); `./scripts/install-brokers` installs them.
fn binary(name: &str) -> PathBuf {
    for dir in ["/usr/sbin", "/usr/bin", "/usr/local/sbin", "/usr/local/bin"] {
        let p = std::path::Path::new(dir).join(name);
        if p.exists() {
            return p;
        }
    }
    panic!("{name} is not installed: run ./scripts/install-brokers");
}

/// A port free on loopback now.
pub fn free_port() -> u16 {
    let l = TcpListener::bind("127.0.0.1:0").expect("binds");
    l.local_addr().expect("address").port()
}

impl Mosquitto {
    /// Starts mosquitto with anonymous access and `extra` configuration lines.
    pub fn start(extra: &str) -> Mosquitto {
        Mosquitto::start_with(|port, _| {
            format!("listener {port} 127.0.0.1\nallow_anonymous true\npersistence false\n{extra}\n")
        })
    }

    /// Starts mosquitto with the configuration `conf(port, dir)` gives (its first listener
    /// on `port`), plus a log file in `dir` and no bound on the messages queued for a
    /// subscriber. A port taken between [`free_port`] and mosquitto's bind (by another
    /// test's process binding port 0) makes mosquitto exit: it is tried again on another.
    pub fn start_with(mut conf: impl FnMut(u16, &std::path::Path) -> String) -> Mosquitto {
        let dir = tempfile::tempdir().expect("temp dir");
        // Started as root, mosquitto runs as the user `mosquitto`: it must write its log and
        // persistence here.
        {
            use std::os::unix::fs::PermissionsExt;
            let open = std::fs::Permissions::from_mode(0o777);
            std::fs::set_permissions(dir.path(), open).expect("chmod");
        }
        let path = dir.path().join("mosquitto.conf");
        let mut m = Mosquitto {
            port: 0,
            child: None,
            conf: path,
            dir,
        };
        for _ in 0..5 {
            m.port = free_port();
            let text = format!(
                "{}\nmax_queued_messages 1000000\nlog_dest file {}\n",
                conf(m.port, m.dir.path()),
                m.log().display()
            );
            std::fs::write(&m.conf, text).expect("writes the configuration");
            if m.run() {
                return m;
            }
        }
        panic!("mosquitto did not start on five ports: {}", m.log_text());
    }

    fn log(&self) -> PathBuf {
        self.dir.path().join("mosquitto.log")
    }

    fn log_text(&self) -> String {
        std::fs::read_to_string(self.log()).unwrap_or_default()
    }

    /// Starts mosquitto and waits until its log says it runs and its port accepts; false if
    /// it exited instead (its port was taken).
    fn run(&mut self) -> bool {
        let running_before = self.log_text().matches(" running").count();
        let child = Command::new(binary("mosquitto"))
            .arg("-c")
            .arg(&self.conf)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("mosquitto starts");
        self.child = Some(child);
        let deadline = Instant::now() + Duration::from_secs(10);
        loop {
            if let Some(Ok(Some(_))) = self.child.as_mut().map(|c| c.try_wait()) {
                self.child = None;
                return false;
            }
            let running = self.log_text().matches(" running").count() > running_before;
            if running && std::net::TcpStream::connect(("127.0.0.1", self.port)).is_ok() {
                return true;
            }
            assert!(
                Instant::now() < deadline,
                "mosquitto did not listen on {}: {}",
                self.port,
                self.log_text()
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Stops it (SIGTERM: with persistence on it saves its state) and waits.
    pub fn stop(&mut self) {
        let Some(mut child) = self.child.take() else {
            return;
        };
        let _ = Command::new("kill").arg(child.id().to_string()).status();
        let deadline = Instant::now() + Duration::from_secs(5);
        while Instant::now() < deadline {
            if let Ok(Some(_)) = child.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = child.kill();
        let _ = child.wait();
    }

    /// Starts it again on the same port with the same configuration.
    pub fn restart(&mut self) {
        self.stop();
        assert!(
            self.run(),
            "mosquitto did not restart on {}: {}",
            self.port,
            self.log_text()
        );
    }

    /// `mqtt://127.0.0.1:PORT/prefix`.
    pub fn url(&self, prefix: &str) -> String {
        format!("mqtt://127.0.0.1:{}/{prefix}", self.port)
    }
}

impl Drop for Mosquitto {
    fn drop(&mut self) {
        self.stop();
    }
}

/// A test's own MQTT client: publishes, and collects what its subscriptions receive.
pub struct Probe {
    client: rumqttc::Client,
    rx: std::sync::mpsc::Receiver<(String, Vec<u8>, bool)>,
    acks: std::sync::Arc<std::sync::atomic::AtomicU64>,
}

impl Probe {
    /// Connects to `port` and subscribes to `topics`, waiting for the subscriptions.
    pub fn connect(port: u16, id: &str, topics: &[&str]) -> Probe {
        Probe::connect_as(port, id, None, topics)
    }

    /// [`Probe::connect`] as user `login.0` with password `login.1`.
    pub fn connect_as(port: u16, id: &str, login: Option<(&str, &str)>, topics: &[&str]) -> Probe {
        Probe::open(port, id, login, topics, true)
    }

    /// [`Probe::connect`] with a persistent session (clean session off), which survives a
    /// broker restart with persistence; it reconnects by itself.
    pub fn connect_persistent(port: u16, id: &str, topics: &[&str]) -> Probe {
        Probe::open(port, id, None, topics, false)
    }

    fn open(
        port: u16,
        id: &str,
        login: Option<(&str, &str)>,
        topics: &[&str],
        clean: bool,
    ) -> Probe {
        let mut o = rumqttc::MqttOptions::new(id, rumqttc::Broker::tcp("127.0.0.1", port));
        o.set_max_packet_size(1 << 20, 1 << 20);
        o.set_clean_session(clean);
        if let Some((user, pass)) = login {
            o.set_credentials(user, pass.to_owned());
        }
        let acks = std::sync::Arc::new(std::sync::atomic::AtomicU64::new(0));
        let counted = acks.clone();
        let (client, mut connection) = rumqttc::Client::builder(o).capacity(100).build();
        // Subscribed once connected (and again after each reconnection), as the worker does.
        let subscriber = client.clone();
        let filters: Vec<String> = topics.iter().map(|t| t.to_string()).collect();
        let (tx, rx) = std::sync::mpsc::channel();
        let (ready_tx, ready_rx) = std::sync::mpsc::channel();
        let want = topics.len();
        std::thread::spawn(move || {
            let mut acks = 0;
            for event in connection.iter() {
                match event {
                    Ok(rumqttc::Event::Incoming(rumqttc::Packet::ConnAck(_))) => {
                        for f in &filters {
                            let _ = subscriber.subscribe(f.clone(), rumqttc::QoS::AtLeastOnce);
                        }
                    }
                    Ok(rumqttc::Event::Incoming(rumqttc::Packet::SubAck(_))) => {
                        acks += 1;
                        if acks == want {
                            let _ = ready_tx.send(());
                        }
                    }
                    Ok(rumqttc::Event::Incoming(rumqttc::Packet::PubAck(_))) => {
                        counted.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
                    }
                    Ok(rumqttc::Event::Incoming(rumqttc::Packet::Publish(p))) => {
                        if tx
                            .send((
                                String::from_utf8_lossy(&p.topic).into_owned(),
                                p.payload.to_vec(),
                                p.retain,
                            ))
                            .is_err()
                        {
                            return;
                        }
                    }
                    Ok(_) => {}
                    Err(_) if clean => return,
                    // Persistent: reconnect (the broker may be restarting).
                    Err(_) => std::thread::sleep(Duration::from_millis(50)),
                }
            }
        });
        if want > 0 {
            ready_rx
                .recv_timeout(Duration::from_secs(10))
                .expect("subscribed");
        }
        Probe { client, rx, acks }
    }

    /// Publishes `payload` to `topic` at QoS 1 and waits for the broker's acknowledgement.
    pub fn publish_acked(&self, topic: &str, payload: &[u8]) {
        let before = self.acks.load(std::sync::atomic::Ordering::SeqCst);
        self.publish(topic, payload);
        let deadline = Instant::now() + Duration::from_secs(10);
        while self.acks.load(std::sync::atomic::Ordering::SeqCst) == before {
            assert!(Instant::now() < deadline, "no PUBACK for {topic}");
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// Publishes `payload` to `topic` at QoS 1.
    pub fn publish(&self, topic: &str, payload: &[u8]) {
        self.client
            .publish(
                topic,
                payload.to_vec(),
                rumqttc::PublishOptions::at_least_once(),
            )
            .expect("publishes");
    }

    /// Messages received within `wait` of the last one (at most `wait` for the first).
    pub fn drain(&self, wait: Duration) -> Vec<(String, Vec<u8>, bool)> {
        let mut out = Vec::new();
        while let Ok(m) = self.rx.recv_timeout(wait) {
            out.push(m);
        }
        out
    }
}

/// A running nats-server with JetStream and its MQTT interface on free loopback ports (its
/// MQTT `max_ack_pending` left at the default: set to 65,535, a session with several
/// subscriptions got only its first one's messages; `ack_wait` 1 s, below the workers' hold
/// for a gap: under load NATS delivers some QoS 1 messages only when it redelivers them,
/// docs/fleet.md).
pub struct Nats {
    /// Its MQTT port.
    pub port: u16,
    child: Child,
    /// Its configuration, log and JetStream store.
    pub dir: tempfile::TempDir,
}

impl Nats {
    /// Starts nats-server (Debian's package: `./scripts/install-brokers`).
    pub fn start() -> Nats {
        let dir = tempfile::tempdir().expect("temp dir");
        let conf = dir.path().join("nats.conf");
        let log_path = dir.path().join("nats.log");
        // A port taken before nats-server binds it makes it exit: tried again on others.
        for _ in 0..5 {
            let (port, client) = (free_port(), free_port());
            std::fs::write(
                &conf,
                format!(
                    "server_name: \"fleet-test\"\nlisten: 127.0.0.1:{client}\n\
                     jetstream {{ store_dir: \"{}\" }}\n\
                     mqtt {{ listen: 127.0.0.1:{port}, ack_wait: \"1s\" }}\n",
                    dir.path().join("js").display()
                ),
            )
            .expect("writes the configuration");
            let log = std::fs::File::create(&log_path).expect("log");
            let mut child = Command::new(binary("nats-server"))
                .arg("-c")
                .arg(&conf)
                .stdin(Stdio::null())
                .stdout(Stdio::null())
                .stderr(log)
                .spawn()
                .expect("nats-server starts (./scripts/install-brokers)");
            let deadline = Instant::now() + Duration::from_secs(20);
            loop {
                if let Ok(Some(_)) = child.try_wait() {
                    break;
                }
                let log = std::fs::read_to_string(&log_path).unwrap_or_default();
                if log.contains("Server is ready")
                    && std::net::TcpStream::connect(("127.0.0.1", port)).is_ok()
                {
                    return Nats { port, child, dir };
                }
                assert!(
                    Instant::now() < deadline,
                    "nats-server did not listen on {port}: {log}"
                );
                std::thread::sleep(Duration::from_millis(20));
            }
        }
        panic!(
            "nats-server did not start on five ports: {}",
            std::fs::read_to_string(&log_path).unwrap_or_default()
        );
    }

    /// `mqtt://127.0.0.1:PORT/prefix`.
    pub fn url(&self, prefix: &str) -> String {
        format!("mqtt://127.0.0.1:{}/{prefix}", self.port)
    }
}

impl Drop for Nats {
    fn drop(&mut self) {
        let _ = Command::new("kill")
            .arg(self.child.id().to_string())
            .status();
        let deadline = Instant::now() + Duration::from_secs(5);
        while Instant::now() < deadline {
            if let Ok(Some(_)) = self.child.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
