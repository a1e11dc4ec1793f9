//! Full ROS 2 message definitions, for MCAP schemas of encoding `ros2msg`
//! exactly as `ros2 bag record -s mcap` writes them (rosbag2's
//! `LocalMessageDefinitionSource::get_full_text`): the type's `.msg` file,
//! then, depth first and each type once, every nested type's `.msg` after a
//! separator line of 80 `=` and a `MSG: <pkg>/<Type>` line; dependencies in
//! sorted order of their names as the `.msg` files spell them.
//!
//! The `.msg` files are verbatim copies of ROS 2 Jazzy's (under
//! `definitions/`); echelon-fleet's `tests/ros2_mcap.rs` checks every constant against the
//! text rebuilt from the installed wheels by `scripts/ros2/msg_definitions.py`.

use crate::msgs::{MessageType, ODOMETRY, TWIST, TWIST_STAMPED};

/// One `.msg` file of `definitions/`.
macro_rules! msg {
    ($pkg:literal, $ty:literal) => {
        include_str!(concat!("../msg/", $pkg, "/", $ty, ".msg"))
    };
}

/// The separator rosbag2 writes before a nested type's definition.
macro_rules! sep {
    ($name:literal) => {
        concat!(
            "\n",
            "================================================================================\n",
            "MSG: ",
            $name,
            "\n"
        )
    };
}

/// `geometry_msgs/msg/Twist` and what it nests.
macro_rules! twist_full {
    () => {
        concat!(
            msg!("geometry_msgs", "Twist"),
            sep!("geometry_msgs/Vector3"),
            msg!("geometry_msgs", "Vector3")
        )
    };
}

/// `std_msgs/msg/Header` and what it nests.
macro_rules! header_full {
    () => {
        concat!(
            msg!("std_msgs", "Header"),
            sep!("builtin_interfaces/Time"),
            msg!("builtin_interfaces", "Time")
        )
    };
}

/// The full definition of `geometry_msgs/msg/Twist`.
pub const TWIST_DEFINITION: &str = twist_full!();

/// The full definition of `geometry_msgs/msg/TwistStamped`.
pub const TWIST_STAMPED_DEFINITION: &str = concat!(
    msg!("geometry_msgs", "TwistStamped"),
    sep!("geometry_msgs/Twist"),
    twist_full!(),
    sep!("std_msgs/Header"),
    header_full!()
);

/// The full definition of `nav_msgs/msg/Odometry`.
pub const ODOMETRY_DEFINITION: &str = concat!(
    msg!("nav_msgs", "Odometry"),
    sep!("geometry_msgs/PoseWithCovariance"),
    msg!("geometry_msgs", "PoseWithCovariance"),
    sep!("geometry_msgs/Pose"),
    msg!("geometry_msgs", "Pose"),
    sep!("geometry_msgs/Point"),
    msg!("geometry_msgs", "Point"),
    sep!("geometry_msgs/Quaternion"),
    msg!("geometry_msgs", "Quaternion"),
    sep!("geometry_msgs/TwistWithCovariance"),
    msg!("geometry_msgs", "TwistWithCovariance"),
    sep!("geometry_msgs/Twist"),
    twist_full!(),
    sep!("std_msgs/Header"),
    header_full!()
);

/// The full definition of `ty`, for the message types echelon speaks
/// ([`TWIST`], [`TWIST_STAMPED`], [`ODOMETRY`]); `None` for any other.
pub fn definition(ty: &MessageType) -> Option<&'static str> {
    [
        (TWIST, TWIST_DEFINITION),
        (TWIST_STAMPED, TWIST_STAMPED_DEFINITION),
        (ODOMETRY, ODOMETRY_DEFINITION),
    ]
    .into_iter()
    .find(|(t, _)| t == ty)
    .map(|(_, d)| d)
}

#[cfg(test)]
mod tests {
    use super::*;

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
        for d in [
            TWIST_DEFINITION,
            TWIST_STAMPED_DEFINITION,
            ODOMETRY_DEFINITION,
        ] {
            let separators = d.matches(&format!("\n{}\nMSG: ", "=".repeat(80))).count();
            assert_eq!(separators, nested(d).len());
        }
        assert!(TWIST_STAMPED_DEFINITION.starts_with("# A twist with reference"));
        assert_eq!(definition(&TWIST_STAMPED), Some(TWIST_STAMPED_DEFINITION));
        assert_eq!(definition(&crate::msgs::HEADER), None);
    }
}
