//! Laws of the ROS 2 wire layer over all inputs: CDR encode→decode round
//! trips, decoders never panic on arbitrary or truncated bytes, non-finite
//! numbers are reported, the attachment round trips, tokens and keys keep
//! their shape for any valid names, the yaw unwrapper is continuous.

use std::f64::consts::{PI, TAU};

use echelon_ros2::attachment::{ATTACHMENT_LEN, Attachment};
use echelon_ros2::cdr::CdrError;
use echelon_ros2::keys::{check_topic_key, topic_key};
use echelon_ros2::liveliness::{Endpoint, NodeInfo, Qos};
use echelon_ros2::msgs::{
    Header, ODOMETRY, Odometry, Point, Pose, PoseStamped, PoseWithCovariance,
    PoseWithCovarianceStamped, Quaternion, RosMessage, TWIST_STAMPED, Time, Twist, TwistStamped,
    TwistWithCovariance, Vector3, YawUnwrapper, wrap_angle,
};
use echelon_ros2::names::{KeyScheme, fully_qualified_topic};
use proptest::prelude::*;

/// Decodes `bytes` as each message type echelon reads, with and without
/// the finiteness check, and as an attachment; none may panic.
fn decode_every_way(bytes: &[u8]) {
    fn both<M: RosMessage>(bytes: &[u8]) {
        let _ = M::from_cdr(bytes);
        let _ = M::from_cdr_finite(bytes);
    }
    both::<Twist>(bytes);
    both::<TwistStamped>(bytes);
    both::<Odometry>(bytes);
    both::<PoseStamped>(bytes);
    both::<PoseWithCovarianceStamped>(bytes);
    let _ = Attachment::decode(bytes);
}

/// Every number of an odometry message, in wire order: the pose (position,
/// orientation), its covariance, the twist (linear, angular), its covariance.
fn numbers_mut(odom: &mut Odometry) -> Vec<&mut f64> {
    let (p, t) = (&mut odom.pose, &mut odom.twist);
    let Point { x, y, z } = &mut p.pose.position;
    let Quaternion {
        x: qx,
        y: qy,
        z: qz,
        w: qw,
    } = &mut p.pose.orientation;
    let Vector3 {
        x: vx,
        y: vy,
        z: vz,
    } = &mut t.twist.linear;
    let Vector3 {
        x: wx,
        y: wy,
        z: wz,
    } = &mut t.twist.angular;
    let numbers: Vec<&mut f64> = [x, y, z, qx, qy, qz, qw]
        .into_iter()
        .chain(&mut p.covariance)
        .chain([vx, vy, vz, wx, wy, wz])
        .chain(&mut t.covariance)
        .collect();
    assert_eq!(numbers.len(), 3 + 4 + 36 + 6 + 36);
    numbers
}

/// Any f64 bit pattern: NaNs, infinities, subnormals, -0.
fn any_f64() -> impl Strategy<Value = f64> + Clone {
    prop_oneof![
        4 => any::<f64>(),
        1 => any::<u64>().prop_map(f64::from_bits),
        1 => Just(f64::NAN),
        1 => Just(f64::INFINITY),
        1 => Just(-0.0),
    ]
}

fn finite_f64() -> impl Strategy<Value = f64> + Clone {
    -1e6..1e6f64
}

fn frame_id() -> impl Strategy<Value = String> {
    // Any UTF-8 without NUL, up to 40 characters (multi-byte included).
    proptest::collection::vec(any::<char>().prop_filter("no NUL", |c| *c != '\0'), 0..40)
        .prop_map(|cs| cs.into_iter().collect())
}

fn vector3(x: impl Strategy<Value = f64> + Clone) -> impl Strategy<Value = Vector3> {
    (x.clone(), x.clone(), x).prop_map(|(x, y, z)| Vector3 { x, y, z })
}

fn twist(x: impl Strategy<Value = f64> + Clone) -> impl Strategy<Value = Twist> {
    (vector3(x.clone()), vector3(x)).prop_map(|(linear, angular)| Twist { linear, angular })
}

fn header() -> impl Strategy<Value = Header> {
    (any::<i32>(), any::<u32>(), frame_id()).prop_map(|(sec, nanosec, frame_id)| Header {
        stamp: Time { sec, nanosec },
        frame_id,
    })
}

fn twist_stamped(x: impl Strategy<Value = f64> + Clone) -> impl Strategy<Value = TwistStamped> {
    (header(), twist(x)).prop_map(|(header, twist)| TwistStamped { header, twist })
}

fn covariance(x: impl Strategy<Value = f64> + Clone) -> impl Strategy<Value = [f64; 36]> {
    proptest::collection::vec(x, 36).prop_map(|v| {
        let mut c = [0.0; 36];
        c.copy_from_slice(&v);
        c
    })
}

fn odometry(x: impl Strategy<Value = f64> + Clone) -> impl Strategy<Value = Odometry> {
    (
        header(),
        frame_id(),
        vector3(x.clone()).prop_map(|Vector3 { x, y, z }| Point { x, y, z }),
        (x.clone(), x.clone(), x.clone(), x.clone()),
        covariance(x.clone()),
        twist(x.clone()),
        covariance(x),
    )
        .prop_map(
            |(header, child_frame_id, position, (qx, qy, qz, qw), pc, tw, tc)| Odometry {
                header,
                child_frame_id,
                pose: PoseWithCovariance {
                    pose: Pose {
                        position,
                        orientation: Quaternion {
                            x: qx,
                            y: qy,
                            z: qz,
                            w: qw,
                        },
                    },
                    covariance: pc,
                },
                twist: TwistWithCovariance {
                    twist: tw,
                    covariance: tc,
                },
            },
        )
}

/// Decoding an encoding gives a message that encodes to the same bytes (so
/// every field is bit-identical, NaN payloads included), and every proper
/// prefix is refused as truncated.
fn round_trip<M: RosMessage>(msg: &M) -> Result<(), TestCaseError> {
    let bytes = msg.to_cdr();
    let decoded = M::from_cdr(&bytes).map_err(|e| TestCaseError::fail(e.to_string()))?;
    prop_assert_eq!(decoded.to_cdr(), bytes.clone());
    for cut in 0..bytes.len() {
        let is_truncated = matches!(M::from_cdr(&bytes[..cut]), Err(CdrError::Truncated { .. }));
        prop_assert!(is_truncated, "prefix {}", cut);
    }
    let mut other = bytes;
    other[1] = 0;
    prop_assert_eq!(
        M::from_cdr(&other).err(),
        Some(CdrError::WrongEncapsulation { found: [0, 0] })
    );
    Ok(())
}

proptest! {
    #[test]
    fn twists_round_trip(msg in twist(any_f64())) {
        round_trip(&msg)?;
    }

    #[test]
    fn twist_stampeds_round_trip(msg in twist_stamped(any_f64())) {
        round_trip(&msg)?;
    }

    #[test]
    fn odometries_round_trip(msg in odometry(any_f64())) {
        round_trip(&msg)?;
    }

    #[test]
    fn finite_messages_decode_equal(ts in twist_stamped(finite_f64()), odom in odometry(finite_f64())) {
        prop_assert_eq!(TwistStamped::from_cdr_finite(&ts.to_cdr()), Ok(ts));
        prop_assert_eq!(Odometry::from_cdr_finite(&odom.to_cdr()), Ok(odom));
    }

    #[test]
    fn a_non_finite_number_anywhere_is_reported(
        odom in odometry(finite_f64()),
        slot in any::<prop::sample::Index>(),
        bad in prop_oneof![Just(f64::NAN), Just(f64::INFINITY), Just(f64::NEG_INFINITY)],
    ) {
        let mut odom = odom;
        let mut numbers = numbers_mut(&mut odom);
        let slot = slot.index(numbers.len());
        *numbers[slot] = bad;
        let refused = matches!(Odometry::from_cdr_finite(&odom.to_cdr()), Err(CdrError::NonFinite { .. }));
        prop_assert!(refused);
        prop_assert!(Odometry::from_cdr(&odom.to_cdr()).is_ok());
    }

    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..700)) {
        decode_every_way(&bytes);
    }

    #[test]
    fn bytes_after_a_valid_header_never_panic(body in proptest::collection::vec(any::<u8>(), 0..700)) {
        let mut bytes = vec![0, 1, 0, 0];
        bytes.extend_from_slice(&body);
        decode_every_way(&bytes);
    }

    #[test]
    fn corrupted_encodings_never_panic(
        msg in odometry(finite_f64()),
        flips in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..8),
    ) {
        let mut bytes = msg.to_cdr();
        for (i, b) in flips {
            let i = i.index(bytes.len());
            bytes[i] = b;
        }
        decode_every_way(&bytes);
    }

    #[test]
    fn attachments_round_trip(seq in any::<i64>(), ts in any::<i64>(), gid in any::<[u8; 16]>()) {
        let a = Attachment { sequence_number: seq, source_timestamp_ns: ts, gid };
        let bytes = a.encode();
        prop_assert_eq!(bytes.len(), ATTACHMENT_LEN);
        prop_assert_eq!(Attachment::decode(&bytes), Ok(a));
    }

    #[test]
    fn the_unwrapped_heading_is_continuous(start in -PI..PI, steps in proptest::collection::vec(-3.0..3.0f64, 1..200)) {
        let mut unwrapper = YawUnwrapper::new();
        let mut heading = start;
        let mut last = unwrapper.unwrap(wrap_angle(heading));
        prop_assert!((last - heading).abs() < 1e-9);
        for step in steps {
            heading += step;
            let out = unwrapper.unwrap(Quaternion::from_yaw(heading).yaw());
            // Steps under π are followed exactly: the output is the true heading.
            prop_assert!((out - heading).abs() < 1e-6, "{} vs {}", out, heading);
            prop_assert!((out - last).abs() <= PI + 1e-9);
            last = out;
        }
        prop_assert!(((last - heading) / TAU).round().abs() < 1e-9);
    }

    #[test]
    fn keys_and_tokens_keep_their_shape(
        ns in proptest::collection::vec("[a-z_][a-z0-9_]{0,6}", 0..3),
        topic in proptest::collection::vec("[a-z_][a-z0-9_]{0,6}", 1..3),
        domain in 0u32..233,
        depth in 0u32..100,
        ids in (any::<u64>(), any::<u64>()),
    ) {
        let namespace = format!("/{}", ns.join("/"));
        let fq = fully_qualified_topic(&namespace, &topic.join("/")).map_err(|e| TestCaseError::fail(e.to_string()))?;
        prop_assert!(fq.starts_with('/') && !fq.contains("//"));
        let key = topic_key(KeyScheme::RmwZenoh, domain, &fq, &TWIST_STAMPED);
        prop_assert_eq!(check_topic_key(KeyScheme::RmwZenoh, &key, &TWIST_STAMPED), Ok(()));
        prop_assert!(check_topic_key(KeyScheme::RmwZenoh, &key, &ODOMETRY).is_err());
        prop_assert_eq!(key.split('/').count(), 3 + fq.matches('/').count());
        let node = NodeInfo::new(domain, "1f2e3d", ids.0, &namespace, "echelon_robot")
            .map_err(|e| TestCaseError::fail(e.to_string()))?;
        let token = node.endpoint_token(Endpoint::Publisher, ids.1, &fq, &TWIST_STAMPED, &Qos::keep_last(depth));
        let parts: Vec<&str> = token.split('/').collect();
        // Admin space, domain, zid, node id, entity id, kind, enclave,
        // namespace, node, topic, type, hash, qos: no empty part, names mangled.
        prop_assert_eq!(parts.len(), 13, "{}", token);
        prop_assert!(parts.iter().all(|p| !p.is_empty()), "{}", token);
        prop_assert_eq!(parts[9].replace('%', "/"), fq);
        prop_assert_eq!(parts[7].replace('%', "/"), if ns.is_empty() { "/".to_owned() } else { namespace });
        prop_assert_eq!(node.node_token().split('/').count(), 9);
    }
}
