//! ROS 2 names and the Zenoh key expressions that carry a topic.
//!
//! - `rmw_zenoh` (ROS 2's Zenoh middleware, Jazzy 0.2.x): the data key is
//!   `<domain id>/<fully qualified topic without the leading slash>/<DDS type
//!   name>/<RIHS01 type hash>`, e.g.
//!   `0/robot1/cmd_vel/geometry_msgs::msg::dds_::TwistStamped_/RIHS01_5f0f…`
//!   (`TopicInfo` in rmw_zenoh's `liveliness_utils.cpp`).
//! - `rmw_zenoh_humble` (rmw_zenoh on ROS 2 Humble, which has no type
//!   hashes): the same key with [`HUMBLE_TYPE_HASH`] in the hash's place,
//!   `0/robot1/cmd_vel/geometry_msgs::msg::dds_::TwistStamped_/TypeHashNotSupported`.
//! - `bridge` (zenoh-bridge-ros2dds for a robot left on DDS): the key is the
//!   topic without the leading slash, `robot1/cmd_vel`; no domain, type or
//!   hash (the bridge's own `namespace` setting, if any, is part of the
//!   namespace given here).

use crate::msgs::MessageType;

use crate::names::KeyScheme;
#[cfg(doc)]
use crate::names::fully_qualified_topic;

/// What rmw_zenoh on Humble writes where a type hash stands, in keys and
/// liveliness tokens.
pub const HUMBLE_TYPE_HASH: &str = "TypeHashNotSupported";

/// The type-hash chunk `scheme` writes for `ty` in keys and liveliness
/// tokens (`None`: the scheme's keys carry no type).
pub fn hash_chunk(scheme: KeyScheme, ty: &MessageType) -> Option<&'static str> {
    match scheme {
        KeyScheme::RmwZenoh => Some(ty.hash),
        KeyScheme::RmwZenohHumble => Some(HUMBLE_TYPE_HASH),
        KeyScheme::Bridge => None,
    }
}

/// The key of `fq_topic` (a fully qualified name, see
/// [`fully_qualified_topic`]) carrying messages of type `ty`.
pub fn topic_key(scheme: KeyScheme, domain_id: u32, fq_topic: &str, ty: &MessageType) -> String {
    let topic = fq_topic.trim_matches('/');
    match hash_chunk(scheme, ty) {
        Some(hash) => format!("{domain_id}/{topic}/{}/{hash}", ty.dds_name()),
        None => topic.to_owned(),
    }
}

/// The key to subscribe to for `fq_topic` whatever type is published on it
/// (`<domain>/<topic>/*/*` for rmw_zenoh), so that a publisher of the wrong
/// type is seen, counted and refused ([`check_topic_key`]) rather than
/// silently never heard.
pub fn topic_key_any_type(scheme: KeyScheme, domain_id: u32, fq_topic: &str) -> String {
    let topic = fq_topic.trim_matches('/');
    match scheme {
        KeyScheme::RmwZenoh | KeyScheme::RmwZenohHumble => format!("{domain_id}/{topic}/*/*"),
        KeyScheme::Bridge => topic.to_owned(),
    }
}

/// A sample's key does not carry the expected type.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum KeyMismatch {
    /// Not of the form `<domain>/<topic>/<type>/<hash>`.
    #[error("key `{0}` is not an rmw_zenoh topic key")]
    NotATopicKey(String),
    /// Another message type.
    #[error("type `{found}` on the key, expected `{expected}`")]
    WrongType {
        /// The type on the key.
        found: String,
        /// The expected DDS type name.
        expected: String,
    },
    /// The right type name but another type hash (another ROS distribution
    /// or a changed definition).
    #[error("type hash `{found}` on the key, expected `{expected}`")]
    WrongHash {
        /// The hash on the key.
        found: String,
        /// The expected hash.
        expected: &'static str,
    },
}

/// Checks that an rmw_zenoh sample key names type `ty` with its hash. Under
/// the `bridge` scheme keys carry no type and every key passes.
pub fn check_topic_key(scheme: KeyScheme, key: &str, ty: &MessageType) -> Result<(), KeyMismatch> {
    let Some(expected_hash) = hash_chunk(scheme, ty) else {
        return Ok(());
    };
    let mut parts = key.rsplitn(3, '/');
    // `<domain>/<topic…>/<type>/<hash>`: at least a domain and a topic before the type.
    let (hash, type_name) = match (parts.next(), parts.next(), parts.next()) {
        (Some(h), Some(t), Some(rest)) if rest.contains('/') => (h, t),
        _ => return Err(KeyMismatch::NotATopicKey(key.to_owned())),
    };
    let expected = ty.dds_name();
    if type_name != expected {
        return Err(KeyMismatch::WrongType {
            found: type_name.to_owned(),
            expected,
        });
    }
    if hash != expected_hash {
        return Err(KeyMismatch::WrongHash {
            found: hash.to_owned(),
            expected: expected_hash,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msgs::{ODOMETRY, TWIST, TWIST_STAMPED};

    #[test]
    fn keys_follow_each_scheme() {
        assert_eq!(
            topic_key(KeyScheme::RmwZenoh, 0, "/robot1/cmd_vel", &TWIST_STAMPED),
            "0/robot1/cmd_vel/geometry_msgs::msg::dds_::TwistStamped_/\
             RIHS01_5f0fcd4f81d5d06ad9b4c4c63e3ea51b82d6ae4d0558f1d475229b1121db6f64"
        );
        assert_eq!(
            topic_key(KeyScheme::RmwZenoh, 42, "/cmd_vel", &TWIST),
            "42/cmd_vel/geometry_msgs::msg::dds_::Twist_/\
             RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a"
        );
        assert_eq!(
            topic_key(KeyScheme::Bridge, 0, "/robot1/odom", &ODOMETRY),
            "robot1/odom"
        );
        assert_eq!(
            topic_key_any_type(KeyScheme::RmwZenoh, 3, "/robot1/odom"),
            "3/robot1/odom/*/*"
        );
    }

    #[test]
    fn sample_keys_are_checked_for_type_and_hash() {
        let key = topic_key(KeyScheme::RmwZenoh, 0, "/robot1/odom", &ODOMETRY);
        assert_eq!(
            check_topic_key(KeyScheme::RmwZenoh, &key, &ODOMETRY),
            Ok(())
        );
        assert!(matches!(
            check_topic_key(KeyScheme::RmwZenoh, &key, &TWIST),
            Err(KeyMismatch::WrongType { .. })
        ));
        let other_hash = format!("0/robot1/odom/{}/RIHS01_00", ODOMETRY.dds_name());
        assert!(matches!(
            check_topic_key(KeyScheme::RmwZenoh, &other_hash, &ODOMETRY),
            Err(KeyMismatch::WrongHash { .. })
        ));
        assert!(matches!(
            check_topic_key(KeyScheme::RmwZenoh, "odom", &ODOMETRY),
            Err(KeyMismatch::NotATopicKey(_))
        ));
        assert_eq!(
            check_topic_key(KeyScheme::Bridge, "robot1/odom", &ODOMETRY),
            Ok(())
        );
    }

    /// Humble's keys (rmw_zenoh's humble branch; hiroz's `no-type-hash`):
    /// the type hash's chunk is `TypeHashNotSupported`; a Humble robot's
    /// key is refused under the Jazzy scheme and a Jazzy one under Humble's,
    /// each saying which hash it found.
    #[test]
    fn humble_keys_carry_no_type_hash() {
        let humble = topic_key(
            KeyScheme::RmwZenohHumble,
            0,
            "/robot1/cmd_vel",
            &TWIST_STAMPED,
        );
        assert_eq!(
            humble,
            "0/robot1/cmd_vel/geometry_msgs::msg::dds_::TwistStamped_/TypeHashNotSupported"
        );
        let jazzy = topic_key(KeyScheme::RmwZenoh, 0, "/robot1/cmd_vel", &TWIST_STAMPED);
        for (scheme, key, ok) in [
            (KeyScheme::RmwZenohHumble, &humble, true),
            (KeyScheme::RmwZenoh, &jazzy, true),
            (KeyScheme::RmwZenohHumble, &jazzy, false),
            (KeyScheme::RmwZenoh, &humble, false),
        ] {
            let r = check_topic_key(scheme, key, &TWIST_STAMPED);
            assert_eq!(r.is_ok(), ok, "{scheme:?} {key}: {r:?}");
            if !ok {
                assert!(matches!(r, Err(KeyMismatch::WrongHash { .. })), "{r:?}");
            }
        }
        assert_eq!(
            topic_key_any_type(KeyScheme::RmwZenohHumble, 3, "/robot1/odom"),
            "3/robot1/odom/*/*"
        );
        assert_eq!(hash_chunk(KeyScheme::Bridge, &ODOMETRY), None);
    }
}
