//! `echelon fleet collector`: records everything published under
//! `echelon/<fleet>/**` (paper section 5's data collector).
//!
//! Every sample that reaches it is logged to `fleet.mcap` exactly once: valid
//! messages on their typed channel (`/reference`, `/agent/K/state`,
//! `/agent/K/stats`), anything else on `/rejected` with the key, the reason and
//! the bytes. Robot states (once started) also go to `trajectory.csv` with the
//! simulator's header. On SIGINT/SIGTERM it stops listening, logs what is still
//! queued, and closes valid files.
//!
//! Given ROS 2 topics ([`RosTopic`], e.g. every robot's `cmd_vel` and
//! `odom`), it also records them as `ros2 bag record -s mcap` does: one
//! channel per topic named like it (`/robot1/cmd_vel`), the raw CDR bytes as
//! received, schema `ros2msg` with the full message definition, `log_time`
//! the receipt time and `publish_time` the rmw_zenoh attachment's source
//! timestamp. Whoever published them (echelon or a real robot), a sample of
//! the wrong type (key) or with an invalid CDR payload is refused: counted
//! and logged on `/rejected` instead.

use std::borrow::Cow;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::fs::File;
use std::io::BufWriter;
use std::path::PathBuf;
use std::time::Duration;

use serde::Serialize;

use echelon::csv::CsvWriter;
use echelon::output::{FrameRows, TRAJECTORY_FILE, TrajectoryRows};
use echelon::sample::AgentSample;
use echelon::stats::{AgentStats, Summary};
use echelon_mcap::{
    AGENT_STATE, AgentStateRecord, JsonSchema, LeaderRecord, McapLog, REFERENCE, REFERENCE_TOPIC,
    ReferenceRecord, agent_topic, nanos,
};

use crate::clock::FleetClock;
use crate::keys::{KeyKind, Keys};
use crate::latency::{Latency, LatencyReport};
use crate::net::NetOptions;
use crate::role::Member;
use crate::ros2::record::{self, RosTopic, RosTopicError};
use crate::runtime::{self, Flow, Outputs, Sample, Task};
use crate::wire::{self, DecodeError, LinkStatus, Message, RobotState};
use crate::{FleetError, StopFlag, unix_nanos};

/// The MCAP file the collector writes.
pub const MCAP_FILE: &str = "fleet.mcap";
/// The collector's summary.
pub const SUMMARY_FILE: &str = "collector.json";
/// Name of the MCAP metadata record holding the per-key latency summaries
/// (each key's value: its [`LatencyReport`] as JSON).
pub const LATENCY_METADATA: &str = "echelon.latency";
/// Topic of everything that was not a valid message of its key.
pub const REJECTED_TOPIC: &str = "/rejected";

/// Schema of `/rejected`.
pub const REJECTED: JsonSchema = JsonSchema {
    name: "echelon.Rejected",
    schema: Cow::Borrowed(
        r#"{
  "$schema": "http://json-schema.org/draft-07/schema#",
  "title": "echelon.Rejected",
  "description": "A sample received under the fleet's keys that was not a valid message for its key.",
  "type": "object",
  "properties": {
    "key": {"type": "string"},
    "reason": {"type": "string"},
    "size": {"type": "integer"},
    "hex": {"type": "string", "description": "the payload, hexadecimal (first 1024 bytes)"}
  },
  "required": ["key", "reason", "size", "hex"]
}"#,
    ),
};

/// Schema of `/agent/K/stats` (a robot's counters, as it published them).
pub const STATS: JsonSchema = JsonSchema {
    name: "echelon.RobotStats",
    schema: Cow::Borrowed(
        r#"{
  "$schema": "http://json-schema.org/draft-07/schema#",
  "title": "echelon.RobotStats",
  "description": "A robot's receive counters and link status (docs/fleet.md).",
  "type": "object",
  "properties": {
    "agent": {"type": "integer"},
    "t": {"type": "number"},
    "link": {"type": "string"},
    "counters": {"type": "object"},
    "published": {"type": "integer"},
    "overruns": {"type": "integer"},
    "safety": {"type": "object", "description": "with [safety]: the filter's counters so far (steps, active, infeasible, stale_brakes, deadlock_breaks, stale_neighbours, lagging, refused, min_distance)"}
  },
  "required": ["agent", "t", "link", "counters"]
}"#,
    ),
};

/// Options of the collector.
#[derive(Debug, Clone)]
pub struct CollectorOptions {
    /// Output directory.
    pub out: PathBuf,
    /// Fleet name.
    pub fleet: String,
    /// Stop after this long of real time (absent: run until a signal).
    pub max_wall: Option<Duration>,
    /// Network.
    pub net: NetOptions,
}

/// Per-agent statistics of the recorded states (once started), from the
/// simulator's accumulator ([`AgentStats`]).
#[derive(Debug, Clone, Default, Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AgentRecord {
    /// Agent number, from 1.
    pub agent: u32,
    /// State messages recorded (started or not).
    pub messages: u64,
    /// Rows written to `trajectory.csv`.
    pub rows: u64,
    /// Fleet time of the last state, s.
    pub t: f64,
    /// Last state `[x, y, θ, v, ω]` (θ wrapped to (−π, π]).
    pub final_state: [f64; 5],
    /// Last ‖e‖, m.
    pub final_error: f64,
    /// RMS of ‖e‖ over the rows, m.
    pub rms_error: f64,
    /// Largest wheel torque magnitude, N m.
    pub peak_torque: f64,
    /// Last link status.
    pub link: String,
    #[serde(skip)]
    stats: AgentStats,
}

impl AgentRecord {
    /// Adds a started robot's sample: a row, and the statistics.
    fn add(&mut self, s: &AgentSample) {
        self.stats.add(s, Summary::SETTLE_TOLERANCE);
        self.rows = self.stats.samples();
        self.t = s.t;
        self.final_state = [s.x, s.y, s.theta, s.v, s.omega];
        self.final_error = self.stats.final_error();
        self.rms_error = self.stats.rms_error();
        self.peak_torque = self.stats.peak_torque();
    }
}

/// What the collector reports (`collector.json`, and one JSON line on stdout).
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CollectorReport {
    /// [`crate::role::Role::Collector`].
    pub role: crate::role::Role,
    /// Samples received, total.
    pub received: u64,
    /// Messages logged to the MCAP file, total (equals `received`).
    pub logged: u64,
    /// Samples received per key.
    pub received_by_key: BTreeMap<String, u64>,
    /// Messages logged per MCAP topic.
    pub logged_by_topic: BTreeMap<String, u64>,
    /// Rejected samples per reason.
    pub rejected: BTreeMap<String, u64>,
    /// ROS 2 samples recorded on their topic's channel.
    pub ros_recorded: u64,
    /// ROS 2 samples refused (wrong type or hash on the key, invalid CDR,
    /// a key of no recorded topic); also counted in `rejected` by reason.
    pub ros_refused: u64,
    /// Delay from the sender's timestamp to receipt of every sample
    /// received, s (`count + unstamped` equals `received`): the Zenoh sample
    /// timestamp, or for a ROS 2 sample without one its rmw_zenoh
    /// attachment's source timestamp.
    pub latency: LatencyReport,
    /// The same per key.
    pub latency_by_key: BTreeMap<String, LatencyReport>,
    /// Per agent.
    pub agents: Vec<AgentRecord>,
}

/// Where the collector's records go: the files ([`run`]), or memory in tests.
pub trait RecordSink {
    /// Logs one MCAP message on `topic` (received at UNIX ns `log_time`, sent
    /// at `publish_time`).
    fn log(
        &mut self,
        topic: &str,
        schema: &JsonSchema,
        log_time: u64,
        publish_time: u64,
        data: &[u8],
    ) -> Result<(), FleetError>;
    /// Logs one ROS 2 message (CDR bytes as received) on the channel of
    /// `topic` (received at UNIX ns `log_time`, published at `publish_time`).
    fn log_ros(
        &mut self,
        topic: &RosTopic,
        log_time: u64,
        publish_time: u64,
        data: &[u8],
    ) -> Result<(), FleetError>;
    /// Appends one `trajectory.csv` row.
    fn row(&mut self, sample: &AgentSample) -> Result<(), FleetError>;
}

/// The collector as a state machine: every sample received goes in through
/// [`Collector::on_message`] with the time it arrived, and comes out as
/// records in a [`RecordSink`]; it counts everything. It reads no clock and
/// opens no file.
pub struct Collector {
    keys: Keys,
    ros: Vec<RosTopic>,
    report: CollectorReport,
    agents: BTreeMap<u32, AgentRecord>,
    latency: Latency,
    latency_by_key: BTreeMap<String, Latency>,
}

fn bump(counts: &mut BTreeMap<String, u64>, name: &str) {
    *counts.entry(name.to_owned()).or_insert(0) += 1;
}

fn hex(bytes: &[u8]) -> String {
    let mut s = String::with_capacity(2 * bytes.len().min(1024));
    for b in bytes.iter().take(1024) {
        let _ = write!(s, "{b:02x}");
    }
    s
}

impl std::fmt::Debug for Collector {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Collector")
            .field("keys", &self.keys)
            .field("ros", &self.ros)
            .field("report", &self.report)
            .finish_non_exhaustive()
    }
}

impl Collector {
    /// A collector of fleet `keys`.
    pub fn new(keys: Keys) -> Collector {
        Collector {
            keys,
            ros: Vec::new(),
            report: CollectorReport {
                role: crate::role::Role::Collector,
                received: 0,
                logged: 0,
                received_by_key: BTreeMap::new(),
                logged_by_topic: BTreeMap::new(),
                rejected: BTreeMap::new(),
                ros_recorded: 0,
                ros_refused: 0,
                latency: LatencyReport::default(),
                latency_by_key: BTreeMap::new(),
                agents: Vec::new(),
            },
            agents: BTreeMap::new(),
            latency: Latency::new(),
            latency_by_key: BTreeMap::new(),
        }
    }

    /// A collector of fleet `keys` that also records the ROS 2 topics
    /// `ros` ([`Collector::on_ros_sample`]). Refused: a topic listed twice,
    /// or named like one of echelon's channels.
    pub fn with_ros2(keys: Keys, ros: Vec<RosTopic>) -> Result<Collector, RosTopicError> {
        record::check_topics(&ros)?;
        Ok(Collector {
            ros,
            ..Collector::new(keys)
        })
    }

    /// The ROS 2 topics it records.
    pub fn ros_topics(&self) -> &[RosTopic] {
        &self.ros
    }

    /// Records a ROS 2 sample that arrived on `key` at UNIX ns `now`, with
    /// its Zenoh attachment if any: exactly one MCAP message, on the
    /// channel of the topic that owns `key` if the key names the topic's
    /// type and hash and the payload is a valid CDR message of that type
    /// (logged as received, `publish_time` the attachment's source
    /// timestamp, else `now`), otherwise on `/rejected` with the reason.
    pub fn on_ros_sample(
        &mut self,
        key: &str,
        bytes: &[u8],
        attachment: Option<&[u8]>,
        now: u64,
        sink: &mut impl RecordSink,
    ) -> Result<(), FleetError> {
        self.count_received(key);
        let Some(i) = self.ros.iter().position(|t| t.owns(key)) else {
            self.report.ros_refused += 1;
            return self.reject(sink, key, "ROS: key of no recorded topic", bytes, now);
        };
        if let Err(refusal) = self.ros[i].check(key, bytes) {
            self.report.ros_refused += 1;
            return self.reject(sink, key, refusal.reason(), bytes, now);
        }
        let topic = &self.ros[i];
        sink.log_ros(topic, now, record::publish_time(attachment, now), bytes)?;
        let name = topic.topic().to_owned();
        self.report.ros_recorded += 1;
        self.count_logged(&name);
        Ok(())
    }

    /// Records the delay of a sample received on `key` (call once per sample
    /// with [`Collector::on_message`] or [`Collector::on_ros_sample`];
    /// `None`: it was not stamped). Allocates only for a key's first sample.
    pub fn record_delay(&mut self, key: &str, delay: Option<i64>) {
        self.latency.record(delay);
        match self.latency_by_key.get_mut(key) {
            Some(l) => l.record(delay),
            None => {
                let mut l = Latency::new();
                l.record(delay);
                self.latency_by_key.insert(key.to_owned(), l);
            }
        }
    }

    /// What it counted so far (`agents` and the latencies are filled by
    /// [`Collector::finish`]).
    pub fn report(&self) -> &CollectorReport {
        &self.report
    }

    fn log(
        &mut self,
        sink: &mut impl RecordSink,
        topic: &str,
        schema: &JsonSchema,
        now: u64,
        publish_time: u64,
        data: &[u8],
    ) -> Result<(), FleetError> {
        sink.log(topic, schema, now, publish_time, data)?;
        self.count_logged(topic);
        Ok(())
    }

    fn count_logged(&mut self, topic: &str) {
        self.report.logged += 1;
        bump(&mut self.report.logged_by_topic, topic);
    }

    fn count_received(&mut self, key: &str) {
        self.report.received += 1;
        bump(&mut self.report.received_by_key, key);
    }

    fn reject(
        &mut self,
        sink: &mut impl RecordSink,
        key: &str,
        reason: &str,
        bytes: &[u8],
        now: u64,
    ) -> Result<(), FleetError> {
        bump(&mut self.report.rejected, reason);
        let record = serde_json::json!({
            "key": key, "reason": reason, "size": bytes.len(), "hex": hex(bytes),
        });
        let data = serde_json::to_vec(&record).map_err(echelon_mcap::McapLogError::from)?;
        self.log(sink, REJECTED_TOPIC, &REJECTED, now, 0, &data)
    }

    /// Records a sample that arrived on `key` at UNIX ns `now`: exactly one
    /// MCAP message (typed, or on `/rejected`), and a CSV row for a started
    /// robot's state.
    pub fn on_message(
        &mut self,
        key: &str,
        bytes: &[u8],
        now: u64,
        sink: &mut impl RecordSink,
    ) -> Result<(), FleetError> {
        self.count_received(key);
        let kind = self.keys.classify(key);
        if let KeyKind::Stats(k) = kind {
            return match serde_json::from_slice::<serde_json::Value>(bytes) {
                Ok(v) if v.get("agent").and_then(|a| a.as_u64()) == Some(u64::from(k)) => {
                    let t = v.get("t").and_then(|t| t.as_f64()).unwrap_or(0.0);
                    let topic = format!("/agent/{k}/stats");
                    self.log(sink, &topic, &STATS, now, nanos(t), bytes)
                }
                Ok(_) => self.reject(sink, key, "stats of another agent", bytes, now),
                Err(_) => self.reject(sink, key, "malformed stats JSON", bytes, now),
            };
        }
        let msg = match wire::decode(bytes) {
            Ok(m) => m,
            Err(DecodeError::Malformed(_)) => {
                return self.reject(sink, key, "malformed", bytes, now);
            }
            Err(DecodeError::WrongVersion(_)) => {
                return self.reject(sink, key, "wrong version", bytes, now);
            }
        };
        match (kind, msg) {
            (KeyKind::Reference, Message::Reference(h, r)) => {
                let rec = ReferenceRecord {
                    t: r.t,
                    seq: Some(h.seq),
                    motion: LeaderRecord::from(&r.motion),
                    speed: r.speed,
                    turn_rate: r.turn_rate,
                };
                let data = serde_json::to_vec(&rec).map_err(echelon_mcap::McapLogError::from)?;
                self.log(sink, REFERENCE_TOPIC, &REFERENCE, now, nanos(r.t), &data)
            }
            (KeyKind::State(k), Message::State(h, s)) if s.agent == k => {
                self.state(k, h.seq, &s, now, sink)
            }
            (KeyKind::Other, _) => self.reject(sink, key, "unknown key", bytes, now),
            _ => self.reject(
                sink,
                key,
                "message of the wrong kind for its key",
                bytes,
                now,
            ),
        }
    }

    fn state(
        &mut self,
        k: u32,
        seq: u64,
        s: &RobotState,
        now: u64,
        sink: &mut impl RecordSink,
    ) -> Result<(), FleetError> {
        let sample = s.sample();
        let rec = AgentStateRecord {
            seq: Some(seq),
            link: Some(s.link.name()),
            leader: Some(LeaderRecord::from(&s.leader)),
            ..AgentStateRecord::new(sample)
        };
        let data = serde_json::to_vec(&rec).map_err(echelon_mcap::McapLogError::from)?;
        self.log(
            sink,
            &agent_topic(k as usize),
            &AGENT_STATE,
            now,
            nanos(s.t),
            &data,
        )?;
        let a = self.agents.entry(k).or_insert_with(|| AgentRecord {
            agent: k,
            ..AgentRecord::default()
        });
        a.messages += 1;
        a.link = s.link.name().to_owned();
        if s.link == LinkStatus::Waiting {
            return Ok(());
        }
        a.add(&sample);
        sink.row(&sample)
    }

    /// The final report, with the per-agent records.
    pub fn finish(mut self) -> CollectorReport {
        self.report.agents = self.agents.into_values().collect();
        self.report.latency = self.latency.report(false);
        self.report.latency_by_key = self
            .latency_by_key
            .iter()
            .map(|(k, l)| (k.clone(), l.report(false)))
            .collect();
        self.report
    }
}

/// The collector's files: `fleet.mcap` and `trajectory.csv` in a directory.
pub struct FileSink {
    log: McapLog<BufWriter<File>>,
    seq: BTreeMap<u16, u32>,
    csv: CsvWriter<BufWriter<File>>,
    trajectory: TrajectoryRows,
    csv_path: PathBuf,
}

impl std::fmt::Debug for FileSink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FileSink")
            .field("log", &self.log)
            .field("csv_path", &self.csv_path)
            .finish_non_exhaustive()
    }
}

impl RecordSink for FileSink {
    fn log(
        &mut self,
        topic: &str,
        schema: &JsonSchema,
        log_time: u64,
        publish_time: u64,
        data: &[u8],
    ) -> Result<(), FleetError> {
        let id = self.log.channel(topic, schema)?;
        self.write(id, log_time, publish_time, data)
    }

    fn log_ros(
        &mut self,
        topic: &RosTopic,
        log_time: u64,
        publish_time: u64,
        data: &[u8],
    ) -> Result<(), FleetError> {
        let id =
            self.log
                .ros2_channel(topic.topic(), &topic.schema(), topic.offered_qos_profiles())?;
        self.write(id, log_time, publish_time, data)
    }

    fn row(&mut self, sample: &AgentSample) -> Result<(), FleetError> {
        self.trajectory
            .row(sample, &mut self.csv)
            .map_err(FleetError::io(&self.csv_path))
    }
}

impl FileSink {
    /// Writes one message on channel `id` with the channel's next sequence number.
    fn write(
        &mut self,
        id: u16,
        log_time: u64,
        publish_time: u64,
        data: &[u8],
    ) -> Result<(), FleetError> {
        let seq = self.seq.entry(id).or_insert(0);
        self.log.write(id, *seq, log_time, publish_time, data)?;
        *seq = seq.wrapping_add(1);
        Ok(())
    }

    /// Creates `out` if needed and the files [`MCAP_FILE`] and
    /// [`TRAJECTORY_FILE`] in it (truncated), the latter with the columns of
    /// a fleet of torque-driven robots ([`FileSink::with_trajectory`]).
    pub fn create(out: &std::path::Path) -> Result<FileSink, FleetError> {
        FileSink::with_trajectory(out, TrajectoryRows::default())
    }

    /// [`FileSink::create`], `trajectory.csv` with the columns of
    /// `trajectory` (those `echelon run` writes for the same scenario:
    /// [`TrajectoryRows::for_agents`]).
    pub fn with_trajectory(
        out: &std::path::Path,
        trajectory: TrajectoryRows,
    ) -> Result<FileSink, FleetError> {
        std::fs::create_dir_all(out).map_err(FleetError::io(out))?;
        let mcap_path = out.join(MCAP_FILE);
        let csv_path = out.join(TRAJECTORY_FILE);
        let log = McapLog::create(&mcap_path)?;
        let file = File::create(&csv_path).map_err(FleetError::io(&csv_path))?;
        let csv = CsvWriter::new(BufWriter::with_capacity(1 << 16, file), trajectory.header())
            .map_err(FleetError::io(&csv_path))?;
        Ok(FileSink {
            log,
            seq: BTreeMap::new(),
            csv,
            trajectory,
            csv_path,
        })
    }

    /// Writes the per-key latency summaries of `report` as the MCAP
    /// metadata record [`LATENCY_METADATA`].
    pub fn latency_metadata(&mut self, report: &CollectorReport) -> Result<(), FleetError> {
        let mut map = BTreeMap::new();
        for (key, l) in &report.latency_by_key {
            let json = serde_json::to_string(l).map_err(echelon_mcap::McapLogError::from)?;
            map.insert(key.clone(), json);
        }
        self.log.metadata(LATENCY_METADATA, map)?;
        Ok(())
    }

    /// Closes both files (MCAP summary and footer written).
    pub fn finish(mut self) -> Result<(), FleetError> {
        self.log.finish()?;
        self.csv.flush().map_err(FleetError::io(&self.csv_path))
    }
}

/// [`Collector`] as a [`Task`] of the fleet runtime: every fleet key (and
/// its ROS 2 topics) in, each sample recorded as soon as it arrives (and
/// those that arrived before its inputs closed); files closed and
/// `collector.json` written with its report.
pub struct CollectorTask {
    collector: Collector,
    sink: FileSink,
    out: PathBuf,
    /// Stop at this time of its clock (real time), s.
    until: f64,
    /// The wall clock (UNIX ns), for `log_time`.
    wall: fn() -> u64,
}

impl std::fmt::Debug for CollectorTask {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CollectorTask")
            .field("collector", &self.collector)
            .field("out", &self.out)
            .field("until", &self.until)
            .finish_non_exhaustive()
    }
}

/// Its input number of the fleet's keys (then one per ROS 2 topic).
const FLEET: usize = 0;

impl CollectorTask {
    /// `collector` recording to `sink`, its summary to `out`, for at most
    /// `max_wall` of real time.
    pub fn new(
        collector: Collector,
        sink: FileSink,
        out: PathBuf,
        max_wall: Option<Duration>,
    ) -> CollectorTask {
        CollectorTask {
            collector,
            sink,
            out,
            until: max_wall.map_or(f64::INFINITY, |m| m.as_secs_f64()),
            wall: unix_nanos,
        }
    }
}

impl Task for CollectorTask {
    type Report = CollectorReport;

    fn inputs(&self) -> Vec<String> {
        std::iter::once(self.collector.keys.everything())
            .chain(self.collector.ros_topics().iter().map(RosTopic::key_expr))
            .collect()
    }

    fn outputs(&self) -> Vec<String> {
        Vec::new()
    }

    fn tokens(&self) -> Vec<String> {
        vec![self.collector.keys.alive(&Member::Collector.liveliness())]
    }

    fn wakes_on_input(&self) -> bool {
        true
    }

    fn on_input(&mut self, input: usize, s: &Sample<'_>) -> Result<(), FleetError> {
        let now = (self.wall)();
        if input == FLEET {
            self.collector.record_delay(s.key, s.delay);
            return self
                .collector
                .on_message(s.key, s.payload, now, &mut self.sink);
        }
        // A ROS 2 publisher stamps its attachment, not the sample.
        let delay = s.delay.or_else(|| {
            let sent = record::publish_time(s.attachment, 0);
            (sent > 0).then(|| s.unix_ns as i64 - sent as i64)
        });
        self.collector.record_delay(s.key, delay);
        self.collector
            .on_ros_sample(s.key, s.payload, s.attachment, now, &mut self.sink)
    }

    fn next_wake(&self) -> f64 {
        self.until
    }

    fn tick(&mut self, now: f64, _: &mut dyn Outputs) -> Result<Flow, FleetError> {
        Ok(if now >= self.until {
            Flow::Stop
        } else {
            Flow::Continue
        })
    }

    fn report(self) -> Result<CollectorReport, FleetError> {
        let mut sink = self.sink;
        let report = self.collector.finish();
        sink.latency_metadata(&report)?;
        sink.finish()?;
        crate::write_json_file(&self.out.join(SUMMARY_FILE), &report)?;
        Ok(report)
    }
}

/// Records until the stop flag (or `max_wall`), then closes the files: the
/// Zenoh driver of [`Collector`] (no ROS 2 topics; see [`run_with_ros2`]).
pub fn run(opts: CollectorOptions, stop: &StopFlag) -> Result<CollectorReport, FleetError> {
    run_with_ros2(opts, Vec::new(), stop)
}

/// [`run`], also recording the ROS 2 topics `ros` (one Zenoh subscription
/// per topic, on [`RosTopic::key_expr`]).
pub fn run_with_ros2(
    opts: CollectorOptions,
    ros: Vec<RosTopic>,
    stop: &StopFlag,
) -> Result<CollectorReport, FleetError> {
    run_recording(opts, ros, TrajectoryRows::default(), stop)
}

/// [`run_with_ros2`], writing `trajectory.csv` with the columns of
/// `trajectory` ([`FileSink::with_trajectory`]): [`CollectorTask`] on the
/// fleet runtime.
pub fn run_recording(
    opts: CollectorOptions,
    ros: Vec<RosTopic>,
    trajectory: TrajectoryRows,
    stop: &StopFlag,
) -> Result<CollectorReport, FleetError> {
    let keys = Keys::new(&opts.fleet);
    let collector =
        Collector::with_ros2(keys, ros).map_err(|e| FleetError::Config(e.to_string()))?;
    let sink = FileSink::with_trajectory(&opts.out, trajectory)?;
    let task = CollectorTask::new(collector, sink, opts.out, opts.max_wall);
    runtime::run(task, &opts.net, FleetClock::new(1.0), stop)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::{Header, Reference};
    use echelon::control::LeaderMotion;

    /// Records in memory.
    #[derive(Debug, Default)]
    struct Memory {
        logged: Vec<(String, u64, u64, Vec<u8>)>,
        rows: Vec<String>,
        trajectory: TrajectoryRows,
    }

    impl RecordSink for Memory {
        fn log(
            &mut self,
            topic: &str,
            _schema: &JsonSchema,
            log_time: u64,
            publish_time: u64,
            data: &[u8],
        ) -> Result<(), FleetError> {
            self.logged
                .push((topic.to_owned(), log_time, publish_time, data.to_vec()));
            Ok(())
        }

        fn log_ros(
            &mut self,
            topic: &RosTopic,
            log_time: u64,
            publish_time: u64,
            data: &[u8],
        ) -> Result<(), FleetError> {
            self.logged.push((
                topic.topic().to_owned(),
                log_time,
                publish_time,
                data.to_vec(),
            ));
            Ok(())
        }

        fn row(&mut self, sample: &AgentSample) -> Result<(), FleetError> {
            // One row on its own, without the header line.
            let mut csv = CsvWriter::new(Vec::new(), "")
                .map_err(FleetError::io(std::path::Path::new("row")))?;
            self.trajectory
                .row(sample, &mut csv)
                .map_err(FleetError::io(std::path::Path::new("row")))?;
            let bytes = csv
                .into_inner()
                .map_err(FleetError::io(std::path::Path::new("row")))?;
            let text = String::from_utf8_lossy(&bytes);
            self.rows.push(text.trim_start_matches('\n').to_owned());
            Ok(())
        }
    }

    /// Valid messages go to their typed topic, a started robot's state also to
    /// the CSV; garbage, wrong versions, unknown keys and messages of the
    /// wrong kind go to `/rejected` with their reason: every sample is logged
    /// exactly once.
    #[test]
    fn every_sample_is_logged_once_and_garbage_is_rejected_with_its_reason() {
        let keys = Keys::new("f");
        let mut c = Collector::new(keys.clone());
        let mut sink = Memory::default();
        let mut reference = Vec::new();
        wire::encode_reference(
            &mut reference,
            Header { source: 1, seq: 4 },
            &Reference {
                t: 2.0,
                motion: LeaderMotion::default(),
                speed: 0.2,
                turn_rate: 0.2,
            },
        );
        let state = |link| {
            let mut b = Vec::new();
            let s = RobotState {
                t: 2.5,
                agent: 1,
                link,
                e: [3e-3, 4e-3],
                ..RobotState::default()
            };
            wire::encode_state(&mut b, Header { source: 2, seq: 0 }, &s);
            b
        };
        let (tracking, waiting) = (state(LinkStatus::Tracking), state(LinkStatus::Waiting));
        let mut wrong_version = reference.clone();
        wrong_version[1] = 9;
        let stats = br#"{"agent":1,"t":3.0}"#;
        let k = |s: &str| s.to_owned();
        let inputs: Vec<(String, &[u8])> = vec![
            (keys.reference(), &reference),
            (keys.state(1), &tracking),
            (keys.state(1), &waiting),
            (keys.stats(1), stats),
            (keys.stats(2), stats),
            (keys.stats(1), b"{"),
            (keys.reference(), &[1, 2, 3]),
            (keys.state(1), &wrong_version),
            (keys.state(2), &tracking),
            (keys.state(1), &reference),
            (k("echelon/f/alive/junk"), &reference),
        ];
        for (i, (key, bytes)) in inputs.iter().enumerate() {
            c.on_message(key, bytes, 1000 + i as u64, &mut sink)
                .unwrap_or_else(|e| panic!("{e}"));
        }
        let report = c.finish();
        assert_eq!(report.received, inputs.len() as u64);
        assert_eq!(report.logged, report.received);
        assert_eq!(sink.logged.len() as u64, report.logged);
        let rejected: Vec<(&str, u64)> = report
            .rejected
            .iter()
            .map(|(r, n)| (r.as_str(), *n))
            .collect();
        assert_eq!(
            rejected,
            [
                ("malformed", 1),
                ("malformed stats JSON", 1),
                ("message of the wrong kind for its key", 2),
                ("stats of another agent", 1),
                ("unknown key", 1),
                ("wrong version", 1),
            ]
        );
        assert_eq!(report.logged_by_topic[REFERENCE_TOPIC], 1);
        assert_eq!(report.logged_by_topic["/agent/1/state"], 2);
        assert_eq!(report.logged_by_topic["/agent/1/stats"], 1);
        assert_eq!(report.logged_by_topic[REJECTED_TOPIC], 7);
        // log_time is the arrival time given, publish_time the sender's.
        assert_eq!((sink.logged[0].1, sink.logged[0].2), (1000, nanos(2.0)));
        // One CSV row: the tracking state, not the waiting one.
        assert_eq!(sink.rows.len(), 1);
        assert!(sink.rows[0].starts_with("2.5,1,"), "{}", sink.rows[0]);
        let a = &report.agents[0];
        assert_eq!((a.agent, a.messages, a.rows), (1, 2, 1));
        assert!((a.final_error - 5e-3).abs() < 1e-15);
        assert_eq!(a.link, "waiting");
    }

    /// The states of a simulated run of velocity bases, sent as robots send
    /// them, give the collector the simulator's statistics (the same
    /// accumulator, the same samples) and the simulator's rows, velocity
    /// columns included.
    #[test]
    fn the_collector_s_statistics_and_rows_are_the_simulator_s() {
        use echelon::output::{FrameRows, TRAJECTORY_HEADER_VELOCITY};
        use echelon::scenario::{Overrides, Scenario};
        use echelon::sim::{Frame, Observer, ObserverError};

        let run = Scenario::builtin("experiment-circle-velocity")
            .unwrap_or_else(|| panic!("a built-in"))
            .build(&Overrides {
                duration: Some(2.0),
                ..Overrides::default()
            })
            .unwrap_or_else(|e| panic!("{e}"));
        let mut simulation = run.simulation();
        let trajectory = TrajectoryRows::for_agents(run.plan.agents());
        assert_eq!(trajectory.header(), TRAJECTORY_HEADER_VELOCITY);
        let keys = Keys::new("f");
        let mut c = Collector::new(keys.clone());
        let mut sink = Memory {
            trajectory,
            ..Memory::default()
        };
        let mut sim_rows = Memory {
            trajectory,
            ..Memory::default()
        };
        let mut summary = Summary::new(run.plan.agents().len(), Summary::SETTLE_TOLERANCE);
        let mut send = |frame: &Frame<'_>| -> Result<(), ObserverError> {
            for (i, (state, o)) in frame.states.iter().zip(frame.outputs).enumerate() {
                let s = RobotState {
                    t: frame.t,
                    agent: i as u32 + 1,
                    link: LinkStatus::Tracking,
                    state: *state,
                    e: o.e,
                    z: o.z,
                    u: o.u,
                    tau: o.tau,
                    velocity: o.velocity.as_ref().map(Into::into),
                    ..RobotState::default()
                };
                let mut b = Vec::new();
                wire::encode_state(
                    &mut b,
                    Header {
                        source: 1,
                        seq: frame.step,
                    },
                    &s,
                );
                c.on_message(&keys.state(s.agent), &b, 0, &mut sink)?;
            }
            for sample in AgentSample::all(frame) {
                sim_rows.row(&sample)?;
            }
            Ok(())
        };
        simulation
            .run(&mut [&mut send as &mut dyn Observer, &mut summary])
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(sink.rows, sim_rows.rows);
        assert!(sink.rows[0].split(',').count() == 20, "{}", sink.rows[0]);
        let report = c.finish();
        let agents = summary.agents(run.plan.agents());
        assert_eq!(report.agents.len(), agents.len());
        for (a, s) in report.agents.iter().zip(&agents) {
            assert_eq!(a.rows, run.plan.steps() + 1);
            assert_eq!(
                (a.final_error, a.rms_error, a.peak_torque),
                (s.final_error, s.rms_error, s.peak_torque)
            );
            assert_eq!(
                [a.final_state[0], a.final_state[1], a.final_state[2]],
                [s.final_pose.x, s.final_pose.y, s.final_pose.theta]
            );
        }
    }

    /// Delays are recorded per key and in total, unstamped samples counted
    /// apart, and the quantiles come out in seconds.
    #[test]
    fn delays_are_summarised_per_key_and_in_total() {
        let keys = Keys::new("f");
        let mut c = Collector::new(keys.clone());
        for d in [1_000_000, 2_000_000, 3_000_000] {
            c.record_delay(&keys.reference(), Some(d));
        }
        c.record_delay(&keys.state(1), Some(5_000_000));
        c.record_delay(&keys.state(1), None);
        let r = c.finish();
        assert_eq!((r.latency.count, r.latency.unstamped), (4, 1));
        assert!((r.latency.max - 5e-3).abs() < 1e-12);
        let reference = &r.latency_by_key[&keys.reference()];
        assert_eq!(reference.count, 3);
        assert!((reference.p50 - 2e-3).abs() <= 2e-3 * crate::latency::RELATIVE_ERROR);
        assert!((reference.max - 3e-3).abs() < 1e-12);
        assert_eq!(r.latency_by_key[&keys.state(1)].unstamped, 1);
        assert!(reference.buckets.is_empty());
    }

    /// ROS samples of the recorded topics are logged as received on their
    /// topic's channel; a wrong type, a wrong hash, bad CDR or a foreign key
    /// goes to `/rejected`, counted as refused; every sample once.
    #[test]
    fn ros_samples_are_recorded_as_received_or_refused_with_their_reason() {
        use echelon_ros2::KeyScheme;
        use echelon_ros2::attachment::Attachment;
        use echelon_ros2::keys::topic_key;
        use echelon_ros2::msgs::{ODOMETRY, TWIST, TWIST_STAMPED, Time, TwistStamped};
        use echelon_ros2::{Odometry, RosMessage};

        let scheme = KeyScheme::RmwZenoh;
        let mut topics = RosTopic::robot(scheme, 0, "/robot1", TWIST_STAMPED)
            .unwrap_or_else(|e| panic!("{e}"))
            .to_vec();
        let mut c =
            Collector::with_ros2(Keys::new("f"), topics.clone()).unwrap_or_else(|e| panic!("{e}"));
        let mut sink = Memory::default();
        let cmd_key = topic_key(scheme, 0, "/robot1/cmd_vel", &TWIST_STAMPED);
        let odom_key = topic_key(scheme, 0, "/robot1/odom", &ODOMETRY);
        let cmd = TwistStamped::planar(0.3, 0.1, Time::from_nanos(5), "base_link").to_cdr();
        let odom = Odometry::planar(
            1.0,
            2.0,
            0.5,
            0.3,
            0.1,
            Time::default(),
            "odom",
            "base_link",
        )
        .to_cdr();
        let attachment = Attachment {
            sequence_number: 1,
            source_timestamp_ns: 777,
            gid: [0; 16],
        }
        .encode();
        let wrong_type = topic_key(scheme, 0, "/robot1/cmd_vel", &TWIST);
        let wrong_hash = format!("0/robot1/odom/{}/RIHS01_00", ODOMETRY.dds_name());
        // (key, payload, attachment)
        type Sample<'a> = (String, &'a [u8], Option<&'a [u8]>);
        let inputs: Vec<Sample<'_>> = vec![
            (cmd_key.clone(), &cmd, Some(&attachment)),
            (odom_key.clone(), &odom, None),
            (odom_key.clone(), &odom[..odom.len() - 3], None),
            (wrong_type, &cmd, None),
            (wrong_hash, &odom, None),
            (cmd_key.clone(), &[0xff; 8], None),
            ("0/robot2/odom/x/y".to_owned(), &odom, None),
        ];
        for (i, (key, bytes, att)) in inputs.iter().enumerate() {
            c.on_ros_sample(key, bytes, *att, 100 + i as u64, &mut sink)
                .unwrap_or_else(|e| panic!("{e}"));
        }
        let report = c.finish();
        assert_eq!(report.received, inputs.len() as u64);
        assert_eq!(report.logged, report.received);
        assert_eq!((report.ros_recorded, report.ros_refused), (2, 5));
        assert_eq!(
            sink.logged[0],
            ("/robot1/cmd_vel".to_owned(), 100, 777, cmd.clone())
        );
        assert_eq!(sink.logged[1], ("/robot1/odom".to_owned(), 101, 101, odom));
        let rejected: Vec<(&str, u64)> = report
            .rejected
            .iter()
            .map(|(r, n)| (r.as_str(), *n))
            .collect();
        assert_eq!(
            rejected,
            [
                ("ROS: key of no recorded topic", 1),
                ("ROS: malformed CDR for the topic's type", 1),
                ("ROS: not CDR little-endian", 1),
                ("ROS: wrong message type on the key", 1),
                ("ROS: wrong type hash on the key", 1),
            ]
        );
        assert_eq!(report.logged_by_topic[REJECTED_TOPIC], 5);
        // A topic twice is refused.
        topics.push(topics[0].clone());
        assert!(Collector::with_ros2(Keys::new("f"), topics).is_err());
    }
}
