//! `fleet up --ros2 --real`: bases each behind its own router, as real robots
//! are, plain and secure, and what it refuses.

use super::*;

/// Three lagged velocity bases under the kinematic law, each following the
/// reference from 0.3–0.5 m off its slot; agent K's robot at `routers[K-1]`.
fn three_robots_behind(routers: &[String]) -> String {
    format!(
        r#"name = "three-real"
description = "fleet up --ros2 --real: three robots, each behind its own router"

[sim]
duration = 12.0
dt = 0.001

[log]
dt = 0.01

{LAB_LAW_AND_BASE}
[fleet.ros2]
connect = "{r3}"

[[agents]]
robot = "lab"
start = {{ x = 0.0, y = -0.6, theta_deg = 90.0 }}
leader = "reference"
offset = {{ x = 0.30, y = 0.35 }}
ros2 = {{ connect = "{r1}" }}

[[agents]]
robot = "lab"
start = {{ x = -0.6, y = 0.3, theta_deg = 0.0 }}
leader = "reference"
offset = {{ x = 0.30, y = -0.35 }}
ros2 = {{ connect = ["{r2}"] }}

[[agents]]
robot = "lab"
start = {{ x = -0.9, y = -0.2, theta_deg = 0.0 }}
leader = "reference"
offset = {{ x = 0.65, y = 0.0 }}
"#,
        r1 = routers[0],
        r2 = routers[1],
        r3 = routers[2],
    )
}

/// `fleet up --ros2 --real` on three simulated bases, each a `fleet base`
/// linked only to its own `fleet router` (standing in for the robot's
/// `rmw_zenohd`), reached through the agents' `ros2.connect` (two per
/// agent, one from `[fleet.ros2]`): no simulated base of its own, real
/// time, and the robots end where the simulator ends (measured over three
/// runs: 0.02 to 1.3 mm at 12 s, the formation still converging, ‖e‖ 0.4
/// to 1.3 mm against the simulator's 0.04 to 0.13 mm; asserted within
/// 1 cm). Nothing crosses between the two
/// networks: each robot's router saw only its base's liveliness token, the
/// fleet's router none of the bases', and the collector no ROS topic.
#[test]
fn fleet_up_real_on_bases_behind_their_own_routers_ends_where_the_simulator_ends() {
    real_fleet_ends_where_the_simulator_ends(false);
}

/// The same in secure mode (certificates from `fleet certs`): each robot's
/// router a `quic/` listener trusting the fleet's CA (as
/// docs/real-robots.md, "Secure mode on real robots", sets up
/// `rmw_zenohd`), each base reaching it as `base-K`, each robot process as
/// `robot-K`, the fleet's own links mutual TLS too; it converges the same.
#[test]
fn secure_fleet_up_real_on_bases_behind_their_own_routers_converges_too() {
    real_fleet_ends_where_the_simulator_ends(true);
}

/// `fleet up --ros2 --real` on [`three_robots_behind`] their own routers
/// (in secure mode with `secure`), checked against the simulator.
fn real_fleet_ends_where_the_simulator_ends(secure: bool) {
    let _fleet = common::one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let mut routers = ports(3);
    let certs = secure.then(|| common::certs(dir.path(), 3));
    let secure_args: Vec<&str> = match &certs {
        Some(c) => vec!["--secure", c.to_str().unwrap()],
        None => Vec::new(),
    };
    if secure {
        for r in &mut routers {
            *r = r.replacen("tcp/", "quic/", 1);
        }
    }
    let scenario = dir.path().join("three-real.toml");
    std::fs::write(&scenario, three_robots_behind(&routers)).unwrap();
    let scenario = scenario.to_str().unwrap();
    let robot_routers: Vec<_> = routers
        .iter()
        .map(|e| {
            // In secure mode the scenario gives the access control its
            // robots and ROS 2 keys.
            let mut a = vec!["fleet", "router", "--listen", e];
            if secure {
                a.push(scenario);
                a.extend(&secure_args);
            }
            spawn(&a)
        })
        .collect();
    let bases: Vec<_> = routers
        .iter()
        .enumerate()
        .map(|(i, e)| {
            let k = (i + 1).to_string();
            let mut a = vec![
                "fleet",
                "base",
                scenario,
                "--ros2",
                "--agent",
                &k,
                "--mode",
                "client",
                "--connect",
                e,
            ];
            a.extend(&secure_args);
            spawn(&a)
        })
        .collect();
    let out = dir.path().join("up");
    let up = Command::new(EXE)
        .args([
            "fleet",
            "up",
            scenario,
            "--ros2",
            "--real",
            "--duration",
            "12",
        ])
        .args(&secure_args)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    check(&up, "fleet up --ros2 --real");
    for b in &bases {
        b.terminate();
    }
    let bases: Vec<Value> = bases.into_iter().map(common::Guard::report).collect();
    for r in &robot_routers {
        r.terminate();
    }
    let robot_routers: Vec<Value> = robot_routers
        .into_iter()
        .map(common::Guard::report)
        .collect();
    let up = common::fleet_summary(&out);
    assert_eq!(up["time_scale"], 1.0);
    assert!(up.get("bases").is_none(), "no simulated base of its own");

    echelon_ok(
        &["run", scenario, "--duration", "12", "--out"],
        &dir.path().join("sim"),
    );
    let s: Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("sim/summary.json")).unwrap(),
    )
    .unwrap();
    let sim: Vec<(f64, f64, f64)> = s["agents"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| {
            (
                f(a, &["final_pose", "x"]),
                f(a, &["final_pose", "y"]),
                f(a, &["final_error"]),
            )
        })
        .collect();
    let robots = up["robots"].as_array().unwrap();
    assert_eq!(robots.len(), 3);
    for (r, (x, y, e)) in robots.iter().zip(&sim) {
        let st = r["final_state"].as_array().unwrap();
        let (rx, ry) = (st[0].as_f64().unwrap(), st[1].as_f64().unwrap());
        let d = (rx - x).hypot(ry - y);
        eprintln!(
            "robot {}: {:.3} mm from the simulator's final position; ‖e‖ {:.3} mm (simulator {:.3} mm)",
            r["agent"],
            d * 1e3,
            f(r, &["final_error"]) * 1e3,
            e * 1e3
        );
        assert!(d < 1e-2, "robot {}: {d} m from the simulator", r["agent"]);
        assert!(f(r, &["final_error"]) < 1e-2, "{r}");
        drove_cleanly(&r["ros2"]);
    }
    for b in &bases {
        let c = &b["counters"];
        assert!(f(c, &["cmd_accepted"]) > 1000.0, "{b}");
        assert_eq!(f(c, &["cmd_received"]), f(c, &["cmd_accepted"]), "{b}");
        assert_eq!(b["last_command"], serde_json::json!([0.0, 0.0]), "{b}");
    }
    // The two networks stay apart: a robot's router saw its base only, the
    // fleet's router the leader, the collector and the robots only.
    for r in &robot_routers {
        assert_eq!(f(r, &["members_joined"]), 1.0, "{r}");
    }
    assert_eq!(f(&up["routers"][0], &["members_joined"]), 5.0, "{up}");
    let col = &up["collector"];
    assert_eq!(f(col, &["ros_recorded"]), 0.0, "{col}");
}

/// `fleet up --ros2 --real` refuses, before starting anything (exit 2, a
/// clear message): another time scale, an agent without `ros2.connect`,
/// `--real` without `--ros2`, and a `tls/` endpoint without certificates.
#[test]
fn fleet_up_real_refuses_what_real_robots_cannot_do() {
    let dir = tempfile::tempdir().unwrap();
    let routers = ports(3);
    let good = three_robots_behind(&routers);
    let refused = |toml: &str, extra: &[&str], says: &str| {
        let path = dir.path().join("s.toml");
        std::fs::write(&path, toml).unwrap();
        let out = Command::new(EXE)
            .args(["fleet", "up"])
            .arg(&path)
            .args(extra)
            .arg("--out")
            .arg(dir.path().join("out"))
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{extra:?}: {err}");
        assert!(err.contains(says), "{extra:?}: {err}");
        assert!(!dir.path().join("out/logs").exists(), "{extra:?}: started");
    };
    refused(
        &good,
        &["--ros2", "--real", "--time-scale", "10"],
        "--time-scale 10: real robots run in real time",
    );
    refused(&good, &["--real"], "--ros2");
    let no_fleet_default =
        good.replace(&format!("[fleet.ros2]\nconnect = \"{}\"\n", routers[2]), "");
    assert_ne!(no_fleet_default, good);
    refused(
        &no_fleet_default,
        &["--ros2", "--real"],
        "agent 3 has no ros2.connect",
    );
    refused(
        &good.replace(&routers[1], "tls/127.0.0.1:7448"),
        &["--ros2", "--real"],
        "agent 2: ros2.connect `tls/127.0.0.1:7448` needs certificates",
    );
    refused(
        &good.replace(&routers[0], "tcp/127.0.0.1"),
        &["--ros2", "--real"],
        "agents[1].ros2.connect",
    );
}

/// A robot process whose robot's router answers but carries no ROS 2 node
/// (the robot's driver not running) does not join the fleet: its graph
/// check fails after 5 s (exit 2) naming the namespace and the router.
#[test]
fn a_robot_without_odometry_behind_its_router_does_not_join_the_fleet() {
    let dir = tempfile::tempdir().unwrap();
    let e = ports(4);
    let scenario = dir.path().join("three-real.toml");
    std::fs::write(&scenario, three_robots_behind(&e[..3])).unwrap();
    let scenario = scenario.to_str().unwrap();
    let _robot_router = spawn(&["fleet", "router", "--listen", &e[0]]);
    let _fleet_router = spawn(&["fleet", "router", "--listen", &e[3]]);
    let started = Instant::now();
    let robot = Command::new(EXE)
        .args([
            "fleet",
            "robot",
            scenario,
            "--agent",
            "1",
            "--ros2",
            "--mode",
            "client",
            "--connect",
            &e[3],
        ])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&robot.stderr);
    assert_eq!(robot.status.code(), Some(2), "{err}");
    assert!(
        err.contains("agent 1: nothing under /robot1: no ROS 2 topic seen at all"),
        "{err}"
    );
    assert!(err.contains(&format!("its router at {}", e[0])), "{err}");
    assert!(started.elapsed() >= Duration::from_secs(5), "{err}");
}
