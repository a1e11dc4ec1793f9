//! docs/fleet.md describes every `echelon fleet` subcommand the binary has,
//! as `echelon fleet --help` lists them.
#![allow(clippy::unwrap_used)] // tests fail loudly by design

use std::path::Path;
use std::process::Command;

/// The subcommands `echelon fleet --help` lists (but `help`).
fn fleet_subcommands() -> Vec<String> {
    let o = Command::new(env!("CARGO_BIN_EXE_echelon"))
        .args(["fleet", "--help"])
        .output()
        .unwrap();
    assert!(o.status.success());
    let help = String::from_utf8(o.stdout).unwrap();
    let start = help.find("Commands:").expect("a Commands: section");
    help[start..]
        .lines()
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .filter_map(|l| l.split_whitespace().next())
        .filter(|c| *c != "help")
        .map(str::to_owned)
        .collect()
}

#[test]
fn fleet_md_describes_every_fleet_subcommand() {
    let commands = fleet_subcommands();
    assert!(
        commands.len() >= 9 && commands.iter().any(|c| c == "excite"),
        "{commands:?}"
    );
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/fleet.md");
    let doc = std::fs::read_to_string(&path).unwrap();
    let missing: Vec<&String> = commands
        .iter()
        .filter(|c| {
            !doc.contains(&format!("`echelon fleet {c} "))
                && !doc.contains(&format!("`echelon fleet {c}`"))
        })
        .collect();
    assert!(
        missing.is_empty(),
        "docs/fleet.md has no `echelon fleet <command> …` for {missing:?}"
    );
}

/// docs/faults.md is the table `echelon fleet faults` writes (`DIR/faults.md`):
/// a measured line for every row of the matrix, each within its bound,
/// with the machine named.
#[test]
fn faults_md_is_the_fault_matrix() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/faults.md");
    let doc = std::fs::read_to_string(&path).unwrap();
    assert!(doc.starts_with("# Fault matrix"), "{doc}");
    assert!(doc.contains("Measured by `echelon fleet faults"), "{doc}");
    for row in echelon_fleet::matrix::rows() {
        let head = format!("| `{}` |", row.name);
        let line = doc
            .lines()
            .find(|l| l.starts_with(&head))
            .unwrap_or_else(|| panic!("docs/faults.md has no row {}", row.name));
        assert!(line.ends_with("| yes |"), "{line}");
    }
}
