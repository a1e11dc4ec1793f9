//! The ROS 2 messages of a velocity base and their CDR codec: plain data
//! and pure functions, shared by the fleet's ROS 2 link (echelon-fleet
//! re-exports these modules as `echelon_fleet::ros2::{cdr, msgs,
//! definitions}`) and by [`crate::bag`], which reads ROS 2 MCAP bags for
//! `echelon identify` without a network stack.
//!
//! - [`cdr`]: the CDR little-endian codec (4-byte encapsulation header,
//!   alignment after it, padding content ignored).
//! - [`msgs`]: `Twist`, `TwistStamped` and `Odometry` with their RIHS01
//!   type hashes, quaternion yaw and a yaw unwrapper.
//! - [`definitions`]: the full message definitions (`ros2msg` schemas) of
//!   the three messages, as `ros2 bag record -s mcap` stores them.

pub mod cdr;
pub mod definitions;
pub mod msgs;
