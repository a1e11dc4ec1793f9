//! A robot's fixed configuration, from the scenario's plan and `[fleet]`.

use echelon::agent::AgentSpec;
use echelon::formation::Leader;
use echelon::guard::Bounds;
use echelon::plan::Plan;
use echelon::safety::{Obstacle, SafetyConfig};
use echelon::scenario::{FleetSettings, LinkLoss};

use crate::FleetError;
use crate::faults::FaultSpec;
use crate::token::OperatorToken;

use super::WatchdogSettings;

/// A robot's safety settings, from the scenario's `[safety]`.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotSafety {
    /// Its filter's settings.
    pub config: SafetyConfig,
    /// The known obstacles.
    pub obstacles: Vec<Obstacle>,
    /// `L` of every agent (index agent − 1).
    pub l: Vec<f64>,
    /// Whether every agent filters (a cooperative neighbour).
    pub cooperative: Vec<bool>,
}

/// Agent `agent`'s spec (from 1) in the scenario's plan, checked for the fleet.
pub fn agent_spec(plan: &Plan, agent: u32) -> Result<AgentSpec, FleetError> {
    let agents = plan.agents();
    let n = agents.len();
    let Some(spec) = (agent as usize)
        .checked_sub(1)
        .and_then(|i| agents.get(i))
        .cloned()
    else {
        return Err(FleetError::Config(format!(
            "--agent {agent}: the scenario has agents 1..={n}"
        )));
    };
    if spec.placement().uses_exact_derivatives() {
        return Err(FleetError::Config(format!(
            "agent {agent}: ly_derivatives = \"exact\" needs the reference's 3rd and 4th derivatives, which the fleet does not send; use \"neglect\""
        )));
    }
    Ok(spec)
}

/// Everything a robot's state machine needs to know, fixed for its life.
#[derive(Debug, Clone)]
pub struct RobotConfig {
    /// Agent number, from 1.
    pub agent: u32,
    /// Its body, leader, placement and controller.
    pub spec: AgentSpec,
    /// Controller period `1 / control_rate`, fleet s.
    pub period: f64,
    /// It publishes its state on every this many ticks while it follows
    /// (1: every tick; `[fleet] state_rate`: every tick when another robot
    /// reads it, else `control_rate / state_rate` rounded).
    pub state_every: u64,
    /// A sample older than this is no longer fresh, fleet s.
    pub link_timeout: f64,
    /// A sample older (or as far in the future) on delivery is refused, fleet s.
    pub stale_after: f64,
    /// What the law sees once the link is lost.
    pub loss: LinkLoss,
    /// Faults injected on what it receives.
    pub faults: FaultSpec,
    /// Stop at this fleet time (absent: never).
    pub duration: Option<f64>,
    /// Its safety filter (absent: none).
    pub safety: Option<RobotSafety>,
    /// The divergence guard's bounds on its plant's state (`[sim] bounds`).
    pub bounds: Bounds,
    /// Its robot is driven by someone else (`ros2 = { driven = true }`):
    /// it commands nothing and publishes the robot's motion as a head.
    pub driven: bool,
    /// Its watchdogs' deadlines.
    pub watchdogs: WatchdogSettings,
    /// The operator token a resume must prove ([`crate::token`]; `None`:
    /// the robot obeys stops and refuses every resume).
    pub operator_token: Option<OperatorToken>,
}

/// Agent `agent`'s safety settings from the scenario's plan (`None`: it
/// does not filter).
fn safety_in(plan: &Plan, agent: u32) -> Option<RobotSafety> {
    let config = plan.safety_of(agent as usize - 1)?;
    let n = plan.agents().len();
    Some(RobotSafety {
        config,
        obstacles: plan.obstacles().to_vec(),
        l: plan.agents().iter().map(|a| a.placement().l()).collect(),
        cooperative: (0..n).map(|i| plan.safety_of(i).is_some()).collect(),
    })
}

/// On every how many controller ticks agent `agent` publishes its state
/// while it follows: every tick when another robot reads it (it is some
/// agent's leader, or any agent filters for safety and takes its
/// neighbours' states), else `control_rate / state_rate` rounded (1
/// without a `state_rate`).
pub(super) fn state_every(plan: &Plan, fleet: &FleetSettings, agent: u32) -> u64 {
    let n = plan.agents().len();
    let read = plan
        .agents()
        .iter()
        .any(|a| a.leader() == Leader::Agent(agent as usize - 1))
        || (0..n).any(|i| plan.safety_of(i).is_some());
    match fleet.state_rate {
        Some(rate) if !read => (fleet.control_rate / rate).round().max(1.0) as u64,
        _ => 1,
    }
}

impl RobotConfig {
    /// Agent `agent`'s configuration from the scenario's plan and its
    /// `[fleet]` settings.
    pub fn from_plan(
        plan: &Plan,
        fleet: &FleetSettings,
        agent: u32,
        faults: FaultSpec,
        duration: Option<f64>,
    ) -> Result<RobotConfig, FleetError> {
        let spec = agent_spec(plan, agent)?;
        let loss = fleet.link_loss[agent as usize - 1];
        let safety = safety_in(plan, agent);
        let period = 1.0 / fleet.control_rate;
        Ok(RobotConfig {
            agent,
            spec,
            period,
            state_every: state_every(plan, fleet, agent),
            link_timeout: fleet.link_timeout,
            stale_after: fleet.stale_after,
            loss,
            faults,
            duration,
            safety,
            bounds: plan.config().bounds,
            driven: false,
            watchdogs: WatchdogSettings {
                // A simulated robot's state is measured every tick.
                odom_timeout: 2.0 * period,
                operator_heartbeat: fleet.operator_heartbeat,
            },
            operator_token: None,
        })
    }
}
