//! The crates by where they run, as docs/architecture.md draws them: its table of crates and
//! their direct dependencies is `cargo metadata`'s; the wire crate is `no_std` with no std
//! dependency; nothing a robot deploys, nor the lab's tools for it, reaches the simulator or
//! the paper's experiments.

use std::collections::{BTreeMap, BTreeSet};
use std::process::Command;

/// Workspace crate (without `presrs-`) -> its direct normal workspace dependencies, and each
/// dependency's `uses_default_features`.
fn graph() -> (BTreeMap<String, BTreeSet<String>>, serde_json::Value) {
    let out = stdout_of(
        Command::new(cargo()).args(["metadata", "--format-version", "1", "--no-deps"]),
        "cargo metadata",
    );
    let meta: serde_json::Value = serde_json::from_str(&out).unwrap();
    let short = |n: &str| n.strip_prefix("presrs-").unwrap_or(n).to_string();
    let mut g = BTreeMap::new();
    for p in meta["packages"].as_array().unwrap() {
        let deps = p["dependencies"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|d| d["kind"].is_null() && d["name"].as_str().unwrap().starts_with("presrs-"))
            .map(|d| short(d["name"].as_str().unwrap()))
            .collect();
        g.insert(short(p["name"].as_str().unwrap()), deps);
    }
    (g, meta)
}

/// The cargo running the tests.
fn cargo() -> String {
    std::env::var("CARGO").unwrap_or_else(|_| "cargo".into())
}

/// `cmd`'s standard output, run in the workspace's root; `what` names it if it fails.
fn stdout_of(cmd: &mut Command, what: &str) -> String {
    let out = cmd
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap_or_else(|e| panic!("{what}: {e}"));
    assert!(
        out.status.success(),
        "{what}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn reaches(g: &BTreeMap<String, BTreeSet<String>>, from: &str) -> BTreeSet<String> {
    let mut seen = BTreeSet::new();
    let mut todo = vec![from.to_string()];
    while let Some(c) = todo.pop() {
        for d in &g[&c] {
            if seen.insert(d.clone()) {
                todo.push(d.clone());
            }
        }
    }
    seen
}

#[test]
fn the_architecture_table_is_the_crate_graph() {
    let (g, _) = graph();
    let doc = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/docs/architecture.md"))
        .unwrap();
    let mut table = BTreeMap::new();
    // The rows of the one table whose header is `| crate | depends on | ...`.
    let rows = doc
        .lines()
        .skip_while(|l| !l.starts_with("| crate | depends on"))
        .skip(2)
        .take_while(|l| l.starts_with("| "));
    for line in rows {
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        let deps: BTreeSet<String> = cells[2]
            .split(',')
            .map(str::trim)
            .filter(|d| !d.is_empty())
            .map(String::from)
            .collect();
        table.insert(cells[1].to_string(), deps);
    }
    assert_eq!(
        table, g,
        "docs/architecture.md's crate table against cargo metadata"
    );
}

#[test]
fn nothing_a_robot_deploys_reaches_the_simulator_or_the_lab() {
    let (g, _) = graph();
    for c in [
        "wire",
        "protocol",
        "node",
        "controller",
        "leg",
        "record",
        "ros2",
        "tools",
    ] {
        let r = reaches(&g, c);
        assert!(
            !r.contains("sim") && !r.contains("lab"),
            "{c} reaches {r:?}"
        );
    }
    assert!(g["wire"].is_empty(), "wire depends on {:?}", g["wire"]);
}

#[test]
fn the_wire_crate_is_no_std_and_turns_its_dependencies_std_off() {
    let (_, meta) = graph();
    let wire = meta["packages"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["name"] == "presrs-wire")
        .unwrap();
    for d in wire["dependencies"].as_array().unwrap() {
        if d["kind"].is_null() {
            let name = d["name"].as_str().unwrap();
            // embedded-can has no std feature at all.
            assert!(
                name == "embedded-can" || d["uses_default_features"] == false,
                "presrs-wire's {name} keeps its default (std) features"
            );
        }
    }
    let lib =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/wire/src/lib.rs")).unwrap();
    assert!(
        lib.starts_with("#![cfg_attr(not(test), no_std)]"),
        "wire/src/lib.rs"
    );
}

/// The robot's build of `presrs` (scripts/package-deb.sh's, the arm64 .deb's) links no
/// simulator, experiment, lab tool or plotting crate: its whole dependency tree, as cargo
/// resolves it for those features.
#[test]
fn the_robot_build_links_no_simulator_lab_or_plots() {
    let args = stdout_of(
        Command::new("bash").args(["scripts/package-deb.sh", "--print-build-args"]),
        "scripts/package-deb.sh --print-build-args",
    );
    let features: Vec<&str> = args
        .split_whitespace()
        .filter(|a| *a != "--bin" && *a != "presrs")
        .collect();
    assert!(
        features.contains(&"--no-default-features"),
        "the robot's build keeps the default (lab) features: {args}"
    );
    let tree = stdout_of(
        Command::new(cargo())
            .args([
                "tree",
                "-p",
                "presrs",
                "-e",
                "normal,build",
                "--prefix",
                "none",
            ])
            .args(&features),
        "cargo tree",
    );
    let crates: BTreeSet<&str> = tree
        .lines()
        .filter_map(|l| l.split_whitespace().next())
        .collect();
    assert!(crates.contains("presrs-node") && crates.contains("presrs-ros2"));
    for lab in [
        "presrs-sim",
        "presrs-lab",
        "presrs-tools",
        "plotters",
        "image",
    ] {
        assert!(!crates.contains(lab), "the robot's build links {lab}");
    }
}
