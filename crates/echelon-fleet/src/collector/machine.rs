//! The collector as a state machine ([`Collector`]): every sample in,
//! records out to a [`RecordSink`], everything counted.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use echelon_mcap::scene::ScenePose;
use echelon_mcap::{
    AGENT_STATE, AgentStateRecord, JsonSchema, LeaderRecord, OdometryRecord, REFERENCE,
    REFERENCE_TOPIC, ReferenceRecord, agent_topic, nanos,
};

use super::schema::Rejected;
use super::{
    AgentRecord, ApproachWatch, COMMAND, COMMAND_TOPIC, Channel, CollectorReport, REJECTED,
    REJECTED_TOPIC, RecordSink, STATS, Stamp,
};
use crate::FleetError;
use crate::command::FleetCommand;
use crate::keys::{KeyKind, Keys};
use crate::latency::{Latency, LatencyReport};
use crate::ros2::record::{self, RosTopic, RosTopicError};
use crate::wire::{self, DecodeError, LinkStatus, Message, RobotState};

/// The collector as a state machine: every sample received goes in through
/// [`Collector::on_message`] with the time it arrived, and comes out as
/// records in a [`RecordSink`]; it counts everything. It reads no clock and
/// opens no file.
#[derive(Debug)]
pub struct Collector {
    pub(super) keys: Keys,
    ros: Vec<RosTopic>,
    report: CollectorReport,
    agents: BTreeMap<u32, AgentRecord>,
    latency: Latency,
    latency_by_key: BTreeMap<String, Latency>,
    /// The state-log rate: at most one state per agent per bin of this
    /// many ns of receipt time (0: every state).
    log_bin: u64,
    /// Per agent, the bin of the last state logged.
    last_bin: BTreeMap<u32, u64>,
    /// With `[safety]`: the closest approach from the states received.
    approach: Option<ApproachWatch>,
}

/// The record of robot state `s`, number `seq` of its stream: what the
/// collector logs on `/agent/K/state` and so what the live dashboard shows
/// of it (its link, ‖e‖, odometry and fix ages), and what `fleet status`
/// shows ([`crate::status`]).
pub fn state_record(seq: u64, s: &RobotState) -> AgentStateRecord {
    AgentStateRecord {
        seq: Some(seq),
        link: Some(s.link.name()),
        leader: Some(LeaderRecord::from(&s.leader)),
        odometry: s.odometry.map(|o| OdometryRecord {
            raw: o.raw,
            age: o.age,
            fix_age: o.fix_age,
        }),
        sigma: Some(s.sigma),
        ..AgentStateRecord::new(s.sample())
    }
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
                decimated: 0,
                dropped: 0,
                latency: LatencyReport::default(),
                latency_by_key: BTreeMap::new(),
                agents: Vec::new(),
                approach: None,
                live: None,
            },
            agents: BTreeMap::new(),
            latency: Latency::new(),
            latency_by_key: BTreeMap::new(),
            log_bin: 0,
            last_bin: BTreeMap::new(),
            approach: None,
        }
    }

    /// Also measures the closest approach between the robots from the
    /// started robots' states it receives (every one, logged or decimated;
    /// [`ApproachWatch`]), into the report's `approach`.
    pub fn with_approach(mut self, watch: Option<ApproachWatch>) -> Collector {
        self.approach = watch;
        self
    }

    /// Logs at most `hz` states per agent per second of receipt time
    /// (`None`: every state): the receipt times are cut into bins of
    /// `1/hz` s and the first state of an agent in each bin is logged (on
    /// `/agent/K/state`, the 3D pose, `trajectory.csv` and its statistics);
    /// the others are counted as `decimated`. Refused: a rate that is not
    /// a positive number.
    pub fn with_log_rate(mut self, hz: Option<f64>) -> Result<Collector, FleetError> {
        self.log_bin = match hz {
            None => 0,
            Some(hz) if hz.is_finite() && hz > 0.0 => (1e9 / hz).round().max(1.0) as u64,
            Some(hz) => {
                return Err(FleetError::Config(format!(
                    "--log-rate {hz}: must be a positive number of states per second"
                )));
            }
        };
        Ok(self)
    }

    /// Samples dropped so far before they reached it (its input queue was
    /// full), a running total.
    pub fn set_dropped(&mut self, total: u64) {
        self.report.dropped = total;
    }

    /// Whether agent `k`'s state received at UNIX ns `now` is logged under
    /// the state-log rate (and if so, notes its bin).
    fn keep_state(&mut self, k: u32, now: u64) -> bool {
        if self.log_bin == 0 {
            return true;
        }
        let bin = now / self.log_bin;
        match self.last_bin.insert(k, bin) {
            Some(last) if last == bin => {
                self.report.decimated += 1;
                false
            }
            _ => true,
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
        let stamp = Stamp {
            log_time: now,
            publish_time: record::publish_time(attachment, now),
        };
        sink.log(Channel::Ros(topic), stamp, bytes)?;
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
        let stamp = Stamp {
            log_time: now,
            publish_time,
        };
        sink.log(Channel::Json(topic, schema), stamp, data)?;
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
        let record = Rejected {
            key,
            reason,
            size: bytes.len(),
            hex: hex(bytes),
        };
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
        if kind == KeyKind::Command {
            return match FleetCommand::decode(bytes) {
                Ok(c) => self.log(sink, COMMAND_TOPIC, &COMMAND, now, c.stamp_unix_ns, bytes),
                Err(_) => self.reject(sink, key, "malformed command", bytes, now),
            };
        }
        if let KeyKind::Halt(k) = kind {
            // A robot's own stop (its base's hazard): a fleet command too.
            return match FleetCommand::decode(bytes) {
                Ok(c)
                    if c.order == crate::command::Order::Stop
                        && c.by == crate::role::Member::Robot(k).identity() =>
                {
                    self.log(sink, COMMAND_TOPIC, &COMMAND, now, c.stamp_unix_ns, bytes)
                }
                Ok(_) => self.reject(sink, key, "a halt that is not its robot's stop", bytes, now),
                Err(_) => self.reject(sink, key, "malformed command", bytes, now),
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
        if let Some(w) = self.approach.as_mut()
            && s.link != LinkStatus::Waiting
        {
            w.on_state(k, s.t, &s.state);
        }
        if !self.keep_state(k, now) {
            let a = self.agents.entry(k).or_insert_with(|| AgentRecord {
                agent: k,
                ..AgentRecord::default()
            });
            a.messages += 1;
            a.link = s.link.name().to_owned();
            return Ok(());
        }
        let rec = state_record(seq, s);
        let sample = rec.sample;
        let data = serde_json::to_vec(&rec).map_err(echelon_mcap::McapLogError::from)?;
        self.log(
            sink,
            &agent_topic(k as usize),
            &AGENT_STATE,
            now,
            nanos(s.t),
            &data,
        )?;
        let stamp = Stamp {
            log_time: now,
            publish_time: nanos(s.t),
        };
        sink.pose(k, &ScenePose::of(&sample, s.leader.p), stamp)?;
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
        if let Some(o) = &s.odometry {
            sink.odometry(s, o)?;
        }
        sink.row(&sample)
    }

    /// The final report, with the per-agent records.
    pub fn finish(mut self) -> CollectorReport {
        self.report.agents = self.agents.into_values().collect();
        self.report.approach = self.approach.as_ref().and_then(ApproachWatch::report);
        self.report.latency = self.latency.report(false);
        self.report.latency_by_key = self
            .latency_by_key
            .iter()
            .map(|(k, l)| (k.clone(), l.report(false)))
            .collect();
        self.report
    }
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use echelon::sample::AgentSample;
    use echelon_mcap::agent_topic;
    use echelon_mcap::scene::ScenePose;
    use proptest::prelude::*;

    use super::{Channel, Collector, RecordSink, Stamp};
    use crate::FleetError;
    use crate::keys::Keys;
    use crate::wire::{self, Header, LinkStatus, RobotState};

    /// Counts what is logged, per topic, and the rows.
    #[derive(Debug, Default)]
    struct Counts {
        logged: BTreeMap<String, Vec<u64>>,
        rows: usize,
    }

    impl RecordSink for Counts {
        fn log(&mut self, channel: Channel<'_>, stamp: Stamp, _: &[u8]) -> Result<(), FleetError> {
            // The ROS 2 channels are not counted.
            if let Channel::Json(topic, _) = channel {
                self.logged
                    .entry(topic.to_owned())
                    .or_default()
                    .push(stamp.log_time);
            }
            Ok(())
        }
        fn row(&mut self, _: &AgentSample) -> Result<(), FleetError> {
            self.rows += 1;
            Ok(())
        }
        fn pose(&mut self, _: u32, _: &ScenePose, _: Stamp) -> Result<(), FleetError> {
            Ok(())
        }
    }

    fn state(agent: u32, seq: u64, t: f64) -> Vec<u8> {
        let mut buf = Vec::new();
        let s = RobotState {
            t,
            agent,
            link: LinkStatus::Tracking,
            ..RobotState::default()
        };
        wire::encode_state(&mut buf, Header { source: 7, seq }, &s);
        buf
    }

    #[test]
    fn a_log_rate_that_is_not_positive_is_refused() {
        for hz in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let c = Collector::new(Keys::new("lab")).with_log_rate(Some(hz));
            assert!(matches!(c, Err(FleetError::Config(_))), "{hz}");
        }
    }

    proptest! {
        /// Under `--log-rate HZ`, each agent's states are logged at most
        /// once per 1/HZ s bin of receipt time and at least once in every
        /// bin one arrived in (the first of it); the rest are counted as
        /// decimated, and every state is either logged or decimated. Other
        /// agents' states do not take an agent's turn.
        #[test]
        fn log_rate_decimates_per_agent(
            hz in 0.5..200.0f64,
            arrivals in prop::collection::vec((1u32..4, 0u64..5_000_000_000), 1..400),
        ) {
            let mut arrivals = arrivals;
            arrivals.sort_by_key(|&(_, at)| at);
            let keys = Keys::new("lab");
            let mut c = Collector::new(keys.clone()).with_log_rate(Some(hz)).unwrap();
            let mut sink = Counts::default();
            for (i, &(k, at)) in arrivals.iter().enumerate() {
                let bytes = state(k, i as u64, at as f64 * 1e-9);
                c.on_message(&keys.state(k), &bytes, 1_000_000_000 + at, &mut sink).unwrap();
            }
            let bin = (1e9 / hz).round() as u64;
            let report = c.finish();
            let mut logged = 0;
            for k in 1..4u32 {
                let times: Vec<u64> = arrivals
                    .iter()
                    .filter(|&&(a, _)| a == k)
                    .map(|&(_, at)| 1_000_000_000 + at)
                    .collect();
                // The first arrival of each bin, in order.
                let mut expected: Vec<u64> = Vec::new();
                for &t in &times {
                    if expected.last().is_none_or(|&l| l / bin != t / bin) {
                        expected.push(t);
                    }
                }
                let got = sink.logged.get(&agent_topic(k as usize)).cloned().unwrap_or_default();
                prop_assert_eq!(&got, &expected, "agent {}", k);
                // At most one per bin: over a span of receipt time T, at
                // most T·HZ + 2 states (the bins it touches).
                if let (Some(first), Some(last)) = (got.first(), got.last()) {
                    prop_assert!(got.len() as u64 <= last / bin - first / bin + 1);
                    prop_assert!((got.len() as f64) <= (last - first) as f64 * 1e-9 * hz + 2.0);
                }
                logged += got.len() as u64;
            }
            prop_assert_eq!(report.received, arrivals.len() as u64);
            prop_assert_eq!(report.logged, logged);
            prop_assert_eq!(report.logged + report.decimated, report.received);
            prop_assert_eq!(sink.rows as u64, logged);
            let messages: u64 = report.agents.iter().map(|a| a.messages).sum();
            prop_assert_eq!(messages, report.received);
        }

        /// Without a log rate every state is logged.
        #[test]
        fn without_a_log_rate_every_state_is_logged(
            arrivals in prop::collection::vec((1u32..4, 0u64..1_000_000), 1..100),
        ) {
            let keys = Keys::new("lab");
            let mut c = Collector::new(keys.clone()).with_log_rate(None).unwrap();
            let mut sink = Counts::default();
            for (i, &(k, at)) in arrivals.iter().enumerate() {
                let bytes = state(k, i as u64, 0.0);
                c.on_message(&keys.state(k), &bytes, at, &mut sink).unwrap();
            }
            let report = c.finish();
            prop_assert_eq!(report.decimated, 0);
            prop_assert_eq!(report.logged, arrivals.len() as u64);
        }
    }
}
