//! What the `fleet doctor` tests share: the lab (the hub's router, the
//! robot's router and a base behind it, on loopback addresses of their
//! own), its scenario, and the doctor run with `--json`.

use std::net::TcpListener;

use echelon_fleet::net::{Mode, NetOptions, Secure};

use super::super::*;
use common::Guard;

/// The hub's loopback address in these tests.
pub(super) const HUB_IP: &str = "127.0.0.2";
/// The robot's (its own router's) loopback address.
pub(super) const ROBOT_IP: &str = "127.0.0.3";
/// The scenario's fleet name.
pub(super) const FLEET: &str = "doctor-one";

/// A free port's endpoint on `ip` over `proto` (`tcp`; `quic` takes a UDP
/// port, and a TCP one free on the same number is as good a guess).
pub(super) fn endpoint_on(proto: &str, ip: &str) -> String {
    let l = TcpListener::bind((ip, 0)).unwrap();
    let u = std::net::UdpSocket::bind(l.local_addr().unwrap()).unwrap();
    format!("{proto}/{ip}:{}", u.local_addr().unwrap().port())
}

/// One lab robot (a lagged velocity base) whose ROS 2 robot is at
/// `connect` (empty: on the fleet's network), odometry at `odom_rate` Hz,
/// with a motion capture's fixes at 10 Hz; `ros2` more `[fleet.ros2]`
/// lines. Its `link_timeout`, 0.4 s, puts the round trips' warning at a
/// p99 of 100 ms (the machine's two cores are shared with other tests).
/// Written to `dir/NAME.toml`; its path.
pub(super) fn one_robot(
    dir: &Path,
    name: &str,
    connect: &str,
    odom_rate: f64,
    ros2: &str,
) -> String {
    let connect = match connect {
        "" => String::new(),
        c => format!("ros2 = {{ connect = \"{c}\" }}\n"),
    };
    let toml = format!(
        r#"name = "{FLEET}"

[sim]
duration = 12.0
dt = 0.001

{LAB_LAW_AND_BASE}
[odometry]
period = 0.02

[fixes]
source = "pose"
period = 0.1
position_noise = 0.005
latency = 0.03

[fleet]
link_timeout = 0.4

[fleet.ros2]
odom_rate = {odom_rate}
{ros2}
[[agents]]
robot = "lab"
start = {{ x = 0.0, y = -0.6, theta_deg = 90.0 }}
leader = "reference"
offset = {{ x = 0.30, y = 0.35 }}
{connect}"#
    );
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(&path, toml).unwrap();
    path.to_string_lossy().into_owned()
}

/// A client session of `connect` (in secure mode with `secure`).
pub(super) fn client(connect: &str, secure: Option<Secure>) -> zenoh::Session {
    echelon_fleet::net::open(&NetOptions {
        mode: Some(Mode::Client),
        connect: vec![connect.to_owned()],
        secure,
        ..NetOptions::default()
    })
    .unwrap()
}

/// Waits (30 s at most) until liveliness token `echelon/<FLEET>/alive/WHO`
/// is seen through `connect`.
pub(super) fn wait_alive(connect: &str, who: &str, secure: Option<Secure>) {
    let session = client(connect, secure);
    let key = format!("echelon/{FLEET}/alive/{who}");
    let started = Instant::now();
    loop {
        let replies = session
            .liveliness()
            .get(&key)
            .timeout(Duration::from_secs(1))
            .wait()
            .unwrap();
        if replies.recv().is_ok_and(|r| r.result().is_ok()) {
            break;
        }
        assert!(
            started.elapsed() < Duration::from_secs(30),
            "{who} never joined at {connect}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    session.close().wait().unwrap();
}

/// Waits (30 s at most) until the router at `hub` answers its probe.
pub(super) fn wait_hub(hub: &str, secure: Option<Secure>) {
    let session = client(hub, secure);
    let keys = echelon_fleet::keys::Keys::new(FLEET);
    let started = Instant::now();
    let second = Duration::from_secs(1);
    while echelon_fleet::probe::ask(&session, &keys, "router", 1, second, second)
        .unwrap()
        .answered
        == 0
    {
        assert!(started.elapsed() < Duration::from_secs(30), "{hub}");
        std::thread::sleep(Duration::from_millis(100));
    }
    session.close().wait().unwrap();
}

/// What one `fleet doctor … --json` said: its exit code, its report, its
/// stderr and how long it took.
pub(super) struct Doctor {
    pub(super) code: Option<i32>,
    pub(super) report: Value,
    pub(super) stderr: String,
    pub(super) took: Duration,
}

impl Doctor {
    pub(super) fn run(args: &[&str]) -> Doctor {
        let started = Instant::now();
        let out = Command::new(EXE)
            .args(["fleet", "doctor"])
            .args(args)
            .arg("--json")
            .output()
            .unwrap();
        let took = started.elapsed();
        let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
        let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
        let report = serde_json::from_str(&stdout)
            .unwrap_or_else(|e| panic!("{e}: {stdout}\nstderr: {stderr}"));
        Doctor {
            code: out.status.code(),
            report,
            stderr,
            took,
        }
    }

    pub(super) fn rows(&self) -> &Vec<Value> {
        self.report["rows"].as_array().unwrap()
    }

    /// The row of `subject`'s `check`.
    pub(super) fn row(&self, subject: &str, check: &str) -> &Value {
        self.rows()
            .iter()
            .find(|r| r["subject"] == subject && r["check"] == check)
            .unwrap_or_else(|| panic!("no {subject} {check}: {}", self.report))
    }

    /// Asserts that exactly the rows `failing` (subject, check) failed,
    /// every other one passing (or, those of `informative`, said for
    /// information), and that the exit code and stderr say so.
    pub(super) fn only_failed(&self, failing: &[(&str, &str)], informative: &[(&str, &str)]) {
        for r in self.rows() {
            let key = (r["subject"].as_str().unwrap(), r["check"].as_str().unwrap());
            let want = if failing.contains(&key) {
                "fail"
            } else if informative.contains(&key) {
                "info"
            } else {
                "pass"
            };
            assert_eq!(r["status"], want, "{r}\n{}", self.report);
        }
        for (subject, check) in failing {
            let _ = self.row(subject, check);
        }
        let code = if failing.is_empty() { 0 } else { 1 };
        assert_eq!(self.code, Some(code), "{}", self.stderr);
        assert_eq!(self.report["ok"], failing.is_empty());
        match failing {
            [] => assert!(self.stderr.is_empty(), "{}", self.stderr),
            _ => assert_eq!(self.stderr.lines().count(), 1, "{}", self.stderr),
        }
    }
}

/// The hub's router, the robot's own router and a base behind it (run
/// from scenario `base_from`), in plain mode; the endpoints and the
/// processes.
pub(super) struct Lab {
    pub(super) hub: String,
    pub(super) robot: String,
    pub(super) base: Option<Guard>,
    _routers: Vec<Guard>,
}

pub(super) fn lab(base_from: impl Fn(&str) -> String) -> Lab {
    let (hub, robot) = (endpoint_on("tcp", HUB_IP), endpoint_on("tcp", ROBOT_IP));
    let routers = vec![
        spawn(&["fleet", "router", "--listen", &hub]),
        spawn(&["fleet", "router", "--listen", &robot]),
    ];
    let scenario = base_from(&robot);
    let base = spawn(&[
        "fleet",
        "base",
        &scenario,
        "--ros2",
        "--agent",
        "1",
        "--mode",
        "client",
        "--connect",
        &robot,
    ]);
    wait_alive(&robot, "base/1", None);
    wait_hub(&hub, None);
    Lab {
        hub,
        robot,
        base: Some(base),
        _routers: routers,
    }
}

/// A robot process of `scenario` joining the hub (`extra` arguments
/// more), once it has joined.
pub(super) fn robot_process(lab: &Lab, scenario: &str, extra: &[&str]) -> Guard {
    let mut args = vec![
        "fleet", "robot", scenario, "--agent", "1", "--ros2", "--hub", &lab.hub,
    ];
    args.extend(extra);
    let robot = spawn(&args);
    wait_alive(&lab.hub, "robot/1", None);
    robot
}
