//! The `echelon` binary, run as a user runs it.
#![allow(clippy::unwrap_used)] // tests fail loudly by design

use std::path::Path;
use std::process::{Command, Output};

const NAMES: [&str; 5] = [
    "circle-pentagon",
    "experiment-circle",
    "experiment-lemniscate",
    "lemniscate-wedge",
    "nonfeasible",
];

fn echelon(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_echelon"))
        .args(args)
        .output()
        .expect("the echelon binary runs")
}

fn stdout(o: &Output) -> String {
    String::from_utf8(o.stdout.clone()).unwrap()
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

#[test]
fn every_command_has_help() {
    for args in [
        &["--help"][..],
        &["run", "--help"],
        &["scenarios", "--help"],
        &["show", "--help"],
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
    let names: Vec<&str> = text
        .lines()
        .map(|l| l.split_whitespace().next().unwrap())
        .collect();
    assert_eq!(names, NAMES);
    assert!(text.lines().all(|l| l.contains("Fig")));
}

#[test]
fn show_round_trips_into_run() {
    let dir = tempfile::tempdir().unwrap();
    for name in NAMES {
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
            let o = echelon(&[
                "run",
                scenario,
                "--out",
                out.to_str().unwrap(),
                "--duration",
                "8",
                "-q",
            ]);
            assert!(o.status.success(), "{}", stderr(&o));
            assert!(stdout(&o).is_empty(), "--quiet prints nothing");
        }
        for f in ["trajectory.csv", "summary.json"] {
            assert!(
                std::fs::read(a.join(f)).unwrap() == std::fs::read(b.join(f)).unwrap(),
                "{name}: {f} differs between the built-in and its shown TOML"
            );
        }
    }
}

#[test]
fn run_writes_the_documented_files_and_summary() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let o = echelon(&["run", "nonfeasible", "--out", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stdout(&o);
    assert!(
        text.contains("nonfeasible: 1 agent, 10 s at dt = 0.001 s (10000 steps)"),
        "{text}"
    );
    assert!(
        text.contains("robot") && text.contains("reference"),
        "{text}"
    );
    let csv = std::fs::read_to_string(out.join("trajectory.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(
        lines.next(),
        Some("t,agent,x,y,theta,v,omega,ex,ey,zx,zy,u1,u2,tau_r,tau_l")
    );
    assert_eq!(
        lines.next().unwrap().split(',').take(5).collect::<Vec<_>>(),
        ["0", "1", "-4.0", "0.4", "-1.5707963267948966"]
    );
    assert_eq!(csv.lines().count(), 1 + 1001, "every 10 ms from 0 to 10 s");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let agent = &summary["agents"][0];
    for key in [
        "final_pose",
        "final_error",
        "rms_error",
        "peak_torque",
        "settle_time",
    ] {
        assert!(agent.get(key).is_some(), "summary has {key}: {summary}");
    }
    assert!(agent["final_error"].as_f64().unwrap() < 1e-3);
    assert!(agent["settle_time"].as_f64().unwrap() < 10.0);
}

#[test]
fn overrides_change_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("o");
    let o = echelon(&[
        "run",
        "circle-pentagon",
        "--out",
        out.to_str().unwrap(),
        "--duration",
        "2",
        "--dt",
        "0.002",
        "--log-dt",
        "0",
        "--law",
        "complete",
        "-q",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["steps"], 1000);
    assert_eq!(summary["dt"], 0.002);
    let rows = std::fs::read_to_string(out.join("trajectory.csv"))
        .unwrap()
        .lines()
        .count()
        - 1;
    assert_eq!(rows, 1001 * 4, "--log-dt 0 logs every step of every agent");
}

#[test]
fn settle_time_is_null_when_never_within_a_centimetre() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("short");
    let o = echelon(&[
        "run",
        "lemniscate-wedge",
        "--out",
        out.to_str().unwrap(),
        "--duration",
        "0.5",
        "-q",
    ]);
    assert!(o.status.success());
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert!(summary["agents"][1]["settle_time"].is_null(), "{summary}");
}

fn scenario_file(dir: &Path, text: &str) -> String {
    let f = dir.join("s.toml");
    std::fs::write(&f, text).unwrap();
    f.to_str().unwrap().to_owned()
}

const GOOD: &str = "[sim]\nduration = 1.0\ndt = 0.01\n\n[reference.line]\nspeed = 0.3\nstart = { x = 0.0, y = 0.0, theta = 0.0 }\n\n[[agents]]\nstart = { x = -1.0, y = 0.0, theta = 0.0 }\nleader = \"reference\"\noffset = { x = 0.5, y = 0.0 }\n";

#[test]
fn bad_input_exits_2_with_one_line_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("never");
    let out_s = out.to_str().unwrap();
    let good = scenario_file(dir.path(), GOOD);
    assert!(
        echelon(&["run", &good, "--out", out_s, "-q"])
            .status
            .success()
    );
    std::fs::remove_dir_all(&out).unwrap();
    let cases: [(String, &[&str]); 7] = [
        (GOOD.replace("[sim]", "[sim"), &["s.toml:1:"]),
        (
            GOOD.replace("dt = 0.01", "dt = \"small\""),
            &["s.toml:3:6: sim.dt: invalid type"],
        ),
        (
            GOOD.replace("leader", "leadr"),
            &["s.toml:11:1: agents[1].leadr: unknown field"],
        ),
        (
            GOOD.replace("x = 0.5", "x = -0.5"),
            &["s.toml:12:16: agents[1].offset.x", "L_X = L_Xoff + L"],
        ),
        (
            GOOD.to_owned() + "[control]\nl = -0.05\n",
            &["s.toml:14:5: control.l", "> 0"],
        ),
        (
            GOOD.replace("theta = 0.0 }\nleader", "theta = nan }\nleader"),
            &["agents[1].start.theta", "finite"],
        ),
        (
            GOOD.replace(
                "[[agents]]",
                "[robots.r]\npreset = \"agent2\"\nmass = -1.0\n\n[[agents]]\nrobot = \"r\"",
            ),
            &["robots.r.mass", "must be > 0"],
        ),
    ];
    for (text, needles) in cases {
        let f = scenario_file(dir.path(), &text);
        let o = echelon(&["run", &f, "--out", out_s]);
        assert_refused(&o, needles);
        assert!(!out.exists(), "a refused run creates no output");
    }
    let cycle = GOOD.replace("leader = \"reference\"", "leader = 2")
        + "\n[[agents]]\nstart = { x = -2.0, y = 0.0, theta = 0.0 }\nleader = 1\noffset = { x = 0.5, y = 0.0 }\n";
    assert_refused(
        &echelon(&["run", &scenario_file(dir.path(), &cycle), "--out", out_s]),
        &["agents[1].leader", "agents 1 → 2 → 1 form a cycle"],
    );
    assert_refused(
        &echelon(&["run", "no-such-scenario"]),
        &["no built-in scenario"],
    );
    assert_refused(
        &echelon(&["run", "/no/such/file.toml"]),
        &["/no/such/file.toml: cannot read"],
    );
    assert_refused(
        &echelon(&["show", "nope"]),
        &["no built-in scenario `nope`"],
    );
    assert!(!out.exists());
}

#[test]
fn bad_flags_exit_2() {
    for args in [
        &["run", "nonfeasible", "--dt", "-1"][..],
        &["run", "nonfeasible", "--dt", "0"],
        &["run", "nonfeasible", "--duration", "nan"],
        &["run", "nonfeasible", "--law", "best"],
        &["frobnicate"],
    ] {
        assert_refused(&echelon(args), &["(see --help)"]);
    }
    assert_refused(
        &echelon(&["run", "nonfeasible", "--law", "best"]),
        &["possible values: paper, complete"],
    );
    let o = echelon(&[
        "run",
        "nonfeasible",
        "--dt",
        "0.003",
        "--out",
        "/nonexistent/never",
    ]);
    assert_refused(&o, &["log.dt", "--log-dt"]);
}

#[test]
fn bench_reports_agent_steps_per_second_as_json_and_text() {
    for topology in ["star", "chain"] {
        let o = echelon(&[
            "bench",
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
        assert!(o.status.success(), "{}", stderr(&o));
        let v: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
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
    }
    let o = echelon(&[
        "bench",
        "--agents",
        "5",
        "--duration",
        "0.1",
        "--dt",
        "0.01",
        "--runs",
        "3",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stdout(&o);
    for needle in [
        "5 agents × 3 runs",
        "10 steps",
        "M agent-steps/s",
        "B per agent",
        "‖e‖ max",
    ] {
        assert!(text.contains(needle), "`{needle}` not in {text}");
    }
}

#[test]
fn bench_results_do_not_depend_on_the_thread_count() {
    let run = |threads: &str| {
        let o = echelon(&[
            "bench",
            "--agents",
            "21",
            "--duration",
            "1",
            "--dt",
            "0.01",
            "--threads",
            threads,
            "--json",
        ]);
        let v: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
        v["max_error"].as_f64().unwrap().to_bits()
    };
    assert_eq!(run("1"), run("2"));
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
