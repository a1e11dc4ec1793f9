//! docs/fleet.md describes every `echelon fleet` subcommand the binary has,
//! as `echelon fleet --help` lists them; every `echelon …` command line in
//! README.md and docs/ parses with the real CLI ([`commands`]).
#![allow(clippy::unwrap_used)] // tests fail loudly by design

use std::path::Path;
use std::process::Command;

#[path = "docs/commands.rs"]
mod commands;

/// The workspace's root.
fn root() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Every `echelon …` command line of README.md and docs/*.md parses with
/// the binary: no subcommand or flag it does not have, no flag without its
/// value, no positional too many, no conflict, no value it refuses (but
/// placeholders), nothing missing in a shell code block.
#[test]
fn every_command_line_in_the_docs_parses() {
    let (checked, wrong) = commands::wrong_lines(&root());
    assert!(checked > 200, "only {checked} command lines found");
    assert!(
        wrong.is_empty(),
        "{} command lines in the docs that the CLI refuses:\n{}",
        wrong.len(),
        wrong.join("\n")
    );
}

/// The checker reads docs as a shell and as usage lines, and refuses what
/// the binary refuses: an unknown flag, subcommand or positional, a flag
/// without its value, conflicting flags, a wrong value, an alternative
/// that is not a possible value; an incomplete shell line, not a fragment.
#[test]
fn the_doc_checker_refuses_what_the_cli_refuses() {
    use commands::{check, command_lines, command_of, expand};
    let words = |s: &str| -> Vec<Vec<String>> {
        expand(s)
            .into_iter()
            .map(|v| v.into_iter().map(|(w, _)| w).collect())
            .collect()
    };
    assert_eq!(
        words("echelon fleet up S --out DIR [--ros2 [--real]] [--topology router|mesh]"),
        [
            "fleet up S --out DIR",
            "fleet up S --out DIR --ros2",
            "fleet up S --out DIR --ros2 --real",
            "fleet up S --out DIR --topology router",
            "fleet up S --out DIR --topology mesh",
        ]
        .map(|l| l.split(' ').map(str::to_owned).collect::<Vec<_>>())
    );
    assert_eq!(
        words("echelon bound --zeta M (--steps N | --max-z Z) [--ts S]"),
        [
            "bound --zeta M --steps N",
            "bound --zeta M --max-z Z",
            "bound --zeta M --steps N --ts S",
        ]
        .map(|l| l.split(' ').map(str::to_owned).collect::<Vec<_>>())
    );
    assert_eq!(
        words(r#"echelon fleet stop lab.toml --reason "a | b" --json 2>&1 | jq . # x"#),
        [["fleet", "stop", "lab.toml", "--reason", "a | b", "--json"].map(str::to_owned)]
    );
    for (line, command) in [
        ("$ echelon run x", Some("echelon run x")),
        (
            "cargo run --release -- run x  # y",
            Some("echelon run x  # y"),
        ),
        (
            "ECHELON_OPERATOR_TOKEN=ab target/release/echelon fleet up",
            Some("echelon fleet up"),
        ),
        (
            "ExecStart=/usr/bin/echelon fleet robot",
            Some("echelon fleet robot"),
        ),
        ("echelon's own", None),
        ("cargo bench -p echelon", None),
    ] {
        assert_eq!(command_of(line).as_deref(), command, "{line}");
    }
    let doc = "x `echelon run x --plot` and `fleet up`\n```sh\necho\necho | echelon run y \\\n  --plot\nechelon run z \\\n  --mcap\n```\n| `echelon fleet up S [--topology router\\|mesh]` |\n";
    let found = command_lines("d.md", doc);
    let texts: Vec<(&str, &str, bool)> = found
        .iter()
        .map(|l| (l.at.as_str(), l.text.as_str(), l.literal))
        .collect();
    assert_eq!(
        texts,
        [
            ("d.md:1", "echelon run x --plot", false),
            ("d.md:1", "echelon fleet up", false),
            ("d.md:6", "echelon run z  --mcap", true),
            (
                "d.md:9",
                "echelon fleet up S [--topology router|mesh]",
                false
            ),
        ]
    );
    let run = |s: &str, literal: bool| {
        let v = expand(s);
        v.iter()
            .map(|w| check(w, literal))
            .collect::<Result<Vec<()>, String>>()
    };
    for good in [
        "echelon run x --plot --out DIR",
        "echelon fleet robot SCENARIO --agent K --outage START:LEN",
        "echelon fleet up SCENARIO --out DIR [--foxglove [ADDR]] [--topology router|mesh]",
        "echelon fleet",
        "echelon run --help",
    ] {
        assert_eq!(run(good, false), Ok(vec![(); expand(good).len()]), "{good}");
    }
    for (bad, why) in [
        ("echelon run x --bogus", "UnknownArgument"),
        ("echelon run x --out", "a value is required"),
        ("echelon nope x", "InvalidSubcommand"),
        ("echelon run x y", "UnknownArgument"),
        ("echelon run x --dt -1", "invalid value '-1'"),
        ("echelon run x [--law paper|best]", "invalid value 'best'"),
        (
            "echelon fleet resume --token A --token-file B",
            "ArgumentConflict",
        ),
        (
            "echelon fleet robot SCENARIO --agent K --no-such-flag",
            "UnknownArgument",
        ),
    ] {
        let e = run(bad, false).unwrap_err();
        assert!(e.contains(why), "{bad}: {e}");
    }
    // Incomplete: fine as a fragment, not as a shell line.
    assert!(run("echelon fleet excite S --ros2 --agent 1", false).is_ok());
    let e = run("echelon fleet excite S --ros2 --agent 1", true).unwrap_err();
    assert!(e.contains("MissingRequiredArgument"), "{e}");
}

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
