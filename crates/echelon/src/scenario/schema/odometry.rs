//! The odometry sections of a scenario file: `[odometry]` and `[fixes]` (also
//! an agent's own `odometry = { … }`, `fixes = { … }`).

use serde::{Deserialize, Serialize};

use super::{Fusion, PoseSpec, ZetaModel};

/// `[odometry]`: the robot dead-reckons from its wheel encoders (paper section 6)
/// and the controller acts on that estimate. All fields optional.
#[serde_with::skip_serializing_none]
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct OdometrySection {
    /// `false` turns odometry off (for one agent, under a global `[odometry]`).
    pub enabled: Option<bool>,
    /// Encoder sampling period, s (default: `sim.controller_period`, else `sim.dt`).
    pub period: Option<f64>,
    /// Encoder ticks per wheel revolution (default: ideal encoders).
    pub ticks_per_rev: Option<u32>,
    /// The paper's additive error `ζ`, m per sample (eq. 23; default 0).
    pub zeta: Option<f64>,
    /// `wheels` (eq. 23, default) or `worst-case` (eq. 31).
    pub zeta_model: Option<ZetaModel>,
    /// Borenstein's `E_d = D_R/D_L` (default 1).
    pub wheel_diameter_ratio: Option<f64>,
    /// Borenstein's `E_b = b_actual/b_nominal` (default 1).
    pub wheelbase_ratio: Option<f64>,
    /// Slip: variance of each wheel's displacement per metre travelled, m²/m (default 0).
    pub slip: Option<f64>,
    /// Standard deviation of the measured linear speed, m/s (default 0).
    pub speed_noise: Option<f64>,
    /// Standard deviation of the measured angular speed, rad/s (default 0).
    pub turn_rate_noise: Option<f64>,
}

/// `[fixes]`: absolute position fixes. All fields optional, but exactly one of
/// `every_steps` and `period` is needed.
#[serde_with::skip_serializing_none]
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct FixesSection {
    /// `false` turns fixes off (for one agent, under a global `[fixes]`).
    pub enabled: Option<bool>,
    /// A fix every `N` odometry samples (the paper's `N`).
    pub every_steps: Option<u64>,
    /// A fix every `T` seconds (a whole number of odometry samples).
    pub period: Option<f64>,
    /// Standard deviation of each fixed coordinate, m (default 0).
    pub position_noise: Option<f64>,
    /// Standard deviation of the fixed heading, rad (absent: fixes carry no heading).
    pub heading_noise: Option<f64>,
    /// Delay from taking a fix to the robot using it, s (default 0).
    pub latency: Option<f64>,
    /// `reset` (the paper, default) or `ekf`.
    pub fusion: Option<Fusion>,
    /// Fleet (`fleet robot --ros2`): the ROS 2 topic the fixes arrive on,
    /// relative to the robot's namespace or absolute (absent: the fleet
    /// takes no fixes; the simulator ignores it).
    pub source: Option<String>,
    /// Fleet: the fix messages' type, `pose-stamped` (default; motion
    /// capture) or `pose-with-covariance-stamped` (AMCL's `amcl_pose`).
    pub message: Option<FixMessage>,
    /// Fleet: the fixes' `header.frame_id` (default `map`).
    pub frame: Option<String>,
    /// Fleet: the pose of the fixes' frame in the world (default: the
    /// world itself).
    pub frame_origin: Option<PoseSpec>,
    /// Fleet: fixes missing for longer than this are reported, s (default:
    /// three fix periods); the robot carries on on odometry.
    pub timeout: Option<f64>,
    /// Fleet: the formation tolerance, m: the robot computes the fix
    /// interval Theorem 2 requires for it and warns when fixes come slower.
    pub tolerance: Option<f64>,
    /// Fleet: refuse fixes whose Mahalanobis distance from the estimate is
    /// implausible (chi-square 99.9 %; default true).
    pub gate: Option<bool>,
}

/// The message type of absolute fixes taken from ROS 2.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "kebab-case")]
pub enum FixMessage {
    /// `geometry_msgs/msg/PoseStamped` (mocap4ros2, vrpn_mocap): the
    /// uncertainty is the fixes' `position_noise`/`heading_noise`.
    #[default]
    PoseStamped,
    /// `geometry_msgs/msg/PoseWithCovarianceStamped` (AMCL's `amcl_pose`):
    /// the uncertainty is the message's covariance.
    PoseWithCovarianceStamped,
}
