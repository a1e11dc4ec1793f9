//! The `echelon` binary, run as a user runs it.
#![allow(clippy::unwrap_used)] // tests fail loudly by design

use std::path::Path;
use std::process::{Command, Output};

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

/// `echelon run SCENARIO --out OUT EXTRA…`.
fn run(scenario: &str, out: &Path, extra: &[&str]) -> Output {
    let mut args = vec!["run", scenario, "--out", out.to_str().unwrap()];
    args.extend_from_slice(extra);
    echelon(&args)
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

#[test]
fn run_writes_the_documented_files_and_summary() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let o = run("nonfeasible", &out, &[]);
    let text = succeeded(&o);
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
    let summary: serde_json::Value = summary(&out);
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
    let o = run(
        "circle-pentagon",
        &out,
        &[
            "--duration",
            "2",
            "--dt",
            "0.002",
            "--log-dt",
            "0",
            "--law",
            "complete",
            "-q",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let summary: serde_json::Value = summary(&out);
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
    let o = run("lemniscate-wedge", &out, &["--duration", "0.5", "-q"]);
    assert!(o.status.success());
    let summary: serde_json::Value = summary(&out);
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
    let cases: [(String, &[&str]); 8] = [
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
        (
            GOOD.replace("dt = 0.01", "dt = 0.01\nbounds = { speed = 0.0 }"),
            &["s.toml:4:", "sim.bounds.speed", "> 0"],
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

/// Velocity bases (issue 11): a torque-only field on one, or the kinematic
/// law on a torque-driven robot, is refused at its field with exit 2.
/// The divergence guard (issue 20): a run whose state blows up stops at once
/// with one line naming the agent, the time and the quantity, exits 1 (not
/// 2: the input was valid), keeps what it wrote up to then, and its summary
/// says it diverged. The same in the torque crossing of issue 20, which used
/// to blow up silently and now converges (exit 0).
#[test]
fn a_diverging_run_exits_1_naming_agent_time_and_quantity() {
    let dir = tempfile::tempdir().unwrap();
    let source = echelon::scenario::Scenario::builtin("nonfeasible")
        .unwrap()
        .source()
        .replace("ke = 1.5", "ke = 1e12");
    let file = scenario_file(dir.path(), &source);
    let out = dir.path().join("out");
    let o = run(&file, &out, &["--mcap"]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "stderr: {err}");
    assert!(!err.contains("panicked"), "{err}");
    // The scenario's warnings about the gain (a line each), then one error line.
    let errors: Vec<&str> = err
        .lines()
        .filter(|l| !l.starts_with("warning: "))
        .collect();
    assert_eq!(errors.len(), 1, "one error line: {err}");
    for needle in [
        "error: ",
        "agent 1 (robot) diverged at t = ",
        "left its bound 100 m/s",
    ] {
        assert!(errors[0].contains(needle), "`{needle}` not in: {err}");
    }
    assert!(
        err.contains("control.ke"),
        "the gain is warned about: {err}"
    );
    assert!(stdout(&o).is_empty(), "no summary table: {}", stdout(&o));
    let s = summary(&out);
    assert_eq!(s["diverged"]["agent"], 1);
    assert_eq!(s["diverged"]["quantity"], "|v|");
    assert_eq!(s["diverged"]["bound"], 100.0);
    for f in [
        "trajectory.csv",
        "reference.csv",
        "scenario.toml",
        "run.mcap",
    ] {
        assert!(out.join(f).exists(), "{f} written");
    }
    // Every row written is within bounds.
    let rows = std::fs::read_to_string(out.join("trajectory.csv")).unwrap();
    for line in rows.lines().skip(1) {
        let v: f64 = line.split(',').nth(5).unwrap().parse().unwrap();
        assert!(v.abs() <= 100.0, "{line}");
    }
}

#[test]
fn bad_velocity_base_input_exits_2() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("never");
    let out_s = out.to_str().unwrap();
    let velocity = |fields: &str| {
        GOOD.replace(
            "[[agents]]",
            &format!("[robots.b]\ndrive = \"velocity\"\n{fields}\n[[agents]]\nrobot = \"b\""),
        )
    };
    let cases: [(String, &[&str]); 3] = [
        (
            velocity("mass = 1.0\n"),
            &["s.toml:11:8: robots.b.mass", "torque-driven robot's field"],
        ),
        (
            velocity("v_max = 0.0\n"),
            &["robots.b.v_max", "must be > 0"],
        ),
        (
            GOOD.to_owned() + "[control]\nlaw = \"kinematic\"\n",
            &["s.toml:14:7: control.law", "torque-driven"],
        ),
    ];
    for (text, needles) in cases {
        let f = scenario_file(dir.path(), &text);
        assert_refused(&echelon(&["run", &f, "--out", out_s]), needles);
        assert!(!out.exists(), "a refused run creates no output");
    }
    let f = scenario_file(dir.path(), &velocity(""));
    assert!(echelon(&["run", &f, "--out", out_s, "-q"]).status.success());
}

/// Safety filter (issue 15): impossible `[safety]` values and a robot that
/// starts inside an obstacle are refused at their field with exit 2; a good
/// one writes `safety.csv` and a `safety` block in `summary.json`.
#[test]
fn bad_safety_input_exits_2() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("never");
    let out_s = out.to_str().unwrap();
    let safety = |table: &str| format!("{GOOD}[safety]\n{table}");
    let cases: [(String, &[&str]); 4] = [
        (
            safety("radius = 0.0\n"),
            &["s.toml:14:10: safety.radius", "> 0"],
        ),
        (
            safety("radius = 0.2\ngain = -1.0\n"),
            &["s.toml:15:8: safety.gain"],
        ),
        (
            safety("radius = 0.2\nobstacles = [{ x = 3.0, y = 0.0, r = 0.0 }]\n"),
            &["s.toml:15:", "safety.obstacles[1].r", "> 0"],
        ),
        (
            safety("radius = 0.2\nobstacles = [{ x = -0.95, y = 0.0, r = 0.1 }]\n"),
            &["s.toml:10:", "agents[1].start", "obstacle 1"],
        ),
    ];
    for (text, needles) in cases {
        let f = scenario_file(dir.path(), &text);
        assert_refused(&echelon(&["run", &f, "--out", out_s]), needles);
        assert!(!out.exists(), "a refused run creates no output");
    }
    let f = scenario_file(dir.path(), &safety("radius = 0.2\n"));
    assert!(echelon(&["run", &f, "--out", out_s, "-q"]).status.success());
    assert!(out.join("safety.csv").exists());
    let summary = std::fs::read_to_string(out.join("summary.json")).unwrap();
    assert!(summary.contains("\"safety\""), "{summary}");
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

fn json(o: &Output) -> serde_json::Value {
    serde_json::from_str(&succeeded(o)).unwrap()
}

#[test]
fn bound_forward_and_inverse_agree() {
    let common = [
        "bound",
        "--ke",
        "1.5",
        "--kz",
        "10",
        "--zeta",
        "1e-4",
        "--omega-max",
        "1",
        "--gamma",
        "0.5",
    ];
    let forward = json(&echelon(
        &[&common[..], &["--steps", "1000", "--ts", "0.01", "--json"]].concat(),
    ));
    let z = forward["z_bound"].as_f64().unwrap();
    let want = 2f64.sqrt() * 1.5 * 1000.0 * 1e-4 * 101f64.sqrt() / (10.0 * 0.5);
    assert!((z - want).abs() < 1e-12 * want, "{forward}");
    assert_eq!(forward["steps"], 1000);
    assert!((forward["fix_period_s"].as_f64().unwrap() - 10.0).abs() < 1e-9);
    // The inverse of that bound is N = 1000 again, and N + 1 would exceed it.
    let z_text = format!("{z:e}");
    let inverse = json(&echelon(
        &[&common[..], &["--max-z", &z_text, "--ts", "0.01", "--json"]].concat(),
    ));
    assert_eq!(inverse["steps"], 1000, "{inverse}");
    let inverse = json(&echelon(
        &[&common[..], &["--max-z", "0.05", "--json"]].concat(),
    ));
    let n = inverse["steps"].as_u64().unwrap();
    assert!(n as f64 * want / 1000.0 <= 0.05 && (n + 1) as f64 * want / 1000.0 > 0.05);
    assert!(inverse["fix_period_s"].is_null());
    // --max-e: ‖e‖ ≤ ‖z‖/K_e.
    let by_e = json(&echelon(
        &[&common[..], &["--max-e", "0.02", "--json"]].concat(),
    ));
    assert_eq!(
        by_e["steps"],
        json(&echelon(
            &[&common[..], &["--max-z", "0.03", "--json"]].concat()
        ))["steps"]
    );
    let text = stdout(&echelon(
        &[&common[..], &["--max-z", "0.05", "--ts", "0.01"]].concat(),
    ));
    assert!(
        text.contains(&format!("N = {n} samples")) && text.contains("fix at least every"),
        "{text}"
    );
}

/// `--law kinematic`: `‖e‖ ≤ √2 N ζ / γ` both ways, the largest `N` its
/// own inverse, over a grid of inputs; `--max-z` and a dynamic bound
/// without `--omega-max` are refused.
#[test]
fn bound_for_the_kinematic_law() {
    for (ke, zeta, gamma, max_e) in [
        ("1.0", "1e-4", "0.99", "0.05"),
        ("2.5", "3e-6", "0.5", "0.02"),
        ("0.3", "1e-3", "0.9", "0.4"),
    ] {
        let common = [
            "bound",
            "--law",
            "kinematic",
            "--ke",
            ke,
            "--zeta",
            zeta,
            "--gamma",
            gamma,
        ];
        let inv = json(&echelon(
            &[&common[..], &["--max-e", max_e, "--ts", "0.02", "--json"]].concat(),
        ));
        let (z, g, e): (f64, f64, f64) = (
            zeta.parse().unwrap(),
            gamma.parse().unwrap(),
            max_e.parse().unwrap(),
        );
        let per = 2f64.sqrt() * z / g;
        let n = inv["steps"].as_u64().unwrap();
        assert!(n as f64 * per <= e && (n + 1) as f64 * per > e, "{inv}");
        assert!((inv["fix_period_s"].as_f64().unwrap() - 0.02 * n as f64).abs() < 1e-9);
        let n_text = n.to_string();
        let fwd = json(&echelon(
            &[&common[..], &["--steps", &n_text, "--json"]].concat(),
        ));
        assert!((fwd["e_bound"].as_f64().unwrap() - n as f64 * per).abs() < 1e-12);
        let want_z = 2f64.sqrt() * ke.parse::<f64>().unwrap() * z * n as f64;
        assert!((fwd["z_bound"].as_f64().unwrap() - want_z).abs() < 1e-12 * want_z.max(1.0));
    }
    assert_refused(
        &echelon(&[
            "bound",
            "--law",
            "kinematic",
            "--zeta",
            "1e-4",
            "--max-z",
            "0.1",
        ]),
        &["--max-e"],
    );
    assert_refused(
        &echelon(&["bound", "--zeta", "1e-4", "--steps", "10"]),
        &["--omega-max"],
    );
}

#[test]
fn bound_refuses_inputs_outside_the_theorem() {
    let bound = ["bound", "--zeta", "1e-4", "--omega-max", "1"];
    for (args, needle) in [
        (&["--gamma", "1"][..], "gamma"),
        (&["--gamma", "0"], "gamma"),
        (&["--ke", "-1"], "--ke"),
        (&["--kz", "0"], "--kz"),
        (&["--zeta", "0"], "--zeta"),
    ] {
        let all = [&bound[..], &["--steps", "10"], args].concat();
        assert_refused(&echelon(&all), &[needle]);
    }
    assert_refused(&echelon(&bound), &["--steps"]);
    assert_refused(
        &echelon(&[&bound[..], &["--steps", "0"]].concat()),
        &["--steps 0"],
    );
}

const STUDY: &str = "[sim]\nduration = 4.0\ndt = 0.001\n[reference.circle]\nspeed = 0.5\nturn_rate = 0.2\nstart = { x = 0.0, y = 0.0, theta = 0.0 }\n[[agents]]\nstart = { x = -0.6, y = -0.2, theta = 0.0 }\nleader = \"reference\"\noffset = { x = 0.5, y = 0.3 }\n[odometry]\nzeta = 1e-5\n";

#[test]
fn sweep_writes_one_row_per_run_the_same_on_any_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    let file = scenario_file(dir.path(), STUDY);
    let run = |threads: &str, out: &str| {
        let out = dir.path().join(out);
        let o = echelon(&[
            "sweep",
            &file,
            "--zeta",
            "1e-5,2e-5",
            "--fix-every",
            "0,100,500",
            "--slip",
            "0,1e-6",
            "--seeds",
            "2",
            "--threads",
            threads,
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        (
            stdout(&o),
            std::fs::read_to_string(out.join("sweep.csv")).unwrap(),
        )
    };
    let (text, one) = run("1", "a");
    for f in ["drift.csv", "sweep.svg", "sweep.png"] {
        assert!(dir.path().join("a").join(f).exists(), "{f}");
    }
    let (_, two) = run("2", "b");
    assert_eq!(one, two, "sweep.csv depends on the thread count");
    let mut lines = one.lines();
    assert_eq!(lines.next().unwrap(), echelon::sweep::SWEEP_HEADER);
    assert_eq!(lines.count(), 2 * 3 * 2 * 2, "ζ × N × slip × seeds");
    assert!(text.contains("24 runs on 1 threads"), "{text}");
    // Rows under Theorem 2's assumptions carry the bound, and respect it.
    for row in one.lines().skip(1) {
        let cells: Vec<&str> = row.split(',').collect();
        let (slip, n, ratio) = (cells[4], cells[5], cells[14]);
        if slip == "0.0" && n != "0" {
            assert!(ratio.parse::<f64>().unwrap() < 1.0, "{row}");
        } else {
            assert!(ratio.is_empty(), "no bound outside the theorem: {row}");
        }
    }
    assert_refused(&echelon(&["sweep", &file, "--gamma", "1"]), &["gamma"]);
    assert_refused(&echelon(&["sweep", &file, "--ed", "0"]), &["--ed"]);
}

#[test]
fn a_velocity_sweep_fills_the_bound_columns_with_the_kinematic_form() {
    // The ideal velocity bases of circle-pentagon-velocity under the kinematic
    // law: z_bound = √2 K_e N ζ, e_bound = √2 N ζ / γ, ratio ‖e‖/e_bound.
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("v");
    let o = echelon(&[
        "sweep",
        "circle-pentagon-velocity",
        "--zeta-model",
        "worst-case",
        "--fix-every",
        "0,100",
        "--seeds",
        "1",
        "--duration",
        "14",
        "--transient",
        "10",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("‖e‖/e bound"), "{}", stdout(&o));
    let csv = std::fs::read_to_string(out.join("sweep.csv")).unwrap();
    let rows: Vec<Vec<&str>> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect())
        .collect();
    assert_eq!(rows.len(), 2);
    assert!(rows[0][13].is_empty(), "no fixes, no bound");
    let num = |c: &str| c.parse::<f64>().unwrap();
    let r = &rows[1];
    let (e_max, z_bound, ratio, e_bound) = (num(r[10]), num(r[13]), num(r[14]), num(r[15]));
    let sqrt2 = std::f64::consts::SQRT_2;
    assert!((z_bound - sqrt2 * 1.5 * 100.0 * 1e-5).abs() < 1e-15);
    assert!((e_bound - sqrt2 * 100.0 * 1e-5 / 0.99).abs() < 1e-15);
    assert!(
        (ratio - e_max / e_bound).abs() < 1e-12 && ratio < 1.0,
        "{r:?}"
    );
}

#[test]
fn umbmark_estimates_and_writes_its_results() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("u");
    let o = echelon(&[
        "umbmark",
        "--ed",
        "1.004",
        "--eb",
        "1.015",
        "--slip",
        "1e-7",
        "--seed",
        "2",
        "--json",
        "--out",
        out.to_str().unwrap(),
    ]);
    let c = json(&o);
    let ed = c["refined"]["ed"].as_f64().unwrap();
    let eb = c["refined"]["eb"].as_f64().unwrap();
    assert!(
        (ed - 1.004).abs() < 0.1 * 0.004 && (eb - 1.015).abs() < 0.1 * 0.015,
        "{c}"
    );
    let csv = std::fs::read_to_string(out.join("umbmark.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 10);
    assert!(out.join("calibration.json").exists());
    let text = stdout(&echelon(&["umbmark", "--ed", "1.004", "--eb", "1.015"]));
    assert!(
        text.contains("Borenstein") && text.contains("corrections: left wheel diameter ×"),
        "{text}"
    );
    assert_refused(
        &echelon(&["umbmark", "--robot", "agent9"]),
        &["unknown robot"],
    );
    assert_refused(
        &echelon(&["umbmark", "--from-log", "/no/such/run"]),
        &["/no/such/run"],
    );
}

#[test]
fn run_writes_odometry_csv_when_agents_dead_reckon() {
    let dir = tempfile::tempdir().unwrap();
    let file = scenario_file(dir.path(), STUDY);
    let out = dir.path().join("r");
    let o = run(&file, &out, &["--seed", "3"]);
    assert!(succeeded(&o).contains("odometry.csv"));
    let odo = std::fs::read_to_string(out.join("odometry.csv")).unwrap();
    assert_eq!(
        odo.lines().next(),
        Some("t,agent,x_hat,y_hat,theta_hat,ex_hat,ey_hat,zx_hat,zy_hat,fix")
    );
    assert_eq!(
        odo.lines().count(),
        std::fs::read_to_string(out.join("trajectory.csv"))
            .unwrap()
            .lines()
            .count()
    );
    // Without odometry no odometry.csv is written.
    let plain = dir.path().join("p");
    assert!(
        run("nonfeasible", &plain, &["--duration", "1", "-q"])
            .status
            .success()
    );
    assert!(!plain.join("odometry.csv").exists());
}

#[test]
fn run_plot_writes_figures_and_report_and_plot_redraws_them() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cp");
    let o = run("circle-pentagon", &out, &["--duration", "5", "--plot"]);
    let text = succeeded(&o);
    for f in [
        "trajectory.csv",
        "reference.csv",
        "summary.json",
        "scenario.toml",
        "paths.svg",
        "paths.png",
        "errors.svg",
        "errors.png",
        "signals.svg",
        "signals.png",
        "report.html",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
        assert!(text.contains(f), "stdout does not name {f}: {text}");
    }
    // `plot` works from the directory alone, with the same result.
    let before = std::fs::read(out.join("report.html")).unwrap();
    std::fs::remove_file(out.join("paths.svg")).unwrap();
    let o = echelon(&["plot", out.to_str().unwrap(), "--quiet"]);
    assert!(succeeded(&o).is_empty());
    assert!(out.join("paths.svg").is_file());
    assert!(std::fs::read(out.join("report.html")).unwrap() == before);
    // The recorded scenario names the overrides of the run.
    let scenario = std::fs::read_to_string(out.join("scenario.toml")).unwrap();
    assert!(scenario.contains("# overrides: --duration 5"), "{scenario}");
}

#[test]
fn plot_refuses_a_directory_that_is_not_a_run() {
    let dir = tempfile::tempdir().unwrap();
    let o = echelon(&["plot", dir.path().to_str().unwrap()]);
    assert_refused(&o, &["summary.json"]);
    std::fs::write(dir.path().join("summary.json"), "{").unwrap();
    let o = echelon(&["plot", dir.path().to_str().unwrap()]);
    assert_refused(&o, &["summary.json", "EOF"]);
    assert!(!dir.path().join("report.html").exists());
}

#[test]
fn lycomp_prints_the_largest_gap_and_writes_fig_5() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("ly");
    let o = echelon(&["lycomp", "--lxoff", "0.5", "--out", out.to_str().unwrap()]);
    let text = succeeded(&o);
    // docs/control-law.md: the largest gap is 0.23 m, near |R_C| = 0.7.
    assert!(
        text.contains("largest gap to eq. 5: 0.230 m at |R_C| = 0.705 m"),
        "{text}"
    );
    assert!(!text.contains("least squares"));
    assert!(out.join("lycomp.svg").is_file() && out.join("lycomp.png").is_file());
    let svg = std::fs::read_to_string(out.join("lycomp.svg")).unwrap();
    assert!(svg.contains("R_C [m]") && svg.contains("L_Ycomp [m]"));

    let o = echelon(&[
        "lycomp",
        "--fit",
        "--lxoff",
        "0.5",
        "--out",
        out.to_str().unwrap(),
    ]);
    let text = succeeded(&o);
    assert!(
        text.contains("eq. 6, least squares   G = 0.213724  δ = 0.450806  ε = 0.702275  largest gap to eq. 5: 0.122 m"),
        "{text}"
    );
    // Outside the paper's range: a warning and the refit.
    let o = echelon(&["lycomp", "--lxoff", "2", "--out", out.to_str().unwrap()]);
    assert!(o.status.success());
    assert!(stderr(&o).starts_with("warning: the paper's polynomials"));
    assert!(stdout(&o).contains("least squares"));
    for bad in ["0", "-1", "nan", "x"] {
        assert_refused(&echelon(&["lycomp", "--lxoff", bad]), &["--lxoff"]);
    }
}

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
    let command = format!(
        "{} {} --out {}",
        env!("CARGO_BIN_EXE_echelon"),
        LONG_RUN.join(" "),
        dir.path().display()
    );
    let o = Command::new("script")
        .args(["-qec", &command, "/dev/null"])
        .env(NO_DELAY.0, NO_DELAY.1)
        .output()
        .expect("`script` (util-linux) runs");
    let screen = succeeded(&o);
    assert!(
        screen.contains("% ") && screen.contains(" t = "),
        "{screen}"
    );
    assert!(screen.contains("circle-pentagon: 4 agents"));
    // With the real delay (1 s), a short run shows none.
    let command = format!(
        "{} run nonfeasible --out {}",
        env!("CARGO_BIN_EXE_echelon"),
        dir.path().display()
    );
    let o = Command::new("script")
        .args(["-qec", &command, "/dev/null"])
        .output()
        .unwrap();
    assert!(!stdout(&o).contains(" t = "), "{}", stdout(&o));
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
    let o = echelon(&["bench", "--drive", "sideways"]);
    assert_eq!(o.status.code(), Some(2));
}
