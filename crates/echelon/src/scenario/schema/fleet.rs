//! The fleet sections of a scenario file: `[fleet]`, its `ros2` and
//! `link_loss` (also an agent's own `ros2 = { … }`, `link_loss = { … }`).

use serde::{Deserialize, Serialize};

use super::{KeyScheme, LinkPolicy, Placement};

/// `[fleet]`: how the scenario runs as separate processes (`echelon fleet`).
/// Every field is optional; the simulator ignores this section.
#[serde_with::skip_serializing_none]
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct FleetSection {
    /// Fleet name, the second chunk of every key expression (default: the
    /// scenario name).
    pub name: Option<String>,
    /// Reference publication rate, Hz (default 50).
    pub reference_rate: Option<f64>,
    /// Robot controller rate, Hz (default 100).
    pub control_rate: Option<f64>,
    /// How often a robot publishes its state when no other robot reads it
    /// (it is no agent's leader and no agent filters for safety), Hz: for
    /// the log and the live view, which need no more (default: every
    /// controller tick; at most `control_rate`).
    pub state_rate: Option<f64>,
    /// A leader stream is lost when no fresh message arrived for this long, s
    /// (default 0.2).
    pub link_timeout: Option<f64>,
    /// Messages older than this on arrival are dropped as stale, s (default 0.5).
    pub stale_after: Option<f64>,
    /// A supervised run's deadman: robots hold when no operator heartbeat
    /// (`echelon fleet heartbeat`) arrived for this long, s (default: none
    /// asked).
    pub operator_heartbeat: Option<f64>,
    /// Link-loss policy for every agent (an agent's own `link_loss` overrides it).
    pub link_loss: Option<LinkLossSection>,
    /// How robots driven through ROS 2 (`fleet robot --ros2`) are reached, for
    /// every agent (an agent's own `ros2` overrides it field by field).
    pub ros2: Option<Ros2Section>,
    /// Where every agent's robot process runs in a lab fleet: `hub`
    /// (default; started by `fleet up`) or `onboard` (an agent's own
    /// `placement` overrides it).
    pub placement: Option<Placement>,
}

impl FleetSection {
    pub(super) fn is_default(&self) -> bool {
        self == &FleetSection::default()
    }
}

/// `[fleet.ros2]` or an agent's `ros2 = { … }`: where a ROS 2 robot's
/// `cmd_vel` and `odom` are (docs/ros2.md).
#[serde_with::skip_serializing_none]
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Ros2Section {
    /// The robot's namespace; `{k}` is replaced by the agent number
    /// (default `/robot{k}`).
    pub namespace: Option<String>,
    /// ROS domain id, 0–232 (default 0).
    pub domain_id: Option<u32>,
    /// `twist-stamped` (default; `diff_drive_controller` since Jazzy) or `twist`.
    pub cmd_vel_type: Option<CmdVelType>,
    /// What stamps a `TwistStamped` command: `zero` (default) or `now`.
    pub cmd_vel_stamp: Option<CmdVelStamp>,
    /// The velocity command topic, relative to the namespace or absolute
    /// (default `cmd_vel`).
    pub cmd_vel: Option<String>,
    /// The odometry topic (default `odom`).
    pub odom: Option<String>,
    /// The robot's body frame, `cmd_vel`'s `frame_id` and odometry's
    /// `child_frame_id` (default `base_link`, REP 105).
    pub base_frame: Option<String>,
    /// The odometry frame (default `odom`, REP 105).
    pub odom_frame: Option<String>,
    /// `rmw_zenoh` (default: ROS 2's Zenoh middleware) or `bridge`
    /// (zenoh-bridge-ros2dds's plain keys, a robot left on DDS).
    pub key_scheme: Option<KeyScheme>,
    /// Odometry older than this is lost: the robot commands zero, s (default 0.5).
    pub odom_timeout: Option<f64>,
    /// The simulated base (`fleet base --ros2`) stops when no `cmd_vel`
    /// arrived for this long, s (default 0.5, as `diff_drive_controller`'s
    /// `cmd_vel_timeout`).
    pub cmd_vel_timeout: Option<f64>,
    /// The simulated base publishes odometry at this rate, Hz (default 50).
    pub odom_rate: Option<f64>,
    /// `true`: someone else drives this robot (teleop, Nav2); its fleet
    /// robot sends no `cmd_vel` and publishes the robot's motion, read from
    /// its odometry, as the head its followers follow (default false).
    pub driven: Option<bool>,
    /// The base's hazard topic, `irobot_create_msgs/msg/HazardDetectionVector`
    /// (an iRobot Create 3's `hazard_detection`; relative to the namespace
    /// or absolute): a BUMP, CLIFF, STALL or WHEEL_DROP stops the robot and
    /// pauses the fleet until it clears and an operator resumes
    /// (docs/real-robots.md). Default: none.
    pub hazards: Option<String>,
    /// The base's e-stop topic, `std_msgs/msg/Bool`, `true` = stop (a
    /// Jackal's `platform/emergency_stop`): stops the robot and pauses the
    /// fleet like a hazard. Default: none.
    pub estop: Option<String>,
    /// The robot's own Zenoh router (its `rmw_zenohd` or bridge), a Zenoh
    /// endpoint such as `tcp/192.168.1.21:7447` or a list of them (tried in
    /// order); `{k}` is replaced by the agent number. A robot process
    /// driving a real robot reaches it there, in a session of its own
    /// (`fleet up --ros2 --real`; docs/ros2.md).
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
#[serde_with::skip_serializing_none]
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct LinkLossSection {
    /// `stop` or `extrapolate` (default).
    pub policy: Option<LinkPolicy>,
    /// How long `extrapolate` keeps the last speed after the last message, s
    /// (default 1).
    pub hold: Option<f64>,
    /// Peak deceleration of `extrapolate`'s smooth stop, m/s² (default 0.1).
    pub decel: Option<f64>,
}
