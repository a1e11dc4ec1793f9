use super::*;

/// `rclpy.serialization.serialize_message` of a TwistStamped with
/// `header.frame_id = "base_link"` and `twist.linear.x = 0.5` (ROS 2
/// Jazzy wheels). Bytes 18..20 are Fast-CDR's uninitialised padding: here
/// `73 ba`, whatever was in memory.
const RCLPY_TWIST_STAMPED: &str = "0001000000000000000000000a000000626173655f6c696e6b0073ba\
    000000000000e03f\
    0000000000000000000000000000000000000000\
    0000000000000000000000000000000000000000";

fn hex(s: &str) -> Vec<u8> {
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).expect("hex"))
        .collect()
}

#[test]
fn an_rclpy_twist_stamped_with_garbage_padding_decodes() {
    let bytes = hex(RCLPY_TWIST_STAMPED);
    let msg = TwistStamped::from_cdr_finite(&bytes).expect("decodes");
    assert_eq!(
        msg,
        TwistStamped::planar(0.5, 0.0, Time::default(), "base_link")
    );
    // Ours differs only in the padding.
    let ours = msg.to_cdr();
    assert_eq!(ours.len(), bytes.len());
    let differing: Vec<usize> = (0..ours.len()).filter(|&i| ours[i] != bytes[i]).collect();
    assert_eq!(differing, vec![26, 27]);
}

/// The generated hashes are ROS 2 Jazzy's (the wheels' `share/*/msg/*.json`,
/// which echelon-fleet's `tests/ros2_interop.rs` reads for the topic types).
#[test]
fn generated_type_hashes_are_jazzys() {
    for (ty, hash) in [
        (
            TIME,
            "b106235e25a4c5ed35098aa0a61a3ee9c9b18d197f398b0e4206cea9acf9c197",
        ),
        (
            HEADER,
            "f49fb3ae2cf070f793645ff749683ac6b06203e41c891e17701b1cb597ce6a01",
        ),
        (
            VECTOR3,
            "cc12fe83e4c02719f1ce8070bfd14aecd40f75a96696a67a2a1f37f7dbb0765d",
        ),
        (
            POINT,
            "6963084842a9b04494d6b2941d11444708d892da2f4b09843b9c43f42a7f6881",
        ),
        (
            QUATERNION,
            "8a765f66778c8ff7c8ab94afcc590a2ed5325a1d9a076ffff38fbce36f458684",
        ),
        (
            POSE,
            "d501954e9476cea2996984e812054b68026ae0bfae789d9a10b23daf35cc90fa",
        ),
        (
            POSE_WITH_COVARIANCE,
            "9a7c0fd234b7f45c6098745ecccd773ca1085670e64107135397aee31c02e1bb",
        ),
        (
            TWIST,
            "9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a",
        ),
        (
            TWIST_WITH_COVARIANCE,
            "49f574f033f095d8b6cd1beaca5ca7925e296e84af1716d16c89d38b059c8c18",
        ),
        (
            TWIST_STAMPED,
            "5f0fcd4f81d5d06ad9b4c4c63e3ea51b82d6ae4d0558f1d475229b1121db6f64",
        ),
        (
            ODOMETRY,
            "3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0",
        ),
        (
            POSE_STAMPED,
            "10f3786d7d40fd2b54367835614bff85d4ad3b5dab62bf8bca0cc232d73b4cd8",
        ),
        (
            POSE_WITH_COVARIANCE_STAMPED,
            "26432f9803e43727d3c8f668d1fdb3c630f548af631e2f4e31382371bfea3b6e",
        ),
    ] {
        assert_eq!(ty.hash, format!("RIHS01_{hash}"), "{}", ty.name);
    }
    assert_eq!(Quaternion::default(), Quaternion::from_yaw(0.0));
}

#[test]
fn dds_names_are_mangled_as_rmw_zenoh_does() {
    assert_eq!(
        TWIST_STAMPED.dds_name(),
        "geometry_msgs::msg::dds_::TwistStamped_"
    );
    assert_eq!(ODOMETRY.dds_name(), "nav_msgs::msg::dds_::Odometry_");
    assert_eq!(
        POSE_STAMPED.dds_name(),
        "geometry_msgs::msg::dds_::PoseStamped_"
    );
    assert_eq!(
        POSE_WITH_COVARIANCE_STAMPED.dds_name(),
        "geometry_msgs::msg::dds_::PoseWithCovarianceStamped_"
    );
}

#[test]
fn planar_poses_round_trip() {
    let stamp = Time {
        sec: -5,
        nanosec: 7,
    };
    for k in -20..=20 {
        let (x, y, yaw) = (
            f64::from(k) * 1.25,
            -0.5 * f64::from(k),
            f64::from(k) * 0.37,
        );
        let fix = PoseStamped::planar(x, y, yaw, stamp, "mocap");
        let back = PoseStamped::from_cdr_finite(&fix.to_cdr()).expect("decodes");
        assert_eq!(back, fix);
        assert_eq!((back.pose.position.x, back.pose.position.y), (x, y));
        assert_eq!(back.pose.position.z, 0.0);
        assert!(wrap_angle(back.yaw() - yaw).abs() < 1e-12, "{yaw}");

        let cov = [[0.25, 0.01, -0.02], [0.01, 0.5, 0.03], [-0.02, 0.03, 0.07]];
        let estimate = PoseWithCovarianceStamped::planar(x, y, yaw, cov, stamp, "map");
        let back = PoseWithCovarianceStamped::from_cdr_finite(&estimate.to_cdr()).expect("decodes");
        assert_eq!(back, estimate);
        assert_eq!(back.header.frame_id, "map");
        assert_eq!(back.pose.pose.position, Point { x, y, z: 0.0 });
        assert!(wrap_angle(back.yaw() - yaw).abs() < 1e-12, "{yaw}");
        assert_eq!(back.planar_covariance(), cov);
    }
}

#[test]
fn the_planar_covariance_is_rows_and_columns_x_y_and_rotation_about_z() {
    // Row-major 6×6 over (x, y, z, rot X, rot Y, rot Z): entry (i, j) = 10 i + j.
    let pose = PoseWithCovariance {
        covariance: std::array::from_fn(|n| (10 * (n / 6) + n % 6) as f64),
        ..PoseWithCovariance::default()
    };
    assert_eq!(
        pose.planar_covariance(),
        [[0.0, 1.0, 5.0], [10.0, 11.0, 15.0], [50.0, 51.0, 55.0]]
    );
    // AMCL's indices; the other 27 entries are zero in a planar estimate.
    let planar = PoseWithCovariance::planar(0.0, 0.0, 0.0, [[1.0; 3]; 3]);
    let set: Vec<usize> = (0..36).filter(|&n| planar.covariance[n] != 0.0).collect();
    assert_eq!(set, [0, 1, 5, 6, 7, 11, 30, 31, 35]);
}

#[test]
fn yaw_of_from_yaw_is_the_wrapped_angle() {
    for k in -20..=20 {
        let a = f64::from(k) * 0.37;
        let q = Quaternion::from_yaw(a);
        assert!((wrap_angle(q.yaw() - a)).abs() < 1e-12, "{a}");
        // Scaled (not normalised) quaternions give the same yaw.
        let s = Quaternion {
            x: 3.0 * q.x,
            y: 3.0 * q.y,
            z: 3.0 * q.z,
            w: 3.0 * q.w,
        };
        assert!((s.yaw() - q.yaw()).abs() < 1e-12);
    }
}

/// Finite quaternions whose squares overflow (or underflow) have the
/// yaw of their normalised rotation: a NaN before (the network fuzz
/// corpus, echelon-fleet's `tests/fuzz_network.rs`: an odometry with
/// two components of 1e200 gave the robot a NaN heading).
#[test]
fn the_yaw_of_a_huge_or_tiny_quaternion_is_finite_and_right() {
    for k in -20..=20 {
        let a = f64::from(k) * 0.37;
        let q = Quaternion::from_yaw(a);
        for scale in [1e300, 1e200, 1e151, 1e-151, 1e-300, 5e-310] {
            let s = Quaternion {
                x: scale * q.x,
                y: scale * q.y,
                z: scale * q.z,
                w: scale * q.w,
            };
            assert!(
                wrap_angle(s.yaw() - a).abs() < 1e-9,
                "{a} × {scale}: {}",
                s.yaw()
            );
        }
    }
    let huge = Quaternion {
        x: f64::MAX,
        y: f64::MAX,
        z: -f64::MAX,
        w: f64::MAX,
    };
    assert!(huge.yaw().is_finite());
    assert_eq!(Quaternion::default().yaw(), 0.0);
    let zero = Quaternion {
        w: 0.0,
        ..Quaternion::default()
    };
    assert_eq!(zero.yaw(), 0.0);
}

/// `checked_yaw` takes a quaternion exactly when tf2 would: a rotation
/// scaled by `s` has squared norm `s²`, taken iff `|s² − 1| < 10e-3`,
/// and then its yaw is the rotation's; zero, non-finite and overflowing
/// quaternions have none.
#[test]
fn checked_yaw_takes_what_tf2_takes() {
    let mut taken = 0;
    for k in -20..=20 {
        let a = f64::from(k) * 0.37;
        let q = Quaternion::from_yaw(a);
        assert_eq!(q.checked_yaw(), Some(q.yaw()));
        // Scales across [0, 2], densest near tf2's edges (s² = 1 ± 0.01).
        let edges = [0.99f64.sqrt(), 1.01f64.sqrt()];
        let scales = (0..=400)
            .map(|n| f64::from(n) * 0.005)
            .chain(edges.iter().flat_map(|e| [e - 1e-9, e + 1e-9]));
        for scale in scales {
            let s = Quaternion {
                x: scale * q.x,
                y: scale * q.y,
                z: scale * q.z,
                w: scale * q.w,
            };
            let norm_sq = s.x * s.x + s.y * s.y + s.z * s.z + s.w * s.w;
            let want = (norm_sq - 1.0).abs() < QUATERNION_NORM_TOLERANCE;
            match s.checked_yaw() {
                Some(yaw) => {
                    assert!(want, "{a} × {scale}: taken");
                    assert!(wrap_angle(yaw - a).abs() < 1e-9, "{a} × {scale}: {yaw}");
                    taken += 1;
                }
                None => assert!(!want, "{a} × {scale}: refused"),
            }
        }
    }
    // Per yaw: 0.995 and 1 of the grid (1.005² = 1.010025 is out) and
    // the two edges' inner sides.
    assert_eq!(taken, 41 * 4);
    let zero = Quaternion {
        w: 0.0,
        ..Quaternion::default()
    };
    assert_eq!(zero.checked_yaw(), None);
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1e200, f64::MAX] {
        let q = Quaternion {
            x: bad,
            ..Quaternion::default()
        };
        assert_eq!(q.checked_yaw(), None, "{bad}");
    }
}

#[test]
fn the_unwrapper_counts_turns() {
    let mut u = YawUnwrapper::new();
    // Turning counter-clockwise 0.3 rad a step for three turns.
    for k in 0..63 {
        let heading = f64::from(k) * 0.3;
        let out = u.unwrap(wrap_angle(heading));
        assert!((out - heading).abs() < 1e-9, "{k}: {out} vs {heading}");
    }
    assert!(u.unwrap(f64::NAN).is_nan());
    assert!((u.unwrap(wrap_angle(62.0 * 0.3 - 0.1)) - (62.0 * 0.3 - 0.1)).abs() < 1e-9);
}

#[test]
fn time_from_nanos_round_trips_and_saturates() {
    for ns in [0i64, 1, 999_999_999, 1_000_000_000, -1, -1_500_000_000] {
        let t = Time::from_nanos(ns);
        assert!(t.nanosec < 1_000_000_000);
        assert_eq!(t.to_nanos(), ns);
    }
    assert_eq!(Time::from_nanos(i64::MAX).sec, i32::MAX);
    assert_eq!(Time::from_nanos(i64::MIN).sec, i32::MIN);
}
