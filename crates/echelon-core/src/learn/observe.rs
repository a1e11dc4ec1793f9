//! Observations ([`super::layout`]), rewards and the baseline policy.

use super::env::{Env, Robot};
use super::layout::{
    E, LEADER_ACCELERATION, LEADER_VELOCITY, NEIGHBOURS, OFFSETS, PER_NEIGHBOUR, PER_OBSTACLE,
    SPEEDS,
};
use super::{EnvConfig, Scalar};
use crate::law::control::{Gains, LeaderMotion, Offset, Variant, law};
use crate::math::lanes::Lanes;
use crate::model::RobotParams;
use crate::model::State;
use crate::reference::{Circle, Jet, Order, Reference, Trajectory};
use crate::safety::Obstacle;

/// The most neighbours an observation lists.
pub const MAX_NEIGHBOURS: usize = 16;
/// The most obstacles an observation lists.
pub const MAX_OBSTACLES: usize = 16;

/// Robot `i`'s `e` (eq. 7) and `R ṗ_d` in its frame, from its heading's
/// `(sin, cos)`.
#[inline]
fn errors(
    s: &State,
    (sin, cos): (f64, f64),
    pd: [f64; 2],
    dpd: [f64; 2],
    lx: f64,
    ly: f64,
) -> ([f64; 2], [f64; 2]) {
    let (dx, dy) = (s.x - pd[0], s.y - pd[1]);
    let e = [cos * dx + sin * dy + lx, -sin * dx + cos * dy + ly];
    let q = [cos * dpd[0] + sin * dpd[1], -sin * dpd[0] + cos * dpd[1]];
    (e, q)
}

/// Environments per block of leaders evaluated together in lanes.
const JW: usize = 8;

/// Each environment's leader now to [`Order::Two`] into `jets` (one per
/// environment): the circles of a block of [`JW`] environments together
/// ([`crate::reference::Circle::jets`], branch-free sines and cosines), any
/// other reference alone ([`Trajectory::eval`]).
#[inline(always)]
pub(super) fn leader_jets(envs: &[Env], jets: &mut [Jet]) {
    for (envs, jets) in envs.chunks(JW).zip(jets.chunks_mut(JW)) {
        let mut all = [None; JW];
        for (c, env) in all.iter_mut().zip(envs) {
            if let Reference::Circle(circle) = &env.leader {
                *c = Some(circle);
            }
        }
        if envs.len() == JW && all.iter().all(Option::is_some) {
            let circles = all.map(|c| c.unwrap_or_else(|| unreachable!("all circles")));
            let t = Lanes(std::array::from_fn(|k| envs[k].t));
            let (p, dp, ddp) = Circle::jets(circles, t);
            for (k, j) in jets.iter_mut().enumerate() {
                *j = Jet {
                    p: [p[0].0[k], p[1].0[k]],
                    dp: [dp[0].0[k], dp[1].0[k]],
                    ddp: [ddp[0].0[k], ddp[1].0[k]],
                    ..Jet::default()
                };
            }
        } else {
            for (j, env) in jets.iter_mut().zip(envs) {
                *j = env.leader.eval(env.t, Order::Two);
            }
        }
    }
}

/// One environment at one instant, as the observations see it.
#[derive(Debug, Clone, Copy)]
pub(super) struct Seen<'a> {
    /// Its robots, their headings as of their states
    /// ([`super::plant::sense`]).
    pub(super) robots: &'a [Robot],
    /// Their points `l` ahead: every `x`, then every `y`
    /// ([`super::plant::place`]).
    pub(super) points: &'a [f64],
    /// Its leader now (to [`Order::Two`]).
    pub(super) jet: Jet,
    /// Its obstacles.
    pub(super) obstacles: &'a [Obstacle],
}

/// Points compared at a time in the neighbour search: their squared
/// distances computed together (in vectors, from the points' `x` and `y`
/// each contiguous), then looked at only when one is a candidate.
const CHUNK: usize = 8;

/// The `best.len()` points of `(xs, ys)` nearest to point `me` within
/// `sqrt(sense2)`, nearest first as `(squared distance, index)` into `best`
/// (the rest infinite); returns the squared distance to the nearest of all
/// (infinite alone). Ties keep the lower index first.
#[inline(always)]
fn nearest(xs: &[f64], ys: &[f64], me: usize, sense2: f64, best: &mut [(f64, usize)]) -> f64 {
    best.fill((f64::INFINITY, 0));
    if xs.len() < 2 {
        return f64::INFINITY;
    }
    let (px, py) = (xs[me], ys[me]);
    // A point is listed when within `sense` and nearer than the last
    // listed so far (none with no room).
    let mut kth = best.last().map_or(f64::NEG_INFINITY, |b| b.0);
    // The nearest of all, lane by lane (folded at the end).
    let mut low = [f64::INFINITY; CHUNK];
    for (c, (cx, cy)) in xs.chunks(CHUNK).zip(ys.chunks(CHUNK)).enumerate() {
        let mut d = [f64::INFINITY; CHUNK];
        if let (Ok(cx), Ok(cy)) = (<&[f64; CHUNK]>::try_from(cx), <&[f64; CHUNK]>::try_from(cy)) {
            for m in 0..CHUNK {
                let (dx, dy) = (cx[m] - px, cy[m] - py);
                d[m] = dx * dx + dy * dy;
            }
        } else {
            for ((d, x), y) in d.iter_mut().zip(cx).zip(cy) {
                let (dx, dy) = (x - px, y - py);
                *d = dx * dx + dy * dy;
            }
        }
        let base = c * CHUNK;
        if (base..base + CHUNK).contains(&me) {
            d[me - base] = f64::INFINITY;
        }
        for (low, &d) in low.iter_mut().zip(&d) {
            *low = if d < *low { d } else { *low };
        }
        // The candidates as bits, looked at in index order.
        let mut candidates = 0u32;
        for (m, &dist) in d.iter().enumerate() {
            candidates |= u32::from(dist <= sense2 && dist < kth) << m;
        }
        while candidates != 0 {
            let m = candidates.trailing_zeros() as usize;
            candidates &= candidates - 1;
            let dist = d[m];
            if dist >= kth {
                continue;
            }
            // Insert, moving the farther ones down one place (branch-free:
            // where it goes is as unpredictable as the robots).
            let mut item = (dist, base + m);
            for slot in best.iter_mut() {
                let here = item.0 < slot.0;
                let (keep, carry) = if here { (item, *slot) } else { (*slot, item) };
                (*slot, item) = (keep, carry);
            }
            kth = best.last().map_or(kth, |b| b.0);
        }
    }
    let mut w = CHUNK;
    while w > 1 {
        w /= 2;
        for m in 0..w {
            low[m] = if low[m + w] < low[m] {
                low[m + w]
            } else {
                low[m]
            };
        }
    }
    low[0]
}

/// The `best.len()` obstacles whose edge is nearest to point `me` and
/// within `sense`, nearest first as `(edge distance, index)` into `best`
/// (the rest infinite); returns the distance from `me` to the nearest edge
/// of all (infinite without obstacles). Ties keep the lower index first.
#[inline(always)]
fn nearest_obstacles(
    obstacles: &[Obstacle],
    me: [f64; 2],
    sense: f64,
    best: &mut [(f64, usize)],
) -> f64 {
    best.fill((f64::INFINITY, 0));
    let mut low = f64::INFINITY;
    for (m, o) in obstacles.iter().enumerate() {
        let edge = (o.x() - me[0]).hypot(o.y() - me[1]) - o.r();
        low = low.min(edge);
        if edge <= sense && best.last().is_some_and(|b| edge < b.0) {
            let mut item = (edge, m);
            for slot in best.iter_mut() {
                if item.0 < slot.0 {
                    std::mem::swap(slot, &mut item);
                }
            }
        }
    }
    low
}

/// What [`write`] found beyond the observations.
#[derive(Debug, Clone, Copy)]
pub(super) struct Found {
    /// The mean of the robots' rewards (0 without rewards).
    pub(super) reward: f64,
    /// The smallest squared distance between two robots' points (infinite
    /// with one robot).
    pub(super) closest2: f64,
    /// The smallest distance from a robot's point to an obstacle's edge
    /// (infinite without obstacles).
    pub(super) obstacle: f64,
}

/// Writes one environment's observations (`N · obs_dim`) and, with
/// `rewards = Some(out)`, each robot's reward ([`super::Weights`]) for the
/// step that ended under its `applied` action; returns their mean and the
/// closest distances ([`Found`]). One pass over the pairs serves all.
#[inline(always)]
pub(super) fn write<T: Scalar>(
    config: &EnvConfig,
    seen: Seen<'_>,
    out: &mut [T],
    mut rewards: Option<&mut [T]>,
) -> Found {
    let Seen {
        robots,
        points,
        jet,
        obstacles,
    } = seen;
    let (xs, ys) = points.split_at(robots.len());
    let d = config.obs_dim();
    let k = config.neighbours.min(MAX_NEIGHBOURS);
    let ko = config.seen_obstacles.min(MAX_OBSTACLES);
    let sense2 = config.sense * config.sense;
    let radius2 = config.radius * config.radius;
    let (mut sum, mut closest, mut clearance) = (0.0, f64::INFINITY, f64::INFINITY);
    let mut best = [(f64::INFINITY, 0usize); MAX_NEIGHBOURS];
    let mut seen_obstacles = [(f64::INFINITY, 0usize); MAX_OBSTACLES];
    for (i, (robot, o)) in robots.iter().zip(out.chunks_exact_mut(d)).enumerate() {
        let (s, [sin, cos], [lx, ly]) = (&robot.state, robot.heading, robot.slot);
        let (e, q) = errors(s, (sin, cos), jet.p, jet.dp, lx, ly);
        let acc = [
            cos * jet.ddp[0] + sin * jet.ddp[1],
            -sin * jet.ddp[0] + cos * jet.ddp[1],
        ];
        let head = [e[0], e[1], s.v, s.omega, q[0], q[1], acc[0], acc[1], lx, ly];
        for (slot, v) in o[..NEIGHBOURS].iter_mut().zip(head) {
            *slot = T::of(v);
        }
        debug_assert_eq!(
            (E, LEADER_VELOCITY, LEADER_ACCELERATION, OFFSETS),
            (0, 4, 6, 8)
        );
        let near = nearest(xs, ys, i, sense2, &mut best[..k]);
        closest = closest.min(near);
        let me = [xs[i], ys[i]];
        let (listed, rest) = o[NEIGHBOURS..].split_at_mut(PER_NEIGHBOUR * k);
        for (&(dist, j), nb) in best[..k].iter().zip(listed.chunks_exact_mut(PER_NEIGHBOUR)) {
            if dist.is_finite() {
                let (dx, dy) = (xs[j] - me[0], ys[j] - me[1]);
                nb[0] = T::of(cos * dx + sin * dy);
                nb[1] = T::of(-sin * dx + cos * dy);
                nb[2] = T::of(1.0);
            } else {
                nb.fill(T::of(0.0));
            }
        }
        let edge = nearest_obstacles(obstacles, me, config.sense, &mut seen_obstacles[..ko]);
        clearance = clearance.min(edge);
        for (&(dist, m), ob) in seen_obstacles[..ko]
            .iter()
            .zip(rest.chunks_exact_mut(PER_OBSTACLE))
        {
            if dist.is_finite() {
                let c = &obstacles[m];
                let (dx, dy) = (c.x() - me[0], c.y() - me[1]);
                ob[0] = T::of(cos * dx + sin * dy);
                ob[1] = T::of(-sin * dx + cos * dy);
                ob[2] = T::of(c.r());
                ob[3] = T::of(1.0);
            } else {
                ob.fill(T::of(0.0));
            }
        }
        if let Some(r) = rewards.as_mut() {
            let (w, a) = (config.weights, robot.applied);
            let effort = match config.robot {
                None => a[0] * a[0] + (config.l * a[1]).powi(2),
                Some(_) => a[0] * a[0] + a[1] * a[1],
            };
            let hits = f64::from(u8::from(near < radius2) + u8::from(edge < config.radius));
            let value =
                -w.tracking * (e[0] * e[0] + e[1] * e[1]) - w.effort * effort - w.collision * hits;
            r[i] = T::of(value);
            sum += value;
        }
    }
    Found {
        reward: sum / robots.len() as f64,
        closest2: closest,
        obstacle: clearance,
    }
}

/// The kinematic law ([`crate::law::kinematic`]) from an observation alone:
/// `ξ* = R ṗ_d − K_e e`, `ω* = ξ*₂ / L_X`, `v* = ξ*₁ + ω* L_Y` (`L̇_Y = 0`:
/// the environments hold fixed offsets). `obs` holds whole observations of
/// `obs_dim` values, `actions` receives `(v*, ω*)` for each.
pub fn baseline<T: Scalar>(obs: &[T], obs_dim: usize, ke: f64, actions: &mut [T]) {
    for (o, a) in obs.chunks_exact(obs_dim).zip(actions.chunks_exact_mut(2)) {
        let xi = [
            o[LEADER_VELOCITY].get() - ke * o[E].get(),
            o[LEADER_VELOCITY + 1].get() - ke * o[E + 1].get(),
        ];
        let omega = xi[1] / o[OFFSETS].get();
        a[0] = T::of(xi[0] + omega * o[OFFSETS + 1].get());
        a[1] = T::of(omega);
    }
}

/// The complete law (eqs. 9–13 with the cross term cancelled,
/// [`crate::law::control::law`]) from an observation alone, as wheel torques
/// `(τ_r, τ_l)` for `robot`: the robot put at the origin facing `x` (the law
/// is the same in any frame), its leader at `(L_X, L_Y) − e` with the
/// observed `R ṗ_d`, `R p̈_d`, `L̇_Y = L̈_Y = 0`.
pub fn baseline_torque<T: Scalar>(
    obs: &[T],
    obs_dim: usize,
    robot: &RobotParams,
    gains: Gains,
    actions: &mut [T],
) {
    for (o, a) in obs.chunks_exact(obs_dim).zip(actions.chunks_exact_mut(2)) {
        let g = |k: usize| o[k].get();
        let me = State {
            x: 0.0,
            y: 0.0,
            theta: 0.0,
            v: g(SPEEDS),
            omega: g(SPEEDS + 1),
        };
        let (lx, ly) = (g(OFFSETS), g(OFFSETS + 1));
        let leader = LeaderMotion {
            p: [lx - g(E), ly - g(E + 1)],
            dp: [g(LEADER_VELOCITY), g(LEADER_VELOCITY + 1)],
            ddp: [g(LEADER_ACCELERATION), g(LEADER_ACCELERATION + 1)],
        };
        let off = Offset {
            lx,
            ly,
            dly: 0.0,
            ddly: 0.0,
        };
        let u = law(robot, &me, &leader, &off, gains, Variant::Complete).u;
        let tau = robot.torques(u);
        a[0] = T::of(tau.right);
        a[1] = T::of(tau.left);
    }
}

/// Environments at most in a [`Group`] (its leaders' jets on the stack).
pub(super) const GROUP_ENVS: usize = 64;

/// A group of (at most [`GROUP_ENVS`]) environments' observations and,
/// after their step (their robots moved and placed, their clocks on),
/// their rewards and facts ([`write`] for each), compiled for the best
/// instruction set this CPU has ([`pulp::Arch::dispatch`]).
pub(super) struct Group<'a, T> {
    pub(super) config: &'a EnvConfig,
    pub(super) envs: &'a [Env],
    pub(super) robots: &'a [Robot],
    /// Their points ([`Seen::points`]), environment after environment.
    pub(super) points: &'a [f64],
    pub(super) obs: &'a mut [T],
    /// With the facts: after a step.
    pub(super) step: Option<(&'a mut [T], &'a mut [super::EnvFacts])>,
}

impl<T: Scalar> pulp::WithSimd for Group<'_, T> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) {
        let Group {
            config,
            envs,
            robots,
            points,
            obs,
            step,
        } = self;
        let n = config.num_agents;
        let d = config.obs_dim();
        let mut jets = [Jet::default(); GROUP_ENVS];
        let jets = &mut jets[..envs.len()];
        leader_jets(envs, jets);
        let each = robots
            .chunks(n)
            .zip(points.chunks(2 * n))
            .zip(obs.chunks_mut(n * d))
            .zip(jets.iter());
        match step {
            None => {
                for (env, (((robots, points), o), &jet)) in envs.iter().zip(each) {
                    let seen = Seen {
                        robots,
                        points,
                        jet,
                        obstacles: &env.obstacles,
                    };
                    write(config, seen, o, None);
                }
            }
            Some((rewards, facts)) => {
                let outs = rewards.chunks_mut(n).zip(facts.iter_mut());
                for ((env, (((robots, points), o), &jet)), (r, f)) in
                    envs.iter().zip(each).zip(outs)
                {
                    let seen = Seen {
                        robots,
                        points,
                        jet,
                        obstacles: &env.obstacles,
                    };
                    let found = write(config, seen, o, Some(r));
                    *f = super::EnvFacts {
                        reward: found.reward,
                        truncated: env.steps >= config.max_steps,
                        min_distance: found.closest2.sqrt(),
                        obstacle_distance: found.obstacle,
                    };
                }
            }
        }
    }
}
