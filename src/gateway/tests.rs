//! Unit tests of the gateway's commands.

use super::*;

#[test]
fn a_host_without_a_port_gets_the_llrp_port() {
    assert_eq!(with_default_port("reader.local"), "reader.local:5084");
    assert_eq!(with_default_port("10.0.0.5:5085"), "10.0.0.5:5085");
    assert_eq!(with_default_port("[::1]:6000"), "[::1]:6000");
    assert_eq!(with_default_port("::1"), "[::1]:5084");
}

fn load(text: &str) -> Result<GatewayConfig, ConfigError> {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("gw.json");
    std::fs::write(&path, text).expect("write");
    GatewayConfig::load(&path)
}

#[test]
fn a_config_names_the_bad_field() {
    let e =
        load(r#"{"proxies":[{"name":"a","upstream":"x","listen":"127.0.0.1:1","recrod":"r"}]}"#)
            .expect_err("typo");
    assert!(e.to_string().contains("proxies[0]"), "{e}");
    assert!(e.to_string().contains("recrod"), "{e}");
    let e = load(
        r#"{"proxies":[{"name":"a","upstream":"x","listen":"l1"},{"name":"a","upstream":"y","listen":"l2"}]}"#,
    )
    .expect_err("same name");
    assert!(e.to_string().contains("proxies[1].name"), "{e}");
    let e = load(r#"{"proxies":[]}"#).expect_err("none");
    assert!(e.to_string().contains("no proxy"), "{e}");
    let e = load(r#"{"proxies":[{"name":"a ","upstream":"x","listen":"l1"}]}"#)
        .expect_err("a name ending in a space");
    assert!(
        e.to_string()
            .contains("proxies[0].name: reader name \"a \" starts or ends with white space"),
        "{e}"
    );
}

#[test]
fn relative_record_paths_are_beside_the_config() {
    let c = load(r#"{"proxies":[{"name":"a","upstream":"x","listen":"l","record":"a.jsonl","region":"etsi"}]}"#)
        .expect("valid");
    let r = c.proxies[0].record.as_ref().expect("record");
    assert!(r.is_absolute() && r.ends_with("a.jsonl"), "{}", r.display());
    assert_eq!(c.proxies[0].region, Some(Region::Etsi));
}

#[test]
fn tls_settings_are_checked_together_and_their_paths_are_beside_the_config() {
    let c = load(
        r#"{"proxies":[{"name":"a","upstream":"x","listen":"l","tls_cert":"c.pem","tls_key":"k.pem","upstream_tls":true,"upstream_ca":"ca.pem"}]}"#,
    )
    .expect("valid");
    let p = &c.proxies[0];
    for f in [&p.tls_cert, &p.tls_key, &p.upstream_ca] {
        let f = f.as_ref().expect("set");
        assert!(f.is_absolute(), "{}", f.display());
    }
    assert!(p.upstream_tls && !p.upstream_insecure);
    for (text, field) in [
        (r#""tls_cert":"c.pem""#, "proxies[0].tls_key"),
        (r#""tls_key":"k.pem""#, "proxies[0].tls_cert"),
        (r#""upstream_tls":true"#, "proxies[0].upstream_tls"),
        (r#""upstream_ca":"ca.pem""#, "proxies[0].upstream_ca"),
        (
            r#""upstream_insecure":true"#,
            "proxies[0].upstream_insecure",
        ),
        (
            r#""upstream_tls":true,"upstream_ca":"ca.pem","upstream_insecure":true"#,
            "proxies[0].upstream_insecure",
        ),
    ] {
        let e = load(&format!(
            r#"{{"proxies":[{{"name":"a","upstream":"x","listen":"l",{text}}}]}}"#
        ))
        .expect_err(text);
        assert!(e.to_string().contains(field), "{text}: {e}");
    }
}
