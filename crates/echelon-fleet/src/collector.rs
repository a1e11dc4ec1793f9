//! `echelon fleet collector`: records everything published under
//! `echelon/<fleet>/**` (paper section 5's data collector).
//!
//! Every sample that reaches it is logged to `fleet.mcap` exactly once: valid
//! messages on their typed channel (`/reference`, `/agent/K/state`,
//! `/agent/K/stats`), anything else on `/rejected` with the key, the reason and
//! the bytes. Robot states (once started) also go to `trajectory.csv` with the
//! simulator's header. On SIGINT/SIGTERM it stops listening, logs what is still
//! queued, and closes valid files.

use std::borrow::Cow;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::Duration;

use serde::Serialize;
use zenoh::Wait;

use echelon::output::{CsvWriter, TRAJECTORY_FILE, TRAJECTORY_HEADER, TrajectoryRow};
use echelon_mcap::{
    AGENT_STATE, AgentStateRecord, JsonSchema, LeaderRecord, McapLog, REFERENCE, REFERENCE_TOPIC,
    ReferenceRecord, agent_topic, nanos,
};

use crate::keys::{KeyKind, Keys};
use crate::net::{self, NetOptions};
use crate::wire::{self, DecodeError, LinkStatus, Message};
use crate::{FleetError, StopFlag, unix_nanos};

/// The MCAP file the collector writes.
pub const MCAP_FILE: &str = "fleet.mcap";
/// The collector's summary.
pub const SUMMARY_FILE: &str = "collector.json";
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
    "overruns": {"type": "integer"}
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

/// Per-agent statistics of the recorded states.
#[derive(Debug, Clone, Default, Serialize)]
pub struct AgentRecord {
    /// Agent number, from 1.
    pub agent: u32,
    /// State messages recorded (started or not).
    pub messages: u64,
    /// Rows written to `trajectory.csv`.
    pub rows: u64,
    /// Fleet time of the last state, s.
    pub t: f64,
    /// Last state `[x, y, θ, v, ω]`.
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
    sum_sq: f64,
}

/// What the collector reports (`collector.json`, and one JSON line on stdout).
#[derive(Debug, Clone, Default, Serialize)]
pub struct CollectorReport {
    /// `collector`.
    pub role: &'static str,
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
    /// Per agent.
    pub agents: Vec<AgentRecord>,
}

struct Channels {
    log: McapLog<BufWriter<File>>,
    seq: BTreeMap<u16, u32>,
}

impl Channels {
    fn write(
        &mut self,
        topic: &str,
        schema: &JsonSchema,
        publish_time: u64,
        data: &[u8],
        report: &mut CollectorReport,
    ) -> Result<(), FleetError> {
        let id = self.log.channel(topic, schema)?;
        let seq = self.seq.entry(id).or_insert(0);
        self.log.write(id, *seq, unix_nanos(), publish_time, data)?;
        *seq = seq.wrapping_add(1);
        report.logged += 1;
        *report.logged_by_topic.entry(topic.to_owned()).or_insert(0) += 1;
        Ok(())
    }
}

/// The collector at work: files open, counters running.
struct Recorder {
    keys: Keys,
    channels: Channels,
    csv: CsvWriter<BufWriter<File>>,
    report: CollectorReport,
    agents: BTreeMap<u32, AgentRecord>,
    csv_path: PathBuf,
}

fn hex(bytes: &[u8]) -> String {
    let mut s = String::with_capacity(2 * bytes.len().min(1024));
    for b in bytes.iter().take(1024) {
        let _ = write!(s, "{b:02x}");
    }
    s
}

impl Recorder {
    fn reject(&mut self, key: &str, reason: &str, bytes: &[u8]) -> Result<(), FleetError> {
        *self.report.rejected.entry(reason.to_owned()).or_insert(0) += 1;
        let record = serde_json::json!({
            "key": key, "reason": reason, "size": bytes.len(), "hex": hex(bytes),
        });
        let data = serde_json::to_vec(&record).map_err(echelon_mcap::McapLogError::from)?;
        self.channels
            .write(REJECTED_TOPIC, &REJECTED, 0, &data, &mut self.report)
    }

    fn record(&mut self, key: &str, bytes: &[u8]) -> Result<(), FleetError> {
        self.report.received += 1;
        *self
            .report
            .received_by_key
            .entry(key.to_owned())
            .or_insert(0) += 1;
        let kind = self.keys.classify(key);
        if let KeyKind::Stats(k) = kind {
            return match serde_json::from_slice::<serde_json::Value>(bytes) {
                Ok(v) if v.get("agent").and_then(|a| a.as_u64()) == Some(u64::from(k)) => {
                    let t = v.get("t").and_then(|t| t.as_f64()).unwrap_or(0.0);
                    let topic = format!("/agent/{k}/stats");
                    self.channels
                        .write(&topic, &STATS, nanos(t), bytes, &mut self.report)
                }
                Ok(_) => self.reject(key, "stats of another agent", bytes),
                Err(_) => self.reject(key, "malformed stats JSON", bytes),
            };
        }
        let msg = match wire::decode(bytes) {
            Ok(m) => m,
            Err(DecodeError::Malformed(_)) => return self.reject(key, "malformed", bytes),
            Err(DecodeError::WrongVersion(_)) => return self.reject(key, "wrong version", bytes),
        };
        match (kind, msg) {
            (KeyKind::Reference, Message::Reference(h, r)) => {
                let rec = ReferenceRecord {
                    t: r.t,
                    seq: Some(h.seq),
                    x: r.motion.p[0],
                    y: r.motion.p[1],
                    vx: r.motion.dp[0],
                    vy: r.motion.dp[1],
                    ax: r.motion.ddp[0],
                    ay: r.motion.ddp[1],
                    speed: r.speed,
                    turn_rate: r.turn_rate,
                };
                let data = serde_json::to_vec(&rec).map_err(echelon_mcap::McapLogError::from)?;
                self.channels.write(
                    REFERENCE_TOPIC,
                    &REFERENCE,
                    nanos(r.t),
                    &data,
                    &mut self.report,
                )
            }
            (KeyKind::State(k), Message::State(h, s)) if s.agent == k => {
                let ne = s.e[0].hypot(s.e[1]);
                // A fleet robot acts on its true state (no odometry model in
                // the fleet): what it saw is what it is.
                let output = echelon::sim::AgentOutput {
                    e: s.e,
                    z: s.z,
                    e_hat: s.e,
                    z_hat: s.z,
                    command: s.u,
                    u: s.u,
                    tau: s.tau,
                };
                let rec = AgentStateRecord {
                    seq: Some(h.seq),
                    link: Some(s.link.name()),
                    leader: Some(LeaderRecord {
                        x: s.leader.p[0],
                        y: s.leader.p[1],
                        vx: s.leader.dp[0],
                        vy: s.leader.dp[1],
                        ax: s.leader.ddp[0],
                        ay: s.leader.ddp[1],
                    }),
                    ..AgentStateRecord::new(s.t, k, &s.state, &output)
                };
                let data = serde_json::to_vec(&rec).map_err(echelon_mcap::McapLogError::from)?;
                self.channels.write(
                    &agent_topic(k as usize),
                    &AGENT_STATE,
                    nanos(s.t),
                    &data,
                    &mut self.report,
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
                a.rows += 1;
                a.t = s.t;
                a.final_state = [
                    s.state.x,
                    s.state.y,
                    s.state.theta,
                    s.state.v,
                    s.state.omega,
                ];
                a.final_error = ne;
                a.sum_sq += ne * ne;
                a.rms_error = (a.sum_sq / a.rows as f64).sqrt();
                a.peak_torque = a.peak_torque.max(s.tau.peak());
                TrajectoryRow {
                    t: s.t,
                    agent: k as usize,
                    state: &s.state,
                    output: &output,
                }
                .write(&mut self.csv)
                .map_err(FleetError::io(&self.csv_path))
            }
            (KeyKind::Other, _) => self.reject(key, "unknown key", bytes),
            _ => self.reject(key, "message of the wrong kind for its key", bytes),
        }
    }

    fn finish(mut self, out: &Path) -> Result<CollectorReport, FleetError> {
        self.channels.log.finish()?;
        self.csv.flush().map_err(FleetError::io(&self.csv_path))?;
        self.report.agents = self.agents.into_values().collect();
        crate::write_json_file(&out.join(SUMMARY_FILE), &self.report)?;
        Ok(self.report)
    }
}

/// Records until the stop flag (or `max_wall`), then closes the files.
pub fn run(opts: CollectorOptions, stop: &StopFlag) -> Result<CollectorReport, FleetError> {
    std::fs::create_dir_all(&opts.out).map_err(FleetError::io(&opts.out))?;
    let keys = Keys::new(&opts.fleet);
    let mcap_path = opts.out.join(MCAP_FILE);
    let csv_path = opts.out.join(TRAJECTORY_FILE);
    let log = McapLog::create(&mcap_path)?;
    let file = File::create(&csv_path).map_err(FleetError::io(&csv_path))?;
    let csv = CsvWriter::new(BufWriter::with_capacity(1 << 16, file), TRAJECTORY_HEADER)
        .map_err(FleetError::io(&csv_path))?;
    let mut rec = Recorder {
        keys: keys.clone(),
        channels: Channels {
            log,
            seq: BTreeMap::new(),
        },
        csv,
        report: CollectorReport {
            role: "collector",
            ..CollectorReport::default()
        },
        agents: BTreeMap::new(),
        csv_path,
    };

    let session = net::open(&opts.net)?;
    let (tx, rx) = mpsc::channel::<(String, Vec<u8>)>();
    let subscriber = session
        .declare_subscriber(keys.everything())
        .callback(move |s| {
            let _ = tx.send((
                s.key_expr().as_str().to_owned(),
                s.payload().to_bytes().into_owned(),
            ));
        })
        .wait()
        .map_err(|e| FleetError::Zenoh(format!("subscribing: {e}")))?;
    let token = session
        .liveliness()
        .declare_token(keys.alive("collector"))
        .wait()
        .map_err(|e| FleetError::Zenoh(format!("liveliness: {e}")))?;

    let started = std::time::Instant::now();
    while !stop.is_raised() && opts.max_wall.is_none_or(|m| started.elapsed() < m) {
        match rx.recv_timeout(Duration::from_millis(50)) {
            Ok((key, bytes)) => rec.record(&key, &bytes)?,
            Err(mpsc::RecvTimeoutError::Timeout) => {}
            Err(mpsc::RecvTimeoutError::Disconnected) => break,
        }
    }
    // Stop listening, then log everything that had already arrived.
    drop(token);
    let _ = subscriber.undeclare().wait();
    let _ = session.close().wait();
    while let Ok((key, bytes)) = rx.try_recv() {
        rec.record(&key, &bytes)?;
    }
    rec.finish(&opts.out)
}
