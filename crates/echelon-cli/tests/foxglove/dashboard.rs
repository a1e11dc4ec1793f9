//! The operator's dashboard: it draws the fleet, and its stop stops every
//! robot (in the secure mode as the operator).

use super::*;

/// Waits for the operator URL the collector prints at start (its log under
/// `out`); its token.
fn operator_token(out: &Path) -> String {
    let log = out.join("logs/collector.log");
    let started = std::time::Instant::now();
    loop {
        let text = std::fs::read_to_string(&log).unwrap_or_default();
        if let Some(i) = text.find("?token=") {
            return text[i + 7..].lines().next().unwrap().trim().to_owned();
        }
        assert!(
            started.elapsed().as_secs() < 60,
            "no operator URL in {text}"
        );
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
}

/// `scripts/foxglove/dashboard_check.py URL TOKEN ROBOTS MORE…`: its JSON.
fn dashboard_check(addr: &str, token: &str, robots: usize, more: &[&str]) -> Value {
    let page = Command::new("python3")
        .arg(script("dashboard_check.py"))
        .args([&format!("http://{addr}/"), token, &robots.to_string()])
        .args(more)
        .output()
        .unwrap();
    check(&page, "dashboard_check.py");
    serde_json::from_slice(&page.stdout).unwrap()
}

/// `fleet stop` or `fleet resume` of `scenario` through `router` with
/// `more` arguments; its report (also when it exits 1: a robot alive did
/// not acknowledge).
fn fleet_command(what: &str, scenario: &str, router: &str, more: &[&str]) -> Value {
    let out = Command::new(common::EXE)
        .args([
            "fleet",
            what,
            scenario,
            "--mode",
            "client",
            "--connect",
            router,
        ])
        .args(["--reason", "foxglove test", "--timeout", "2"])
        .args(more)
        .env_remove("ECHELON_OPERATOR_TOKEN")
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    let line = text.lines().rfind(|l| l.starts_with('{'));
    let line = line.unwrap_or_else(|| {
        panic!(
            "fleet {what}: no report: {text} {}",
            String::from_utf8_lossy(&out.stderr)
        )
    });
    serde_json::from_str(line).unwrap()
}

/// The recorded states (`read_3d.py`'s `states`) of robot `k` logged in
/// `(from, to]` UNIX ns.
fn states_of(states: &[Value], k: u64, from: u64, to: u64) -> Vec<&Value> {
    states
        .iter()
        .filter(|r| r[1].as_u64() == Some(k))
        .filter(|r| {
            let logged = r[5].as_u64().unwrap();
            logged > from && logged <= to
        })
        .collect()
}

fn moving(r: &Value) -> bool {
    num(&r[6]) != 0.0 || num(&r[7]) != 0.0
}

/// The page's Stop all (pressed at `pressed`): every robot commands zero,
/// and once it has, nothing else until `until` (UNIX ns). The states
/// between the press and the first zero were in flight or ticked before the
/// stop reached the robot; how soon the stop takes hold is a tick-level
/// property, proven on a fake clock by the robot's bus test
/// (`a_fleet_stop_on_the_bus_holds_every_robot_until_the_resume`), not by a
/// wall-clock margin here. The delay seen is printed for the reader.
fn check_stopped(states: &[Value], robots: u64, pressed: u64, until: u64) {
    for k in 1..=robots {
        let after = states_of(states, k, pressed, until);
        let first_zero = after
            .iter()
            .position(|r| !moving(r))
            .unwrap_or_else(|| panic!("robot {k} never commanded zero after the press"));
        let delay = (after[first_zero][5].as_u64().unwrap() - pressed) as f64 * 1e-9;
        eprintln!("robot {k}: zero {:.1} ms after the press", 1e3 * delay);
        let held = &after[first_zero..];
        assert!(
            held.len() > 1,
            "robot {k}: one state after the stop took hold"
        );
        for r in held {
            assert!(!moving(r), "robot {k} moved again before the resume: {r}");
        }
    }
}

/// `fleet up experiment-circle` (and `extra`) for `duration` fleet s at
/// ×2 into `out`, its dashboard on a free address: the process, the
/// address and the operator token.
fn dashboard_fleet(out: &Path, duration: &str, extra: &[&str]) -> (common::Guard, String, String) {
    let addr = free_addr();
    let out_s = out.display().to_string();
    let fleet = common::spawn(
        &[
            &["fleet", "up", "experiment-circle"][..],
            extra,
            &[
                "--duration",
                duration,
                "--time-scale",
                "2",
                "--quiet",
                "--dashboard",
                &addr,
                "--out",
                &out_s,
            ],
        ]
        .concat(),
    );
    let token = operator_token(out);
    (fleet, addr, token)
}

/// `fleet up --dashboard` in headless Chromium (scripts/foxglove/
/// dashboard_check.py over the DevTools protocol), after a `fleet stop`
/// and a `fleet resume` from the command line: the page draws every robot
/// where the collector recorded it; its table shows per robot the link,
/// the state's age, ‖e‖ and "—" for the odometry and fix ages the
/// simulated plants do not have, and formats injected states' odometry
/// block; opened without the operator token its Stop all is disabled and
/// the server refuses the stop; opened with the token, pressing Stop all
/// puts a stop numbered past the command line's resume (not taken for an
/// older command), acknowledged by every robot, and every robot commands
/// zero until the page's Resume, after which they all move.
#[test]
fn the_dashboard_draws_the_fleet_and_its_stop_stops_every_robot() {
    let _fleet = one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let scenario = "experiment-circle";
    let out = dir.path().join("fleet");
    let (fleet, addr, token) = dashboard_fleet(&out, "40", &[]);
    let router = common::endpoints_of(&out)["router/1"].clone();
    let robots = 2;
    // Stop until both robots are in the fleet (and acknowledge), then resume.
    let started = std::time::Instant::now();
    while fleet_command("stop", scenario, &router, &[])["acknowledged"]
        .as_array()
        .unwrap()
        .len()
        < robots
    {
        assert!(started.elapsed().as_secs() < 30, "the robots did not join");
        std::thread::sleep(std::time::Duration::from_millis(200));
    }
    // The dashboard's token is the fleet's operator token, which `fleet
    // resume` reads from the file `fleet up` wrote.
    let token_file = out.join("operator-token");
    assert_eq!(
        std::fs::read_to_string(&token_file).unwrap().trim(),
        token,
        "the dashboard's token is fleet up's"
    );
    let token_file = token_file.to_str().unwrap();
    let cli_resume = fleet_command("resume", scenario, &router, &["--token-file", token_file]);
    assert_eq!(
        cli_resume["acknowledged"].as_array().unwrap().len(),
        robots,
        "{cli_resume}"
    );
    let resumed = cli_resume["published_unix_ns"].as_u64().unwrap();
    // States carrying the odometry block of a robot that has one.
    let injected = serde_json::json!([
        [1, {"t": 1.0, "x": 0.0, "y": 0.0, "theta": 0.0, "u1": 0.5, "u2": -0.25,
             "error_norm": 0.01234, "link": "tracking",
             "odometry": {"raw": [1.0, 2.0, 0.5], "age": 0.0312, "fix_age": 12.3456}}, 0.2],
        [2, {"t": 1.0, "x": 0.0, "y": 0.0, "theta": 0.0, "v_cmd": 0.1, "omega_cmd": 0.0,
             "error_norm": 2.5, "link": "extrapolating", "sat": true,
             "odometry": {"raw": [0.0, 0.0, 0.0], "age": 1234.5678, "fix_age": null}}, 0.0],
        [3, {"t": 1.0, "x": 0.0, "y": 0.0, "theta": 0.0, "u1": 0.0, "u2": 0.0,
             "error_norm": 0.0, "link": "stopped"}, 3.0],
    ]);
    let page = dashboard_check(
        &addr,
        &token,
        robots,
        &["--states", &injected.to_string(), "--resume"],
    );
    let mut fleet = fleet;
    assert!(fleet.0.wait().unwrap().success());

    assert_eq!(page["errors"], serde_json::json!([]), "{page}");
    assert_eq!(page["readonly"]["disabled"], true);
    assert_eq!(page["readonly"]["status"], 403);
    assert_eq!(page["stop"]["status"], 200);
    assert_eq!(page["resume"]["status"], 200);
    // The table: one row per robot; simulated plants have no odometry
    // block, so their odometry and fix ages are "—".
    let table = page["table"].as_array().unwrap();
    assert_eq!(table.len(), robots, "{table:?}");
    for (k, row) in table.iter().enumerate() {
        assert_eq!(row[0], (k + 1).to_string());
        assert!(
            row[2].as_str().unwrap().parse::<f64>().unwrap() >= 0.0,
            "{row}"
        );
        assert_eq!((&row[3], &row[4]), (&"—".into(), &"—".into()), "{row}");
        assert!(row[5].as_str().unwrap().parse::<f64>().is_ok(), "{row}");
    }
    assert_eq!(
        page["cells"],
        serde_json::json!([
            [
                "1",
                "tracking",
                "0.20",
                "0.03",
                "12.35",
                "0.012",
                "—",
                "—",
                "0.50, -0.25"
            ],
            [
                "2",
                "extrapolating",
                "0.00",
                "1234.57",
                "—",
                "2.500",
                "—",
                "yes",
                "0.10, 0.00"
            ],
            [
                "3",
                "stopped",
                "3.00",
                "—",
                "—",
                "0.000",
                "—",
                "—",
                "0.00, 0.00"
            ],
        ])
    );

    let read = read_3d(&out.join("fleet.mcap"));
    let states = read["states"].as_array().unwrap();
    // Drawn where recorded: the drawn robot mapped back to the world is the
    // state's position (to the canvas transform's rounding, 1e-9 m).
    let samples = page["samples"].as_array().unwrap();
    let mut seen: BTreeMap<u64, std::collections::BTreeSet<u64>> = BTreeMap::new();
    for s in samples {
        let (k, t) = (s[0].as_u64().unwrap(), num(&s[1]));
        let state = states
            .iter()
            .find(|r| r[1].as_u64() == Some(k) && (num(&r[0]) - t).abs() < 1e-9)
            .unwrap_or_else(|| panic!("robot {k} drawn at t = {t}, which it never reported"));
        let (dx, dy) = (num(&s[2]) - num(&state[2]), num(&s[3]) - num(&state[3]));
        assert!(
            dx.hypot(dy) < 1e-9,
            "robot {k} at {t}: drawn {s}, recorded {state}"
        );
        seen.entry(k).or_default().insert((t * 1e9) as u64);
    }
    assert_eq!(seen.len(), robots, "{seen:?}");
    assert!(
        seen.values().all(|ts| ts.len() >= 5),
        "the drawing moved: {seen:?}"
    );

    // The page's stop, numbered one past the command line's resume, by the
    // operator, acknowledged by every robot; its resume one past it.
    let stop = &page["stop"]["outcome"];
    let resume = &page["resume"]["outcome"];
    let seq = cli_resume["command"]["seq"].as_u64().unwrap();
    assert_eq!(stop["command"]["seq"].as_u64(), Some(seq + 1), "{stop}");
    assert_eq!(stop["command"]["order"], "stop");
    assert_eq!(stop["command"]["by"], "operator");
    assert_eq!(
        stop["acknowledged"],
        serde_json::json!(["robot/1", "robot/2"])
    );
    assert_eq!(resume["command"]["seq"].as_u64(), Some(seq + 2), "{resume}");
    assert_eq!(
        resume["acknowledged"],
        serde_json::json!(["robot/1", "robot/2"])
    );

    // Every robot moved between the command line's resume and the press,
    // commanded zero after the press until the page's resume,
    // and moved again after it.
    let pressed = (num(&page["stop"]["pressed_ms"]) * 1e6) as u64;
    let lifted = (num(&page["resume"]["pressed_ms"]) * 1e6) as u64;
    for k in 1..=robots as u64 {
        assert!(
            states_of(states, k, resumed, pressed)
                .iter()
                .any(|r| moving(r)),
            "robot {k} did not move after the command line's resume"
        );
        assert!(
            states_of(states, k, lifted, u64::MAX)
                .iter()
                .any(|r| moving(r)),
            "robot {k} did not move after the page's resume"
        );
    }
    check_stopped(states, robots as u64, pressed, lifted);
}

/// `fleet up --secure --dashboard`: the collector's dashboard stops the
/// fleet as the `operator` identity of the certificate directory (the only
/// one, with the leader, whose commands the access control lets through):
/// pressing Stop all makes every robot command zero.
#[test]
fn in_secure_mode_the_dashboard_stops_the_fleet_as_the_operator() {
    let _fleet = one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let certs = common::certs(dir.path(), 2);
    let out = dir.path().join("fleet");
    let (fleet, addr, token) = dashboard_fleet(&out, "30", &["--secure", certs.to_str().unwrap()]);
    let robots = 2;
    let page = dashboard_check(&addr, &token, robots, &[]);
    let mut fleet = fleet;
    assert!(fleet.0.wait().unwrap().success());
    assert_eq!(page["errors"], serde_json::json!([]), "{page}");
    assert_eq!(page["stop"]["status"], 200, "{page}");
    let stop = &page["stop"]["outcome"];
    assert_eq!(stop["command"]["by"], "operator");
    assert_eq!(
        stop["acknowledged"],
        serde_json::json!(["robot/1", "robot/2"])
    );
    let read = read_3d(&out.join("fleet.mcap"));
    let states = read["states"].as_array().unwrap();
    let pressed = (num(&page["stop"]["pressed_ms"]) * 1e6) as u64;
    check_stopped(states, robots as u64, pressed, u64::MAX);
}
