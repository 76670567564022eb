//! The broker's security as the fleet uses it, against a real mosquitto configured with a
//! password file, an ACL and a TLS listener (certificates made here with rcgen): TLS and
//! credentials work end to end; wrong credentials are refused with a clear error; a client
//! without the right to a topic cannot get a message into it (checked at the subscriber:
//! MQTT 3.1.1 does not tell the publisher).

mod broker_support;
mod http_support;

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use broker_support::{free_port, publishing_sim, worker, Mosquitto, Probe};
use http_support::{counter, request};

/// CA and server certificate for 127.0.0.1 in `dir`: (ca.pem, server.pem, server.key).
fn pki(dir: &Path) -> (String, String, String) {
    let ca_key = rcgen::KeyPair::generate().expect("CA key");
    let mut ca = rcgen::CertificateParams::new(Vec::<String>::new()).expect("params");
    ca.is_ca = rcgen::IsCa::Ca(rcgen::BasicConstraints::Unconstrained);
    ca.distinguished_name
        .push(rcgen::DnType::CommonName, "fleet test CA");
    let ca = ca.self_signed(&ca_key).expect("CA certificate");
    let key = rcgen::KeyPair::generate().expect("server key");
    let mut params = rcgen::CertificateParams::new(vec!["127.0.0.1".to_string()]).expect("params");
    params
        .distinguished_name
        .push(rcgen::DnType::CommonName, "broker");
    let cert = params.signed_by(&key, &ca, &ca_key).expect("certificate");
    let write = |name: &str, text: String| {
        let p = dir.join(name);
        std::fs::write(&p, text).expect("writes PEM");
        p.to_str().expect("utf-8").to_string()
    };
    (
        write("ca.pem", ca.pem()),
        write("server.pem", cert.pem()),
        write("server.key", key.serialize_pem()),
    )
}

/// `mosquitto_passwd -b FILE USER PASS`.
fn add_user(file: &Path, user: &str, pass: &str) {
    let mut c = Command::new("mosquitto_passwd");
    if !file.exists() {
        c.arg("-c");
    }
    let ok = c
        .arg("-b")
        .arg(file)
        .args([user, pass])
        .stdout(Stdio::null())
        .status()
        .expect("mosquitto_passwd runs (./scripts/install-brokers)");
    assert!(ok.success());
}

/// A batch of one read of `epc` (with its antenna's pose, so it is filed at once).
fn batch(epc: &str) -> Vec<u8> {
    serde_json::json!({
        "v": 1, "gateway": "probe", "reader": "r", "seq": 1,
        "reads": [{"epcHex": epc, "antennaPort": 1, "phaseAngle": 10.0, "frequency": 866300,
                   "lastSeenTime": "2026-01-01T00:00:00Z", "firstSeenUs": 1_000_000,
                   "antennaPose": {"x": 0.0, "y": 0.0, "z": 1.0}}]
    })
    .to_string()
    .into_bytes()
}

#[test]
#[ignore = "needs mosquitto (./scripts/install-brokers); ./scripts/test runs it"]
fn tls_credentials_and_topic_rights_are_enforced_by_the_broker() {
    let (mut plain, mut ca) = (0, String::new());
    let broker = Mosquitto::start_with(|port, dir| {
        plain = free_port();
        let (ca_pem, cert, key) = pki(dir);
        ca = ca_pem.clone();
        let passwords = dir.join("passwords");
        add_user(&passwords, "gw", "gw-pass");
        add_user(&passwords, "worker", "worker-pass");
        add_user(&passwords, "intruder", "intruder-pass");
        let acl = dir.join("acl");
        std::fs::write(
            &acl,
            "user gw\ntopic readwrite sec/v1/#\n\nuser worker\ntopic readwrite sec/v1/#\n\n\
             user intruder\ntopic read sec/v1/#\n",
        )
        .expect("writes the ACL");
        format!(
            "per_listener_settings false\nallow_anonymous false\npassword_file {}\nacl_file {}\n\
             persistence false\nlistener {port} 127.0.0.1\ncafile {ca_pem}\ncertfile {cert}\n\
             keyfile {key}\nlistener {plain} 127.0.0.1\n",
            passwords.display(),
            acl.display()
        )
    });
    let tls = |login: &str| format!("mqtts://{login}@127.0.0.1:{}/sec", broker.port);

    // Wrong credentials: refused, and said so.
    let mut sim = Command::new(env!("CARGO_BIN_EXE_llrp-gateway"))
        .args(["sim", "--no-http", "--listen", "127.0.0.1:0", "--publish"])
        .arg(tls("gw:wrong"))
        .args(["--mqtt-ca", &ca])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("runs");
    let deadline = Instant::now() + Duration::from_secs(20);
    let status = loop {
        if let Some(s) = sim.try_wait().expect("waits") {
            break s;
        }
        if Instant::now() > deadline {
            let _ = sim.kill();
            panic!("sim with wrong credentials did not stop");
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let mut err = String::new();
    std::io::Read::read_to_string(&mut sim.stderr.take().expect("piped"), &mut err).expect("reads");
    assert!(!status.success());
    assert!(err.contains("refused the connection"), "{err}");
    assert!(!err.contains("wrong"), "the password is shown: {err}");

    // A worker over TLS with its own credentials.
    let (_w, http) = worker(&tls("worker:worker-pass"), &["--mqtt-ca", &ca]);

    // The intruder may read but not write: its batch never reaches the worker, while the
    // gateway's, published after it, does.
    let shard = |epc: &str| llrp_gateway::fleet::schema::shard(epc, 16);
    let (bad, good) = ("300833B2DDD90140000000BB", "300833B2DDD90140000000AA");
    let intruder = Probe::connect_as(plain, "intruder", Some(("intruder", "intruder-pass")), &[]);
    intruder.publish_acked(&format!("sec/v1/reads/{}", shard(bad)), &batch(bad));
    let gw = Probe::connect_as(plain, "gw-probe", Some(("gw", "gw-pass")), &[]);
    gw.publish_acked(&format!("sec/v1/reads/{}", shard(good)), &batch(good));
    let deadline = Instant::now() + Duration::from_secs(20);
    while request(http, "GET", &format!("/api/tags/{good}"), &[], b"").status != 200 {
        assert!(
            Instant::now() < deadline,
            "the gateway's read did not arrive"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    // Had the intruder's been delivered, it would have come first.
    assert_eq!(
        request(http, "GET", &format!("/api/tags/{bad}"), &[], b"").status,
        404
    );
    assert_eq!(counter(http, "mqtt_received"), 1.0);

    // The simulator with the right credentials, over TLS: its reads localize at the worker.
    let sim = publishing_sim(&tls("gw:gw-pass"), &["--mqtt-ca", &ca]);
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        let tags = request(http, "GET", "/api/tags", &[], b"").json();
        let located = tags["tags"]
            .as_array()
            .map(|t| t.iter().filter(|t| t["estimate"]["x"].is_number()).count())
            .unwrap_or(0);
        if located >= 1 {
            break;
        }
        assert!(Instant::now() < deadline, "nothing localized: {tags}");
        std::thread::sleep(Duration::from_millis(100));
    }
    drop(sim);
}

#[test]
#[ignore = "needs mosquitto (./scripts/install-brokers); ./scripts/test runs it"]
fn a_password_from_the_environment_or_a_file_logs_in_as_one_in_the_url_does() {
    let broker = Mosquitto::start_with(|port, dir| {
        let passwords = dir.join("passwords");
        add_user(&passwords, "gw", "gw-pass");
        add_user(&passwords, "worker", "worker-pass");
        format!(
            "per_listener_settings false\nallow_anonymous false\npassword_file {}\n\
             persistence false\nlistener {port} 127.0.0.1\n",
            passwords.display()
        )
    });
    let url = |user: &str| format!("mqtt://{user}@127.0.0.1:{}/sec", broker.port);
    let dir = tempfile::tempdir().expect("temp dir");
    let file = |name: &str, text: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, text).expect("writes");
        p.display().to_string()
    };

    // A wrong password from a file is refused as a wrong one in the URL is, and not shown.
    let wrong = file("wrong", "wrong-pass-from-file\n");
    let out = Command::new(env!("CARGO_BIN_EXE_llrp-gateway"))
        .args(["sim", "--no-http", "--listen", "127.0.0.1:0", "--publish"])
        .arg(url("gw"))
        .args(["--mqtt-password-file", &wrong])
        .stdin(Stdio::null())
        .output()
        .expect("runs");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains("refused the connection"), "{err}");
    assert!(!err.contains("wrong-pass"), "the password is shown: {err}");

    // The worker's password from a file, the simulator's from the environment.
    let worker_password = file("worker", "worker-pass\n");
    let (_w, http) = worker(&url("worker"), &["--mqtt-password-file", &worker_password]);
    let gw = url("gw");
    let sim_args = [
        "sim",
        "--no-http",
        "--listen",
        "127.0.0.1:0",
        "--speed",
        "20",
        "--publish",
        gw.as_str(),
    ];
    let mut sim =
        http_support::Proc::spawn_env(&sim_args, &[("LLRP_GATEWAY_MQTT_PASSWORD", "gw-pass")]);
    sim.address("listening on ");
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        let tags = request(http, "GET", "/api/tags", &[], b"").json();
        let located = tags["tags"]
            .as_array()
            .map(|t| t.iter().filter(|t| t["estimate"]["x"].is_number()).count())
            .unwrap_or(0);
        if located >= 1 {
            break;
        }
        assert!(Instant::now() < deadline, "nothing localized: {tags}");
        std::thread::sleep(Duration::from_millis(100));
    }
    let log = sim.stop_and_log();
    assert!(log.iter().all(|l| !l.contains("gw-pass")), "{log:#?}");
}
