use super::*;
use crate::scenario::builtin;

const BASE: &str = include_str!("../../../tests/fixtures/fleet-base.toml");

fn parse(extra: &str) -> Result<FleetSettings, ScenarioError> {
    Scenario::parse(&format!("{BASE}{extra}"), "t.toml", None)?.fleet()
}

#[test]
fn every_builtin_has_the_defaults() {
    for (name, src) in builtin() {
        let s = Scenario::parse(src, name, None).unwrap_or_else(|e| panic!("{e}"));
        let f = s.fleet().unwrap_or_else(|e| panic!("{e}"));
        for (k, l) in f.ros2.iter().enumerate() {
            assert_eq!(l.namespace, format!("/robot{}", k + 1));
            assert_eq!(l.odom_timeout, DEFAULT_ODOM_TIMEOUT);
            assert_eq!(l.cmd_vel_stamp, CmdVelStamp::Zero);
        }
        assert_eq!(f.name, *name);
        assert_eq!(f.reference_rate, DEFAULT_REFERENCE_RATE);
        assert_eq!(f.control_rate, DEFAULT_CONTROL_RATE);
        assert!(f.link_loss.iter().all(|l| *l == LinkLoss::default()));
    }
}

#[test]
fn agent_settings_override_the_fleet_section() {
    let f = parse(
        "link_loss = { policy = \"stop\" }\n\n[fleet]\nname = \"lab.1\"\ncontrol_rate = 200\nlink_loss = { hold = 2.5 }\n",
    )
    .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(f.name, "lab.1");
    assert_eq!(f.control_rate, 200.0);
    assert_eq!(
        f.link_loss[0],
        LinkLoss {
            policy: LinkPolicy::Stop,
            hold: 2.5,
            decel: DEFAULT_DECEL
        }
    );
}

#[test]
fn bad_values_are_located() {
    let e = parse("\n[fleet]\nname = \"a/b\"\n")
        .err()
        .unwrap_or_else(|| panic!());
    assert_eq!(e.field, "fleet.name");
    assert!(
        e.location.line > 0 && e.message.contains("fleet name"),
        "{e}"
    );
    let e = parse("link_loss = { decel = -1.0 }\n")
        .err()
        .unwrap_or_else(|| panic!());
    assert_eq!(e.field, "agents[1].link_loss.decel");
    assert!(e.location.line > 0, "{e}");
    // A robot that cannot stop, set by the agent or by the file.
    let e = parse("link_loss = { decel = 0.0 }\n")
        .err()
        .unwrap_or_else(|| panic!());
    assert_eq!(e.field, "agents[1].link_loss.decel");
    assert!(e.message.contains("able to stop"), "{e}");
    let e = parse("\n[fleet.link_loss]\ndecel = 0.0\n")
        .err()
        .unwrap_or_else(|| panic!());
    assert_eq!(e.field, "fleet.link_loss.decel");
    assert!(e.message.contains("able to stop"), "{e}");
    let e = parse("\n[fleet.link_loss]\nhold = -1.0\n")
        .err()
        .unwrap_or_else(|| panic!());
    assert_eq!(e.field, "fleet.link_loss.hold");
    let e = parse("\n[fleet]\ncontrol_rate = 0\n")
        .err()
        .unwrap_or_else(|| panic!());
    assert_eq!(e.field, "fleet.control_rate");
    let e = parse("\n[fleet]\nrate = 5\n")
        .err()
        .unwrap_or_else(|| panic!());
    assert!(e.message.contains("unknown field"), "{e}");
    assert!(!is_valid_fleet_name("") && is_valid_fleet_name("a-b_c.9"));
}

#[test]
fn the_odom_origin_is_the_start_unless_given() {
    // BASE's agent starts at the origin, heading 0.
    let f = parse("").unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(f.ros2[0].odom_origin, Pose::default());
    let f = parse(
        "odom_origin = { x = 1.5, y = -2.0, theta_deg = 90.0 }
",
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let o = f.ros2[0].odom_origin;
    assert_eq!((o.x, o.y), (1.5, -2.0));
    assert!((o.theta - std::f64::consts::FRAC_PI_2).abs() < 1e-15);
    // A start pose away from the origin is the default origin.
    let src = BASE.replace(
        "[[agents]]\nstart = { x = 0.0, y = 0.0, theta = 0.0 }",
        "[[agents]]\nstart = { x = 3.0, y = 4.0, theta = 0.5, v = 0.2 }",
    );
    assert_ne!(src, BASE);
    let f = Scenario::parse(&src, "t.toml", None)
        .and_then(|s| s.fleet())
        .unwrap_or_else(|e| panic!("{e}"));
    let o = f.ros2[0].odom_origin;
    assert_eq!((o.x, o.y, o.theta), (3.0, 4.0, 0.5));
    // An origin is a pose: no speed, one heading, finite, located.
    assert_refused(&[
        (
            "odom_origin = { x = 0.0, y = 0.0, theta = 0.0, v = 1.0 }\n",
            "agents[1].odom_origin.v",
        ),
        (
            "odom_origin = { x = 0.0, y = 0.0, theta = 0.0, theta_deg = 1.0 }\n",
            "agents[1].odom_origin.theta_deg",
        ),
        (
            "odom_origin = { x = 0.0, y = 0.0 }\n",
            "agents[1].odom_origin",
        ),
        (
            "odom_origin = { x = nan, y = 0.0, theta = 0.0 }\n",
            "agents[1].odom_origin.x",
        ),
    ]);
}

#[test]
fn fixes_from_ros2_are_resolved_with_their_defaults() {
    // No source: no fixes from ROS 2 (the simulator's own fixes only).
    let f = parse(
        "fixes = { period = 0.1 }
",
    )
    .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(f.ros2[0].fixes, None);
    let f = parse(
        "fixes = { period = 0.1, source = \"pose\" }
",
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let src = f.ros2[0]
        .fixes
        .clone()
        .unwrap_or_else(|| panic!("a source"));
    assert_eq!(
        src,
        FixSource {
            topic: "/robot1/pose".into(),
            message: FixMessage::PoseStamped,
            frame: "map".into(),
            frame_origin: Pose::default(),
            timeout: None,
            tolerance: None,
            gate: true,
        }
    );
    // Every field given, over the file's [fixes].
    let f = parse(
        "fixes = { source = \"/mocap/r1/pose\", message = \"pose-with-covariance-stamped\", frame = \"mocap\", frame_origin = { x = 1.0, y = 2.0, theta_deg = 90.0 }, timeout = 2.0, tolerance = 0.05, gate = false }\n[fixes]\nperiod = 0.1\n",
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let src = f.ros2[0]
        .fixes
        .clone()
        .unwrap_or_else(|| panic!("a source"));
    assert_eq!(src.topic, "/mocap/r1/pose");
    assert_eq!(src.message, FixMessage::PoseWithCovarianceStamped);
    assert_eq!(src.frame, "mocap");
    assert_eq!((src.frame_origin.x, src.frame_origin.y), (1.0, 2.0));
    assert!((src.frame_origin.theta - std::f64::consts::FRAC_PI_2).abs() < 1e-15);
    assert_eq!(
        (src.timeout, src.tolerance, src.gate),
        (Some(2.0), Some(0.05), false)
    );
    // Turned off for the agent under a file's source.
    let f = parse("fixes = { enabled = false }\n[fixes]\nperiod = 0.1\nsource = \"pose\"\n")
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(f.ros2[0].fixes, None);
    // Bad values name their field and line.
    assert_refused(&[
        (
            "fixes = { period = 0.1, source = \"bad topic\" }\n",
            "agents[1].fixes.source",
        ),
        (
            "fixes = { period = 0.1, source = \"pose\", frame = \"a b\" }\n",
            "agents[1].fixes.frame",
        ),
        (
            "fixes = { period = 0.1, source = \"pose\", timeout = 0.0 }\n",
            "agents[1].fixes.timeout",
        ),
        (
            "fixes = { period = 0.1, source = \"pose\", tolerance = -1.0 }\n",
            "agents[1].fixes.tolerance",
        ),
        (
            "fixes = { period = 0.1, source = \"pose\", frame_origin = { x = 0.0, y = 0.0 } }\n",
            "agents[1].fixes.frame_origin",
        ),
        (
            "fixes = { period = 0.1, source = \"pose\", message = \"odometry\" }\n",
            "agents[1].fixes.message",
        ),
    ]);
}

#[test]
fn robot_routers_are_resolved_and_checked() {
    // None by default: the robot is on the fleet's network.
    let f = parse("").unwrap_or_else(|e| panic!("{e}"));
    assert!(f.ros2[0].connect.is_empty());
    // One endpoint per agent, `{k}` from [fleet.ros2], or the agent's list.
    let f = parse("\n[fleet.ros2]\nconnect = \"tcp/192.168.1.2{k}:7447\"\n")
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(f.ros2[0].connect, vec!["tcp/192.168.1.21:7447".to_owned()]);
    let f = parse(
        "ros2 = { connect = [\"tls/robot-1.lab:7448\", \"tcp/[fe80::1]:7447#iface=eth0\"] }\n[fleet.ros2]\nconnect = \"tcp/10.0.0.1:7447\"\n",
    )
    .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(
        f.ros2[0].connect,
        vec![
            "tls/robot-1.lab:7448".to_owned(),
            "tcp/[fe80::1]:7447#iface=eth0".to_owned()
        ]
    );
    // A bad endpoint names its field and line, at the agent or the file.
    for (extra, field, says) in [
        (
            "ros2 = { connect = \"192.168.1.21:7447\" }\n",
            "agents[1].ros2.connect",
            "not a Zenoh endpoint",
        ),
        (
            "ros2 = { connect = \"192.168.1.21\" }\n",
            "agents[1].ros2.connect",
            "not a Zenoh endpoint",
        ),
        (
            "ros2 = { connect = \"tcp/192.168.1.21\" }\n",
            "agents[1].ros2.connect",
            "no port",
        ),
        (
            "ros2 = { connect = \"tcp/192.168.1.21:0\" }\n",
            "agents[1].ros2.connect",
            "not a port",
        ),
        (
            "ros2 = { connect = \"tcp/192.168.1.21:74470\" }\n",
            "agents[1].ros2.connect",
            "not a port",
        ),
        (
            "ros2 = { connect = \"ws/robot:7447\" }\n",
            "agents[1].ros2.connect",
            "protocol must be",
        ),
        (
            "ros2 = { connect = \"tcp/:7447\" }\n",
            "agents[1].ros2.connect",
            "not a host",
        ),
        (
            "ros2 = { connect = \"tcp/robot {k}:7447\" }\n",
            "agents[1].ros2.connect",
            "not a host",
        ),
        (
            "ros2 = { connect = \"tcp/[::zz]:7447\" }\n",
            "agents[1].ros2.connect",
            "not a host",
        ),
        (
            "ros2 = { connect = [] }\n",
            "agents[1].ros2.connect",
            "empty list",
        ),
        (
            "\n[fleet.ros2]\nconnect = \"tcp/robot{j}:7447\"\n",
            "fleet.ros2.connect",
            "not a host",
        ),
        (
            "\n[fleet.ros2]\nconnect = [\"tcp/a:1\", \"udp/b\"]\n",
            "fleet.ros2.connect",
            "no port",
        ),
    ] {
        let e = parse(extra).err().unwrap_or_else(|| panic!("{extra}"));
        assert_eq!(e.field, field, "{e}");
        assert!(e.location.line > 0, "{e}");
        assert!(e.message.contains(says), "{extra}: {e}");
    }
    // Not a string or a list of strings: refused by the parser.
    let e = parse("ros2 = { connect = 7447 }\n")
        .err()
        .unwrap_or_else(|| panic!());
    assert!(e.location.line > 0, "{e}");
}

/// Each `(extra, field)`: the base scenario with `extra` is refused, the
/// error naming `field` at a line of the file.
fn assert_refused(cases: &[(&str, &str)]) {
    for (extra, field) in cases {
        let e = parse(extra).err().unwrap_or_else(|| panic!("{extra}"));
        assert_eq!(e.field, *field, "{e}");
        assert!(e.location.line > 0, "{e}");
    }
}

/// A command period that leaves a base less than two commands per
/// `cmd_vel_timeout` (a Create 3 stops its wheels 0.5 s after the last)
/// is refused, naming the rate needed; the hazard and e-stop topics are
/// resolved in the namespace.
#[test]
fn the_command_period_fits_the_bases_wheel_timeout() {
    let e = parse("\n[fleet]\ncontrol_rate = 3.0\n").expect_err("3 Hz");
    let text = e.to_string();
    assert!(
        text.contains("cmd_vel_timeout") && text.contains("give at least 4 Hz"),
        "{text}"
    );
    assert!(parse("\n[fleet]\ncontrol_rate = 4.0\n").is_ok());
    let e = parse("\n[fleet]\ncontrol_rate = 10.0\nros2 = { cmd_vel_timeout = 0.15 }\n")
        .expect_err("0.15 s");
    assert!(e.to_string().contains("give at least 14 Hz"), "{e}");
    let f = parse(
        "\n[fleet]\nros2 = { namespace = \"/tb{k}\", hazards = \"hazard_detection\", estop = \"/estop\" }\n",
    )
    .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(f.ros2[0].hazards.as_deref(), Some("/tb1/hazard_detection"));
    assert_eq!(f.ros2[0].estop.as_deref(), Some("/estop"));
    let e = parse("\n[fleet]\nros2 = { hazards = \"bad topic\" }\n").expect_err("a bad name");
    assert!(e.to_string().contains("hazards"), "{e}");
}
