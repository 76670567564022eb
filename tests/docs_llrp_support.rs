//! docs/llrp-support.md names every LLRP message and parameter the codec knows, so what the
//! simulated reader does with each is written down: a message or parameter added to the codec
//! fails this test until the page says what the reader does with it.

use std::collections::BTreeSet;
use std::path::Path;

use llrp::message::MessageKind;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The page's text, with the message names' `/ _RESPONSE` and `and their _RESPONSEs`
/// shorthands spelled out.
fn page() -> String {
    let text = std::fs::read_to_string(root().join("docs/llrp-support.md")).expect("the page");
    let mut out = String::new();
    for line in text.lines() {
        out.push_str(line);
        out.push('\n');
        let cells: Vec<&str> = line.split('|').collect();
        let Some(first) = cells.get(1) else { continue };
        for name in first.split(',') {
            let name = name.trim().trim_end_matches(" and their _RESPONSEs");
            let name = name.split(" / ").next().unwrap_or(name);
            if first.contains("_RESPONSE") {
                out.push_str(&format!("{name}_RESPONSE\n"));
            }
        }
    }
    out
}

/// Whether `name` appears in `text` as a whole name (not inside a longer one).
fn names(text: &str, name: &str) -> bool {
    text.match_indices(name).any(|(i, _)| {
        let before = text[..i].chars().next_back();
        let after = text[i + name.len()..].chars().next();
        let edge = |c: Option<char>| !c.is_some_and(|c| c.is_ascii_alphanumeric() || c == '_');
        edge(before) && edge(after)
    })
}

#[test]
fn every_message_the_codec_knows_is_on_the_page() {
    let page = page();
    let known: BTreeSet<&str> = (0..1024u16)
        .map(|ty| MessageKind::standard(ty).name())
        .filter(|n| *n != "UNKNOWN")
        .collect();
    assert!(known.len() > 40, "{known:?}");
    let missing: Vec<&&str> = known.iter().filter(|n| !names(&page, n)).collect();
    assert!(
        missing.is_empty(),
        "not on docs/llrp-support.md: {missing:?}"
    );
    for custom in [
        "IMPINJ_ENABLE_EXTENSIONS",
        "IMPINJ_SAVE_SETTINGS",
        "CUSTOM_MESSAGE",
    ] {
        assert!(names(&page, custom), "{custom}");
    }
}

#[test]
fn every_parameter_the_codec_knows_is_on_the_page() {
    // The codec declares each parameter with its spec name in quotes after its type number:
    // `tlv [177] "ROSpec"`, `custom [25882 50] "ImpinjTagReportContentSelector"`, and the TV
    // ones as `tv_param!(… Name, 13, "EPC-96", …)` or `const NAME: &str = "…"`.
    let mut known = BTreeSet::new();
    let dir = root().join("protocol/src/params");
    let mut sources: Vec<_> = std::fs::read_dir(&dir)
        .expect("the codec's parameters")
        .map(|e| e.expect("an entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "rs"))
        .collect();
    sources.push(root().join("protocol/src/impinj.rs"));
    for path in sources {
        let text = std::fs::read_to_string(&path).expect("a source");
        known.extend(declared(&text));
    }
    assert!(known.len() > 100, "{} parameters found", known.len());
    let page = page();
    let missing: Vec<&String> = known.iter().filter(|n| !names(&page, n)).collect();
    assert!(
        missing.is_empty(),
        "not on docs/llrp-support.md: {missing:?}"
    );
}

/// The parameter names a codec source declares.
fn declared(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    for line in text.lines() {
        let l = line.trim();
        let quoted = || l.split('"').nth(1).map(str::to_string);
        let is_param = (l.contains(": tlv [") || l.contains(": custom ["))
            && l.contains('"')
            && !l.contains("custom_message");
        let is_tv = l.starts_with("tv_param!(") || l.contains("const NAME: &'static str");
        if is_param || is_tv {
            out.extend(quoted());
        } else if let Some(prev) = l.strip_suffix(");") {
            // The second line of a `tv_param!(/// doc\n Name, 13, "EPC-96", …);`.
            if prev.contains(", \"")
                && prev
                    .split(',')
                    .nth(1)
                    .is_some_and(|n| n.trim().parse::<u16>().is_ok())
            {
                out.extend(quoted());
            }
        }
    }
    out
}
