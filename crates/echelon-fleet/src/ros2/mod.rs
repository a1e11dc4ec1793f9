//! The fleet's ROS 2 side: a fleet robot driving a ROS 2 base, a simulated
//! ROS 2 base, and the ROS 2 topics the collector records. The protocol
//! itself (names, messages, CDR, keys, liveliness tokens, attachments) is
//! the sans-IO crate `echelon_ros2`; what is here adds the fleet's plant,
//! processes, Zenoh session and MCAP log to it.
//!
//! - [`drive`]: [`drive::Ros2Drive`], a fleet [`crate::plant::Plant`] that
//!   reads odometry and sends `cmd_vel`.
//! - [`drift`]: the position uncertainty `σ` of a robot on odometry alone.
//! - [`fixes`]: absolute fixes from ROS 2 poses fused with the odometry,
//!   and Theorem 2 in the loop.
//! - [`sim_base`]: a simulated ROS 2 velocity base (sans-IO), answering
//!   `cmd_vel` with odometry; [`base`]: it as a process (`echelon fleet
//!   base`).
//! - [`graph`]: the robot's ROS 2 graph (its `cmd_vel` subscriber's type,
//!   its `odom` publisher) checked before anything moves.
//! - [`hazard`]: the base's own safety words (a Create 3's hazards, an
//!   e-stop), which stop the robot and pause the fleet.
//! - [`record`]: the topics the fleet collector records into `fleet.mcap`
//!   as ROS 2 channels, and the checks a sample passes first.
//! - [`refusal`]: why a ROS 2 sample was refused, for all of them.
//! - [`ground_truth_topic`]: where a simulated base publishes its ground truth.
//! - [`declare_tokens`]: rmw_zenoh liveliness tokens declared on a session.
//!
//! Interoperability with real ROS 2 is proven by `tests/ros2_*.rs` against
//! the ROS 2 Jazzy Python wheels and an independent Zenoh peer.

pub mod base;
pub mod drift;
pub mod drive;
pub mod endpoint;
pub mod fixes;
pub mod graph;
pub mod hazard;
pub mod record;
pub mod refusal;
pub mod sim_base;

pub use record::{RosRefusal, RosTopic, RosTopicError};

use echelon::scenario::Ros2Link;

/// A simulated base's ground-truth topic in `namespace`.
pub fn ground_truth_topic(link: &Ros2Link) -> String {
    // The namespace is canonical and `ground_truth` a valid relative name.
    echelon_ros2::names::fully_qualified_topic(&link.namespace, "ground_truth")
        .unwrap_or_else(|_| format!("{}/ground_truth", link.namespace.trim_end_matches('/')))
}

/// Declares each of `tokens` on `session`; they live as long as the returned
/// handles.
pub fn declare_tokens(
    session: &zenoh::Session,
    tokens: &[String],
) -> Result<Vec<zenoh::liveliness::LivelinessToken>, crate::FleetError> {
    use zenoh::Wait;
    tokens
        .iter()
        .map(|t| {
            session
                .liveliness()
                .declare_token(t.clone())
                .wait()
                .map_err(|e| crate::FleetError::Zenoh(format!("liveliness {t}: {e}")))
        })
        .collect()
}
