//! echelon's ROS 2 wire layer against real ROS 2 serialization: the ROS 2
//! Jazzy wheels from PyPI (rclpy's `serialize_message` /
//! `deserialize_message`, Fast-CDR underneath), driven through
//! `scripts/ros2/rclpy_codec.py`.
//!
//! - golden vectors both ways: rclpy's encodings decode in echelon to the
//!   same values, bit for bit, and echelon's encodings deserialize in rclpy
//!   to the same values; both encodings have the same length (they may
//!   differ only in padding, which Fast-CDR leaves uninitialised);
//! - every proper prefix of an rclpy encoding is refused as truncated;
//! - the RIHS01 type hash constants equal the wheels' `share/*/msg/*.json`.
//!
//! These tests need `python3` with the wheels (`scripts/test` installs
//! `scripts/requirements-ros2.txt`); without them they fail and say so.

use std::io::Write;
use std::path::PathBuf;
use std::process::{Command, Stdio};

use echelon_ros2::cdr::CdrError;
use echelon_ros2::msgs::{
    HEADER, Header, ODOMETRY, Odometry, Point, Pose, PoseWithCovariance, Quaternion, RosMessage,
    TWIST, TWIST_STAMPED, Time, Twist, TwistStamped, TwistWithCovariance, Vector3,
};
use serde_json::{Value, json};

mod common;
use common::{odometry, twist, twist_stamped};

const INSTALL_HINT: &str = "the ROS 2 interop tests need python3 (3.11) with the ROS 2 Jazzy \
    wheels: run `scripts/test` (it installs scripts/requirements-ros2.txt), or \
    `python3 -m pip install -r scripts/requirements-ros2.txt` (ros-jazzy-rclpy[fastrtps], \
    ros-jazzy-geometry-msgs, ros-jazzy-nav-msgs; ~280 MB); set ECHELON_PYTHON to use \
    another interpreter";

fn script() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scripts/ros2/rclpy_codec.py")
}

/// Runs the rclpy helper with `python`; an error message names what to install.
fn run_with(python: &str, command: &str, input: Option<&Value>) -> Result<Value, String> {
    let mut child = Command::new(python)
        .arg(script())
        .arg(command)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| format!("cannot run `{python}`: {e}; {INSTALL_HINT}"))?;
    if let Some(input) = input {
        let mut stdin = child.stdin.take().ok_or("no stdin")?;
        stdin
            .write_all(input.to_string().as_bytes())
            .map_err(|e| format!("writing to {python}: {e}"))?;
    }
    drop(child.stdin.take());
    let out = child
        .wait_with_output()
        .map_err(|e| format!("waiting for {python}: {e}"))?;
    if !out.status.success() {
        return Err(format!(
            "`{python} {} {command}` failed ({}): {}\n{INSTALL_HINT}",
            script().display(),
            out.status,
            String::from_utf8_lossy(&out.stderr).trim()
        ));
    }
    serde_json::from_slice(&out.stdout).map_err(|e| format!("bad JSON from rclpy_codec.py: {e}"))
}

fn python() -> String {
    std::env::var("ECHELON_PYTHON").unwrap_or_else(|_| "python3".to_owned())
}

fn rclpy(command: &str, input: Option<&Value>) -> Value {
    match run_with(&python(), command, input) {
        Ok(v) => v,
        Err(e) => panic!("{e}"),
    }
}

/// A float from a few parameters that covers signs, magnitudes and the
/// special values (subnormal, -0, max, tiny).
fn spread(k: usize) -> f64 {
    const SPECIAL: [f64; 8] = [
        0.0,
        -0.0,
        f64::MAX,
        f64::MIN_POSITIVE,
        5e-324,
        -1.0e-300,
        std::f64::consts::PI,
        -123_456.789,
    ];
    if k.is_multiple_of(3) {
        SPECIAL[(k / 3) % SPECIAL.len()]
    } else {
        (k as f64 * 0.731 - 7.3) * 10f64.powi((k % 7) as i32 - 3)
    }
}

fn frame(k: usize) -> String {
    // Lengths 0..=9 cover every padding after the string; one non-ASCII name.
    match k % 11 {
        10 => "bäse_link_ü".to_owned(),
        n => "base_link".chars().cycle().take(n).collect(),
    }
}

fn time(k: usize) -> Time {
    Time {
        sec: [0, 1_700_000_000, -5, i32::MAX, i32::MIN][k % 5],
        nanosec: [0, 123_456_789, 999_999_999, u32::MAX][k % 4],
    }
}

fn vector(k: usize) -> Vector3 {
    Vector3 {
        x: spread(k),
        y: spread(k + 1),
        z: spread(k + 2),
    }
}

fn point(k: usize) -> Point {
    let Vector3 { x, y, z } = vector(k);
    Point { x, y, z }
}

fn twists() -> Vec<Twist> {
    let mut v: Vec<Twist> = (0..12)
        .map(|k| Twist {
            linear: vector(3 * k),
            angular: vector(3 * k + 1),
        })
        .collect();
    v.push(Twist::planar(0.5, -0.25));
    // Non-finite numbers travel as they are; the decoder reports them.
    v.push(Twist::planar(f64::NAN, f64::INFINITY));
    v.push(Twist::planar(f64::NEG_INFINITY, 0.0));
    v
}

fn twist_stampeds() -> Vec<TwistStamped> {
    (0..14)
        .map(|k| TwistStamped {
            header: Header {
                stamp: time(k),
                frame_id: frame(k),
            },
            twist: twists()[k % twists().len()],
        })
        .collect()
}

fn odometries() -> Vec<Odometry> {
    let mut v: Vec<Odometry> = (0..12)
        .map(|k| Odometry {
            header: Header {
                stamp: time(k + 1),
                frame_id: frame(k + 3),
            },
            child_frame_id: frame(k),
            pose: PoseWithCovariance {
                pose: Pose {
                    position: point(k),
                    orientation: Quaternion::from_yaw(spread(k + 5)),
                },
                covariance: std::array::from_fn(|i| spread(i + k)),
            },
            twist: TwistWithCovariance {
                twist: twists()[k],
                covariance: std::array::from_fn(|i| spread(2 * i + k)),
            },
        })
        .collect();
    v.push(Odometry::planar(
        1.5,
        -2.25,
        3.0,
        0.4,
        -0.1,
        Time::from_nanos(1_700_000_000_123_456_789),
        "odom",
        "base_link",
    ));
    v
}

fn serialize_in_rclpy(type_name: &str, values: &[Value]) -> Vec<Vec<u8>> {
    let input: Vec<Value> = values
        .iter()
        .map(|v| json!({"type": type_name, "value": v}))
        .collect();
    let out = rclpy("serialize", Some(&Value::from(input)));
    out.as_array()
        .expect("a list of hex strings")
        .iter()
        .map(|h| {
            let h = h.as_str().expect("hex");
            (0..h.len())
                .step_by(2)
                .map(|i| u8::from_str_radix(&h[i..i + 2], 16).expect("hex digit"))
                .collect()
        })
        .collect()
}

fn deserialize_in_rclpy(type_name: &str, payloads: &[Vec<u8>]) -> Vec<Value> {
    let input: Vec<Value> = payloads
        .iter()
        .map(|p| {
            let hex: String = p.iter().map(|b| format!("{b:02x}")).collect();
            json!({"type": type_name, "hex": hex})
        })
        .collect();
    rclpy("deserialize", Some(&Value::from(input)))
        .as_array()
        .expect("a list of values")
        .clone()
}

/// Both directions for one message type.
fn both_ways<M: RosMessage>(messages: &[M], to_json: fn(&M) -> Value) {
    let values: Vec<Value> = messages.iter().map(to_json).collect();

    // rclpy -> echelon.
    let theirs = serialize_in_rclpy(M::TYPE.name, &values);
    assert_eq!(theirs.len(), messages.len());
    for (k, (bytes, value)) in theirs.iter().zip(&values).enumerate() {
        let decoded = M::from_cdr(bytes)
            .unwrap_or_else(|e| panic!("{} #{k}: rclpy's bytes refused: {e}", M::TYPE.name));
        assert_eq!(
            &to_json(&decoded),
            value,
            "{} #{k}: decoded values differ",
            M::TYPE.name
        );
        let ours = decoded.to_cdr();
        assert_eq!(
            ours.len(),
            bytes.len(),
            "{} #{k}: encoded lengths differ",
            M::TYPE.name
        );
        // Every proper prefix is refused as truncated, never a panic.
        for cut in 0..bytes.len() {
            assert!(
                matches!(M::from_cdr(&bytes[..cut]), Err(CdrError::Truncated { .. })),
                "{} #{k}: prefix of {cut} bytes not refused as truncated",
                M::TYPE.name
            );
        }
    }

    // echelon -> rclpy.
    let ours: Vec<Vec<u8>> = messages.iter().map(RosMessage::to_cdr).collect();
    let back = deserialize_in_rclpy(M::TYPE.name, &ours);
    assert_eq!(back.len(), values.len());
    for (k, (got, want)) in back.iter().zip(&values).enumerate() {
        assert_eq!(got, want, "{} #{k}: rclpy read other values", M::TYPE.name);
    }
}

#[test]
fn twist_golden_vectors_both_ways() {
    both_ways(&twists(), twist);
}

#[test]
fn twist_stamped_golden_vectors_both_ways() {
    both_ways(&twist_stampeds(), twist_stamped);
}

#[test]
fn odometry_golden_vectors_both_ways() {
    both_ways(&odometries(), odometry);
}

#[test]
fn rclpy_odometry_with_nan_is_reported_non_finite() {
    let mut odom = odometries().pop().expect("one");
    odom.pose.pose.position.y = f64::NAN;
    let bytes = serialize_in_rclpy(ODOMETRY.name, &[odometry(&odom)]);
    assert!(Odometry::from_cdr(&bytes[0]).is_ok());
    assert_eq!(
        Odometry::from_cdr_finite(&bytes[0]),
        Err(CdrError::NonFinite {
            field: "pose.pose.position"
        })
    );
}

#[test]
fn type_hash_constants_equal_the_wheels() {
    let hashes = rclpy("hashes", None);
    for ty in [TWIST, TWIST_STAMPED, ODOMETRY, HEADER] {
        assert_eq!(
            hashes.get(ty.name).and_then(Value::as_str),
            Some(ty.hash),
            "{}",
            ty.name
        );
    }
}

#[test]
fn a_missing_interpreter_is_reported_with_what_to_install() {
    let err = run_with("/nonexistent/python3", "check", None).expect_err("cannot run");
    assert!(err.contains("scripts/test"), "{err}");
    assert!(err.contains("requirements-ros2.txt"), "{err}");
    // And the real one answers.
    let check = rclpy("check", None);
    assert_eq!(check["ok"], Value::Bool(true), "{check}");
}
