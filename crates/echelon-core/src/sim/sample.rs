//! One agent at one instant: the one sample type that `trajectory.csv`, the
//! MCAP `/agent/K/state` channel, the fleet's wire state and the report all
//! carry, whoever produced it (the simulator's frames, `sim/outputs.rs`, or a
//! fleet robot).
//!
//! Its fields are `trajectory.csv`'s columns, in order ([`COLUMNS`],
//! [`VELOCITY_COLUMNS`]); serialised (serde, JSON Schema through schemars)
//! they are the MCAP record's fields. SI units, radians.

use crate::model::State;
use crate::model::base::VelocityCommand;

/// One agent at one instant: true state, tracking error `e` (eq. 7) and
/// backstepping error `z` (eq. 10) of the true state in the robot's body
/// frame, the generalised input the plant received and the wheel torques,
/// and for a velocity base its command ([`VelocitySample`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize, schemars::JsonSchema)
)]
pub struct AgentSample {
    /// Time, s.
    pub t: f64,
    /// Agent number, from 1.
    pub agent: u32,
    /// Position x, m.
    pub x: f64,
    /// Position y, m.
    pub y: f64,
    /// Heading, rad, wrapped to (−π, π].
    pub theta: f64,
    /// Linear speed, m/s.
    pub v: f64,
    /// Angular speed, rad/s.
    pub omega: f64,
    /// Tracking error `e_x`, m.
    pub ex: f64,
    /// Tracking error `e_y`, m.
    pub ey: f64,
    /// Backstepping error `z_x`, m/s.
    pub zx: f64,
    /// Backstepping error `z_y`, m/s.
    pub zy: f64,
    /// Force `u1` the plant received, N (0 on a velocity base).
    pub u1: f64,
    /// Torque `u2` the plant received, N m (0 on a velocity base).
    pub u2: f64,
    /// Right wheel torque, N m (0 on a velocity base).
    pub tau_r: f64,
    /// Left wheel torque, N m (0 on a velocity base).
    pub tau_l: f64,
    /// A velocity base's command; absent for a torque-driven robot.
    #[cfg_attr(
        feature = "serde",
        serde(flatten, default, skip_serializing_if = "Option::is_none")
    )]
    pub velocity: Option<VelocitySample>,
}

/// What a velocity base was commanded and what it followed.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize, schemars::JsonSchema)
)]
pub struct VelocitySample {
    /// The kinematic law's `v*`, m/s.
    pub v_cmd: f64,
    /// The kinematic law's `ω*`, rad/s.
    pub omega_cmd: f64,
    /// `v` after the base's speed limits, m/s.
    pub v_applied: f64,
    /// `ω` after the base's speed limits, rad/s.
    pub omega_applied: f64,
    /// Whether the speed limits cut the command.
    pub sat: bool,
}

/// The columns of `trajectory.csv`: [`AgentSample`]'s fields before its
/// velocity-base ones, in order.
pub const COLUMNS: [&str; 15] = [
    "t", "agent", "x", "y", "theta", "v", "omega", "ex", "ey", "zx", "zy", "u1", "u2", "tau_r",
    "tau_l",
];

/// The columns `trajectory.csv` adds after [`COLUMNS`] when some agent is on
/// a velocity base: [`VelocitySample`]'s fields, in order (`sat` written 0 or 1).
pub const VELOCITY_COLUMNS: [&str; 5] = ["v_cmd", "omega_cmd", "v_applied", "omega_applied", "sat"];

impl VelocitySample {
    /// The law's command `command`, what the base follows (`applied`) and
    /// whether its limits cut it.
    pub fn new(command: VelocityCommand, applied: VelocityCommand, saturated: bool) -> Self {
        VelocitySample {
            v_cmd: command.v,
            omega_cmd: command.omega,
            v_applied: applied.v,
            omega_applied: applied.omega,
            sat: saturated,
        }
    }
}

impl AgentSample {
    /// ‖e‖, m.
    pub fn error_norm(&self) -> f64 {
        self.ex.hypot(self.ey)
    }

    /// The larger wheel torque magnitude, N m.
    pub fn peak_torque(&self) -> f64 {
        self.tau_r.abs().max(self.tau_l.abs())
    }

    /// The state `(x, y, θ, v, ω)` (θ wrapped).
    pub fn state(&self) -> State {
        State {
            x: self.x,
            y: self.y,
            theta: self.theta,
            v: self.v,
            omega: self.omega,
        }
    }
}
