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

#[path = "../common/mod.rs"]
mod common;

/// The kinematic law and the `lab` velocity base (lagged, limited) on a
/// slow circle, as the tests of robots behind their own routers write them
/// (`real.rs`, `doctor/lab.rs`): a scenario's middle, TOML.
const LAB_LAW_AND_BASE: &str = r#"[control]
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
start = { x = 0.0, y = 0.0, theta_deg = 0.0 }
"#;
mod doctor;
mod excite;
mod hazards;
mod python_base;
mod real;
mod refusals;
mod up;

use common::{EXE, check, echelon_ok, f, ports, spawn, spawn_peer};
const SCENARIO: &str = "experiment-circle-velocity";

/// `fleet up` of [`SCENARIO`] on simulated ROS 2 bases: 30 fleet seconds
/// at ×10, quietly.
const UP_ROS2: [&str; 7] = [
    SCENARIO,
    "--ros2",
    "--time-scale",
    "10",
    "--duration",
    "30",
    "--quiet",
];

/// Agent 1's start pose in [`SCENARIO`], world `[x, y, θ]`.
const START: [f64; 3] = [0.0, -0.6, std::f64::consts::FRAC_PI_2];

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

/// What the test session heard on robot 1's `cmd_vel`: `(v, ω)` in order.
type Heard = Arc<Mutex<Vec<(f64, f64)>>>;
