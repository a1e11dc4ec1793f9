//! What a robot reports: its final report, its stats messages, its safety counters.

use serde::{Deserialize, Serialize};

use crate::command::CommandCounts;
use crate::latency::LatencyReport;
use crate::link::Counters;
use crate::role::Role;
use crate::ros2::drive::Ros2Counters;
use crate::ros2::fixes::FixReport;
use crate::ros2::hazard::{HazardReport, HazardStats};

/// What a robot reports when it stops (one JSON line on stdout; `fleet
/// up` reads it back as this type, so a renamed field is an error, never a 0).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotReport {
    /// [`Role::Robot`].
    pub role: Role,
    /// Agent number, from 1.
    pub agent: u32,
    /// Display name.
    pub name: String,
    /// The leader stream's counters.
    pub counters: Counters,
    /// Messages still delayed by `--delay` when it stopped.
    pub pending: u64,
    /// State messages published.
    pub published: u64,
    /// Controller ticks run.
    pub ticks: u64,
    /// Ticks started more than a period late.
    pub overruns: u64,
    /// Fleet time at the end, s.
    pub t: f64,
    /// Final state.
    pub final_state: [f64; 5],
    /// Final ‖e‖ against the leader motion used, m.
    pub final_error: f64,
    /// Whether it ended more than `Summary::SETTLE_TOLERANCE` from its slot
    /// while its safety filter held it (stuck, breaking a deadlock or
    /// changing its command in the last `DEADLOCK_MEMORY` seconds): the
    /// simulator's `deadlocked_at_end`, so a robot its filter kept from its
    /// slot is reported, never silent (`docs/safety.md`, "Deadlock").
    pub deadlocked_at_end: bool,
    /// Final link status.
    pub link: String,
    /// Delay from the sender's timestamp to receipt of every sample on the
    /// leader stream (reference or leader robot's state), s; `count +
    /// unstamped` equals `counters.received`.
    pub latency: LatencyReport,
    /// With `--ros2`: the drive's odometry and command counters.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ros2: Option<Ros2Counters>,
    /// With `[safety]`: what its safety filter did.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub safety: Option<SafetyCounts>,
    /// With fixes from ROS 2: what they did, and Theorem 2's requirement.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fixes: Option<FixReport>,
    /// With a base's safety words (`hazards`, `estop`): what they did,
    /// every stopping episode with its onset and clearing time.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hazards: Option<HazardReport>,
    /// What the fleet commands (`fleet stop`, `fleet resume`) did.
    pub commands: CommandCounts,
    /// What its watchdogs (odometry, operator heartbeat) did.
    #[serde(default)]
    pub watchdogs: super::WatchdogCounts,
    /// With `--fault-at`: what its simulated robot did from the fault on.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub aftermath: Option<crate::faults::AftermathReport>,
    /// Samples dropped before it took them: more than its input queue
    /// holds ([`crate::runtime::DEFAULT_QUEUE`]) waited for one tick.
    pub dropped: u64,
}

/// What a robot's safety filter did over its run (`docs/safety.md`, "In the
/// fleet").
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SafetyCounts {
    /// Control steps that went through the filter.
    pub steps: u64,
    /// Steps whose command the filter changed (filtered or braked).
    pub active: u64,
    /// Steps braked because the QP was infeasible (or the solver failed).
    pub infeasible: u64,
    /// Steps braked because a neighbour within range stayed stale past the hold.
    pub stale_brakes: u64,
    /// Deadlocks it started breaking (keep right).
    pub deadlock_breaks: u64,
    /// Neighbours within range whose stream went stale (once per episode).
    pub stale_neighbours: u64,
    /// Neighbour entries (one per neighbour and step) whose sample was more
    /// than two control periods old, so the robot kept the whole pair
    /// constraint itself (`neighbours.rs`).
    pub lagging: u64,
    /// Neighbour messages refused (unknown agent, reordered, malformed; its
    /// own are ignored).
    pub refused: u64,
    /// Smallest distance from its point to a neighbour's point it saw within
    /// range, m (`null`: none seen).
    pub min_distance: Option<f64>,
}

impl SafetyCounts {
    /// The fleet's total over the robots' counters: summed, the smallest
    /// `min_distance`; `None` when no robot filters.
    pub fn total<'a>(robots: impl IntoIterator<Item = &'a SafetyCounts>) -> Option<SafetyCounts> {
        let mut any = false;
        let mut t = SafetyCounts::default();
        for s in robots {
            any = true;
            t.steps += s.steps;
            t.active += s.active;
            t.infeasible += s.infeasible;
            t.stale_brakes += s.stale_brakes;
            t.deadlock_breaks += s.deadlock_breaks;
            t.stale_neighbours += s.stale_neighbours;
            t.lagging += s.lagging;
            t.refused += s.refused;
            if let Some(d) = s.min_distance {
                t.min_distance = Some(t.min_distance.map_or(d, |m| m.min(d)));
            }
        }
        any.then_some(t)
    }
}

/// The stats message published on `echelon/<fleet>/robot/<k>/stats`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, schemars::JsonSchema)]
#[schemars(title = "echelon.RobotStats")]
pub struct RobotStats {
    /// Agent number, from 1.
    pub agent: u32,
    /// Fleet time, s.
    pub t: f64,
    /// Link status.
    pub link: &'static str,
    /// The leader stream's counters.
    pub counters: Counters,
    /// State messages published.
    pub published: u64,
    /// Ticks started more than a period late.
    pub overruns: u64,
    /// With `[safety]`: what its safety filter did so far.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub safety: Option<SafetyCounts>,
    /// With fixes from ROS 2: what they did so far (fix age, intervals
    /// against Theorem 2's).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fixes: Option<FixReport>,
    /// With a base's safety words: the hazards in force and the counters.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub hazards: Option<HazardStats>,
    /// What the fleet commands did so far.
    pub commands: CommandCounts,
    /// What its watchdogs did so far.
    #[serde(default)]
    pub watchdogs: super::WatchdogCounts,
    /// Its process's CPU use (the task reads it when it publishes; absent
    /// where `/proc` cannot be read).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cpu: Option<crate::cost::CpuUse>,
}
