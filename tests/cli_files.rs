//! The rule for every file a command writes (docs/recordings.md, "Files a command writes"):
//! an input is never written, an existing file is replaced only with `--force`, and a failure
//! leaves nothing behind; `import` of a capture it cannot read says so and fails; `localize`
//! refuses a read without a hex EPC.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_llrp-gateway"))
}

fn run(args: &[&Path]) -> (Output, String) {
    let out = bin().args(args).output().expect("runs");
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    (out, err)
}

fn p(s: &str) -> &Path {
    Path::new(s)
}

/// A copy of a shipped recording in a fresh directory.
fn recording() -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().expect("temp dir");
    let rec = dir.path().join("session.jsonl");
    std::fs::copy(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/sessions/s1-sllurp-impinj.jsonl"),
        &rec,
    )
    .expect("copies");
    (dir, rec)
}

/// The names in `dir`, sorted.
fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .expect("dir")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

#[test]
fn export_onto_its_own_recording_is_refused_and_the_recording_kept() {
    let (dir, rec) = recording();
    let before = std::fs::read(&rec).expect("reads");
    // By the same name, and by another name for the same file.
    let alias = dir.path().join(".").join("session.jsonl");
    for out in [&rec, &alias] {
        for (force, flag) in [(false, "--pcapng"), (true, "--pcapng"), (false, "--mcap")] {
            let mut args = vec![p("export"), &rec, p(flag), out];
            if force {
                args.push(p("--force"));
            }
            let (o, err) = run(&args);
            assert!(!o.status.success(), "{err}");
            assert!(err.contains("this is the input"), "{err}");
        }
    }
    assert_eq!(
        std::fs::read(&rec).expect("reads"),
        before,
        "the recording is intact"
    );
    assert_eq!(names(dir.path()), ["session.jsonl"]);
}

#[test]
fn import_and_export_refuse_an_existing_file_without_force_and_replace_it_with_force() {
    let (dir, rec) = recording();
    let cap = dir.path().join("session.pcapng");
    let (o, err) = run(&[p("export"), &rec, p("--pcapng"), &cap]);
    assert!(o.status.success(), "{err}");
    let existing = dir.path().join("existing.jsonl");
    std::fs::write(&existing, "keep me\n").expect("writes");
    for (cmd, input, flag) in [
        ("import", &cap, "--output"),
        ("export", &rec, "--pcapng"),
        ("export", &rec, "--mcap"),
    ] {
        let (o, err) = run(&[p(cmd), input, p(flag), &existing]);
        assert!(!o.status.success(), "{cmd}: {err}");
        assert!(
            err.contains("exists") && err.contains("--force"),
            "{cmd}: {err}"
        );
        assert_eq!(
            std::fs::read_to_string(&existing).expect("reads"),
            "keep me\n"
        );
    }
    let (o, err) = run(&[p("import"), &cap, p("--output"), &existing, p("--force")]);
    assert!(o.status.success(), "{err}");
    let text = std::fs::read_to_string(&existing).expect("reads");
    assert!(text.starts_with("{\"llrp_recording\""), "{text:.80}");
    assert_eq!(
        names(dir.path()),
        ["existing.jsonl", "session.jsonl", "session.pcapng"],
        "no temporary file is left"
    );
}

/// A classic pcap (microseconds, Ethernet) whose one packet header declares `incl_len` bytes
/// and is followed by 64 bytes.
fn absurd_pcap(incl_len: u32) -> Vec<u8> {
    let mut b = Vec::new();
    b.extend_from_slice(&0xa1b2_c3d4u32.to_le_bytes());
    b.extend_from_slice(&2u16.to_le_bytes());
    b.extend_from_slice(&4u16.to_le_bytes());
    b.extend_from_slice(&0i32.to_le_bytes());
    b.extend_from_slice(&0u32.to_le_bytes());
    b.extend_from_slice(&65_535u32.to_le_bytes());
    b.extend_from_slice(&1u32.to_le_bytes());
    b.extend_from_slice(&1_700_000_000u32.to_le_bytes());
    b.extend_from_slice(&0u32.to_le_bytes());
    b.extend_from_slice(&incl_len.to_le_bytes());
    b.extend_from_slice(&incl_len.to_le_bytes());
    b.extend_from_slice(&[0u8; 64]);
    b
}

#[test]
fn a_capture_whose_packet_length_is_absurd_is_reported_and_import_fails_writing_nothing() {
    let dir = tempfile::tempdir().expect("temp dir");
    for incl_len in [u32::MAX, 100_000_000] {
        let cap = dir.path().join("absurd.pcap");
        std::fs::write(&cap, absurd_pcap(incl_len)).expect("writes");
        let out = dir.path().join("out.jsonl");
        let (o, err) = run(&[p("import"), &cap, p("--output"), &out]);
        assert!(
            !o.status.success(),
            "{incl_len}: exit 0 with nothing read: {err}"
        );
        assert!(err.contains("inside a packet"), "what was not read: {err}");
        assert!(!out.exists(), "nothing written");
        assert_eq!(
            names(dir.path()),
            ["absurd.pcap"],
            "no temporary file is left"
        );
    }
}

#[test]
fn localize_refuses_a_read_with_an_empty_or_non_hex_epc_by_line() {
    let dir = tempfile::tempdir().expect("temp dir");
    let good = r#"{"epc":"3034F8","antenna":1,"t_us":1000,"phase_rad":1.0,"rssi_dbm":-50.0}"#;
    for (epc, why) in [("", "empty"), ("not-hex", "no hex digit")] {
        let reads = dir.path().join("reads.jsonl");
        std::fs::write(&reads, format!("{good}\n{}\n", good.replace("3034F8", epc)))
            .expect("writes");
        let out = dir.path().join("estimates.json");
        let (o, err) = run(&[p("localize"), &reads, p("--output"), &out]);
        assert!(!o.status.success(), "{err}");
        assert!(
            err.contains("line 2") && err.contains("epc") && err.contains(why),
            "{err}"
        );
        assert!(!out.exists());
    }
}

#[test]
fn sim_refuses_an_existing_truth_file_without_force() {
    let dir = tempfile::tempdir().expect("temp dir");
    let truth = dir.path().join("truth.jsonl");
    std::fs::write(&truth, "earlier truth\n").expect("writes");
    let (o, err) = run(&[
        p("sim"),
        p("--no-http"),
        p("--listen"),
        p("127.0.0.1:0"),
        p("--truth"),
        &truth,
    ]);
    assert!(!o.status.success(), "{err}");
    assert!(err.contains("exists") && err.contains("--force"), "{err}");
    assert_eq!(
        std::fs::read_to_string(&truth).expect("reads"),
        "earlier truth\n"
    );
}
