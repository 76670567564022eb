//! The layering rules of ARCHITECTURE.md that the crate graph does not check yet, checked by
//! reading the sources (issue 42): each layer's files may not name a module of a layer above
//! it (`crate::net`, `crate::http`, …) nor an async or network crate (`tokio`, `axum`, …).
//! The uses still there from before the rules are listed in [`KNOWN`], each to be removed: a
//! new one fails the test, and so does a listed one that is gone (so the list only shrinks).

#[path = "common/cargo_metadata.rs"]
mod cargo_metadata;

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

/// One layer: its folder under `src/`, the groups of crate modules it may not name, and the
/// external crates it may not name.
struct Layer {
    dir: &'static str,
    modules: &'static [&'static [&'static str]],
    crates: &'static [&'static str],
}

/// The application's modules: sockets, servers, brokers, files, commands, evaluation.
const APPLICATION: &[&str] = &[
    "net",
    "http",
    "fleet",
    "record",
    "foxglove",
    "mcap_estimates",
    "gateway",
    "inventory",
    "cli",
    "eval",
    "realism",
    "options",
    "files",
    "decode",
    "stop",
];

/// The simulator's modules.
const SIMULATOR: &[&str] = &["physics", "scenario", "reader", "sim"];

/// Async runtimes, servers and brokers' clients: the application's alone.
const ASYNC: &[&str] = &[
    "tokio",
    "tokio_rustls",
    "axum",
    "hyper",
    "hyper_util",
    "rumqttc",
    "tokio_tungstenite",
];

const LAYERS: &[Layer] = &[
    // The channel model is pure: scenario, time and seed in; no reader, no localizer. (In the
    // simulator crate, which cannot name the localizer or the application: this checks that
    // it names no reader either.)
    Layer {
        dir: "../crates/sim/src/physics",
        modules: &[&["reader", "sim", "localize"], APPLICATION],
        crates: ASYNC,
    },
    // The scenario file format knows only itself and the physics it configures.
    Layer {
        dir: "../crates/sim/src/scenario",
        modules: &[&["reader", "sim", "localize"], APPLICATION],
        crates: ASYNC,
    },
    // The simulated reader is a sans-IO session: bytes and time in, bytes and a deadline out.
    Layer {
        dir: "../crates/sim/src/reader",
        modules: &[&["sim", "localize"], APPLICATION],
        crates: ASYNC,
    },
    // Recordings (format, recorder, replay session, pcapng) know the codec, reads, files and
    // the wall clock; the servers and clients that feed them are above.
    Layer {
        dir: "record",
        modules: &[
            SIMULATOR,
            &[
                "localize",
                "mcap_estimates",
                "net",
                "http",
                "fleet",
                "foxglove",
                "gateway",
                "inventory",
                "cli",
                "eval",
                "realism",
            ],
        ],
        crates: &[
            "axum",
            "hyper",
            "hyper_util",
            "rumqttc",
            "tokio_tungstenite",
            "llrp_gateway_sim",
            "llrp_gateway_localize",
            "clap",
        ],
    },
    // Sockets serve the sans-IO sessions (the reader's, the replay's), record what passes and
    // offer it to the feed; what consumes the feed (the localizer, HTTP, MQTT) and the
    // commands that compose them are above.
    Layer {
        dir: "net",
        modules: &[&[
            "localize",
            "http",
            "fleet",
            "gateway",
            "inventory",
            "cli",
            "eval",
            "realism",
            "sim",
            "scenario",
        ]],
        crates: &[
            "axum",
            "hyper",
            "hyper_util",
            "rumqttc",
            "llrp_gateway_localize",
            "clap",
        ],
    },
    // The HTTP API serves the localizer's state and takes poses into its feed: it knows no
    // socket server, simulator, recording, broker or command.
    Layer {
        dir: "http",
        modules: &[
            SIMULATOR,
            &[
                "net",
                "fleet",
                "record",
                "gateway",
                "inventory",
                "cli",
                "eval",
                "realism",
            ],
        ],
        crates: &["rumqttc", "llrp_gateway_sim", "clap"],
    },
    // The running simulator (its readers on their sockets, its own inventory, its truth) is
    // one source of the feed: it knows no HTTP, MQTT or other command, which the composition
    // root attaches.
    Layer {
        dir: "sim",
        modules: &[&[
            "http",
            "fleet",
            "gateway",
            "inventory",
            "cli",
            "eval",
            "realism",
        ]],
        crates: &["axum", "hyper", "hyper_util", "rumqttc", "clap"],
    },
    // MQTT publishing and workers take the localizer's feed and state; they do not reach into
    // the simulator, the HTTP server or the other commands.
    Layer {
        dir: "fleet",
        modules: &[
            SIMULATOR,
            &["http", "gateway", "inventory", "cli", "eval", "realism"],
        ],
        crates: &["axum", "hyper", "hyper_util", "llrp_gateway_sim", "clap"],
    },
    // The proxy's own folder (its `--config` file, its tap of the sessions) knows sockets,
    // recordings and the localizer's feed; the command line, the HTTP API, MQTT, the
    // simulator and the other commands are above it.
    Layer {
        dir: "gateway",
        modules: &[
            SIMULATOR,
            &["cli", "http", "fleet", "inventory", "eval", "realism"],
        ],
        crates: &[
            "axum",
            "hyper",
            "hyper_util",
            "rumqttc",
            "llrp_gateway_sim",
            "clap",
        ],
    },
    // The inventory client knows sockets, reads, files and recordings, as the proxy does.
    Layer {
        dir: "inventory",
        modules: &[
            SIMULATOR,
            &["cli", "http", "fleet", "gateway", "eval", "realism"],
        ],
        crates: &[
            "axum",
            "hyper",
            "hyper_util",
            "rumqttc",
            "llrp_gateway_sim",
            "clap",
        ],
    },
];

/// Uses from before the rules, as (file under `src/`, name): each one is a layering fault to
/// remove (issue 42), and is listed here only so that the test catches new ones meanwhile.
const KNOWN: &[(&str, &str)] = &[
    // Empty since 2026-12-07: the MQTT worker's command, which assembled localizer, settings,
    // HTTP and MQTT itself from inside `fleet/`, moved to `cli/worker.rs`.
];

/// Every `.rs` file under `dir`.
fn sources(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).expect("a source folder") {
            let path = entry.expect("an entry").path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|e| e == "rs") {
                out.push(path);
            }
        }
    }
    out.sort();
    out
}

/// The code of `text` without comments (line comments, doc comments, block comments) and
/// without string literals, so that only what the compiler resolves is looked at.
fn code(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let b = text.as_bytes();
    let mut i = 0;
    while i < b.len() {
        if b[i..].starts_with(b"//") {
            while i < b.len() && b[i] != b'\n' {
                i += 1;
            }
        } else if b[i..].starts_with(b"/*") {
            let mut depth = 0;
            while i < b.len() {
                if b[i..].starts_with(b"/*") {
                    depth += 1;
                    i += 2;
                } else if b[i..].starts_with(b"*/") {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    i += 1;
                }
            }
        } else if b[i] == b'"' {
            i += 1;
            while i < b.len() && b[i] != b'"' {
                i += if b[i] == b'\\' { 2 } else { 1 };
            }
            i += 1;
        } else {
            out.push(b[i] as char);
            i += 1;
        }
    }
    out
}

/// The first path segments `code` names after `crate::`, including each of a group's
/// (`crate::{a::x, b}` names `a` and `b`).
fn crate_modules(code: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    let ident = |s: &str| -> String {
        s.trim_start()
            .chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_')
            .collect()
    };
    for (at, _) in code.match_indices("crate::") {
        // `llrp_gateway::crate::` cannot occur; a `$crate::` is a macro's and is skipped.
        if code[..at].ends_with('$') {
            continue;
        }
        let rest = &code[at + "crate::".len()..];
        if let Some(group) = rest.trim_start().strip_prefix('{') {
            let mut depth = 0;
            let mut segment_start = true;
            for (k, c) in group.char_indices() {
                match c {
                    '{' => depth += 1,
                    '}' if depth == 0 => break,
                    '}' => depth -= 1,
                    ',' if depth == 0 => segment_start = true,
                    c if segment_start && !c.is_whitespace() => {
                        out.insert(ident(&group[k..]));
                        segment_start = false;
                    }
                    _ => {}
                }
            }
        } else {
            out.insert(ident(rest));
        }
    }
    out
}

/// Whether `code` names the external crate `name` (`name::…` as a path, not a field).
fn names_crate(code: &str, name: &str) -> bool {
    let pattern = format!("{name}::");
    let path = code.match_indices(&pattern).any(|(at, _)| {
        let before = code[..at].chars().next_back();
        !before.is_some_and(|c| c.is_alphanumeric() || c == '_' || c == ':' || c == '.')
    });
    // `use name;` and `use name as x;` name it without a path.
    let word = |rest: &str| !rest.starts_with(|c: char| c.is_alphanumeric() || c == '_');
    let used = code.match_indices("use ").any(|(at, _)| {
        let before = code[..at].chars().next_back();
        let rest = code[at + "use ".len()..].trim_start();
        !before.is_some_and(|c| c.is_alphanumeric() || c == '_')
            && (rest.strip_prefix(name).is_some_and(word)
                || rest
                    .strip_prefix("::")
                    .and_then(|r| r.strip_prefix(name))
                    .is_some_and(word))
    });
    path || used
}

#[test]
fn no_layer_names_a_layer_above_it_or_an_async_crate() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut found: BTreeSet<(String, String)> = BTreeSet::new();
    for layer in LAYERS {
        for file in sources(&src.join(layer.dir)) {
            // Under src/, or a crate's src/ (named from the workspace's root).
            let root = src.parent().expect("the workspace root");
            let rel = file
                .strip_prefix(&src)
                .or_else(|_| file.strip_prefix(root))
                .expect("under the workspace")
                .to_string_lossy()
                .replace('\\', "/");
            let text = code(&std::fs::read_to_string(&file).expect("a source file"));
            for m in crate_modules(&text) {
                if layer.modules.iter().any(|g| g.contains(&m.as_str())) {
                    found.insert((rel.clone(), m));
                }
            }
            for c in layer.crates {
                if names_crate(&text, c) {
                    found.insert((rel.clone(), (*c).to_string()));
                }
            }
        }
    }
    let known: BTreeSet<(String, String)> = KNOWN
        .iter()
        .map(|(f, m)| ((*f).to_string(), (*m).to_string()))
        .collect();
    let new: Vec<_> = found.difference(&known).collect();
    let gone: Vec<_> = known.difference(&found).collect();
    assert!(
        new.is_empty(),
        "layering broken (ARCHITECTURE.md), file under src/ and what it names: {new:?}"
    );
    assert!(
        gone.is_empty(),
        "fixed, so take them off KNOWN in tests/architecture.rs: {gone:?}"
    );
}

#[test]
fn the_checker_sees_grouped_uses_and_skips_comments_and_strings() {
    let text = code(
        "use crate::{physics::World, reads::{Read, ReadDecoder}};\n\
         // crate::net in a comment\n\
         /* crate::http /* nested */ */\n\
         let s = \"crate::fleet\";\n\
         let t = tokio::spawn(x); let u = my_tokio::x; let v = a.tokio::b;\n",
    );
    let modules: Vec<String> = crate_modules(&text).into_iter().collect();
    assert_eq!(modules, ["physics", "reads"]);
    assert!(names_crate(&text, "tokio"));
    assert!(!names_crate(&code("let u = my_tokio::x;"), "tokio"));
    // A clap type, derive or import, in a subsystem.
    for text in [
        "use clap::ValueEnum;",
        "use clap::{Args, Parser};",
        "#[derive(Clone, clap::ValueEnum)]",
        "use clap;",
        "use ::clap as c;",
    ] {
        assert!(names_crate(&code(text), "clap"), "{text}");
    }
    for text in [
        "let clapper = 1;",
        "use clapper::x;",
        "self.clap::x",
        "// use clap;",
    ] {
        assert!(!names_crate(&code(text), "clap"), "{text}");
    }
}

#[test]
fn the_codec_crate_depends_on_no_async_or_network_crate() {
    let manifest =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("protocol/Cargo.toml"))
            .expect("protocol/Cargo.toml");
    // The [dependencies] table, up to the next table.
    let deps = manifest
        .split("\n[")
        .find(|t| t.starts_with("dependencies]"))
        .expect("a [dependencies] table");
    for c in ASYNC.iter().map(|c| c.replace('_', "-")) {
        assert!(
            !deps
                .lines()
                .any(|l| l.trim_start().starts_with(&format!("{c} "))
                    || l.trim_start().starts_with(&format!("{c}="))),
            "protocol/ depends on {c}"
        );
    }
}

/// The keys of `manifest`'s `[dependencies]` table.
fn dependencies(manifest: &str) -> Vec<String> {
    manifest
        .split("\n[")
        .find(|t| t.starts_with("dependencies]"))
        .expect("a [dependencies] table")
        .lines()
        .skip(1)
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .filter_map(|l| l.split(['=', ' ']).next().map(str::to_string))
        .collect()
}

/// Checks that the manifest at `path` (from the workspace root) lists `expected` among its
/// `[dependencies]` (so the check reads the right table) and nothing outside `allowed`.
fn depends_only_on(path: &str, expected: &str, allowed: &[&str]) {
    let manifest = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join(path))
        .unwrap_or_else(|e| panic!("{path}: {e}"));
    let deps = dependencies(&manifest);
    assert!(deps.iter().any(|d| d == expected), "{path}: {deps:?}");
    for d in &deps {
        assert!(
            allowed.contains(&d.as_str()),
            "{path} lists {d}: not allowed below the application (ARCHITECTURE.md)"
        );
    }
}

#[test]
fn the_vocabulary_crate_depends_only_on_the_codec_and_serialization() {
    // Reads and poses in SI units, the feed and the wall clock sit below the localizer, the
    // simulator and the application: the crate names none of them (the compiler enforces it
    // once the manifest does not list them) and no async or network crate. The feed's drop
    // counters are metric handles (prometheus-client's, without IO); CSV is the csv crate's
    // (a parser over `io::Read`, no IO of its own).
    depends_only_on(
        "crates/vocab/Cargo.toml",
        "llrp",
        &[
            "llrp",
            "bytes",
            "csv",
            "prometheus-client",
            "serde",
            "serde_json",
            "serde_path_to_error",
            "thiserror",
        ],
    );
}

#[test]
fn the_localizer_crate_depends_only_on_the_vocabulary_and_numeric_crates() {
    // The localizer sees reads and poses (the vocabulary's), never the simulator, and knows
    // no sockets, HTTP or MQTT: so it works the same on a real reader's data and runs in any
    // host. Its counters are metric handles (prometheus-client's, without IO).
    depends_only_on(
        "crates/localize/Cargo.toml",
        "llrp-gateway-vocab",
        &[
            "llrp-gateway-vocab",
            "nalgebra",
            "levenberg-marquardt",
            "rustc-hash",
            "rand",
            "rand_chacha",
            "rand_distr",
            "serde",
            "serde_json",
            "serde_path_to_error",
            "thiserror",
            "prometheus-client",
        ],
    );
}

#[test]
fn the_simulator_crate_depends_on_no_async_crate_localizer_or_application() {
    // The scenario format, the pure channel model and the sans-IO reader: the codec, numbers
    // and serialization, nothing above them (the compiler enforces it once the manifest does
    // not list them).
    depends_only_on(
        "crates/sim/Cargo.toml",
        "rand",
        &[
            "llrp",
            "llrp-gateway-vocab",
            "bytes",
            "serde",
            "serde_json",
            "serde_path_to_error",
            "thiserror",
            "tracing",
            "rand",
            "rand_chacha",
            "rand_distr",
        ],
    );
}

/// The resolved crate graph of the workspace on this platform (`cargo metadata`, offline: the
/// build before the tests fetched every crate): per package name, its normal (not dev, not
/// build) dependencies' names.
fn crate_graph() -> std::collections::BTreeMap<String, BTreeSet<String>> {
    let meta = cargo_metadata::metadata();
    let name_of: std::collections::BTreeMap<&str, &str> = meta["packages"]
        .as_array()
        .expect("packages")
        .iter()
        .map(|p| {
            (
                p["id"].as_str().expect("an id"),
                p["name"].as_str().expect("a name"),
            )
        })
        .collect();
    let mut graph = std::collections::BTreeMap::new();
    for node in meta["resolve"]["nodes"].as_array().expect("resolved nodes") {
        let deps: BTreeSet<String> = node["deps"]
            .as_array()
            .expect("deps")
            .iter()
            .filter(|d| {
                d["dep_kinds"]
                    .as_array()
                    .expect("kinds")
                    .iter()
                    .any(|k| k["kind"].is_null())
            })
            .map(|d| name_of[d["pkg"].as_str().expect("a package")].to_string())
            .collect();
        graph.insert(
            name_of[node["id"].as_str().expect("an id")].to_string(),
            deps,
        );
    }
    graph
}

/// Every crate `name` depends on, directly or not (normal dependencies).
fn closure(
    graph: &std::collections::BTreeMap<String, BTreeSet<String>>,
    name: &str,
) -> BTreeSet<String> {
    let mut seen = BTreeSet::new();
    let mut stack = vec![name.to_string()];
    while let Some(n) = stack.pop() {
        for d in graph.get(&n).into_iter().flatten() {
            if seen.insert(d.clone()) {
                stack.push(d.clone());
            }
        }
    }
    seen
}

#[test]
fn the_crate_graph_is_the_layering() {
    // Between the workspace's crates, each edge is one ARCHITECTURE.md draws: the codec at the
    // bottom, the vocabulary on it, the simulator on both, the localizer on the
    // vocabulary, the application on all of them; and below the application no crate reaches
    // an async runtime, a server or a broker's client, however indirectly.
    let graph = crate_graph();
    let workspace = [
        "llrp",
        "llrp-gateway-vocab",
        "llrp-gateway-sim",
        "llrp-gateway-localize",
        "llrp-gateway",
    ];
    let edges = |name: &str| -> BTreeSet<&str> {
        graph[name]
            .iter()
            .filter_map(|d| workspace.iter().copied().find(|w| w == d))
            .filter(|d| *d != name)
            .collect()
    };
    let expected: [(&str, &[&str]); 5] = [
        ("llrp", &[]),
        ("llrp-gateway-vocab", &["llrp"]),
        ("llrp-gateway-sim", &["llrp", "llrp-gateway-vocab"]),
        ("llrp-gateway-localize", &["llrp-gateway-vocab"]),
        (
            "llrp-gateway",
            &[
                "llrp",
                "llrp-gateway-vocab",
                "llrp-gateway-sim",
                "llrp-gateway-localize",
            ],
        ),
    ];
    for (name, deps) in expected {
        assert_eq!(
            edges(name),
            deps.iter().copied().collect::<BTreeSet<&str>>(),
            "{name}'s workspace dependencies (ARCHITECTURE.md)"
        );
    }
    for name in &workspace[..4] {
        let reached = closure(&graph, name);
        for forbidden in ["tokio", "mio", "axum", "hyper", "rumqttc", "tokio-rustls"] {
            assert!(
                !reached.contains(forbidden),
                "{name} reaches {forbidden}: below the application (ARCHITECTURE.md)"
            );
        }
    }
    // The application does reach them: the check sees what it looks for.
    assert!(closure(&graph, "llrp-gateway").contains("tokio"));
}

#[test]
fn only_the_composition_root_starts_the_localizer_or_serves_its_api() {
    // Every command's localizer, HTTP API and metrics registry are built in one place,
    // `cli/root.rs` (ARCHITECTURE.md, "One composition root"); a second place that starts a
    // `Live` or launches the API would assemble them again. Test modules are not looked at.
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let root = src.join("cli").join("root.rs");
    let mut found = Vec::new();
    for file in sources(&src) {
        if file == root {
            continue;
        }
        let text = std::fs::read_to_string(&file).expect("a source file");
        let text = text.split("#[cfg(test)]").next().unwrap_or_default();
        let code = code(text);
        for what in ["Live::start", "launch::launch", "launch::{launch"] {
            if code.replace(char::is_whitespace, "").contains(what) {
                found.push((file.display().to_string(), what));
            }
        }
    }
    assert!(
        found.is_empty(),
        "started outside the composition root: {found:?}"
    );
}

#[test]
fn only_the_command_line_names_clap() {
    // Rule 14 for every source file of the application, not only the layers above: the
    // single-file modules, `eval/` and `realism/` too. Only `cli/` and `main.rs` name clap.
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let allowed = [src.join("cli"), src.join("main.rs")];
    let found: Vec<String> = sources(&src)
        .into_iter()
        .filter(|f| !allowed.iter().any(|a| f.starts_with(a)))
        .filter(|f| {
            let text = std::fs::read_to_string(f).expect("a source file");
            names_crate(&code(&text), "clap")
        })
        .map(|f| f.display().to_string())
        .collect();
    assert!(found.is_empty(), "names clap outside src/cli/: {found:?}");
}
