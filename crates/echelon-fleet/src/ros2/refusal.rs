//! Why a ROS 2 sample was refused: one type for the drive's odometry, the
//! simulated base's `cmd_vel` and the fixes' poses.

use echelon_ros2::CdrError;

/// Why a ROS 2 sample was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SampleRefusal {
    /// The key carries another type or hash.
    #[error("wrong type on the key: {0}")]
    WrongType(String),
    /// Not CDR of the expected type.
    #[error("malformed CDR: {0}")]
    Malformed(CdrError),
    /// A NaN or an infinity.
    #[error("non-finite {0}")]
    NonFinite(&'static str),
    /// No usable orientation: a quaternion that is not a rotation (all
    /// zero, or a squared norm beyond tf2's tolerance of 1:
    /// [`echelon_ros2::msgs::Quaternion::checked_yaw`]).
    #[error("no usable orientation: not a unit quaternion (tf2's tolerance)")]
    Orientation,
    /// Frames other than configured.
    #[error("frames `{0}` → `{1}`, expected the configured ones")]
    WrongFrames(String, String),
    /// rmw_zenoh subscribers drop a sample without its attachment.
    #[error("no valid rmw_zenoh attachment")]
    NoAttachment,
    /// A stamped command older than `cmd_vel_timeout` by the receiver's
    /// clock (`diff_drive_controller` drops these).
    #[error("stamped {age:.3} s ago by the receiver's clock, beyond cmd_vel_timeout {timeout} s")]
    Stale {
        /// The command's age by the receiver's clock, s.
        age: f64,
        /// The timeout, s.
        timeout: f64,
    },
}

impl From<CdrError> for SampleRefusal {
    /// A non-finite field is [`SampleRefusal::NonFinite`]; any other CDR
    /// error is [`SampleRefusal::Malformed`].
    fn from(e: CdrError) -> Self {
        match e {
            CdrError::NonFinite { field } => Self::NonFinite(field),
            e => Self::Malformed(e),
        }
    }
}
