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
mod tests;
