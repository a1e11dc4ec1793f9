//! # echelon-mcap
//!
//! MCAP logs of echelon runs, for robotics tools (Foxglove, the `mcap` CLI,
//! Python's `mcap` reader). Every channel carries JSON messages
//! (`message_encoding = "json"`) described by a JSON Schema
//! (`schema encoding = "jsonschema"`), so a viewer can plot any field.
//!
//! The same topics and schemas serve simulated runs (`echelon run --mcap`,
//! through [`McapObserver`]) and fleet runs (the fleet collector, through
//! [`McapLog`] directly):
//!
//! | topic | schema | content |
//! |---|---|---|
//! | `/reference` | `echelon.Reference` | the virtual leader: `p_d`, `ṗ_d`, `p̈_d`, `V_d`, `ω_d` |
//! | `/agent/K/state` | `echelon.AgentState` | agent K (from 1): the `trajectory.csv` row, plus, in a fleet, sequence, link status and the leader motion the robot used |
//!
//! Times: `publish_time` is the run's (or fleet's) time `t` in nanoseconds;
//! `log_time` is `t` too for a simulation, the collector's UNIX receive time for
//! a fleet.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{self, BufWriter, Seek, Write};
use std::path::{Path, PathBuf};

use serde::Serialize;

use echelon::model::State;
use echelon::model::wrap_angle;
use echelon::reference::{Order, Reference, Trajectory};
use echelon::sim::{AgentOutput, Frame, Observer, ObserverError};

/// A failure while writing an MCAP file.
#[derive(Debug, thiserror::Error)]
pub enum McapLogError {
    /// The file could not be created or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: io::Error,
    },
    /// The MCAP writer refused (unknown channel, I/O inside the writer…).
    #[error("MCAP: {0}")]
    Mcap(#[from] mcap::McapError),
    /// A record could not be serialised.
    #[error("JSON: {0}")]
    Json(#[from] serde_json::Error),
}

/// A named JSON Schema for a channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct JsonSchema {
    /// Schema name, e.g. `echelon.AgentState`.
    pub name: &'static str,
    /// The JSON Schema document.
    pub schema: &'static str,
}

/// Schema of `/agent/K/state` messages ([`AgentStateRecord`]).
pub const AGENT_STATE: JsonSchema = JsonSchema {
    name: "echelon.AgentState",
    schema: r#"{
  "$schema": "http://json-schema.org/draft-07/schema#",
  "title": "echelon.AgentState",
  "description": "One robot at one instant: state, tracking error e (eq. 7) and backstepping error z (eq. 10) in the robot's body frame, generalised input u and wheel torques. SI units, radians.",
  "type": "object",
  "properties": {
    "t": {"type": "number", "description": "time, s"},
    "agent": {"type": "integer", "description": "agent number, from 1"},
    "x": {"type": "number", "description": "m"},
    "y": {"type": "number", "description": "m"},
    "theta": {"type": "number", "description": "heading, rad, wrapped to (-pi, pi]"},
    "v": {"type": "number", "description": "linear speed, m/s"},
    "omega": {"type": "number", "description": "angular speed, rad/s"},
    "ex": {"type": "number", "description": "tracking error e_x, m"},
    "ey": {"type": "number", "description": "tracking error e_y, m"},
    "zx": {"type": "number", "description": "backstepping error z_x, m/s"},
    "zy": {"type": "number", "description": "backstepping error z_y, m/s"},
    "u1": {"type": "number", "description": "force, N"},
    "u2": {"type": "number", "description": "torque, N m"},
    "tau_r": {"type": "number", "description": "right wheel torque, N m"},
    "tau_l": {"type": "number", "description": "left wheel torque, N m"},
    "error_norm": {"type": "number", "description": "|e|, m"},
    "seq": {"type": "integer", "description": "fleet only: the robot's message sequence number"},
    "link": {"type": "string", "description": "fleet only: waiting, tracking, extrapolating, stopping or stopped"},
    "leader": {
      "type": "object",
      "description": "fleet only: the leader motion the law used",
      "properties": {
        "x": {"type": "number"}, "y": {"type": "number"},
        "vx": {"type": "number"}, "vy": {"type": "number"},
        "ax": {"type": "number"}, "ay": {"type": "number"}
      }
    }
  },
  "required": ["t", "agent", "x", "y", "theta", "v", "omega", "ex", "ey", "zx", "zy", "u1", "u2", "tau_r", "tau_l"]
}"#,
};

/// Schema of `/reference` messages ([`ReferenceRecord`]).
pub const REFERENCE: JsonSchema = JsonSchema {
    name: "echelon.Reference",
    schema: r#"{
  "$schema": "http://json-schema.org/draft-07/schema#",
  "title": "echelon.Reference",
  "description": "The virtual leader at one instant: position p_d, velocity and acceleration, speed V_d and turn rate omega_d. SI units.",
  "type": "object",
  "properties": {
    "t": {"type": "number", "description": "time, s"},
    "seq": {"type": "integer", "description": "fleet only: the leader's sequence number"},
    "x": {"type": "number"}, "y": {"type": "number"},
    "vx": {"type": "number"}, "vy": {"type": "number"},
    "ax": {"type": "number"}, "ay": {"type": "number"},
    "speed": {"type": "number", "description": "V_d, m/s"},
    "turn_rate": {"type": "number", "description": "omega_d, rad/s"}
  },
  "required": ["t", "x", "y", "vx", "vy", "ax", "ay", "speed", "turn_rate"]
}"#,
};

/// The leader motion a fleet robot's law used.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LeaderRecord {
    /// `p_d`, m.
    pub x: f64,
    /// `p_d`, m.
    pub y: f64,
    /// `ṗ_d`, m/s.
    pub vx: f64,
    /// `ṗ_d`, m/s.
    pub vy: f64,
    /// `p̈_d`, m/s².
    pub ax: f64,
    /// `p̈_d`, m/s².
    pub ay: f64,
}

/// One `/agent/K/state` message.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AgentStateRecord {
    /// Time, s.
    pub t: f64,
    /// Agent number from 1.
    pub agent: u32,
    /// m.
    pub x: f64,
    /// m.
    pub y: f64,
    /// Heading, rad, wrapped to (−π, π].
    pub theta: f64,
    /// m/s.
    pub v: f64,
    /// rad/s.
    pub omega: f64,
    /// `e_x`, m.
    pub ex: f64,
    /// `e_y`, m.
    pub ey: f64,
    /// `z_x`, m/s.
    pub zx: f64,
    /// `z_y`, m/s.
    pub zy: f64,
    /// N.
    pub u1: f64,
    /// N m.
    pub u2: f64,
    /// N m.
    pub tau_r: f64,
    /// N m.
    pub tau_l: f64,
    /// ‖e‖, m.
    pub error_norm: f64,
    /// Fleet: the robot's sequence number.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub seq: Option<u64>,
    /// Fleet: link status.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub link: Option<&'static str>,
    /// Fleet: the leader motion used.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub leader: Option<LeaderRecord>,
}

impl AgentStateRecord {
    /// The simulator's view of agent `agent` (from 1) at `t`: state, errors,
    /// applied input and torques (θ wrapped); fleet fields empty.
    pub fn new(t: f64, agent: u32, s: &State, o: &AgentOutput) -> AgentStateRecord {
        AgentStateRecord {
            t,
            agent,
            x: s.x,
            y: s.y,
            theta: wrap_angle(s.theta),
            v: s.v,
            omega: s.omega,
            ex: o.e[0],
            ey: o.e[1],
            zx: o.z[0],
            zy: o.z[1],
            u1: o.u.u1,
            u2: o.u.u2,
            tau_r: o.tau.right,
            tau_l: o.tau.left,
            error_norm: o.e[0].hypot(o.e[1]),
            seq: None,
            link: None,
            leader: None,
        }
    }
}

/// One `/reference` message.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ReferenceRecord {
    /// Time, s.
    pub t: f64,
    /// Fleet: the leader's sequence number.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub seq: Option<u64>,
    /// `p_d`, m.
    pub x: f64,
    /// `p_d`, m.
    pub y: f64,
    /// `ṗ_d`, m/s.
    pub vx: f64,
    /// `ṗ_d`, m/s.
    pub vy: f64,
    /// `p̈_d`, m/s².
    pub ax: f64,
    /// `p̈_d`, m/s².
    pub ay: f64,
    /// `V_d`, m/s.
    pub speed: f64,
    /// `ω_d`, rad/s.
    pub turn_rate: f64,
}

/// The topic of agent `k` (from 1).
pub fn agent_topic(k: usize) -> String {
    format!("/agent/{k}/state")
}

/// The reference topic.
pub const REFERENCE_TOPIC: &str = "/reference";

/// A time in seconds as MCAP nanoseconds (negative and non-finite times as 0).
pub fn nanos(t: f64) -> u64 {
    if t.is_finite() && t > 0.0 {
        (t * 1e9).round() as u64
    } else {
        0
    }
}

/// An MCAP file being written: JSON channels registered by topic.
pub struct McapLog<W: Write + Seek> {
    writer: mcap::Writer<W>,
    schemas: BTreeMap<&'static str, u16>,
    channels: BTreeMap<String, u16>,
    messages: u64,
}

impl<W: Write + Seek> std::fmt::Debug for McapLog<W> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("McapLog")
            .field("channels", &self.channels)
            .field("messages", &self.messages)
            .finish_non_exhaustive()
    }
}

impl McapLog<BufWriter<File>> {
    /// Creates (truncates) `path`.
    pub fn create(path: &Path) -> Result<Self, McapLogError> {
        let file = File::create(path).map_err(|source| McapLogError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        McapLog::new(BufWriter::with_capacity(1 << 16, file))
    }
}

impl<W: Write + Seek> McapLog<W> {
    /// Starts an MCAP stream on `w` (uncompressed chunks, profile empty,
    /// deterministic: the same messages give the same bytes).
    pub fn new(w: W) -> Result<Self, McapLogError> {
        let writer = mcap::WriteOptions::new()
            .compression(None)
            .library(concat!("echelon-mcap ", env!("CARGO_PKG_VERSION")))
            .create(w)?;
        Ok(McapLog {
            writer,
            schemas: BTreeMap::new(),
            channels: BTreeMap::new(),
            messages: 0,
        })
    }

    /// The channel id of `topic` with `schema`, registering both on first use.
    pub fn channel(&mut self, topic: &str, schema: &JsonSchema) -> Result<u16, McapLogError> {
        if let Some(&id) = self.channels.get(topic) {
            return Ok(id);
        }
        let schema_id = match self.schemas.get(schema.name) {
            Some(&id) => id,
            None => {
                let id =
                    self.writer
                        .add_schema(schema.name, "jsonschema", schema.schema.as_bytes())?;
                self.schemas.insert(schema.name, id);
                id
            }
        };
        let id = self
            .writer
            .add_channel(schema_id, topic, "json", &BTreeMap::new())?;
        self.channels.insert(topic.to_owned(), id);
        Ok(id)
    }

    /// Writes one message (already JSON) on a channel.
    pub fn write(
        &mut self,
        channel: u16,
        sequence: u32,
        log_time: u64,
        publish_time: u64,
        data: &[u8],
    ) -> Result<(), McapLogError> {
        self.writer.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: channel,
                sequence,
                log_time,
                publish_time,
            },
            data,
        )?;
        self.messages += 1;
        Ok(())
    }

    /// Serialises `record` as JSON and writes it.
    pub fn write_json<T: Serialize>(
        &mut self,
        channel: u16,
        sequence: u32,
        log_time: u64,
        publish_time: u64,
        record: &T,
    ) -> Result<(), McapLogError> {
        let data = serde_json::to_vec(record)?;
        self.write(channel, sequence, log_time, publish_time, &data)
    }

    /// Messages written so far.
    pub fn messages(&self) -> u64 {
        self.messages
    }

    /// Writes the summary and footer, flushes, and returns the sink.
    pub fn finish(mut self) -> Result<W, McapLogError> {
        self.writer.finish()?;
        let mut w = self.writer.into_inner();
        w.flush().map_err(|source| McapLogError::Io {
            path: PathBuf::new(),
            source,
        })?;
        Ok(w)
    }
}

/// An [`Observer`] writing a simulation to MCAP (`echelon run --mcap`): the
/// reference and every agent, every `every`-th step and the last, like
/// `trajectory.csv`.
pub struct McapObserver<W: Write + Seek> {
    log: McapLog<W>,
    every: u64,
    reference: Reference,
    reference_channel: u16,
    agent_channels: Vec<u16>,
    sequence: u32,
}

impl<W: Write + Seek> std::fmt::Debug for McapObserver<W> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("McapObserver")
            .field("log", &self.log)
            .field("every", &self.every)
            .finish_non_exhaustive()
    }
}

impl<W: Write + Seek> McapObserver<W> {
    /// Logs `agents` robots following `reference`, every `every` steps.
    pub fn new(
        w: W,
        reference: Reference,
        agents: usize,
        every: u64,
    ) -> Result<Self, McapLogError> {
        let mut log = McapLog::new(w)?;
        let reference_channel = log.channel(REFERENCE_TOPIC, &REFERENCE)?;
        let agent_channels = (1..=agents)
            .map(|k| log.channel(&agent_topic(k), &AGENT_STATE))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(McapObserver {
            log,
            every,
            reference,
            reference_channel,
            agent_channels,
            sequence: 0,
        })
    }

    /// Finishes the file and returns the sink.
    pub fn finish(self) -> Result<W, McapLogError> {
        self.log.finish()
    }

    /// Messages written so far.
    pub fn messages(&self) -> u64 {
        self.log.messages()
    }
}

impl<W: Write + Seek> Observer for McapObserver<W> {
    fn observe(&mut self, frame: &Frame<'_>) -> Result<(), ObserverError> {
        if !frame.is_logged(self.every) {
            return Ok(());
        }
        let time = nanos(frame.t);
        let seq = self.sequence;
        self.sequence = self.sequence.wrapping_add(1);
        let jet = self.reference.eval(frame.t, Order::Two);
        let reference = ReferenceRecord {
            t: frame.t,
            seq: None,
            x: jet.p[0],
            y: jet.p[1],
            vx: jet.dp[0],
            vy: jet.dp[1],
            ax: jet.ddp[0],
            ay: jet.ddp[1],
            speed: jet.speed(),
            turn_rate: jet.turn_rate(),
        };
        self.log
            .write_json(self.reference_channel, seq, time, time, &reference)?;
        for (i, (s, o)) in frame.states.iter().zip(frame.outputs).enumerate() {
            let record = AgentStateRecord::new(frame.t, (i + 1) as u32, s, o);
            self.log
                .write_json(self.agent_channels[i], seq, time, time, &record)?;
        }
        Ok(())
    }
}
