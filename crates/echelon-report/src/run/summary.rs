//! `summary.json`, the fields the report shows (serde; others are ignored).

use serde::Deserialize;

/// Per-agent results of `summary.json` (fields this crate shows; others are ignored).
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct AgentResult {
    /// 1-based number.
    pub agent: usize,
    /// Name.
    pub name: String,
    /// Final ‖e‖, m.
    pub final_error: Option<f64>,
    /// RMS ‖e‖, m.
    pub rms_error: Option<f64>,
    /// Peak |τ|, N·m.
    pub peak_torque: Option<f64>,
    /// Settling time, s.
    pub settle_time: Option<f64>,
    /// Steps at which a velocity base's speed limits cut the command (`None`:
    /// a torque-driven agent).
    #[serde(default)]
    pub saturated_ticks: Option<u64>,
}

/// `summary.json` (fields this crate shows; others are ignored).
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct SummaryFile {
    /// Scenario name.
    pub scenario: String,
    /// Simulated time, s.
    pub duration: f64,
    /// RK4 step, s.
    pub dt: f64,
    /// Steps.
    pub steps: u64,
    /// Sampled controller period, s.
    #[serde(default)]
    pub controller_period: Option<f64>,
    /// Settling tolerance, m.
    pub settle_tolerance: f64,
    /// Warnings.
    #[serde(default)]
    pub warnings: Vec<String>,
    /// Per agent.
    pub agents: Vec<AgentResult>,
    /// The safety filter's statistics (`None`: no `[safety]`).
    #[serde(default)]
    pub safety: Option<SafetySummary>,
    /// Present when the run diverged and stopped there (see
    /// `echelon::stats::Divergence`): the logs end at its last state within
    /// bounds.
    #[serde(default)]
    pub diverged: Option<DivergedSummary>,
}

/// `summary.json`'s `diverged` (fields this crate shows).
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct DivergedSummary {
    /// When, s.
    pub t: f64,
    /// The one-line message naming the agent, the time and the quantity.
    pub message: String,
}

/// `summary.json`'s `safety` (see `echelon::stats::SafetyReport`).
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct SafetySummary {
    /// The smallest `radius` among the agents that filter, m.
    pub radius: f64,
    /// Smallest distance between two robots' points `L` ahead over the run
    /// (every step), m.
    pub min_distance: f64,
    /// When, s.
    pub min_distance_t: f64,
    /// Between which agents (1-based).
    pub min_distance_agents: [usize; 2],
    /// Smallest distance from a robot's point to an obstacle's edge, m.
    #[serde(default)]
    pub min_obstacle_clearance: Option<f64>,
    /// Controller samples at which a filter changed the command (all agents).
    pub active: u64,
    /// Samples at which a robot braked (QP infeasible).
    pub infeasible: u64,
    /// Deadlocks broken.
    pub deadlock_breaks: u64,
    /// Per agent.
    pub agents: Vec<AgentSafetySummary>,
}

/// One agent's line of [`SafetySummary`].
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct AgentSafetySummary {
    /// 1-based number.
    pub agent: usize,
    /// Samples at which its filter changed the command.
    pub active: u64,
    /// Samples at which it braked.
    pub infeasible: u64,
    /// Deadlocks it started breaking.
    pub deadlock_breaks: u64,
}
