//! Run statistics: per agent ([`AgentStats`], [`Summary`]: `summary.json`'s
//! `agents`, and the fleet collector's per-robot figures), the safety
//! filter's ([`SafetyWatch`]: `summary.json`'s `safety`) and where a run
//! diverged ([`Divergence`]).

use crate::agent::AgentSpec;
use crate::error::SimError;
use crate::model::{Pose, State};
use crate::plan::Plan;
use crate::safety::{Obstacle, Tally};
use crate::sample::AgentSample;
use crate::sim::{Frame, Observer, ObserverError, Simulation};

/// `null` (how JSON writes a value that is not finite) read back as NaN.
fn nan_if_null<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(<Option<f64> as serde::Deserialize>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// Per-agent statistics of a run (what `summary.json` reports; read back by
/// the report).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AgentSummary {
    /// 1-based agent number.
    pub agent: usize,
    /// Display name.
    pub name: String,
    /// Final pose `{x, y, theta}` (θ wrapped to (−π, π]).
    pub final_pose: Pose,
    /// Final ‖e‖, m.
    #[serde(deserialize_with = "nan_if_null")]
    pub final_error: f64,
    /// RMS of ‖e‖ over every step of the run, m.
    #[serde(deserialize_with = "nan_if_null")]
    pub rms_error: f64,
    /// Largest wheel torque magnitude applied at any step, N m.
    #[serde(deserialize_with = "nan_if_null")]
    pub peak_torque: f64,
    /// Time after which ‖e‖ stays below the settling tolerance, s (`None`: never).
    pub settle_time: Option<f64>,
    /// Steps at which a velocity base's speed limits cut the command (only
    /// for velocity agents; absent for torque-driven ones).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub saturated_ticks: Option<u64>,
}

/// Where and how a run diverged (`summary.json`'s `diverged`).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Divergence {
    /// 1-based agent number.
    pub agent: usize,
    /// Its name.
    pub name: String,
    /// When, s.
    pub t: f64,
    /// What left its bound (`|v|`, `|omega|`, `‖(x, y)‖`, or a component
    /// that is not finite).
    pub quantity: String,
    /// Its value (`null` when not finite).
    pub value: Option<f64>,
    /// Its bound (`null` for a value that must only be finite).
    pub bound: Option<f64>,
    /// The one-line message.
    pub message: String,
}

impl Divergence {
    /// From a [`SimError::Diverged`]; `None` for any other error.
    pub fn of(e: &SimError) -> Option<Divergence> {
        let SimError::Diverged {
            agent,
            name,
            t,
            breach,
        } = e
        else {
            return None;
        };
        Some(Divergence {
            agent: *agent,
            name: name.clone(),
            t: *t,
            quantity: breach.quantity.to_owned(),
            value: breach.value.is_finite().then_some(breach.value),
            bound: breach.bound.is_finite().then_some(breach.bound),
            message: e.to_string(),
        })
    }
}

/// The running statistics of one agent's samples, in the order they come:
/// what `summary.json` reports per agent ([`Summary`], fed by the simulator)
/// and what the fleet collector reports per robot (fed by the states it
/// records). The one place these statistics are computed.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct AgentStats {
    samples: u64,
    sum_sq: f64,
    peak_torque: f64,
    settled_since: Option<f64>,
    last: Option<AgentSample>,
    saturated: Option<u64>,
}

impl AgentStats {
    /// Adds sample `s`; `tolerance` is the settling tolerance on ‖e‖, m.
    pub fn add(&mut self, s: &AgentSample, tolerance: f64) {
        self.samples += 1;
        let ne = s.error_norm();
        self.sum_sq += ne * ne;
        self.peak_torque = self.peak_torque.max(s.peak_torque());
        if ne >= tolerance {
            self.settled_since = None;
        } else if self.settled_since.is_none() {
            self.settled_since = Some(s.t);
        }
        if let Some(v) = s.velocity {
            *self.saturated.get_or_insert(0) += u64::from(v.sat);
        }
        self.last = Some(*s);
    }

    /// Samples added.
    pub fn samples(&self) -> u64 {
        self.samples
    }

    /// The last sample added.
    pub fn last(&self) -> Option<&AgentSample> {
        self.last.as_ref()
    }

    /// ‖e‖ of the last sample, m (`NaN` before any).
    pub fn final_error(&self) -> f64 {
        self.last.map_or(f64::NAN, |s| s.error_norm())
    }

    /// RMS of ‖e‖ over the samples, m.
    pub fn rms_error(&self) -> f64 {
        (self.sum_sq / self.samples.max(1) as f64).sqrt()
    }

    /// Largest wheel torque magnitude of any sample, N m.
    pub fn peak_torque(&self) -> f64 {
        self.peak_torque
    }

    /// Time after which ‖e‖ stayed below the tolerance, s (`None`: it did not).
    pub fn settle_time(&self) -> Option<f64> {
        self.settled_since
    }

    /// Samples at which a velocity base's speed limits cut the command
    /// (`None` for a torque-driven robot).
    pub fn saturated_ticks(&self) -> Option<u64> {
        self.saturated
    }
}

/// Accumulates [`AgentSummary`] statistics over every frame of a run: one
/// [`AgentStats`] per agent, fed with the frame's [`AgentSample`]s.
#[derive(Debug, Clone)]
pub struct Summary {
    tolerance: f64,
    agents: Vec<AgentStats>,
}

impl Summary {
    /// The settling tolerance on ‖e‖ used by `summary.json`: 1 cm.
    pub const SETTLE_TOLERANCE: f64 = 0.01;

    /// Whether a robot ended deadlocked: more than [`Self::SETTLE_TOLERANCE`]
    /// from its slot (‖e‖ = `error`) while its filter `held` it
    /// ([`crate::safety::SafetyFilter::deadlocked`]). The simulator's
    /// summary and the fleet robot's report use this one rule.
    pub fn deadlocked_at_end(held: bool, error: f64) -> bool {
        held && error >= Self::SETTLE_TOLERANCE
    }

    /// A summary for `n` agents with the given settling tolerance on ‖e‖ (m).
    pub fn new(n: usize, tolerance: f64) -> Summary {
        Summary {
            tolerance,
            agents: vec![AgentStats::default(); n],
        }
    }

    /// Each agent's statistics so far.
    pub fn stats(&self) -> &[AgentStats] {
        &self.agents
    }

    /// The per-agent results, named after `agents`.
    pub fn agents(&self, agents: &[AgentSpec]) -> Vec<AgentSummary> {
        agents
            .iter()
            .zip(&self.agents)
            .enumerate()
            .map(|(i, (a, stats))| AgentSummary {
                agent: i + 1,
                name: a.name().to_owned(),
                final_pose: stats.last().map_or(Pose::default(), |s| Pose {
                    x: s.x,
                    y: s.y,
                    theta: s.theta,
                }),
                final_error: stats.final_error(),
                rms_error: stats.rms_error(),
                peak_torque: stats.peak_torque(),
                settle_time: stats.settle_time(),
                saturated_ticks: stats.saturated_ticks(),
            })
            .collect()
    }
}

impl Observer for Summary {
    fn observe(&mut self, frame: &Frame<'_>) -> Result<(), ObserverError> {
        for (stats, sample) in self.agents.iter_mut().zip(AgentSample::all(frame)) {
            stats.add(&sample, self.tolerance);
        }
        Ok(())
    }
}

/// One agent's safety statistics over a run.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AgentSafety {
    /// 1-based agent number.
    pub agent: usize,
    /// Controller samples at which the filter changed the command.
    pub active: u64,
    /// Controller samples at which the QP was infeasible (or failed) and the
    /// robot braked.
    pub infeasible: u64,
    /// Deadlocks it started breaking.
    pub deadlock_breaks: u64,
    /// Whether, at the end of the run, it was not within the settling
    /// tolerance of its slot and its filter held it ([`crate::sim::SafetyOutput::deadlocked`]):
    /// a robot that did not reach its slot
    /// because the filter held it is reported here, never silently.
    pub deadlocked_at_end: bool,
}

/// Safety statistics of a run (`summary.json`'s `safety`), from the true
/// states of every frame it is shown (every step in `run_to_dir`).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SafetyReport {
    /// The closest approach (`radius`, `min_distance`, `min_distance_t`,
    /// `min_distance_agents`, `min_obstacle_clearance`: the same keys at
    /// the top of `summary.json`'s `safety`).
    #[serde(flatten)]
    pub closest: ClosestApproach,
    /// Sum over agents of [`AgentSafety::active`].
    pub active: u64,
    /// Sum over agents of [`AgentSafety::infeasible`].
    pub infeasible: u64,
    /// Sum over agents of [`AgentSafety::deadlock_breaks`].
    pub deadlock_breaks: u64,
    /// Agents deadlocked at the end of the run (1-based).
    pub deadlocked_at_end: Vec<usize>,
    /// Per agent.
    pub agents: Vec<AgentSafety>,
}

/// The geometric part of the safety statistics: the closest approach
/// between two robots' points `L` ahead (how close, when, which pair) and
/// the smallest obstacle clearance, under the smallest filter `radius`
/// (`summary.json`'s `safety` and `collector.json`'s `approach` share it).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClosestApproach {
    /// The smallest `radius` among the agents that filter, m.
    pub radius: f64,
    /// Smallest distance between two robots' points `L` ahead, m.
    pub min_distance: f64,
    /// When it happened, s.
    pub min_distance_t: f64,
    /// Between which agents (1-based, the smaller first).
    pub min_distance_agents: [usize; 2],
    /// Smallest distance from a robot's point to an obstacle's edge, m
    /// (absent without obstacles).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min_obstacle_clearance: Option<f64>,
}

/// Accumulates a [`ClosestApproach`] over the instants it is shown: at each
/// one, every pair of the robots shown (their points `L` ahead) and every
/// robot against every obstacle. The simulator's [`SafetyWatch`] feeds it
/// every frame; the fleet's collector the states it receives.
#[derive(Debug, Clone)]
pub struct Approach {
    l: Vec<f64>,
    obstacles: Vec<Obstacle>,
    closest: ClosestApproach,
    /// Whether a pair was ever shown.
    paired: bool,
    /// The points of the instant being recorded (kept, so that recording
    /// does not allocate once it has seen every agent).
    points: Vec<(usize, [f64; 2])>,
}

/// Equal when they accumulate for the same agents and obstacles and hold
/// the same result (the scratch points of the last instant are not state).
impl PartialEq for Approach {
    fn eq(&self, other: &Approach) -> bool {
        (&self.l, &self.obstacles, &self.closest, self.paired)
            == (&other.l, &other.obstacles, &other.closest, other.paired)
    }
}

impl Approach {
    /// An accumulator for agents whose points are `l[i]` ahead, filtering
    /// at `radius` among `obstacles`.
    pub fn new(l: Vec<f64>, radius: f64, obstacles: Vec<Obstacle>) -> Approach {
        Approach {
            l,
            closest: ClosestApproach {
                radius,
                min_distance: f64::INFINITY,
                min_distance_t: 0.0,
                min_distance_agents: [0, 0],
                min_obstacle_clearance: (!obstacles.is_empty()).then_some(f64::INFINITY),
            },
            obstacles,
            paired: false,
            points: Vec::new(),
        }
    }

    /// The accumulator of `plan`'s agents and obstacles (`None`: no agent
    /// filters).
    pub fn of(plan: &Plan) -> Option<Approach> {
        let radius = plan.safety_radius()?;
        let l = plan.agents().iter().map(|a| a.placement().l()).collect();
        Some(Approach::new(l, radius, plan.obstacles().to_vec()))
    }

    /// Number of agents.
    pub fn agents(&self) -> usize {
        self.l.len()
    }

    /// Agent `i`'s (0-based) point `L` ahead in state `s`.
    pub fn point(&self, i: usize, s: &State) -> [f64; 2] {
        crate::safety::point(s, self.l[i])
    }

    /// Records every agent's state at time `t` (`states[i]` is agent
    /// `i + 1`'s).
    pub fn record(&mut self, t: f64, states: &[State]) {
        self.record_some(t, states.iter().enumerate());
    }

    /// Records the states of some agents at time `t`: `(i, state)` with `i`
    /// the 0-based agent index, in increasing `i` (agents out of range are
    /// ignored). Ties keep the earliest instant, then the first pair in the
    /// order `(j, i)`, `j < i`, by `i` then `j`.
    pub fn record_some<'s>(
        &mut self,
        t: f64,
        states: impl IntoIterator<Item = (usize, &'s State)>,
    ) {
        let mut points = std::mem::take(&mut self.points);
        points.clear();
        points.extend(
            states
                .into_iter()
                .filter(|&(i, _)| i < self.l.len())
                .map(|(i, s)| (i, self.point(i, s))),
        );
        let c = &mut self.closest;
        for (n, &(i, p)) in points.iter().enumerate() {
            for &(j, q) in &points[..n] {
                let d = (p[0] - q[0]).hypot(p[1] - q[1]);
                self.paired = true;
                if d < c.min_distance {
                    (c.min_distance, c.min_distance_t, c.min_distance_agents) =
                        (d, t, [j + 1, i + 1]);
                }
            }
            if let Some(clear) = c.min_obstacle_clearance.as_mut() {
                for o in &self.obstacles {
                    *clear = clear.min((p[0] - o.x()).hypot(p[1] - o.y()) - o.r());
                }
            }
        }
        self.points = points;
    }

    /// Whether two robots were ever shown at one instant.
    pub fn paired(&self) -> bool {
        self.paired
    }

    /// What it gathered so far.
    pub fn closest(&self) -> &ClosestApproach {
        &self.closest
    }
}

/// Gathers a [`SafetyReport`] over a run (nothing without a safety filter).
#[derive(Debug, Clone, Default)]
pub struct SafetyWatch {
    approach: Option<Approach>,
    report: Option<SafetyReport>,
    /// Each agent's filter answers at its controller's samples.
    tallies: Vec<Tally>,
}

impl SafetyWatch {
    /// The report, `None` when the run had no safety filter.
    pub fn report(&self) -> Option<&SafetyReport> {
        self.report.as_ref()
    }

    /// Smallest distance between two robots' points in `states`, and which
    /// ([`Approach`] over one instant).
    pub fn closest_pair(states: &[State], l: &[f64]) -> Option<(f64, [usize; 2])> {
        let mut a = Approach::new(l.to_vec(), f64::INFINITY, Vec::new());
        a.record(0.0, states);
        let c = a.closest();
        a.paired()
            .then_some((c.min_distance, c.min_distance_agents))
    }
}

impl Observer for SafetyWatch {
    fn start(&mut self, sim: &Simulation) -> Result<(), ObserverError> {
        if !sim.has_safety() {
            return Ok(());
        }
        let l: Vec<f64> = sim.agents().iter().map(|a| a.placement().l()).collect();
        let radius = sim.safety_radius().unwrap_or(f64::INFINITY);
        let approach = Approach::new(l, radius, sim.obstacles().to_vec());
        self.report = Some(SafetyReport {
            closest: approach.closest().clone(),
            active: 0,
            infeasible: 0,
            deadlock_breaks: 0,
            deadlocked_at_end: Vec::new(),
            agents: (1..=approach.agents())
                .map(|agent| AgentSafety {
                    agent,
                    active: 0,
                    infeasible: 0,
                    deadlock_breaks: 0,
                    deadlocked_at_end: false,
                })
                .collect(),
        });
        self.tallies = vec![Tally::default(); approach.agents()];
        self.approach = Some(approach);
        Ok(())
    }

    fn observe(&mut self, frame: &Frame<'_>) -> Result<(), ObserverError> {
        let (Some(r), Some(approach)) = (self.report.as_mut(), self.approach.as_mut()) else {
            return Ok(());
        };
        approach.record(frame.t, frame.states);
        r.closest.clone_from(approach.closest());
        let agents = r.agents.iter_mut().zip(&mut self.tallies);
        for (((a, tally), o), out) in agents.zip(frame.safety).zip(frame.outputs) {
            if o.sampled {
                tally.record(o.outcome, false, f64::INFINITY);
                (a.active, a.infeasible) = (tally.active, tally.infeasible);
            }
            a.deadlock_breaks = o.deadlock_breaks;
            let e = out.e[0].hypot(out.e[1]);
            a.deadlocked_at_end = Summary::deadlocked_at_end(o.enabled && o.deadlocked, e);
        }
        if frame.last {
            r.active = r.agents.iter().map(|a| a.active).sum();
            r.infeasible = r.agents.iter().map(|a| a.infeasible).sum();
            r.deadlock_breaks = r.agents.iter().map(|a| a.deadlock_breaks).sum();
            r.deadlocked_at_end = r
                .agents
                .iter()
                .filter(|a| a.deadlocked_at_end)
                .map(|a| a.agent)
                .collect();
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests;
