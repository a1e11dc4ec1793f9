//! The scenario file format (TOML). Units are SI and angles radians; a field may
//! take degrees only if its name ends in `_deg`. Unknown fields are errors.

use std::collections::BTreeMap;
use std::fmt;

use serde::de::{self, Visitor};
use serde::{Deserialize, Deserializer, Serialize, Serializer};

pub use super::fleet::{LinkPolicy, Placement};
pub use crate::base::AccelLimit;
pub use crate::control::{Law, Variant};
pub use crate::lycomp::{LyComp, LyDerivatives};
pub use crate::odometry::{Fusion, ZetaModel};
pub use echelon_ros2::KeyScheme;

mod fleet;
mod odometry;

pub use fleet::{CmdVelStamp, CmdVelType, Endpoints, FleetSection, LinkLossSection, Ros2Section};
pub use odometry::{FixMessage, FixesSection, OdometrySection};

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
#[serde_with::skip_serializing_none]
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct SafetySection {
    /// `false` turns the filter off (for one agent, under `[safety]`).
    pub enabled: Option<bool>,
    /// Smallest distance between two robots' points `L` ahead, and a
    /// point's clearance from an obstacle's edge, m (`[safety]` only; required).
    pub radius: Option<f64>,
    /// `γ`, 1/s (default 1).
    pub gain: Option<f64>,
    /// Sensing range: robots whose point is farther are ignored, m (default:
    /// every robot).
    pub range: Option<f64>,
    /// Static disc obstacles (`[safety]` only).
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
#[serde_with::skip_serializing_none]
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct BoundsSpec {
    /// Largest `|v|`, m/s.
    pub speed: Option<f64>,
    /// Largest `|ω|`, rad/s.
    pub turn_rate: Option<f64>,
    /// Largest distance from the world origin, m.
    pub distance: Option<f64>,
}

/// `[log]`: what goes to `trajectory.csv`.
#[serde_with::skip_serializing_none]
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct LogSection {
    /// Logging period, s (0: every step; default 0.01).
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
#[serde_with::skip_serializing_none]
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct ControlSection {
    /// `paper` (default for torque-driven robots), `complete`, or `kinematic`
    /// (the only law of a velocity base, and its default).
    pub law: Option<Law>,
    /// `K_e` (default 1.5).
    pub ke: Option<f64>,
    /// `K_z` (default 10).
    pub kz: Option<f64>,
    /// `L`, m (default 0.05).
    pub l: Option<f64>,
    /// `exact`, `fit` (default) or `none`.
    pub lycomp: Option<LyComp>,
    /// `neglect` (default) or `exact`.
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
#[serde_with::skip_serializing_none]
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct RobotSection {
    /// `torque` (default; `velocity` when `preset` names a velocity base).
    pub drive: Option<DriveName>,
    /// Start from this preset (`agent1`, `agent2`; velocity bases: `ideal`,
    /// `turtlebot3-burger`, `turtlebot4`, `jackal`) and override the fields given.
    pub preset: Option<String>,
    /// Speed lag `τ_v`, s (velocity base; 0: ideal).
    pub tau_v: Option<f64>,
    /// Turn-rate lag `τ_ω`, s (velocity base; 0: ideal).
    pub tau_omega: Option<f64>,
    /// Largest `|v|`, m/s (velocity base; absent: unlimited).
    pub v_max: Option<f64>,
    /// Largest `|ω|`, rad/s (velocity base; absent: unlimited).
    pub omega_max: Option<f64>,
    /// Largest `|v̇|`, m/s² (velocity base with `tau_v > 0`; absent: unlimited).
    pub a_max: Option<f64>,
    /// Largest `|ω̇|`, rad/s² (velocity base with `tau_omega > 0`; absent: unlimited).
    pub alpha_max: Option<f64>,
    /// `joint` (default: keeps the path) or `per-axis` acceleration limits.
    pub accel: Option<AccelLimit>,
    /// Velocity base: how far it may back up in one go, m (the `turtlebot4`
    /// preset: 0.1, the Create 3's backup limit); the law and the safety
    /// filter never ask for more (docs/real-robots.md). Default: no limit.
    pub reverse_limit: Option<f64>,
    /// `m`, kg.
    pub mass: Option<f64>,
    /// `η`, kg/s.
    pub linear_friction: Option<f64>,
    /// `J`, kg m².
    pub inertia: Option<f64>,
    /// `ψ`, kg m²/s.
    pub angular_friction: Option<f64>,
    /// `l` (half the wheel separation), m.
    pub half_wheelbase: Option<f64>,
    /// `r`, m.
    pub wheel_radius: Option<f64>,
    /// Per-wheel torque limit, N m (absent: unlimited).
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
        #[serde(
            default,
            skip_serializing_if = "Option::is_none",
            deserialize_with = "exact_array"
        )]
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
        #[serde(
            default,
            skip_serializing_if = "Option::is_none",
            deserialize_with = "exact_rows"
        )]
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
    /// Where its robot process runs in a lab fleet: `hub` (started by
    /// `fleet up`) or `onboard` (on the robot's computer, joining the hub);
    /// overrides `[fleet] placement`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub placement: Option<Placement>,
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
/// to the left of the follower, in the follower's frame (the paper's
/// Definition 1); with `frame = "leader"`, the follower's point `L` ahead
/// sits `L_Xoff` behind and `L_Yoff` to the right of the leader in the
/// leader's frame (a rigid formation).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct OffsetSpec {
    /// `L_Xoff`, m.
    pub x: f64,
    /// `L_Yoff`, m.
    pub y: f64,
    /// The frame the offset is written in (default `"follower"`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frame: Option<FrameName>,
}

/// The frame an offset is written in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum FrameName {
    /// The follower's (the paper's eq. 7): its slot turns with its heading.
    Follower,
    /// The leader's: the slot is fixed in the leader's frame, the point `L`
    /// ahead of the follower tracks it (eqs. 14–16); no `L_Ycomp`.
    Leader,
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

/// `[f64; N]` from an array of exactly `N` numbers. Serde's own arrays read
/// the first `N` elements and the TOML deserializer does not refuse the
/// rest: `[0.0, 1.0, 2.0, 5.0]` was a waypoint, its `5.0` dropped.
struct Exact<const N: usize>([f64; N]);

impl<'de, const N: usize> Deserialize<'de> for Exact<N> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Numbers<const N: usize>;
        impl<'de, const N: usize> Visitor<'de> for Numbers<N> {
            type Value = Exact<N>;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                write!(f, "an array of length {N}")
            }
            fn visit_seq<A: de::SeqAccess<'de>>(self, mut seq: A) -> Result<Exact<N>, A::Error> {
                let mut out = [0.0; N];
                for (i, slot) in out.iter_mut().enumerate() {
                    *slot = seq
                        .next_element()?
                        .ok_or_else(|| de::Error::invalid_length(i, &self))?;
                }
                let mut len = N;
                while seq.next_element::<de::IgnoredAny>()?.is_some() {
                    len += 1;
                }
                if len > N {
                    return Err(de::Error::invalid_length(len, &self));
                }
                Ok(Exact(out))
            }
        }
        d.deserialize_seq(Numbers::<N>)
    }
}

/// An optional `[f64; N]`, its length exact ([`Exact`]).
fn exact_array<'de, D: Deserializer<'de>, const N: usize>(
    d: D,
) -> Result<Option<[f64; N]>, D::Error> {
    Ok(Option::<Exact<N>>::deserialize(d)?.map(|e| e.0))
}

/// Optional rows of `N` numbers, each row's length exact ([`Exact`]).
fn exact_rows<'de, D: Deserializer<'de>, const N: usize>(
    d: D,
) -> Result<Option<Vec<[f64; N]>>, D::Error> {
    Ok(
        Option::<Vec<Exact<N>>>::deserialize(d)?
            .map(|rows| rows.into_iter().map(|e| e.0).collect()),
    )
}
