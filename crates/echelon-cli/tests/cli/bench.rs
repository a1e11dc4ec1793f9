//! `echelon bench`.

use super::*;

/// `echelon bench --drive DRIVE --json` plus `extra` flags.
fn bench_json(drive: &str, extra: &[&str]) -> serde_json::Value {
    let mut args = vec!["bench", "--drive", drive, "--json", "--dt", "0.01"];
    args.extend_from_slice(extra);
    json(&echelon(&args))
}

#[test]
fn bench_reports_agent_steps_per_second_as_json_and_text() {
    for drive in ["torque", "velocity"] {
        for topology in ["star", "chain"] {
            let v = bench_json(
                drive,
                &[
                    "--agents",
                    "9",
                    "--topology",
                    topology,
                    "--duration",
                    "0.5",
                    "--threads",
                    "2",
                ],
            );
            assert_eq!(v["drive"], drive);
            assert_eq!(v["agents"], 9);
            assert_eq!(v["steps"], 50);
            assert_eq!(v["topology"], topology);
            assert_eq!(v["threads"], 2);
            let (seconds, rate) = (
                v["seconds"].as_f64().unwrap(),
                v["agent_steps_per_s"].as_f64().unwrap(),
            );
            assert!(seconds > 0.0);
            assert!(
                (rate * seconds - 9.0 * 50.0).abs() < 1e-6 * rate * seconds,
                "rate = N steps / s"
            );
            assert!(v["bytes_per_agent"].as_f64().unwrap() > 0.0);
            if drive == "velocity" {
                // The random starts are metres away: the Jackal's limits act,
                // but not on every tick.
                let ticks = v["saturated_ticks"].as_u64().unwrap();
                assert!(ticks > 0 && ticks < 9 * 50, "{ticks}");
            } else {
                assert!(v.get("saturated_ticks").is_none());
            }
        }
        let o = echelon(&[
            "bench",
            "--drive",
            drive,
            "--agents",
            "5",
            "--duration",
            "0.1",
            "--dt",
            "0.01",
            "--runs",
            "3",
        ]);
        let text = succeeded(&o);
        let mut needles = vec![
            "5 agents × 3 runs",
            "10 steps",
            "M agent-steps/s",
            "‖e‖ max",
        ];
        if drive == "velocity" {
            needles.extend(["velocity drive", "saturated ticks"]);
        } else {
            needles.push("B per agent");
        }
        for needle in needles {
            assert!(text.contains(needle), "{drive}: `{needle}` not in {text}");
        }
    }
    // The default drive is torque.
    let v = json(&echelon(&[
        "bench",
        "--agents",
        "3",
        "--duration",
        "0.1",
        "--dt",
        "0.01",
        "--json",
    ]));
    assert_eq!(v["drive"], "torque");
}

#[test]
fn bench_results_do_not_depend_on_the_thread_count() {
    for drive in ["torque", "velocity"] {
        let run = |threads: &str| {
            let v = bench_json(
                drive,
                &["--agents", "37", "--duration", "1", "--threads", threads],
            );
            (
                v["max_error"].as_f64().unwrap().to_bits(),
                v["saturated_ticks"].as_u64(),
            )
        };
        assert_eq!(run("1"), run("2"), "{drive}");
    }
}

#[test]
fn bench_refuses_bad_input_in_one_line() {
    for (args, needle) in [
        (&["bench", "--agents", "0"][..], "≥ 1"),
        (&["bench", "--threads", "0"], "≥ 1"),
        (&["bench", "--agents", "many"], "whole number"),
        (&["bench", "--dt", "-1"], "> 0"),
        (&["bench", "--topology", "ring"], "ring"),
        (
            &["bench", "--agents", "1000000", "--runs", "256"],
            "at most",
        ),
    ] {
        assert_refused(&echelon(args), &[needle]);
    }
}

// `echelon bench --drive velocity`: the velocity-base kernel's speed report,
// its saturated ticks, thread independence and refusals.
#[test]
fn velocity_bench_refuses_a_step_longer_than_the_lag() {
    let o = echelon(&["bench", "--drive", "velocity", "--dt", "0.1"]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("tau_v") && !err.contains("panicked"), "{err}");
    // The message names the flag the user gave, its value and what would
    // do, for any step past the lag.
    for dt in ["0.0500001", "0.3", "2", "1000"] {
        assert_refused(
            &echelon(&["bench", "--drive", "velocity", "--dt", dt]),
            &["--dt", dt, "lag", "--dt ≤ 0.05"],
        );
    }
    let o = echelon(&["bench", "--drive", "sideways"]);
    assert_eq!(o.status.code(), Some(2));
}

/// A bench on a terminal shows a progress bar on stderr once it is long (the
/// delay shortened to 0 here); piped, stderr holds the one "stepping" line and
/// stdout the same report as ever.
#[test]
fn a_long_bench_shows_progress_on_a_terminal_only() {
    let args = [
        "bench",
        "--agents",
        "64",
        "--duration",
        "4",
        "--dt",
        "0.001",
    ];
    let screen = super::terminal::shows_progress(&super::terminal::on_terminal(&args, true));
    assert!(screen.contains("M agent-steps/s"), "{screen}");
    let piped = Command::new(env!("CARGO_BIN_EXE_echelon"))
        .args(args)
        .env("ECHELON_PROGRESS_DELAY_MS", "0")
        .output()
        .unwrap();
    let err = stderr(&piped);
    assert!(
        err.starts_with("stepping 1 × 64 agents for 4000 steps") && err.lines().count() == 1,
        "{err}"
    );
    assert!(succeeded(&piped).contains("4000 steps of 0.001 s"));
}

/// A bench whose formation diverges (a step far too long) says so and exits
/// 1, as a diverged `echelon run` does, not 2 (the input was accepted).
#[test]
fn a_diverged_bench_says_so_and_exits_1() {
    for dt in ["0.9", "0.5"] {
        let o = echelon(&["bench", "--agents", "10", "--dt", dt, "--duration", "100"]);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{err}");
        assert!(
            err.contains("the formation diverged") && !err.contains("panicked"),
            "{err}"
        );
        assert_eq!(stdout(&o), "");
    }
}
