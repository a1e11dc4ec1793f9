//! The `[fleet]` section resolved: what `echelon fleet` needs beyond the
//! simulation (fleet name, rates, link-loss policies).

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::locate::FieldPath;
use super::plausible::{self, Part};
use super::schema::{CmdVelStamp, CmdVelType, FixMessage, FixesSection, Ros2Section};
use super::{Merge, Scenario};
use crate::check;
use crate::error::ScenarioError;
use crate::model::Pose;
use echelon_ros2::names::{self as ros_names, KeyScheme};

/// Default reference publication rate, Hz.
pub const DEFAULT_REFERENCE_RATE: f64 = 50.0;
/// Default robot controller rate, Hz.
pub const DEFAULT_CONTROL_RATE: f64 = 100.0;
/// Default time without a fresh message after which a leader stream is lost, s.
pub const DEFAULT_LINK_TIMEOUT: f64 = 0.2;
/// Default age on arrival beyond which a message is stale, s.
pub const DEFAULT_STALE_AFTER: f64 = 0.5;
/// Default ROS 2 odometry timeout, s.
pub const DEFAULT_ODOM_TIMEOUT: f64 = 0.5;
/// Default `cmd_vel` timeout of the simulated ROS 2 base, s (as
/// `diff_drive_controller`'s `cmd_vel_timeout`).
pub const DEFAULT_CMD_VEL_TIMEOUT: f64 = 0.5;
/// Default odometry rate of the simulated ROS 2 base, Hz.
pub const DEFAULT_ODOM_RATE: f64 = 50.0;
/// Default ROS 2 namespace of agent `k` (`{k}` is its number).
pub const DEFAULT_NAMESPACE: &str = "/robot{k}";
/// Largest ROS 2 domain id (rmw's limit for the default DDS port mapping,
/// kept by rmw_zenoh).
pub const MAX_DOMAIN_ID: u32 = 232;

/// Default `extrapolate` hold time, s.
pub const DEFAULT_HOLD: f64 = 1.0;
/// Default peak deceleration of `extrapolate`'s stop, m/s².
pub const DEFAULT_DECEL: f64 = 0.1;

/// What a robot does when its leader's stream is lost (`policy = "stop"` or
/// `"extrapolate"` in a scenario).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, Serialize, JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum LinkPolicy {
    /// Converge to the last received position (the paper's experiment).
    Stop,
    /// Keep the last `V_d`, `ω_d` for the hold time, then slow smoothly to rest.
    #[default]
    Extrapolate,
}

/// Where an agent's robot process runs in a lab fleet (`placement = "hub"`
/// or `"onboard"`, in `[fleet]` for every agent or in the agent; docs/lab.md).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, Serialize, JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum Placement {
    /// On the hub's computer, started by `fleet up` (off-board: it reaches
    /// its robot over the network).
    #[default]
    Hub,
    /// On the robot's own computer, started there (`fleet robot --config`,
    /// from `fleet bundle`), joining the hub.
    Onboard,
}

impl Placement {
    /// Its name in a scenario.
    pub fn name(self) -> &'static str {
        match self {
            Placement::Hub => "hub",
            Placement::Onboard => "onboard",
        }
    }
}

/// A resolved link-loss policy.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkLoss {
    /// Stop or extrapolate.
    pub policy: LinkPolicy,
    /// `extrapolate`: how long the last speed is kept after the last message, s.
    pub hold: f64,
    /// `extrapolate`: peak deceleration of the smooth stop, m/s².
    pub decel: f64,
}

impl Default for LinkLoss {
    fn default() -> Self {
        LinkLoss {
            policy: LinkPolicy::Extrapolate,
            hold: DEFAULT_HOLD,
            decel: DEFAULT_DECEL,
        }
    }
}

/// The `[fleet]` settings with defaults applied and values checked.
#[derive(Debug, Clone, PartialEq)]
pub struct FleetSettings {
    /// Fleet name: the second chunk of every key expression.
    pub name: String,
    /// Reference publication rate, Hz.
    pub reference_rate: f64,
    /// Robot controller rate, Hz.
    pub control_rate: f64,
    /// A state nobody reads at the control rate is published at this rate,
    /// Hz (`None`: every tick; never above `control_rate`).
    pub state_rate: Option<f64>,
    /// Link-loss detection time, s.
    pub link_timeout: f64,
    /// Staleness threshold on a message's age at arrival, s.
    pub stale_after: f64,
    /// The operator heartbeat's deadline, s (`None`: none asked): a robot
    /// with no heartbeat for this long holds.
    pub operator_heartbeat: Option<f64>,
    /// Per agent (0-based), its link-loss policy.
    pub link_loss: Vec<LinkLoss>,
    /// Per agent (0-based), where its robot process runs.
    pub placement: Vec<Placement>,
    /// Per agent (0-based), where its robot is when driven through ROS 2.
    pub ros2: Vec<Ros2Link>,
}

/// One agent's ROS 2 robot, resolved (`[fleet.ros2]` under the agent's `ros2`).
#[derive(Debug, Clone, PartialEq)]
pub struct Ros2Link {
    /// ROS domain id.
    pub domain_id: u32,
    /// The robot's namespace, canonical (`/robot1`).
    pub namespace: String,
    /// The fully qualified `cmd_vel` topic (`/robot1/cmd_vel`).
    pub cmd_vel: String,
    /// The fully qualified odometry topic (`/robot1/odom`).
    pub odom: String,
    /// `cmd_vel`'s message type.
    pub cmd_vel_type: CmdVelType,
    /// What stamps a `TwistStamped` command.
    pub cmd_vel_stamp: CmdVelStamp,
    /// How topics map onto Zenoh keys.
    pub key_scheme: KeyScheme,
    /// The body frame (`cmd_vel`'s `frame_id`, odometry's `child_frame_id`).
    pub base_frame: String,
    /// The odometry frame.
    pub odom_frame: String,
    /// Odometry older than this is lost, s.
    pub odom_timeout: f64,
    /// The simulated base stops after this long without a command, s.
    pub cmd_vel_timeout: f64,
    /// The simulated base's odometry rate, Hz.
    pub odom_rate: f64,
    /// The odometry frame's pose in the world (`odom_origin`, default the
    /// agent's start pose): a world pose is `odom_origin ⊕ odometry pose`.
    pub odom_origin: Pose,
    /// Where its absolute fixes come from (its `fixes.source`), if anywhere.
    pub fixes: Option<FixSource>,
    /// The base's hazard topic (`HazardDetectionVector`), fully qualified,
    /// if it has one the fleet listens to.
    pub hazards: Option<String>,
    /// The base's e-stop topic (`Bool`), fully qualified, if any.
    pub estop: Option<String>,
    /// Driven by someone else (teleop, Nav2): the fleet robot only reads it
    /// and publishes its motion as the head of its followers.
    pub driven: bool,
    /// Its own Zenoh router's endpoints (`connect`, `{k}` replaced), tried
    /// in order; empty: the robot is reached through the fleet's network.
    pub connect: Vec<String>,
}

/// A ROS 2 topic of absolute fixes for one robot (an agent's `fixes` with a
/// `source`), resolved. The fixes' noises, schedule, latency and fusion
/// are the agent's [`crate::odometry::FixSpec`] (the simulator's, one
/// description of the same fix stream).
#[derive(Debug, Clone, PartialEq)]
pub struct FixSource {
    /// The fully qualified topic (`/robot1/pose`, `/mocap/robot1/pose`).
    pub topic: String,
    /// Its message type.
    pub message: FixMessage,
    /// The fixes' `header.frame_id`.
    pub frame: String,
    /// The pose of that frame in the world: a world fix is
    /// `frame_origin ⊕ message pose`.
    pub frame_origin: Pose,
    /// Fixes missing for longer than this are reported, s (`None`: three
    /// fix periods).
    pub timeout: Option<f64>,
    /// The formation tolerance Theorem 2's fix interval is computed for, m.
    pub tolerance: Option<f64>,
    /// Whether implausible fixes are refused.
    pub gate: bool,
}

/// Whether `s` can be one chunk of a Zenoh key expression as echelon uses it:
/// non-empty, ASCII letters, digits, `-`, `_` and `.` only.
pub fn is_valid_fleet_name(s: &str) -> bool {
    !s.is_empty()
        && s.bytes()
            .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'-' | b'_' | b'.'))
}

impl Scenario {
    /// The fleet's name: `[fleet] name`, checked, else the scenario's name
    /// with every character a key expression chunk refuses as `-`.
    fn fleet_name(&self) -> Result<String, ScenarioError> {
        let f = &self.file.fleet;
        let at = FieldPath::from("fleet");
        Ok(match &f.name {
            Some(n) => {
                if !is_valid_fleet_name(n) {
                    return Err(self.error(
                        &at.key("name"),
                        format!("`{n}` is not a valid fleet name (letters, digits, '-', '_' and '.' only; it becomes a key expression chunk)"),
                    ));
                }
                n.clone()
            }
            None => {
                let cleaned: String = self
                    .name()
                    .chars()
                    .map(|c| {
                        if c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.') {
                            c
                        } else {
                            '-'
                        }
                    })
                    .collect();
                if cleaned.is_empty() {
                    "fleet".to_owned()
                } else {
                    cleaned
                }
            }
        })
    }

    /// Every agent's `link_loss`: its own, else `[fleet.link_loss]`, else
    /// the defaults; checked.
    fn link_losses(&self) -> Result<Vec<LinkLoss>, ScenarioError> {
        let f = &self.file.fleet;
        let at = FieldPath::from("fleet");
        self.file
            .agents
            .iter()
            .enumerate()
            .map(|(i, a)| {
                let links = Merge::new(
                    a.link_loss.as_ref(),
                    f.link_loss.as_ref(),
                    FieldPath::from("agents").index(i).key("link_loss"),
                    at.key("link_loss"),
                );
                let pick = |get, key: &str, default: f64| {
                    let (v, path) = links.get_or(get, key, default);
                    check::non_negative("", v).map_err(|e| self.locator().param(&path, &e))
                };
                let hold = pick(|l| l.hold, "hold", DEFAULT_HOLD)?;
                let decel = pick(|l| l.decel, "decel", DEFAULT_DECEL)?;
                if decel == 0.0 {
                    let (_, path) = links.get_or(|l| l.decel, "decel", decel);
                    return Err(self.error(&path, "0 must be > 0 (a robot must be able to stop)"));
                }
                let (policy, _) = links.get_or(|l| l.policy, "policy", LinkPolicy::Extrapolate);
                Ok(LinkLoss {
                    policy,
                    hold,
                    decel,
                })
            })
            .collect::<Result<Vec<_>, ScenarioError>>()
    }

    /// Resolves and checks the `[fleet]` section and every agent's `link_loss`.
    pub fn fleet(&self) -> Result<FleetSettings, ScenarioError> {
        let f = &self.file.fleet;
        let at = FieldPath::from("fleet");
        let name = self.fleet_name()?;
        let positive = |v: Option<f64>, key: &str, default: f64| -> Result<f64, ScenarioError> {
            check::positive("", v.unwrap_or(default))
                .map_err(|e| self.locator().param(&at.key(key), &e))
        };
        let reference_rate = positive(f.reference_rate, "reference_rate", DEFAULT_REFERENCE_RATE)?;
        let control_rate = positive(f.control_rate, "control_rate", DEFAULT_CONTROL_RATE)?;
        let link_timeout = positive(f.link_timeout, "link_timeout", DEFAULT_LINK_TIMEOUT)?;
        let stale_after = positive(f.stale_after, "stale_after", DEFAULT_STALE_AFTER)?;
        let state_rate = f
            .state_rate
            .map(|v| positive(Some(v), "state_rate", v))
            .transpose()?;
        if let Some(r) = state_rate.filter(|&r| r > control_rate) {
            return Err(self.error(
                &at.key("state_rate"),
                format!("{r} Hz is above control_rate ({control_rate} Hz): a robot publishes at most once a tick"),
            ));
        }
        let operator_heartbeat = f
            .operator_heartbeat
            .map(|v| positive(Some(v), "operator_heartbeat", v))
            .transpose()?;
        let link_loss = self.link_losses()?;
        let placement = self
            .file
            .agents
            .iter()
            .map(|a| a.placement.or(f.placement).unwrap_or_default())
            .collect();
        let ros2 = (0..self.file.agents.len())
            .map(|i| self.ros2_link(i))
            .collect::<Result<Vec<_>, ScenarioError>>()?;
        for (i, a) in ros2.iter().enumerate() {
            if let Some(j) = ros2[..i].iter().position(|b| {
                b.domain_id == a.domain_id && (b.cmd_vel == a.cmd_vel || b.odom == a.odom)
            }) {
                let path = Merge::new(
                    self.file.agents[i].ros2.as_ref(),
                    f.ros2.as_ref(),
                    FieldPath::from("agents").index(i).key("ros2"),
                    at.key("ros2"),
                )
                .path_of("namespace");
                return Err(self.error(
                    &path,
                    format!(
                        "agents {} and {} would share `{}`/`{}` in domain {}: each robot needs its own namespace (use `{{k}}`)",
                        j + 1,
                        i + 1,
                        a.cmd_vel,
                        a.odom,
                        a.domain_id
                    ),
                ));
            }
        }
        // A base that stops its wheels `cmd_vel_timeout` after its last
        // command (a Create 3: 0.5 s; diff_drive_controller's default) must
        // get at least two commands in that time, or one late command
        // stutters it.
        if let Some((i, a)) = ros2
            .iter()
            .enumerate()
            .find(|(_, a)| 2.0 / control_rate > a.cmd_vel_timeout)
        {
            return Err(self.error(
                &at.key("control_rate"),
                format!(
                    "{control_rate} Hz sends a command every {:.3} s, but agent {}'s base stops {} s after its last one (cmd_vel_timeout): give at least {} Hz",
                    1.0 / control_rate,
                    i + 1,
                    a.cmd_vel_timeout,
                    (2.0 / a.cmd_vel_timeout).ceil()
                ),
            ));
        }
        // Each value passed its own rules; now its plausible range (the fleet
        // has no value that is only unusual: nothing to warn about).
        plausible::check(&self.file, &self.locator(), Part::Fleet)?;
        Ok(FleetSettings {
            name,
            reference_rate,
            control_rate,
            state_rate,
            link_timeout,
            stale_after,
            operator_heartbeat,
            link_loss,
            placement,
            ros2,
        })
    }

    /// Agent `i`'s (0-based) odometry origin in the world: its
    /// `odom_origin`, else its `start` pose.
    fn odom_origin(&self, i: usize) -> Result<Pose, ScenarioError> {
        let a = &self.file.agents[i];
        let at = FieldPath::from("agents").index(i);
        let pose = match &a.odom_origin {
            Some(p) => self.locator().pose(p, &at.key("odom_origin"), false)?,
            None => self.locator().pose(&a.start, &at.key("start"), true)?,
        };
        Ok(pose.pose())
    }

    /// Agent `i`'s (0-based) ROS 2 robot, names checked by ROS 2's rules.
    fn ros2_link(&self, i: usize) -> Result<Ros2Link, ScenarioError> {
        let links = Merge::new(
            self.file.agents[i].ros2.as_ref(),
            self.file.fleet.ros2.as_ref(),
            FieldPath::from("agents").index(i).key("ros2"),
            FieldPath::from("fleet").key("ros2"),
        );
        let named = |get: fn(&Ros2Section) -> Option<String>, key: &str, default: &str| {
            links.get_or(get, key, default.to_owned())
        };
        let (template, ns_path) = named(|r| r.namespace.clone(), "namespace", DEFAULT_NAMESPACE);
        let namespace =
            ros_names::normalize_namespace(&template.replace("{k}", &(i + 1).to_string()))
                .map_err(|e| self.error(&ns_path, e.to_string()))?;
        let topic = |get: fn(&Ros2Section) -> Option<String>, key: &str, default: &str| {
            let (name, path) = named(get, key, default);
            ros_names::fully_qualified_topic(&namespace, &name)
                .map_err(|e| self.error(&path, e.to_string()))
        };
        let cmd_vel = topic(|r| r.cmd_vel.clone(), "cmd_vel", "cmd_vel")?;
        let odom = topic(|r| r.odom.clone(), "odom", "odom")?;
        let optional_topic = |get: fn(&Ros2Section) -> Option<String>, key: &str| {
            links
                .get(get, key)
                .map(|(name, path)| {
                    ros_names::fully_qualified_topic(&namespace, &name)
                        .map_err(|e| self.error(&path, e.to_string()))
                })
                .transpose()
        };
        let hazards = optional_topic(|r| r.hazards.clone(), "hazards")?;
        let estop = optional_topic(|r| r.estop.clone(), "estop")?;
        let frame = |get: fn(&Ros2Section) -> Option<String>, key: &str, default: &str| {
            let (name, path) = named(get, key, default);
            if name.is_empty() || name.chars().any(|c| c.is_whitespace() || c.is_control()) {
                return Err(self.error(
                    &path,
                    format!("frame id `{name}` must be non-empty, without spaces"),
                ));
            }
            Ok(name)
        };
        let base_frame = frame(|r| r.base_frame.clone(), "base_frame", "base_link")?;
        let odom_frame = frame(|r| r.odom_frame.clone(), "odom_frame", "odom")?;
        let (domain_id, path) = links.get_or(|r| r.domain_id, "domain_id", 0);
        if domain_id > MAX_DOMAIN_ID {
            return Err(self.error(
                &path,
                format!("{domain_id} is not a ROS domain id (0 to {MAX_DOMAIN_ID})"),
            ));
        }
        let positive = |get: fn(&Ros2Section) -> Option<f64>, key: &str, default: f64| {
            let (v, path) = links.get_or(get, key, default);
            check::positive("", v).map_err(|e| self.locator().param(&path, &e))
        };
        Ok(Ros2Link {
            domain_id,
            cmd_vel,
            odom,
            cmd_vel_type: links
                .get_or(|r| r.cmd_vel_type, "cmd_vel_type", CmdVelType::default())
                .0,
            cmd_vel_stamp: links
                .get_or(|r| r.cmd_vel_stamp, "cmd_vel_stamp", CmdVelStamp::default())
                .0,
            key_scheme: links
                .get_or(|r| r.key_scheme, "key_scheme", KeyScheme::default())
                .0,
            base_frame,
            odom_frame,
            odom_timeout: positive(|r| r.odom_timeout, "odom_timeout", DEFAULT_ODOM_TIMEOUT)?,
            cmd_vel_timeout: positive(
                |r| r.cmd_vel_timeout,
                "cmd_vel_timeout",
                DEFAULT_CMD_VEL_TIMEOUT,
            )?,
            odom_rate: positive(|r| r.odom_rate, "odom_rate", DEFAULT_ODOM_RATE)?,
            odom_origin: self.odom_origin(i)?,
            fixes: self.fix_source(i, &namespace)?,
            hazards,
            estop,
            driven: links.get_or(|r| r.driven, "driven", false).0,
            namespace,
            connect: self.connect(i, &links)?,
        })
    }

    /// Agent `i`'s (0-based) robot router endpoints (`connect`, `{k}`
    /// replaced), each checked.
    fn connect(
        &self,
        i: usize,
        links: &Merge<'_, Ros2Section>,
    ) -> Result<Vec<String>, ScenarioError> {
        let Some((endpoints, path)) = links.get(|r| r.connect.clone(), "connect") else {
            return Ok(Vec::new());
        };
        let endpoints: Vec<String> = endpoints
            .to_vec()
            .iter()
            .map(|e| e.replace("{k}", &(i + 1).to_string()))
            .collect();
        if endpoints.is_empty() {
            return Err(self.error(
                &path,
                "an empty list: give the robot's router, e.g. \"tcp/192.168.1.21:7447\"",
            ));
        }
        for e in &endpoints {
            check_endpoint(e).map_err(|m| self.error(&path, format!("agent {}: {m}", i + 1)))?;
        }
        Ok(endpoints)
    }

    /// Agent `i`'s (0-based) fixes from ROS 2: its `fixes` over `[fixes]`,
    /// when they are on and name a `source`.
    fn fix_source(&self, i: usize, namespace: &str) -> Result<Option<FixSource>, ScenarioError> {
        let fix = Merge::new(
            self.file.agents[i].fixes.as_ref(),
            self.file.fixes.as_ref(),
            FieldPath::from("agents").index(i).key("fixes"),
            FieldPath::from("fixes"),
        );
        let on = fix.get(|s| s.enabled, "enabled").is_none_or(|(e, _)| e);
        let Some((source, path)) = fix.get(|s: &FixesSection| s.source.clone(), "source") else {
            return Ok(None);
        };
        if !on {
            return Ok(None);
        }
        let topic = ros_names::fully_qualified_topic(namespace, &source)
            .map_err(|e| self.error(&path, e.to_string()))?;
        let (frame, path) = fix.get_or(|s| s.frame.clone(), "frame", "map".to_owned());
        if frame.is_empty() || frame.chars().any(|c| c.is_whitespace() || c.is_control()) {
            return Err(self.error(
                &path,
                format!("frame id `{frame}` must be non-empty, without spaces"),
            ));
        }
        let frame_origin = match fix.get(|s| s.frame_origin.clone(), "frame_origin") {
            Some((p, path)) => self.locator().pose(&p, &path, false)?.pose(),
            None => Pose::default(),
        };
        let positive = |get: fn(&FixesSection) -> Option<f64>, key: &str| {
            fix.get(get, key)
                .map(|(v, path)| {
                    check::positive("", v).map_err(|e| self.locator().param(&path, &e))
                })
                .transpose()
        };
        Ok(Some(FixSource {
            topic,
            message: fix
                .get_or(|s| s.message, "message", FixMessage::default())
                .0,
            frame,
            frame_origin,
            timeout: positive(|s| s.timeout, "timeout")?,
            tolerance: positive(|s| s.tolerance, "tolerance")?,
            gate: fix.get_or(|s| s.gate, "gate", true).0,
        }))
    }
}

mod endpoint;
pub use endpoint::{
    ENDPOINT_PROTOCOLS, check_endpoint, check_listen_endpoint, endpoint_address,
    endpoint_host_port, endpoint_port,
};

#[cfg(test)]
mod tests;
