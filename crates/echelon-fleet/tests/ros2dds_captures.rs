//! What the real zenoh-bridge-ros2dds 1.10.2 sends, recorded in front of
//! real DDS nodes (a Fast DDS rclpy base, a Cyclone DDS Create 3 hazard
//! node; `scripts/interop/ros2dds/record_captures`), read by echelon
//! without building the bridge: `tests/fixtures/ros2dds/*.jsonl`
//! (their README says how each was made).
//!
//! - the keys are echelon's `bridge` key scheme for the robot's topics;
//! - every payload decodes with echelon's codecs (odometry in `odom` →
//!   `base_link`, the hazard vector with its BUMP, the e-stop);
//! - the liveliness tokens give the robot's graph, which passes the
//!   graph check for the right scenario and fails, with the line a user
//!   sees, for the usual mistakes: a `cmd_vel` of the other type, a
//!   namespace that matches nothing, a missing `odom`; on Jazzy the type
//!   hashes the bridge relays from the DDS nodes are echelon's.

use echelon_fleet::ros2::hazard::{BaseSafety, Hazard};
use echelon_ros2::graph::{self, Direction, Expected, GraphEndpoint};
use echelon_ros2::keys::topic_key;
use echelon_ros2::msgs::{
    BOOL, Bool, HAZARD_DETECTION_VECTOR, MessageType, ODOMETRY, Odometry, RosMessage, TWIST,
    TWIST_STAMPED, Twist, TwistStamped,
};
use echelon_ros2::names::KeyScheme;
use serde_json::Value;

fn capture(name: &str) -> Vec<Value> {
    let path = format!(
        "{}/tests/fixtures/ros2dds/{name}",
        env!("CARGO_MANIFEST_DIR")
    );
    std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("{path}: {e}"))
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{path}: {e}")))
        .collect()
}

fn unhex(s: &str) -> Vec<u8> {
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap_or_else(|e| panic!("{e}")))
        .collect()
}

fn tokens(c: &[Value]) -> Vec<GraphEndpoint> {
    let mut seen: Vec<GraphEndpoint> = c
        .iter()
        .filter(|r| r["type"] == "token" && r["kind"] == "put")
        .filter_map(|r| graph::parse_token(r["key"].as_str().unwrap_or_default()))
        .collect();
    seen.sort();
    seen.dedup();
    seen
}

fn samples<'a>(c: &'a [Value], key: &'a str) -> impl Iterator<Item = Vec<u8>> + 'a {
    c.iter()
        .filter(move |r| r["type"] == "sample" && r["key"] == key)
        .map(|r| unhex(r["payload_hex"].as_str().unwrap_or_default()))
}

/// The robot's topics as a scenario with `namespace = "/bot1"`,
/// `key_scheme = "bridge"` names them.
fn expected<'a>(ns: &'a str, cmd: &'a MessageType, topics: &'a [String; 4]) -> Vec<Expected<'a>> {
    vec![
        Expected {
            role: "cmd_vel",
            topic: &topics[0],
            ty: cmd,
            direction: Direction::Subscription,
        },
        Expected {
            role: "odom",
            topic: &topics[1],
            ty: &ODOMETRY,
            direction: Direction::Publisher,
        },
        Expected {
            role: "hazards",
            topic: &topics[2],
            ty: &HAZARD_DETECTION_VECTOR,
            direction: Direction::Publisher,
        },
        Expected {
            role: "estop",
            topic: &topics[3],
            ty: &BOOL,
            direction: Direction::Publisher,
        },
    ]
    .into_iter()
    .filter(|_| !ns.is_empty())
    .collect()
}

fn topics(ns: &str) -> [String; 4] {
    [
        "cmd_vel",
        "odom",
        "hazard_detection",
        "platform/emergency_stop",
    ]
    .map(|t| format!("{ns}/{t}"))
}

#[test]
fn keys_are_the_bridge_scheme_and_payloads_decode() {
    for (name, cmd) in [
        ("jazzy_create3.jsonl", TWIST),
        ("jazzy_twist_stamped.jsonl", TWIST_STAMPED),
        ("humble.jsonl", TWIST),
    ] {
        let c = capture(name);
        let key = |topic: &str, ty: &MessageType| topic_key(KeyScheme::Bridge, 0, topic, ty);
        let odom_key = key("/bot1/odom", &ODOMETRY);
        let hazard_key = key("/bot1/hazard_detection", &HAZARD_DETECTION_VECTOR);
        let estop_key = key("/bot1/platform/emergency_stop", &BOOL);
        assert_eq!(
            (odom_key.as_str(), hazard_key.as_str(), estop_key.as_str()),
            (
                "bot1/odom",
                "bot1/hazard_detection",
                "bot1/platform/emergency_stop"
            )
        );
        let odoms: Vec<Odometry> = samples(&c, &odom_key)
            .map(|p| Odometry::from_cdr_finite(&p).unwrap_or_else(|e| panic!("{name}: {e}")))
            .collect();
        assert!(odoms.len() >= 3, "{name}");
        for o in &odoms {
            assert_eq!(
                (o.header.frame_id.as_str(), o.child_frame_id.as_str()),
                ("odom", "base_link")
            );
            assert!(
                o.pose.pose.orientation.checked_yaw().is_some(),
                "{name}: {o:?}"
            );
        }
        // The hazard node reports nothing, then a BUMP: in force on the last vector.
        let mut safety = BaseSafety::new(KeyScheme::Bridge);
        let vectors: Vec<Vec<u8>> = samples(&c, &hazard_key).collect();
        assert!(vectors.len() >= 2, "{name}");
        for (i, v) in vectors.iter().enumerate() {
            safety
                .on_hazards(&hazard_key, v, i as f64 * 0.1)
                .unwrap_or_else(|e| panic!("{name}: {e}"));
        }
        let in_force = safety.update((vectors.len() - 1) as f64 * 0.1);
        assert!(in_force.contains(Hazard::Bump), "{name}: {in_force:?}");
        assert_eq!(safety.report().events.len(), 1, "{name}");
        let estops: Vec<bool> = samples(&c, &estop_key)
            .map(|p| {
                Bool::from_cdr(&p)
                    .unwrap_or_else(|e| panic!("{name}: {e}"))
                    .data
            })
            .collect();
        assert_eq!(estops.first(), Some(&false), "{name}");
        assert_eq!(estops.last(), Some(&true), "{name}");
        // The commands put on the bridge's cmd_vel key, as the DDS base took them.
        for r in c.iter().filter(|r| r["type"] == "put") {
            assert_eq!(r["key"], "bot1/cmd_vel");
            let p = unhex(r["payload_hex"].as_str().unwrap_or_default());
            let v = if cmd == TWIST {
                Twist::from_cdr_finite(&p).map(|t| t.linear.x)
            } else {
                TwistStamped::from_cdr_finite(&p).map(|t| t.twist.linear.x)
            };
            assert_eq!(v, Ok(0.2), "{name}");
        }
    }
}

#[test]
fn the_graph_of_the_real_bridge_passes_the_check_and_the_usual_mistakes_are_named() {
    let ns = "/bot1";
    let t = topics(ns);
    for (name, cmd, other) in [
        ("jazzy_create3.jsonl", TWIST, TWIST_STAMPED),
        ("jazzy_twist_stamped.jsonl", TWIST_STAMPED, TWIST),
        ("humble.jsonl", TWIST, TWIST_STAMPED),
    ] {
        let seen = tokens(&capture(name));
        assert_eq!(seen.len(), 4, "{name}: {seen:?}");
        // Jazzy: the bridge relays each DDS node's type hash, which is
        // echelon's (rclpy's Fast DDS node for Twist/TwistStamped/Odometry;
        // the Cyclone node for the irobot and std_msgs types). Humble: none.
        for e in &seen {
            let ours = [
                TWIST,
                TWIST_STAMPED,
                ODOMETRY,
                HAZARD_DETECTION_VECTOR,
                BOOL,
            ]
            .into_iter()
            .find(|m| m.name == e.type_name)
            .unwrap_or_else(|| panic!("{name}: {e:?}"));
            match name {
                "humble.jsonl" => assert_eq!(e.hash, None, "{e:?}"),
                _ => assert_eq!(e.hash.as_deref(), Some(ours.hash), "{e:?}"),
            }
        }
        assert_eq!(
            graph::check(&seen, ns, &expected(ns, &cmd, &t)),
            Ok(()),
            "{name}"
        );
        let wrong = graph::check(&seen, ns, &expected(ns, &other, &t)).expect_err("wrong type");
        assert_eq!(
            wrong.to_string(),
            format!(
                "cmd_vel takes {}, the scenario sends {}",
                cmd.name,
                other.name.rsplit('/').next().unwrap_or_default()
            ),
            "{name}"
        );
        let red = topics("/tb4_red");
        let e = graph::check(&seen, "/tb4_red", &expected("/tb4_red", &cmd, &red))
            .expect_err("namespace");
        assert_eq!(
            e.to_string(),
            "nothing under /tb4_red: topics seen under /bot1"
        );
        let no_odom: Vec<GraphEndpoint> = seen
            .iter()
            .filter(|e| e.topic != "/bot1/odom")
            .cloned()
            .collect();
        let e = graph::check(&no_odom, ns, &expected(ns, &cmd, &t)).expect_err("odom");
        assert_eq!(
            e.to_string(),
            "no publisher of /bot1/odom (odom); seen there: /bot1/hazard_detection (HazardDetectionVector), /bot1/platform/emergency_stop (Bool)"
        );
    }
}
