//! Every command says its error the one way (`llrp-gateway COMMAND: MESSAGE` on standard error)
//! and exits with status 1: the errors found at run time, after the arguments parsed (issue
//! 42: the process exits in one place, `cli::exit`).

use std::path::Path;
use std::process::Command;

/// Runs the binary with `args`; its exit code and standard error.
fn run(args: &[&str]) -> (Option<i32>, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_llrp-gateway"))
        .args(args)
        .output()
        .expect("runs");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// `args` fail with status 1, every line of standard error said as `command`'s, the last one
/// containing `says`.
fn fails_as(command: &str, args: &[&str], says: &str) {
    let (code, err) = run(args);
    assert_eq!(code, Some(1), "{args:?}: {err}");
    let prefix = format!("llrp-gateway {command}: ");
    assert!(err.starts_with(&prefix), "{args:?}: {err}");
    for line in err.lines() {
        assert!(line.starts_with(&prefix), "{args:?}: {line:?} in {err}");
    }
    let last = err.lines().last().unwrap_or_default();
    assert!(last.contains(says), "{args:?}: {says:?} not in {last:?}");
}

#[test]
fn each_command_says_its_run_time_error_as_llrp_gateway_command_message_and_exits_1() {
    let dir = tempfile::tempdir().expect("temp dir");
    let p = |name: &str| dir.path().join(name).display().to_string();
    let missing = p("missing.jsonl");
    let out = p("out.pcapng");
    let (config, rec) = (p("gw.json"), p("out.jsonl"));
    std::fs::write(&config, r#"{"proxies": []}"#).expect("writes");
    fails_as(
        "export",
        &["export", &missing, "--pcapng", &out],
        "missing.jsonl",
    );
    assert!(!Path::new(&out).exists(), "nothing written");
    fails_as(
        "import",
        &["import", &missing, "--output", &rec],
        "cannot read",
    );
    fails_as("replay", &["replay", &missing], "missing.jsonl");
    fails_as(
        "proxy",
        &["proxy", "--upstream", "reader.invalid", "--upstream-tls"],
        "--upstream-tls needs --upstream-ca",
    );
    fails_as(
        "proxy",
        &["proxy", "--config", &config],
        "proxies: no proxy given",
    );
    fails_as(
        "proxy",
        &[
            "proxy",
            "--upstream",
            "127.0.0.1:9",
            "--listen",
            "not-an-address",
        ],
        "cannot listen on not-an-address",
    );
    fails_as(
        "inventory",
        &["inventory", "127.0.0.1:9", "--output", "/dev/null"],
        "--format jsonl",
    );
    fails_as(
        "inventory",
        &["inventory", "127.0.0.1:9", "--tls"],
        "--tls needs --tls-ca",
    );
    fails_as(
        "bench localize",
        &["bench", "localize", "--scenario", &missing],
        "missing.jsonl",
    );
    fails_as(
        "bench realism",
        &["bench", "realism", "--scenario", &missing],
        "missing.jsonl",
    );
    fails_as(
        "bench readrate",
        &[
            "bench",
            "readrate",
            "--reader-model",
            "acme-9000",
            "--seconds",
            "0.1",
        ],
        "acme-9000",
    );
    fails_as("decode", &["decode", &missing], "cannot read input");
    fails_as("sim", &["sim", "--scenario", &missing], "missing.jsonl");
    fails_as(
        "localize",
        &["localize", &missing, "--output", &p("estimates.json")],
        "missing.jsonl",
    );
}

/// A secret's file that gives no secret (missing, empty) is an error naming its option and
/// the file; a password apart from a URL that names no user, or that has one already, too.
#[test]
fn a_secret_that_cannot_be_used_is_said_naming_its_option() {
    let dir = tempfile::tempdir().expect("temp dir");
    let file = |name: &str, text: Option<&str>| {
        let p = dir.path().join(name);
        if let Some(t) = text {
            std::fs::write(&p, t).expect("writes");
        }
        p.display().to_string()
    };
    let missing = file("missing", None);
    let empty = file("empty", Some("\n"));
    let password = file("password", Some("pw-SECRET\n"));
    let publish = |url: &str, file: &str| -> Vec<String> {
        let sim = [
            "sim",
            "--no-http",
            "--listen",
            "127.0.0.1:0",
            "--publish",
            url,
        ];
        let password = ["--mqtt-password-file", file];
        sim.iter().chain(&password).map(|s| s.to_string()).collect()
    };
    let worker = |extra: &[&str]| -> Vec<String> {
        let args = ["localize", "--subscribe", "mqtt://w@127.0.0.1:9"].iter();
        args.chain(extra).map(|s| s.to_string()).collect()
    };
    let cases: Vec<(&str, Vec<String>, String)> = vec![
        (
            "sim",
            vec!["sim".into(), "--http-token-file".into(), missing.clone()],
            format!("--http-token-file {missing}: cannot read it"),
        ),
        (
            "sim",
            publish("mqtt://gw@127.0.0.1:9", &empty),
            format!("--mqtt-password-file {empty}: it is empty"),
        ),
        (
            "sim",
            publish("mqtt://127.0.0.1:9", &password),
            "names no user".into(),
        ),
        (
            "sim",
            publish("mqtt://gw:inurl@127.0.0.1:9", &password),
            "both in the URL and apart from it".into(),
        ),
        (
            "localize",
            worker(&["--mqtt-password-file", &missing]),
            format!("--mqtt-password-file {missing}: cannot read it"),
        ),
        (
            "localize",
            worker(&["--http", "127.0.0.1:0", "--http-token-file", &empty]),
            format!("--http-token-file {empty}: it is empty"),
        ),
    ];
    for (command, args, says) in cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        fails_as(command, &args, &says);
        let (_, err) = run(&args);
        assert!(!err.contains("SECRET") && !err.contains("inurl"), "{err}");
    }
}
