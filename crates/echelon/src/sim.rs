//! The simulator: fixed-step RK4 over a formation of robots.
//!
//! The law is evaluated inside every RK4 stage (a continuous-time controller, as
//! the paper simulates in Simulink), leaders before followers so that a follower
//! sees its leader's state and acceleration at the same instant. Optionally the
//! controller is sampled at a period `T_s` and its command held (zero-order hold)
//! in between. Stepping is explicit ([`Simulation::step`]) over plain data; the
//! same inputs give the same bits.

use crate::agent::{Actuation, Command, Guard, Sight};
pub use crate::agent::{AgentSpec, Drive};
use crate::base::VelocityCommand;
use crate::control::{LawOutput, errors};
use crate::error::SimError;
use crate::follow::{LeaderView, follow};
use crate::formation::{Formation, Leader};
use crate::kinematic::kinematic_law;
pub use crate::model::Pose;
use crate::model::{Input, State, Torques};
use crate::odometry::Odometer;
pub use crate::plan::{Agents, Plan, SafetySpec, SimConfig, Timing};
use crate::reference::{Jet, Order, Reference, Trajectory};
use crate::safety::{Neighbour, Obstacle, Outcome, SafetyFilter};

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
    fn commanded(&self) -> Command {
        match self.velocity {
            Some(v) => Command::Velocity(v.command),
            None => Command::Torque(self.command),
        }
    }

    /// The outputs of an agent whose true errors are `e`, `z`, whose
    /// controller sees `e_hat`, `z_hat`, commanding `command` of which its
    /// motors apply `applied`.
    fn of(
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
        held: Option<&[Command]>,
        odometers: &[Option<Odometer>],
        mut out: Option<&mut [AgentOutput]>,
        dx: &mut [State],
        speeds: &mut [[f64; 4]],
    ) {
        if let (None, Some(h)) = (&out, held) {
            // Between samples of a sampled controller, with nobody looking at
            // the law's outputs: only the plant moves.
            for (i, a) in self.agents.iter().enumerate() {
                let applied = a.drive.actuate(h[i]);
                dx[i] = a.drive.derivative(&x[i], &applied);
                speeds[i] = a.drive.speeds(&x[i], &applied);
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
            let law = follow(a, &sensed(i), leader);
            let (LawOutput { e, z, .. }, motion, offset) = (law.law, law.leader, law.offset);
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
            let command = held.map_or_else(|| law.command(), |h| h[i]);
            let applied = a.drive.actuate(command);
            dx[i] = a.drive.derivative(&x[i], &applied);
            speeds[i] = a.drive.speeds(&x[i], &applied);
            let output = AgentOutput::of(e_true, z_true, e, z, command, &applied);
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
    plan: Plan,
    config: SimConfig,
    steps: u64,
    hold_every: u64,
    step: u64,
    state: Vec<State>,
    /// The commands held between controller samples (the law's, filtered).
    held: Vec<Command>,
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

impl Simulation {
    /// The simulation of `plan` at `t = 0`.
    pub fn new(plan: &Plan) -> Simulation {
        let agents = plan.agents().to_vec();
        let config = *plan.config();
        let order = if agents.iter().any(|a| a.placement.uses_exact_derivatives()) {
            Order::Four
        } else {
            Order::Two
        };
        let uses_reference = agents.iter().any(|a| a.leader == Leader::Reference);
        let n = agents.len();
        let state: Vec<State> = agents.iter().map(|a| a.start).collect();
        let velocity_agents = agents.iter().any(|a| a.velocity_robot().is_some());
        let held = agents.iter().map(|a| a.drive.zero()).collect();
        let mut hold_every = config.hold_every();
        let safety = plan.safety().map(|spec| {
            if hold_every == 0 {
                hold_every = 1;
            }
            let period = hold_every as f64 * config.dt;
            Box::new(SafetyState {
                filters: spec
                    .agents
                    .iter()
                    .map(|c| c.map(|c| SafetyFilter::new(c).with_period(period)))
                    .collect(),
                obstacles: spec.obstacles.clone(),
                l: agents.iter().map(|a| a.placement.l).collect(),
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
            })
        });
        Simulation {
            sys: System {
                agents,
                formation: plan.formation().clone(),
                reference: plan.reference().clone(),
                order,
                uses_reference,
            },
            plan: plan.clone(),
            config,
            steps: config.steps(),
            hold_every,
            step: 0,
            state,
            held,
            velocity_agents,
            speeds: std::array::from_fn(|_| vec![[0.0; 4]; n]),
            out: vec![AgentOutput::default(); n],
            k1: vec![State::default(); n],
            fresh: false,
            odometers: plan.odometers().to_vec(),
            odometry_every: plan.odometry_every().to_vec(),
            distance: vec![0.0; n],
            input_integral: vec![[0.0; 2]; n],
            safety,
            stage: vec![State::default(); n],
            k2: vec![State::default(); n],
            k3: vec![State::default(); n],
            k4: vec![State::default(); n],
        }
    }

    /// The plan it runs.
    pub fn plan(&self) -> &Plan {
        &self.plan
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
        self.plan.warnings()
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
                *h = o.commanded();
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
            let guard = Guard {
                filter,
                sight: Sight::Neighbours(&safety.neighbours),
                obstacles: &safety.obstacles,
            };
            let act = self.sys.agents[i].act(t, &safety.seen[i], self.held[i], Some(guard));
            self.held[i] = act.command;
            let o = &mut safety.out[i];
            o.nominal = act.nominal.values();
            o.filtered = act.command.values();
            if let Some(g) = act.safety {
                (o.outcome, o.deadlock, o.min_distance) = (g.outcome, g.deadlock, g.min_distance);
            }
            let Some(filter) = safety.filters[i].as_ref() else {
                continue;
            };
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
            let applied = a.drive.actuate(self.held[i]);
            let o = &mut self.out[i];
            (o.u, o.tau) = (applied.u, applied.tau);
            if let (Some(v), Some((c, _))) = (o.velocity.as_mut(), applied.velocity) {
                v.applied = c;
            }
        }
    }

    /// The obstacles every agent knows (empty without a safety filter).
    pub fn obstacles(&self) -> &[Obstacle] {
        self.plan.obstacles()
    }

    /// Whether a safety filter runs.
    pub fn has_safety(&self) -> bool {
        self.safety.is_some()
    }

    /// The smallest `radius` among the agents that filter (`None`: none does).
    pub fn safety_radius(&self) -> Option<f64> {
        self.plan.safety_radius()
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
            .simulation()
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
