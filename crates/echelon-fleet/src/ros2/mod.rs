//! The ROS 2 wire layer: what a robot running ROS 2 on Zenoh (rmw_zenoh,
//! Jazzy) or behind zenoh-bridge-ros2dds exchanges, with no ROS installation
//! on echelon's side.
//!
//! - [`cdr`] (from echelon-mcap): the CDR little-endian codec (4-byte encapsulation header,
//!   alignment after it, padding content ignored).
//! - [`msgs`] (from echelon-mcap): `Twist`, `TwistStamped` and `Odometry` with their RIHS01
//!   type hashes, quaternion yaw and a yaw unwrapper.
//! - [`keys`]: ROS names and the topic key expressions of the `rmw_zenoh`
//!   and `bridge` schemes.
//! - [`liveliness`]: rmw_zenoh's liveliness tokens and QoS strings, so that
//!   `ros2 node list` / `ros2 topic list` see echelon.
//! - [`attachment`]: the 33-byte attachment (sequence number, timestamp,
//!   publisher GID) rmw_zenoh subscriptions require.
//! - [`definitions`] (from echelon-mcap): the full message definitions (`ros2msg` schemas) of
//!   the three messages, as `ros2 bag record -s mcap` stores them.
//! - [`record`]: the topics the fleet collector records into `fleet.mcap`
//!   as ROS 2 channels, and the checks a sample passes first.
//!
//! Everything here is plain data and pure functions; the Zenoh session, the
//! publishers and the subscriptions belong to the robot and the simulated
//! base. Interoperability with real ROS 2 serialization is proven by
//! `tests/ros2_interop.rs` against the ROS 2 Jazzy Python wheels.

pub mod attachment;
pub mod base;
pub mod drive;
pub mod keys;
pub mod liveliness;
pub mod record;

// Moved to echelon-mcap (pure, no Zenoh) so that `echelon identify` reads
// ROS 2 bags with them; re-exported here under their old paths.
pub use echelon_mcap::ros2::{cdr, definitions, msgs};

pub use attachment::{Attachment, AttachmentError, Gid};
pub use cdr::CdrError;
pub use keys::{KeyMismatch, KeyScheme, NameError};
pub use liveliness::{NodeInfo, Qos};
pub use msgs::{MessageType, Odometry, RosMessage, Time, Twist, TwistStamped, YawUnwrapper};
pub use record::{RosRefusal, RosTopic, RosTopicError};
