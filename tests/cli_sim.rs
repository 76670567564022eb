//! `llrp-gateway sim` from the command line: bad input gets a clear one-line error.

use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_llrp-gateway"))
}

#[test]
fn a_bad_scenario_file_names_the_field_and_the_reason() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("bad.json");
    let mut s: serde_json::Value =
        serde_json::from_str(include_str!("../fixtures/scenarios/s1.json")).expect("s1 parses");
    s["readers"][0]["antennas"][0]["beamwidth_deg"] = serde_json::json!(-5);
    std::fs::write(&path, s.to_string()).expect("write");
    let out = bin()
        .args(["sim", "--scenario"])
        .arg(&path)
        .output()
        .expect("runs");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("readers[0].antennas[0].beamwidth_deg"),
        "error names the field: {err}"
    );
    assert!(err.contains("-5"), "error gives the value: {err}");
}

#[test]
fn a_bad_speed_is_refused() {
    let out = bin()
        .args(["sim", "--speed", "fast"])
        .output()
        .expect("runs");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("positive number or `max`"), "{err}");
}

#[test]
fn an_unusable_listen_address_is_reported() {
    let out = bin()
        .args(["sim", "--listen", "256.0.0.1:5084"])
        .output()
        .expect("runs");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("cannot listen on 256.0.0.1:5084"), "{err}");
}

/// A client's malformed requests get LLRP answers, the connection carries on, and nothing is
/// logged at error level for them (the log is the binary's stderr at its default level).
#[test]
fn a_clients_mistakes_are_answered_and_not_logged_as_errors() {
    use std::io::{BufRead, BufReader, Read, Write};
    use std::net::TcpStream;
    use std::process::Stdio;
    use std::time::Duration;

    let mut child = bin()
        .args(["sim", "--listen", "127.0.0.1:0", "--speed", "max"])
        .stderr(Stdio::piped())
        .stdout(Stdio::null())
        .spawn()
        .expect("runs");
    let stderr = child.stderr.take().expect("piped");
    let (addr_tx, addr_rx) = std::sync::mpsc::channel();
    let log = std::thread::spawn(move || {
        let mut all = String::new();
        for line in BufReader::new(stderr).lines() {
            let line = line.unwrap_or_default();
            if let Some(at) = line.find("listening on ") {
                let _ = addr_tx.send(line[at + "listening on ".len()..].trim().to_string());
            }
            all.push_str(&line);
            all.push('\n');
        }
        all
    });
    let addr = addr_rx
        .recv_timeout(Duration::from_secs(20))
        .expect("the simulator listens");
    let mut s = TcpStream::connect(&addr).expect("connects");
    s.set_read_timeout(Some(Duration::from_secs(10)))
        .expect("timeout");
    // Header: version 1 (or `ver`), type, length, message ID.
    let frame = |ver: u16, ty: u16, id: u32, body: &[u8]| {
        let mut f = Vec::new();
        f.extend_from_slice(&((ver << 10) | ty).to_be_bytes());
        f.extend_from_slice(&(10 + body.len() as u32).to_be_bytes());
        f.extend_from_slice(&id.to_be_bytes());
        f.extend_from_slice(body);
        f
    };
    // An unknown message type, an unsupported version, a truncated GET_READER_CONFIG, then a
    // good GET_READER_CAPABILITIES.
    for f in [
        frame(1, 999, 1, &[]),
        frame(3, 1, 2, &[0]),
        frame(1, 2, 3, &[0, 0]),
        frame(1, 1, 4, &[0]),
    ] {
        s.write_all(&f).expect("send");
    }
    let mut answered = Vec::new();
    while !answered.iter().any(|&(ty, id)| (ty, id) == (11, 4)) {
        let mut h = [0u8; 10];
        s.read_exact(&mut h).expect("a message from the reader");
        let ty = u16::from_be_bytes([h[0], h[1]]) & 0x3FF;
        let len = u32::from_be_bytes([h[2], h[3], h[4], h[5]]) as usize;
        let id = u32::from_be_bytes([h[6], h[7], h[8], h[9]]);
        let mut body = vec![0u8; len.saturating_sub(10)];
        s.read_exact(&mut body).expect("its body");
        answered.push((ty, id));
    }
    // ERROR_MESSAGE (100) for the unknown type and the bad version, the response type (12)
    // for the truncated request.
    for want in [(100, 1), (100, 2), (12, 3)] {
        assert!(answered.contains(&want), "{want:?} not in {answered:?}");
    }
    drop(s);
    std::thread::sleep(Duration::from_millis(200));
    let _ = child.kill();
    let _ = child.wait();
    let log = log.join().expect("log reader");
    assert!(log.contains("listening on"), "{log}");
    assert!(
        !log.contains("ERROR"),
        "a client's mistake logged as an error:\n{log}"
    );
}
