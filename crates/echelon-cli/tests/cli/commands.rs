//! Help, the scenario list and `show`.

use super::*;

#[test]
fn every_command_has_help() {
    for args in [
        &["--help"][..],
        &["run", "--help"],
        &["scenarios", "--help"],
        &["show", "--help"],
        &["plot", "--help"],
        &["lycomp", "--help"],
        &["bench", "--help"],
    ] {
        let o = echelon(args);
        assert!(o.status.success(), "{args:?}");
        assert!(stdout(&o).contains("Usage: echelon"), "{args:?}");
    }
    assert!(stdout(&echelon(&["--version"])).starts_with("echelon "));
}

#[test]
fn scenarios_lists_the_built_ins_with_a_line_each() {
    let o = echelon(&["scenarios"]);
    assert!(o.status.success());
    let text = stdout(&o);
    let listed: Vec<&str> = text
        .lines()
        .map(|l| l.split_whitespace().next().unwrap())
        .collect();
    assert_eq!(listed, names().collect::<Vec<_>>());
    // Each line: the name, then a description of several words.
    assert!(
        text.lines().all(|l| l.split_whitespace().count() > 4),
        "{text}"
    );
}

#[test]
fn show_round_trips_into_run() {
    let dir = tempfile::tempdir().unwrap();
    for name in names() {
        let shown = echelon(&["show", name]);
        assert!(shown.status.success());
        let file = dir.path().join(format!("{name}.toml"));
        std::fs::write(&file, &shown.stdout).unwrap();
        let (a, b) = (
            dir.path().join(format!("{name}-builtin")),
            dir.path().join(format!("{name}-file")),
        );
        // A shorter run keeps the test fast; the golden tests run the full durations.
        for (scenario, out) in [(name, &a), (file.to_str().unwrap(), &b)] {
            let o = run(scenario, out, &["--duration", "8", "-q"]);
            assert!(succeeded(&o).is_empty(), "--quiet prints nothing");
        }
        for f in ["trajectory.csv", "summary.json"] {
            assert!(
                std::fs::read(a.join(f)).unwrap() == std::fs::read(b.join(f)).unwrap(),
                "{name}: {f} differs between the built-in and its shown TOML"
            );
        }
    }
}
