//! The kernel stays a kernel (issue house): nothing in its normal
//! dependency tree reads or writes a format, a file or a network, and no
//! file of its source does IO. `cargo tree` is asked, not a list kept by
//! hand; the same question with the `serde` feature on shows the check can
//! see a serialisation crate when there is one.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;
use std::process::Command;

/// Crates that are formats, IO or ROS: none may be a normal dependency of
/// the kernel with its default features.
const FORBIDDEN: [&str; 12] = [
    "serde",
    "serde_json",
    "schemars",
    "toml",
    "csv",
    "echelon-ros2",
    "echelon",
    "zenoh",
    "mcap",
    "pyo3",
    "tokio",
    "clap",
];

/// The package names of `cargo tree -e normal -p echelon-core` with
/// `features`.
fn tree(features: &[&str]) -> Vec<String> {
    let mut cmd = Command::new(env!("CARGO"));
    cmd.current_dir(env!("CARGO_MANIFEST_DIR")).args([
        "tree",
        "--locked",
        "--offline",
        "-e",
        "normal",
        "-p",
        "echelon-core",
        "--prefix",
        "none",
        "--format",
        "{p}",
    ]);
    if !features.is_empty() {
        cmd.args(["--features", &features.join(",")]);
    }
    let out = cmd.output().expect("cargo runs");
    assert!(
        out.status.success(),
        "cargo tree: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut names: Vec<String> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .filter_map(|l| l.split_whitespace().next().map(str::to_owned))
        .collect();
    names.sort();
    names.dedup();
    names
}

#[test]
fn the_kernel_depends_on_no_format_file_or_network_crate() {
    let names = tree(&[]);
    assert!(names.iter().any(|n| n == "echelon-core"), "{names:?}");
    let bad: Vec<&String> = names
        .iter()
        .filter(|n| FORBIDDEN.contains(&n.as_str()))
        .collect();
    assert!(
        bad.is_empty(),
        "the kernel depends on {bad:?} (all: {names:?})"
    );
}

#[test]
fn with_the_serde_feature_the_check_sees_serde() {
    let names = tree(&["serde"]);
    assert!(names.iter().any(|n| n == "serde"), "{names:?}");
    assert!(
        !names.iter().any(|n| n == "toml" || n == "csv"),
        "{names:?}"
    );
}

/// Every `.rs` file under `dir`.
fn sources(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            sources(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

#[test]
fn no_kernel_source_does_io() {
    let mut files = Vec::new();
    sources(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("src"),
        &mut files,
    );
    assert!(files.len() > 20, "{files:?}");
    for file in files {
        let text = std::fs::read_to_string(&file).unwrap();
        for io in [
            "std::fs",
            "std::net",
            "std::process",
            "std::env",
            "File::",
            "println!",
            "eprintln!",
        ] {
            assert!(
                !text.contains(io),
                "{} uses {io}: the kernel does no IO",
                file.display()
            );
        }
    }
}
