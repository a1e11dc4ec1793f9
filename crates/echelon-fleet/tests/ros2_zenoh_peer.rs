//! echelon's Zenoh (the `zenoh` crate of Cargo.lock) talking to an
//! independent ROS 2 base on eclipse-zenoh from PyPI
//! (`scripts/ros2/fake_base.py`: rclpy serialization, rmw_zenoh keys,
//! attachment written and read by `zenoh.ext`, liveliness tokens).
//!
//! echelon declares a node, a `cmd_vel` publisher and an `odom` subscription
//! as rmw_zenoh tokens, publishes TwistStamped commands with attachments and
//! a final zero command, and reads the base's odometry. The test proves:
//! the base decoded every command and every attachment (GID, increasing
//! sequence numbers), saw echelon's three tokens verbatim, applied the
//! commands (its pose moved as a unicycle would) and the last command it
//! received was zero; echelon checked every odom key's type and hash,
//! decoded every attachment and odometry, and its last odometry equals the
//! base's final pose.
//!
//! Needs `python3` with `scripts/requirements-ros2.txt` (run `scripts/test`).

use std::net::TcpListener;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use echelon_fleet::net::{self, NetOptions};
use echelon_ros2::attachment::{Attachment, gid_from_token};
use echelon_ros2::keys::{check_topic_key, topic_key, topic_key_any_type};
use echelon_ros2::liveliness::{Endpoint, NodeInfo, Qos};
use echelon_ros2::msgs::{ODOMETRY, Odometry, RosMessage, TWIST_STAMPED, Time, TwistStamped};
use echelon_ros2::names::{KeyScheme, fully_qualified_topic};
use zenoh::Wait;

#[path = "common/python.rs"]
mod python;

const INSTALL_HINT: &str = "this test needs python3 (3.11) with the ROS 2 Jazzy wheels and \
    eclipse-zenoh: run `scripts/test` (it installs scripts/requirements-ros2.txt), or \
    `python3 -m pip install -r scripts/requirements-ros2.txt`; set ECHELON_PYTHON to use \
    another interpreter";

fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free port")
}

#[test]
fn a_python_ros2_base_hears_echelon_and_answers() {
    let port = free_port();
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let dir = tempfile::tempdir().expect("temp dir");
    let report_path = dir.path().join("base.json");
    let python = python::python();
    // As on a real robot: the ROS 2 side listens (its router), echelon connects.
    let mut child = Command::new(&python)
        .arg(python::script("fake_base.py"))
        .args([
            "--listen",
            &endpoint,
            "--namespace",
            "/robot1",
            "--duration",
            "8",
        ])
        .args(["--rate", "50", "--cmd-timeout", "0.5", "--report"])
        .arg(&report_path)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("cannot run `{python}`: {e}; {INSTALL_HINT}"));
    let session = net::open(&NetOptions {
        connect: vec![endpoint.clone()],
        ..NetOptions::default()
    })
    .unwrap_or_else(|e| panic!("connecting to fake_base.py: {e}; {INSTALL_HINT}"));

    let zid = session.zid().to_string();
    let node = NodeInfo::new(0, &zid, 0, "/robot1", "echelon_robot").expect("valid node");
    let cmd_topic = fully_qualified_topic("/robot1", "cmd_vel").expect("valid");
    let odom_topic = fully_qualified_topic("/robot1", "odom").expect("valid");
    let pub_token = node.endpoint_token(
        Endpoint::Publisher,
        1,
        &cmd_topic,
        &TWIST_STAMPED,
        &Qos::keep_last(10),
    );
    let sub_token = node.endpoint_token(
        Endpoint::Subscription,
        2,
        &odom_topic,
        &ODOMETRY,
        &Qos::default(),
    );
    let declare = |key: &str| {
        session
            .liveliness()
            .declare_token(key.to_owned())
            .wait()
            .unwrap_or_else(|e| panic!("token {key}: {e}"))
    };
    let _tokens = [
        declare(&node.node_token()),
        declare(&pub_token),
        declare(&sub_token),
    ];
    let gid = gid_from_token(&pub_token);
    let odom_sub = session
        .declare_subscriber(topic_key_any_type(KeyScheme::RmwZenoh, 0, &odom_topic))
        .wait()
        .unwrap_or_else(|e| panic!("{e}"));
    let publisher = session
        .declare_publisher(topic_key(
            KeyScheme::RmwZenoh,
            0,
            &cmd_topic,
            &TWIST_STAMPED,
        ))
        .wait()
        .unwrap_or_else(|e| panic!("{e}"));

    let mut seq = 0i64;
    let mut buf = Vec::new();
    let mut send = |v: f64, omega: f64| {
        seq += 1;
        let now = i64::try_from(
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .expect("after 1970")
                .as_nanos(),
        )
        .expect("fits");
        TwistStamped::planar(v, omega, Time::from_nanos(now), "base_link").encode_into(&mut buf);
        let attachment = Attachment {
            sequence_number: seq,
            source_timestamp_ns: now,
            gid,
        };
        publisher
            .put(buf.clone())
            .attachment(attachment.encode().to_vec())
            .wait()
            .unwrap_or_else(|e| panic!("{e}"));
    };

    let mut odoms: Vec<Odometry> = Vec::new();
    // Waits up to `wait` for one sample, then takes only those already
    // queued: the base publishes faster than any wait, so waiting for each
    // would never return while it runs.
    let drain = |odoms: &mut Vec<Odometry>, wait: Duration| {
        let first = odom_sub.recv_timeout(wait).ok().flatten();
        let queued = std::iter::from_fn(|| odom_sub.try_recv().ok().flatten());
        for sample in first.into_iter().chain(queued) {
            let key = sample.key_expr().as_str().to_owned();
            check_topic_key(KeyScheme::RmwZenoh, &key, &ODOMETRY)
                .unwrap_or_else(|e| panic!("{key}: {e}"));
            let attachment = sample
                .attachment()
                .expect("the base attaches rmw_zenoh metadata");
            let attachment =
                Attachment::decode(&attachment.to_bytes()).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(attachment.gid, core::array::from_fn(|i| 0xb0 + i as u8));
            let odom = Odometry::from_cdr_finite(&sample.payload().to_bytes())
                .unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(odom.header.frame_id, "odom");
            assert_eq!(odom.child_frame_id, "base_link");
            odoms.push(odom);
        }
    };

    // Wait for the base's first odometry (it is up and connected), then
    // command 0.4 m/s and 0.5 rad/s for 1.5 s, then zero.
    let start = Instant::now();
    while odoms.is_empty() {
        assert!(
            start.elapsed() < Duration::from_secs(20),
            "no odometry from the Python base; {INSTALL_HINT}"
        );
        drain(&mut odoms, Duration::from_millis(100));
        if let Ok(Some(status)) = child.try_wait() {
            let mut err = String::new();
            if let Some(mut e) = child.stderr.take() {
                let _ = std::io::Read::read_to_string(&mut e, &mut err);
            }
            panic!("fake_base.py exited ({status}): {err}\n{INSTALL_HINT}");
        }
    }
    let moving = Instant::now();
    while moving.elapsed() < Duration::from_millis(1500) {
        send(0.4, 0.5);
        drain(&mut odoms, Duration::from_millis(20));
    }
    for _ in 0..5 {
        send(0.0, 0.0);
        drain(&mut odoms, Duration::from_millis(20));
    }
    let sent = seq;
    // The base keeps publishing its (now still) pose until it exits.
    while child.try_wait().expect("wait").is_none() {
        drain(&mut odoms, Duration::from_millis(50));
    }
    drain(&mut odoms, Duration::from_millis(200));
    let status = child.wait().expect("exit");
    let mut base_stderr = String::new();
    if let Some(mut e) = child.stderr.take() {
        let _ = std::io::Read::read_to_string(&mut e, &mut base_stderr);
    }
    assert!(status.success(), "fake_base.py: {status}: {base_stderr}");

    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report_path).expect("report"))
            .expect("JSON");
    let commands = report["commands"].as_i64().expect("commands");
    assert!(
        commands > 0 && commands <= sent,
        "{commands} of {sent}: {report}\n{base_stderr}"
    );
    assert_eq!(report["attachments_valid"], commands, "{report}");
    assert_eq!(report["attachments_invalid"], 0);
    assert_eq!(report["undecodable"], 0);
    let seqs: Vec<i64> = report["sequence_numbers"]
        .as_array()
        .expect("list")
        .iter()
        .filter_map(serde_json::Value::as_i64)
        .collect();
    assert!(seqs.windows(2).all(|w| w[0] < w[1]), "{seqs:?}");
    let hex: String = gid.iter().map(|b| format!("{b:02x}")).collect();
    assert_eq!(report["last_attachment"]["gid"], hex.as_str());
    assert_eq!(report["last_command"]["v"], 0.0);
    assert_eq!(report["last_command"]["omega"], 0.0);
    assert_eq!(report["last_command"]["frame_id"], "base_link");
    let tokens: Vec<&str> = report["tokens"]
        .as_array()
        .expect("list")
        .iter()
        .filter_map(serde_json::Value::as_str)
        .collect();
    for token in [node.node_token(), pub_token.clone(), sub_token.clone()] {
        assert!(
            tokens.contains(&token.as_str()),
            "{token} not in {tokens:?}"
        );
    }

    // The base moved as commanded: a unicycle at 0.4 m/s, 0.5 rad/s turns
    // left; it then stopped.
    let fin = &report["final_pose"];
    let (x, y, yaw) = (
        fin["x"].as_f64().expect("x"),
        fin["y"].as_f64().expect("y"),
        fin["yaw"].as_f64().expect("yaw"),
    );
    assert!(x > 0.2 && y > 0.0 && yaw > 0.2, "{fin}");
    // Turning radius v/ω = 0.8 m: the pose lies on that circle.
    let r = (x * x + (y - 0.8) * (y - 0.8)).sqrt();
    assert!((r - 0.8).abs() < 1e-6, "radius {r}");
    let last = odoms.last().expect("odometry");
    let p = last.pose.pose.position;
    assert!(
        (p.x - x).abs() < 1e-12 && (p.y - y).abs() < 1e-12,
        "{p:?} vs {fin}"
    );
    assert!((last.yaw() - yaw).abs() < 1e-9);
    assert_eq!(last.twist.twist.linear.x, 0.0);
}
