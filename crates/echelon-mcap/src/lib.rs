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
//! | `/tf`, `/scene`, `/scene/static` | `foxglove.FrameTransforms`, `foxglove.SceneUpdate` (protobuf) | the 3D channels ([`scene`]): each robot's pose, body, slot, leader link and safety circle; the reference path and obstacles |
//!
//! Times: `publish_time` is the run's (or fleet's) time `t` in nanoseconds;
//! `log_time` is `t` too for a simulation, the collector's UNIX receive time for
//! a fleet.
//!
//! A fleet log may also hold ROS 2 channels ([`McapLog::ros2_channel`]):
//! the raw CDR messages of ROS topics, written as `ros2 bag record -s mcap`
//! writes them (schema encoding `ros2msg` with the full message definition,
//! message encoding `cdr`, channel metadata `offered_qos_profiles` and
//! `topic_type_hash`), so ROS 2 tools and Foxglove decode them.

#![cfg_attr(not(test), warn(clippy::too_many_lines))]

pub mod bag;
mod observer;
mod records;
pub mod scene;

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{self, BufWriter, Seek, Write};
use std::path::{Path, PathBuf};

use serde::Serialize;

pub use observer::McapObserver;
pub use records::{
    AGENT_STATE, AgentStateRecord, CDR, JsonSchema, LeaderRecord, OdometryRecord, REFERENCE,
    REFERENCE_TOPIC, ROS2MSG, ReferenceRecord, Ros2Schema, agent_topic,
};

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
    /// A Foxglove message could not be encoded.
    #[error("Foxglove message: {0}")]
    Encode(String),
    /// A topic already has a channel of another schema.
    #[error("topic `{topic}` already has schema `{registered}`, not `{requested}`")]
    TopicSchema {
        /// The topic.
        topic: String,
        /// The schema it was registered with.
        registered: String,
        /// The schema asked for now.
        requested: String,
    },
}

/// A time in seconds as MCAP nanoseconds (negative and non-finite times as 0).
pub fn nanos(t: f64) -> u64 {
    if t.is_finite() && t > 0.0 {
        (t * 1e9).round() as u64
    } else {
        0
    }
}

/// An MCAP file being written: JSON and ROS 2 channels registered by topic.
pub struct McapLog<W: Write + Seek> {
    writer: mcap::Writer<W>,
    /// By (schema encoding, name).
    schemas: BTreeMap<(String, String), u16>,
    /// By topic: channel id and schema name.
    channels: BTreeMap<String, (u16, String)>,
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
    /// A topic already registered with another schema is refused.
    pub fn channel(&mut self, topic: &str, schema: &JsonSchema) -> Result<u16, McapLogError> {
        if let Some(id) = self.existing(topic, schema.name)? {
            return Ok(id);
        }
        let schema_id = self.schema("jsonschema", schema.name, schema.schema.as_bytes())?;
        self.add_channel(topic, schema.name, schema_id, "json", BTreeMap::new())
    }

    /// The channel id of the ROS 2 topic `topic` (e.g. `/robot1/cmd_vel`)
    /// carrying `schema`, registering both on first use exactly as rosbag2's
    /// MCAP storage does: schema `schema.name` of encoding [`ROS2MSG`] whose
    /// data is the full definition, channel of message encoding [`CDR`] with
    /// metadata `offered_qos_profiles` (rosbag2's YAML list of QoS profiles)
    /// and `topic_type_hash`. A topic already registered with another schema
    /// is refused.
    pub fn ros2_channel(
        &mut self,
        topic: &str,
        schema: &Ros2Schema,
        offered_qos_profiles: &str,
    ) -> Result<u16, McapLogError> {
        if let Some(id) = self.existing(topic, schema.name)? {
            return Ok(id);
        }
        let schema_id = self.schema(ROS2MSG, schema.name, schema.definition.as_bytes())?;
        let metadata = BTreeMap::from([
            (
                "offered_qos_profiles".to_owned(),
                offered_qos_profiles.to_owned(),
            ),
            ("topic_type_hash".to_owned(), schema.type_hash.to_owned()),
        ]);
        self.add_channel(topic, schema.name, schema_id, CDR, metadata)
    }

    /// The channel id of `topic` carrying Foxglove's well-known message
    /// type `T` (e.g. `foxglove::messages::FrameTransforms`), registering
    /// both on first use with the schema and message encoding the `foxglove`
    /// crate gives (`protobuf`, its file descriptor set): what Foxglove's 3D
    /// panel draws. A topic already registered with another schema is refused.
    pub fn foxglove_channel<T: foxglove::Encode>(
        &mut self,
        topic: &str,
    ) -> Result<u16, McapLogError> {
        let schema = T::get_schema().ok_or_else(|| {
            McapLogError::Encode(format!("{topic}: the message type has no schema"))
        })?;
        if let Some(id) = self.existing(topic, &schema.name)? {
            return Ok(id);
        }
        let schema_id = self.schema(&schema.encoding, &schema.name, &schema.data)?;
        let encoding = T::get_message_encoding();
        self.add_channel(topic, &schema.name, schema_id, &encoding, BTreeMap::new())
    }

    fn existing(&self, topic: &str, schema: &str) -> Result<Option<u16>, McapLogError> {
        match self.channels.get(topic) {
            Some((id, registered)) if registered == schema => Ok(Some(*id)),
            Some((_, registered)) => Err(McapLogError::TopicSchema {
                topic: topic.to_owned(),
                registered: registered.clone(),
                requested: schema.to_owned(),
            }),
            None => Ok(None),
        }
    }

    fn schema(&mut self, encoding: &str, name: &str, data: &[u8]) -> Result<u16, McapLogError> {
        let key = (encoding.to_owned(), name.to_owned());
        if let Some(&id) = self.schemas.get(&key) {
            return Ok(id);
        }
        let id = self.writer.add_schema(name, encoding, data)?;
        self.schemas.insert(key, id);
        Ok(id)
    }

    fn add_channel(
        &mut self,
        topic: &str,
        schema_name: &str,
        schema_id: u16,
        message_encoding: &str,
        metadata: BTreeMap<String, String>,
    ) -> Result<u16, McapLogError> {
        let id = self
            .writer
            .add_channel(schema_id, topic, message_encoding, &metadata)?;
        self.channels
            .insert(topic.to_owned(), (id, schema_name.to_owned()));
        Ok(id)
    }

    /// Writes one message (already encoded: JSON, or CDR on a ROS 2 channel).
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

    /// Writes a metadata record `name` holding `map`.
    pub fn metadata(
        &mut self,
        name: &str,
        map: BTreeMap<String, String>,
    ) -> Result<(), McapLogError> {
        self.writer.write_metadata(&mcap::records::Metadata {
            name: name.to_owned(),
            metadata: map,
        })?;
        Ok(())
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

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use std::collections::BTreeSet;
    use std::io::Cursor;

    use echelon::sample::AgentSample;
    use echelon::scenario::{Overrides, Scenario};
    use echelon::sim::Every;
    use serde_json::Value;

    use super::*;

    /// The JSON type names `value` may carry (a whole number is also a number).
    fn types_of(value: &Value) -> Vec<&'static str> {
        match value {
            Value::Null => vec!["null"],
            Value::Bool(_) => vec!["boolean"],
            Value::Number(n) if n.is_f64() => vec!["number"],
            Value::Number(_) => vec!["integer", "number"],
            Value::String(_) => vec!["string"],
            Value::Array(_) => vec!["array"],
            Value::Object(_) => vec!["object"],
        }
    }

    /// Checks `value` against the subset of JSON Schema the derived schemas
    /// use (`type`, `properties`, `required`, `minimum`); names where it fails.
    fn conforms(value: &Value, schema: &Value, at: &str) -> Result<(), String> {
        let allowed: Vec<&str> = match &schema["type"] {
            Value::String(t) => vec![t.as_str()],
            Value::Array(ts) => ts.iter().filter_map(Value::as_str).collect(),
            other => return Err(format!("{at}: schema without a type: {other}")),
        };
        if !types_of(value).iter().any(|t| allowed.contains(t)) {
            return Err(format!("{at}: {value} is not of type {allowed:?}"));
        }
        if let (Some(min), Some(v)) = (schema["minimum"].as_f64(), value.as_f64())
            && v < min
        {
            return Err(format!("{at}: {v} < minimum {min}"));
        }
        if let Value::Object(fields) = value {
            let properties = schema["properties"]
                .as_object()
                .ok_or_else(|| format!("{at}: an object schema without properties"))?;
            for (k, v) in fields {
                let sub = properties
                    .get(k)
                    .ok_or_else(|| format!("{at}: field `{k}` is not in the schema"))?;
                conforms(v, sub, &format!("{at}.{k}"))?;
            }
            for r in schema["required"].as_array().into_iter().flatten() {
                let r = r.as_str().unwrap();
                if !fields.contains_key(r) {
                    return Err(format!("{at}: required field `{r}` missing"));
                }
            }
        }
        Ok(())
    }

    /// The paper's circle experiment, `duration` s long.
    fn circle(duration: f64) -> echelon::Run {
        scenario("experiment-circle", duration)
    }

    /// The built-in scenario `name`, `duration` s long.
    fn scenario(name: &str, duration: f64) -> echelon::Run {
        Scenario::builtin(name)
            .unwrap()
            .build(&Overrides {
                duration: Some(duration),
                ..Overrides::default()
            })
            .unwrap()
    }

    fn keys(v: &Value) -> BTreeSet<String> {
        v.as_object().unwrap().keys().cloned().collect()
    }

    fn schema(s: &JsonSchema) -> Value {
        serde_json::from_str(&s.schema).unwrap()
    }

    /// A fleet record of a velocity base: every field there is.
    fn fleet_state() -> AgentStateRecord {
        let mut record = AgentStateRecord {
            seq: Some(7),
            link: Some("tracking"),
            leader: Some(LeaderRecord {
                x: 1.0,
                y: 2.0,
                vx: 0.5,
                vy: -0.5,
                ax: 0.0,
                ay: 0.25,
            }),
            odometry: Some(OdometryRecord {
                raw: [0.5, -0.25, 6.5],
                age: 0.01,
                fix_age: Some(0.05),
            }),
            sigma: Some(0.02),
            ..AgentStateRecord::new(AgentSample::new(
                1.5,
                2,
                &echelon::State {
                    x: 1.0,
                    y: -1.0,
                    theta: 4.0,
                    v: 0.3,
                    omega: -0.1,
                },
                &echelon::sim::AgentOutput::default(),
            ))
        };
        record.sample.velocity = Some(echelon::sample::VelocitySample::default());
        record
    }

    #[test]
    fn schemas_have_exactly_the_serialised_fields() {
        let agent = schema(&AGENT_STATE);
        let full = serde_json::to_value(fleet_state()).unwrap();
        assert_eq!(keys(&agent["properties"]), keys(&full));
        assert_eq!(
            keys(&agent["properties"]["leader"]["properties"]),
            keys(&full["leader"])
        );
        // The fields a simulated run always writes are the required ones.
        let sim = serde_json::to_value(AgentStateRecord {
            seq: None,
            link: None,
            leader: None,
            odometry: None,
            sigma: None,
            sample: AgentSample {
                velocity: None,
                ..fleet_state().sample
            },
            ..fleet_state()
        })
        .unwrap();
        let required: BTreeSet<String> = agent["required"]
            .as_array()
            .unwrap()
            .iter()
            .map(|r| r.as_str().unwrap().to_owned())
            .collect();
        assert_eq!(required, keys(&sim));
        for record in [&full, &sim] {
            conforms(record, &agent, "AgentState").unwrap();
        }
        assert_eq!(agent["title"], "echelon.AgentState");

        let reference = schema(&REFERENCE);
        let fleet = ReferenceRecord {
            seq: Some(3),
            ..ReferenceRecord::at(circle(0.5).plan.reference(), 0.5)
        };
        let full = serde_json::to_value(fleet).unwrap();
        assert_eq!(keys(&reference["properties"]), keys(&full));
        conforms(&full, &reference, "Reference").unwrap();
        assert_eq!(reference["title"], "echelon.Reference");
    }

    #[test]
    fn the_checker_refuses_what_the_schema_does_not_describe() {
        let agent = schema(&AGENT_STATE);
        let mut record = serde_json::to_value(fleet_state()).unwrap();
        record["extra"] = Value::from(1.0);
        assert!(conforms(&record, &agent, "a").is_err());
        let mut record = serde_json::to_value(fleet_state()).unwrap();
        record["agent"] = Value::from("one");
        assert!(conforms(&record, &agent, "a").is_err());
        let mut record = serde_json::to_value(fleet_state()).unwrap();
        record.as_object_mut().unwrap().remove("t");
        assert!(conforms(&record, &agent, "a").is_err());
    }

    /// A simulated run through the observer, torque-driven or on velocity
    /// bases: every message conforms to its channel's schema, one message
    /// per channel per logged frame, and the file is finished (readable
    /// summary).
    #[test]
    fn every_message_of_a_run_conforms_to_its_channel_schema() {
        for name in ["experiment-circle", "experiment-circle-velocity"] {
            a_run_conforms(name);
        }
    }

    fn a_run_conforms(name: &str) {
        let run = scenario(name, 0.5);
        let velocity = run.plan.agents()[0].velocity_robot().is_some();
        let every = 7;
        let mut mcap = Every::new(every, McapObserver::new(Cursor::new(Vec::new())).unwrap());
        run.simulation().run(&mut mcap).unwrap();
        let bytes = mcap.into_inner().into_inner().unwrap().into_inner();
        let steps = run.plan.steps();
        let frames = steps / every + 1 + u64::from(!steps.is_multiple_of(every));
        let mut counts: BTreeMap<String, u64> = BTreeMap::new();
        let mut scene_counts: BTreeMap<String, u64> = BTreeMap::new();
        for m in mcap::MessageStream::new(&bytes).unwrap() {
            let m = m.unwrap();
            let schema = m.channel.schema.as_ref().unwrap();
            if schema.encoding != "jsonschema" {
                // The 3D channels: Foxglove's schemas, checked in scene's tests.
                assert_eq!(
                    (
                        schema.encoding.as_str(),
                        m.channel.message_encoding.as_str()
                    ),
                    ("protobuf", "protobuf")
                );
                *scene_counts.entry(m.channel.topic.clone()).or_default() += 1;
                continue;
            }
            let schema: Value = serde_json::from_slice(&schema.data).unwrap();
            let record: Value = serde_json::from_slice(&m.data).unwrap();
            conforms(&record, &schema, &m.channel.topic).unwrap();
            if m.channel.topic != REFERENCE_TOPIC {
                assert_eq!(record.get("v_cmd").is_some(), velocity, "{record}");
            }
            *counts.entry(m.channel.topic.clone()).or_default() += 1;
        }
        let agents = run.plan.agents().len();
        assert_eq!(counts.len(), agents + 1);
        assert!(counts.values().all(|&n| n == frames), "{counts:?}");
        let agents = agents as u64;
        assert_eq!(
            scene_counts,
            BTreeMap::from([
                (scene::TF_TOPIC.to_owned(), frames * agents),
                (scene::SCENE_TOPIC.to_owned(), frames * agents),
                (scene::SCENE_STATIC_TOPIC.to_owned(), 1),
            ])
        );
        let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
        assert_eq!(
            summary.stats.unwrap().message_count,
            frames * (agents + 1) + 2 * frames * agents + 1
        );
    }

    /// A ROS 2 channel as rosbag2 writes it, next to a JSON one: schema
    /// `ros2msg` with the definition, channel `cdr` with its metadata, the
    /// bytes as given; one schema for two topics of a type; a topic cannot
    /// change schema.
    #[test]
    fn ros2_channels_are_written_as_rosbag2_writes_them() {
        const TWIST: Ros2Schema = Ros2Schema {
            name: "geometry_msgs/msg/Twist",
            definition: "Vector3  linear\nVector3  angular\n\n\
                ================================================================================\n\
                MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n",
            type_hash: "RIHS01_00",
        };
        let mut log = McapLog::new(Cursor::new(Vec::new())).unwrap();
        let json = log.channel(REFERENCE_TOPIC, &REFERENCE).unwrap();
        let a = log
            .ros2_channel("/a/cmd_vel", &TWIST, "- depth: 10")
            .unwrap();
        let b = log.ros2_channel("/b/cmd_vel", &TWIST, "[]").unwrap();
        assert_eq!(log.ros2_channel("/a/cmd_vel", &TWIST, "x").unwrap(), a);
        let clash = log.ros2_channel(REFERENCE_TOPIC, &TWIST, "[]").unwrap_err();
        assert!(
            matches!(&clash, McapLogError::TopicSchema { registered, .. } if registered == "echelon.Reference"),
            "{clash}"
        );
        assert!(log.channel("/a/cmd_vel", &REFERENCE).is_err());
        let payload = [0u8, 1, 0, 0, 0xaa, 0xbb];
        log.write(a, 0, 10, 5, &payload).unwrap();
        log.write(b, 0, 11, 6, &payload[..4]).unwrap();
        log.write_json(json, 0, 12, 12, &serde_json::json!({}))
            .unwrap();
        let bytes = log.finish().unwrap().into_inner();

        let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
        assert_eq!(summary.schemas.len(), 2);
        let mut seen = 0;
        for m in mcap::MessageStream::new(&bytes).unwrap() {
            let m = m.unwrap();
            let schema = m.channel.schema.as_ref().unwrap();
            if m.channel.topic == REFERENCE_TOPIC {
                assert_eq!(
                    (
                        m.channel.message_encoding.as_str(),
                        schema.encoding.as_str()
                    ),
                    ("json", "jsonschema")
                );
                assert!(m.channel.metadata.is_empty());
                continue;
            }
            seen += 1;
            assert_eq!(m.channel.message_encoding, CDR);
            assert_eq!(schema.encoding, ROS2MSG);
            assert_eq!(schema.name, TWIST.name);
            assert_eq!(&schema.data[..], TWIST.definition.as_bytes());
            assert_eq!(m.channel.metadata["topic_type_hash"], "RIHS01_00");
            let (qos, len, times) = if m.channel.topic == "/a/cmd_vel" {
                ("- depth: 10", 6, (10, 5))
            } else {
                ("[]", 4, (11, 6))
            };
            assert_eq!(m.channel.metadata["offered_qos_profiles"], qos);
            assert_eq!(&m.data[..], &payload[..len]);
            assert_eq!((m.log_time, m.publish_time), times);
        }
        assert_eq!(seen, 2);
    }
}
