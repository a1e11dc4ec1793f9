//! The simulator: fixed-step RK4 over a formation of robots.
//!
//! The law is evaluated inside every RK4 stage (a continuous-time controller, as
//! the paper simulates in Simulink), leaders before followers so that a follower
//! sees its leader's state and acceleration at the same instant. Optionally the
//! controller is sampled at a period `T_s` and its command held (zero-order hold)
//! in between. Stepping is explicit ([`Simulation::step`]) over plain data; the
//! same inputs give the same bits.

use crate::error::SimError;
use crate::formation::agent::{Actuation, Command, Guard, Sight};
use crate::formation::agent::{AgentSpec, Drive};
use crate::formation::{Formation, Leader};
use crate::model::State;
use crate::model::base::VelocityRobot;
use crate::odometry::Odometer;
use crate::reference::{Order, Reference};
use crate::safety::{Neighbour, Obstacle, SafetyFilter};
use crate::sim::plan::{Plan, SimConfig};

mod driven;
pub mod guard;
mod observe;
mod outputs;
pub mod plan;
pub mod sample;
mod system;

pub use driven::StepByError;
pub use observe::{Every, Frame, Observer, ObserverError};
pub use outputs::{AgentOutput, SafetyOutput, VelocityOutput};
use system::{CallerLaw, Source, System};

/// Where the commands of [`Simulation::evaluate_now`] come from.
enum Now<'a, 'b> {
    /// Each agent's own law, through its act step.
    Law,
    /// The held commands (already through the act step).
    Held,
    /// A caller's law in place of each agent's own, through its act step.
    Caller(&'a mut CallerLaw<'b>),
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
    /// Each torque robot's `(v̇, ω̇)` under the torques its filter gave at
    /// the last sample (at its state as seen), for its neighbours' filters
    /// ([`Neighbour::sharing`]); `None` for other agents.
    shared: Vec<Option<[f64; 2]>>,
    neighbours: Vec<Neighbour>,
}

/// A running simulation: plain state vectors stepped explicitly.
#[derive(Debug, Clone)]
pub struct Simulation {
    sys: System,
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
    /// How far each robot travelled along its heading in the last step, m.
    moved: Vec<f64>,
}

impl Simulation {
    /// The simulation of `plan` at `t = 0`.
    pub fn new(plan: &Plan) -> Simulation {
        let agents = plan.agents();
        let config = *plan.config();
        let order = if agents.iter().any(|a| a.placement().needs_jerk()) {
            Order::Four
        } else {
            Order::Two
        };
        let uses_reference = agents.iter().any(|a| a.leader() == Leader::Reference);
        let n = agents.len();
        let state: Vec<State> = agents.iter().map(|a| a.start()).collect();
        let velocity_agents = agents.iter().any(|a| a.velocity_robot().is_some());
        let held = agents.iter().map(|a| a.drive().zero()).collect();
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
                l: agents.iter().map(|a| a.placement().l()).collect(),
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
                shared: vec![None; n],
                neighbours: Vec::with_capacity(n),
            })
        });
        let backup = agents
            .iter()
            .map(|a| a.velocity_robot().and_then(VelocityRobot::backup))
            .collect();
        let backup_period = if hold_every > 0 {
            hold_every as f64 * config.dt
        } else {
            config.dt
        };
        let mut sim = Simulation {
            sys: System {
                plan: plan.clone(),
                order,
                uses_reference,
                backup,
                backup_period,
            },
            moved: vec![0.0; n],
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
        };
        sim.plan_backups(false);
        sim
    }

    /// The plan it runs.
    pub fn plan(&self) -> &Plan {
        &self.sys.plan
    }

    /// Each agent's odometer (empty without odometry).
    pub fn odometers(&self) -> &[Option<Odometer>] {
        &self.odometers
    }

    /// The agents.
    pub fn agents(&self) -> &[AgentSpec] {
        self.sys.plan.agents()
    }

    /// The leader graph.
    pub fn formation(&self) -> &Formation {
        self.sys.plan.formation()
    }

    /// The reference the virtual leader follows.
    pub fn reference(&self) -> &Reference {
        self.sys.plan.reference()
    }

    /// The integration settings.
    pub fn config(&self) -> &SimConfig {
        &self.config
    }

    /// Things that are allowed but probably not what the user wants.
    pub fn warnings(&self) -> &[String] {
        self.sys.plan.warnings()
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

    /// Evaluates every agent at the current state and time (RK4's first
    /// stage): its derivative into `k1`, the stage's speeds and, when
    /// `observe`, its outputs ([`System::evaluate_by`]).
    fn evaluate_now(&mut self, commands: Now<'_, '_>, observe: bool) {
        let source = match commands {
            Now::Law => Source::Law,
            Now::Held => Source::Held(&self.held),
            Now::Caller(law) => Source::Caller(law),
        };
        self.sys.evaluate_by(
            self.time(),
            &self.state,
            source,
            &self.odometers,
            observe.then_some(&mut self.out[..]),
            &mut self.k1,
            &mut self.speeds[0],
        );
    }

    /// Evaluates the controllers at the current state (RK4's first stage), once.
    fn refresh(&mut self) {
        if self.fresh {
            return;
        }
        let sample = self.hold_every > 0 && self.step.is_multiple_of(self.hold_every);
        let held = self.hold_every > 0 && !sample;
        self.evaluate_now(if held { Now::Held } else { Now::Law }, true);
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
            *seen = system::sensed(&self.odometers, &self.state, j);
        }
        // Before any filter answers anew: every torque robot's acceleration
        // under its filter's last answer, what it is doing now (its
        // neighbours take over what it falls short of, `Neighbour::sharing`).
        for (j, agent) in self.sys.plan.agents().iter().enumerate() {
            safety.shared[j] = match (&safety.filters[j], agent.drive()) {
                (Some(f), Drive::Torque { robot, .. }) => {
                    Some(f.last_acceleration(&safety.seen[j], robot))
                }
                _ => None,
            };
        }
        for i in 0..n {
            if safety.filters[i].is_none() {
                continue;
            }
            safety.neighbours.clear();
            for j in (0..n).filter(|&j| j != i) {
                let shared = safety.shared[j];
                let dv = shared.unwrap_or([self.k1[j].v, self.k1[j].omega]);
                safety.neighbours.push(
                    Neighbour::of_state(
                        &safety.seen[j],
                        safety.l[j],
                        Some(dv),
                        safety.filters[j].is_some(),
                    )
                    .sharing(shared.is_some()),
                );
            }
            let Some(filter) = safety.filters[i].as_mut() else {
                continue;
            };
            let guard = Guard {
                filter,
                sight: Sight::Neighbours(&safety.neighbours),
                obstacles: &safety.obstacles,
                error: Some(self.out[i].e_hat[0].hypot(self.out[i].e_hat[1])),
                reverse: self.sys.backup[i].map_or(f64::INFINITY, |b| b.cap()),
            };
            let act = self.sys.plan.agents()[i].act(t, &safety.seen[i], self.held[i], Some(guard));
            self.held[i] = self.sys.within_backup(i, &safety.seen[i], act.command);
            let o = &mut safety.out[i];
            o.nominal = act.nominal.values();
            o.filtered = self.held[i].values();
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
        self.evaluate_now(Now::Held, false);
        for (i, a) in self.sys.plan.agents().iter().enumerate() {
            let applied = a.drive().actuate(self.held[i]);
            let o = &mut self.out[i];
            (o.u, o.tau) = (applied.u, applied.tau);
            if let (Some(v), Some((c, _))) = (o.velocity.as_mut(), applied.velocity) {
                v.applied = c;
            }
        }
    }

    /// The obstacles every agent knows (empty without a safety filter).
    pub fn obstacles(&self) -> &[Obstacle] {
        self.sys.plan.obstacles()
    }

    /// Whether a safety filter runs.
    pub fn has_safety(&self) -> bool {
        self.safety.is_some()
    }

    /// The smallest `radius` among the agents that filter (`None`: none does).
    pub fn safety_radius(&self) -> Option<f64> {
        self.sys.plan.safety_radius()
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
    /// the configuration's [`crate::sim::guard::Bounds`]; the simulation then stays at that state.
    pub fn step(&mut self) -> Result<(), SimError> {
        self.refresh();
        let hold = self.hold_every > 0;
        self.advance(|sys, held, odo, t, x, dx, sp| {
            sys.evaluate(t, x, hold.then_some(held), odo, None, dx, sp);
            Ok(())
        })?;
        if self.velocity_agents {
            self.settle();
        }
        Ok(())
    }

    /// RK4 from the first stage's slope (`k1`, fresh): the three inner
    /// stages, each `x + h k` from the previous stage's slope and then
    /// `stage` (the slope there), and the step's combination, distance,
    /// input integral, bounds and odometry. A failed `stage` leaves the
    /// state as it was.
    #[allow(clippy::type_complexity)]
    fn advance(
        &mut self,
        mut stage: impl FnMut(
            &System,
            &[Command],
            &[Option<Odometer>],
            f64,
            &[State],
            &mut [State],
            &mut [[f64; 4]],
        ) -> Result<(), SimError>,
    ) -> Result<(), SimError> {
        let dt = self.config.dt;
        let t = self.time();
        let (sys, held, odo) = (&self.sys, &self.held[..], &self.odometers[..]);
        let [_, sp2, sp3, sp4] = &mut self.speeds;
        add_scaled(&mut self.stage, &self.state, &self.k1, 0.5 * dt);
        stage(sys, held, odo, t + 0.5 * dt, &self.stage, &mut self.k2, sp2)?;
        add_scaled(&mut self.stage, &self.state, &self.k2, 0.5 * dt);
        stage(sys, held, odo, t + 0.5 * dt, &self.stage, &mut self.k3, sp3)?;
        add_scaled(&mut self.stage, &self.state, &self.k3, dt);
        stage(sys, held, odo, t + dt, &self.stage, &mut self.k4, sp4)?;
        let h6 = dt / 6.0;
        for (i, x) in self.state.iter_mut().enumerate() {
            let k = [&self.k1[i], &self.k2[i], &self.k3[i], &self.k4[i]];
            let before = self.distance[i];
            // ṡ = v through the same RK4 stages: the stage speeds are
            // v, v + dt/2 v̇₁, v + dt/2 v̇₂, v + dt v̇₃.
            if let Drive::Velocity(_) = sys.plan.agents()[i].drive() {
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
            self.moved[i] = self.distance[i] - before;
        }
        self.plan_backups(true);
        self.step += 1;
        self.fresh = false;
        let bounds = self.config.bounds;
        for (i, s) in self.state.iter().enumerate() {
            if let Some(breach) = bounds.check(s) {
                return Err(SimError::Diverged {
                    agent: i + 1,
                    name: self.sys.plan.agents()[i].name().to_owned(),
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
        Ok(())
    }

    /// Brings each backup budget up to date with the last step's motion
    /// (when `moved`) and plans the next step from the state now.
    fn plan_backups(&mut self, moved: bool) {
        let period = self.sys.backup_period;
        let sys = &mut self.sys;
        for (i, b) in sys.backup.iter_mut().enumerate() {
            let (Some(b), Some(r)) = (b.as_mut(), sys.plan.agents()[i].velocity_robot()) else {
                continue;
            };
            if moved {
                b.observe(self.moved[i]);
            }
            b.plan(&r.base(), &self.state[i], period);
        }
    }

    /// Makes each velocity base's state consistent with the command at the new
    /// state ([`Drive::settle`]: an axis without lag takes the command's
    /// velocity), evaluating the controllers there (in sampled
    /// mode, the held command or the new sample).
    fn settle(&mut self) {
        self.refresh();
        self.settle_to_outputs();
    }

    /// [`Simulation::settle`] under the commands in the outputs now.
    fn settle_to_outputs(&mut self) {
        for (i, a) in self.sys.plan.agents().iter().enumerate() {
            if let Some(v) = self.out[i].velocity {
                let applied = Actuation {
                    velocity: Some((v.applied, v.saturated)),
                    ..Actuation::default()
                };
                self.state[i] = a.drive().settle(&self.state[i], &applied);
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

/// `out = x + h k`, agent by agent (an RK4 stage's state).
#[inline]
fn add_scaled(out: &mut [State], x: &[State], k: &[State], h: f64) {
    for (s, (x, k)) in out.iter_mut().zip(x.iter().zip(k)) {
        *s = x.add_scaled(k, h);
    }
}
