//! The odometry sections of a scenario file: `[odometry]` and `[fixes]` (also
//! an agent's own `odometry = { … }`, `fixes = { … }`).

use serde::{Deserialize, Serialize};

use super::{Fusion, PoseSpec, ZetaModel};

/// `[odometry]`: the robot dead-reckons from its wheel encoders (paper section 6)
/// and the controller acts on that estimate. All fields optional.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct OdometrySection {
    /// `false` turns odometry off (for one agent, under a global `[odometry]`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub enabled: Option<bool>,
    /// Encoder sampling period, s (default: `sim.controller_period`, else `sim.dt`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub period: Option<f64>,
    /// Encoder ticks per wheel revolution (default: ideal encoders).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ticks_per_rev: Option<u32>,
    /// The paper's additive error `ζ`, m per sample (eq. 23; default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub zeta: Option<f64>,
    /// `wheels` (eq. 23, default) or `worst-case` (eq. 31).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub zeta_model: Option<ZetaModel>,
    /// Borenstein's `E_d = D_R/D_L` (default 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wheel_diameter_ratio: Option<f64>,
    /// Borenstein's `E_b = b_actual/b_nominal` (default 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wheelbase_ratio: Option<f64>,
    /// Slip: variance of each wheel's displacement per metre travelled, m²/m (default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub slip: Option<f64>,
    /// Standard deviation of the measured linear speed, m/s (default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub speed_noise: Option<f64>,
    /// Standard deviation of the measured angular speed, rad/s (default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub turn_rate_noise: Option<f64>,
}

/// `[fixes]`: absolute position fixes. All fields optional, but exactly one of
/// `every_steps` and `period` is needed.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct FixesSection {
    /// `false` turns fixes off (for one agent, under a global `[fixes]`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub enabled: Option<bool>,
    /// A fix every `N` odometry samples (the paper's `N`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub every_steps: Option<u64>,
    /// A fix every `T` seconds (a whole number of odometry samples).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub period: Option<f64>,
    /// Standard deviation of each fixed coordinate, m (default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub position_noise: Option<f64>,
    /// Standard deviation of the fixed heading, rad (absent: fixes carry no heading).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub heading_noise: Option<f64>,
    /// Delay from taking a fix to the robot using it, s (default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub latency: Option<f64>,
    /// `reset` (the paper, default) or `ekf`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fusion: Option<Fusion>,
    /// Fleet (`fleet robot --ros2`): the ROS 2 topic the fixes arrive on,
    /// relative to the robot's namespace or absolute (absent: the fleet
    /// takes no fixes; the simulator ignores it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source: Option<String>,
    /// Fleet: the fix messages' type, `pose-stamped` (default; motion
    /// capture) or `pose-with-covariance-stamped` (AMCL's `amcl_pose`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub message: Option<FixMessage>,
    /// Fleet: the fixes' `header.frame_id` (default `map`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frame: Option<String>,
    /// Fleet: the pose of the fixes' frame in the world (default: the
    /// world itself).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frame_origin: Option<PoseSpec>,
    /// Fleet: fixes missing for longer than this are reported, s (default:
    /// three fix periods); the robot carries on on odometry.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub timeout: Option<f64>,
    /// Fleet: the formation tolerance, m: the robot computes the fix
    /// interval Theorem 2 requires for it and warns when fixes come slower.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tolerance: Option<f64>,
    /// Fleet: refuse fixes whose Mahalanobis distance from the estimate is
    /// implausible (chi-square 99.9 %; default true).
    #[serde(default, skip_serializing_if = "Option::is_none")]
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
