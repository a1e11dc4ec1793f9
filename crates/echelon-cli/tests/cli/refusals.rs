//! Bad input: exit 2 with one line, nothing written; a diverging run exits 1.

use super::*;

const GOOD: &str = "[sim]\nduration = 1.0\ndt = 0.01\n\n[reference.line]\nspeed = 0.3\nstart = { x = 0.0, y = 0.0, theta = 0.0 }\n\n[[agents]]\nstart = { x = -1.0, y = 0.0, theta = 0.0 }\nleader = \"reference\"\noffset = { x = 0.5, y = 0.0 }\n";

/// `echelon run` refuses each scenario text naming each of its needles
/// (files `dir/s.toml`), and creates no `out`.
fn refuses_each<'a>(
    dir: &Path,
    out: &Path,
    cases: impl IntoIterator<Item = (String, &'a [&'a str])>,
) {
    for (text, needles) in cases {
        let f = scenario_file(dir, &text);
        assert_refused(
            &echelon(&["run", &f, "--out", out.to_str().unwrap()]),
            needles,
        );
        assert!(!out.exists(), "a refused run creates no output");
    }
}

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
    refuses_each(dir.path(), &out, cases);
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

/// A diverged run says so wherever it is looked at: `run --plot` still draws
/// its figures (they show what went wrong) and exits 1; its report.html
/// names the divergence; `echelon plot` on its directory exits 1 naming it
/// (it exited 0, and the report said nothing, as if the run had ended).
/// For built-ins of both drives, blown up by each gain; a run that does not
/// diverge, plotted into the same directory, exits 0 and its report is clean.
#[test]
fn a_diverged_run_says_so_in_its_report_and_plot_exits_1() {
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        ("nonfeasible", "ke = 1.5", "ke = 1e12"),
        ("experiment-circle", "kz = 10.0", "kz = 1e12"),
        ("circle-pentagon-velocity", "ke = 1.5", "ke = 1e9"),
    ];
    for (i, (name, from, to)) in cases.into_iter().enumerate() {
        let source = echelon::scenario::Scenario::builtin(name)
            .unwrap()
            .source()
            .to_owned();
        assert!(source.contains(from), "{name} has `{from}`");
        let file = dir.path().join(format!("{i}.toml"));
        std::fs::write(&file, source.replace(from, to)).unwrap();
        let out = dir.path().join(format!("out{i}"));
        let o = run(file.to_str().unwrap(), &out, &["--plot", "--quiet"]);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{name}: {err}");
        assert!(!err.contains("panicked"), "{name}: {err}");
        let message = summary(&out)["diverged"]["message"]
            .as_str()
            .expect("summary.json says it diverged")
            .to_owned();
        assert!(err.contains(&message), "{name}: `{message}` not in {err}");
        let report = std::fs::read_to_string(out.join("report.html"))
            .unwrap_or_else(|e| panic!("{name}: --plot drew no report: {e}"));
        assert!(
            report.contains("id=\"diverged\"") && report.contains(&message),
            "{name}: the report does not say `{message}`"
        );
        for f in ["paths.svg", "errors.png", "signals.svg"] {
            assert!(out.join(f).exists(), "{name}: {f} drawn");
        }
        let o = echelon(&["plot", out.to_str().unwrap(), "--quiet"]);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{name}: plot: {err}");
        assert!(
            err.starts_with("error: ") && err.contains(&message) && err.lines().count() == 1,
            "{name}: plot: {err}"
        );
        // The same directory, rewritten by a run that does not diverge.
        let o = run(name, &out, &["--duration", "0.5", "--quiet"]);
        assert_eq!(o.status.code(), Some(0), "{name}: {}", stderr(&o));
        let o = echelon(&["plot", out.to_str().unwrap(), "--quiet"]);
        assert_eq!(o.status.code(), Some(0), "{name}: plot: {}", stderr(&o));
        let report = std::fs::read_to_string(out.join("report.html")).unwrap();
        assert!(
            !report.contains("id=\"diverged\""),
            "{name}: a clean run's report"
        );
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
    refuses_each(dir.path(), &out, cases);
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
    refuses_each(dir.path(), &out, cases);
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
    // The flag changed the step: it is named first, the file's log.dt after.
    assert_refused(&o, &["command line: --dt: 0.003 s", "log.dt", "--log-dt"]);
}

/// A fleet time or timeout no `std::time::Duration` holds (or a time scale
/// that makes the run's real length one) used to panic (exit 101) in
/// `fleet up`, `fleet stop`, `fleet leader`: each is refused at its flag,
/// at every magnitude, before anything starts.
#[test]
fn fleet_times_beyond_any_duration_are_refused_at_their_flag() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("never");
    let out_s = out.to_str().unwrap();
    let up = ["fleet", "up", "circle-pentagon", "--out", out_s];
    for exp in (10..=300).step_by(29) {
        let big = format!("1e{exp}");
        let tiny = format!("1e-{exp}");
        for (args, flag) in [
            ([&up[..], &["--duration", &big]].concat(), "--duration"),
            (
                [&up[..], &["--duration", "1", "--time-scale", &tiny]].concat(),
                "--time-scale",
            ),
            ([&up[..], &["--time-scale", &big]].concat(), "--time-scale"),
            (
                vec!["fleet", "stop", "circle-pentagon", "--timeout", &big],
                "--timeout",
            ),
            (
                vec!["fleet", "leader", "circle-pentagon", "--wait-timeout", &big],
                "--wait-timeout",
            ),
            (
                vec!["fleet", "bench", "--duration", &big, "--out", out_s],
                "--duration",
            ),
        ] {
            assert_refused(&echelon(&args), &[flag]);
            assert!(!out.exists(), "{args:?} wrote {out_s}");
        }
    }
}

/// An I/O failure is said once: the libraries' errors carry their I/O
/// cause in their message and as their source, and the line printed both
/// (`afile: File exists (os error 17): File exists (os error 17)`). For
/// each command that writes or reads a directory, given a file, a missing
/// path or a path under a file.
#[test]
fn an_io_error_is_said_once() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("afile");
    std::fs::write(&file, "x").unwrap();
    let missing = dir.path().join("missing");
    let under = file.join("sub");
    for path in [&file, &missing, &under] {
        let p = path.to_str().unwrap();
        for args in [
            vec!["run", "nonfeasible", "--duration", "0.05", "--out", p],
            vec!["plot", p],
            vec!["umbmark", "--from-log", p],
            vec!["identify", p],
        ] {
            let o = echelon(&args);
            let err = stderr(&o);
            if o.status.success() {
                continue;
            }
            assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
            assert!(err.matches("(os error").count() <= 1, "{args:?}: {err}");
        }
    }
}

/// A refused huge value is written in exponent form: `--duration 1e300`
/// was printed with 301 digits.
#[test]
fn a_huge_refused_value_is_written_short() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("never");
    for exp in (20..=300).step_by(40) {
        let big = format!("1e{exp}");
        let o = echelon(&[
            "run",
            "circle-pentagon",
            "--duration",
            &big,
            "--out",
            out.to_str().unwrap(),
        ]);
        assert_refused(&o, &["--duration: ", &format!("{big} s at dt")]);
        assert!(stderr(&o).len() < 200, "{}", stderr(&o));
    }
}

/// A malformed `--connect` or `--listen` endpoint is refused at its flag
/// before any Zenoh session: Zenoh's own refusal was a JSON5 dump with a
/// source path, and `tcp/1.2.3.4:99999` waited for a connection that could
/// never open. Listening on port 0 (any free port) stays allowed.
#[test]
fn a_bad_fleet_endpoint_is_refused_at_its_flag() {
    let bad = [
        "nonsense",
        "tcp/1.2.3.4:99999",
        "tcp/1.2.3.4:0",
        "tcp/1.2.3.4",
        "udp/[::1",
        "http/1.2.3.4:80",
        "tcp/:7447",
        "tcp/bad_host:7447",
    ];
    for e in bad {
        for args in [
            vec!["fleet", "leader", "circle-pentagon", "--connect", e],
            vec!["fleet", "stop", "circle-pentagon", "--connect", e],
        ] {
            let o = echelon(&args);
            assert_refused(&o, &["'--connect <ENDPOINT>'", e]);
            assert!(!stderr(&o).contains("Json5Err"), "{}", stderr(&o));
        }
        if e != "tcp/1.2.3.4:0" {
            let o = echelon(&["fleet", "router", "--listen", e]);
            assert_refused(&o, &["'--listen <ENDPOINT>'", e]);
        }
    }
}

/// `fleet up --secure DIR` without every process's certificates is refused
/// before anything starts or is written: a missing directory, and one made
/// for fewer robots than the scenario has (the first robot without a
/// certificate is named), in both topologies. It used to start the
/// routers, the collector and the leader and leave `endpoints.json`,
/// `fleet.mcap`, `logs/` in `--out` before a robot failed.
#[test]
fn fleet_up_without_every_certificate_is_refused_before_it_starts() {
    let dir = tempfile::tempdir().unwrap();
    let certs = dir.path().join("certs");
    let c = certs.to_str().unwrap();
    let made = echelon(&["fleet", "certs", c, "--robots", "2"]);
    assert!(made.status.success(), "{}", stderr(&made));
    let out = dir.path().join("never");
    let out_s = out.to_str().unwrap();
    let missing = dir.path().join("missing");
    for topology in ["router", "mesh"] {
        // circle-pentagon has four robots: robot-3 has none.
        for (secure, needle) in [(missing.to_str().unwrap(), "ca.pem"), (c, "robot-3.pem")] {
            let o = echelon(&[
                "fleet",
                "up",
                "circle-pentagon",
                "--topology",
                topology,
                "--secure",
                secure,
                "--out",
                out_s,
            ]);
            assert_refused(&o, &["secure mode needs", needle, "fleet certs"]);
            assert!(!out.exists(), "{topology} {secure}: wrote {out_s}");
        }
    }
}

/// A `fleet stop` (or `resume`) that reaches no robot did not stop
/// anything: it exits 1 saying so, instead of 0 with a warning (typed
/// without the hub's endpoint, it reached nobody). Nothing listens here.
#[test]
fn a_fleet_order_that_reaches_no_robot_fails() {
    let token = ["--token", "0123456789abcdef0123456789abcdef"];
    for (order, more) in [("stop", &[][..]), ("resume", &token[..])] {
        let o = Command::new(env!("CARGO_BIN_EXE_echelon"))
            .args(["fleet", order, "circle-pentagon", "--timeout", "0.5"])
            .args(more)
            .env_remove("ECHELON_OPERATOR_TOKEN")
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
        let err = stderr(&o);
        assert!(
            err.contains(&format!(
                "fleet {order}: no robot of fleet `circle-pentagon` is reachable"
            )),
            "{err}"
        );
        assert!(err.contains("--connect"), "{err}");
    }
}

/// The dds wave's scenario fields refused at their place, exit 2, nothing
/// started: a `reverse_limit` that is not `> 0`, one on a torque-driven
/// robot, a `hazards` topic that is no ROS name, a control rate that leaves
/// a base fewer than two commands per `cmd_vel_timeout`; and a `--hazard`
/// that is not NAME@FROM+DURATION.
#[test]
fn the_dds_fields_are_refused_at_their_place() {
    let dir = tempfile::tempdir().unwrap();
    let robot = |section: &str| {
        GOOD.replace(
            "[[agents]]",
            &format!("{section}\n[[agents]]\nrobot = \"tb\""),
        )
    };
    let limited = robot("[robots.tb]\npreset = \"turtlebot4\"\nreverse_limit = 0.1\n");
    let run_cases: [(String, &[&str]); 2] = [
        (
            robot("[robots.tb]\npreset = \"turtlebot4\"\nreverse_limit = 0.0\n"),
            &["s.toml:11:17: robots.tb.reverse_limit", "must be > 0"],
        ),
        (
            robot("[robots.tb]\npreset = \"agent1\"\nreverse_limit = 0.1\n"),
            &[
                "s.toml:11:17: robots.tb.reverse_limit",
                "velocity base's field",
            ],
        ),
    ];
    let out = dir.path().join("never");
    refuses_each(dir.path(), &out, run_cases);
    for (tail, needles) in [
        (
            "\n[fleet.ros2]\nhazards = \"bad topic\"\n",
            &["s.toml:", "fleet.ros2.hazards", "bad topic"][..],
        ),
        (
            "\n[fleet]\ncontrol_rate = 3.0\n",
            &[
                "s.toml:",
                "fleet.control_rate",
                "cmd_vel_timeout",
                "give at least 4 Hz",
            ][..],
        ),
    ] {
        let f = scenario_file(dir.path(), &format!("{limited}{tail}"));
        assert_refused(
            &echelon(&["fleet", "robot", &f, "--agent", "1", "--ros2"]),
            needles,
        );
    }
    let f = scenario_file(dir.path(), &limited);
    let out_s = out.to_str().unwrap();
    for bad in [
        "BUMP",
        "PUSH@1+2",
        "BUMP@-1+2",
        "BUMP@1+0",
        "x:BUMP@1+2",
        "1:BUMP@1",
    ] {
        let o = echelon(&["fleet", "up", &f, "--ros2", "--hazard", bad, "--out", out_s]);
        assert_eq!(o.status.code(), Some(2), "{bad}: {}", stderr(&o));
        assert!(stderr(&o).contains("--hazard"), "{bad}: {}", stderr(&o));
        assert!(!out.exists(), "{bad}: nothing started");
    }
}

/// `fleet resume` needs the operator token (`--token`, `--token-file` or
/// ECHELON_OPERATOR_TOKEN): without one, or with one that is not 32
/// hexadecimal characters, or a file that is missing, it exits 2 before
/// anything is put; `fleet stop` takes no token (a stop is always
/// allowed). Nothing listens here.
#[test]
fn fleet_resume_needs_the_operator_token() {
    let dir = tempfile::tempdir().unwrap();
    let bad_file = dir.path().join("operator-token");
    std::fs::write(&bad_file, "not a token\n").unwrap();
    let bad_file = bad_file.to_str().unwrap();
    let missing = dir.path().join("none");
    let missing = missing.to_str().unwrap();
    let resume = |more: &[&str], env: Option<&str>| {
        let mut c = Command::new(env!("CARGO_BIN_EXE_echelon"));
        c.args(["fleet", "resume", "circle-pentagon", "--timeout", "0.5"])
            .args(more)
            .env_remove("ECHELON_OPERATOR_TOKEN");
        if let Some(v) = env {
            c.env("ECHELON_OPERATOR_TOKEN", v);
        }
        c.output().unwrap()
    };
    let cases: [(&[&str], Option<&str>, &[&str]); 6] = [
        (
            &[],
            None,
            &[
                "fleet resume needs the operator token: give --token-file OUT/operator-token (written by fleet up), --token, or ECHELON_OPERATOR_TOKEN",
            ],
        ),
        (&[], Some(""), &["fleet resume needs the operator token"]),
        (
            &["--token", "abc"],
            None,
            &["--token", "32 hexadecimal characters"],
        ),
        (
            &["--token-file", bad_file],
            None,
            &[
                "--token-file",
                "operator-token",
                "32 hexadecimal characters",
            ],
        ),
        (&["--token-file", missing], None, &["--token-file", "none"]),
        (
            &[],
            Some("xyz"),
            &["ECHELON_OPERATOR_TOKEN", "32 hexadecimal characters"],
        ),
    ];
    for (more, env, needles) in cases {
        let o = resume(more, env);
        assert_eq!(o.status.code(), Some(2), "{more:?} {env:?}: {}", stderr(&o));
        assert!(o.stdout.is_empty(), "nothing put: {}", stdout(&o));
        let err = stderr(&o);
        for n in needles {
            assert!(err.contains(n), "{more:?} {env:?}: {n}: {err}");
        }
    }
    // The token from the environment is taken (it then fails as a resume
    // that reached no robot, exit 1).
    let o = resume(&[], Some("0123456789ABCDEF0123456789abcdef"));
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    // A stop takes no token.
    let o = echelon(&["fleet", "stop", "circle-pentagon", "--token", "x"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--token"), "{}", stderr(&o));
}

/// `[fleet] operator_heartbeat` is refused at its place (file, line,
/// column, field; exit 2, nothing started) when it is not a positive
/// number of seconds in its plausible range, by every process that reads
/// it; `fleet heartbeat` on a scenario that asks for none says so (exit 2).
#[test]
fn the_operator_heartbeat_is_refused_at_its_place() {
    let dir = tempfile::tempdir().unwrap();
    for (value, needles) in [
        (
            "0.0",
            &["s.toml:15:22: fleet.operator_heartbeat", "> 0"][..],
        ),
        (
            "-1.0",
            &["s.toml:15:22: fleet.operator_heartbeat", "> 0"][..],
        ),
        (
            "1e5",
            &["s.toml:15:22: fleet.operator_heartbeat", "0.01 to 3600 s"][..],
        ),
        (
            "\"1 s\"",
            &["s.toml:15:22: fleet.operator_heartbeat", "invalid type"][..],
        ),
    ] {
        let f = scenario_file(
            dir.path(),
            &format!("{GOOD}\n[fleet]\noperator_heartbeat = {value}\n"),
        );
        for args in [
            &["fleet", "robot", &f, "--agent", "1"][..],
            &["fleet", "heartbeat", &f][..],
        ] {
            assert_refused(&echelon(args), needles);
        }
    }
    let f = scenario_file(dir.path(), GOOD);
    assert_refused(
        &echelon(&["fleet", "heartbeat", &f]),
        &["asks for no operator heartbeat", "operator_heartbeat"],
    );
}

/// `[fleet] state_rate` is refused at its place (file, line, column,
/// field; exit 2, nothing started) when it is not a positive number of
/// hertz, is above the control rate or outside its plausible range.
#[test]
fn the_state_rate_is_refused_at_its_place() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("never");
    for (value, needles) in [
        ("0.0", &["s.toml:15:14: fleet.state_rate", "> 0"][..]),
        ("-5.0", &["s.toml:15:14: fleet.state_rate", "> 0"][..]),
        (
            "150.0",
            &[
                "s.toml:15:14: fleet.state_rate",
                "above control_rate (100 Hz)",
            ][..],
        ),
        (
            "0.01",
            &[
                "s.toml:15:14: fleet.state_rate",
                "plausible range 0.1 to 10000 Hz",
            ][..],
        ),
        (
            "\"10 Hz\"",
            &["s.toml:15:14: fleet.state_rate", "invalid type"][..],
        ),
    ] {
        let f = scenario_file(
            dir.path(),
            &format!("{GOOD}\n[fleet]\nstate_rate = {value}\n"),
        );
        for args in [
            &["fleet", "robot", &f, "--agent", "1"][..],
            &["fleet", "up", &f, "--out", out.to_str().unwrap()][..],
        ] {
            assert_refused(&echelon(args), needles);
        }
        assert!(!out.exists(), "nothing written for {value}");
    }
}

/// `placement` (in `[fleet]` or an agent) is refused at its place (file,
/// line, column, field; exit 2, nothing written or started) when it is
/// neither `"hub"` nor `"onboard"`, by the commands that read it.
#[test]
fn a_placement_that_is_not_one_is_refused_at_its_place() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    for (text, needles) in [
        (
            format!("{GOOD}\n[fleet]\nplacement = \"roof\"\n"),
            &["s.toml:15:13: fleet.placement", "unknown variant `roof`"][..],
        ),
        (
            GOOD.replacen("[[agents]]\n", "[[agents]]\nplacement = 1\n", 1),
            &["s.toml:10:13: agents[1].placement", "wanted string"][..],
        ),
    ] {
        let f = scenario_file(dir.path(), &text);
        for args in [
            &["fleet", "up", &f, "--out", out.to_str().unwrap()][..],
            &[
                "fleet",
                "bundle",
                &f,
                "--hub",
                "tcp/10.0.0.1:7447",
                "--out",
                out.to_str().unwrap(),
            ][..],
        ] {
            assert_refused(&echelon(args), needles);
            assert!(!out.exists(), "{args:?} wrote {out:?}");
        }
    }
}
