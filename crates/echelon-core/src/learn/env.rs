//! One environment's episode and commands, and its robots as one slice of
//! the environments' robots (contiguous across environments, so that a
//! step walks memory in order however few robots an environment has).

use super::{EnvConfig, FixedEpisode, Scalar, episode, plant};
use crate::model::State;
use crate::model::Torques;
use crate::model::base::VelocityCommand;
use crate::reference::Reference;
use crate::safety::{Neighbour, Obstacle, SafetyConfig, SafetyFilter};

/// One robot of one environment: what a step and the observations read and
/// write of it.
#[derive(Debug, Clone, Copy)]
pub(super) struct Robot {
    pub(super) state: State,
    /// `(sin θ, cos θ)`, as of `state` ([`plant::sense`]); its point `l`
    /// ahead is in the environments' points ([`plant::place`]).
    pub(super) heading: [f64; 2],
    /// Its slot: `L_X`, `L_Y` (eq. 7), m.
    pub(super) slot: [f64; 2],
    /// The clipped (and filtered) action of the last step: `(v, ω)` or
    /// `(τ_r, τ_l)`.
    pub(super) applied: [f64; 2],
    /// Scratch: a torque robot's `(v̇, ω̇)` under the torques its filter
    /// gave at the last step, for its neighbours' filters
    /// ([`Neighbour::sharing`]).
    pub(super) shared: [f64; 2],
}

impl Default for Robot {
    fn default() -> Self {
        Robot {
            state: State::default(),
            heading: [0.0, 1.0],
            slot: [0.0; 2],
            applied: [0.0; 2],
            shared: [0.0; 2],
        }
    }
}

/// One environment: its leader, its episode, and its robots' filters.
#[derive(Debug, Clone)]
pub(super) struct Env {
    /// The virtual leader (a [`crate::reference::Circle`] in a drawn
    /// episode, a scenario's reference in a fixed one).
    pub(super) leader: Reference,
    /// Its episode's static obstacles (room for `config.obstacles`, made
    /// once).
    pub(super) obstacles: Vec<Obstacle>,
    /// One per robot with `safety`, else none.
    pub(super) filters: Vec<SafetyFilter>,
    /// Scratch for the filters.
    pub(super) neighbours: Vec<Neighbour>,
    pub(super) t: f64,
    pub(super) steps: u64,
    pub(super) episode_seed: u64,
}

impl Env {
    /// An environment of `n` robots before its first episode.
    pub(super) fn new(config: &EnvConfig, n: usize) -> Env {
        Env {
            leader: Reference::Circle(
                crate::reference::Circle::new([0.0; 2], 0.0, 0.0, 0.0)
                    .unwrap_or_else(|_| unreachable!("a circle at rest")),
            ),
            obstacles: Vec::with_capacity(config.obstacles),
            filters: vec![filter(config); if config.safety { n } else { 0 }],
            neighbours: Vec::with_capacity(if config.safety { n } else { 0 }),
            t: 0.0,
            steps: 0,
            episode_seed: 0,
        }
    }

    /// A new episode of its `robots` (their `points` placed) from this
    /// environment's stream.
    pub(super) fn start(
        &mut self,
        config: &EnvConfig,
        fixed: Option<&FixedEpisode>,
        robots: &mut [Robot],
        points: &mut [f64],
    ) {
        self.episode_seed = episode::mix(self.episode_seed, 0x5eed);
        match fixed {
            None => episode::draw(
                config,
                self.episode_seed,
                &mut self.leader,
                robots,
                &mut self.obstacles,
            ),
            Some(f) => {
                self.leader = f.leader.clone();
                for (i, r) in robots.iter_mut().enumerate() {
                    r.slot = [f.lx[i], f.ly[i]];
                    r.state = f.starts[i];
                }
                self.obstacles.clear();
                self.obstacles.extend_from_slice(&f.obstacles);
            }
        }
        plant::sense(robots);
        plant::place(robots, config.l, points);
        for f in &mut self.filters {
            *f = filter(config);
        }
        for r in robots.iter_mut() {
            r.applied = [0.0; 2];
        }
        self.t = 0.0;
        self.steps = 0;
    }

    /// Its robots' clipped actions ([`clip`]) through their filters into
    /// their `applied` (with `config.safety`: without, the clipped actions
    /// are applied); how much the filter changed each into `changed`. The
    /// robots move in [`plant::advance`].
    pub(super) fn filter<T: Scalar>(
        &mut self,
        config: &EnvConfig,
        robots: &mut [Robot],
        changed: &mut [T],
    ) {
        if let Some(robot) = &config.robot {
            for (r, f) in robots.iter_mut().zip(&self.filters) {
                r.shared = f.last_acceleration(&r.state, robot);
            }
        }
        let torque = config.robot.is_some();
        for (i, change) in changed.iter_mut().enumerate() {
            self.neighbours.clear();
            for (j, r) in robots.iter().enumerate() {
                if j != i {
                    let dv = torque.then_some(r.shared);
                    self.neighbours
                        .push(Neighbour::of_state(&r.state, config.l, dv, true).sharing(torque));
                }
            }
            let nominal = robots[i].applied;
            let (me, filter) = (&robots[i].state, &mut self.filters[i]);
            let a = match &config.robot {
                None => {
                    let cmd = VelocityCommand {
                        v: nominal[0],
                        omega: nominal[1],
                    };
                    let out = filter.velocity(
                        self.t,
                        me,
                        config.l,
                        cmd,
                        &config.base,
                        &self.neighbours,
                        &self.obstacles,
                    );
                    [out.command.v, out.command.omega]
                }
                Some(robot) => {
                    let u = robot.inputs(Torques {
                        right: nominal[0],
                        left: nominal[1],
                    });
                    let out = filter.torque(
                        self.t,
                        me,
                        config.l,
                        robot,
                        u,
                        &self.neighbours,
                        &self.obstacles,
                    );
                    let tau = robot.torques(out.command);
                    [tau.right, tau.left]
                }
            };
            robots[i].applied = a;
            *change = T::of(match config.robot {
                None => (a[0] - nominal[0]).hypot(config.l * (a[1] - nominal[1])),
                Some(_) => (a[0] - nominal[0]).hypot(a[1] - nominal[1]),
            });
        }
    }
}

/// The step's actions clipped to their bounds into `robots`' `applied`
/// (any number of environments' robots at once).
pub(super) fn clip<T: Scalar>(config: &EnvConfig, robots: &mut [Robot], actions: &[T]) {
    let bound = config.action_bound();
    for (r, a) in robots.iter_mut().zip(actions.chunks_exact(2)) {
        r.applied = [
            a[0].get().clamp(-bound[0], bound[0]),
            a[1].get().clamp(-bound[1], bound[1]),
        ];
    }
}

/// A fresh filter of `config`'s radius and gain, stepped at its `dt`.
fn filter(config: &EnvConfig) -> SafetyFilter {
    SafetyFilter::new(
        SafetyConfig::new(config.radius, config.gain, f64::INFINITY)
            .unwrap_or_else(|_| unreachable!("checked by EnvConfig::check")),
    )
    .with_period(config.dt)
}
