//! The progress bar on a terminal only, and a closed pipe.

use super::*;

/// The bar's delay, shortened so that any run of a few thousand steps is "long".
const NO_DELAY: (&str, &str) = ("ECHELON_PROGRESS_DELAY_MS", "0");

const LONG_RUN: [&str; 2] = ["run", "circle-pentagon"];

#[test]
fn no_progress_bar_when_stderr_is_not_a_terminal() {
    let dir = tempfile::tempdir().unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_echelon"))
        .args(LONG_RUN)
        .args(["--out", dir.path().to_str().unwrap()])
        .env(NO_DELAY.0, NO_DELAY.1)
        .output()
        .unwrap();
    assert!(o.status.success());
    assert_eq!(stderr(&o), "");
}

#[test]
fn progress_bar_on_a_terminal_for_long_runs() {
    // `script` (util-linux) runs the command on a pseudo-terminal.
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().to_str().unwrap();
    let screen = shows_progress(&on_terminal(
        &[&LONG_RUN[..], &["--out", out]].concat(),
        true,
    ));
    assert!(screen.contains("circle-pentagon: 4 agents"));
    // With the real delay (1 s), a short run shows none.
    let o = on_terminal(&["run", "nonfeasible", "--out", out], false);
    assert!(!stdout(&o).contains(" t = "), "{}", stdout(&o));
}

/// `echelon args` run on a pseudo-terminal by `script` (util-linux), with
/// the bar's delay shortened (`no_delay`) or real; its output is the screen.
pub(super) fn on_terminal(args: &[&str], no_delay: bool) -> Output {
    let command = format!("{} {}", env!("CARGO_BIN_EXE_echelon"), args.join(" "));
    let mut script = Command::new("script");
    script.args(["-qec", &command, "/dev/null"]);
    if no_delay {
        script.env(NO_DELAY.0, NO_DELAY.1);
    }
    script.output().expect("`script` (util-linux) runs")
}

/// The screen of a successful run, which showed the progress bar.
pub(super) fn shows_progress(o: &Output) -> String {
    let screen = succeeded(o);
    assert!(
        screen.contains("% ") && screen.contains(" t = "),
        "{screen}"
    );
    screen
}

#[test]
fn a_closed_pipe_ends_quietly_instead_of_panicking() {
    // `echelon … | head`: the reader goes away before echelon writes.
    let bench = [
        "bench",
        "--agents",
        "9",
        "--duration",
        "0.1",
        "--dt",
        "0.01",
    ];
    let bench_json = [&bench[..], &["--json"]].concat();
    for args in [
        &["show", "circle-pentagon"][..],
        &["scenarios"],
        &["umbmark"],
        &[
            "bound",
            "--zeta",
            "1e-4",
            "--steps",
            "10",
            "--omega-max",
            "1",
        ],
        &bench,
        &bench_json,
    ] {
        let mut child = Command::new(env!("CARGO_BIN_EXE_echelon"))
            .args(args)
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        drop(child.stdout.take());
        let o = child.wait_with_output().unwrap();
        let err = stderr(&o);
        assert!(!err.contains("panicked"), "{args:?}: {err}");
        assert_eq!(o.status.code(), Some(0), "{args:?}: {err}");
    }
}
