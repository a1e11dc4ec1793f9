#![allow(clippy::unwrap_used)] // tests fail loudly by design
//! `echelon bench --drive velocity`: the velocity-base kernel's speed report,
//! its saturated ticks, thread independence and refusals.

use std::process::{Command, Output};

fn echelon(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_echelon"))
        .args(args)
        .output()
        .unwrap()
}

fn json(args: &[&str]) -> serde_json::Value {
    let o = echelon(args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{args:?}: {err}");
    serde_json::from_str(String::from_utf8_lossy(&o.stdout).trim()).unwrap()
}

#[test]
fn velocity_bench_reports_speed_and_saturation() {
    for topology in ["star", "chain"] {
        let v = json(&[
            "bench",
            "--drive",
            "velocity",
            "--agents",
            "9",
            "--topology",
            topology,
            "--duration",
            "0.5",
            "--dt",
            "0.01",
            "--threads",
            "2",
            "--json",
        ]);
        assert_eq!(v["drive"], "velocity");
        assert_eq!(v["topology"], topology);
        assert_eq!(v["steps"], 50);
        let (seconds, rate) = (
            v["seconds"].as_f64().unwrap(),
            v["agent_steps_per_s"].as_f64().unwrap(),
        );
        assert!((rate * seconds - 9.0 * 50.0).abs() < 1e-6 * rate * seconds);
        // The random starts are metres away: the Jackal's limits act, but not
        // on every tick.
        let ticks = v["saturated_ticks"].as_u64().unwrap();
        assert!(ticks > 0 && ticks < 9 * 50, "{ticks}");
    }
    // The default drive is torque, without saturation counts.
    let v = json(&[
        "bench",
        "--agents",
        "3",
        "--duration",
        "0.1",
        "--dt",
        "0.01",
        "--json",
    ]);
    assert_eq!(v["drive"], "torque");
    assert!(v.get("saturated_ticks").is_none());
    let o = echelon(&[
        "bench",
        "--drive",
        "velocity",
        "--agents",
        "5",
        "--duration",
        "0.1",
        "--dt",
        "0.01",
        "--runs",
        "3",
    ]);
    assert!(o.status.success());
    let text = String::from_utf8_lossy(&o.stdout);
    for needle in [
        "velocity drive",
        "5 agents × 3 runs",
        "saturated ticks",
        "‖e‖ max",
    ] {
        assert!(text.contains(needle), "`{needle}` not in {text}");
    }
}

#[test]
fn velocity_bench_does_not_depend_on_the_thread_count() {
    let run = |threads: &str| {
        let v = json(&[
            "bench",
            "--drive",
            "velocity",
            "--agents",
            "37",
            "--duration",
            "1",
            "--dt",
            "0.01",
            "--threads",
            threads,
            "--json",
        ]);
        (
            v["max_error"].as_f64().unwrap().to_bits(),
            v["saturated_ticks"].as_u64().unwrap(),
        )
    };
    assert_eq!(run("1"), run("2"));
}

#[test]
fn velocity_bench_refuses_a_step_longer_than_the_lag() {
    let o = echelon(&["bench", "--drive", "velocity", "--dt", "0.1"]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("tau_v") && !err.contains("panicked"), "{err}");
    let o = echelon(&["bench", "--drive", "sideways"]);
    assert_eq!(o.status.code(), Some(2));
}
