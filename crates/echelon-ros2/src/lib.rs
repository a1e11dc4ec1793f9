//! ROS 2 in one room: everything echelon needs to speak to ROS 2 (Jazzy)
//! robots and read their bags, with no ROS installation and no I/O.
//!
//! - [`names`]: ROS names (topics, namespaces, nodes) by `rcl`'s rules and
//!   the [`KeyScheme`] of a link; the scenario parser (crate `echelon`)
//!   refuses a bad `[fleet.ros2]` name with them.
//! - [`cdr`]: the CDR little-endian codec (4-byte encapsulation header,
//!   alignment after it, padding content ignored).
//! - [`msgs`]: the message types (`Twist`, `TwistStamped`, `Odometry` and
//!   what they nest) with their RIHS01 type hashes, quaternion yaw and a
//!   yaw unwrapper.
//! - [`definitions`]: the full message definitions (`ros2msg` schemas), as
//!   `ros2 bag record -s mcap` stores them.
//! - [`keys`]: the topic key expressions of the `rmw_zenoh` and `bridge`
//!   schemes.
//! - [`liveliness`]: rmw_zenoh's liveliness tokens and QoS strings, so that
//!   `ros2 node list` / `ros2 topic list` see echelon.
//! - [`attachment`]: the 33-byte attachment (sequence number, timestamp,
//!   publisher GID) rmw_zenoh subscriptions require.
//!
//! Everything here is plain data and pure functions: the Zenoh session,
//! publishers, subscriptions and tokens belong to the fleet
//! (`echelon_fleet::ros2`: the ROS 2 drive, the simulated base and the
//! recorded topics), and MCAP files to `echelon-mcap`, which reads ROS 2
//! bags with these types for `echelon identify`. This crate depends on no
//! other echelon crate, so the core's scenario parser can use [`names`].
//!
//! Interoperability with real ROS 2 is proven by echelon-fleet's
//! `tests/ros2_*.rs` against the ROS 2 Jazzy Python wheels.

pub mod attachment;
pub mod cdr;
pub mod definitions;
pub mod keys;
pub mod liveliness;
pub mod msgs;
pub mod names;

pub use attachment::{Attachment, AttachmentError, Gid};
pub use cdr::CdrError;
pub use keys::KeyMismatch;
pub use liveliness::{NodeInfo, Qos};
pub use msgs::{MessageType, Odometry, RosMessage, Time, Twist, TwistStamped, YawUnwrapper};
pub use names::{KeyScheme, NameError};
