#![allow(clippy::unwrap_used)]
//! The 3D channels (`/tf`, `/scene`, `/scene/static`: Foxglove's
//! well-known schemas) of `echelon run --mcap` and of the fleet collector's
//! `fleet.mcap`, read back by an independent reader: Python's `mcap` and
//! Foxglove's published protobuf classes (`scripts/foxglove/read_3d.py`;
//! `scripts/test` installs both).

use std::collections::BTreeMap;
use std::f64::consts::{PI, TAU};
use std::path::Path;
use std::process::Command;

use serde_json::Value;

mod common;

use common::{check, echelon_ok, one_fleet_at_a_time};

/// Poses: the CSV and the 3D channels both carry the f64 values themselves
/// (the CSV in shortest round-trip form, protobuf as doubles), so they agree
/// to rounding of the quaternion's half-angle trigonometry only.
const POSITION_TOLERANCE: f64 = 1e-9;
const HEADING_TOLERANCE: f64 = 1e-9;

fn script(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../scripts/foxglove")
        .join(name)
}

/// `read_3d.py`'s JSON of `mcap`.
fn read_3d(mcap: &Path) -> Value {
    let out = Command::new("python3")
        .arg(script("read_3d.py"))
        .arg(mcap)
        .output()
        .unwrap_or_else(|e| panic!("python3: {e}"));
    check(
        &out,
        "read_3d.py (needs `python3 -m pip install -r scripts/requirements-test.txt`)",
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

/// `a − b` wrapped to (−π, π].
fn angle_diff(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(TAU);
    if d > PI { d - TAU } else { d }
}

fn num(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

/// The 3D channels' schemas are Foxglove's well-known ones: protobuf, named
/// as Foxglove names them, and defining the messages exactly as Foxglove's
/// published classes do (`schemas`: topic → [message encoding, schema name,
/// schema encoding, same definition]).
fn check_schemas(schemas: &Value) {
    for (topic, name) in [
        ("/tf", "foxglove.FrameTransforms"),
        ("/scene", "foxglove.SceneUpdate"),
        ("/scene/static", "foxglove.SceneUpdate"),
    ] {
        assert_eq!(
            schemas[topic],
            serde_json::json!(["protobuf", name, "protobuf", true]),
            "{topic}: {schemas}"
        );
    }
}

/// Robot `k` of an entity id or child frame `robotK…`.
fn robot_of(id: &str) -> Option<u64> {
    let rest = id.strip_prefix("robot")?;
    let digits = rest.split('/').next()?;
    digits.parse().ok()
}

/// Every state (t, agent, x, y, θ), in order per robot, has its transform
/// `world` → `robotK/base_link` stamped t with that position and heading
/// and its body at that position, in the same order; there are no others.
fn check_poses(read: &Value, states: &[(f64, u64, f64, f64, f64)]) {
    let mut tf: BTreeMap<u64, Vec<(f64, f64, f64, f64)>> = BTreeMap::new();
    for e in read["tf"].as_array().unwrap() {
        let frame = e[1].as_str().unwrap();
        assert_eq!(e[2], "world");
        assert!(frame.ends_with("/base_link"), "{frame}");
        let k = robot_of(frame).unwrap_or_else(|| panic!("child frame {frame}"));
        assert_eq!(num(&e[5]), 0.0);
        tf.entry(k)
            .or_default()
            .push((num(&e[0]), num(&e[3]), num(&e[4]), num(&e[6])));
    }
    let mut bodies: BTreeMap<u64, Vec<(f64, f64)>> = BTreeMap::new();
    for e in read["scene"].as_array().unwrap() {
        let id = e[1].as_str().unwrap();
        if let Some(k) = id.strip_prefix("robot").and_then(|k| k.parse::<u64>().ok()) {
            bodies.entry(k).or_default().push((num(&e[2]), num(&e[3])));
        }
    }
    let mut by_robot: BTreeMap<u64, Vec<(f64, f64, f64, f64)>> = BTreeMap::new();
    for &(t, k, x, y, theta) in states {
        by_robot.entry(k).or_default().push((t, x, y, theta));
    }
    assert_eq!(
        tf.keys().collect::<Vec<_>>(),
        by_robot.keys().collect::<Vec<_>>()
    );
    for (k, want) in &by_robot {
        let (got, body) = (&tf[k], &bodies[k]);
        assert_eq!(got.len(), want.len(), "robot {k}: one transform per state");
        assert_eq!(body.len(), want.len(), "robot {k}: one body per state");
        for ((&(tt, tx, ty, tyaw), &(t, x, y, theta)), &b) in got.iter().zip(want).zip(body) {
            assert!(
                (tt - t).abs() < 1e-9,
                "robot {k}: transform at {tt}, state at {t}"
            );
            assert!(
                (tx - x).abs() <= POSITION_TOLERANCE && (ty - y).abs() <= POSITION_TOLERANCE,
                "robot {k} at {t}: transform ({tx}, {ty}), state ({x}, {y})"
            );
            assert!(
                angle_diff(tyaw, theta).abs() <= HEADING_TOLERANCE,
                "robot {k} at {t}: yaw {tyaw}, θ {theta}"
            );
            assert_eq!(b, (tx, ty), "robot {k} at {t}: body");
        }
    }
}

/// `echelon run --mcap`: the 3D channels carry Foxglove's schemas, and each
/// robot's transform and body equal trajectory.csv's pose at every logged
/// step; the fixed scene holds the reference path and each obstacle.
#[test]
fn run_mcap_3d_channels_are_foxglove_and_match_the_csv() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    echelon_ok(
        &[
            "run",
            "obstacle-slalom",
            "--duration",
            "2",
            "--mcap",
            "--quiet",
            "--out",
        ],
        &out,
    );
    let read = read_3d(&out.join("run.mcap"));
    check_schemas(&read["schemas"]);
    let csv = std::fs::read_to_string(out.join("trajectory.csv")).unwrap();
    let states: Vec<(f64, u64, f64, f64, f64)> = csv
        .lines()
        .skip(1)
        .map(|l| {
            let v: Vec<&str> = l.split(',').collect();
            let n = |i: usize| v[i].parse::<f64>().unwrap();
            (n(0), v[1].parse().unwrap(), n(2), n(3), n(4))
        })
        .collect();
    assert!(!states.is_empty());
    check_poses(&read, &states);
    let run = echelon::scenario::Scenario::builtin("obstacle-slalom")
        .unwrap()
        .build(&echelon::scenario::Overrides::default())
        .unwrap();
    let obstacles = run.plan.obstacles().len();
    assert!(obstacles > 0);
    let mut want = vec!["reference".to_owned()];
    want.extend((1..=obstacles).map(|i| format!("obstacle/{i}")));
    assert_eq!(read["static"], serde_json::json!(want));
    // docs/foxglove-layout.json draws these channels in `world` and plots a
    // field the state records have.
    let layout: Value = serde_json::from_str(
        &std::fs::read_to_string(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/foxglove-layout.json"),
        )
        .unwrap(),
    )
    .unwrap();
    let three_d = &layout["configById"]["3D!echelon"];
    assert_eq!(three_d["followTf"], "world");
    for topic in three_d["topics"].as_object().unwrap().keys() {
        assert!(read["schemas"].get(topic).is_some(), "{topic}");
    }
    let schema = echelon_mcap::AGENT_STATE.schema.to_string();
    for p in layout["configById"]["Plot!echelon"]["paths"]
        .as_array()
        .unwrap()
    {
        let field = p["value"].as_str().unwrap().rsplit('.').next().unwrap();
        assert!(schema.contains(&format!("\"{field}\"")), "{field}");
    }
    // Each leader link starts at its robot.
    for l in read["links"].as_array().unwrap() {
        let k = robot_of(l[1].as_str().unwrap()).unwrap();
        let t = num(&l[0]);
        let s = states
            .iter()
            .find(|s| s.1 == k && (s.0 - t).abs() < 1e-9)
            .unwrap();
        assert_eq!((num(&l[2]), num(&l[3])), (s.2, s.3));
    }
}

/// A free loopback address, `127.0.0.1:PORT`.
fn free_addr() -> String {
    let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    l.local_addr().unwrap().to_string()
}

/// `fleet up` into `dir` with `extra` arguments; fleet-summary.json.
fn up(dir: &Path, extra: &[&str]) -> Value {
    echelon_ok(
        &[
            &[
                "fleet",
                "up",
                "experiment-circle",
                "--duration",
                "20",
                "--time-scale",
                "5",
                "--quiet",
            ],
            extra,
            &["--out"],
        ]
        .concat(),
        dir,
    );
    serde_json::from_str(&std::fs::read_to_string(dir.join("fleet-summary.json")).unwrap()).unwrap()
}

/// `ws_client.py URL --seconds S [more]`, started now.
fn viewer(url: &str, seconds: &str, more: &[&str]) -> std::process::Child {
    Command::new("python3")
        .arg(script("ws_client.py"))
        .args([url, "--seconds", seconds])
        .args(more)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap()
}

fn finished(child: std::process::Child, what: &str) -> Value {
    let out = child.wait_with_output().unwrap();
    check(&out, what);
    serde_json::from_slice(&out.stdout).unwrap()
}

/// `fleet up --foxglove`: an independent client of Foxglove's WebSocket
/// protocol (scripts/foxglove/ws_client.py) subscribes during the run and
/// decodes every robot's transform and body at ≥ 10 Hz, on channels with
/// Foxglove's schemas, next to the JSON ones; a second viewer subscribes
/// and never reads: the fleet's latency stays what it is without viewers,
/// and the collector counts what it could not hand over. fleet.mcap's 3D
/// channels equal its `/agent/K/state` records.
#[test]
fn fleet_up_serves_foxglove_live_and_a_stalled_viewer_costs_nothing() {
    let _fleet = one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let base = up(&dir.path().join("base"), &[]);

    let addr = free_addr();
    let url = format!("ws://{addr}");
    let stalled = viewer(&url, "6", &["--stall"]);
    let reader = viewer(&url, "2", &[]);
    let live_dir = dir.path().join("live");
    let live = up(&live_dir, &["--foxglove", &addr]);
    let read = finished(reader, "ws_client.py");
    let _ = finished(stalled, "ws_client.py --stall");

    let endpoints: Value =
        serde_json::from_str(&std::fs::read_to_string(live_dir.join("endpoints.json")).unwrap())
            .unwrap();
    assert_eq!(endpoints["foxglove"], url.as_str());
    let channels = &read["channels"];
    check_schemas(channels);
    let robots = live["robots"].as_array().unwrap().len();
    assert!(robots >= 2);
    for k in 1..=robots {
        assert_eq!(
            channels[format!("/agent/{k}/state")][1],
            "echelon.AgentState"
        );
        for (what, rate) in [
            ("transform", &read["tf"][format!("robot{k}/base_link")]),
            ("body", &read["scene"][format!("robot{k}")]),
            ("slot", &read["scene"][format!("robot{k}/slot")]),
        ] {
            assert!(num(&rate["rate"]) >= 10.0, "robot {k}'s {what}: {rate}");
        }
    }
    assert_eq!(channels["/reference"][1], "echelon.Reference");

    // The collector saw both viewers and counted every record it handed
    // over or dropped.
    let feed = &live["collector"]["live"];
    assert!(feed["max_clients"].as_u64().unwrap() >= 2, "{feed}");
    assert!(feed["queued"].as_u64().unwrap() > 0, "{feed}");
    assert!(feed["dropped"].is_u64(), "{feed}");
    // What the server was given to send, and each viewer's queue: its
    // drops are the crate's, uncounted (docs/foxglove.md).
    assert!(feed["served"].as_u64().unwrap() > 0, "{feed}");
    assert_eq!(feed["viewer_backlog"], 1024, "{feed}");
    assert!(base["collector"].get("live").is_none());
    // The fleet's latency with two viewers, one stalled, is what it is
    // without (a stated margin for a loaded 2-core machine: twice, plus 1 ms).
    for who in ["collector", "robots"] {
        for q in ["p50", "p95"] {
            let (b, l) = (num(&base["latency"][who][q]), num(&live["latency"][who][q]));
            assert!(
                l <= 2.0 * b + 1e-3,
                "{who} {q}: {l} s with viewers, {b} s without"
            );
        }
    }

    // fleet.mcap: one transform and body per recorded state, at its pose.
    let read = read_3d(&live_dir.join("fleet.mcap"));
    check_schemas(&read["schemas"]);
    let states: Vec<(f64, u64, f64, f64, f64)> = read["states"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| {
            (
                num(&s[0]),
                s[1].as_u64().unwrap(),
                num(&s[2]),
                num(&s[3]),
                num(&s[4]),
            )
        })
        .collect();
    assert!(states.len() > robots * 10);
    check_poses(&read, &states);
}

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

/// `fleet stop` or `fleet resume` of `scenario` through `router`; its
/// report (also when it exits 1: a robot alive did not acknowledge).
fn fleet_command(what: &str, scenario: &str, router: &str) -> Value {
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

/// The page's Stop all (pressed at `pressed`): every robot's command is
/// zero within 100 ms (the collector's receipt of the robot's state), and
/// stays zero until `until` (UNIX ns).
fn check_stopped(states: &[Value], robots: u64, pressed: u64, until: u64) {
    for k in 1..=robots {
        let after = states_of(states, k, pressed, until);
        let first_zero = after
            .iter()
            .find(|r| !moving(r))
            .unwrap_or_else(|| panic!("robot {k} never commanded zero after the press"));
        let within = (first_zero[5].as_u64().unwrap() - pressed) as f64 * 1e-9;
        assert!(within <= 0.1, "robot {k}: zero {within} s after the press");
        let late: Vec<_> = after
            .iter()
            .filter(|r| r[5].as_u64().unwrap() > pressed + 100_000_000)
            .collect();
        assert!(!late.is_empty());
        for r in late {
            assert!(!moving(r), "robot {k}: {r}");
        }
    }
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
/// zero within 100 ms until the page's Resume, after which they all move.
#[test]
fn the_dashboard_draws_the_fleet_and_its_stop_stops_every_robot() {
    let _fleet = one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let addr = free_addr();
    let out = dir.path().join("fleet");
    let out_s = out.display().to_string();
    let scenario = "experiment-circle";
    let fleet = common::spawn(&[
        "fleet",
        "up",
        scenario,
        "--duration",
        "40",
        "--time-scale",
        "2",
        "--quiet",
        "--dashboard",
        &addr,
        "--out",
        &out_s,
    ]);
    let token = operator_token(&out);
    let router = common::endpoints_of(&out)["router/1"].clone();
    let robots = 2;
    // Stop until both robots are in the fleet (and acknowledge), then resume.
    let started = std::time::Instant::now();
    while fleet_command("stop", scenario, &router)["acknowledged"]
        .as_array()
        .unwrap()
        .len()
        < robots
    {
        assert!(started.elapsed().as_secs() < 30, "the robots did not join");
        std::thread::sleep(std::time::Duration::from_millis(200));
    }
    let cli_resume = fleet_command("resume", scenario, &router);
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
    // commanded zero within 100 ms of the press until the page's resume,
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
/// pressing Stop all makes every robot command zero within 100 ms.
#[test]
fn in_secure_mode_the_dashboard_stops_the_fleet_as_the_operator() {
    let _fleet = one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let certs = common::certs(dir.path(), 2);
    let addr = free_addr();
    let out = dir.path().join("fleet");
    let out_s = out.display().to_string();
    let fleet = common::spawn(&[
        "fleet",
        "up",
        "experiment-circle",
        "--secure",
        certs.to_str().unwrap(),
        "--duration",
        "30",
        "--time-scale",
        "2",
        "--quiet",
        "--dashboard",
        &addr,
        "--out",
        &out_s,
    ]);
    let token = operator_token(&out);
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
