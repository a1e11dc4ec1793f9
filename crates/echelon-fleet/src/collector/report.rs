//! The collector's typed report (`collector.json`): counts, latencies and
//! per-agent statistics.

use std::collections::BTreeMap;

use serde::Serialize;

use echelon::sample::AgentSample;
use echelon::stats::{AgentStats, Summary};

use crate::latency::LatencyReport;

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
    pub(super) stats: AgentStats,
}

impl AgentRecord {
    /// Adds a started robot's sample: a row, and the statistics.
    pub(super) fn add(&mut self, s: &AgentSample) {
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
    /// Messages logged to the MCAP file, total (equals `received` less
    /// `decimated`).
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
    /// Robot states received but not logged under the state-log rate
    /// (`--log-rate`).
    #[serde(default)]
    pub decimated: u64,
    /// Samples that reached the process but not the collector: its input
    /// queue was full (never received, logged or counted in `received`).
    #[serde(default)]
    pub dropped: u64,
    /// Delay from the sender's timestamp to receipt of every sample
    /// received, s (`count + unstamped` equals `received`): the Zenoh sample
    /// timestamp, or for a ROS 2 sample without one its rmw_zenoh
    /// attachment's source timestamp.
    pub latency: LatencyReport,
    /// The same per key.
    pub latency_by_key: BTreeMap<String, LatencyReport>,
    /// Per agent.
    pub agents: Vec<AgentRecord>,
    /// With the scenario's `[safety]`: the closest approach between two
    /// robots' points `L` ahead from the true states received (matched in
    /// time as [`super::ApproachWatch`] says), and the obstacle clearance.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub approach: Option<echelon::stats::ClosestApproach>,
    /// With `--foxglove`: what the live feed served and dropped.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub live: Option<super::LiveReport>,
}
