//! Observations ([`super::layout`]), rewards and the baseline policy.

use super::layout::{
    E, LEADER_ACCELERATION, LEADER_VELOCITY, NEIGHBOURS, OFFSETS, SPEEDS, obs_dim,
};
use super::{EnvConfig, Scalar, Slots};
use crate::law::control::{Gains, LeaderMotion, Offset, Variant, law};
use crate::model::RobotParams;
use crate::model::State;
use crate::safety::point;

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
    pub(super) states: &'a [State],
    /// The robots' points `l` ahead ([`points`]).
    pub(super) points: &'a [[f64; 2]],
    pub(super) slots: &'a Slots,
    pub(super) t: f64,
}

/// Writes one environment's observations (`N · obs_dim`) and, with
/// `rewards = Some((applied, out))`, each robot's reward
/// ([`super::Weights`]) for the step that ended under `applied`; returns
/// their mean (0 without). One pass over the pairs serves both.
pub(super) fn write<T: Scalar>(
    config: &EnvConfig,
    seen: Seen<'_>,
    out: &mut [T],
    mut rewards: Option<(&[[f64; 2]], &mut [T])>,
) -> f64 {
    let Seen {
        states,
        points,
        slots,
        t,
    } = seen;
    let d = obs_dim(config.neighbours);
    let jet = slots.leader_at(t);
    let k = config.neighbours.min(MAX_NEIGHBOURS);
    let sense2 = config.sense * config.sense;
    let radius2 = config.radius * config.radius;
    let mut sum = 0.0;
    for (i, (s, o)) in states.iter().zip(out.chunks_exact_mut(d)).enumerate() {
        let (sin, cos) = s.theta.sin_cos();
        let (lx, ly) = (slots.lx[i], slots.ly[i]);
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
        // The k nearest points within `sense`, by insertion into a fixed
        // array, on squared distances (the same order, no square root).
        let me = points[i];
        let mut best = [(f64::INFINITY, 0usize); MAX_NEIGHBOURS];
        let mut nearest = f64::INFINITY;
        for (j, p) in points.iter().enumerate() {
            if j == i {
                continue;
            }
            let (dx, dy) = (p[0] - me[0], p[1] - me[1]);
            let dist = dx * dx + dy * dy;
            nearest = nearest.min(dist);
            if dist > sense2 || k == 0 || dist >= best[k - 1].0 {
                continue;
            }
            let mut at = k - 1;
            while at > 0 && best[at - 1].0 > dist {
                best[at] = best[at - 1];
                at -= 1;
            }
            best[at] = (dist, j);
        }
        let rest = &mut o[NEIGHBOURS..];
        rest.fill(T::of(0.0));
        for (m, &(dist, j)) in best[..k].iter().enumerate() {
            if dist.is_finite() {
                let p = points[j];
                let (dx, dy) = (p[0] - me[0], p[1] - me[1]);
                rest[3 * m] = T::of(cos * dx + sin * dy);
                rest[3 * m + 1] = T::of(-sin * dx + cos * dy);
                rest[3 * m + 2] = T::of(1.0);
            }
        }
        if let Some((applied, r)) = rewards.as_mut() {
            let (w, a) = (config.weights, applied[i]);
            let effort = match config.robot {
                None => a[0] * a[0] + (config.l * a[1]).powi(2),
                Some(_) => a[0] * a[0] + a[1] * a[1],
            };
            let value = -w.tracking * (e[0] * e[0] + e[1] * e[1])
                - w.effort * effort
                - if nearest < radius2 { w.collision } else { 0.0 };
            r[i] = T::of(value);
            sum += value;
        }
    }
    sum / states.len() as f64
}

/// The robots' points `l` ahead ([`point`]) into `out`.
pub(super) fn points(states: &[State], l: f64, out: &mut [[f64; 2]]) {
    for (s, p) in states.iter().zip(out) {
        *p = point(s, l);
    }
}

/// The smallest distance between two of `points`, m.
pub(super) fn closest(points: &[[f64; 2]]) -> f64 {
    let mut best = f64::INFINITY;
    for (i, p) in points.iter().enumerate() {
        for q in &points[i + 1..] {
            best = best.min((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2));
        }
    }
    best.sqrt()
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
