//! `echelon fleet status` from outside the fleet, as a client of its
//! router: every robot listed with its state, link age, ‖e‖ (the very
//! value the collector records for the same state), CPU; a fleet stop
//! shows as `stopped`, a resume as `running` again, a killed robot as
//! `lost`, a simulated base's bump as its robot's last hazard; `--watch
//! --json` prints one document a second until SIGTERM; nobody there is one
//! line and exit 1.

use std::time::Instant;

use super::*;

/// Runs `echelon fleet status ARGS…`: its exit code, stdout and stderr.
fn status(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(EXE)
        .args(["fleet", "status"])
        .args(args)
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// `fleet status SCENARIO --json` through `router`: its one document.
fn status_json(scenario: &str, router: &str) -> Value {
    let (code, out, err) = status(&[scenario, "--json", "--mode", "client", "--connect", router]);
    assert_eq!(code, 0, "{out} {err}");
    assert_eq!(out.lines().count(), 1, "one document: {out}");
    serde_json::from_str(&out).unwrap()
}

/// Polls `fleet status` until every robot is in `state` (30 s at most);
/// that status.
fn until_all(scenario: &str, router: &str, state: &str) -> Value {
    let started = Instant::now();
    loop {
        let s = status_json(scenario, router);
        let robots = s["robots"].as_array().unwrap();
        if !robots.is_empty() && robots.iter().all(|r| r["state"] == state) {
            return s;
        }
        assert!(
            started.elapsed() < Duration::from_secs(30),
            "not every robot {state}: {s}"
        );
    }
}

/// The router endpoint of a `fleet up` writing to `dir`.
fn router_of(dir: &Path) -> String {
    endpoints_of(dir)
        .remove("router/1")
        .expect("a router/1 endpoint")
}

/// What `fleet status --json` says of a running fleet: the leader and the
/// collector alive, the reference fresh; each robot alive, its latest state
/// fresh, tracking, a finite ‖e‖, its process's CPU (some already spent
/// if `busy`: the first stats come before the first 10 ms clock tick).
fn assert_running(s: &Value, fleet: &str, robots: u64, busy: bool) {
    assert_eq!(s["fleet"], fleet, "{s}");
    assert_eq!(s["leader"]["alive"], true, "{s}");
    assert_eq!(s["collector"]["alive"], true, "{s}");
    assert!(f(s, &["leader", "reference_age"]) < 0.5, "{s}");
    assert!(f(s, &["listened"]) >= 1.5, "{s}");
    let list = s["robots"].as_array().unwrap();
    assert_eq!(
        list.iter().map(|r| u(r, &["robot"])).collect::<Vec<_>>(),
        (1..=robots).collect::<Vec<_>>(),
        "{s}"
    );
    for r in list {
        assert_eq!(r["alive"], true, "{r}");
        assert_eq!(r["link"], "tracking", "{r}");
        assert!(f(r, &["link_age"]) < 0.5, "{r}");
        assert!(u(r, &["states"]) > 10, "{r}");
        let e = f(r, &["error_norm"]);
        assert!(e.is_finite() && (0.0..1.0).contains(&e), "{r}");
        assert!(f(r, &["t"]) > 0.0, "{r}");
        let cpu = f(r, &["cpu", "seconds"]);
        assert!(if busy { cpu > 0.0 } else { cpu >= 0.0 }, "{r}");
        // A simulated robot has no base reporting hazards.
        assert_eq!(r["hazards"], Value::Null, "{r}");
    }
}

/// `fleet up` (×2): `fleet status` from outside lists both robots running,
/// each ‖e‖ exactly what the collector's trajectory.csv has for the same
/// robot at the same instant; the table has a row per robot; after `fleet
/// stop` both are `stopped`, after `fleet resume` `running` again; once the
/// fleet is gone, nobody answers (exit 1).
#[test]
fn status_shows_the_fleet_up_running_stopped_and_resumed() {
    let _fleet = common::one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let scenario = fixture("fast-circle.toml");
    let out = dir.path().join("fleet");
    let up = common::fleet_up_in_background(
        &[
            &scenario,
            "--time-scale",
            "2",
            "--duration",
            "30",
            "--quiet",
        ],
        &out,
    );
    let router = router_of(&out);
    let running = until_all(&scenario, &router, "running");
    assert_running(&running, "fast-circle", 2, false);

    // The table: the leader's line, a header, a row per robot.
    let (code, table, err) = status(&["--fleet", "fast-circle", "--connect", &router]);
    assert_eq!(code, 0, "{table} {err}");
    let lines: Vec<&str> = table.lines().collect();
    assert_eq!(lines.len(), 4, "{table}");
    assert!(
        lines[0].starts_with("fleet fast-circle: leader alive, reference "),
        "{table}"
    );
    for column in ["robot", "state", "link age, s", "‖e‖, m", "hazard", "CPU"] {
        assert!(lines[1].contains(column), "{column}: {table}");
    }
    for (k, line) in lines[2..].iter().enumerate() {
        let cells: Vec<&str> = line.split_whitespace().collect();
        assert_eq!(
            cells[..3],
            [&(k + 1).to_string(), "running", "tracking"],
            "{table}"
        );
    }

    let stop = Command::new(EXE)
        .args(["fleet", "stop", &scenario, "--mode", "client", "--connect"])
        .arg(&router)
        .output()
        .unwrap();
    check(&stop, "fleet stop");
    let stopped = status_json(&scenario, &router);
    for r in stopped["robots"].as_array().unwrap() {
        assert_eq!(
            (&r["state"], &r["link"]),
            (&"stopped".into(), &"stopped".into()),
            "{stopped}"
        );
        assert!(f(r, &["link_age"]) < 0.5, "{r}");
    }
    let token = out.join("operator-token");
    let resume = Command::new(EXE)
        .args([
            "fleet",
            "resume",
            &scenario,
            "--mode",
            "client",
            "--connect",
        ])
        .arg(&router)
        .arg("--token-file")
        .arg(&token)
        .env_remove("ECHELON_OPERATOR_TOKEN")
        .output()
        .unwrap();
    check(&resume, "fleet resume");
    assert_running(
        &until_all(&scenario, &router, "running"),
        "fast-circle",
        2,
        true,
    );

    let o = up.join().unwrap();
    check(&o, "fleet up");
    // The same states as the collector's: at the instant the status
    // showed (trajectory.csv writes times to the nanosecond), the
    // collector logged this very ‖e‖.
    let csv = rows(&out.join("trajectory.csv"));
    for r in running["robots"].as_array().unwrap() {
        let (k, t) = (u(r, &["robot"]) as usize, f(r, &["t"]));
        let (_, _, v) = csv
            .iter()
            .find(|(ct, a, _)| *a == k && (ct - t).abs() < 1e-9)
            .unwrap_or_else(|| panic!("no row of robot {k} at t = {t}"));
        let e = v[5].hypot(v[6]);
        assert!(
            (e - f(r, &["error_norm"])).abs() <= 1e-12 * e.max(1e-9),
            "robot {k} at {t}: csv {e}, status {r}"
        );
    }
    // The fleet is gone: nobody heard.
    let (code, _, err) = status(&[
        "--fleet",
        "fast-circle",
        "--connect",
        &router,
        "--mode",
        "client",
    ]);
    assert_eq!(code, 1, "{err}");
    assert!(
        err.starts_with("error: no robot of fleet `fast-circle` heard at"),
        "{err}"
    );
}

/// `fleet up --ros2` (simulated bases, ×2) with robot 2's base reporting
/// a BUMP: `fleet status` shows it as robot 2's last hazard, with its
/// clearing, and both robots stopped (the bump paused the fleet); robot 1,
/// whose base reported nothing, has no hazard; a ROS 2 robot's odometry age
/// is there, as on the dashboard.
#[test]
fn a_bump_shows_as_the_robots_last_hazard() {
    let _fleet = common::one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let scenario = dir.path().join("bump.toml");
    let base = Scenario::builtin("experiment-circle-velocity").unwrap();
    let toml = format!(
        "{}\n[fleet.ros2]\nhazards = \"hazard_detection\"\n",
        base.source()
    );
    std::fs::write(&scenario, toml).unwrap();
    let scenario = scenario.to_str().unwrap().to_owned();
    let out = dir.path().join("fleet");
    let up = common::fleet_up_in_background(
        &[
            &scenario,
            "--ros2",
            "--time-scale",
            "2",
            "--duration",
            "24",
            "--hazard",
            "2:BUMP@3+2",
            "--quiet",
        ],
        &out,
    );
    let router = router_of(&out);
    let started = Instant::now();
    let s = loop {
        let s = status_json(&scenario, &router);
        if s["robots"][1]["hazards"]["last"]["cleared"].is_number() {
            break s;
        }
        assert!(started.elapsed() < Duration::from_secs(40), "{s}");
    };
    let (r1, r2) = (&s["robots"][0], &s["robots"][1]);
    let last = &r2["hazards"]["last"];
    assert_eq!(last["hazard"], "BUMP", "{s}");
    assert!(f(last, &["cleared"]) - f(last, &["at"]) > 1.5, "{s}");
    assert_eq!(r2["hazards"]["in_force"], serde_json::json!([]), "{s}");
    assert_eq!(r1["hazards"]["last"], Value::Null, "{s}");
    for r in [r1, r2] {
        assert_eq!(
            (&r["state"], &r["link"]),
            (&"stopped".into(), &"stopped".into()),
            "{s}"
        );
        assert!(f(r, &["odometry_age"]) >= 0.0, "{r}");
        assert!(f(r, &["cpu", "seconds"]) > 0.0, "{r}");
    }
    let (code, table, err) = status(&[&scenario, "--mode", "client", "--connect", &router]);
    assert_eq!(code, 0, "{err}");
    let row = table.lines().find(|l| l.starts_with("2 ")).unwrap();
    assert!(
        row.contains(" BUMP at ") && row.contains(", cleared "),
        "{table}"
    );
    let o = up.join().unwrap();
    check(&o, "fleet up");
}

/// Processes by hand behind a router: `--watch --json` prints one
/// document a second until SIGTERM, exit 0; robot 2 killed (SIGKILL) is
/// `lost` (its liveliness token gone) while robot 1 runs on.
#[test]
fn a_killed_robot_is_lost_and_watch_redraws_every_second() {
    let _fleet = common::one_fleet_at_a_time();
    let ep = common::ports(1).remove(0);
    let scenario = fixture("fast-circle.toml");
    let router = spawn(&["fleet", "router", "--listen", &ep]);
    let client = ["--mode", "client", "--connect", &ep];
    let run = ["--time-scale", "2", "--duration", "60"];
    let robot = |k: &str| {
        spawn(
            &[
                &["fleet", "robot", &scenario, "--agent", k][..],
                &run,
                &client,
            ]
            .concat(),
        )
    };
    let (robot1, robot2) = (robot("1"), robot("2"));
    let wait = ["--wait-for", "robot/1", "--wait-for", "robot/2"];
    let leader = spawn(&[&["fleet", "leader", &scenario][..], &run, &wait, &client].concat());
    let started = Instant::now();
    loop {
        let s = status_json(&scenario, &ep);
        if s["robots"]
            .as_array()
            .unwrap()
            .iter()
            .all(|r| r["state"] == "running")
        {
            assert_eq!(s["collector"]["alive"], false, "none started: {s}");
            break;
        }
        assert!(started.elapsed() < Duration::from_secs(30), "{s}");
    }

    let watch = spawn(
        &[
            &["fleet", "status", &scenario, "--watch", "--json"][..],
            &client,
        ]
        .concat(),
    );
    std::thread::sleep(Duration::from_millis(4200));
    watch.terminate();
    let mut watch = watch;
    let code = watch.0.wait().unwrap();
    let mut text = String::new();
    std::io::Read::read_to_string(&mut watch.0.stdout.take().unwrap(), &mut text).unwrap();
    assert!(code.success(), "{code}: {text}");
    let docs: Vec<Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    // Listening 1.5 s, then one a second: 3 in 4.2 s (2 to 4 on a busy machine).
    assert!((2..=4).contains(&docs.len()), "{text}");
    let times: Vec<f64> = docs.iter().map(|d| f(d, &["leader", "t"])).collect();
    assert!(times.windows(2).all(|w| w[1] > w[0]), "{times:?}");

    let mut robot2 = robot2;
    robot2.0.kill().unwrap();
    robot2.0.wait().unwrap();
    let started = Instant::now();
    let s = loop {
        let s = status_json(&scenario, &ep);
        if s["robots"][1]["state"] == "lost" {
            break s;
        }
        assert!(started.elapsed() < Duration::from_secs(10), "{s}");
    };
    assert_eq!(s["robots"][1]["alive"], false, "{s}");
    assert_eq!(s["robots"][0]["state"], "running", "{s}");
    assert_eq!(s["robots"][0]["alive"], true, "{s}");
    // The others are killed when their guards drop.
    drop((leader, robot1, router));
}

/// Nobody at the endpoint (no router there), or a router with no fleet
/// behind it: one line, exit 1; a listening time that is not a positive
/// number: exit 2.
#[test]
fn nobody_there_is_one_line_and_exit_1() {
    let ep = common::ports(1).remove(0);
    let (code, out, err) = status(&[
        "--fleet",
        "ghost",
        "--connect",
        &ep,
        "--mode",
        "client",
        "--listen-for",
        "0.5",
    ]);
    assert_eq!(code, 1, "{out} {err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.starts_with(&format!(
            "error: no robot of fleet `ghost` heard at {ep} within 0.5 s"
        )),
        "{err}"
    );
    assert!(out.is_empty(), "{out}");
    let router = spawn(&["fleet", "router", "--listen", &ep]);
    let (code, out, err) = status(&[
        "--fleet",
        "ghost",
        "--connect",
        &ep,
        "--mode",
        "client",
        "--listen-for",
        "0.5",
        "--json",
    ]);
    assert_eq!(code, 1, "{out} {err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains("no robot of fleet `ghost` heard at"), "{err}");
    drop(router);
    for bad in ["0", "-1", "soon"] {
        let (code, _, err) = status(&["--fleet", "ghost", "--listen-for", bad]);
        assert_eq!(code, 2, "{bad}: {err}");
        assert_eq!(err.lines().count(), 1, "{err}");
    }
}
