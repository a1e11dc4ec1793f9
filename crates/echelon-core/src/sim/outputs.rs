//! What each agent is doing at one instant, as observers see it.

use super::Frame;
use crate::formation::agent::{Actuation, Command};
use crate::model::base::VelocityCommand;
use crate::model::{Input, State, Torques, wrap_angle};
use crate::safety::Outcome;
use crate::sim::sample::{AgentSample, VelocitySample};

/// What one agent's controller and motors are doing at one instant.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct AgentOutput {
    /// Tracking error `e` (eq. 7) of the true state, body frame, m.
    pub e: [f64; 2],
    /// Backstepping error `z` (eq. 10) of the true state, body frame, m/s.
    pub z: [f64; 2],
    /// `ê` (eq. 35): the tracking error the controller sees (its estimated pose).
    /// Equal to `e` without odometry.
    pub e_hat: [f64; 2],
    /// `ẑ` (eq. 33): the backstepping error the controller sees. Equal to `z`
    /// without odometry.
    pub z_hat: [f64; 2],
    /// What the controller commands (held value in sampled mode).
    pub command: Input,
    /// What the plant receives after torque saturation.
    pub u: Input,
    /// Wheel torques applied.
    pub tau: Torques,
    /// For a velocity base: the command and what the base follows; `command`,
    /// `u`, `tau` are then zero. `None` for a torque-driven robot.
    pub velocity: Option<VelocityOutput>,
}

impl AgentOutput {
    /// The command the controller gave: `(v*, ω*)` on a velocity base,
    /// `command` otherwise.
    pub(super) fn commanded(&self) -> Command {
        match self.velocity {
            Some(v) => Command::Velocity(v.command),
            None => Command::Torque(self.command),
        }
    }

    /// The outputs of an agent whose true errors are `e`, `z`, whose
    /// controller sees `e_hat`, `z_hat`, commanding `command` of which its
    /// motors apply `applied`.
    pub(super) fn of(
        e: [f64; 2],
        z: [f64; 2],
        e_hat: [f64; 2],
        z_hat: [f64; 2],
        command: Command,
        applied: &Actuation,
    ) -> AgentOutput {
        let out = AgentOutput {
            e,
            z,
            e_hat,
            z_hat,
            ..AgentOutput::default()
        };
        match (command, applied.velocity) {
            (Command::Velocity(command), Some((applied, saturated))) => AgentOutput {
                velocity: Some(VelocityOutput {
                    command,
                    applied,
                    saturated,
                }),
                ..out
            },
            (command, _) => AgentOutput {
                command: match command {
                    Command::Torque(u) => u,
                    Command::Velocity(_) => Input::default(),
                },
                u: applied.u,
                tau: applied.tau,
                ..out
            },
        }
    }
}

/// What a velocity base is commanded and what it follows at one instant.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct VelocityOutput {
    /// The kinematic law's `(v*, ω*)` (held value in sampled mode).
    pub command: VelocityCommand,
    /// The command after the base's speed limits ([`crate::model::base::VelocityBase::limit`]).
    pub applied: VelocityCommand,
    /// Whether the speed limits cut the command.
    pub saturated: bool,
}

/// What an agent's safety filter did at the last controller sample
/// ([`crate::safety`]). The commands are `(v, ω)` for a velocity base and
/// `(u1, u2)` for a torque-driven robot.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SafetyOutput {
    /// Whether this agent runs the filter.
    pub enabled: bool,
    /// Whether the filter ran at this frame (a controller sample).
    pub sampled: bool,
    /// What the filter did.
    pub outcome: Outcome,
    /// Whether the agent is breaking a deadlock.
    pub deadlock: bool,
    /// Deadlocks this agent has started breaking so far.
    pub deadlock_breaks: u64,
    /// Whether its filter holds the agent: it changed its command (stuck
    /// behind its barriers, breaking a deadlock, or filtering) now or within
    /// [`crate::safety::DEADLOCK_MEMORY`] before ([`crate::safety::SafetyFilter::deadlocked`]).
    pub deadlocked: bool,
    /// The law's command.
    pub nominal: [f64; 2],
    /// The command sent to the base.
    pub filtered: [f64; 2],
    /// Distance from the agent's point to the nearest neighbour's point it
    /// sees (within `range`), m; infinite when it sees none.
    pub min_distance: f64,
}

// The sample of a simulated agent (sample.rs holds the type; the simulator,
// which is above it, builds it from its outputs).

impl From<&VelocityOutput> for VelocitySample {
    fn from(v: &VelocityOutput) -> Self {
        VelocitySample::new(v.command, v.applied, v.saturated)
    }
}

impl AgentSample {
    /// Agent `agent` (from 1) at `t` in true state `s` with controller
    /// output `o` (the heading wrapped).
    pub fn new(t: f64, agent: u32, s: &State, o: &AgentOutput) -> AgentSample {
        AgentSample {
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
            velocity: o.velocity.as_ref().map(VelocitySample::from),
        }
    }

    /// Agent `i` (from 0) of `frame`; `None` past its agents.
    pub fn of(frame: &Frame<'_>, i: usize) -> Option<AgentSample> {
        let (s, o) = (frame.states.get(i)?, frame.outputs.get(i)?);
        Some(AgentSample::new(frame.t, i as u32 + 1, s, o))
    }

    /// Every agent of `frame`, in order.
    pub fn all<'a>(frame: &'a Frame<'_>) -> impl Iterator<Item = AgentSample> + 'a {
        (0..frame.states.len()).map_while(|i| AgentSample::of(frame, i))
    }
}
