//! A real robot at the head (issue 23): agent 1's robot is driven by
//! someone else (`ros2 = { driven = true }`); its fleet robot publishes the
//! robot's motion, read from its odometry, and two followers in a column
//! follow it. Here the "someone" is this test publishing a teleop script on
//! the simulated base's `cmd_vel` (stops, a turn on the spot, an arc, a
//! reversal), as `teleop_twist_keyboard` would.

#![allow(clippy::unwrap_used)]

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use zenoh::Wait;

use echelon_fleet::keys::Keys;
use echelon_fleet::wire::{self, Message};
use echelon_ros2::attachment::Attachment;
use echelon_ros2::keys::topic_key;
use echelon_ros2::msgs::{RosMessage, TWIST_STAMPED, Time, TwistStamped};

mod common;

use common::{ports, spawn_peer};

const SCENARIO: &str = r#"name = "teleop-column"
[sim]
duration = 40.0
dt = 0.001

[control]
law = "kinematic"
ke = 1.5
l = 0.05
lycomp = "none"

[robots.lab]
drive = "velocity"
tau_v = 0.05
tau_omega = 0.05
v_max = 0.5
omega_max = 3.0
a_max = 2.0
alpha_max = 8.0
half_wheelbase = 0.15
wheel_radius = 0.05

[reference.line]
speed = 0.1
start = { x = 0.0, y = 0.0, theta = 0.0 }

[[agents]]
name = "head"
robot = "lab"
start = { x = 0.0, y = 0.0, theta = 0.0 }
leader = "reference"
mode = "tracking"
ros2 = { driven = true }

[[agents]]
robot = "lab"
start = { x = -0.5, y = 0.05, theta = 0.0 }
leader = 1
offset = { x = 0.5, y = 0.0 }

[[agents]]
robot = "lab"
start = { x = -1.0, y = -0.05, theta = 0.0 }
leader = 2
offset = { x = 0.5, y = 0.0 }
"#;

/// The teleop script, head fleet time: `(until, v, ω)`.
const SCRIPT: [(f64, f64, f64); 8] = [
    (4.0, 0.0, 0.0),
    (9.0, 0.15, 0.0),
    (12.0, 0.0, 0.0),
    (15.0, 0.0, 0.6),
    (20.0, 0.15, 0.2),
    (23.0, 0.0, 0.0),
    (28.0, -0.1, 0.0),
    (31.0, 0.0, 0.0),
];

/// The followers' ‖e‖ in the last second of every segment is within this, m
/// (measured: at most 2.5 mm).
const SETTLED: f64 = 0.02;

#[test]
fn a_teleoperated_head_leads_a_column() {
    let _fleet = common::one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("teleop-column.toml");
    std::fs::write(&path, SCENARIO).unwrap();
    let scenario = path.to_str().unwrap();
    let e = ports(7);
    let session = common::open_peer(&e);
    // Every robot's published state: (agent, fleet t, ‖e‖).
    let states: Arc<Mutex<Vec<(u32, f64, f64)>>> = Arc::default();
    let s = states.clone();
    let _sub = session
        .declare_subscriber(Keys::new("teleop-column").states())
        .callback(move |sample| {
            if let Ok(Message::State(_, st)) = wire::decode(&sample.payload().to_bytes()) {
                s.lock()
                    .unwrap()
                    .push((st.agent, st.t, st.e[0].hypot(st.e[1])));
            }
        })
        .wait()
        .unwrap();
    let scale = ["--time-scale", "2"];
    let mut children = Vec::new();
    for k in 1..=3u32 {
        let agent = k.to_string();
        let i = 2 * k as usize - 1;
        let mut a = vec!["fleet", "base", scenario, "--ros2", "--agent", &agent];
        a.extend(scale);
        children.push(spawn_peer(&a, &e, i));
        let mut a = vec!["fleet", "robot", scenario, "--ros2", "--simulated-base"];
        a.extend(["--agent", &agent, "--duration", "31"]);
        a.extend(scale);
        children.push(spawn_peer(&a, &e, i + 1));
    }
    // The driver: the script on the head base's cmd_vel at 20 Hz (wall),
    // by the head's own published time.
    let key = topic_key(
        echelon_ros2::KeyScheme::RmwZenoh,
        0,
        "/robot1/cmd_vel",
        &TWIST_STAMPED,
    );
    let start = Instant::now();
    let mut seq = 0;
    loop {
        let head_t = states
            .lock()
            .unwrap()
            .iter()
            .rev()
            .find(|s| s.0 == 1)
            .map(|s| s.1);
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "the head never reached the script's end ({head_t:?})"
        );
        let Some(t) = head_t else {
            std::thread::sleep(Duration::from_millis(50));
            continue;
        };
        let Some(&(_, v, w)) = SCRIPT.iter().find(|s| t < s.0) else {
            break;
        };
        seq += 1;
        let cmd = TwistStamped::planar(v, w, Time::default(), "base_link").to_cdr();
        let att = Attachment {
            sequence_number: seq,
            source_timestamp_ns: 0,
            gid: [9; 16],
        }
        .encode();
        session
            .put(&key, cmd)
            .attachment(att.to_vec())
            .wait()
            .unwrap();
        std::thread::sleep(Duration::from_millis(50));
    }
    let reports: Vec<_> = children
        .into_iter()
        .skip(1)
        .step_by(2)
        .map(|robot| robot.report())
        .collect();
    // The head commanded nothing; the followers tracked their leaders.
    assert_eq!(reports[0]["ros2"]["cmd_sent"], 0, "{}", reports[0]);
    for r in &reports[1..] {
        assert!(r["ros2"]["cmd_sent"].as_u64().unwrap() > 1000, "{r}");
        assert_eq!(r["counters"]["link_losses"], 0, "{r}");
    }
    let states = states.lock().unwrap();
    let mut from = 0.0;
    for &(until, v, w) in &SCRIPT {
        for agent in [2, 3] {
            let window: Vec<f64> = states
                .iter()
                .filter(|s| s.0 == agent && (until - 1.0..until).contains(&s.1))
                .map(|s| s.2)
                .collect();
            assert!(
                window.len() > 50,
                "agent {agent} in [{}, {until}): {}",
                until - 1.0,
                window.len()
            );
            let worst = window.iter().copied().fold(0.0, f64::max);
            eprintln!("agent {agent}, {from}–{until} s (v {v}, ω {w}): ‖e‖ ≤ {worst:.4} m");
            assert!(
                worst < SETTLED,
                "agent {agent}: ‖e‖ {worst} m at the end of the segment {from}–{until} s (v {v}, ω {w})"
            );
        }
        from = until;
    }
}
