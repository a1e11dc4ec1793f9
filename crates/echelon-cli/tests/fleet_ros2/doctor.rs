//! `fleet doctor` before a run, one test per finding, with the hub's
//! router on 127.0.0.2 and the robot's own router (its "rmw_zenohd", with a
//! `fleet base` behind it) on 127.0.0.3, the doctor on 127.0.0.1: a healthy
//! fleet passes every row (exit 0); odometry under another namespace, too
//! slow, a robot process whose clock is 200 ms off, an unreachable robot
//! router (or hub) and an expired certificate each fail their row (exit 1),
//! in bounded time; an endpoint that does not parse exits 2 with one line.
//! The doctor sends a robot nothing (a base's report counts no command).

use echelon::scenario::Scenario;
use echelon_fleet::net::Secure;

use super::*;

mod lab;
use lab::{
    Doctor, HUB_IP, ROBOT_IP, endpoint_on, lab, one_robot, robot_process, wait_alive, wait_hub,
};

/// A healthy fleet: the hub reached, its router's probe answering with
/// this version and clock, the robot's router reached at its
/// `ros2.connect`, odometry at the scenario's 20 Hz, a `cmd_vel` reader,
/// 10 Hz fixes, the robot process running with the same version and a
/// clock within 5 ms of the hub's: every row passes, exit 0, nothing on
/// stderr, well within the listening time and the timeouts.
#[test]
fn a_healthy_fleet_passes_every_row() {
    let _fleet = common::one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let lab = lab(|robot| one_robot(dir.path(), "healthy", robot, 20.0, ""));
    let scenario = one_robot(dir.path(), "healthy", &lab.robot, 20.0, "");
    let _robot = robot_process(&lab, &scenario, &[]);
    let d = Doctor::run(&[&scenario, "--hub", &lab.hub]);
    d.only_failed(&[], &[]);
    for (subject, check) in [
        ("hub", "reachable"),
        ("hub", "router probe"),
        ("hub", "version"),
        ("hub", "clock offset"),
        ("hub", "round trip"),
        ("robot-1", "ros 2 reachable"),
        ("robot-1", "odometry"),
        ("robot-1", "cmd_vel reader"),
        ("robot-1", "fixes"),
        ("robot-1", "robot process"),
        ("robot-1", "version"),
        ("robot-1", "clock offset"),
        ("robot-1", "round trip"),
    ] {
        let _ = d.row(subject, check);
    }
    assert_eq!(d.row("robot-1", "ros 2 reachable")["value"], lab.robot);
    assert_eq!(d.row("hub", "reachable")["value"], lab.hub);
    let hz: f64 = d.row("robot-1", "odometry")["value"]
        .as_str()
        .and_then(|v| v.strip_suffix(" Hz"))
        .unwrap()
        .parse()
        .unwrap();
    assert!((19.0..=21.0).contains(&hz), "{hz} Hz");
    eprintln!(
        "healthy: {:.1} s; odometry {hz} Hz; robot clock {}; round trip {}; fixes {}",
        d.took.as_secs_f64(),
        d.row("robot-1", "clock offset")["value"],
        d.row("robot-1", "round trip")["value"],
        d.row("robot-1", "fixes")["value"]
    );
    assert!(d.took < Duration::from_secs(15), "{:?}", d.took);
}

/// The robot's base runs under `/x1` while the scenario says `/robot1`:
/// the odometry row fails naming what it heard and what the scenario says
/// (and the `cmd_vel` reader and the fixes, under `/x1` too, fail), exit 1.
#[test]
fn odometry_under_another_namespace_is_named() {
    let _fleet = common::one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let lab = lab(|robot| one_robot(dir.path(), "x", robot, 20.0, "namespace = \"/x{k}\""));
    let scenario = one_robot(dir.path(), "doctor", &lab.robot, 20.0, "");
    let d = Doctor::run(&[&scenario, "--hub", &lab.hub]);
    let failing = [
        ("robot-1", "odometry"),
        ("robot-1", "cmd_vel reader"),
        ("robot-1", "fixes"),
    ];
    d.only_failed(&failing, &[("robot-1", "robot process")]);
    let detail = d.row("robot-1", "odometry")["detail"].as_str().unwrap();
    assert!(
        detail.starts_with("wrong namespace: heard /x1/odom, the scenario says /robot1/odom"),
        "{detail}"
    );
    let graph = d.row("robot-1", "cmd_vel reader")["detail"]
        .as_str()
        .unwrap();
    assert!(
        graph.contains("nothing under /robot1: topics seen under /x1"),
        "{graph}"
    );
}

/// The base publishes odometry at 2 Hz (its scenario's `odom_rate`) where
/// the doctor's scenario says 20 Hz: that row alone fails, measuring 2 Hz;
/// exit 1. The doctor sent the base nothing: its report counts no command.
#[test]
fn odometry_too_slow_fails_its_row() {
    let _fleet = common::one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let mut lab = lab(|robot| one_robot(dir.path(), "slow", robot, 2.0, ""));
    let scenario = one_robot(dir.path(), "doctor", &lab.robot, 20.0, "");
    let d = Doctor::run(&[&scenario, "--hub", &lab.hub]);
    d.only_failed(&[("robot-1", "odometry")], &[("robot-1", "robot process")]);
    let row = d.row("robot-1", "odometry");
    let hz: f64 = row["value"]
        .as_str()
        .and_then(|v| v.strip_suffix(" Hz"))
        .unwrap()
        .parse()
        .unwrap();
    assert!((1.5..=2.5).contains(&hz), "{row}");
    assert!(
        row["detail"]
            .as_str()
            .unwrap()
            .contains("the scenario says 20 Hz"),
        "{row}"
    );
    let base = lab.base.take().unwrap();
    base.terminate();
    let report = base.report();
    assert_eq!(f(&report, &["counters", "cmd_received"]), 0.0, "{report}");
    assert!(
        f(&report, &["counters", "odom_published"]) > 5.0,
        "{report}"
    );
}

/// The robot process's wall clock runs 200 ms ahead of the hub's
/// (`--wall-clock-jump 0:0.2`, stepped at its first tick): its clock row
/// fails, measuring 200 ms within a few ms; every other row passes; exit 1.
#[test]
fn a_robot_clock_200_ms_off_fails() {
    let _fleet = common::one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let lab = lab(|robot| one_robot(dir.path(), "doctor", robot, 20.0, ""));
    let scenario = one_robot(dir.path(), "doctor", &lab.robot, 20.0, "");
    let _robot = robot_process(&lab, &scenario, &["--wall-clock-jump", "0:0.2"]);
    let d = Doctor::run(&[&scenario, "--hub", &lab.hub]);
    d.only_failed(&[("robot-1", "clock offset")], &[]);
    let row = d.row("robot-1", "clock offset");
    let ms: f64 = row["value"]
        .as_str()
        .and_then(|v| v.strip_suffix(" ms"))
        .unwrap()
        .parse()
        .unwrap();
    assert!((190.0..=210.0).contains(&ms), "{row}");
    eprintln!("a clock stepped by +200 ms measured at {ms} ms");
}

/// The robot's `ros2.connect` names a port nothing listens on: that row
/// fails naming the endpoint, within the timeout (2 s here), and the
/// doctor ends in bounded time; exit 1. The same with the hub's endpoint
/// answering nothing either.
#[test]
fn an_unreachable_robot_router_is_named_in_bounded_time() {
    let _fleet = common::one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let hub = endpoint_on("tcp", HUB_IP);
    let _router = spawn(&["fleet", "router", "--listen", &hub]);
    let nowhere = endpoint_on("tcp", ROBOT_IP);
    let scenario = one_robot(dir.path(), "doctor", &nowhere, 20.0, "");
    wait_hub(&hub, None);
    let d = Doctor::run(&[&scenario, "--hub", &hub, "--timeout", "2"]);
    d.only_failed(
        &[("robot-1", "ros 2 reachable")],
        &[("robot-1", "robot process")],
    );
    let row = d.row("robot-1", "ros 2 reachable");
    assert_eq!(row["value"], nowhere);
    assert!(
        row["detail"]
            .as_str()
            .unwrap()
            .contains("not reached within 2.0 s"),
        "{row}"
    );
    assert!(d.stderr.contains("robot-1 ros 2 reachable"), "{}", d.stderr);
    assert!(d.took < Duration::from_secs(10), "{:?}", d.took);
    eprintln!("unreachable robot router: {:.1} s", d.took.as_secs_f64());
    // A hub that never answers either: its row fails too, named, as soon.
    let no_hub = endpoint_on("tcp", HUB_IP);
    let d = Doctor::run(&[&scenario, "--hub", &no_hub, "--timeout", "2"]);
    d.only_failed(
        &[("hub", "reachable"), ("robot-1", "ros 2 reachable")],
        &[("robot-1", "robot process")],
    );
    assert_eq!(d.row("hub", "reachable")["value"], no_hub);
    assert!(d.took < Duration::from_secs(10), "{:?}", d.took);
}

/// Secure mode: certificates from `fleet certs` with robot 1's expired a
/// day ago (`--expires robot-1=-1`); the hub's router a `quic/` listener,
/// the base on the fleet's network as `base-1`, the doctor as the
/// operator. The certificate row of robot 1 fails (expired), every other
/// certificate, and everything else, passes; exit 1.
#[test]
fn an_expired_certificate_fails() {
    let _fleet = common::one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let certs = dir.path().join("certs");
    let certs_arg = certs.to_str().unwrap();
    echelon_ok(
        &[
            "fleet",
            "certs",
            "--robots",
            "1",
            "--host",
            HUB_IP,
            "--expires",
            "robot-1=-1",
        ],
        &certs,
    );
    let hub = endpoint_on("quic", HUB_IP);
    let scenario = one_robot(dir.path(), "doctor", "", 20.0, "");
    let secure = ["--secure", certs_arg];
    let _router = spawn(
        &[
            &["fleet", "router", &scenario, "--listen", &hub][..],
            &secure,
        ]
        .concat(),
    );
    let _base = spawn(
        &[
            &[
                "fleet", "base", &scenario, "--ros2", "--agent", "1", "--hub", &hub,
            ][..],
            &secure,
        ]
        .concat(),
    );
    let s = Scenario::resolve(&scenario).unwrap();
    let as_operator = Secure {
        dir: certs.clone(),
        identity: "operator".into(),
        robots: 1,
        ros2: echelon_fleet::net::ros_acl(&s.fleet().unwrap().ros2),
    };
    wait_alive(&hub, "base/1", Some(as_operator.clone()));
    wait_hub(&hub, Some(as_operator));
    let d = Doctor::run(&[&scenario, "--hub", &hub, "--secure", certs_arg]);
    d.only_failed(
        &[("robot-1", "certificate robot-1")],
        &[("robot-1", "robot process")],
    );
    let row = d.row("robot-1", "certificate robot-1");
    assert!(
        row["value"].as_str().unwrap().starts_with("expired "),
        "{row}"
    );
    for id in ["ca", "leader", "collector", "router", "operator"] {
        assert_eq!(d.row("hub", &format!("certificate {id}"))["status"], "pass");
    }
    assert_eq!(d.row("robot-1", "certificate base-1")["status"], "pass");
    assert_eq!(
        d.row("robot-1", "ros 2 reachable")["value"],
        "through the hub"
    );
}

/// An endpoint that does not parse, a listening time of 0: exit 2, one
/// line, nothing on stdout, nothing reached.
#[test]
fn bad_input_exits_2_with_one_line() {
    for args in [
        &["experiment-circle-velocity", "--hub", "tcp/127.0.0.2:99999"][..],
        &["experiment-circle-velocity", "--hub", "127.0.0.2:7447"],
        &["experiment-circle-velocity", "--listen-for", "0"],
        &["no-such-scenario"],
    ] {
        let out = Command::new(EXE)
            .args(["fleet", "doctor"])
            .args(args)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert_eq!(stderr.lines().count(), 1, "{args:?}: {stderr}");
        assert!(out.stdout.is_empty(), "{args:?}");
    }
}
