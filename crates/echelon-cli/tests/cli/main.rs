//! The `echelon` binary, run as a user runs it.
#![allow(clippy::unwrap_used)] // tests fail loudly by design

use std::path::Path;
use std::process::{Command, Output};

mod bench;
mod bound;
mod commands;
mod newuser;
mod refusals;
mod run;
mod sweep;
mod terminal;

/// The built-in scenarios' names (`echelon`'s scenario tests pin the list).
fn names() -> impl Iterator<Item = &'static str> {
    echelon::scenario::builtin().iter().map(|(n, _)| *n)
}

fn echelon(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_echelon"))
        .args(args)
        .output()
        .expect("the echelon binary runs")
}

/// `echelon ARGS… --out OUT`.
fn echelon_into(out: &Path, args: &[&str]) -> Output {
    echelon(&[args, &["--out", out.to_str().unwrap()]].concat())
}

/// `echelon run SCENARIO EXTRA… --out OUT`.
fn run(scenario: &str, out: &Path, extra: &[&str]) -> Output {
    echelon_into(out, &[&["run", scenario], extra].concat())
}

fn stdout(o: &Output) -> String {
    String::from_utf8(o.stdout.clone()).unwrap()
}

/// The `summary.json` a run wrote into `dir`.
fn summary(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap()
}

/// The standard output of a command that succeeded.
fn succeeded(o: &Output) -> String {
    assert!(o.status.success(), "{}", stderr(o));
    stdout(o)
}

fn stderr(o: &Output) -> String {
    String::from_utf8(o.stderr.clone()).unwrap()
}

/// A failed command: exit code 2, one `error:` line, no panic.
fn assert_refused(o: &Output, needles: &[&str]) {
    let err = stderr(o);
    assert_eq!(o.status.code(), Some(2), "stderr: {err}");
    assert!(!err.contains("panicked"), "{err}");
    assert_eq!(err.lines().count(), 1, "one line: {err}");
    assert!(err.starts_with("error: "), "{err}");
    for n in needles {
        assert!(err.contains(n), "`{n}` not in: {err}");
    }
}

fn scenario_file(dir: &Path, text: &str) -> String {
    let f = dir.join("s.toml");
    std::fs::write(&f, text).unwrap();
    f.to_str().unwrap().to_owned()
}

fn json(o: &Output) -> serde_json::Value {
    serde_json::from_str(&succeeded(o)).unwrap()
}

const STUDY: &str = "[sim]\nduration = 4.0\ndt = 0.001\n[reference.circle]\nspeed = 0.5\nturn_rate = 0.2\nstart = { x = 0.0, y = 0.0, theta = 0.0 }\n[[agents]]\nstart = { x = -0.6, y = -0.2, theta = 0.0 }\nleader = \"reference\"\noffset = { x = 0.5, y = 0.3 }\n[odometry]\nzeta = 1e-5\n";
