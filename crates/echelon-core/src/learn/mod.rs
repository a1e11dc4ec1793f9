//! Formation control as a vectorised multi-agent environment: `E`
//! environments of `N` velocity-base robots each, stepped under actions
//! from outside (a learned policy), with observations and rewards out —
//! what `echelon.envs` (Gymnasium, PettingZoo) wraps.
//!
//! Each environment is a formation behind a virtual leader, a reference of
//! constant speed and turn rate ([`crate::reference::Circle`]): robot `i`
//! holds its leader `L_X` ahead and `L_Y` to the left in its own frame
//! (eq. 7), slots on a lattice `spacing` metres apart behind the leader,
//! jittered and shuffled per episode. A robot's action is a velocity command
//! `(v, ω)`, clipped to the base's limits, applied through the base model
//! ([`VelocityBase::rk4_step`]: lags, limits) for one step `dt`; with a
//! safety radius set it goes through the robot's own barrier-certificate
//! filter first ([`crate::safety::SafetyFilter::velocity`]), every robot seeing the others
//! as cooperative neighbours, as in the fleet.
//!
//! An episode may hold static disc obstacles ([`Obstacle`]): drawn on the
//! leader's path (`obstacles` of them per episode), or a scenario's. The
//! observations list the nearest, the rewards count coming within the
//! radius of one's edge as a collision, and the filter keeps every robot's
//! point at least the radius clear of every edge.
//!
//! Observations ([`layout`]) carry what the kinematic law needs, so the
//! paper's law is a policy of observations alone ([`baseline`]).
//!
//! Everything is plain data on caller-owned buffers: [`VecFormation::step`]
//! reads `E·N·2` actions and writes observations, rewards and the step's
//! facts; it allocates nothing once built and runs its environments on all
//! cores (rayon).

mod env;
mod episode;
pub mod layout;
mod observe;
mod plant;

use pulp::Arch;
use rayon::prelude::*;

use crate::engine::VConsts;
use crate::error::ParamError;
use crate::law::lycomp::LyComp;
use crate::model::base::VelocityBase;
use crate::model::{RobotParams, State};
use crate::reference::Reference;
use crate::safety::{Obstacle, SafetyConfig};

use env::{Env, Robot};
pub use episode::{FixedEpisode, PlanRobots};
pub use observe::{MAX_NEIGHBOURS, MAX_OBSTACLES, baseline, baseline_torque};

/// A number an environment's buffers hold (`f64`, or `f32` on request).
pub trait Scalar: Copy + Send + Sync + 'static {
    /// `v` in this type (rounded for `f32`).
    fn of(v: f64) -> Self;
    /// This value as `f64`.
    fn get(self) -> f64;
}

impl Scalar for f64 {
    #[inline]
    fn of(v: f64) -> Self {
        v
    }
    #[inline]
    fn get(self) -> f64 {
        self
    }
}

impl Scalar for f32 {
    #[inline]
    fn of(v: f64) -> Self {
        v as f32
    }
    #[inline]
    fn get(self) -> f64 {
        f64::from(self)
    }
}

/// The weights of a robot's reward (per step):
/// `r = −tracking ‖e‖² − effort ‖a‖² − collision · ([a neighbour's point
/// within the radius] + [an obstacle's edge within the radius])`, with
/// `a = (v, l ω)` the clipped action (`(τ_r, τ_l)` on torque robots).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Weights {
    /// Per m² of tracking error.
    pub tracking: f64,
    /// Per (m/s)² of action.
    pub effort: f64,
    /// Per step spent within the radius of another robot's point (and
    /// again per step within the radius of an obstacle's edge).
    pub collision: f64,
}

impl Default for Weights {
    fn default() -> Self {
        Weights {
            tracking: 1.0,
            effort: 0.01,
            collision: 10.0,
        }
    }
}

/// Everything that makes a set of environments, checked by
/// [`VecFormation::new`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EnvConfig {
    /// `E`, ≥ 1.
    pub num_envs: usize,
    /// `N`, ≥ 1.
    pub num_agents: usize,
    /// Step, s (> 0).
    pub dt: f64,
    /// Distance between neighbouring slots, m (> 0).
    pub spacing: f64,
    /// The point ahead of the axle that the safety filter keeps apart, m (> 0).
    pub l: f64,
    /// The distance between two robots' points counted as a collision (and
    /// kept by the filter when `safety`), m (> 0).
    pub radius: f64,
    /// Whether every action goes through the safety filter.
    pub safety: bool,
    /// The filter's `γ`, 1/s.
    pub gain: f64,
    /// The robots' base (speed limits bound the actions; lags, if any)
    /// when `robot` is `None`.
    pub base: VelocityBase,
    /// Torque-driven robots (eq. 3) instead of velocity bases: the actions
    /// are wheel torques `(τ_r, τ_l)`, N m, bounded by its `torque_limit`
    /// (which must be set).
    pub robot: Option<RobotParams>,
    /// How many neighbours each observation lists (nearest first).
    pub neighbours: usize,
    /// Neighbours farther than this (point to point) are not listed, nor
    /// obstacles whose edge is farther, m.
    pub sense: f64,
    /// Obstacles drawn per episode (a scenario's episodes hold its own).
    pub obstacles: usize,
    /// Their radii are drawn in `[obstacle_radius.0, obstacle_radius.1]`, m.
    pub obstacle_radius: (f64, f64),
    /// How many obstacles each observation lists (nearest edge first).
    pub seen_obstacles: usize,
    /// Reward weights.
    pub weights: Weights,
    /// Steps before an episode is truncated (≥ 1).
    pub max_steps: u64,
    /// The leader's speed is drawn in `[speed.0, speed.1]` m/s per episode.
    pub speed: (f64, f64),
    /// Its turn rate in `[−turn, turn]` rad/s.
    pub turn: f64,
}

impl EnvConfig {
    /// The bound on each action component: `(v_max, ω_max)`, or the torque
    /// limit on both wheels.
    pub fn action_bound(&self) -> [f64; 2] {
        match &self.robot {
            None => [self.base.v_max(), self.base.omega_max()],
            Some(r) => [r.torque_limit().unwrap_or(f64::INFINITY); 2],
        }
    }

    /// Values per robot observation ([`layout::obs_dim`]).
    pub fn obs_dim(&self) -> usize {
        layout::obs_dim(self.neighbours, self.seen_obstacles)
    }

    /// `num_envs × num_agents` robots on an ideal base limited to 0.5 m/s and
    /// 2 rad/s, 1 m apart, 50 ms steps, no filter, no obstacles.
    pub fn new(num_envs: usize, num_agents: usize) -> EnvConfig {
        EnvConfig {
            num_envs,
            num_agents,
            dt: 0.05,
            spacing: 1.0,
            l: 0.1,
            radius: 0.4,
            safety: false,
            gain: 1.0,
            base: layout::default_base(),
            robot: None,
            neighbours: 4,
            sense: 3.0,
            obstacles: 0,
            obstacle_radius: (0.1, 0.3),
            seen_obstacles: 0,
            weights: Weights::default(),
            max_steps: 500,
            speed: (0.05, 0.2),
            turn: 0.1,
        }
    }

    fn check(&self) -> Result<(), ParamError> {
        let count = |field, n: usize| {
            if n == 0 {
                Err(ParamError::new(field, 0.0, "must be ≥ 1"))
            } else {
                Ok(())
            }
        };
        count("num_envs", self.num_envs)?;
        count("num_agents", self.num_agents)?;
        crate::check::positive("dt", self.dt)?;
        crate::check::positive("spacing", self.spacing)?;
        crate::check::positive("l", self.l)?;
        crate::check::positive("radius", self.radius)?;
        crate::check::positive("gain", self.gain)?;
        crate::check::positive("sense", self.sense)?;
        if self.max_steps == 0 {
            return Err(ParamError::new("max_steps", 0.0, "must be ≥ 1"));
        }
        let (lo, hi) = self.speed;
        if !(lo.is_finite() && hi.is_finite() && 0.0 <= lo && lo <= hi) {
            return Err(ParamError::new(
                "speed",
                lo,
                "must be 0 ≤ low ≤ high, finite",
            ));
        }
        if !(self.turn.is_finite() && self.turn >= 0.0) {
            return Err(ParamError::new("turn", self.turn, "must be finite and ≥ 0"));
        }
        let w = self.weights;
        for (f, v) in [
            ("weights.tracking", w.tracking),
            ("weights.effort", w.effort),
            ("weights.collision", w.collision),
        ] {
            if !v.is_finite() {
                return Err(ParamError::new(f, v, "must be finite"));
            }
        }
        if let Some(robot) = &self.robot {
            if robot.torque_limit().is_none() {
                return Err(ParamError::new(
                    "robot.torque_limit",
                    f64::INFINITY,
                    "must be set (it bounds the actions)",
                ));
            }
        } else if self.base.v_max().is_infinite() || self.base.omega_max().is_infinite() {
            return Err(ParamError::new(
                "base",
                f64::INFINITY,
                "needs finite v_max and omega_max (they bound the actions)",
            ));
        }
        if self.neighbours > observe::MAX_NEIGHBOURS {
            return Err(ParamError::new(
                "neighbours",
                self.neighbours as f64,
                "must be ≤ 16",
            ));
        }
        if self.seen_obstacles > observe::MAX_OBSTACLES {
            return Err(ParamError::new(
                "seen_obstacles",
                self.seen_obstacles as f64,
                "must be ≤ 16",
            ));
        }
        let (lo, hi) = self.obstacle_radius;
        if !(lo.is_finite() && hi.is_finite() && 0.0 < lo && lo <= hi) {
            return Err(ParamError::new(
                "obstacle_radius",
                lo,
                "must be 0 < low ≤ high, finite",
            ));
        }
        if self.safety {
            SafetyConfig::new(self.radius, self.gain, f64::INFINITY)?;
        }
        self.base.check_step(self.dt)
    }
}

/// What one step of one environment says beyond its observations.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EnvFacts {
    /// The mean of its robots' rewards.
    pub reward: f64,
    /// The episode reached `max_steps`.
    pub truncated: bool,
    /// The smallest distance between two robots' points after the step, m
    /// (infinite with one robot).
    pub min_distance: f64,
    /// The smallest distance from a robot's point to an obstacle's edge
    /// after the step, m (infinite without obstacles).
    pub obstacle_distance: f64,
}

/// `E` environments of `N` robots (see the module documentation).
#[derive(Debug, Clone)]
pub struct VecFormation {
    config: EnvConfig,
    /// The base in lanes ([`plant`]).
    consts: VConsts,
    /// The best instruction set of this CPU, for [`plant`].
    arch: Arch,
    /// Every robot, environment after environment (`E·N`).
    robots: Vec<Robot>,
    /// Every robot's point `l` ahead (`2·E·N`), environment after
    /// environment: its robots' `x`, then their `y` ([`plant::place`]).
    points: Vec<f64>,
    envs: Vec<Env>,
    /// Every episode's formation, when it is a scenario's.
    fixed: Option<std::sync::Arc<FixedEpisode>>,
}

impl VecFormation {
    /// The environments of `config`, reset with `seed` (environment `k`'s
    /// episodes drawn from `seed` and `k`).
    pub fn new(config: EnvConfig, seed: u64) -> Result<VecFormation, ParamError> {
        config.check()?;
        let n = config.num_agents;
        let mut me = VecFormation {
            config,
            consts: VConsts::new(&config.base, config.dt, LyComp::None),
            arch: Arch::new(),
            robots: vec![Robot::default(); config.num_envs * n],
            points: vec![0.0; 2 * config.num_envs * n],
            envs: vec![Env::new(&config, n); config.num_envs],
            fixed: None,
        };
        me.reset(seed, None);
        Ok(me)
    }

    /// Environments whose every episode is `fixed` (a scenario's formation,
    /// [`FixedEpisode::of_plan`]); `config.num_agents` must be its number of
    /// agents.
    pub fn fixed(
        config: EnvConfig,
        fixed: FixedEpisode,
        seed: u64,
    ) -> Result<VecFormation, ParamError> {
        let n = fixed.starts.len();
        if n != config.num_agents || fixed.lx.len() != n || fixed.ly.len() != n {
            return Err(ParamError::new(
                "num_agents",
                config.num_agents as f64,
                format!("must be the scenario's number of agents, {n}"),
            ));
        }
        if config.obstacles != 0 {
            return Err(ParamError::new(
                "obstacles",
                config.obstacles as f64,
                "must be 0 with a scenario (its episodes hold the scenario's obstacles)",
            ));
        }
        let config = EnvConfig {
            obstacles: fixed.obstacles.len(),
            ..config
        };
        let mut me = VecFormation::new(config, seed)?;
        me.fixed = Some(std::sync::Arc::new(fixed));
        me.reset(seed, None);
        Ok(me)
    }

    /// The configuration.
    pub fn config(&self) -> &EnvConfig {
        &self.config
    }

    /// Values per robot observation ([`layout::obs_dim`]).
    pub fn obs_dim(&self) -> usize {
        self.config.obs_dim()
    }

    /// Reseeds every environment from `seed` and resets those `mask` selects
    /// (all when `None`); the others keep their state and their episode.
    pub fn reset(&mut self, seed: u64, mask: Option<&[bool]>) {
        let (config, n) = (self.config, self.config.num_agents);
        let robots = self.robots.chunks_mut(n).zip(self.points.chunks_mut(2 * n));
        for (k, (env, (robots, points))) in self.envs.iter_mut().zip(robots).enumerate() {
            env.episode_seed = episode::mix(seed, k as u64);
            if mask.is_none_or(|m| m[k]) {
                env.start(&config, self.fixed.as_deref(), robots, points);
            }
        }
    }

    /// Resets the environments `mask` selects, each with its next episode
    /// from its own stream (what autoreset does).
    pub fn reset_next(&mut self, mask: &[bool]) {
        let (config, n) = (self.config, self.config.num_agents);
        let robots = self.robots.chunks_mut(n).zip(self.points.chunks_mut(2 * n));
        for ((env, (robots, points)), &on) in self.envs.iter_mut().zip(robots).zip(mask) {
            if on {
                env.start(&config, self.fixed.as_deref(), robots, points);
            }
        }
    }

    /// Writes every robot's observation into `obs` (`E·N·obs_dim`).
    pub fn observe<T: Scalar>(&self, obs: &mut [T]) {
        let n = self.config.num_agents;
        let per = n * self.obs_dim();
        assert_eq!(obs.len(), self.envs.len() * per, "obs length");
        let (config, arch, g) = (&self.config, self.arch, group_envs(n));
        obs.par_chunks_mut(g * per)
            .zip(self.envs.par_chunks(g))
            .zip(self.robots.par_chunks(g * n))
            .zip(self.points.par_chunks(g * 2 * n))
            .for_each(|(((obs, envs), robots), points)| {
                arch.dispatch(observe::Group {
                    config,
                    envs,
                    robots,
                    points,
                    obs,
                    step: None,
                });
            });
    }

    /// One step of every environment under `actions` (`E·N·2`, `(v, ω)` per
    /// robot; clipped to the base's limits): observations into `obs`,
    /// each robot's reward into `rewards` (`E·N`), how much the filter
    /// changed each action (`‖Δ(v, Lω)‖`, m/s) into `changed` (`E·N`), and
    /// each environment's facts into `facts` (`E`). Actions must be finite
    /// (checked by the caller: [`first_not_finite`]).
    pub fn step<T: Scalar>(
        &mut self,
        actions: &[T],
        obs: &mut [T],
        rewards: &mut [T],
        changed: &mut [T],
        facts: &mut [EnvFacts],
    ) {
        let (e, n, d) = (self.envs.len(), self.config.num_agents, self.obs_dim());
        assert!(
            actions.len() == e * n * 2
                && obs.len() == e * n * d
                && rewards.len() == e * n
                && changed.len() == e * n
                && facts.len() == e,
            "buffer lengths"
        );
        let (config, consts, arch) = (&self.config, &self.consts, self.arch);
        // Groups of environments, their robots stepped together in lanes.
        let g = group_envs(n);
        self.envs
            .par_chunks_mut(g)
            .zip(self.robots.par_chunks_mut(g * n))
            .zip(self.points.par_chunks_mut(g * 2 * n))
            .zip(actions.par_chunks(g * n * 2))
            .zip(obs.par_chunks_mut(g * n * d))
            .zip(rewards.par_chunks_mut(g * n))
            .zip(changed.par_chunks_mut(g * n))
            .zip(facts.par_chunks_mut(g))
            .for_each(|(((((((envs, robots), points), a), o), r), c), f)| {
                env::clip(config, robots, a);
                if config.safety {
                    let each = robots.chunks_mut(n).zip(c.chunks_mut(n));
                    for (env, (robots, c)) in envs.iter_mut().zip(each) {
                        env.filter(config, robots, c);
                    }
                } else {
                    c.fill(T::of(0.0));
                }
                plant::advance(config, consts, arch, robots);
                for ((env, robots), points) in envs
                    .iter_mut()
                    .zip(robots.chunks(n))
                    .zip(points.chunks_mut(2 * n))
                {
                    env.t += config.dt;
                    env.steps += 1;
                    plant::place(robots, config.l, points);
                }
                arch.dispatch(observe::Group {
                    config,
                    envs,
                    robots,
                    points,
                    obs: o,
                    step: Some((r, f)),
                });
            });
    }

    /// Every robot's state, environment by environment.
    pub fn states(&self) -> impl Iterator<Item = &State> {
        self.robots.iter().map(|r| &r.state)
    }

    /// Environment `k`'s leader.
    pub fn leader(&self, k: usize) -> &Reference {
        &self.envs[k].leader
    }

    /// Environment `k`'s slots: each robot's `L_X`, `L_Y` (eq. 7), m.
    pub fn slots(&self, k: usize) -> impl Iterator<Item = [f64; 2]> + '_ {
        let n = self.config.num_agents;
        self.robots[k * n..(k + 1) * n].iter().map(|r| r.slot)
    }

    /// Environment `k`'s obstacles (its episode's).
    pub fn obstacles(&self, k: usize) -> &[Obstacle] {
        &self.envs[k].obstacles
    }

    /// Environment `k`'s time in its episode, s.
    pub fn time(&self, k: usize) -> f64 {
        self.envs[k].t
    }
}

/// Robots per group of environments stepped together ([`plant`]): whole
/// blocks of lanes, few enough groups' worth of work to share the cores.
const GROUP_ROBOTS: usize = 64;

/// Environments of `n` robots per group: [`GROUP_ROBOTS`]' worth (at
/// least one environment; at most [`observe::GROUP_ENVS`]).
fn group_envs(n: usize) -> usize {
    GROUP_ROBOTS.div_ceil(n).min(observe::GROUP_ENVS)
}

/// The index of the first value of `values` that is not finite.
pub fn first_not_finite<T: Scalar>(values: &[T]) -> Option<usize> {
    values.iter().position(|v| !v.get().is_finite())
}

#[cfg(test)]
mod tests;
