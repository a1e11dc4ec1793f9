//! The scenario file format (TOML). Units are SI and angles radians; a field may
//! take degrees only if its name ends in `_deg`. Unknown fields are errors.

use std::collections::BTreeMap;
use std::fmt;

use serde::de::{self, Visitor};
use serde::{Deserialize, Deserializer, Serialize, Serializer};

pub use super::fleet::LinkPolicy;
pub use crate::base::AccelLimit;
pub use crate::control::{Law, Variant};
pub use crate::lycomp::{LyComp, LyDerivatives};
pub use crate::odometry::{Fusion, ZetaModel};
pub use echelon_ros2::KeyScheme;

/// A whole scenario file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ScenarioFile {
    /// Short name (defaults to the file name).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// One line saying what the scenario shows.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub description: Option<String>,
    /// Integration settings.
    pub sim: SimSection,
    /// Logging settings.
    #[serde(default, skip_serializing_if = "LogSection::is_default")]
    pub log: LogSection,
    /// Controller defaults for every agent.
    #[serde(default, skip_serializing_if = "ControlSection::is_empty")]
    pub control: ControlSection,
    /// Robot definitions by name, in addition to the presets `agent1`, `agent2`.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub robots: BTreeMap<String, RobotSection>,
    /// The virtual leader's trajectory.
    pub reference: ReferenceSection,
    /// The robots of the formation, numbered from 1 in this order.
    pub agents: Vec<AgentSection>,
    /// Seed of every random model (odometry noise, slip, fixes); default 0.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// Odometry for every agent (an agent's `odometry` overrides field by field).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub odometry: Option<OdometrySection>,
    /// Absolute position fixes for every agent (an agent's `fixes` overrides).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fixes: Option<FixesSection>,
    /// Settings for running the scenario as a networked fleet (`echelon fleet`).
    #[serde(default, skip_serializing_if = "FleetSection::is_default")]
    pub fleet: FleetSection,
    /// Barrier-certificate safety filter for every agent (`docs/safety.md`;
    /// an agent's `safety` overrides `enabled`, `gain`, `range`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub safety: Option<SafetySection>,
}

/// `[safety]` or an agent's `safety = { … }`: keep each robot's point `L`
/// ahead at least `radius` from the others' and from obstacles' edges.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SafetySection {
    /// `false` turns the filter off (for one agent, under `[safety]`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub enabled: Option<bool>,
    /// Smallest distance between two robots' points `L` ahead, and a
    /// point's clearance from an obstacle's edge, m (`[safety]` only; required).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radius: Option<f64>,
    /// `γ`, 1/s (default 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gain: Option<f64>,
    /// Sensing range: robots whose point is farther are ignored, m (default:
    /// every robot).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub range: Option<f64>,
    /// Static disc obstacles (`[safety]` only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub obstacles: Option<Vec<ObstacleSpec>>,
}

/// A disc obstacle `{ x, y, r }`, m.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ObstacleSpec {
    /// Centre, m.
    pub x: f64,
    /// Centre, m.
    pub y: f64,
    /// Radius, m.
    pub r: f64,
}

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

/// `[fleet]`: how the scenario runs as separate processes (`echelon fleet`).
/// Every field is optional; the simulator ignores this section.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct FleetSection {
    /// Fleet name, the second chunk of every key expression (default: the
    /// scenario name).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// Reference publication rate, Hz (default 50).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference_rate: Option<f64>,
    /// Robot controller rate, Hz (default 100).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub control_rate: Option<f64>,
    /// A leader stream is lost when no fresh message arrived for this long, s
    /// (default 0.2).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link_timeout: Option<f64>,
    /// Messages older than this on arrival are dropped as stale, s (default 0.5).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stale_after: Option<f64>,
    /// Link-loss policy for every agent (an agent's own `link_loss` overrides it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link_loss: Option<LinkLossSection>,
    /// How robots driven through ROS 2 (`fleet robot --ros2`) are reached, for
    /// every agent (an agent's own `ros2` overrides it field by field).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ros2: Option<Ros2Section>,
}

impl FleetSection {
    fn is_default(&self) -> bool {
        self == &FleetSection::default()
    }
}

/// `[fleet.ros2]` or an agent's `ros2 = { … }`: where a ROS 2 robot's
/// `cmd_vel` and `odom` are (docs/ros2.md).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Ros2Section {
    /// The robot's namespace; `{k}` is replaced by the agent number
    /// (default `/robot{k}`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub namespace: Option<String>,
    /// ROS domain id, 0–232 (default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub domain_id: Option<u32>,
    /// `twist-stamped` (default; `diff_drive_controller` since Jazzy) or `twist`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cmd_vel_type: Option<CmdVelType>,
    /// What stamps a `TwistStamped` command: `zero` (default) or `now`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cmd_vel_stamp: Option<CmdVelStamp>,
    /// The velocity command topic, relative to the namespace or absolute
    /// (default `cmd_vel`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cmd_vel: Option<String>,
    /// The odometry topic (default `odom`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub odom: Option<String>,
    /// The robot's body frame, `cmd_vel`'s `frame_id` and odometry's
    /// `child_frame_id` (default `base_link`, REP 105).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub base_frame: Option<String>,
    /// The odometry frame (default `odom`, REP 105).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub odom_frame: Option<String>,
    /// `rmw_zenoh` (default: ROS 2's Zenoh middleware) or `bridge`
    /// (zenoh-bridge-ros2dds's plain keys, a robot left on DDS).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub key_scheme: Option<KeyScheme>,
    /// Odometry older than this is lost: the robot commands zero, s (default 0.5).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub odom_timeout: Option<f64>,
    /// The simulated base (`fleet base --ros2`) stops when no `cmd_vel`
    /// arrived for this long, s (default 0.5, as `diff_drive_controller`'s
    /// `cmd_vel_timeout`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cmd_vel_timeout: Option<f64>,
    /// The simulated base publishes odometry at this rate, Hz (default 50).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub odom_rate: Option<f64>,
    /// `true`: someone else drives this robot (teleop, Nav2); its fleet
    /// robot sends no `cmd_vel` and publishes the robot's motion, read from
    /// its odometry, as the head its followers follow (default false).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub driven: Option<bool>,
    /// The robot's own Zenoh router (its `rmw_zenohd` or bridge), a Zenoh
    /// endpoint such as `tcp/192.168.1.21:7447` or a list of them (tried in
    /// order); `{k}` is replaced by the agent number. A robot process
    /// driving a real robot reaches it there, in a session of its own
    /// (`fleet up --ros2 --real`; docs/ros2.md).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub connect: Option<Endpoints>,
}

/// One Zenoh endpoint or a list of them.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(untagged)]
pub enum Endpoints {
    /// One endpoint, `tcp/192.168.1.21:7447`.
    One(String),
    /// Several, tried in order.
    Many(Vec<String>),
}

impl Endpoints {
    /// The endpoints, in order.
    pub fn to_vec(&self) -> Vec<String> {
        match self {
            Endpoints::One(e) => vec![e.clone()],
            Endpoints::Many(v) => v.clone(),
        }
    }
}

/// The `cmd_vel` message type.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "kebab-case")]
pub enum CmdVelType {
    /// `geometry_msgs/msg/TwistStamped` (what `diff_drive_controller` takes
    /// since Jazzy).
    #[default]
    TwistStamped,
    /// `geometry_msgs/msg/Twist`.
    Twist,
}

/// The stamp of a `TwistStamped` command.
///
/// `diff_drive_controller` (Humble and Jazzy alike) drops a stamped command
/// whose stamp is older than its `cmd_vel_timeout` by the controller's own
/// clock, and takes a zero stamp as "now" (its `cmd_vel` callback replaces
/// it with `get_node()->now()`). A wall-clock stamp therefore stops a robot
/// whose clock is not synchronised with this machine's, or that runs on
/// `use_sim_time`.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "kebab-case")]
pub enum CmdVelStamp {
    /// A zero stamp: the controller takes the command as received now.
    /// Works whatever the robot's clock.
    #[default]
    Zero,
    /// This machine's wall clock at sending: for robots whose clocks are
    /// synchronised (chrony/NTP/PTP) and logs that want send times.
    Now,
}

/// `[fleet.link_loss]` or an agent's `link_loss = { … }`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct LinkLossSection {
    /// `stop` or `extrapolate` (default).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub policy: Option<LinkPolicy>,
    /// How long `extrapolate` keeps the last speed after the last message, s
    /// (default 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hold: Option<f64>,
    /// Peak deceleration of `extrapolate`'s smooth stop, m/s² (default 0.1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub decel: Option<f64>,
}

/// `[sim]`: how long and how finely to integrate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SimSection {
    /// Simulated time, s.
    pub duration: f64,
    /// RK4 step, s.
    pub dt: f64,
    /// Sampled controller with zero-order hold at this period, s (a multiple of
    /// `dt`). Absent: continuous-time controller, evaluated in every RK4 stage.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub controller_period: Option<f64>,
    /// The divergence guard's bounds on every robot's state (default
    /// `|v| ≤ 100 m/s`, `|ω| ≤ 100 rad/s`, `‖(x, y)‖ ≤ 1e6 m`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bounds: Option<BoundsSpec>,
}

/// `[sim] bounds = { speed, turn_rate, distance }`: the divergence guard
/// ([`crate::guard::Bounds`]); each field optional.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct BoundsSpec {
    /// Largest `|v|`, m/s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub speed: Option<f64>,
    /// Largest `|ω|`, rad/s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub turn_rate: Option<f64>,
    /// Largest distance from the world origin, m.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub distance: Option<f64>,
}

/// `[log]`: what goes to `trajectory.csv`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct LogSection {
    /// Logging period, s (0: every step; default 0.01).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dt: Option<f64>,
}

impl LogSection {
    fn is_default(&self) -> bool {
        self == &LogSection::default()
    }
}

/// `[control]` (defaults for all agents) or an agent's `control` (overrides).
/// Every field is optional; unset fields fall back to `[control]`, then to the
/// paper's values.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ControlSection {
    /// `paper` (default for torque-driven robots), `complete`, or `kinematic`
    /// (the only law of a velocity base, and its default).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub law: Option<Law>,
    /// `K_e` (default 1.5).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ke: Option<f64>,
    /// `K_z` (default 10).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kz: Option<f64>,
    /// `L`, m (default 0.05).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub l: Option<f64>,
    /// `exact`, `fit` (default) or `none`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lycomp: Option<LyComp>,
    /// `neglect` (default) or `exact`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ly_derivatives: Option<LyDerivatives>,
}

impl ControlSection {
    fn is_empty(&self) -> bool {
        self == &ControlSection::default()
    }
}

/// How a `[robots.NAME]` is driven.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum DriveName {
    /// Wheel torques: the paper's plant (eq. 3).
    Torque,
    /// A velocity-controlled base (`crate::base`).
    Velocity,
}

/// `[robots.NAME]`: a robot's parameters, optionally starting from a preset.
/// A torque-driven robot (the default) takes the fields from `mass` to
/// `torque_limit`; a velocity base (`drive = "velocity"`) takes `tau_v` to
/// `accel`; both take the wheel geometry.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RobotSection {
    /// `torque` (default; `velocity` when `preset` names a velocity base).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub drive: Option<DriveName>,
    /// Start from this preset (`agent1`, `agent2`; velocity bases: `ideal`,
    /// `turtlebot3-burger`, `turtlebot4`, `jackal`) and override the fields given.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub preset: Option<String>,
    /// Speed lag `τ_v`, s (velocity base; 0: ideal).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tau_v: Option<f64>,
    /// Turn-rate lag `τ_ω`, s (velocity base; 0: ideal).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tau_omega: Option<f64>,
    /// Largest `|v|`, m/s (velocity base; absent: unlimited).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub v_max: Option<f64>,
    /// Largest `|ω|`, rad/s (velocity base; absent: unlimited).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub omega_max: Option<f64>,
    /// Largest `|v̇|`, m/s² (velocity base with `tau_v > 0`; absent: unlimited).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub a_max: Option<f64>,
    /// Largest `|ω̇|`, rad/s² (velocity base with `tau_omega > 0`; absent: unlimited).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub alpha_max: Option<f64>,
    /// `joint` (default: keeps the path) or `per-axis` acceleration limits.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub accel: Option<AccelLimit>,
    /// `m`, kg.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mass: Option<f64>,
    /// `η`, kg/s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub linear_friction: Option<f64>,
    /// `J`, kg m².
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub inertia: Option<f64>,
    /// `ψ`, kg m²/s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub angular_friction: Option<f64>,
    /// `l` (half the wheel separation), m.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub half_wheelbase: Option<f64>,
    /// `r`, m.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wheel_radius: Option<f64>,
    /// Per-wheel torque limit, N m (absent: unlimited).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub torque_limit: Option<f64>,
}

/// A pose, optionally with initial speeds. Exactly one of `theta` (rad) and
/// `theta_deg` (degrees).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PoseSpec {
    /// x, m.
    pub x: f64,
    /// y, m.
    pub y: f64,
    /// Heading, rad.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub theta: Option<f64>,
    /// Heading, degrees.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub theta_deg: Option<f64>,
    /// Initial linear speed, m/s (default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub v: Option<f64>,
    /// Initial angular speed, rad/s (default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub omega: Option<f64>,
}

/// `[reference.KIND]`: the virtual leader's trajectory.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub enum ReferenceSection {
    /// Eq. 18: constant speed and turn rate from a start pose.
    Circle {
        /// `V_d`, m/s.
        speed: f64,
        /// `ω_d`, rad/s.
        turn_rate: f64,
        /// Start pose (speeds not allowed).
        start: PoseSpec,
    },
    /// A straight line at constant speed from a start pose.
    Line {
        /// `V_d`, m/s.
        speed: f64,
        /// Start pose (speeds not allowed).
        start: PoseSpec,
    },
    /// Eq. 19.
    Lemniscate {
        /// Half-width `a`, m.
        a: f64,
        /// Rate `c`, rad/s.
        c: f64,
        /// Centre `[x, y]`, m (default origin).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        center: Option<[f64; 2]>,
    },
    /// Eqs. 17/20: the non-feasible cubic.
    Cubic {
        /// Scale `s`, m/s³ (eq. 20: 0.0625).
        scale: f64,
        /// Switch time `t₀`, s (eq. 20: 4).
        t_switch: f64,
    },
    /// Timed waypoints through a septic spline (C³ over all time, C⁶ between
    /// waypoints), at rest at the first and last.
    Waypoints {
        /// `[[t, x, y], …]` in s and m.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        points: Option<Vec<[f64; 3]>>,
        /// A CSV file with header `t,x,y`, relative to the scenario file.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        file: Option<String>,
    },
}

/// `[[agents]]`: one robot of the formation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct AgentSection {
    /// Display name (default `agent K`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// A preset (`agent1`, `agent2`) or a `[robots.NAME]` (default `agent1`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub robot: Option<String>,
    /// Initial pose and speeds.
    pub start: PoseSpec,
    /// `"reference"` or the number of the agent it follows.
    #[schemars(with = "serde_json::Value")]
    pub leader: LeaderSpec,
    /// `formation` (default: hold the leader at `offset`) or `tracking`
    /// (pure tracking, eqs. 14–16: no offset).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mode: Option<ModeName>,
    /// `(L_Xoff, L_Yoff)`, m: where the follower holds its leader (formation mode).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub offset: Option<OffsetSpec>,
    /// Controller settings for this agent only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub control: Option<ControlSection>,
    /// The largest `|v̇|` its act step lets the law ask, m/s².
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_accel: Option<f64>,
    /// Odometry settings for this agent (over `[odometry]`, field by field).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub odometry: Option<OdometrySection>,
    /// Fix settings for this agent (over `[fixes]`, field by field).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fixes: Option<FixesSection>,
    /// This agent's link-loss policy in a fleet (overrides `[fleet.link_loss]`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link_loss: Option<LinkLossSection>,
    /// This agent's ROS 2 robot (overrides `[fleet.ros2]` field by field).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ros2: Option<Ros2Section>,
    /// Where its robot's odometry frame (`odom`, REP 105) lies in the world:
    /// the robot's world pose when its odometry started (power-on). Default:
    /// its `start` pose (a robot placed on its start mark at power-on).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub odom_origin: Option<PoseSpec>,
    /// This agent's safety filter (over `[safety]`: `enabled`, `gain`, `range`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub safety: Option<SafetySection>,
}

/// What an agent's controller does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum ModeName {
    /// Leader-follower at an offset (eq. 13).
    Formation,
    /// Pure tracking of the leader's position (eqs. 14–16).
    Tracking,
}

/// `(L_Xoff, L_Yoff)`: the leader is `L_Xoff + L` ahead and `L_Yoff + L_Ycomp`
/// to the left of the follower, in the follower's frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct OffsetSpec {
    /// `L_Xoff`, m.
    pub x: f64,
    /// `L_Yoff`, m.
    pub y: f64,
}

/// An agent's leader: `"reference"` or an agent number (from 1).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LeaderSpec {
    /// The virtual leader.
    Reference,
    /// Agent number (1-based).
    Agent(i64),
}

impl Serialize for LeaderSpec {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            LeaderSpec::Reference => s.serialize_str("reference"),
            LeaderSpec::Agent(k) => s.serialize_i64(*k),
        }
    }
}

impl<'de> Deserialize<'de> for LeaderSpec {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl Visitor<'_> for V {
            type Value = LeaderSpec;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("\"reference\" or the number of an agent (counting from 1)")
            }
            fn visit_str<E: de::Error>(self, v: &str) -> Result<LeaderSpec, E> {
                if v == "reference" {
                    Ok(LeaderSpec::Reference)
                } else {
                    Err(E::invalid_value(de::Unexpected::Str(v), &self))
                }
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<LeaderSpec, E> {
                Ok(LeaderSpec::Agent(v))
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<LeaderSpec, E> {
                i64::try_from(v)
                    .map(LeaderSpec::Agent)
                    .map_err(|_| E::invalid_value(de::Unexpected::Unsigned(v), &self))
            }
        }
        d.deserialize_any(V)
    }
}
