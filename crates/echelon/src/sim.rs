//! The simulator: fixed-step RK4 over a formation of robots.
//!
//! The law is evaluated inside every RK4 stage (a continuous-time controller, as
//! the paper simulates in Simulink), leaders before followers so that a follower
//! sees its leader's state and acceleration at the same instant. Optionally the
//! controller is sampled at a period `T_s` and its command held (zero-order hold)
//! in between. Stepping is explicit ([`Simulation::step`]) over plain data; the
//! same inputs give the same bits.

use crate::base::{VelocityCommand, VelocityRobot};
use crate::check;
use crate::control::{Gains, Law, LawOutput, Variant, errors};
use crate::error::{FormationError, ParamError, SimError};
use crate::follow::{Follow, LeaderView, follow};
use crate::formation::{Formation, Leader};
use crate::guard::Bounds;
use crate::kinematic::kinematic_law;
use crate::lycomp::{FitCoefficients, LyComp, Placement};
use crate::math::whole_ratio;
pub use crate::model::Pose;
use crate::model::{Input, RobotParams, State, Torques};
use crate::odometry::{Odometer, OdometrySpec};
use crate::reference::{Jet, Order, Reference, Trajectory};
use crate::safety::{Neighbour, Obstacle, Outcome, SafetyConfig, SafetyFilter};

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
    /// A velocity-controlled base under the kinematic law ([`crate::kinematic`]).
    Velocity(VelocityRobot),
}

impl Drive {
    /// `(l, r)`: half the wheel separation and the wheel radius, m (what
    /// odometry needs).
    pub fn wheels(&self) -> (f64, f64) {
        match self {
            Drive::Torque { robot, .. } => (robot.half_wheelbase, robot.wheel_radius),
            Drive::Velocity(r) => (r.half_wheelbase, r.wheel_radius),
        }
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
/// [`AgentSpec::velocity`], which refuse impossible values; the fields are
/// public to read.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub struct AgentSpec {
    /// Display name (the scenario's, e.g. `agent 1`).
    pub name: String,
    /// The body and the law that drives it.
    pub drive: Drive,
    /// Whom it follows.
    pub leader: Leader,
    /// `L_Xoff`, `L_Yoff`, `L` and the `L_Ycomp` options.
    pub placement: Placement,
    /// `K_e`, `K_z` (`K_z` unused by the kinematic law).
    pub gains: Gains,
    /// Initial state.
    pub start: State,
}

impl AgentSpec {
    /// A torque-driven agent, refusing an impossible robot
    /// ([`RobotParams::validate`]), gains ([`Gains::new`]), placement
    /// ([`Placement::new`]) or a start state that is not finite. Whether its
    /// leader exists is the formation's business ([`Simulation::new`]).
    pub fn new(
        name: impl Into<String>,
        robot: RobotParams,
        leader: Leader,
        placement: Placement,
        gains: Gains,
        variant: Variant,
        start: State,
    ) -> Result<AgentSpec, ParamError> {
        robot.validate()?;
        AgentSpec::checked(
            name.into(),
            Drive::Torque { robot, variant },
            leader,
            placement,
            gains,
            start,
        )
    }

    /// An agent on a velocity-controlled base under the kinematic law,
    /// refusing an impossible base ([`VelocityRobot::validate`]) and the rest
    /// as [`AgentSpec::new`]. A start speed outside the base's limits is refused.
    pub fn velocity(
        name: impl Into<String>,
        robot: VelocityRobot,
        leader: Leader,
        placement: Placement,
        gains: Gains,
        start: State,
    ) -> Result<AgentSpec, ParamError> {
        robot.validate()?;
        let b = &robot.base;
        check::require(
            "v",
            start.v,
            start.v.abs() <= b.v_max,
            format!("exceeds the base's v_max = {} m/s", b.v_max),
        )?;
        check::require(
            "omega",
            start.omega,
            start.omega.abs() <= b.omega_max,
            format!("exceeds the base's omega_max = {} rad/s", b.omega_max),
        )?;
        AgentSpec::checked(
            name.into(),
            Drive::Velocity(robot),
            leader,
            placement,
            gains,
            start,
        )
    }

    fn checked(
        name: String,
        drive: Drive,
        leader: Leader,
        placement: Placement,
        gains: Gains,
        start: State,
    ) -> Result<AgentSpec, ParamError> {
        gains.validate()?;
        placement.validate()?;
        start.validate_start()?;
        Ok(AgentSpec {
            name,
            drive,
            leader,
            placement,
            gains,
            start,
        })
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

/// When the controller runs.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Timing {
    /// Continuous-time: the law is evaluated in every RK4 stage.
    #[default]
    Continuous,
    /// Sampled every `period` seconds (a multiple of `dt`), command held in between.
    Sampled {
        /// `T_s`, s.
        period: f64,
    },
}

/// Integration settings, built by [`SimConfig::new`] (the fields are public to read).
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub struct SimConfig {
    /// RK4 step, s.
    pub dt: f64,
    /// Simulated time, s (the run ends at the first step at or after it).
    pub duration: f64,
    /// Continuous or sampled controller.
    pub timing: Timing,
    /// The divergence guard: a state outside stops the run
    /// ([`SimError::Diverged`]).
    pub bounds: Bounds,
}

/// At most this many steps in a run.
const MAX_STEPS: f64 = 1e12;

impl SimConfig {
    /// Integration settings, refusing a step or duration that is not a finite
    /// number > 0, more than 10¹² steps and a controller period that is not a
    /// whole multiple of `dt`. Errors name `dt`, `duration` or `controller_period`.
    pub fn new(dt: f64, duration: f64, timing: Timing) -> Result<SimConfig, ParamError> {
        check::positive("dt", dt)?;
        check::positive("duration", duration)?;
        let steps = Self::steps_for(dt, duration);
        check::require(
            "duration",
            duration,
            steps <= MAX_STEPS,
            format!("s at dt {dt} s is {steps:e} steps: too many"),
        )?;
        if let Timing::Sampled { period } = timing {
            check::multiple_of("controller_period", period, dt, &format!("dt = {dt} s"))?;
        }
        Ok(SimConfig {
            dt,
            duration,
            timing,
            bounds: Bounds::DEFAULT,
        })
    }

    /// The same settings with the divergence guard's `bounds`.
    pub fn with_bounds(self, bounds: Bounds) -> SimConfig {
        SimConfig { bounds, ..self }
    }

    fn steps_for(dt: f64, duration: f64) -> f64 {
        (duration / dt - 1e-9).ceil().max(1.0)
    }

    /// Steps of the run (it ends at the first step at or after `duration`).
    fn steps(&self) -> u64 {
        Self::steps_for(self.dt, self.duration) as u64
    }

    /// Steps between controller samples (0: continuous).
    fn hold_every(&self) -> u64 {
        match self.timing {
            Timing::Continuous => 0,
            Timing::Sampled { period } => whole_ratio(period, self.dt).unwrap_or(1),
        }
    }
}

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

/// What a velocity base is commanded and what it follows at one instant.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct VelocityOutput {
    /// The kinematic law's `(v*, ω*)` (held value in sampled mode).
    pub command: VelocityCommand,
    /// The command after the base's speed limits ([`crate::base::VelocityBase::limit`]).
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
    /// [`crate::safety::DEADLOCK_MEMORY`] before ([`SafetyFilter::deadlocked`]).
    pub deadlocked: bool,
    /// The law's command.
    pub nominal: [f64; 2],
    /// The command sent to the base.
    pub filtered: [f64; 2],
    /// Distance from the agent's point to the nearest neighbour's point it
    /// sees (within `range`), m; infinite when it sees none.
    pub min_distance: f64,
}

/// Safety settings of a simulation: each agent's filter (`None`: it does
/// not filter) and the known obstacles.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SafetySpec {
    /// Per agent.
    pub agents: Vec<Option<SafetyConfig>>,
    /// Static obstacles every agent knows.
    pub obstacles: Vec<Obstacle>,
}

/// The filters of a running simulation and their scratch.
#[derive(Debug, Clone)]
struct SafetyState {
    filters: Vec<Option<SafetyFilter>>,
    obstacles: Vec<Obstacle>,
    /// `L` of each agent (the point kept apart).
    l: Vec<f64>,
    out: Vec<SafetyOutput>,
    seen: Vec<State>,
    neighbours: Vec<Neighbour>,
}

/// A sampled controller's held command: torques' inputs or a velocity command.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct Held {
    u: Input,
    c: VelocityCommand,
}

/// The simulation at one step, as observers see it.
#[derive(Debug, Clone, Copy)]
pub struct Frame<'a> {
    /// Time, s.
    pub t: f64,
    /// Step index (`t = step · dt`).
    pub step: u64,
    /// Whether this is the final frame of the run.
    pub last: bool,
    /// The agents' states.
    pub states: &'a [State],
    /// The agents' controller outputs at these states.
    pub outputs: &'a [AgentOutput],
    /// Each agent's odometer, if it dead-reckons (empty without odometry).
    pub odometers: &'a [Option<Odometer>],
    /// Each agent's safety filter output (empty without a safety filter).
    pub safety: &'a [SafetyOutput],
    /// Each agent's true distance travelled `∫v dt` since `t = 0`, m.
    pub distance: &'a [f64],
    /// Each agent's integral since `t = 0` of the input its plant received:
    /// `∫u1 dt, ∫u2 dt` (N s, N m s) for a torque robot, `∫v dt, ∫ω dt` of
    /// the applied command (m, rad) for a velocity base. Summed with RK4's
    /// weights over the stages, as `distance` and the state are: for a torque
    /// robot `m Δv + η Δs = Δ∫u1` and `J Δω + ψ Δθ = Δ∫u2` hold to rounding
    /// between any two frames.
    pub input_integral: &'a [[f64; 2]],
}

/// An error an observer may return (e.g. an I/O error while logging).
pub type ObserverError = Box<dyn std::error::Error + Send + Sync>;

/// Watches a run from its beginning to its end: logging, statistics, progress
/// (argmin's observers, ripgrep's `Sink`). [`Simulation::run`] calls
/// [`start`](Observer::start) once, [`observe`](Observer::observe) for every
/// frame it is shown and [`finish`](Observer::finish) once after the final
/// frame. How often an observer sees frames is chosen where it is attached
/// ([`Every`]), not inside it.
///
/// When the run fails (a non-finite state, an observer's error) `finish` is not
/// called: an observer that holds a resource releases it when dropped, and a
/// file writer leaves its file incomplete for the caller to remove.
pub trait Observer {
    /// Called once before the first frame, with the simulation about to run
    /// (its agents, reference, configuration and number of steps).
    fn start(&mut self, _sim: &Simulation) -> Result<(), ObserverError> {
        Ok(())
    }

    /// Called for each frame shown to the observer, in order; the final frame
    /// has [`Frame::last`] set.
    fn observe(&mut self, frame: &Frame<'_>) -> Result<(), ObserverError>;

    /// Called once after the final frame of a run that succeeded: flush,
    /// write footers, close.
    fn finish(&mut self) -> Result<(), ObserverError> {
        Ok(())
    }
}

/// A closure is an observer of every frame (no start or finish work).
impl<F: FnMut(&Frame<'_>) -> Result<(), ObserverError>> Observer for F {
    fn observe(&mut self, frame: &Frame<'_>) -> Result<(), ObserverError> {
        self(frame)
    }
}

/// An observer shown every `every`-th step (`t = 0, every·dt, …`) and the
/// final frame; `every` of 0 or 1 shows every step. This is the schedule of
/// `trajectory.csv` (`log.dt`): a log's rate is set where it is attached
/// (argmin's `ObserverMode::Every`), and `start`/`finish` pass through.
#[derive(Debug, Clone)]
pub struct Every<O> {
    every: u64,
    observer: O,
}

impl<O> Every<O> {
    /// Shows `observer` every `every`-th step and the final frame.
    pub fn new(every: u64, observer: O) -> Every<O> {
        Every {
            every: every.max(1),
            observer,
        }
    }

    /// Whether this schedule shows `frame`.
    #[inline]
    pub fn shows(&self, frame: &Frame<'_>) -> bool {
        frame.step.is_multiple_of(self.every) || frame.last
    }

    /// The observer, e.g. to read what it gathered.
    pub fn get_ref(&self) -> &O {
        &self.observer
    }

    /// The observer, released from its schedule.
    pub fn into_inner(self) -> O {
        self.observer
    }
}

impl<O: Observer> Observer for Every<O> {
    fn start(&mut self, sim: &Simulation) -> Result<(), ObserverError> {
        self.observer.start(sim)
    }

    fn observe(&mut self, frame: &Frame<'_>) -> Result<(), ObserverError> {
        if self.shows(frame) {
            self.observer.observe(frame)
        } else {
            Ok(())
        }
    }

    fn finish(&mut self) -> Result<(), ObserverError> {
        self.observer.finish()
    }
}

/// Several observers as one, each hook called on each in order.
impl<const N: usize> Observer for [&mut dyn Observer; N] {
    fn start(&mut self, sim: &Simulation) -> Result<(), ObserverError> {
        self.iter_mut().try_for_each(|o| o.start(sim))
    }

    fn observe(&mut self, frame: &Frame<'_>) -> Result<(), ObserverError> {
        self.iter_mut().try_for_each(|o| o.observe(frame))
    }

    fn finish(&mut self) -> Result<(), ObserverError> {
        self.iter_mut().try_for_each(|o| o.finish())
    }
}

/// An observer that may be absent (`None` sees nothing).
impl<O: Observer> Observer for Option<O> {
    fn start(&mut self, sim: &Simulation) -> Result<(), ObserverError> {
        self.as_mut().map_or(Ok(()), |o| o.start(sim))
    }

    fn observe(&mut self, frame: &Frame<'_>) -> Result<(), ObserverError> {
        self.as_mut().map_or(Ok(()), |o| o.observe(frame))
    }

    fn finish(&mut self) -> Result<(), ObserverError> {
        self.as_mut().map_or(Ok(()), |o| o.finish())
    }
}

/// Immutable description of the system being simulated.
#[derive(Debug, Clone)]
struct System {
    agents: Vec<AgentSpec>,
    formation: Formation,
    reference: Reference,
    order: Order,
    uses_reference: bool,
}

impl System {
    /// Evaluates every agent at time `t` and states `x`: state derivatives into
    /// `dx`, the velocities each robot moves at into `speeds` and, when `out`
    /// is given (RK4's first stage, which observers see), controller outputs
    /// into it. With `held`, the commands are held values (sampled controller)
    /// instead of fresh law outputs. With odometers, the law acts on what they
    /// measure (eqs. 32–35) while `e`, `z` in `out` are those of the true state.
    /// A velocity base's command is limited ([`crate::base::VelocityBase::limit`])
    /// before it drives the base.
    #[inline]
    #[allow(clippy::too_many_arguments)]
    fn evaluate(
        &self,
        t: f64,
        x: &[State],
        held: Option<&[Held]>,
        odometers: &[Option<Odometer>],
        mut out: Option<&mut [AgentOutput]>,
        dx: &mut [State],
        speeds: &mut [[f64; 4]],
    ) {
        if let (None, Some(h)) = (&out, held) {
            // Between samples of a sampled controller, with nobody looking at
            // the law's outputs: only the plant moves.
            for (i, a) in self.agents.iter().enumerate() {
                match &a.drive {
                    Drive::Torque { robot, .. } => {
                        let u = robot.actuate(h[i].u).0;
                        dx[i] = robot.derivative(&x[i], u);
                        speeds[i] = [x[i].v, x[i].omega, u.u1, u.u2];
                    }
                    Drive::Velocity(r) => {
                        let c = r.base.limit(h[i].c).0;
                        dx[i] = r.base.derivative(&x[i], c);
                        let (v, w) = r.base.speeds(&x[i], c);
                        speeds[i] = [v, w, c.v, c.omega];
                    }
                }
            }
            return;
        }
        let jet = if self.uses_reference {
            self.reference.eval(t, self.order)
        } else {
            Jet::default()
        };
        let sensed = |j: usize| match odometers.get(j) {
            Some(Some(o)) => o.measure(&x[j]),
            _ => x[j],
        };
        for &i in self.formation.order() {
            let a = &self.agents[i];
            // What the law knows of the leader, from a state of robot j: the
            // leader was evaluated first, so dx[j].v is its v̇ now and
            // speeds[j] the velocities its base moves at.
            let view = |state: State, j: usize| {
                let state = match self.agents[j].drive {
                    Drive::Torque { .. } => state,
                    Drive::Velocity(_) => State {
                        v: speeds[j][0],
                        omega: speeds[j][1],
                        ..state
                    },
                };
                LeaderView::Robot { state, dv: dx[j].v }
            };
            let leader = match a.leader {
                Leader::Reference => LeaderView::Reference(&jet),
                Leader::Agent(j) => view(sensed(j), j),
            };
            let Follow {
                law: LawOutput { u, e, z },
                leader: motion,
                offset,
                velocity,
            } = follow(a, &sensed(i), leader);
            let (e_true, z_true) = if out.is_none() || odometers.is_empty() {
                (e, z)
            } else {
                // The same errors from the true states of the robot and its leader.
                let (motion, offset) = match a.leader {
                    Leader::Reference => (motion, offset),
                    Leader::Agent(j) => view(x[j], j).resolve(&a.placement),
                };
                let s = &x[i];
                match a.drive {
                    Drive::Torque { .. } => errors(
                        s.x,
                        s.y,
                        s.theta.sin_cos(),
                        s.v,
                        s.omega,
                        motion.p,
                        motion.dp,
                        offset.lx,
                        offset.ly,
                        offset.dly,
                        a.gains.ke,
                    ),
                    Drive::Velocity(_) => {
                        let k = kinematic_law(s, &motion, &offset, a.gains.ke);
                        (k.e, k.z)
                    }
                }
            };
            let output = match &a.drive {
                Drive::Torque { robot, .. } => {
                    let command = held.map_or(u, |h| h[i].u);
                    let (applied, tau) = robot.actuate(command);
                    dx[i] = robot.derivative(&x[i], applied);
                    speeds[i] = [x[i].v, x[i].omega, applied.u1, applied.u2];
                    AgentOutput {
                        e: e_true,
                        z: z_true,
                        e_hat: e,
                        z_hat: z,
                        command,
                        u: applied,
                        tau,
                        velocity: None,
                    }
                }
                Drive::Velocity(r) => {
                    let command = held.map_or(velocity.unwrap_or_default(), |h| h[i].c);
                    let (c, saturated) = r.base.limit(command);
                    dx[i] = r.base.derivative(&x[i], c);
                    let (v, w) = r.base.speeds(&x[i], c);
                    speeds[i] = [v, w, c.v, c.omega];
                    AgentOutput {
                        e: e_true,
                        z: z_true,
                        e_hat: e,
                        z_hat: z,
                        velocity: Some(VelocityOutput {
                            command,
                            applied: c,
                            saturated,
                        }),
                        ..AgentOutput::default()
                    }
                }
            };
            if let Some(out) = out.as_deref_mut() {
                out[i] = output;
            }
        }
    }
}

/// A running simulation: plain state vectors stepped explicitly.
#[derive(Debug, Clone)]
pub struct Simulation {
    sys: System,
    config: SimConfig,
    steps: u64,
    hold_every: u64,
    warnings: Vec<String>,
    step: u64,
    state: Vec<State>,
    held: Vec<Held>,
    /// Whether any agent is on a velocity base (its state is settled after each step).
    velocity_agents: bool,
    /// Velocities each robot moves at in RK4's four stages, and the inputs
    /// its plant receives there (`u1, u2` or the applied `v, ω` command).
    speeds: [Vec<[f64; 4]>; 4],
    /// Outputs and derivative (RK4's k1) at the current state, when `fresh`.
    out: Vec<AgentOutput>,
    k1: Vec<State>,
    fresh: bool,
    /// Per-agent odometers (empty when no agent dead-reckons).
    odometers: Vec<Option<Odometer>>,
    /// Sample every this many steps, per agent.
    odometry_every: Vec<u64>,
    /// True distance travelled `∫v dt`, per agent (what the wheels turn through).
    distance: Vec<f64>,
    /// `∫ input dt` per agent, RK4-weighted over the stages ([`Frame::input_integral`]).
    input_integral: Vec<[f64; 2]>,
    /// Safety filters, when any agent filters.
    safety: Option<Box<SafetyState>>,
    // Scratch for stages 2–4.
    stage: Vec<State>,
    k2: Vec<State>,
    k3: Vec<State>,
    k4: Vec<State>,
}

/// The agents of a formation, checked together: their leader graph is a
/// forest rooted at the reference ([`Formation::new`]) and no agent behind a
/// robot leader asks for exact `L_Y` derivatives (they need the leader's 3rd
/// and 4th derivatives, which only analytic references provide).
#[derive(Debug, Clone)]
pub struct Agents {
    specs: Vec<AgentSpec>,
    formation: Formation,
}

impl Agents {
    /// Checks the agents together (each is valid by [`AgentSpec::new`]).
    pub fn new(specs: Vec<AgentSpec>) -> Result<Agents, FormationError> {
        let formation = Formation::new(specs.iter().map(|a| a.leader).collect())?;
        for (i, a) in specs.iter().enumerate() {
            if let Leader::Agent(j) = a.leader
                && a.placement.uses_exact_derivatives()
            {
                return Err(FormationError::ExactDerivativesNeedReference {
                    agent: i + 1,
                    leader: j + 1,
                });
            }
            if let Leader::Agent(j) = a.leader
                && a.torque_robot().is_some()
                && specs[j]
                    .velocity_robot()
                    .is_some_and(|r| r.base.tau_v == 0.0)
            {
                return Err(FormationError::NoLeaderAcceleration {
                    agent: i + 1,
                    leader: j + 1,
                });
            }
        }
        Ok(Agents { specs, formation })
    }

    /// The agents.
    pub fn specs(&self) -> &[AgentSpec] {
        &self.specs
    }

    /// Their leader graph.
    pub fn formation(&self) -> &Formation {
        &self.formation
    }
}

impl Simulation {
    /// Builds a simulation from agents and settings that are valid by
    /// construction ([`AgentSpec::new`], [`SimConfig::new`]), refusing what
    /// only exists at the level of the formation ([`Agents::new`]) and a
    /// velocity base's lag the step cannot resolve
    /// ([`crate::base::VelocityBase::check_step`]).
    pub fn new(
        agents: Vec<AgentSpec>,
        reference: Reference,
        config: SimConfig,
    ) -> Result<Simulation, SimError> {
        for (i, a) in agents.iter().enumerate() {
            if let Some(r) = a.velocity_robot() {
                r.base
                    .check_step(config.dt)
                    .map_err(|source| SimError::Param {
                        context: format!("agent {} robot", i + 1),
                        source,
                    })?;
            }
        }
        Ok(Simulation::of(Agents::new(agents)?, reference, config))
    }

    /// [`Simulation::new`] for agents already checked together: checks nothing.
    pub fn of(agents: Agents, reference: Reference, config: SimConfig) -> Simulation {
        let Agents {
            specs: agents,
            formation,
        } = agents;
        let mut warnings = Vec::new();
        for (i, a) in agents.iter().enumerate() {
            let ctx = format!("agent {}", i + 1);
            if a.variant() == Some(Variant::Paper) && a.gains.ke * a.gains.kz <= 0.25 {
                warnings.push(format!(
                    "{ctx}: K_e K_z = {} ≤ 1/4: Theorem 1 does not guarantee convergence for the paper law (use law = \"complete\")",
                    a.gains.ke * a.gains.kz
                ));
            }
            let (lo, hi) = FitCoefficients::PAPER_RANGE;
            if a.placement.comp == LyComp::Fit && !(lo..=hi).contains(&a.placement.lx_off) {
                warnings.push(format!(
                    "{ctx}: L_Xoff = {} m is outside the range {lo}–{hi} m where the eq. 6 fit holds (use lycomp = \"exact\")",
                    a.placement.lx_off
                ));
            }
        }

        let order = if agents.iter().any(|a| a.placement.uses_exact_derivatives()) {
            Order::Four
        } else {
            Order::Two
        };
        let uses_reference = agents.iter().any(|a| a.leader == Leader::Reference);
        let n = agents.len();
        let state: Vec<State> = agents.iter().map(|a| a.start).collect();
        let velocity_agents = agents.iter().any(|a| a.velocity_robot().is_some());
        Simulation {
            sys: System {
                agents,
                formation,
                reference,
                order,
                uses_reference,
            },
            config,
            steps: config.steps(),
            hold_every: config.hold_every(),
            warnings,
            step: 0,
            state,
            held: vec![Held::default(); n],
            velocity_agents,
            speeds: std::array::from_fn(|_| vec![[0.0; 4]; n]),
            out: vec![AgentOutput::default(); n],
            k1: vec![State::default(); n],
            fresh: false,
            odometers: Vec::new(),
            odometry_every: Vec::new(),
            distance: vec![0.0; n],
            input_integral: vec![[0.0; 2]; n],
            safety: None,
            stage: vec![State::default(); n],
            k2: vec![State::default(); n],
            k3: vec![State::default(); n],
            k4: vec![State::default(); n],
        }
    }

    /// Gives agents odometers: `specs[i]` for agent `i` (`None`: it knows its true
    /// pose). The controller then acts on the odometry estimate while the plant
    /// moves truly. Random errors draw from `seed`, one stream per agent. Refuses
    /// sampling periods that are not whole multiples of `dt` and invalid models.
    pub fn with_odometry(
        mut self,
        specs: Vec<Option<OdometrySpec>>,
        seed: u64,
    ) -> Result<Simulation, SimError> {
        let n = self.sys.agents.len();
        if specs.len() != n {
            return Err(SimError::Timing(format!(
                "{} odometry specs for {n} agents",
                specs.len()
            )));
        }
        if specs.iter().all(Option::is_none) {
            return Ok(self);
        }
        let dt = self.config.dt;
        let mut odometers = Vec::with_capacity(n);
        let mut every = Vec::with_capacity(n);
        for (i, spec) in specs.into_iter().enumerate() {
            let context = || format!("agent {} odometry", i + 1);
            match spec {
                None => {
                    odometers.push(None);
                    every.push(1);
                }
                Some(spec) => {
                    let a = &self.sys.agents[i];
                    let param = |source| SimError::Param {
                        context: context(),
                        source,
                    };
                    let k = check::multiple_of("period", spec.period, dt, &format!("dt = {dt} s"))
                        .map_err(param)?;
                    let (l, r) = a.drive.wheels();
                    let o = Odometer::with_wheels(spec, l, r, &a.start, seed, i as u64)
                        .map_err(param)?;
                    odometers.push(Some(o));
                    every.push(k);
                }
            }
        }
        self.odometers = odometers;
        self.odometry_every = every;
        self.fresh = false;
        Ok(self)
    }

    /// Each agent's odometer (empty without odometry).
    pub fn odometers(&self) -> &[Option<Odometer>] {
        &self.odometers
    }

    /// The agents.
    pub fn agents(&self) -> &[AgentSpec] {
        &self.sys.agents
    }

    /// The leader graph.
    pub fn formation(&self) -> &Formation {
        &self.sys.formation
    }

    /// The reference the virtual leader follows.
    pub fn reference(&self) -> &Reference {
        &self.sys.reference
    }

    /// The integration settings.
    pub fn config(&self) -> &SimConfig {
        &self.config
    }

    /// Things that are allowed but probably not what the user wants.
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }

    /// Total number of steps of the run.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Current step index.
    pub fn step_index(&self) -> u64 {
        self.step
    }

    /// Current time, s.
    pub fn time(&self) -> f64 {
        self.step as f64 * self.config.dt
    }

    /// Whether the run has reached its duration.
    pub fn is_done(&self) -> bool {
        self.step >= self.steps
    }

    /// Current states.
    pub fn states(&self) -> &[State] {
        &self.state
    }

    /// Evaluates the controllers at the current state (RK4's first stage), once.
    fn refresh(&mut self) {
        if self.fresh {
            return;
        }
        let sample = self.hold_every > 0 && self.step.is_multiple_of(self.hold_every);
        let held = (self.hold_every > 0 && !sample).then_some(&self.held[..]);
        self.sys.evaluate(
            self.time(),
            &self.state,
            held,
            &self.odometers,
            Some(&mut self.out),
            &mut self.k1,
            &mut self.speeds[0],
        );
        if sample {
            for (h, o) in self.held.iter_mut().zip(&self.out) {
                h.u = o.command;
                if let Some(v) = o.velocity {
                    h.c = v.command;
                }
            }
            if self.safety.is_some() {
                self.filter();
            }
        } else if let Some(safety) = self.safety.as_deref_mut() {
            for o in &mut safety.out {
                o.sampled = false;
            }
        }
        self.fresh = true;
    }

    /// Runs each agent's safety filter on the held (just sampled) commands,
    /// with the neighbours' states its controller sees (its odometry estimate
    /// when it dead-reckons, as a neighbour would broadcast it), and
    /// re-evaluates the plant's derivative for the filtered commands.
    fn filter(&mut self) {
        let t = self.time();
        let Some(safety) = self.safety.as_deref_mut() else {
            return;
        };
        let n = self.state.len();
        for (j, seen) in safety.seen.iter_mut().enumerate() {
            *seen = match self.odometers.get(j) {
                Some(Some(o)) => o.measure(&self.state[j]),
                _ => self.state[j],
            };
        }
        for i in 0..n {
            if safety.filters[i].is_none() {
                continue;
            }
            safety.neighbours.clear();
            for j in (0..n).filter(|&j| j != i) {
                let dv = [self.k1[j].v, self.k1[j].omega];
                safety.neighbours.push(Neighbour::of_state(
                    &safety.seen[j],
                    safety.l[j],
                    Some(dv),
                    safety.filters[j].is_some(),
                ));
            }
            let Some(filter) = safety.filters[i].as_mut() else {
                continue;
            };
            let (me, l) = (&safety.seen[i], safety.l[i]);
            let (nb, obs) = (&safety.neighbours[..], &safety.obstacles[..]);
            let h = &mut self.held[i];
            let o = &mut safety.out[i];
            match &self.sys.agents[i].drive {
                Drive::Velocity(r) => {
                    let f = filter.velocity(t, me, l, h.c, &r.base, nb, obs);
                    h.c = f.command;
                    o.nominal = [f.nominal.v, f.nominal.omega];
                    o.filtered = [f.command.v, f.command.omega];
                    (o.outcome, o.deadlock, o.min_distance) =
                        (f.outcome, f.deadlock, f.min_distance);
                }
                Drive::Torque { robot, .. } => {
                    let f = filter.torque(t, me, l, robot, h.u, nb, obs);
                    h.u = f.command;
                    o.nominal = [f.nominal.u1, f.nominal.u2];
                    o.filtered = [f.command.u1, f.command.u2];
                    (o.outcome, o.deadlock, o.min_distance) =
                        (f.outcome, f.deadlock, f.min_distance);
                }
            }
            o.sampled = true;
            o.deadlock_breaks = filter.deadlock_breaks();
            o.deadlocked = filter.deadlocked();
        }
        // The plant moves under the filtered commands from this instant on.
        self.sys.evaluate(
            t,
            &self.state,
            Some(&self.held),
            &self.odometers,
            None,
            &mut self.k1,
            &mut self.speeds[0],
        );
        for (i, a) in self.sys.agents.iter().enumerate() {
            let (h, o) = (&self.held[i], &mut self.out[i]);
            match &a.drive {
                Drive::Torque { robot, .. } => {
                    (o.u, o.tau) = robot.actuate(h.u);
                }
                Drive::Velocity(r) => {
                    if let Some(v) = o.velocity.as_mut() {
                        v.applied = r.base.limit(h.c).0;
                    }
                }
            }
        }
    }

    /// Puts a safety filter between each agent's law and its base
    /// ([`crate::safety`]); `spec.agents[i]` for agent `i` (`None`: it does
    /// not filter). The law and the filter then run once per controller
    /// period (once per step `dt` for a continuous-time controller) and the
    /// filtered command is held in between. Refuses a spec of the wrong
    /// length, and a robot whose point starts within `radius` of another's
    /// or of an obstacle's edge.
    pub fn with_safety(mut self, spec: SafetySpec) -> Result<Simulation, SimError> {
        let n = self.sys.agents.len();
        if spec.agents.len() != n {
            return Err(SimError::Timing(format!(
                "{} safety configs for {n} agents",
                spec.agents.len()
            )));
        }
        if spec.agents.iter().all(Option::is_none) {
            return Ok(self);
        }
        let l: Vec<f64> = self.sys.agents.iter().map(|a| a.placement.l).collect();
        let points: Vec<[f64; 2]> = self
            .sys
            .agents
            .iter()
            .zip(&l)
            .map(|(a, &l)| crate::safety::point(&a.start, l))
            .collect();
        if let Some((agent, source)) =
            crate::safety::start_conflict(&points, &spec.agents, &spec.obstacles)
        {
            return Err(SimError::Param {
                context: format!("agent {} start", agent + 1),
                source,
            });
        }
        if self.hold_every == 0 {
            self.hold_every = 1;
        }
        let period = self.hold_every as f64 * self.config.dt;
        self.safety = Some(Box::new(SafetyState {
            filters: spec
                .agents
                .iter()
                .map(|c| c.map(|c| SafetyFilter::new(c).with_period(period)))
                .collect(),
            obstacles: spec.obstacles,
            l,
            out: spec
                .agents
                .iter()
                .map(|c| SafetyOutput {
                    enabled: c.is_some(),
                    min_distance: f64::INFINITY,
                    ..SafetyOutput::default()
                })
                .collect(),
            seen: vec![State::default(); n],
            neighbours: Vec::with_capacity(n),
        }));
        self.fresh = false;
        Ok(self)
    }

    /// The obstacles every agent knows (empty without a safety filter).
    pub fn obstacles(&self) -> &[Obstacle] {
        self.safety.as_ref().map_or(&[], |s| &s.obstacles[..])
    }

    /// Each agent's safety settings (`None`: it does not filter); empty
    /// without a safety filter.
    pub fn safety_configs(&self) -> Vec<Option<SafetyConfig>> {
        self.safety.as_deref().map_or_else(Vec::new, |s| {
            s.filters
                .iter()
                .map(|f| f.as_ref().map(|f| *f.config()))
                .collect()
        })
    }

    /// Whether a safety filter runs.
    pub fn has_safety(&self) -> bool {
        self.safety.is_some()
    }

    /// The smallest `radius` among the agents that filter (`None`: none does).
    pub fn safety_radius(&self) -> Option<f64> {
        let s = self.safety.as_deref()?;
        s.filters
            .iter()
            .flatten()
            .map(|f| f.config().radius)
            .reduce(f64::min)
    }

    /// The current frame (evaluating the controllers if needed).
    pub fn frame(&mut self) -> Frame<'_> {
        self.refresh();
        Frame {
            t: self.time(),
            step: self.step,
            last: self.is_done(),
            states: &self.state,
            outputs: &self.out,
            odometers: &self.odometers,
            safety: self.safety.as_ref().map_or(&[], |s| &s.out[..]),
            distance: &self.distance,
            input_integral: &self.input_integral,
        }
    }

    /// Advances one RK4 step; the law is evaluated in each of the four stages.
    /// Fails ([`SimError::Diverged`]) if a state stops being finite or leaves
    /// the configuration's [`Bounds`]; the simulation then stays at that state.
    pub fn step(&mut self) -> Result<(), SimError> {
        self.refresh();
        let dt = self.config.dt;
        let t = self.time();
        let held = (self.hold_every > 0).then_some(&self.held[..]);
        let sys = &self.sys;
        let odo = &self.odometers[..];
        for (s, (x, k)) in self.stage.iter_mut().zip(self.state.iter().zip(&self.k1)) {
            *s = x.add_scaled(k, 0.5 * dt);
        }
        let [_, sp2, sp3, sp4] = &mut self.speeds;
        sys.evaluate(
            t + 0.5 * dt,
            &self.stage,
            held,
            odo,
            None,
            &mut self.k2,
            sp2,
        );
        for (s, (x, k)) in self.stage.iter_mut().zip(self.state.iter().zip(&self.k2)) {
            *s = x.add_scaled(k, 0.5 * dt);
        }
        sys.evaluate(
            t + 0.5 * dt,
            &self.stage,
            held,
            odo,
            None,
            &mut self.k3,
            sp3,
        );
        for (s, (x, k)) in self.stage.iter_mut().zip(self.state.iter().zip(&self.k3)) {
            *s = x.add_scaled(k, dt);
        }
        sys.evaluate(t + dt, &self.stage, held, odo, None, &mut self.k4, sp4);
        let h6 = dt / 6.0;
        for (i, x) in self.state.iter_mut().enumerate() {
            let k = [&self.k1[i], &self.k2[i], &self.k3[i], &self.k4[i]];
            // ṡ = v through the same RK4 stages: the stage speeds are
            // v, v + dt/2 v̇₁, v + dt/2 v̇₂, v + dt v̇₃.
            if let Drive::Velocity(_) = sys.agents[i].drive {
                // ṡ = the speed the base moves at, stage by stage.
                let s = |k: usize| self.speeds[k][i][0];
                self.distance[i] += h6 * (s(0) + 2.0 * s(1) + 2.0 * s(2) + s(3));
            } else {
                self.distance[i] += dt * x.v + dt * dt / 6.0 * (k[0].v + k[1].v + k[2].v);
            }
            for (j, acc) in self.input_integral[i].iter_mut().enumerate() {
                let u = |k: usize| self.speeds[k][i][2 + j];
                *acc += h6 * (u(0) + 2.0 * u(1) + 2.0 * u(2) + u(3));
            }
            *x = x.rk4_combine(k, h6);
        }
        self.step += 1;
        self.fresh = false;
        let bounds = self.config.bounds;
        for (i, s) in self.state.iter().enumerate() {
            if let Some(breach) = bounds.check(s) {
                return Err(SimError::Diverged {
                    agent: i + 1,
                    name: self.sys.agents[i].name.clone(),
                    t: self.time(),
                    breach,
                });
            }
        }
        let now = self.time();
        for (i, odometer) in self.odometers.iter_mut().enumerate() {
            if let Some(o) = odometer
                && self.step.is_multiple_of(self.odometry_every[i])
            {
                o.sample(now, &self.state[i], self.distance[i]);
            }
        }
        if self.velocity_agents {
            self.settle();
        }
        Ok(())
    }

    /// Makes each velocity base's state consistent with the command at the new
    /// state ([`crate::base::VelocityBase::settle`]: an axis without lag takes
    /// the command's velocity), evaluating the controllers there (in sampled
    /// mode, the held command or the new sample).
    fn settle(&mut self) {
        self.refresh();
        for (i, a) in self.sys.agents.iter().enumerate() {
            if let (Drive::Velocity(r), Some(v)) = (&a.drive, self.out[i].velocity) {
                self.state[i] = r.base.settle(&self.state[i], v.applied);
            }
        }
        self.fresh = false;
    }

    /// Runs to the end: `observer` is started, shown every frame (`t = 0` to
    /// the last) and finished ([`Observer`]).
    pub fn run(&mut self, observer: &mut dyn Observer) -> Result<(), SimError> {
        let failed = |e: ObserverError| SimError::Observer(e.to_string());
        observer.start(self).map_err(failed)?;
        loop {
            let frame = self.frame();
            let last = frame.last;
            observer.observe(&frame).map_err(failed)?;
            if last {
                break;
            }
            self.step()?;
        }
        observer.finish().map_err(failed)
    }
}

pub use crate::stats::{AgentSafety, AgentSummary, Divergence, SafetyReport, SafetyWatch, Summary};

#[cfg(test)]
mod observer_tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use crate::scenario::{Overrides, Scenario};

    /// Records which hooks it saw, in order.
    #[derive(Debug, Default)]
    struct Hooks {
        events: Vec<String>,
        fail_at: Option<u64>,
    }

    impl Observer for Hooks {
        fn start(&mut self, sim: &Simulation) -> Result<(), ObserverError> {
            self.events.push(format!("start {}", sim.steps()));
            Ok(())
        }

        fn observe(&mut self, frame: &Frame<'_>) -> Result<(), ObserverError> {
            if self.fail_at == Some(frame.step) {
                return Err("stop here".into());
            }
            self.events.push(format!(
                "{}{}",
                frame.step,
                if frame.last { "!" } else { "" }
            ));
            Ok(())
        }

        fn finish(&mut self) -> Result<(), ObserverError> {
            self.events.push("finish".into());
            Ok(())
        }
    }

    /// A short run of the paper's circle: `steps` steps of 1 ms.
    fn circle(steps: u64) -> Simulation {
        Scenario::builtin("experiment-circle")
            .unwrap()
            .build(&Overrides {
                dt: Some(0.001),
                duration: Some(steps as f64 * 0.001),
                ..Overrides::default()
            })
            .unwrap()
            .simulation
    }

    #[test]
    fn hooks_run_once_around_the_frames_every_shows() {
        let mut sim = circle(10);
        let mut every = Every::new(4, Hooks::default());
        sim.run(&mut every).unwrap();
        let events = every.into_inner().events;
        assert_eq!(
            events,
            ["start 10", "0", "4", "8", "10!", "finish"].map(String::from)
        );
        // 0 and 1 show every frame; a multiple of the run shows no extra last.
        for (k, want) in [(0, 11), (1, 11), (5, 3), (10, 2), (20, 2)] {
            let mut sim = circle(10);
            let mut every = Every::new(k, Hooks::default());
            sim.run(&mut every).unwrap();
            assert_eq!(every.get_ref().events.len() - 2, want, "every {k}");
        }
    }

    #[test]
    fn a_failed_run_is_not_finished() {
        let mut sim = circle(10);
        let mut hooks = Hooks {
            fail_at: Some(3),
            ..Hooks::default()
        };
        let err = sim.run(&mut hooks).unwrap_err();
        assert!(err.to_string().contains("stop here"), "{err}");
        assert_eq!(hooks.events, ["start 10", "0", "1", "2"].map(String::from));
    }

    #[test]
    fn observers_in_an_array_each_see_every_hook_in_order() {
        let mut sim = circle(3);
        let (mut a, mut b) = (Hooks::default(), Some(Hooks::default()));
        let mut none: Option<Hooks> = None;
        sim.run(&mut [&mut a as &mut dyn Observer, &mut b, &mut none])
            .unwrap();
        let want = ["start 3", "0", "1", "2", "3!", "finish"].map(String::from);
        assert_eq!(a.events, want);
        assert_eq!(b.unwrap().events, want);
    }
}
