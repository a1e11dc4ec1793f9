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
