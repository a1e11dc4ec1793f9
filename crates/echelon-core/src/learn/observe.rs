//! Observations ([`super::layout`]), rewards and the baseline policy.

use super::env::Robot;
use super::layout::{
    E, LEADER_ACCELERATION, LEADER_VELOCITY, NEIGHBOURS, OFFSETS, SPEEDS, obs_dim,
};
use super::{EnvConfig, Scalar};
use crate::law::control::{Gains, LeaderMotion, Offset, Variant, law};
use crate::model::RobotParams;
use crate::model::State;
use crate::reference::{Order, Reference, Trajectory};

/// The most neighbours an observation lists.
pub const MAX_NEIGHBOURS: usize = 16;

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

/// One environment at one instant, as the observations see it.
#[derive(Debug, Clone, Copy)]
pub(super) struct Seen<'a> {
    /// Its robots, their headings and points as of their states
    /// ([`super::plant::sense`]).
    pub(super) robots: &'a [Robot],
    pub(super) leader: &'a Reference,
    pub(super) t: f64,
}

/// Points compared at a time in the neighbour search: their squared
/// distances computed together (in vectors), then looked at only when one
/// is a candidate.
const CHUNK: usize = 8;

/// The `best.len()` robots' points nearest to robot `me`'s within
/// `sqrt(sense2)`, nearest first as `(squared distance, index)` into `best`
/// (the rest infinite); returns the squared distance to the nearest of all
/// (infinite alone). Ties keep the lower index first.
#[inline(always)]
fn nearest(robots: &[Robot], me: usize, sense2: f64, best: &mut [(f64, usize)]) -> f64 {
    let p = robots[me].point;
    best.fill((f64::INFINITY, 0));
    let mut closest = f64::INFINITY;
    // A point is listed when within `sense` and nearer than the last
    // listed so far (none with no room).
    let mut kth = best.last().map_or(f64::NEG_INFINITY, |b| b.0);
    for (c, chunk) in robots.chunks(CHUNK).enumerate() {
        let mut d = [f64::INFINITY; CHUNK];
        for (d, q) in d.iter_mut().zip(chunk) {
            let (dx, dy) = (q.point[0] - p[0], q.point[1] - p[1]);
            *d = dx * dx + dy * dy;
        }
        let base = c * CHUNK;
        if (base..base + CHUNK).contains(&me) {
            d[me - base] = f64::INFINITY;
        }
        let mut low = f64::INFINITY;
        for &x in &d {
            low = if x < low { x } else { low };
        }
        closest = if low < closest { low } else { closest };
        if !(low <= sense2 && low < kth) {
            continue;
        }
        for (m, &dist) in d.iter().enumerate() {
            if !(dist <= sense2 && dist < kth) {
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
    closest
}

/// Writes one environment's observations (`N · obs_dim`) and, with
/// `rewards = Some(out)`, each robot's reward ([`super::Weights`]) for the
/// step that ended under its `applied` action; returns
/// their mean (0 without) and the smallest squared distance between two
/// robots' points (infinite with one robot). One pass over the pairs serves
/// all three.
#[inline(always)]
pub(super) fn write<T: Scalar>(
    config: &EnvConfig,
    seen: Seen<'_>,
    out: &mut [T],
    mut rewards: Option<&mut [T]>,
) -> (f64, f64) {
    let Seen { robots, leader, t } = seen;
    let d = obs_dim(config.neighbours);
    let jet = leader.eval(t, Order::Two);
    let k = config.neighbours.min(MAX_NEIGHBOURS);
    let sense2 = config.sense * config.sense;
    let radius2 = config.radius * config.radius;
    let (mut sum, mut closest) = (0.0, f64::INFINITY);
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
        let mut best = [(f64::INFINITY, 0usize); MAX_NEIGHBOURS];
        let near = nearest(robots, i, sense2, &mut best[..k]);
        closest = closest.min(near);
        let me = robot.point;
        let rest = &mut o[NEIGHBOURS..];
        rest.fill(T::of(0.0));
        for (m, &(dist, j)) in best[..k].iter().enumerate() {
            if dist.is_finite() {
                let p = robots[j].point;
                let (dx, dy) = (p[0] - me[0], p[1] - me[1]);
                rest[3 * m] = T::of(cos * dx + sin * dy);
                rest[3 * m + 1] = T::of(-sin * dx + cos * dy);
                rest[3 * m + 2] = T::of(1.0);
            }
        }
        if let Some(r) = rewards.as_mut() {
            let (w, a) = (config.weights, robot.applied);
            let effort = match config.robot {
                None => a[0] * a[0] + (config.l * a[1]).powi(2),
                Some(_) => a[0] * a[0] + a[1] * a[1],
            };
            let value = -w.tracking * (e[0] * e[0] + e[1] * e[1])
                - w.effort * effort
                - if near < radius2 { w.collision } else { 0.0 };
            r[i] = T::of(value);
            sum += value;
        }
    }
    (sum / robots.len() as f64, closest)
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

/// A group of environments' observations, rewards and facts after their
/// step (their robots moved, their clocks on: [`write`] for each),
/// compiled for the best instruction set this CPU has
/// ([`pulp::Arch::dispatch`]).
pub(super) struct Group<'a, T> {
    pub(super) config: &'a EnvConfig,
    pub(super) envs: &'a [super::env::Env],
    pub(super) robots: &'a [Robot],
    pub(super) obs: &'a mut [T],
    pub(super) rewards: &'a mut [T],
    pub(super) facts: &'a mut [super::EnvFacts],
}

impl<T: Scalar> pulp::WithSimd for Group<'_, T> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) {
        let Group {
            config,
            envs,
            robots,
            obs,
            rewards,
            facts,
        } = self;
        let n = config.num_agents;
        let d = obs_dim(config.neighbours);
        let outs = robots
            .chunks(n)
            .zip(obs.chunks_mut(n * d))
            .zip(rewards.chunks_mut(n));
        for (env, (((robots, o), r), f)) in envs.iter().zip(outs.zip(facts)) {
            let (reward, nearest) = write(config, env.seen(robots), o, Some(r));
            *f = super::EnvFacts {
                reward,
                truncated: env.steps >= config.max_steps,
                min_distance: nearest.sqrt(),
            };
        }
    }
}
