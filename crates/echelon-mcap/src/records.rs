//! What the log holds: the schemas (JSON, ROS 2) and the JSON records of an
//! agent's state and of the reference, with their topics.

use std::borrow::Cow;
use std::sync::LazyLock;

use echelon::control::LeaderMotion;
use echelon::reference::{Order, Reference, Trajectory};
use echelon::sample::AgentSample;
use serde::Serialize;

/// Schema encoding of ROS 2 message definitions (`.msg` text).
pub const ROS2MSG: &str = "ros2msg";

/// Message encoding of ROS 2 messages (CDR with its encapsulation header).
pub const CDR: &str = "cdr";

/// A ROS 2 message type as rosbag2's MCAP storage records it: the schema
/// (name `pkg/msg/Type`, encoding [`ROS2MSG`], data the full definition
/// text) and the type hash it puts in each channel's `topic_type_hash`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Ros2Schema {
    /// `package/msg/Type`.
    pub name: &'static str,
    /// The type's `.msg` text followed by every nested type's, each after a
    /// line of 80 `=` and a `MSG: package/Type` line.
    pub definition: &'static str,
    /// The RIHS01 type hash, `RIHS01_` and 64 hex digits.
    pub type_hash: &'static str,
}

/// A named JSON Schema for a channel.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct JsonSchema {
    /// Schema name, e.g. `echelon.AgentState`.
    pub name: &'static str,
    /// The JSON Schema document.
    pub schema: Cow<'static, str>,
}

impl JsonSchema {
    /// The schema of the record type `T`, derived from its serialised form
    /// (draft 07, nested records inlined): it names exactly the fields `T`
    /// serialises, with their doc comments as descriptions.
    pub fn of<T: schemars::JsonSchema>(name: &'static str) -> JsonSchema {
        let schema = schemars::generate::SchemaSettings::draft07()
            .with(|s| s.inline_subschemas = true)
            .into_generator()
            .into_root_schema_for::<T>();
        JsonSchema {
            name,
            schema: Cow::Owned(format!("{:#}", schema.as_value())),
        }
    }
}

/// Schema of `/agent/K/state` messages, derived from [`AgentStateRecord`].
pub static AGENT_STATE: LazyLock<JsonSchema> =
    LazyLock::new(|| JsonSchema::of::<AgentStateRecord>("echelon.AgentState"));

/// Schema of `/reference` messages, derived from [`ReferenceRecord`].
pub static REFERENCE: LazyLock<JsonSchema> =
    LazyLock::new(|| JsonSchema::of::<ReferenceRecord>("echelon.Reference"));

/// A leader motion `p_d`, `ṗ_d`, `p̈_d`: the one a fleet robot's law used,
/// or the virtual leader's (in [`ReferenceRecord`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, schemars::JsonSchema)]
pub struct LeaderRecord {
    /// `p_d` x, m.
    pub x: f64,
    /// `p_d` y, m.
    pub y: f64,
    /// `ṗ_d` x, m/s.
    pub vx: f64,
    /// `ṗ_d` y, m/s.
    pub vy: f64,
    /// `p̈_d` x, m/s².
    pub ax: f64,
    /// `p̈_d` y, m/s².
    pub ay: f64,
}

impl From<&LeaderMotion> for LeaderRecord {
    fn from(m: &LeaderMotion) -> Self {
        LeaderRecord {
            x: m.p[0],
            y: m.p[1],
            vx: m.dp[0],
            vy: m.dp[1],
            ax: m.ddp[0],
            ay: m.ddp[1],
        }
    }
}

/// One robot at one instant (an `/agent/K/state` message): the
/// [`AgentSample`] (the `trajectory.csv` row, velocity-base fields included
/// for a velocity base), ‖e‖, and in a fleet the robot's sequence number,
/// link status and the leader motion it used. SI units, radians.
#[derive(Debug, Clone, PartialEq, Serialize, schemars::JsonSchema)]
#[schemars(title = "echelon.AgentState")]
pub struct AgentStateRecord {
    /// The sample.
    #[serde(flatten)]
    pub sample: AgentSample,
    /// ‖e‖, m.
    pub error_norm: f64,
    /// Fleet only: the robot's message sequence number.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub seq: Option<u64>,
    /// Fleet only: link status (waiting, tracking, extrapolating, stopping or stopped).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub link: Option<&'static str>,
    /// Fleet only: the leader motion the law used.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub leader: Option<LeaderRecord>,
    /// Fleet, ROS 2 robots only: the robot's own odometry.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub odometry: Option<OdometryRecord>,
    /// Fleet only: `σ`, the standard deviation of the robot's position
    /// estimate along its most uncertain axis, m (0: exact or unknown), by
    /// which its neighbours widened their radius.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sigma: Option<f64>,
}

/// A ROS 2 robot's own odometry beside its world pose (docs/ros2.md,
/// "Frames"): the world pose is `odom_origin ⊕ raw` (or the fixes'
/// correction ⊕ raw).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, schemars::JsonSchema)]
pub struct OdometryRecord {
    /// The pose in the robot's odom frame `[x, y, θ]` (m, m, rad; heading
    /// unwrapped), before the odom → world map.
    pub raw: [f64; 3],
    /// Age of the newest odometry sample when the state was published, s.
    pub age: f64,
    /// Age of the newest accepted fix then, s (null: none yet, or no fixes).
    pub fix_age: Option<f64>,
}

impl AgentStateRecord {
    /// The record of `sample`; fleet fields empty.
    pub fn new(sample: AgentSample) -> AgentStateRecord {
        AgentStateRecord {
            error_norm: sample.error_norm(),
            sample,
            seq: None,
            link: None,
            leader: None,
            odometry: None,
            sigma: None,
        }
    }
}

/// The virtual leader at one instant (a `/reference` message): position
/// `p_d`, velocity and acceleration, speed `V_d` and turn rate `ω_d`. SI units.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, schemars::JsonSchema)]
#[schemars(title = "echelon.Reference")]
pub struct ReferenceRecord {
    /// Time, s.
    pub t: f64,
    /// Fleet only: the leader's sequence number.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub seq: Option<u64>,
    /// `p_d`, `ṗ_d`, `p̈_d`.
    #[serde(flatten)]
    pub motion: LeaderRecord,
    /// `V_d`, m/s.
    pub speed: f64,
    /// `ω_d`, rad/s.
    pub turn_rate: f64,
}

impl ReferenceRecord {
    /// The reference `reference` at `t` (simulation: no sequence number).
    pub fn at(reference: &Reference, t: f64) -> ReferenceRecord {
        let jet = reference.eval(t, Order::Two);
        ReferenceRecord {
            t,
            seq: None,
            motion: LeaderRecord::from(&LeaderMotion {
                p: jet.p,
                dp: jet.dp,
                ddp: jet.ddp,
            }),
            speed: jet.speed(),
            turn_rate: jet.turn_rate(),
        }
    }
}

/// The topic of agent `k` (from 1).
pub fn agent_topic(k: usize) -> String {
    format!("/agent/{k}/state")
}

/// The reference topic.
pub const REFERENCE_TOPIC: &str = "/reference";
