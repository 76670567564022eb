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
