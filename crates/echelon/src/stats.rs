//! Run statistics: per agent ([`AgentStats`], [`Summary`]: `summary.json`'s
//! `agents`, and the fleet collector's per-robot figures), the safety
//! filter's ([`SafetyWatch`]: `summary.json`'s `safety`) and where a run
//! diverged ([`Divergence`]).

use crate::agent::AgentSpec;
use crate::error::SimError;
use crate::model::{Pose, State};
use crate::safety::{Obstacle, Outcome};
use crate::sample::AgentSample;
use crate::sim::{Frame, Observer, ObserverError, Simulation};

/// Per-agent statistics of a run (what `summary.json` reports).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct AgentSummary {
    /// 1-based agent number.
    pub agent: usize,
    /// Display name.
    pub name: String,
    /// Final pose `{x, y, theta}` (θ wrapped to (−π, π]).
    pub final_pose: Pose,
    /// Final ‖e‖, m.
    pub final_error: f64,
    /// RMS of ‖e‖ over every step of the run, m.
    pub rms_error: f64,
    /// Largest wheel torque magnitude applied at any step, N m.
    pub peak_torque: f64,
    /// Time after which ‖e‖ stays below the settling tolerance, s (`None`: never).
    pub settle_time: Option<f64>,
    /// Steps at which a velocity base's speed limits cut the command (only
    /// for velocity agents; absent for torque-driven ones).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub saturated_ticks: Option<u64>,
}

/// Where and how a run diverged (`summary.json`'s `diverged`).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
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
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
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
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SafetyReport {
    /// The smallest `radius` among the agents that filter, m.
    pub radius: f64,
    /// Smallest distance between two robots' points `L` ahead, m.
    pub min_distance: f64,
    /// When it happened, s.
    pub min_distance_t: f64,
    /// Between which agents (1-based).
    pub min_distance_agents: [usize; 2],
    /// Smallest distance from a robot's point to an obstacle's edge, m
    /// (absent without obstacles).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub min_obstacle_clearance: Option<f64>,
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

/// Gathers a [`SafetyReport`] over a run (nothing without a safety filter).
#[derive(Debug, Clone, Default)]
pub struct SafetyWatch {
    l: Vec<f64>,
    obstacles: Vec<Obstacle>,
    report: Option<SafetyReport>,
}

impl SafetyWatch {
    /// The report, `None` when the run had no safety filter.
    pub fn report(&self) -> Option<&SafetyReport> {
        self.report.as_ref()
    }

    /// Smallest distance between two robots' points in `states`, and which.
    pub fn closest_pair(states: &[State], l: &[f64]) -> Option<(f64, [usize; 2])> {
        let points: Vec<[f64; 2]> = states
            .iter()
            .zip(l)
            .map(|(s, &l)| crate::safety::point(s, l))
            .collect();
        let mut best = None;
        for i in 0..points.len() {
            for j in 0..i {
                let d = (points[i][0] - points[j][0]).hypot(points[i][1] - points[j][1]);
                if best.is_none_or(|(b, _)| d < b) {
                    best = Some((d, [j + 1, i + 1]));
                }
            }
        }
        best
    }
}

impl Observer for SafetyWatch {
    fn start(&mut self, sim: &Simulation) -> Result<(), ObserverError> {
        if !sim.has_safety() {
            return Ok(());
        }
        self.l = sim.agents().iter().map(|a| a.placement().l()).collect();
        self.obstacles = sim.obstacles().to_vec();
        let radius = sim.safety_radius().unwrap_or(f64::INFINITY);
        self.report = Some(SafetyReport {
            radius,
            min_distance: f64::INFINITY,
            min_distance_t: 0.0,
            min_distance_agents: [0, 0],
            min_obstacle_clearance: (!self.obstacles.is_empty()).then_some(f64::INFINITY),
            active: 0,
            infeasible: 0,
            deadlock_breaks: 0,
            deadlocked_at_end: Vec::new(),
            agents: (1..=self.l.len())
                .map(|agent| AgentSafety {
                    agent,
                    active: 0,
                    infeasible: 0,
                    deadlock_breaks: 0,
                    deadlocked_at_end: false,
                })
                .collect(),
        });
        Ok(())
    }

    fn observe(&mut self, frame: &Frame<'_>) -> Result<(), ObserverError> {
        let Some(r) = self.report.as_mut() else {
            return Ok(());
        };
        if let Some((d, pair)) = SafetyWatch::closest_pair(frame.states, &self.l)
            && d < r.min_distance
        {
            (r.min_distance, r.min_distance_t, r.min_distance_agents) = (d, frame.t, pair);
        }
        if let Some(clear) = r.min_obstacle_clearance.as_mut() {
            for (s, &l) in frame.states.iter().zip(&self.l) {
                let p = crate::safety::point(s, l);
                for o in &self.obstacles {
                    *clear = clear.min((p[0] - o.x()).hypot(p[1] - o.y()) - o.r());
                }
            }
        }
        for ((a, o), out) in r.agents.iter_mut().zip(frame.safety).zip(frame.outputs) {
            if o.sampled {
                a.active += u64::from(o.outcome != Outcome::Nominal);
                a.infeasible += u64::from(o.outcome == Outcome::Braked);
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
