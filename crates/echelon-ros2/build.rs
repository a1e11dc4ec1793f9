//! Generates the ROS 2 message types from their `.msg` files (`msg/`), as
//! rosidl generators do for C++/Python (and r2r/rclrs for Rust): structs,
//! CDR codecs, RIHS01 type hashes and rosbag2's full definitions, into
//! `$OUT_DIR/msgs.rs` and `$OUT_DIR/definitions.rs`, which `src/msgs.rs`
//! and `src/definitions.rs` include. Adding a message is adding its `.msg`
//! (and those it nests) under `msg/`.

#![cfg_attr(not(test), warn(clippy::too_many_lines))]

#[path = "build/describe.rs"]
mod describe;
#[path = "build/emit.rs"]
mod emit;
#[path = "build/msg.rs"]
mod msg;

use std::path::PathBuf;

/// The types a topic carries (`cmd_vel`, `odom`, a motion-capture pose, AMCL's
/// `amcl_pose`, a Create 3's `hazard_detection`, an e-stop's `Bool`), by
/// `package/Type`: those with a full definition, which the
/// fleet records and `identify` reads.
const TOPIC_TYPES: &[&str] = &[
    "geometry_msgs/Twist",
    "geometry_msgs/TwistStamped",
    "nav_msgs/Odometry",
    "geometry_msgs/PoseStamped",
    "geometry_msgs/PoseWithCovarianceStamped",
    "irobot_create_msgs/HazardDetectionVector",
    "std_msgs/Bool",
];

fn main() {
    let manifest = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").expect("set by cargo"));
    let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("set by cargo"));
    let root = manifest.join("msg");
    println!("cargo::rerun-if-changed=msg");
    println!("cargo::rerun-if-changed=build");
    let all = msg::read_all(&root);
    write(&out.join("msgs.rs"), &emit::msgs(&all));
    write(
        &out.join("definitions.rs"),
        &emit::definitions(&all, TOPIC_TYPES),
    );
}

fn write(path: &std::path::Path, text: &str) {
    std::fs::write(path, text).unwrap_or_else(|e| panic!("writing {}: {e}", path.display()));
}
