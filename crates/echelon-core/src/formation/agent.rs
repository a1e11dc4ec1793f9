//! One robot of a formation and its act step: the law's command, the
//! safety filter (or its brake), the drive's limits and what its motors
//! apply. The simulator ([`crate::sim`]) and the fleet's robot process call
//! the same functions, so a command takes one path from the law to the plant.
//!
//! ```text
//! sensed state, leader ─▶ law (eq. 13 / kinematic) ─▶ Command (nominal)
//!   ─▶ AgentSpec::act: safety filter (crate::safety) or its brake
//!   ─▶ Command ─▶ Drive::actuate: torque limit / speed limits ─▶ Actuation
//!   ─▶ Drive::derivative: the plant (eq. 3, or the velocity base)
//! ```

use crate::check;
use crate::error::ParamError;
use crate::formation::Leader;
use crate::law::control::{Gains, Law, Variant};
use crate::law::lycomp::Placement;
use crate::model::base::{VelocityCommand, VelocityRobot};
use crate::model::{Input, RobotParams, State, Torques};
use crate::safety::{Neighbour, Obstacle, Outcome, SafetyFilter};
use crate::sim::sample::VelocitySample;

/// How a robot is driven, and so which law drives it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Drive {
    /// Wheel torques (eq. 3, the paper's plant) under the dynamic law (eq. 13).
    Torque {
        /// Physical parameters.
        robot: RobotParams,
        /// Paper or complete law.
        variant: Variant,
    },
    /// A velocity-controlled base under the kinematic law ([`crate::law::kinematic`]).
    Velocity(VelocityRobot),
}

impl Drive {
    /// `(l, r)`: half the wheel separation and the wheel radius, m (what
    /// odometry needs).
    pub fn wheels(&self) -> (f64, f64) {
        match self {
            Drive::Torque { robot, .. } => (robot.half_wheelbase(), robot.wheel_radius()),
            Drive::Velocity(r) => (r.half_wheelbase(), r.wheel_radius()),
        }
    }

    /// `start` as this drive's start state: finite, and on a velocity base
    /// within its speed limits.
    fn start(&self, start: State) -> Result<State, ParamError> {
        if let Drive::Velocity(robot) = self {
            let b = robot.base();
            for (field, value, max, unit) in [
                ("v", start.v, b.v_max(), "m/s"),
                ("omega", start.omega, b.omega_max(), "rad/s"),
            ] {
                let reason = format!("exceeds the base's {field}_max = {max} {unit}");
                check::require(field, value, value.abs() <= max, reason)?;
            }
        }
        start.start()
    }

    /// The law this drive runs.
    pub fn law(&self) -> Law {
        match self {
            Drive::Torque { variant, .. } => Law::from(*variant),
            Drive::Velocity(_) => Law::Kinematic,
        }
    }
}

/// One robot of a formation: its body, its leader, where it holds that leader,
/// and its controller. Built by [`AgentSpec::new`] (torque-driven) or
/// [`AgentSpec::velocity`], which refuse impossible values; read through
/// its getters.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub struct AgentSpec {
    name: String,
    drive: Drive,
    leader: Leader,
    placement: Placement,
    gains: Gains,
    start: State,
    max_accel: Option<f64>,
}

impl AgentSpec {
    /// A torque-driven agent (its robot is valid by construction,
    /// [`RobotParams::new`]), refusing impossible gains ([`Gains::new`]), placement
    /// ([`Placement::new`]) or a start state that is not finite. Whether its
    /// leader exists is the formation's business ([`crate::sim::plan::Plan::new`]).
    pub fn new(
        name: impl Into<String>,
        robot: RobotParams,
        leader: Leader,
        placement: Placement,
        gains: Gains,
        variant: Variant,
        start: State,
    ) -> Result<AgentSpec, ParamError> {
        AgentSpec::checked(
            name,
            Drive::Torque { robot, variant },
            leader,
            placement,
            gains,
            start,
        )
    }

    /// An agent on a velocity-controlled base under the kinematic law (its
    /// base is possible by construction, [`VelocityRobot::new`]), refusing
    /// the rest as [`AgentSpec::new`]. A start speed outside the base's limits is refused.
    pub fn velocity(
        name: impl Into<String>,
        robot: VelocityRobot,
        leader: Leader,
        placement: Placement,
        gains: Gains,
        start: State,
    ) -> Result<AgentSpec, ParamError> {
        AgentSpec::checked(
            name,
            Drive::Velocity(robot),
            leader,
            placement,
            gains,
            start,
        )
    }

    fn checked(
        name: impl Into<String>,
        drive: Drive,
        leader: Leader,
        placement: Placement,
        gains: Gains,
        start: State,
    ) -> Result<AgentSpec, ParamError> {
        Ok(AgentSpec {
            name: name.into(),
            start: drive.start(start)?,
            drive,
            leader,
            placement,
            gains,
            max_accel: None,
        })
    }

    /// This agent starting in `start` instead, refused as by its constructor.
    pub fn with_start(self, start: State) -> Result<AgentSpec, ParamError> {
        Ok(AgentSpec {
            start: self.drive.start(start)?,
            ..self
        })
    }

    /// This agent with the largest linear acceleration `|v̇|` its act step
    /// lets the law ask, m/s² (a payload's or a passenger's comfort, not the
    /// motors'): `> 0`, and a velocity base must have a lag `τ_v > 0` (an
    /// ideal base's speed jumps to its command).
    pub fn with_max_accel(self, max_accel: Option<f64>) -> Result<AgentSpec, ParamError> {
        if let Some(a) = max_accel {
            crate::check::positive("max_accel", a)?;
            if let Drive::Velocity(r) = &self.drive {
                crate::check::require(
                    "max_accel",
                    a,
                    r.base().tau_v() > 0.0,
                    "needs a velocity base with a lag (tau_v > 0)",
                )?;
            }
        }
        Ok(AgentSpec { max_accel, ..self })
    }

    /// This agent following `leader` instead.
    pub fn with_leader(self, leader: Leader) -> AgentSpec {
        AgentSpec { leader, ..self }
    }

    /// This agent held at `placement` instead.
    pub fn with_placement(self, placement: Placement) -> AgentSpec {
        AgentSpec { placement, ..self }
    }

    /// This agent with the gains `gains` instead.
    pub fn with_gains(self, gains: Gains) -> AgentSpec {
        AgentSpec { gains, ..self }
    }

    /// The largest `|v̇|` the act step lets the law ask, m/s².
    pub fn max_accel(&self) -> Option<f64> {
        self.max_accel
    }

    /// What this agent's act step does beyond its law, when it does anything
    /// (the setting's name, e.g. `max_accel`): what a runner of the bare law,
    /// as the batch engine, must refuse. The safety filter is the plan's
    /// ([`crate::sim::plan::Plan::safety`]), not the agent's.
    pub fn beyond_law(&self) -> Option<&'static str> {
        self.max_accel.map(|_| "max_accel")
    }

    /// Display name (the scenario's, e.g. `agent 1`).
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The body and the law that drives it.
    pub fn drive(&self) -> &Drive {
        &self.drive
    }

    /// Whom it follows.
    pub fn leader(&self) -> Leader {
        self.leader
    }

    /// `L_Xoff`, `L_Yoff`, `L` and the `L_Ycomp` options.
    pub fn placement(&self) -> Placement {
        self.placement
    }

    /// `K_e`, `K_z` (`K_z` unused by the kinematic law).
    pub fn gains(&self) -> Gains {
        self.gains
    }

    /// Initial state.
    pub fn start(&self) -> State {
        self.start
    }

    /// `nominal` with the linear acceleration it asks of the robot in state
    /// `me` brought within `±max_accel`: for a torque robot `m v̇ = u1 − η v`
    /// (eq. 3) bounds `u1`; for a velocity base the lag `τ_v v̇ = v* − v`
    /// bounds `v*`. The turn is kept.
    fn limit_accel(&self, me: &State, nominal: Command) -> Command {
        let Some(a) = self.max_accel else {
            return nominal;
        };
        match (&self.drive, nominal) {
            (Drive::Torque { robot, .. }, Command::Torque(u)) => {
                let drag = robot.linear_friction() * me.v;
                let reach = a * robot.mass();
                Command::Torque(Input {
                    u1: u.u1.clamp(drag - reach, drag + reach),
                    ..u
                })
            }
            (Drive::Velocity(r), Command::Velocity(c)) => {
                let reach = a * r.base().tau_v();
                Command::Velocity(VelocityCommand {
                    v: c.v.clamp(me.v - reach, me.v + reach),
                    ..c
                })
            }
            (_, other) => other,
        }
    }

    /// The torque plant (eq. 3), `None` for a velocity base.
    pub fn torque_robot(&self) -> Option<&RobotParams> {
        match &self.drive {
            Drive::Torque { robot, .. } => Some(robot),
            Drive::Velocity(_) => None,
        }
    }

    /// The velocity base, `None` for a torque-driven robot.
    pub fn velocity_robot(&self) -> Option<&VelocityRobot> {
        match &self.drive {
            Drive::Velocity(r) => Some(r),
            Drive::Torque { .. } => None,
        }
    }

    /// The form of eq. 13, `None` under the kinematic law.
    pub fn variant(&self) -> Option<Variant> {
        self.drive.law().variant()
    }

    /// The law that drives it.
    pub fn law(&self) -> Law {
        self.drive.law()
    }
}

/// What the law asks of a drive: wheel torques' inputs (eq. 13, a
/// torque-driven robot) or a velocity command (the kinematic law, a velocity
/// base). The one command type of the simulator, the safety filter's callers
/// and the fleet's plants.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Command {
    /// `u = (u1, u2)` (eq. 3c–3d).
    Torque(Input),
    /// `(v*, ω*)`.
    Velocity(VelocityCommand),
}

impl Command {
    /// The command's two numbers: `(u1, u2)` or `(v, ω)`.
    pub fn values(&self) -> [f64; 2] {
        match *self {
            Command::Torque(u) => [u.u1, u.u2],
            Command::Velocity(c) => [c.v, c.omega],
        }
    }
}

/// What the motors apply for a command ([`Drive::actuate`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Actuation {
    /// Applied generalised input (after torque saturation); zero on a
    /// velocity base.
    pub u: Input,
    /// Applied wheel torques; zero on a velocity base.
    pub tau: Torques,
    /// On a velocity base, the command after its speed limits
    /// ([`crate::model::base::VelocityBase::limit`]) and whether they cut it.
    pub velocity: Option<(VelocityCommand, bool)>,
}

impl Drive {
    /// Zero in the drive's own terms: no torque, or a zero velocity command.
    pub fn zero(&self) -> Command {
        match self {
            Drive::Torque { .. } => Command::Torque(Input::default()),
            Drive::Velocity(_) => Command::Velocity(VelocityCommand::default()),
        }
    }

    /// What the motors apply for `command`: each wheel torque within the
    /// torque limit ([`RobotParams::actuate`]), or the velocity command within
    /// the base's speed limits ([`crate::model::base::VelocityBase::limit`]). A
    /// command of the other drive's kind applies as zero.
    #[inline]
    pub fn actuate(&self, command: Command) -> Actuation {
        match (self, command) {
            (Drive::Torque { robot, .. }, Command::Torque(u)) => {
                let (u, tau) = robot.actuate(u);
                Actuation {
                    u,
                    tau,
                    velocity: None,
                }
            }
            (Drive::Velocity(r), Command::Velocity(c)) => Actuation {
                velocity: Some(r.base().limit(c)),
                ..Actuation::default()
            },
            (_, _) => self.actuate(self.zero()),
        }
    }

    /// The plant's state derivative in `s` under `applied` (eq. 3, or the
    /// velocity base's [`crate::model::base::VelocityBase::derivative`]).
    #[inline]
    pub fn derivative(&self, s: &State, applied: &Actuation) -> State {
        match self {
            Drive::Torque { robot, .. } => robot.derivative(s, applied.u),
            Drive::Velocity(r) => r.base().derivative(s, applied.applied_velocity()),
        }
    }

    /// `s` made consistent with `applied` (a velocity base's
    /// [`crate::model::base::VelocityBase::settle`]: an axis without lag takes the
    /// applied command's velocity, a lagged one stays within the speed
    /// limits); a torque-driven robot's state is `s` as it is (eq. 3 has
    /// nothing to settle).
    #[inline]
    pub fn settle(&self, s: &State, applied: &Actuation) -> State {
        match self {
            Drive::Torque { .. } => *s,
            Drive::Velocity(r) => r.base().settle(s, applied.applied_velocity()),
        }
    }

    /// One RK4 step of `h` from `s` with `applied` held (zero-order hold):
    /// [`State::rk4_step`] over [`Drive::derivative`], then
    /// [settled](Drive::settle). Eq. 3's
    /// [`RobotParams::rk4_step`] on a torque-driven robot,
    /// [`crate::model::base::VelocityBase::rk4_step`] on a velocity base, bit for bit.
    #[inline]
    pub fn rk4_step(&self, s: &State, applied: &Actuation, h: f64) -> State {
        self.settle(&s.rk4_step(h, |x| self.derivative(x, applied)), applied)
    }

    /// `[v, ω, in₁, in₂]`: the velocities the robot moves at in `s` under
    /// `applied`, and the input its plant receives (`u1, u2`, or the applied
    /// `v, ω` command).
    #[inline]
    pub fn speeds(&self, s: &State, applied: &Actuation) -> [f64; 4] {
        match self {
            Drive::Torque { .. } => [s.v, s.omega, applied.u.u1, applied.u.u2],
            Drive::Velocity(r) => {
                let c = applied.applied_velocity();
                let (v, w) = r.base().speeds(s, c);
                [v, w, c.v, c.omega]
            }
        }
    }

    /// The safety filter's brake for a robot in `me` that cannot trust what
    /// it sees: a zero velocity command, or `u = (−η v, −ψ ω)`
    /// ([`RobotParams::brake`]).
    pub fn brake(&self, me: &State) -> Command {
        match self {
            Drive::Torque { robot, .. } => Command::Torque(robot.brake(me)),
            Drive::Velocity(_) => Command::Velocity(VelocityCommand::default()),
        }
    }
}

impl Actuation {
    /// A velocity base's sample of `cmd`, the command it was sent, and this
    /// actuation (`None` on a torque-driven robot).
    pub fn velocity_sample(&self, cmd: Command) -> Option<VelocitySample> {
        let (applied, saturated) = self.velocity?;
        let command = match cmd {
            Command::Velocity(c) => c,
            Command::Torque(_) => VelocityCommand::default(),
        };
        Some(VelocitySample::new(command, applied, saturated))
    }

    /// The velocity command the base follows (zero on a torque robot).
    #[inline]
    fn applied_velocity(&self) -> VelocityCommand {
        self.velocity.map_or_else(VelocityCommand::default, |v| v.0)
    }
}

/// What a robot's safety filter sees of its neighbours at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Sight<'a> {
    /// The neighbours in range, each fresh enough to filter against.
    Neighbours(&'a [Neighbour]),
    /// A neighbour in range went stale: the robot brakes ([`Drive::brake`]).
    Stale,
}

/// The safety filter an act step runs, and what it knows at that instant.
#[derive(Debug)]
pub struct Guard<'a> {
    /// The robot's filter (it keeps its deadlock memory across steps).
    pub filter: &'a mut SafetyFilter,
    /// What it sees of its neighbours.
    pub sight: Sight<'a>,
    /// The static obstacles it knows.
    pub obstacles: &'a [Obstacle],
    /// The law's tracking error ‖e‖ now, m, as the controller sees it: the
    /// filter's progress measure ([`SafetyFilter::set_tracking_error`]);
    /// `None`: unknown.
    pub error: Option<f64>,
    /// The backward speed a velocity base accepts this period, m/s
    /// ([`crate::model::base::Backup::cap`]; infinite: no limit): the filter's
    /// reverse cap ([`SafetyFilter::set_reverse_cap`]).
    pub reverse: f64,
}

/// One act step's answer ([`AgentSpec::act`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Act {
    /// The law's command, as given.
    pub nominal: Command,
    /// The command for the plant.
    pub command: Command,
    /// What the filter did (`None`: no filter ran).
    pub safety: Option<Guarded>,
}

/// What an act step's safety filter did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Guarded {
    /// The filter's outcome ([`Outcome::Braked`] also for a stale neighbour).
    pub outcome: Outcome,
    /// A neighbour went stale and the robot braked without filtering.
    pub stale: bool,
    /// Whether the robot is breaking a deadlock.
    pub deadlock: bool,
    /// Distance to the nearest neighbour's point in range, m (infinite:
    /// none, or stale).
    pub min_distance: f64,
}

impl AgentSpec {
    /// The act step after the law: the law's command `nominal` for this
    /// robot in (sensed) state `me` at time `t`, through its safety filter
    /// when `guard` is given (`crate::safety`; its brake when a neighbour is
    /// stale): the command its plant receives ([`Drive::actuate`] applies
    /// the drive's limits to it).
    pub fn act(&self, t: f64, me: &State, nominal: Command, guard: Option<Guard<'_>>) -> Act {
        let nominal = self.limit_accel(me, nominal);
        let Some(Guard {
            filter,
            sight,
            obstacles,
            error,
            reverse,
        }) = guard
        else {
            return Act {
                nominal,
                command: nominal,
                safety: None,
            };
        };
        filter.set_tracking_error(error.unwrap_or(f64::NAN));
        filter.set_reverse_cap(reverse);
        let l = self.placement.l();
        let guarded = |outcome, deadlock, min_distance| Guarded {
            outcome,
            stale: false,
            deadlock,
            min_distance,
        };
        let (command, safety) = match (sight, &self.drive, nominal) {
            (Sight::Stale, drive, _) => (
                drive.brake(me),
                Guarded {
                    outcome: Outcome::Braked,
                    stale: true,
                    deadlock: false,
                    min_distance: f64::INFINITY,
                },
            ),
            (Sight::Neighbours(nb), Drive::Velocity(r), Command::Velocity(c)) => {
                let f = filter.velocity(t, me, l, c, &r.base(), nb, obstacles);
                (
                    Command::Velocity(f.command),
                    guarded(f.outcome, f.deadlock, f.min_distance),
                )
            }
            (Sight::Neighbours(nb), Drive::Torque { robot, .. }, Command::Torque(u)) => {
                let f = filter.torque(t, me, l, robot, u, nb, obstacles);
                (
                    Command::Torque(f.command),
                    guarded(f.outcome, f.deadlock, f.min_distance),
                )
            }
            // A command of the other drive's kind: the drive applies zero.
            (Sight::Neighbours(_), drive, _) => {
                (drive.zero(), guarded(Outcome::Braked, false, f64::INFINITY))
            }
        };
        Act {
            nominal,
            command,
            safety: Some(safety),
        }
    }
}
