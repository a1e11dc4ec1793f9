//! The fleet collector's ROS 2 channels read back by independent tools:
//!
//! - the embedded message definitions equal the text rosbag2 builds from
//!   the ROS 2 Jazzy wheels' `.msg` files (`scripts/ros2/msg_definitions.py`);
//! - a `fleet.mcap` written by the collector (its state machine fed with
//!   echelon-encoded samples, and its Zenoh driver fed over the network)
//!   is read by foxglove's `mcap` and `mcap-ros2-support` Python packages
//!   (`scripts/ros2/read_mcap.py`), which decode every recorded message with
//!   the channel's `ros2msg` schema to exactly the values sent (v, ω, frame
//!   ids, stamps, pose, covariances), with the receipt time as `log_time` and
//!   the attachment's source timestamp as `publish_time`; refused samples
//!   are not on the ROS channels.
//!
//! These tests need `python3` with `scripts/requirements-test.txt`
//! (`mcap-ros2-support`, and the ROS 2 Jazzy wheels of
//! `scripts/requirements-ros2.txt`); `scripts/test` installs them. Without
//! them they fail and say what to install.

use std::path::Path;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use echelon::control::LeaderMotion;
use echelon_fleet::StopFlag;
use echelon_fleet::collector::{
    self, Collector, CollectorOptions, FileSink, MCAP_FILE, REJECTED_TOPIC,
};
use echelon_fleet::keys::Keys;
use echelon_fleet::net::{self, NetOptions};
use echelon_fleet::ros2::record::RosTopic;
use echelon_fleet::wire;
use echelon_ros2::KeyScheme;
use echelon_ros2::attachment::Attachment;
use echelon_ros2::definitions::{ODOMETRY_DEFINITION, TWIST_DEFINITION, TWIST_STAMPED_DEFINITION};
use echelon_ros2::keys::topic_key;
use echelon_ros2::liveliness::{History, Qos};
use echelon_ros2::msgs::{
    ODOMETRY, Odometry, RosMessage, TWIST, TWIST_STAMPED, Time, Twist, TwistStamped,
};
use serde_json::Value;

mod common;
use common::{odometry, twist, twist_stamped};
#[path = "common/python.rs"]
mod python;
use python::Helpers;
use zenoh::Wait;

const INSTALL_HINT: &str = "the ROS 2 MCAP tests need python3 (3.11) with mcap-ros2-support \
    and the ROS 2 Jazzy wheels: run `scripts/test` (it installs scripts/requirements-test.txt), \
    or `python3 -m pip install -r scripts/requirements-test.txt`; set ECHELON_PYTHON to use \
    another interpreter";

/// Runs `scripts/ros2/<name> args…` and parses its JSON output.
fn run_script(name: &str, args: &[&str]) -> Value {
    Helpers::new(INSTALL_HINT)
        .run(name, args, None)
        .unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn embedded_definitions_equal_rosbag2s_text_from_the_wheels() {
    let names = [TWIST.name, TWIST_STAMPED.name, ODOMETRY.name];
    let theirs = run_script("msg_definitions.py", &names);
    for (name, ours) in names.into_iter().zip([
        TWIST_DEFINITION,
        TWIST_STAMPED_DEFINITION,
        ODOMETRY_DEFINITION,
    ]) {
        let theirs = theirs[name]
            .as_str()
            .unwrap_or_else(|| panic!("{name}: no definition from the wheels"));
        assert_eq!(ours, theirs, "{name}: the embedded definition differs");
    }
}

#[test]
fn a_missing_interpreter_is_reported_with_what_to_install() {
    python::assert_missing_interpreter_named(INSTALL_HINT, "requirements-test.txt");
    // A missing file is an error of the script, reported with its stderr.
    let err = Helpers::new(INSTALL_HINT)
        .run("read_mcap.py", &["/nonexistent.mcap"], None)
        .expect_err("no such file");
    assert!(err.contains("nonexistent.mcap"), "{err}");
}

/// One message the test expects on a ROS channel.
#[derive(Debug)]
struct Expected {
    topic: &'static str,
    log_time: u64,
    publish_time: u64,
    message: Value,
}

fn attachment(seq: i64, source_timestamp_ns: i64) -> [u8; 33] {
    Attachment {
        sequence_number: seq,
        source_timestamp_ns,
        gid: [0x5a; 16],
    }
    .encode()
}

/// Reads `mcap` with read_mcap.py and checks its ROS channels and messages.
fn check_read_back(mcap: &Path, topics: &[RosTopic], expected: &[Expected]) {
    let back = run_script("read_mcap.py", &[&mcap.display().to_string()]);
    let channels = back["channels"].as_object().expect("channels");
    for t in topics {
        let c = &channels
            .get(t.topic())
            .unwrap_or_else(|| panic!("{}: no channel in {channels:?}", t.topic()));
        assert_eq!(c["message_encoding"], "cdr", "{}", t.topic());
        assert_eq!(c["schema_encoding"], "ros2msg", "{}", t.topic());
        assert_eq!(c["schema_name"], t.msg().name, "{}", t.topic());
        assert_eq!(
            c["schema_data"].as_str(),
            Some(t.schema().definition),
            "{}",
            t.topic()
        );
        assert_eq!(c["metadata"]["topic_type_hash"], t.msg().hash);
        // The QoS YAML parses (PyYAML) to rosbag2's profile list.
        let qos = &c["qos"];
        assert_eq!(qos.as_array().map(Vec::len), Some(1), "{qos}");
        assert_eq!(qos[0]["history"], "keep_last");
        let depth = match t.qos().history {
            History::KeepLast(d) => d,
            History::KeepAll => 0,
        };
        assert_eq!(qos[0]["depth"], depth, "{}", t.topic());
        assert_eq!(qos[0]["reliability"], "reliable");
        assert_eq!(qos[0]["durability"], "volatile");
        assert_eq!(qos[0]["liveliness"], "automatic");
        assert_eq!(qos[0]["deadline"]["sec"], 9_223_372_036u64);
        assert_eq!(qos[0]["deadline"]["nsec"], 854_775_807u64);
        assert_eq!(qos[0]["avoid_ros_namespace_conventions"], false);
    }
    assert_eq!(
        channels.len(),
        topics.len(),
        "only the ROS channels are cdr"
    );
    let messages = back["messages"].as_array().expect("messages");
    assert_eq!(messages.len(), expected.len(), "ROS messages read back");
    for (k, (got, want)) in messages.iter().zip(expected).enumerate() {
        assert_eq!(got["topic"], want.topic, "#{k}");
        assert_eq!(got["log_time"], want.log_time, "#{k} {}", want.topic);
        assert_eq!(
            got["publish_time"], want.publish_time,
            "#{k} {}",
            want.topic
        );
        assert_eq!(got["message"], want.message, "#{k} {}", want.topic);
    }
}

/// The collector state machine fed by hand through its file sink, and the
/// messages it should record on the ROS channels, in order.
struct Fed {
    c: Collector,
    sink: FileSink,
    /// The last receipt time, ns.
    now: u64,
    expected: Vec<Expected>,
}

impl Fed {
    /// Feeds one ROS sample on `key` 10 ms after the last one; its receipt
    /// time.
    fn ros(&mut self, key: &str, bytes: &[u8], att: Option<&[u8]>) -> u64 {
        self.now += 10_000_000;
        self.c
            .on_ros_sample(key, bytes, att, self.now, &mut self.sink)
            .unwrap_or_else(|e| panic!("{e}"));
        self.now
    }

    /// Feeds `bytes` on `key`, with the attachment `(sequence number, source
    /// timestamp)` if any, and expects `message` on `topic`, logged at its
    /// receipt time and published at the attachment's source timestamp (at
    /// its receipt time without one).
    fn recorded(
        &mut self,
        key: &str,
        bytes: &[u8],
        att: Option<(i64, i64)>,
        topic: &'static str,
        message: Value,
    ) {
        let encoded = att.map(|(seq, source_ts)| attachment(seq, source_ts));
        let log_time = self.ros(key, bytes, encoded.as_ref().map(|a| &a[..]));
        self.expected.push(Expected {
            topic,
            log_time,
            publish_time: att.map_or(log_time, |(_, source_ts)| source_ts as u64),
            message,
        });
    }
}

/// The collector state machine writes `fleet.mcap` through its file sink;
/// mcap-ros2-support decodes every recorded message to the values sent.
#[test]
fn collector_ros_channels_decode_in_mcap_ros2_support() {
    let dir = tempfile::tempdir().expect("temp dir");
    let [cmd1, odom1] = RosTopic::robot(KeyScheme::RmwZenoh, 0, "/robot1", TWIST_STAMPED)
        .unwrap_or_else(|e| panic!("{e}"));
    let [cmd2, _] =
        RosTopic::robot(KeyScheme::RmwZenoh, 0, "/robot2", TWIST).unwrap_or_else(|e| panic!("{e}"));
    let odom3 = RosTopic::new(KeyScheme::Bridge, 0, "/robot3", "odom", ODOMETRY)
        .unwrap_or_else(|e| panic!("{e}"));
    let topics = vec![cmd1, odom1, cmd2, odom3.with_qos(Qos::keep_last(10))];
    let mut fed = Fed {
        c: Collector::with_ros2(Keys::new("t"), topics.clone()).unwrap_or_else(|e| panic!("{e}")),
        sink: FileSink::create(dir.path()).unwrap_or_else(|e| panic!("{e}")),
        now: 1_764_000_000_000_000_000,
        expected: Vec::new(),
    };

    let key =
        |ns: &str, topic: &str, ty| topic_key(KeyScheme::RmwZenoh, 0, &format!("{ns}/{topic}"), ty);
    for k in 0..6u32 {
        let kf = f64::from(k);
        // robot1: TwistStamped commands with attachments.
        let stamp = Time::from_nanos(1_764_000_000_123_456_789 + i64::from(k) * 20_000_000);
        let cmd = TwistStamped::planar(0.25 + 0.01 * kf, -0.4 + 0.1 * kf, stamp, "base_link");
        fed.recorded(
            &key("/robot1", "cmd_vel", &TWIST_STAMPED),
            &cmd.to_cdr(),
            Some((i64::from(k) + 1, stamp.to_nanos() + 1000)),
            "/robot1/cmd_vel",
            twist_stamped(&cmd),
        );
        // robot1: odometry with covariances, no attachment.
        let mut odom = Odometry::planar(
            1.5 - 0.1 * kf,
            -2.25 + 0.05 * kf,
            3.0 + 0.2 * kf,
            0.3,
            -0.1,
            stamp,
            "odom",
            "base_link",
        );
        odom.pose.covariance = std::array::from_fn(|i| i as f64 * 1e-3 + kf);
        odom.twist.covariance[35] = 0.5 * kf;
        let odom_key = key("/robot1", "odom", &ODOMETRY);
        fed.recorded(
            &odom_key,
            &odom.to_cdr(),
            None,
            "/robot1/odom",
            odometry(&odom),
        );
        // Refused on the way: a Twist on robot1's TwistStamped topic,
        // truncated odometry, garbage.
        let twist_on_cmd = Twist::planar(1.0, 1.0).to_cdr();
        fed.ros(&key("/robot1", "cmd_vel", &TWIST), &twist_on_cmd, None);
        fed.ros(&odom_key, &odom.to_cdr()[..100], None);
        fed.ros(&odom_key, b"junk", None);
        // The fleet's own traffic goes on as before.
        let mut reference = Vec::new();
        wire::encode_reference(
            &mut reference,
            wire::Header {
                source: 1,
                seq: u64::from(k),
            },
            &wire::Reference {
                t: kf * 0.1,
                motion: LeaderMotion::default(),
                speed: 0.2,
                turn_rate: 0.1,
            },
        );
        fed.now += 1;
        fed.c
            .on_message("echelon/t/reference", &reference, fed.now, &mut fed.sink)
            .unwrap_or_else(|e| panic!("{e}"));
    }
    // robot2: plain Twist, one with NaN (recorded as sent).
    for (v, w) in [(0.1, 0.2), (f64::NAN, -0.0), (-0.3, 1e-300)] {
        let cmd = Twist::planar(v, w);
        fed.recorded(
            &key("/robot2", "cmd_vel", &TWIST),
            &cmd.to_cdr(),
            None,
            "/robot2/cmd_vel",
            twist(&cmd),
        );
    }
    // robot3 behind zenoh-bridge-ros2dds: plain key, non-ASCII frame.
    let odom = Odometry::planar(
        0.0,
        1.0,
        -1.0,
        0.0,
        0.0,
        Time::default(),
        "ödom",
        "base_link",
    );
    fed.recorded(
        "robot3/odom",
        &odom.to_cdr(),
        None,
        "/robot3/odom",
        odometry(&odom),
    );
    fed.sink.finish().unwrap_or_else(|e| panic!("{e}"));
    let report = fed.c.finish();
    assert_eq!(report.ros_recorded, fed.expected.len() as u64);
    assert_eq!(report.ros_refused, 18);
    assert_eq!(report.logged_by_topic[REJECTED_TOPIC], 18);
    assert_eq!(report.logged_by_topic["/reference"], 6);
    assert_eq!(report.logged, report.received);

    // The bridge topic was given keep_last(10); the others rmw_zenoh's default.
    check_read_back(&dir.path().join(MCAP_FILE), &topics, &fed.expected);
}

/// The collector's Zenoh driver subscribes to the ROS topics' keys and
/// records what a publisher puts there, attachment times included.
#[test]
fn the_zenoh_driver_records_ros_topics_it_hears() {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free port");
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let dir = tempfile::tempdir().expect("temp dir");
    let topics = RosTopic::robot(KeyScheme::RmwZenoh, 0, "/robot1", TWIST_STAMPED)
        .unwrap_or_else(|e| panic!("{e}"))
        .to_vec();
    let stop = StopFlag::new();
    let opts = CollectorOptions {
        out: dir.path().to_path_buf(),
        fleet: "z".to_owned(),
        max_wall: Some(Duration::from_secs(20)),
        net: NetOptions {
            listen: vec![endpoint.clone()],
            ..NetOptions::default()
        },
        die_at: None,
    };
    let collector = {
        let stop = stop.clone();
        let topics = topics.clone();
        std::thread::spawn(move || collector::run_with_ros2(opts, topics, &stop))
    };
    let session = net::open(&NetOptions {
        connect: vec![endpoint],
        ..NetOptions::default()
    })
    .unwrap_or_else(|e| panic!("{e}"));
    let cmd_key = topic_key(KeyScheme::RmwZenoh, 0, "/robot1/cmd_vel", &TWIST_STAMPED);
    let bad_key = topic_key(KeyScheme::RmwZenoh, 0, "/robot1/odom", &TWIST);
    // Publish until the collector's subscription is there (its liveliness
    // token is declared after its subscriptions), then a known burst.
    let alive = Keys::new("z").alive("collector");
    let deadline = std::time::Instant::now() + Duration::from_secs(15);
    loop {
        let replies = session
            .liveliness()
            .get(&alive)
            .wait()
            .unwrap_or_else(|e| panic!("{e}"));
        if replies
            .recv_timeout(Duration::from_millis(200))
            .ok()
            .flatten()
            .is_some()
        {
            break;
        }
        assert!(
            std::time::Instant::now() < deadline,
            "the collector never came up"
        );
    }
    std::thread::sleep(Duration::from_millis(300));
    let mut sent = Vec::new();
    for k in 0..5i64 {
        let cmd = TwistStamped::planar(0.1 * k as f64, 0.05, Time::from_nanos(k), "base_link");
        let ts = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(1, |d| d.as_nanos() as i64);
        session
            .put(&cmd_key, cmd.to_cdr())
            .attachment(attachment(k + 1, ts).to_vec())
            .wait()
            .unwrap_or_else(|e| panic!("{e}"));
        session
            .put(&bad_key, Twist::planar(1.0, 0.0).to_cdr())
            .wait()
            .unwrap_or_else(|e| panic!("{e}"));
        sent.push((ts as u64, cmd));
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_millis(500));
    stop.raise();
    let report = collector
        .join()
        .expect("collector thread")
        .unwrap_or_else(|e| panic!("{e}"));
    let _ = session.close().wait();
    assert_eq!(report.ros_recorded, 5, "{report:?}");
    assert_eq!(report.ros_refused, 5, "{report:?}");
    assert_eq!(report.rejected["ROS: wrong message type on the key"], 5);

    let back = run_script(
        "read_mcap.py",
        &[&dir.path().join(MCAP_FILE).display().to_string()],
    );
    let messages = back["messages"].as_array().expect("messages");
    assert_eq!(messages.len(), 5);
    for (got, (ts, cmd)) in messages.iter().zip(&sent) {
        assert_eq!(got["topic"], "/robot1/cmd_vel");
        assert_eq!(got["publish_time"], *ts);
        assert!(got["log_time"].as_u64().is_some_and(|t| t >= *ts), "{got}");
        assert_eq!(got["message"], twist_stamped(cmd));
    }
}
