//! LLRP over TLS: the simulated reader seen by OpenSSL's `s_client`, the crate's client with
//! the right CA, a wrong CA and `--tls-insecure`, the proxy with TLS on both sides (plaintext
//! compared byte for byte on either side of it), a failed upstream handshake, the `inventory`
//! and `sim` binaries, and clients that fail the handshake without disturbing the reader.
//!
//! Every certificate is made here with rcgen: a test CA, a server certificate it signs for
//! `localhost` and 127.0.0.1, and an unrelated CA.

mod common;

use std::io::{BufRead, BufReader, Read as _, Write as _};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use common::*;
use llrp::message::*;
use llrp::Message;
use llrp_gateway::net::client::{Client, ClientError, InventorySpec, ReadStream};
use llrp_gateway::net::proxy::{Proxy, ProxyConfig};
use llrp_gateway::net::stream::Stream;
use llrp_gateway::net::tls::{self, Acceptor, Connector, ServerFiles, Verify};
use llrp_gateway::record::{Entry, Event, Header, RecordOptions, Recorder, Recording};
use llrp_gateway::sim::{self, RunningSim, SimOptions};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::watch;
use tokio_rustls::rustls;

/// Longest any wait below may take (a hang guard, not a measurement).
const GUARD: Duration = Duration::from_secs(60);

/// The test's certificates, as PEM files in a temporary folder.
struct Pki {
    _dir: tempfile::TempDir,
    /// The CA that signed the server certificate.
    ca: PathBuf,
    /// A CA that signed nothing here.
    other_ca: PathBuf,
    /// The server certificate (for `localhost` and 127.0.0.1) and its key.
    cert: PathBuf,
    key: PathBuf,
}

impl Pki {
    fn new() -> Pki {
        let dir = tempfile::tempdir().expect("temp dir");
        let ca_cert = |name: &str| {
            let key = rcgen::KeyPair::generate().expect("CA key");
            let mut params = rcgen::CertificateParams::new(Vec::<String>::new()).expect("params");
            params.is_ca = rcgen::IsCa::Ca(rcgen::BasicConstraints::Unconstrained);
            params
                .distinguished_name
                .push(rcgen::DnType::CommonName, name);
            let cert = params.self_signed(&key).expect("CA certificate");
            (cert, key)
        };
        let (ca, ca_key) = ca_cert("llrp-gateway test CA");
        let (other, _) = ca_cert("some other CA");
        let key = rcgen::KeyPair::generate().expect("server key");
        let mut params =
            rcgen::CertificateParams::new(vec!["localhost".to_string(), "127.0.0.1".to_string()])
                .expect("params");
        params
            .distinguished_name
            .push(rcgen::DnType::CommonName, "simulated reader");
        let cert = params
            .signed_by(&key, &ca, &ca_key)
            .expect("server certificate");
        let write = |name: &str, text: String| {
            let p = dir.path().join(name);
            std::fs::write(&p, text).expect("write PEM");
            p
        };
        Pki {
            ca: write("ca.pem", ca.pem()),
            other_ca: write("other-ca.pem", other.pem()),
            cert: write("reader.pem", cert.pem()),
            key: write("reader.key", key.serialize_pem()),
            _dir: dir,
        }
    }

    fn server_files(&self) -> ServerFiles {
        ServerFiles {
            cert: self.cert.clone(),
            key: self.key.clone(),
        }
    }

    fn acceptor(&self) -> Acceptor {
        self.server_files().acceptor().expect("server TLS")
    }

    fn connector(&self) -> Connector {
        Connector::new(&Verify::Ca(self.ca.clone()), None).expect("client TLS")
    }
}

/// The embedded S1 over TLS on an ephemeral loopback port.
async fn tls_sim(pki: &Pki) -> RunningSim {
    sim::start(
        &s1(),
        &SimOptions {
            tls: Some(pki.server_files()),
            ..Default::default()
        },
    )
    .await
    .expect("the simulator starts with TLS")
}

/// Reads one LLRP frame from a blocking reader.
fn read_frame(r: &mut impl std::io::Read) -> std::io::Result<Vec<u8>> {
    let mut frame = vec![0u8; 10];
    r.read_exact(&mut frame)?;
    let len = u32::from_be_bytes([frame[2], frame[3], frame[4], frame[5]]) as usize;
    frame.resize(len.max(10), 0);
    r.read_exact(&mut frame[10..])?;
    Ok(frame)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn openssl_s_client_gets_the_success_greeting_from_the_simulated_reader_over_tls() {
    let pki = Pki::new();
    let sim = tls_sim(&pki).await;
    let port = sim.addrs[0].port();
    let ca = pki.ca.clone();
    let frame = tokio::task::spawn_blocking(move || {
        // OpenSSL verifies the chain against the test CA and stops on any error
        // (-verify_return_error); -quiet prints only the application data.
        let mut child = Command::new("openssl")
            .args([
                "s_client",
                "-connect",
                &format!("127.0.0.1:{port}"),
                "-quiet",
            ])
            .arg("-CAfile")
            .arg(&ca)
            .args(["-verify_return_error", "-verify_ip", "127.0.0.1"])
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("openssl runs (Debian package openssl)");
        let mut out = child.stdout.take().expect("piped");
        let got = read_frame(&mut out);
        let _ = child.kill();
        let _ = child.wait();
        let mut err = String::new();
        if let Some(mut e) = child.stderr.take() {
            let _ = e.read_to_string(&mut err);
        }
        (got, err)
    });
    let (got, err) = tokio::time::timeout(GUARD, frame)
        .await
        .expect("s_client answered in time")
        .expect("joined");
    let frame = got.unwrap_or_else(|e| panic!("no frame from s_client ({e}); stderr:\n{err}"));
    let m = Message::decode(&frame).expect("the bytes decode as LLRP");
    assert!(
        matches!(m.body, MessageBody::ReaderEventNotification(_)),
        "{m:?}"
    );
    assert_eq!(
        connection_status(&m),
        Some(ConnectionAttemptStatus::Success),
        "{m:?}"
    );
    sim.shutdown().await;
}

/// Runs a short inventory on `client` and returns its reads.
async fn inventory(client: Client) -> Vec<llrp_gateway::reads::Read> {
    let mut stream = ReadStream::start(client, &InventorySpec::default(), None, T)
        .await
        .expect("the inventory starts");
    let mut reads = Vec::new();
    let deadline = tokio::time::Instant::now() + GUARD;
    while reads.len() < 20 && tokio::time::Instant::now() < deadline {
        match stream.next(Duration::from_millis(500), &mut reads).await {
            Ok(()) | Err(ClientError::Timeout(_)) => {}
            Err(e) => panic!("the inventory broke off: {e}"),
        }
    }
    stream.finish(T, &mut reads).await.expect("a clean close");
    reads
}

#[tokio::test]
async fn the_client_inventories_the_simulated_reader_over_tls_trusting_the_ca() {
    let pki = Pki::new();
    let sim = tls_sim(&pki).await;
    let addr = sim.addrs[0].to_string();
    let client = Client::connect_reader_with(&addr, Some(&pki.connector()), T)
        .await
        .expect("TLS connection and greeting");
    let reads = inventory(client).await;
    assert!(reads.len() >= 20, "only {} reads", reads.len());
    assert!(reads.iter().all(|r| !r.epc.is_empty()));
    sim.shutdown().await;
}

#[tokio::test]
async fn a_reader_certificate_from_another_ca_is_refused_as_a_certificate_error() {
    let pki = Pki::new();
    let sim = tls_sim(&pki).await;
    let addr = sim.addrs[0].to_string();
    let wrong = Connector::new(&Verify::Ca(pki.other_ca.clone()), None).expect("client TLS");
    let e = match Client::connect_reader_with(&addr, Some(&wrong), T).await {
        Ok(_) => panic!("the handshake succeeded with the wrong CA"),
        Err(e) => e,
    };
    let ClientError::Tls(io) = &e else {
        panic!("not a TLS error: {e}");
    };
    assert!(
        matches!(
            tls::rustls_error(io),
            Some(rustls::Error::InvalidCertificate(
                rustls::CertificateError::UnknownIssuer
            ))
        ),
        "{e}"
    );
    assert!(tls::is_certificate_error(io), "{e}");
    assert!(!e.is_transient(), "a refused certificate is not retried");
    // A certificate for another name fails too, even from the right CA.
    let other_name =
        Connector::new(&Verify::Ca(pki.ca.clone()), Some("reader.example")).expect("client TLS");
    match Client::connect_reader_with(&addr, Some(&other_name), T).await {
        Err(ClientError::Tls(io)) => assert!(
            matches!(
                tls::rustls_error(&io),
                Some(rustls::Error::InvalidCertificate(_))
            ),
            "{io}"
        ),
        Err(e) => panic!("not a TLS error: {e}"),
        Ok(_) => panic!("the handshake succeeded for another name"),
    }
    sim.shutdown().await;
}

#[tokio::test]
async fn a_self_signed_reader_certificate_marked_as_a_ca_is_trusted_when_given_as_the_ca_file() {
    // As `openssl req -x509` makes them (basicConstraints CA:TRUE): WebPKI alone refuses such
    // a certificate as an end entity (CaUsedAsEndEntity); given itself, it is pinned.
    let dir = tempfile::tempdir().expect("temp dir");
    let key = rcgen::KeyPair::generate().expect("key");
    let mut params = rcgen::CertificateParams::new(vec!["127.0.0.1".to_string()]).expect("params");
    params.is_ca = rcgen::IsCa::Ca(rcgen::BasicConstraints::Unconstrained);
    let cert = params.self_signed(&key).expect("certificate");
    let (cert_path, key_path) = (dir.path().join("self.pem"), dir.path().join("self.key"));
    std::fs::write(&cert_path, cert.pem()).expect("write");
    std::fs::write(&key_path, key.serialize_pem()).expect("write");
    let sim = sim::start(
        &s1(),
        &SimOptions {
            tls: Some(ServerFiles {
                cert: cert_path.clone(),
                key: key_path,
            }),
            ..Default::default()
        },
    )
    .await
    .expect("starts");
    let pinned = Connector::new(&Verify::Ca(cert_path), None).expect("client TLS");
    let mut c = Client::connect_reader_with(&sim.addrs[0].to_string(), Some(&pinned), T)
        .await
        .expect("the pinned certificate is trusted");
    c.capabilities(T).await.expect("the session works");
    c.close_connection(T).await.expect("closed");
    // Another self-signed certificate is still refused.
    let other = Pki::new();
    let wrong = Connector::new(&Verify::Ca(other.cert.clone()), None).expect("client TLS");
    assert!(matches!(
        Client::connect_reader_with(&sim.addrs[0].to_string(), Some(&wrong), T).await,
        Err(ClientError::Tls(_))
    ));
    sim.shutdown().await;
}

#[tokio::test]
async fn tls_insecure_accepts_a_certificate_nobody_vouches_for() {
    let pki = Pki::new();
    let sim = tls_sim(&pki).await;
    let any = Connector::new(&Verify::Insecure, None).expect("client TLS");
    let mut c = Client::connect_reader_with(&sim.addrs[0].to_string(), Some(&any), T)
        .await
        .expect("any certificate is accepted");
    c.capabilities(T).await.expect("the session works");
    c.close_connection(T).await.expect("closed");
    sim.shutdown().await;
}

/// Plaintext one [`tls_relay`] passed, per direction.
#[derive(Default)]
struct Log {
    /// From the side that connected to the relay.
    forward: Mutex<Vec<u8>>,
    /// From the target back.
    back: Mutex<Vec<u8>>,
}

/// Copies `rd` to `wr` (each chunk flushed) into `log`, then closes `wr`.
async fn copy_logged(
    mut rd: impl tokio::io::AsyncRead + Unpin,
    mut wr: impl tokio::io::AsyncWrite + Unpin,
    log: Arc<Log>,
    forward: bool,
) {
    let mut buf = vec![0u8; 16384];
    loop {
        let n = rd.read(&mut buf).await.unwrap_or(0);
        if n == 0 || wr.write_all(&buf[..n]).await.is_err() || wr.flush().await.is_err() {
            let _ = wr.shutdown().await;
            return;
        }
        let side = if forward { &log.forward } else { &log.back };
        side.lock().expect("lock").extend_from_slice(&buf[..n]);
    }
}

/// A relay for one connection that logs the plaintext it passes: TLS or TCP towards the
/// side that connects (`accept`), TLS or TCP towards `target` (`connect`).
async fn tls_relay(
    target: SocketAddr,
    accept: Option<Acceptor>,
    connect: Option<Connector>,
) -> (SocketAddr, Arc<Log>, tokio::task::JoinHandle<()>) {
    let l = TcpListener::bind("127.0.0.1:0").await.expect("bind");
    let addr = l.local_addr().expect("bound");
    let log = Arc::new(Log::default());
    let log2 = Arc::clone(&log);
    let task = tokio::spawn(async move {
        let (a, _) = l.accept().await.expect("accept");
        let a = match accept {
            Some(acc) => Stream::from(acc.accept(a).await.expect("relay: TLS from its client")),
            None => Stream::from(a),
        };
        let b = TcpStream::connect(target).await.expect("connect target");
        let b = match connect {
            Some(c) => Stream::from(
                c.connect(&target.to_string(), b)
                    .await
                    .expect("relay: TLS to its target"),
            ),
            None => Stream::from(b),
        };
        let (ar, aw) = a.into_split();
        let (br, bw) = b.into_split();
        tokio::join!(
            copy_logged(ar, bw, Arc::clone(&log2), true),
            copy_logged(br, aw, log2, false)
        );
    });
    (addr, log, task)
}

/// A proxy in the test process; its stop sender, task and (if any) recording writer.
struct Running {
    addr: SocketAddr,
    stop: watch::Sender<bool>,
    task: tokio::task::JoinHandle<std::io::Result<()>>,
    recording: Option<llrp_gateway::record::RecorderTask>,
}

impl Running {
    async fn stop(self) {
        let _ = self.stop.send(true);
        self.task.await.expect("joined").expect("proxy ran");
        if let Some(r) = self.recording {
            r.await.expect("joined").expect("recording written");
        }
    }
}

async fn proxy(
    upstream: SocketAddr,
    tls: Option<Acceptor>,
    upstream_tls: Option<Connector>,
    record: Option<&Path>,
) -> Running {
    let (recorder, recording) = match record {
        Some(p) => {
            let (r, t) = Recorder::create(
                p,
                Header::new(upstream.to_string(), 0),
                RecordOptions::default(),
            )
            .expect("recording");
            (Some(r), Some(t))
        }
        None => (None, None),
    };
    let config = ProxyConfig {
        name: "tls".parse().expect("a reader name"),
        upstream: upstream.to_string(),
        listen: "127.0.0.1:0".into(),
        record: record.map(Path::to_owned),
        region: None,
        connect_timeout: Duration::from_secs(5),
        tls,
        upstream_tls,
    };
    let p = Proxy::bind(config, recorder, None).await.expect("binds");
    let addr = p.local_addr().expect("bound");
    let (stop, rx) = watch::channel(false);
    let task = tokio::spawn(p.run(rx));
    Running {
        addr,
        stop,
        task,
        recording,
    }
}

#[tokio::test]
async fn the_proxy_forwards_the_plaintext_byte_for_byte_with_tls_on_both_sides() {
    let pki = Pki::new();
    let sim = start(&s1(), llrp_gateway::net::clock::Speed::Factor(1.0)).await;
    // client ─TCP─ relay A ─TLS─ proxy ─TLS─ relay B ─TCP─ simulated reader. A logs the
    // plaintext on the client's side of the proxy, B on the reader's side; both of the
    // proxy's sides are TLS.
    let (b_addr, b_log, b_task) = tls_relay(sim.addrs[0], Some(pki.acceptor()), None).await;
    let p = proxy(b_addr, Some(pki.acceptor()), Some(pki.connector()), None).await;
    let (a_addr, a_log, a_task) = tls_relay(p.addr, None, Some(pki.connector())).await;

    let mut c = Client::connect(a_addr).await.expect("connects");
    let greeting = c.recv(T).await.expect("greeting");
    assert_eq!(
        connection_status(&greeting),
        Some(ConnectionAttemptStatus::Success)
    );
    c.transact(GetReaderCapabilities::default(), T)
        .await
        .expect("capabilities");
    // A frame the codec cannot decode goes through unchanged as well.
    let mut bad = Message::new(77, GetReaderConfig::default())
        .to_bytes()
        .to_vec();
    bad.extend_from_slice(&[0xde, 0xad]);
    let len = bad.len() as u32;
    bad[2..6].copy_from_slice(&len.to_be_bytes());
    c.send_raw(&bad).await.expect("send");
    c.recv(T).await.expect("an answer to the bad frame");
    let spec = rospec(
        1,
        vec![0],
        ro_null(),
        ai_null(),
        full_report(RoReportTriggerType::UponNTagsOrEndOfAiSpec, 1),
    );
    assert_eq!(
        request_status(
            &mut c,
            AddRospec {
                ro_spec: spec,
                ..Default::default()
            }
        )
        .await,
        StatusCode::M_Success
    );
    assert_eq!(
        request_status(
            &mut c,
            EnableRospec {
                ro_spec_id: 1,
                ..Default::default()
            }
        )
        .await,
        StatusCode::M_Success
    );
    let (tags, _) = collect_reports(&mut c, GUARD, |t| t.len() >= 50).await;
    assert!(tags.len() >= 50, "only {} reads", tags.len());
    c.request(CloseConnection::default(), T)
        .await
        .expect("close response");
    c.until_closed(T).await.expect("closed");
    drop(c);
    tokio::time::timeout(GUARD, a_task)
        .await
        .expect("relay A ends")
        .expect("relay A");
    tokio::time::timeout(GUARD, b_task)
        .await
        .expect("relay B ends")
        .expect("relay B");
    p.stop().await;
    sim.shutdown().await;

    let a_fwd = a_log.forward.lock().expect("lock").clone();
    let a_back = a_log.back.lock().expect("lock").clone();
    let b_fwd = b_log.forward.lock().expect("lock").clone();
    let b_back = b_log.back.lock().expect("lock").clone();
    assert!(a_fwd.windows(bad.len()).any(|w| w == bad.as_slice()));
    assert!(a_back.len() > 50 * 10, "{} bytes back", a_back.len());
    assert_eq!(a_fwd, b_fwd, "the reader got exactly what the client sent");
    assert_eq!(
        a_back, b_back,
        "the client got exactly what the reader sent"
    );
}

#[tokio::test]
async fn a_failed_upstream_tls_handshake_gets_the_client_a_failed_connection_attempt() {
    let pki = Pki::new();
    let sim = tls_sim(&pki).await;
    let wrong = Connector::new(&Verify::Ca(pki.other_ca.clone()), None).expect("client TLS");
    let dir = tempfile::tempdir().expect("temp dir");
    let rec = dir.path().join("rec.jsonl");
    let p = proxy(sim.addrs[0], None, Some(wrong), Some(&rec)).await;
    let mut c = Client::connect(p.addr).await.expect("the proxy accepts");
    let m = c.recv(T).await.expect("a notification");
    assert_eq!(
        connection_status(&m),
        Some(ConnectionAttemptStatus::FailedOtherReason),
        "{m:?}"
    );
    c.until_closed(T).await.expect("then closed");
    // The reader is not held: a client trusting the right CA gets it at once.
    let mut ok = Client::connect_reader_with(&sim.addrs[0].to_string(), Some(&pki.connector()), T)
        .await
        .expect("the reader is free");
    ok.capabilities(T).await.expect("works");
    p.stop().await;
    sim.shutdown().await;
    let r = Recording::open(&rec).expect("reads");
    let reasons: Vec<String> = r
        .entries
        .iter()
        .filter_map(|e| match e {
            Entry::Marker {
                event: Event::Disconnect,
                reason,
                ..
            } => Some(reason.clone()),
            _ => None,
        })
        .collect();
    assert_eq!(reasons.len(), 1, "{reasons:?}");
    assert!(
        reasons[0].contains("TLS handshake failed") && reasons[0].contains("UnknownIssuer"),
        "{reasons:?}"
    );
}

#[tokio::test]
async fn clients_that_fail_the_handshake_do_not_stop_the_reader_serving_the_next() {
    let pki = Pki::new();
    let sim = tls_sim(&pki).await;
    let addr = sim.addrs[0];
    // One client connects and says nothing; it holds a handshake open throughout.
    let silent = TcpStream::connect(addr).await.expect("connect");
    // One speaks plain LLRP to the TLS port: its handshake fails and it is closed.
    let mut plain = TcpStream::connect(addr).await.expect("connect");
    plain
        .write_all(&Message::new(1, GetReaderCapabilities::default()).to_bytes())
        .await
        .expect("send");
    let mut got = Vec::new();
    let read = tokio::time::timeout(GUARD, plain.read_to_end(&mut got))
        .await
        .expect("the reader closes the plain client");
    // A TLS alert at most (or a reset), never an LLRP greeting.
    assert!(
        read.is_err() || got.first() != Some(&0x04),
        "plain bytes answered in plain LLRP: {got:02x?}"
    );
    // One refuses the reader's certificate.
    let wrong = Connector::new(&Verify::Ca(pki.other_ca.clone()), None).expect("client TLS");
    assert!(matches!(
        Client::connect_reader_with(&addr.to_string(), Some(&wrong), T).await,
        Err(ClientError::Tls(_))
    ));
    // The next TLS client is served as if nothing had happened, while the silent one waits.
    let mut c = Client::connect_reader_with(&addr.to_string(), Some(&pki.connector()), T)
        .await
        .expect("greeting Success");
    c.capabilities(T).await.expect("the session works");
    c.close_connection(T).await.expect("closed");
    drop(silent);
    sim.shutdown().await;
}

/// A child process whose standard error is collected line by line.
struct Proc {
    child: std::process::Child,
    lines: std::sync::mpsc::Receiver<String>,
}

impl Proc {
    fn spawn(mut cmd: Command) -> Proc {
        let mut child = cmd
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("starts");
        let err = child.stderr.take().expect("piped");
        let (tx, lines) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(err).lines() {
                let Ok(line) = line else { return };
                if tx.send(line).is_err() {
                    return;
                }
            }
        });
        Proc { child, lines }
    }

    /// The first line holding `pattern` (within [`GUARD`]).
    fn wait_line(&self, pattern: &str) -> String {
        let until = std::time::Instant::now() + GUARD;
        loop {
            let left = until.saturating_duration_since(std::time::Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(l) if l.contains(pattern) => return l,
                Ok(_) => {}
                Err(e) => panic!("no line with {pattern:?}: {e}"),
            }
        }
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_llrp-gateway"))
}

#[test]
fn the_inventory_binary_reads_over_tls_from_the_sim_binary() {
    let pki = Pki::new();
    let mut cmd = bin();
    cmd.args(["sim", "--no-http", "--listen", "127.0.0.1:0", "--tls-cert"])
        .arg(&pki.cert)
        .arg("--tls-key")
        .arg(&pki.key);
    let sim = Proc::spawn(cmd);
    let line = sim.wait_line("listening on");
    assert!(line.ends_with("(TLS)"), "{line}");
    let addr = line
        .split("listening on ")
        .nth(1)
        .and_then(|rest| rest.split_whitespace().next())
        .expect("an address")
        .to_string();
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("reads.jsonl");
    let run = bin()
        .args(["inventory", &addr, "--seconds", "2", "--tls", "--tls-ca"])
        .arg(&pki.ca)
        .arg("--output")
        .arg(&out)
        .output()
        .expect("inventory runs");
    let log = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{log}");
    assert!(log.contains("over TLS, inventory started"), "{log}");
    let f = std::fs::File::open(&out).expect("the reads file");
    let reads = llrp_gateway::reads::read_jsonl(BufReader::new(f)).expect("reads");
    assert!(!reads.is_empty(), "no reads; log:\n{log}");

    // Without a trust choice, and with a CA file that is not PEM: refused, and said why.
    let run = bin()
        .args(["inventory", &addr, "--seconds", "1", "--tls"])
        .output()
        .expect("inventory runs");
    let log = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success());
    assert!(
        log.contains("--tls-ca") && log.contains("--tls-insecure"),
        "{log}"
    );
    let bad = dir.path().join("bad-ca.pem");
    std::fs::File::create(&bad)
        .and_then(|mut f| f.write_all(b"-----BEGIN CERTIFICATE-----\nnot base64!\n"))
        .expect("write");
    let run = bin()
        .args(["inventory", &addr, "--seconds", "1", "--tls", "--tls-ca"])
        .arg(&bad)
        .output()
        .expect("inventory runs");
    let log = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success());
    assert!(log.contains("bad-ca.pem") && log.contains("PEM"), "{log}");
}

#[tokio::test]
async fn a_recording_replays_over_tls() {
    use llrp_gateway::record::replay::{ReplayOptions, Script};
    use llrp_gateway::record::Recording;
    let pki = Pki::new();
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fixtures/sessions/dock-door-inventory.jsonl");
    let recording = Recording::open(&path).expect("fixture");
    let script = std::sync::Arc::new(Script::new(&recording, None).expect("script"));
    let l = tokio::net::TcpListener::bind("127.0.0.1:0")
        .await
        .expect("bind");
    let addr = l.local_addr().expect("bound").to_string();
    let (stop, rx) = tokio::sync::watch::channel(false);
    let options = ReplayOptions {
        speed: None,
        looped: false,
    };
    tokio::spawn(llrp_gateway::net::replay::serve(
        l,
        script,
        options,
        Some(pki.acceptor()),
        rx,
    ));
    // A plain TCP client that never starts a handshake stays connected meanwhile: it must
    // not keep the TLS client out (a replay serves one client at a time).
    let plain = Client::connect(&addr).await.expect("TCP");
    let client = Client::connect_reader_with(&addr, Some(&pki.connector()), T)
        .await
        .expect("TLS connection and the recorded greeting");
    let reads = inventory(client).await;
    assert!(reads.len() >= 20, "only {} reads", reads.len());
    drop(plain);
    let _ = stop.send(true);
}

/// A TLS client that drops in the middle of a TLS record (a record header promising bytes
/// that never come, then the end of the stream, no close_notify) hands the reader back as any
/// other leaving does: shown not connected, and the reader's own inventory resumes.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_tls_client_dropping_mid_record_hands_the_reader_back_to_its_own_inventory() {
    use llrp_gateway::localize::live::{Live, Settings};
    use llrp_gateway::localize::shared::Shared;
    use llrp_gateway::sim::{feed, LocalizeFeed, PoseSource};

    let pki = Pki::new();
    let scenario = s1();
    let live = Live::start(feed::settings(&scenario, Settings::default())).expect("starts");
    let sim = sim::start(
        &scenario,
        &SimOptions {
            tls: Some(pki.server_files()),
            speed: llrp_gateway::net::clock::Speed::Factor(4.0),
            localize: Some(LocalizeFeed {
                tap: live.tap.clone(),
                poses: PoseSource::Estimated,
                pose_interval_us: feed::POSE_INTERVAL_US,
                read_poses: true,
            }),
            ..Default::default()
        },
    )
    .await
    .expect("starts");
    let shared = live.shared.clone();
    let until = |pred: &dyn Fn(&Shared) -> bool| {
        let deadline = std::time::Instant::now() + GUARD;
        loop {
            if pred(&shared) {
                return true;
            }
            if std::time::Instant::now() > deadline {
                return false;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    };
    let own = |s: &Shared, more_than: u64| {
        s.readers()
            .first()
            .is_some_and(|r| !r.connected && r.inventory == "self" && r.reads > more_than)
    };
    assert!(until(&|s| own(s, 0)), "{:?}", shared.readers());
    let addr = sim.addrs[0].to_string();
    let tcp = TcpStream::connect(&addr).await.expect("connects");
    let mut tls = pki
        .connector()
        .connect(&addr, tcp)
        .await
        .expect("handshake");
    let mut greeting = [0u8; 10];
    tls.read_exact(&mut greeting).await.expect("the greeting");
    assert!(
        until(&|s| s.readers().first().is_some_and(|r| r.connected)),
        "{:?}",
        shared.readers()
    );
    // Application data promising 64 bytes, three of them sent, then the end of the stream.
    let (mut raw, _) = tls.into_inner();
    raw.write_all(&[0x17, 0x03, 0x03, 0x00, 0x40, 1, 2, 3])
        .await
        .expect("writes");
    drop(raw);
    let before = shared.readers()[0].reads;
    assert!(
        until(&|s| own(s, before)),
        "the reader was not handed back: {:?}",
        shared.readers()
    );
    sim.shutdown().await;
    live.stop();
}
