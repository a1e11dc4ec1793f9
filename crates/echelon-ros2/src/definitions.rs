//! Full ROS 2 message definitions, for MCAP schemas of encoding `ros2msg`
//! exactly as `ros2 bag record -s mcap` writes them (rosbag2's
//! `LocalMessageDefinitionSource::get_full_text`): the type's `.msg` file,
//! then, depth first and each type once, every nested type's `.msg` after a
//! separator line of 80 `=` and a `MSG: <pkg>/<Type>` line; dependencies in
//! sorted order of their names.
//!
//! `build.rs` generates them from the `.msg` files under `msg/` (verbatim
//! copies of ROS 2 Jazzy's) for the types a topic carries; echelon-fleet's
//! `tests/ros2_mcap.rs` checks every constant against the text rebuilt from
//! the installed wheels by `scripts/ros2/msg_definitions.py`.

use crate::msgs::MessageType;

include!(concat!(env!("OUT_DIR"), "/definitions.rs"));

/// The full definition of `ty`, for the message types a topic carries
/// ([`TOPIC_TYPES`]: `Twist`, `TwistStamped`, `Odometry`, `PoseStamped`,
/// `PoseWithCovarianceStamped`); `None` for any other.
pub fn definition(ty: &MessageType) -> Option<&'static str> {
    TOPIC_TYPES.iter().find(|(t, _)| t == ty).map(|&(_, d)| d)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msgs::{HEADER, POSE, POSE_WITH_COVARIANCE_STAMPED, TWIST_STAMPED};

    /// The `MSG:` lines of a definition, in order.
    fn nested(definition: &str) -> Vec<&str> {
        definition
            .lines()
            .filter_map(|l| l.strip_prefix("MSG: "))
            .collect()
    }

    #[test]
    fn each_nested_type_appears_once_after_a_separator() {
        assert_eq!(nested(TWIST_DEFINITION), ["geometry_msgs/Vector3"]);
        assert_eq!(
            nested(TWIST_STAMPED_DEFINITION),
            [
                "geometry_msgs/Twist",
                "geometry_msgs/Vector3",
                "std_msgs/Header",
                "builtin_interfaces/Time"
            ]
        );
        assert_eq!(nested(ODOMETRY_DEFINITION).len(), 9);
        assert_eq!(
            nested(POSE_STAMPED_DEFINITION),
            [
                "geometry_msgs/Pose",
                "geometry_msgs/Point",
                "geometry_msgs/Quaternion",
                "std_msgs/Header",
                "builtin_interfaces/Time"
            ]
        );
        assert_eq!(
            nested(POSE_WITH_COVARIANCE_STAMPED_DEFINITION),
            [
                "geometry_msgs/PoseWithCovariance",
                "geometry_msgs/Pose",
                "geometry_msgs/Point",
                "geometry_msgs/Quaternion",
                "std_msgs/Header",
                "builtin_interfaces/Time"
            ]
        );
        for d in [
            TWIST_DEFINITION,
            TWIST_STAMPED_DEFINITION,
            ODOMETRY_DEFINITION,
            POSE_STAMPED_DEFINITION,
            POSE_WITH_COVARIANCE_STAMPED_DEFINITION,
        ] {
            let separators = d.matches(&format!("\n{}\nMSG: ", "=".repeat(80))).count();
            assert_eq!(separators, nested(d).len());
        }
        assert!(TWIST_STAMPED_DEFINITION.starts_with("# A twist with reference"));
        assert_eq!(definition(&TWIST_STAMPED), Some(TWIST_STAMPED_DEFINITION));
        assert_eq!(
            definition(&POSE_WITH_COVARIANCE_STAMPED),
            Some(POSE_WITH_COVARIANCE_STAMPED_DEFINITION)
        );
        assert_eq!(definition(&HEADER), None);
        assert_eq!(definition(&POSE), None);
    }
}
