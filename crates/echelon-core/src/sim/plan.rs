//! The plan of a run: a scenario resolved into plain, validated values
//! (agents and their drives, the reference, timing, odometry, safety) that
//! the simulator ([`crate::sim::Simulation::new`]), the batch engine and
//! every fleet role read. Built by `echelon::scenario::Scenario::build` or
//! by hand ([`Plan::new`], then [`Plan::with_odometry`],
//! [`Plan::with_safety`]); each constructor refuses what cannot run, so a
//! `Plan` always can.

use crate::check;
use crate::error::{FormationError, SimError};
use crate::error::{ParamError, num};
use crate::formation::agent::AgentSpec;
use crate::formation::{Formation, Leader};
use crate::law::control::Variant;
use crate::law::lycomp::{FitCoefficients, LyComp, OffsetFrame};
use crate::math::whole_ratio;
use crate::odometry::{Odometer, OdometrySpec};
use crate::reference::Reference;
use crate::safety::{Obstacle, SafetyConfig};
use crate::sim::guard::Bounds;

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
            format!("s at dt {} s is {steps:e} steps: too many", num(dt)),
        )?;
        if let Timing::Sampled { period } = timing {
            check::multiple_of("controller_period", period, dt, "dt")?;
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
    pub(crate) fn steps(&self) -> u64 {
        Self::steps_for(self.dt, self.duration) as u64
    }

    /// Steps between controller samples (0: continuous).
    pub(crate) fn hold_every(&self) -> u64 {
        match self.timing {
            Timing::Continuous => 0,
            Timing::Sampled { period } => whole_ratio(period, self.dt).unwrap_or(1),
        }
    }
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
    /// Refuses what the agents cannot do behind `reference`: a slot in the
    /// leader's frame behind a reference that stands still at times (it
    /// has no heading there).
    pub fn behind(&self, reference: &Reference) -> Result<(), FormationError> {
        match self.specs.iter().position(|a| {
            a.leader() == Leader::Reference
                && a.placement().frame() == OffsetFrame::Leader
                && !reference.keeps_moving()
        }) {
            Some(i) => Err(FormationError::LeaderFrameNeedsHeading { agent: i + 1 }),
            None => Ok(()),
        }
    }

    /// Checks the agents together (each is valid by [`AgentSpec::new`]).
    pub fn new(specs: Vec<AgentSpec>) -> Result<Agents, FormationError> {
        let formation = Formation::new(specs.iter().map(|a| a.leader()).collect())?;
        for (i, a) in specs.iter().enumerate() {
            if let Leader::Agent(j) = a.leader()
                && a.placement().uses_exact_derivatives()
            {
                return Err(FormationError::ExactDerivativesNeedReference {
                    agent: i + 1,
                    leader: j + 1,
                });
            }
            if let Leader::Agent(j) = a.leader()
                && a.torque_robot().is_some()
                && specs[j]
                    .velocity_robot()
                    .is_some_and(|r| r.base().tau_v() == 0.0)
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

/// A run, resolved and checked: what the simulator, the batch engine and
/// the fleet's roles build from. Read-only once built.
#[derive(Debug, Clone)]
pub struct Plan {
    agents: Agents,
    reference: Reference,
    config: SimConfig,
    /// Each agent's odometer at `t = 0` (empty when no agent dead-reckons)
    /// and its sampling interval in steps.
    odometers: Vec<Option<Odometer>>,
    odometry_every: Vec<u64>,
    seed: u64,
    safety: Option<SafetySpec>,
    warnings: Vec<String>,
}

impl Plan {
    /// A plan from agents and settings that are valid by construction
    /// ([`AgentSpec::new`], [`SimConfig::new`]), refusing what only exists
    /// at the level of the formation ([`Agents::new`]) and a velocity base's
    /// lag the step cannot resolve
    /// ([`crate::model::base::VelocityBase::check_step`]).
    pub fn new(
        agents: Vec<AgentSpec>,
        reference: Reference,
        config: SimConfig,
    ) -> Result<Plan, SimError> {
        for (i, a) in agents.iter().enumerate() {
            if let Some(r) = a.velocity_robot() {
                r.base()
                    .check_step(config.dt)
                    .map_err(|source| SimError::Param {
                        context: format!("agent {} robot", i + 1),
                        source,
                    })?;
            }
        }
        let agents = Agents::new(agents)?;
        agents.behind(&reference)?;
        Ok(Plan::of(agents, reference, config))
    }

    /// [`Plan::new`] for agents already checked together: checks nothing
    /// more, and notes what is allowed but probably not meant
    /// ([`Plan::warnings`]).
    pub fn of(agents: Agents, reference: Reference, config: SimConfig) -> Plan {
        let mut warnings = Vec::new();
        for (i, a) in agents.specs.iter().enumerate() {
            let ctx = format!("agent {}", i + 1);
            if a.variant() == Some(Variant::Paper) && a.gains().ke() * a.gains().kz() <= 0.25 {
                warnings.push(format!(
                    "{ctx}: K_e K_z = {} ≤ 1/4: Theorem 1 does not guarantee convergence for the paper law (use law = \"complete\")",
                    a.gains().ke() * a.gains().kz()
                ));
            }
            let (lo, hi) = FitCoefficients::PAPER_RANGE;
            if a.placement().lycomp() == LyComp::Fit && !(lo..=hi).contains(&a.placement().lx_off())
            {
                warnings.push(format!(
                    "{ctx}: L_Xoff = {} m is outside the range {lo}–{hi} m where the eq. 6 fit holds (use lycomp = \"exact\")",
                    a.placement().lx_off()
                ));
            }
        }
        Plan {
            agents,
            reference,
            config,
            odometers: Vec::new(),
            odometry_every: Vec::new(),
            seed: 0,
            safety: None,
            warnings,
        }
    }

    /// Gives agents odometers: `specs[i]` for agent `i` (`None`: it knows
    /// its true pose). The controller then acts on the odometry estimate
    /// while the plant moves truly. Random errors draw from `seed`, one
    /// stream per agent. Refuses sampling periods that are not whole
    /// multiples of `dt` and invalid models.
    pub fn with_odometry(
        mut self,
        specs: Vec<Option<OdometrySpec>>,
        seed: u64,
    ) -> Result<Plan, SimError> {
        let n = self.agents.specs.len();
        if specs.len() != n {
            return Err(SimError::Timing(format!(
                "{} odometry specs for {n} agents",
                specs.len()
            )));
        }
        self.seed = seed;
        if specs.iter().all(Option::is_none) {
            self.odometers = Vec::new();
            self.odometry_every = Vec::new();
            return Ok(self);
        }
        let dt = self.config.dt;
        let mut odometers = Vec::with_capacity(n);
        let mut every = Vec::with_capacity(n);
        for (i, (spec, a)) in specs.into_iter().zip(&self.agents.specs).enumerate() {
            let context = || format!("agent {} odometry", i + 1);
            match spec {
                None => {
                    odometers.push(None);
                    every.push(1);
                }
                Some(spec) => {
                    let param = |source| SimError::Param {
                        context: context(),
                        source,
                    };
                    let k =
                        check::multiple_of("period", spec.period(), dt, &format!("dt = {dt} s"))
                            .map_err(param)?;
                    let (l, r) = a.drive().wheels();
                    let o = Odometer::with_wheels(spec, l, r, &a.start(), seed, i as u64);
                    odometers.push(Some(o));
                    every.push(k);
                }
            }
        }
        self.odometers = odometers;
        self.odometry_every = every;
        Ok(self)
    }

    /// Puts a safety filter between each agent's law and its base
    /// ([`crate::safety`]); `spec.agents[i]` for agent `i` (`None`: it does
    /// not filter). The law and the filter then run once per controller
    /// period (once per step `dt` for a continuous-time controller) and the
    /// filtered command is held in between. Refuses a spec of the wrong
    /// length, and a robot whose point starts within `radius` of another's
    /// or of an obstacle's edge.
    pub fn with_safety(mut self, spec: SafetySpec) -> Result<Plan, SimError> {
        let n = self.agents.specs.len();
        if spec.agents.len() != n {
            return Err(SimError::Timing(format!(
                "{} safety configs for {n} agents",
                spec.agents.len()
            )));
        }
        if spec.agents.iter().all(Option::is_none) {
            self.safety = None;
            return Ok(self);
        }
        let points: Vec<[f64; 2]> = self
            .agents
            .specs
            .iter()
            .map(|a| crate::safety::point(&a.start(), a.placement().l()))
            .collect();
        if let Some((agent, source)) =
            crate::safety::start_conflict(&points, &spec.agents, &spec.obstacles)
        {
            return Err(SimError::Param {
                context: format!("agent {} start", agent + 1),
                source,
            });
        }
        self.safety = Some(spec);
        Ok(self)
    }

    /// The agents.
    pub fn agents(&self) -> &[AgentSpec] {
        &self.agents.specs
    }

    /// The leader graph.
    pub fn formation(&self) -> &Formation {
        &self.agents.formation
    }

    /// The reference the virtual leader follows.
    pub fn reference(&self) -> &Reference {
        &self.reference
    }

    /// The integration settings.
    pub fn config(&self) -> &SimConfig {
        &self.config
    }

    /// Steps of the run (it ends at the first step at or after `duration`).
    pub fn steps(&self) -> u64 {
        self.config.steps()
    }

    /// Each agent's odometer at `t = 0` (empty when no agent dead-reckons).
    pub fn odometers(&self) -> &[Option<Odometer>] {
        &self.odometers
    }

    /// Agent `i`'s (0-based) odometer, `None` when it knows its true pose
    /// (or the plan has no odometry at all: [`Plan::odometers`] is empty then).
    pub fn odometer(&self, i: usize) -> Option<&Odometer> {
        self.odometers.get(i).and_then(Option::as_ref)
    }

    /// Each agent's odometry sampling interval, in steps (empty without
    /// odometry).
    pub fn odometry_every(&self) -> &[u64] {
        &self.odometry_every
    }

    /// The seed of the random models.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// The safety settings (`None`: no agent filters).
    pub fn safety(&self) -> Option<&SafetySpec> {
        self.safety.as_ref()
    }

    /// The obstacles every agent knows (empty without a safety filter).
    pub fn obstacles(&self) -> &[Obstacle] {
        self.safety.as_ref().map_or(&[], |s| &s.obstacles[..])
    }

    /// Agent `i`'s safety settings (`None`: it does not filter).
    pub fn safety_of(&self, i: usize) -> Option<SafetyConfig> {
        self.safety.as_ref()?.agents.get(i).copied().flatten()
    }

    /// The smallest `radius` among the agents that filter (`None`: none does).
    pub fn safety_radius(&self) -> Option<f64> {
        let s = self.safety.as_ref()?;
        s.agents.iter().flatten().map(|c| c.radius).reduce(f64::min)
    }

    /// Things that are allowed but probably not what the user wants.
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }
}
