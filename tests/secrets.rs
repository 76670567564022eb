//! Secrets off the command line (issue 47): the HTTP API's bearer token and the MQTT broker's
//! password may come from an environment variable or a file instead of an argument, which
//! every local user sees in the process list; with any of the three the API is guarded alike;
//! and no secret shows in a log line, the API's output or the process's arguments.

mod http_support;

use std::net::SocketAddr;

use http_support::{post_poses, request, Proc};

const TOKEN_ENV: &str = "LLRP_GATEWAY_HTTP_TOKEN";
const PASSWORD_ENV: &str = "LLRP_GATEWAY_MQTT_PASSWORD";

/// `sim` with its LLRP listener and HTTP API on free loopback ports, `extra` options and
/// `env`; the child and the API's address.
fn sim(extra: &[&str], env: &[(&str, &str)]) -> (Proc, SocketAddr) {
    let mut args = vec!["sim", "--listen", "127.0.0.1:0", "--http", "127.0.0.1:0"];
    args.extend_from_slice(extra);
    let mut p = Proc::spawn_env(&args, env);
    let http = p
        .address("live map on http://")
        .parse()
        .expect("an HTTP address");
    (p, http)
}

/// A write without the token is refused; with `token` it passes the token check (an empty
/// pose array is then judged on its body: 400); with another token it is refused.
fn guarded_by(http: SocketAddr, token: &str) {
    let without = post_poses(http, &[], b"[]");
    assert_eq!(without.status, 401, "{}", without.text());
    let bearer = format!("Bearer {token}");
    let with = post_poses(http, &[("Authorization", &bearer)], b"[]");
    assert_eq!(with.status, 400, "past the token check: {}", with.text());
    let wrong = post_poses(http, &[("Authorization", "Bearer not-it")], b"[]");
    assert_eq!(wrong.status, 401, "{}", wrong.text());
}

/// One way to give the token: (arguments, environment, the token).
type Way<'a> = (&'a [&'a str], &'a [(&'a str, &'a str)], &'a str);

#[test]
fn the_token_from_the_environment_or_a_file_guards_the_api_as_the_flag_does() {
    let dir = tempfile::tempdir().expect("temp dir");
    let file = dir.path().join("token");
    // As `echo TOKEN > FILE` writes it: the line end is not part of the token.
    std::fs::write(&file, "from-a-file\n").expect("writes");
    let file = file.display().to_string();
    let ways: [Way; 3] = [
        (&["--http-token", "from-the-flag"], &[], "from-the-flag"),
        (&[], &[(TOKEN_ENV, "from-the-env")], "from-the-env"),
        (&["--http-token-file", file.as_str()], &[], "from-a-file"),
    ];
    for (args, env, token) in ways {
        let (mut p, http) = sim(args, env);
        guarded_by(http, token);
        p.stop();
    }
}

#[test]
fn secrets_show_in_no_log_line_api_output_or_process_arguments() {
    let (token, password) = ("tok-SECRET-7f3a", "pw-SECRET-91c2");
    let dir = tempfile::tempdir().expect("temp dir");
    let password_file = dir.path().join("password");
    std::fs::write(&password_file, format!("{password}\n")).expect("writes");
    // A broker that is not there: the publisher logs its address while it retries.
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port")
        .port();
    let url = format!("mqtt://gw@127.0.0.1:{port}/site");
    let env = [
        (TOKEN_ENV, token),
        (PASSWORD_ENV, password),
        ("RUST_LOG", "debug"),
    ];
    let (mut p, http) = sim(&["--publish", url.as_str()], &env);
    guarded_by(http, token);
    let bearer = format!("Bearer {token}");
    for path in [
        "/api/tags",
        "/api/readers",
        "/api/truth",
        "/api/openapi.json",
        "/metrics",
        "/healthz",
    ] {
        let r = request(http, "GET", path, &[("Authorization", &bearer)], b"");
        let text = r.text();
        assert!(!text.contains("SECRET"), "{path}: {text}");
    }
    let cmdline = std::fs::read(format!("/proc/{}/cmdline", p.pid())).expect("cmdline");
    assert!(!String::from_utf8_lossy(&cmdline).contains("SECRET"));
    // The MQTT worker too, its secrets from files.
    let token_file = dir.path().join("token");
    std::fs::write(&token_file, token).expect("writes");
    let tf = token_file.display().to_string();
    let pf = password_file.display().to_string();
    let worker_args = [
        "localize",
        "--subscribe",
        url.as_str(),
        "--mqtt-password-file",
        pf.as_str(),
        "--http",
        "127.0.0.1:0",
        "--http-token-file",
        tf.as_str(),
    ];
    let mut w = Proc::spawn_env(&worker_args, &[("RUST_LOG", "debug")]);
    let worker_http = w
        .address("live map on http://")
        .parse()
        .expect("an HTTP address");
    guarded_by(worker_http, token);
    let sim_log = p.stop_and_log();
    let worker_log = w.stop_and_log();
    for line in sim_log.iter().chain(&worker_log) {
        assert!(!line.contains("SECRET"), "a secret in the log: {line}");
    }
    // The logs did name the broker, the password hidden.
    let shown = format!("mqtt://gw:***@127.0.0.1:{port}/site");
    assert!(sim_log.iter().any(|l| l.contains(&shown)), "{sim_log:#?}");
    assert!(
        worker_log.iter().any(|l| l.contains(&shown)),
        "{worker_log:#?}"
    );
}

#[test]
fn help_names_the_variables_but_not_their_values_and_an_empty_one_is_refused() {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_llrp-gateway"))
        .args(["sim", "--help"])
        .env(TOKEN_ENV, "tok-SECRET-help")
        .env(PASSWORD_ENV, "pw-SECRET-help")
        .output()
        .expect("runs");
    let help = String::from_utf8_lossy(&out.stdout);
    assert!(
        help.contains(TOKEN_ENV) && help.contains(PASSWORD_ENV),
        "{help}"
    );
    assert!(!help.contains("SECRET"), "{help}");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_llrp-gateway"))
        .args(["sim", "--listen", "127.0.0.1:0", "--http", "127.0.0.1:0"])
        .env(TOKEN_ENV, "")
        .output()
        .expect("runs");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("--http-token") && err.contains("must not be empty"),
        "{err}"
    );
}
