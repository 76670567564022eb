//! The workspace's `rust-version` (Cargo.toml's `[workspace.package]`, which every member
//! inherits) is the real minimum the lock file allows: the highest `rust-version` that any
//! package of the resolved graph declares (`cargo metadata`, this platform, normal, build and
//! dev dependencies: `cargo test` builds them all). Only one toolchain can be had on the
//! project's machines, so no build with the minimum itself is run; what this test checks is
//! that the field is neither below what a dependency says it needs (as 1.80 was, when tokio
//! asked for 1.85) nor above it. Clippy's `incompatible_msrv` lint (in `cargo clippy -D
//! warnings`) checks the project's own code against the field for the standard library's APIs.

use std::collections::BTreeSet;

/// A `rust-version` as (major, minor, patch); "1.85" is 1.85.0.
fn parse(version: &str) -> (u64, u64, u64) {
    let mut parts = version.split('.').map(|p| {
        p.parse::<u64>()
            .unwrap_or_else(|_| panic!("not a rust-version: {version:?}"))
    });
    let major = parts.next().unwrap_or(0);
    let minor = parts.next().unwrap_or(0);
    let patch = parts.next().unwrap_or(0);
    (major, minor, patch)
}

#[path = "common/cargo_metadata.rs"]
mod cargo_metadata;
use cargo_metadata::metadata;

#[test]
fn the_workspace_rust_version_is_the_highest_its_dependencies_declare() {
    let meta = metadata();
    let members: BTreeSet<&str> = meta["workspace_members"]
        .as_array()
        .expect("members")
        .iter()
        .map(|m| m.as_str().expect("an id"))
        .collect();
    let resolved: BTreeSet<&str> = meta["resolve"]["nodes"]
        .as_array()
        .expect("resolved nodes")
        .iter()
        .map(|n| n["id"].as_str().expect("an id"))
        .collect();
    let mut declared = BTreeSet::new();
    let mut needed: Option<((u64, u64, u64), Vec<String>)> = None;
    for p in meta["packages"].as_array().expect("packages") {
        let id = p["id"].as_str().expect("an id");
        let version = p["rust_version"].as_str();
        if members.contains(id) {
            declared.insert(version.map(parse));
            continue;
        }
        let Some(version) = version.filter(|_| resolved.contains(id)) else {
            continue;
        };
        let name = format!(
            "{} {}",
            p["name"].as_str().unwrap_or("?"),
            p["version"].as_str().unwrap_or("?")
        );
        let v = parse(version);
        match &mut needed {
            Some((max, names)) if *max == v => names.push(name),
            Some((max, _)) if *max > v => {}
            _ => needed = Some((v, vec![name])),
        }
    }
    let (needed, by) = needed.expect("some dependency declares a rust-version");
    let declared: Vec<_> = declared.into_iter().collect();
    assert_eq!(
        declared,
        vec![Some(needed)],
        "every workspace crate's rust-version (Cargo.toml's [workspace.package]) must be \
         {}.{}.{}, the highest any dependency declares ({})",
        needed.0,
        needed.1,
        needed.2,
        by.join(", ")
    );
}

#[test]
fn a_rust_version_without_a_patch_is_patch_zero() {
    assert_eq!(parse("1.85"), (1, 85, 0));
    assert_eq!(parse("1.89.1"), (1, 89, 1));
    assert!(parse("1.85") < parse("1.85.1"));
}
