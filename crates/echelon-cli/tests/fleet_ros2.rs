//! The fleet driving ROS 2 bases over rmw_zenoh, as processes:
//!
//! - `fleet up --ros2`: leader, robots, simulated ROS 2 bases and collector;
//!   the robots end where the simulator ends;
//! - `fleet up --ros2 --real`: the same on bases each behind its own
//!   router, as real robots are, and its refusals;
//! - a robot whose base dies and whose odometry topic then carries garbage
//!   counts and refuses it and commands zero; SIGTERM leaves a zero
//!   `cmd_vel` as the last message on its key;
//! - a robot process driving an independent ROS 2 base written in Python
//!   (eclipse-zenoh, rclpy serialization: `scripts/ros2/fake_base.py`)
//!   converges to its slot.

#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serde_json::Value;
use zenoh::Wait;

use echelon_ros2::keys::topic_key;
use echelon_ros2::msgs::{ODOMETRY, Odometry, RosMessage, TWIST, Time, TwistStamped};

mod common;

use common::{EXE, args, check, echelon_ok, f, mesh, ports, spawn};
const SCENARIO: &str = "experiment-circle-velocity";
/// Agent 1's start pose in [`SCENARIO`], world `[x, y, θ]`.
const START: [f64; 3] = [0.0, -0.6, std::f64::consts::FRAC_PI_2];

/// The simulator's final poses of the scenario run for `duration`.
fn simulated_final(duration: &str, dir: &Path) -> Vec<(f64, f64)> {
    echelon_ok(&["run", SCENARIO, "--duration", duration, "--out"], dir);
    let s: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap();
    s["agents"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| (f(a, &["final_pose", "x"]), f(a, &["final_pose", "y"])))
        .collect()
}

/// A robot's ROS 2 counters after a run: it sent over 1000 commands, took
/// over 500 odometry samples and refused none.
fn drove_cleanly(ros: &Value) {
    assert!(
        f(ros, &["cmd_sent"]) > 1000.0 && f(ros, &["odom_accepted"]) > 500.0,
        "{ros}"
    );
    for k in [
        "odom_malformed",
        "odom_non_finite",
        "odom_wrong_type",
        "odom_wrong_frames",
    ] {
        assert_eq!(f(ros, &[k]), 0.0, "{k}: {ros}");
    }
}

/// `fleet up --ros2`: every robot↔base message in ROS 2's format; the
/// robots end within 5 mm of the simulator's final positions (measured:
/// 0.25 mm at 30 s), and the collector recorded the ROS topics and each
/// robot's raw odometry ([`raw_odometry_is_what_the_base_published`]).
#[test]
fn fleet_up_ros2_ends_where_the_simulator_ends() {
    let _fleet = common::one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    echelon_ok(
        &[
            "fleet",
            "up",
            SCENARIO,
            "--ros2",
            "--time-scale",
            "10",
            "--duration",
            "30",
            "--quiet",
            "--out",
        ],
        dir.path(),
    );
    let up: Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("fleet-summary.json")).unwrap(),
    )
    .unwrap();
    let sim = simulated_final("30", &dir.path().join("sim"));
    let robots = up["robots"].as_array().unwrap();
    assert_eq!(robots.len(), sim.len());
    for (r, (x, y)) in robots.iter().zip(&sim) {
        let st = r["final_state"].as_array().unwrap();
        let (rx, ry) = (st[0].as_f64().unwrap(), st[1].as_f64().unwrap());
        let d = (rx - x).hypot(ry - y);
        assert!(d < 5e-3, "robot {}: {d} m from the simulator", r["agent"]);
        assert!(f(r, &["final_error"]) < 5e-3, "{r}");
        drove_cleanly(&r["ros2"]);
    }
    for b in up["bases"].as_array().unwrap() {
        let c = &b["counters"];
        assert_eq!(f(c, &["cmd_received"]), f(c, &["cmd_accepted"]), "{b}");
        assert_eq!(b["last_command"], serde_json::json!([0.0, 0.0]), "{b}");
    }
    let col = &up["collector"];
    assert!(f(col, &["ros_recorded"]) > 1000.0, "{col}");
    assert_eq!(f(col, &["ros_refused"]), 0.0, "{col}");
    raw_odometry_is_what_the_base_published(dir.path());
}

/// Issue 22: the collector keeps each ROS 2 robot's raw odometry. In the
/// run's `fleet.mcap`, every `/agent/K/state` carries `odometry` (`raw`,
/// `age`, `fix_age`): `raw` is, bit for bit, the pose of an odometry
/// message its base published in its odom frame (`/robotK/odom`, as the
/// collector recorded it; the heading unwrapped), the world pose is
/// `odom_origin ⊕ raw` (no fixes: the origin is the agent's start), the
/// age is within the odometry timeout and `fix_age` is null. `odometry.csv`
/// has the same, one row per started state.
fn raw_odometry_is_what_the_base_published(dir: &Path) {
    use std::collections::BTreeMap;
    let scenario = echelon::scenario::Scenario::builtin(SCENARIO).unwrap();
    let links = scenario.fleet().unwrap().ros2;
    let bytes = std::fs::read(dir.join("fleet.mcap")).unwrap();
    // Per robot: odometry poses `[x, y, yaw]` as the base published them.
    let mut odom: BTreeMap<u32, Vec<[f64; 3]>> = BTreeMap::new();
    let mut states: Vec<(u32, Value)> = Vec::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let topic = m.channel.topic.as_str();
        if let Some(k) = topic
            .strip_prefix("/agent/")
            .and_then(|r| r.strip_suffix("/state"))
        {
            states.push((k.parse().unwrap(), serde_json::from_slice(&m.data).unwrap()));
        } else if let Some(k) = topic
            .strip_prefix("/robot")
            .and_then(|r| r.strip_suffix("/odom"))
        {
            let o = Odometry::from_cdr_finite(&m.data).unwrap();
            let p = o.pose.pose.position;
            odom.entry(k.parse().unwrap())
                .or_default()
                .push([p.x, p.y, o.yaw()]);
        }
    }
    for poses in odom.values_mut() {
        poses.sort_by(|a, b| a[0].total_cmp(&b[0]));
    }
    // The published odometry at `(x, y)` (to the last bit of a JSON
    // round trip): its yaw.
    let published = |k: u32, x: f64, y: f64| -> Option<f64> {
        let poses = &odom[&k];
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * (1.0 + b.abs());
        let from = poses.partition_point(|p| p[0] < x - 1e-9);
        poses[from..]
            .iter()
            .take_while(|p| p[0] <= x + 1e-9)
            .find(|p| close(p[0], x) && close(p[1], y))
            .map(|p| p[2])
    };
    assert_eq!(odom.len(), links.len(), "every base's odometry recorded");
    let mut checked = BTreeMap::new();
    for (k, v) in &states {
        let o = &v["odometry"];
        let raw: Vec<f64> = o["raw"]
            .as_array()
            .unwrap_or_else(|| panic!("robot {k}: no raw odometry in {v}"))
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        let yaw = published(*k, raw[0], raw[1])
            .unwrap_or_else(|| panic!("robot {k}: raw {raw:?} is no odometry its base published"));
        assert!(
            echelon::model::wrap_angle(raw[2] - yaw).abs() < 1e-12,
            "robot {k}: raw heading {} against {yaw}",
            raw[2]
        );
        let link = &links[*k as usize - 1];
        let world = link.odom_origin.compose(&echelon::model::Pose {
            x: raw[0],
            y: raw[1],
            theta: raw[2],
        });
        let got = [f(v, &["x"]), f(v, &["y"]), f(v, &["theta"])];
        let want = [world.x, world.y, world.theta];
        for (g, w) in got.iter().zip(want) {
            assert!(
                (g - w).abs() < 1e-9,
                "robot {k}: world {got:?}, odom_origin ⊕ raw {want:?}"
            );
        }
        let age = f(o, &["age"]);
        assert!(
            (0.0..=link.odom_timeout).contains(&age),
            "robot {k}: age {age}"
        );
        assert!(o["fix_age"].is_null(), "robot {k}: {o}");
        // No `[odometry]`: its error is unknown, σ 0.
        assert_eq!(f(v, &["sigma"]), 0.0, "robot {k}");
        *checked.entry(*k).or_insert(0) += 1;
    }
    assert!(checked.values().all(|&n| n > 500), "{checked:?}");
    // The same in odometry.csv, one row per started state.
    let csv = std::fs::read_to_string(dir.join("odometry.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(
        lines.next(),
        Some("t,agent,x,y,theta,x_raw,y_raw,theta_raw,age,fix_age")
    );
    let mut rows = 0;
    for line in lines {
        let cells: Vec<&str> = line.split(',').collect();
        assert_eq!(cells.len(), 10, "{line}");
        assert_eq!(cells[9], "", "no fix: {line}");
        let n: Vec<f64> = cells[..9].iter().map(|c| c.parse().unwrap()).collect();
        let k = n[1] as u32;
        assert!(published(k, n[5], n[6]).is_some(), "{line}");
        let world = links[k as usize - 1]
            .odom_origin
            .compose(&echelon::model::Pose {
                x: n[5],
                y: n[6],
                theta: n[7],
            });
        assert!(
            (world.x - n[2]).abs() < 1e-9 && (world.y - n[3]).abs() < 1e-9,
            "{line}"
        );
        rows += 1;
    }
    assert!(rows > 1000, "{rows} rows");
}

/// What the test session heard on robot 1's `cmd_vel`: `(v, ω)` in order.
type Heard = Arc<Mutex<Vec<(f64, f64)>>>;

/// Robot 1 drives a simulated base; the base dies and the test then puts
/// garbage, truncated CDR, NaN poses and a wrong type hash on the odom
/// topic: each is counted and refused and the robot commands zero and holds.
/// SIGTERM then leaves a zero `cmd_vel` as the last message on its key.
#[test]
fn bad_odometry_is_refused_and_sigterm_leaves_zero_on_cmd_vel() {
    let _fleet = common::one_fleet_at_a_time();
    let e = ports(4);
    let session = echelon_fleet::net::open(&echelon_fleet::net::NetOptions {
        listen: vec![e[0].clone()],
        ..Default::default()
    })
    .unwrap();
    let heard: Heard = Arc::default();
    let h = heard.clone();
    let cmd_key = "0/robot1/cmd_vel/**";
    let _sub = session
        .declare_subscriber(cmd_key)
        .callback(move |s| {
            let m = TwistStamped::from_cdr_finite(&s.payload().to_bytes()).unwrap();
            h.lock()
                .unwrap()
                .push((m.twist.linear.x, m.twist.angular.z));
        })
        .wait()
        .unwrap();
    let base_net = mesh(&e[1], &e[..1]);
    let base = spawn(&args(
        &["fleet", "base", SCENARIO, "--ros2", "--agent", "1"],
        &base_net,
    ));
    let robot_net = mesh(&e[2], &e[..2]);
    let robot = spawn(&args(
        &["fleet", "robot", SCENARIO, "--ros2", "--agent", "1"],
        &robot_net,
    ));
    let leader_net = mesh(&e[3], &e[..3]);
    let _leader = spawn(&args(
        &[
            "fleet",
            "leader",
            SCENARIO,
            "--wait-for",
            "robot/1",
            "--wait-for",
            "base/1",
        ],
        &leader_net,
    ));
    // Until the robot drives (a non-zero command).
    let start = Instant::now();
    while !heard
        .lock()
        .unwrap()
        .iter()
        .any(|&(v, w)| v != 0.0 || w != 0.0)
    {
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "robot 1 never moved"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    std::thread::sleep(Duration::from_secs(1));
    base.terminate();
    let base_report = base.report();
    assert!(
        f(&base_report, &["counters", "cmd_accepted"]) > 10.0,
        "{base_report}"
    );

    // Only bad odometry from now on.
    let odom_key = topic_key(
        echelon_ros2::KeyScheme::RmwZenoh,
        0,
        "/robot1/odom",
        &ODOMETRY,
    );
    let good = Odometry::planar(
        0.0,
        -0.6,
        1.5,
        0.0,
        0.0,
        Time::default(),
        "odom",
        "base_link",
    )
    .to_cdr();
    let nan = Odometry::planar(
        f64::NAN,
        -0.6,
        1.5,
        0.0,
        0.0,
        Time::default(),
        "odom",
        "base_link",
    )
    .to_cdr();
    let wrong_type = topic_key(echelon_ros2::KeyScheme::RmwZenoh, 0, "/robot1/odom", &TWIST);
    let mut sent = 0;
    let garbage_from = heard.lock().unwrap().len();
    for _ in 0..20 {
        session.put(&odom_key, b"garbage".to_vec()).wait().unwrap();
        session.put(&odom_key, good[..40].to_vec()).wait().unwrap();
        session.put(&odom_key, nan.clone()).wait().unwrap();
        session.put(&wrong_type, good.clone()).wait().unwrap();
        sent += 1;
        std::thread::sleep(Duration::from_millis(50));
    }
    // The odometry went stale 0.5 s after the base died: zero ever since
    // (allowing the in-flight commands of that half second).
    let after: Vec<_> = heard.lock().unwrap()[garbage_from..].to_vec();
    let tail = &after[after.len() / 2..];
    assert!(
        !tail.is_empty() && tail.iter().all(|&c| c == (0.0, 0.0)),
        "{tail:?}"
    );

    robot.terminate();
    let report = robot.report();
    std::thread::sleep(Duration::from_millis(300));
    let ros = &report["ros2"];
    for k in ["odom_malformed", "odom_non_finite", "odom_wrong_type"] {
        assert!(
            f(ros, &[k]) >= f64::from(sent) * if k == "odom_malformed" { 2.0 } else { 1.0 } - 2.0,
            "{k}: {ros}"
        );
    }
    assert!(f(ros, &["cmd_zero"]) > 0.0);
    let last = *heard.lock().unwrap().last().unwrap();
    assert_eq!(last, (0.0, 0.0), "the last cmd_vel after SIGTERM");
}

fn fake_base() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scripts/ros2/fake_base.py")
}

/// The liveliness tokens `fake_base.py` saw.
fn tokens(base: &Value) -> Vec<&str> {
    base["tokens"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(Value::as_str)
        .collect()
}

/// [`SCENARIO`] written to `dir/<name>.toml` with `agent1` added to agent
/// 1's table and `ros2` as its `[fleet.ros2]` section.
fn variant(dir: &Path, name: &str, agent1: &str, ros2: &str) -> PathBuf {
    let src = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../../scenarios/{SCENARIO}.toml")),
    )
    .unwrap();
    let src = src.replacen("[[agents]]\n", &format!("[[agents]]\n{agent1}"), 1);
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(&path, format!("{src}\n[fleet.ros2]\n{ros2}")).unwrap();
    path
}

/// Robot 1 of `scenario` (and a leader) against `fake_base.py` with
/// `base_args`, 10 s of fleet time; the robot's and the base's reports.
///
/// The base is a robot switched on at `origin` (world `[x, y, θ]`): its
/// odometry starts at zero there, so it starts at `origin⁻¹ ⊕ start` in its
/// odom frame; the scenario must say so (`odom_origin`, or nothing when
/// `origin` is agent 1's start). At the end the robot's world pose is the
/// base's odometry carried by `origin`.
fn drive_python_base(scenario: &str, base_args: &[&str], origin: [f64; 3]) -> (Value, Value) {
    let (sin, cos) = origin[2].sin_cos();
    let (dx, dy) = (START[0] - origin[0], START[1] - origin[1]);
    let odom_start = [
        cos * dx + sin * dy,
        -sin * dx + cos * dy,
        START[2] - origin[2],
    ]
    .map(|v| v.to_string());
    let e = ports(3);
    let dir = tempfile::tempdir().unwrap();
    let report_path = dir.path().join("base.json");
    let python = std::env::var("ECHELON_PYTHON").unwrap_or_else(|_| "python3".to_owned());
    let mut child = Command::new(&python)
        .arg(fake_base())
        .args(["--listen", &e[0], "--namespace", "/robot1", "--duration", "25"])
        .args(["--x", &odom_start[0], "--y", &odom_start[1], "--yaw", &odom_start[2]])
        .args(base_args)
        .arg("--report")
        .arg(&report_path)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| {
            panic!("cannot run `{python}`: {e}; run `scripts/test` (it installs scripts/requirements-test.txt)")
        });
    let robot_net = mesh(&e[1], &e[..1]);
    let robot = spawn(&args(
        &[
            "fleet",
            "robot",
            scenario,
            "--ros2",
            "--agent",
            "1",
            "--duration",
            "10",
        ],
        &robot_net,
    ));
    let leader_net = mesh(&e[2], &e[..2]);
    let leader = spawn(&args(
        &[
            "fleet",
            "leader",
            scenario,
            "--duration",
            "10",
            "--wait-for",
            "robot/1",
            "--wait-timeout",
            "60",
        ],
        &leader_net,
    ));
    let report = robot.report();
    leader.report();
    let _ = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status();
    let status = child.wait().unwrap();
    let mut err = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut err).unwrap();
    assert!(status.success(), "fake_base.py: {status}: {err}");
    assert!(f(&report, &["final_error"]) < 5e-3, "{report}");
    let base: Value =
        serde_json::from_str(&std::fs::read_to_string(&report_path).unwrap()).unwrap();
    let odom = [
        f(&base, &["final_pose", "x"]),
        f(&base, &["final_pose", "y"]),
    ];
    let world = [
        origin[0] + cos * odom[0] - sin * odom[1],
        origin[1] + sin * odom[0] + cos * odom[1],
    ];
    let robot = [0, 1].map(|k| report["final_state"][k].as_f64().unwrap());
    assert!(
        (world[0] - robot[0]).hypot(world[1] - robot[1]) < 1e-2,
        "the base's odometry {odom:?} carried by {origin:?} is {world:?}, the robot ended at {robot:?}"
    );
    (report, base)
}

/// The robot process against an independent ROS 2 base (eclipse-zenoh and
/// rclpy serialization, `scripts/ros2/fake_base.py`, an ideal unicycle):
/// the base decodes every command with its attachment and sees the robot's
/// rmw_zenoh tokens, and the robot converges to its slot (final ‖e‖ < 5 mm
/// after 10 s; the transient settles in about 2.3 s).
#[test]
fn a_robot_process_drives_a_python_ros2_base_to_its_slot() {
    let _fleet = common::one_fleet_at_a_time();
    // Switched on at its start mark: its odometry starts at zero.
    let (report, base) = drive_python_base(SCENARIO, &[], START);
    assert_eq!(f(&report, &["ros2", "odom_wrong_type"]), 0.0, "{report}");
    let commands = f(&base, &["commands"]);
    assert!(commands > 300.0, "{base}");
    assert_eq!(f(&base, &["attachments_valid"]), commands, "{base}");
    assert_eq!(f(&base, &["undecodable"]), 0.0);
    assert_eq!(
        base["last_command"]["v"], 0.0,
        "the robot stopped with zero"
    );
    assert_eq!(base["last_command"]["frame_id"], "base_link");
    let tokens = tokens(&base);
    assert!(
        tokens
            .iter()
            .any(|t| t.ends_with("/NN/%/%robot1/echelon_robot")),
        "{tokens:?}"
    );
    assert!(
        tokens.iter().any(|t| t.contains(
            "/MP/%/%robot1/echelon_robot/%robot1%cmd_vel/geometry_msgs::msg::dds_::TwistStamped_/"
        )),
        "{tokens:?}"
    );
}

/// Secure mode with ROS 2: every link is mutual TLS (QUIC), and a rogue
/// holding a valid certificate (robot 2's) that floods robot 1's `cmd_vel`
/// with a full-speed command reaches no base: base 1 heard exactly what
/// robot 1 sent, and robot 1 converged.
///
/// Over Zenoh's `tls` link this test was ignored: zenoh-link-tls reads and
/// writes one rustls stream from two tasks through an `UnsafeCell`
/// (eclipse-zenoh/zenoh#2557, open), and a fleet process died with SIGILL
/// inside rustls about one run in six. The secure mode now runs over QUIC.
#[test]
fn secure_ros2_fleet_takes_cmd_vel_only_from_its_robot() {
    let _fleet = common::one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let certs = common::certs(dir.path(), 2);
    let fleet_dir = dir.path().join("fleet");
    let fleet = std::thread::spawn({
        let (fleet_dir, certs) = (fleet_dir.clone(), certs.clone());
        move || {
            Command::new(EXE)
                .args(["fleet", "up", SCENARIO, "--ros2", "--time-scale", "10"])
                .args(["--duration", "30", "--quiet", "--secure"])
                .arg(&certs)
                .arg("--out")
                .arg(&fleet_dir)
                .output()
                .unwrap()
        }
    });
    let connect: Vec<String> = common::endpoints_of(&fleet_dir).into_values().collect();
    assert!(
        connect.iter().all(|e| e.starts_with("quic/")),
        "{connect:?}"
    );
    let tls = common::tls_as(&certs, "robot-2");
    let config = common::outsider_config(&connect, tls, 10000, false);
    let rogue = zenoh::open(zenoh::Config::from_json5(&config.to_string()).unwrap())
        .wait()
        .unwrap();
    let key = topic_key(
        echelon_ros2::KeyScheme::RmwZenoh,
        0,
        "/robot1/cmd_vel",
        &echelon_ros2::msgs::TWIST_STAMPED,
    );
    let attachment = echelon_ros2::Attachment {
        sequence_number: 1,
        source_timestamp_ns: 1,
        gid: [9; 16],
    }
    .encode();
    let payload = TwistStamped::planar(1.0, 2.0, Time::default(), "base_link").to_cdr();
    let mut puts = 0;
    while !fleet.is_finished() {
        rogue
            .put(&key, payload.clone())
            .attachment(attachment.to_vec())
            .wait()
            .unwrap();
        puts += 1;
        std::thread::sleep(Duration::from_millis(5));
    }
    check(&fleet.join().unwrap(), "fleet up");
    assert!(puts > 100, "the rogue published {puts}");
    let up: Value = serde_json::from_str(
        &std::fs::read_to_string(fleet_dir.join("fleet-summary.json")).unwrap(),
    )
    .unwrap();
    let robot = &up["robots"][0];
    let base = &up["bases"][0];
    let sent = f(robot, &["ros2", "cmd_sent"]);
    let heard = f(base, &["counters", "cmd_received"]);
    // At most what robot 1 sent (a few of its first, waiting, zeros may go
    // before the links are up); the rogue's hundreds of puts would show.
    assert!(
        heard <= sent && heard > 0.9 * sent,
        "base 1 heard {heard}, robot 1 sent {sent}"
    );
    assert!(f(robot, &["final_error"]) < 5e-3, "{robot}");
}

/// The other wire options against the same independent base: plain
/// `geometry_msgs/Twist` commands and zenoh-bridge-ros2dds's keys (no type,
/// hash or attachment on the key).
#[test]
fn twist_commands_over_bridge_keys_drive_the_python_base_too() {
    let _fleet = common::one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    // And a robot switched on elsewhere than its start mark: its odometry
    // origin is given in the world.
    let origin = [1.0, 2.0, 0.3];
    let scenario = variant(
        dir.path(),
        "bridge",
        &format!(
            "odom_origin = {{ x = {}, y = {}, theta = {} }}\n",
            origin[0], origin[1], origin[2]
        ),
        "cmd_vel_type = \"twist\"\nkey_scheme = \"bridge\"\n",
    );
    let (_, base) = drive_python_base(
        scenario.to_str().unwrap(),
        &["--cmd-type", "twist", "--scheme", "bridge"],
        origin,
    );
    assert_eq!(base["cmd_key"], "robot1/cmd_vel", "{base}");
    assert!(f(&base, &["commands"]) > 300.0, "{base}");
    assert_eq!(f(&base, &["undecodable"]), 0.0);
    assert_eq!(base["last_command"]["v"], 0.0);
}

/// A Humble robot (rmw_zenoh's humble branch: `TypeHashNotSupported` where
/// Jazzy writes the type hash, in keys and liveliness tokens) under
/// `key_scheme = "rmw_zenoh_humble"`: the independent base hears every
/// command on Humble's key, sees the robot's Humble tokens, and the robot
/// takes its odometry and converges.
#[test]
fn a_humble_robot_is_driven_over_humbles_keys() {
    let _fleet = common::one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let scenario = variant(
        dir.path(),
        "humble",
        "",
        "key_scheme = \"rmw_zenoh_humble\"\n",
    );
    let (report, base) = drive_python_base(
        scenario.to_str().unwrap(),
        &["--scheme", "rmw_zenoh_humble"],
        START,
    );
    assert_eq!(
        base["cmd_key"],
        "0/robot1/cmd_vel/geometry_msgs::msg::dds_::TwistStamped_/TypeHashNotSupported",
        "{base}"
    );
    assert!(f(&base, &["commands"]) > 300.0, "{base}");
    assert_eq!(f(&base, &["attachments_valid"]), f(&base, &["commands"]));
    assert_eq!(f(&report, &["ros2", "odom_wrong_type"]), 0.0, "{report}");
    let tokens = tokens(&base);
    assert!(
        tokens.iter().any(|t| t.contains(
            "/MP/%/%robot1/echelon_robot/%robot1%cmd_vel/geometry_msgs::msg::dds_::TwistStamped_/TypeHashNotSupported/"
        )),
        "{tokens:?}"
    );
    assert!(!tokens.iter().any(|t| t.contains("RIHS01_")), "{tokens:?}");
}

/// A bad `[fleet.ros2]` value stops `fleet robot --ros2` and `fleet up
/// --ros2` before anything starts: one line naming file, line, column and
/// field, exit 2.
#[test]
fn a_bad_ros2_setting_is_refused_with_its_place() {
    let dir = tempfile::tempdir().unwrap();
    let src = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../scenarios/experiment-circle-velocity.toml"),
    )
    .unwrap();
    let line = src.lines().count() + 3;
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, format!("{src}\n[fleet.ros2]\ndomain_id = 300\n")).unwrap();
    let bad = bad.to_str().unwrap();
    let out_dir = dir.path().join("out");
    for args in [
        vec!["fleet", "robot", bad, "--agent", "1", "--ros2"],
        vec![
            "fleet",
            "up",
            bad,
            "--ros2",
            "--out",
            out_dir.to_str().unwrap(),
        ],
    ] {
        let out = Command::new(EXE).args(&args).output().unwrap();
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(
            err.contains(&format!(
                "{bad}:{line}:13: fleet.ros2.domain_id: 300 is not a ROS domain id"
            )),
            "{err}"
        );
    }
}

/// A robot driving a real ROS 2 base runs in real time: `--time-scale` is
/// refused (exit 2, one line) unless its base is `fleet base`'s simulation.
#[test]
fn a_real_robot_refuses_a_time_scale() {
    let out = Command::new(EXE)
        .args([
            "fleet",
            "robot",
            SCENARIO,
            "--agent",
            "1",
            "--ros2",
            "--time-scale",
            "10",
        ])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(
        err.contains("real time") && err.contains("--time-scale 10"),
        "{err}"
    );
}

/// `fleet excite --ros2` on a simulated ROS 2 base (`fleet base --ros2`,
/// lags τ_v = τ_ω = 0.1 s with its speed and acceleration limits, the
/// scenario's `lab` robot), in real time for 16 s: it completes within a
/// 1 m radius, and `echelon identify` recovers both lags within 5 % from
/// the bag it wrote.
#[test]
fn fleet_excite_records_a_bag_that_identify_turns_into_the_base_lags() {
    let _fleet = common::one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let bag = dir.path().join("excite.mcap");
    let e = ports(2);
    let base_net = mesh(&e[0], &[]);
    let base = spawn(&args(
        &["fleet", "base", SCENARIO, "--ros2", "--agent", "1"],
        &base_net,
    ));
    let excite_net = mesh(&e[1], &e[..1]);
    let bag_arg = bag.to_str().unwrap();
    let excite = spawn(&args(
        &[
            "fleet",
            "excite",
            SCENARIO,
            "--ros2",
            "--agent",
            "1",
            "--duration",
            "16",
            "--out",
            bag_arg,
        ],
        &excite_net,
    ));
    let report = excite.report();
    base.terminate();
    let base_report = base.report();
    assert_eq!(report["ended"], "completed", "{report}");
    assert!(f(&report, &["max_distance"]) <= 1.0, "{report}");
    assert!(f(&report, &["cmd_recorded"]) > 250.0, "{report}");
    assert!(f(&report, &["odom_recorded"]) > 250.0, "{report}");
    assert!(
        f(&base_report, &["counters", "cmd_accepted"]) >= f(&report, &["cmd_recorded"]) - 1.0,
        "{base_report}"
    );
    let out = dir.path().join("id");
    let o = Command::new(EXE)
        .args(["identify", bag_arg, "--out", out.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let json: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("identify.json")).unwrap()).unwrap();
    // `fleet base` publishes noise-free odometry and applies each command
    // when it arrives: the processes' timing jitter is then the only
    // residual, which the misfit check (issue 20) must name rather than print
    // a lag it cannot vouch for. Either a lag within 5 % of the base's 0.1 s,
    // or no number and the misfit said.
    for (i, field) in ["tau_v", "tau_omega"].into_iter().enumerate() {
        let p = &json["params"][i];
        assert_eq!(p["field"], field);
        match p["estimate"]["value"].as_f64() {
            Some(tau) => assert!((tau / 0.1 - 1.0).abs() < 0.05, "{field} = {tau}: {json}"),
            None => {
                let why = p["not_identifiable"].as_str().unwrap_or_default();
                assert!(why.contains("misfits this log"), "{field}: {json}");
            }
        }
    }
}

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

[control]
law = "kinematic"
ke = 1.5
kz = 10.0
l = 0.05
lycomp = "fit"
ly_derivatives = "neglect"

[robots.lab]
drive = "velocity"
tau_v = 0.1
tau_omega = 0.1
v_max = 0.3
omega_max = 2.0
a_max = 1.0
alpha_max = 5.0
half_wheelbase = 0.15
wheel_radius = 0.05

[reference.circle]
speed = 0.08
turn_rate = 0.08
start = {{ x = 0.0, y = 0.0, theta_deg = 0.0 }}

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
    let up: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("fleet-summary.json")).unwrap())
            .unwrap();
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

/// A robot process whose robot's router answers but carries no odometry
/// (the robot's driver not running) does not join the fleet: after 30 s it
/// fails (exit 2) naming the topic and the router.
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
        err.contains(&format!(
            "nothing arrived from agent 1's robot (/robot1/odom at {})",
            e[0]
        )),
        "{err}"
    );
    assert!(started.elapsed() >= Duration::from_secs(30), "{err}");
}
