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

use echelon_ros2::cdr::CdrError;
use echelon_ros2::msgs::{
    HEADER, Header, ODOMETRY, Odometry, POSE_STAMPED, POSE_WITH_COVARIANCE_STAMPED, Point, Pose,
    PoseStamped, PoseWithCovariance, PoseWithCovarianceStamped, Quaternion, RosMessage, TWIST,
    TWIST_STAMPED, Time, Twist, TwistStamped, TwistWithCovariance, Vector3,
};
use serde_json::{Value, json};

mod common;
use common::{covariance, header, odometry, quat, twist, twist_stamped};
#[path = "common/python.rs"]
mod python;
use python::Helpers;

const INSTALL_HINT: &str = "the ROS 2 interop tests need python3 (3.11) with the ROS 2 Jazzy \
    wheels: run `scripts/test` (it installs scripts/requirements-ros2.txt), or \
    `python3 -m pip install -r scripts/requirements-ros2.txt` (ros-jazzy-rclpy[fastrtps], \
    ros-jazzy-geometry-msgs, ros-jazzy-nav-msgs; ~280 MB); set ECHELON_PYTHON to use \
    another interpreter";

/// Runs `rclpy_codec.py command` with `input` on its stdin.
fn rclpy(command: &str, input: Option<&Value>) -> Value {
    Helpers::new(INSTALL_HINT)
        .run("rclpy_codec.py", &[command], input)
        .unwrap_or_else(|e| panic!("{e}"))
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

/// A frame name longer than any padding or small-buffer optimisation.
fn long_frame() -> String {
    (0..40).map(|k| format!("robot_{k}/")).collect::<String>() + "base_link"
}

fn pose_json(p: &Pose) -> Value {
    json!({"position": common::point(&p.position), "orientation": quat(&p.orientation)})
}

fn pose_stamped(p: &PoseStamped) -> Value {
    json!({"header": header(&p.header), "pose": pose_json(&p.pose)})
}

fn pose_with_covariance_stamped(p: &PoseWithCovarianceStamped) -> Value {
    json!({
        "header": header(&p.header),
        "pose": {"pose": pose_json(&p.pose.pose), "covariance": covariance(&p.pose.covariance)},
    })
}

/// Poses whose orientation is a unit quaternion for even `k` and four
/// arbitrary numbers (not normalised, as a wire value may be) for odd `k`.
fn pose(k: usize) -> Pose {
    Pose {
        position: point(k + 2),
        orientation: if k.is_multiple_of(2) {
            Quaternion::from_yaw(spread(k + 4))
        } else {
            Quaternion {
                x: spread(k),
                y: spread(k + 3),
                z: spread(k + 5),
                w: spread(k + 7),
            }
        },
    }
}

fn pose_stampeds() -> Vec<PoseStamped> {
    let mut v: Vec<PoseStamped> = (0..14)
        .map(|k| PoseStamped {
            header: Header {
                stamp: time(k + 2),
                frame_id: frame(k + 5),
            },
            pose: pose(k),
        })
        .collect();
    v.push(PoseStamped::planar(
        2.5,
        -1.75,
        -2.0,
        Time::from_nanos(-1_500_000_000),
        &long_frame(),
    ));
    v.push(PoseStamped::planar(0.0, 0.0, 0.0, Time::default(), ""));
    v.push(PoseStamped::planar(
        f64::NAN,
        1.0,
        0.5,
        Time::from_nanos(1),
        "mocap",
    ));
    v
}

fn pose_with_covariance_stampeds() -> Vec<PoseWithCovarianceStamped> {
    let mut v: Vec<PoseWithCovarianceStamped> = (0..13)
        .map(|k| PoseWithCovarianceStamped {
            header: Header {
                stamp: time(k + 3),
                frame_id: frame(k + 7),
            },
            pose: PoseWithCovariance {
                pose: pose(k + 1),
                covariance: std::array::from_fn(|i| spread(3 * i + k)),
            },
        })
        .collect();
    // All 36 entries distinct (a transposed or shifted index shows).
    v.push(PoseWithCovarianceStamped {
        header: Header {
            stamp: Time::from_nanos(-7),
            frame_id: long_frame(),
        },
        pose: PoseWithCovariance {
            pose: Pose::planar(-3.5, 4.25, 2.75),
            covariance: distinct_covariance(),
        },
    });
    v.push(PoseWithCovarianceStamped::planar(
        1.0,
        2.0,
        -3.0,
        [[0.25, 0.01, -0.02], [0.01, 0.5, 0.03], [-0.02, 0.03, 0.068]],
        Time::from_nanos(1_700_000_000_123_456_789),
        "map",
    ));
    v.push(PoseWithCovarianceStamped::planar(
        0.0,
        0.0,
        0.0,
        [
            [f64::INFINITY, 0.0, 0.0],
            [0.0, f64::NAN, 0.0],
            [0.0, 0.0, -0.0],
        ],
        Time::default(),
        "",
    ));
    v
}

/// A covariance whose 36 entries differ: entry (i, j) is `i + j / 8 + 1/64`.
fn distinct_covariance() -> [f64; 36] {
    std::array::from_fn(|n| (n / 6) as f64 + (n % 6) as f64 / 8.0 + 1.0 / 64.0)
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

/// One test a row `name: messages, their rclpy JSON;`, checking the
/// messages [`both_ways`].
macro_rules! golden_vectors_both_ways {
    ($($name:ident: $messages:expr, $to_json:expr;)*) => {$(
        #[test]
        fn $name() {
            both_ways(&$messages, $to_json);
        }
    )*};
}

golden_vectors_both_ways! {
    twist_golden_vectors_both_ways: twists(), twist;
    twist_stamped_golden_vectors_both_ways: twist_stampeds(), twist_stamped;
    odometry_golden_vectors_both_ways: odometries(), odometry;
    pose_stamped_golden_vectors_both_ways: pose_stampeds(), pose_stamped;
}

#[test]
fn pose_with_covariance_stamped_golden_vectors_both_ways() {
    let messages = pose_with_covariance_stampeds();
    let distinct = &messages[13].pose.covariance;
    for (i, a) in distinct.iter().enumerate() {
        assert!(distinct[..i].iter().all(|b| b != a), "entry {i} repeats");
    }
    both_ways(&messages, pose_with_covariance_stamped);
}

#[test]
fn the_planar_covariance_of_an_rclpy_pose_is_rows_and_columns_0_1_5() {
    // In rclpy, covariance[6 i + j] is entry (i, j) over (x, y, z, rot X, rot Y, rot Z).
    let mut msg = pose_with_covariance_stampeds().swap_remove(13);
    msg.pose.pose.orientation = Quaternion::from_yaw(-2.5);
    let bytes = serialize_in_rclpy(
        POSE_WITH_COVARIANCE_STAMPED.name,
        &[pose_with_covariance_stamped(&msg)],
    );
    let decoded = PoseWithCovarianceStamped::from_cdr_finite(&bytes[0]).expect("finite");
    let c = distinct_covariance();
    assert_eq!(
        decoded.planar_covariance(),
        [
            [c[0], c[1], c[5]],
            [c[6], c[7], c[11]],
            [c[30], c[31], c[35]]
        ]
    );
    assert!((decoded.yaw() + 2.5).abs() < 1e-12);
    assert_eq!(
        (decoded.pose.pose.position.x, decoded.pose.pose.position.y),
        (-3.5, 4.25)
    );
}

#[test]
fn rclpy_poses_with_nan_are_reported_non_finite() {
    let fix = PoseStamped::planar(1.0, 2.0, 0.3, Time::from_nanos(-3), "mocap");
    let mut fixes = [fix.clone(), fix];
    fixes[0].pose.position.y = f64::NAN;
    fixes[1].pose.orientation.w = f64::NAN;
    let values: Vec<Value> = fixes.iter().map(pose_stamped).collect();
    let bytes = serialize_in_rclpy(POSE_STAMPED.name, &values);
    for (b, field) in bytes.iter().zip(["pose.position", "pose.orientation"]) {
        assert!(PoseStamped::from_cdr(b).is_ok());
        assert_eq!(
            PoseStamped::from_cdr_finite(b),
            Err(CdrError::NonFinite { field })
        );
    }

    let estimate = pose_with_covariance_stampeds().swap_remove(14);
    let mut estimates = [estimate.clone(), estimate.clone(), estimate];
    estimates[0].pose.pose.position.x = f64::NAN;
    estimates[1].pose.pose.orientation.z = f64::NAN;
    estimates[2].pose.covariance[35] = f64::NAN;
    let values: Vec<Value> = estimates.iter().map(pose_with_covariance_stamped).collect();
    let bytes = serialize_in_rclpy(POSE_WITH_COVARIANCE_STAMPED.name, &values);
    for (b, field) in bytes.iter().zip([
        "pose.pose.position",
        "pose.pose.orientation",
        "pose.covariance",
    ]) {
        assert!(PoseWithCovarianceStamped::from_cdr(b).is_ok());
        assert_eq!(
            PoseWithCovarianceStamped::from_cdr_finite(b),
            Err(CdrError::NonFinite { field })
        );
    }
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
    for ty in [
        TWIST,
        TWIST_STAMPED,
        ODOMETRY,
        HEADER,
        POSE_STAMPED,
        POSE_WITH_COVARIANCE_STAMPED,
    ] {
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
    python::assert_missing_interpreter_named(INSTALL_HINT, "requirements-ros2.txt");
    // And the real one answers.
    let check = rclpy("check", None);
    assert_eq!(check["ok"], Value::Bool(true), "{check}");
}
