//! The robots' motion over one step, a group of environments at a time:
//! velocity bases in blocks of [`VW`] lanes across the group's environments
//! (the batch engine's base model, [`held_step`]: one RK4 step under the
//! held command, lags and limits), torque robots one by one (eq. 3,
//! [`RobotParams::rk4_step`](crate::model::RobotParams::rk4_step)); then
//! every robot's heading's sine and cosine, in lanes ([`sense`]), which the
//! next step's first stage and the observations read, and its point `l`
//! ahead ([`place`]), which the neighbour search reads.

use pulp::{Arch, Simd, WithSimd};

use super::EnvConfig;
use super::env::Robot;
use crate::engine::{V4, VConsts, VW, held_step};
use crate::math::lanes::Lanes;
use crate::model::base::VelocityCommand;
use crate::model::{State, Torques};

/// The lanes of `get` over a chunk of up to [`VW`] robots, padding lanes
/// repeating the first robot's value (harmless numbers for the padded
/// lanes' arithmetic).
#[inline(always)]
fn gather(chunk: &[Robot], get: impl Fn(&Robot) -> f64) -> V4 {
    let mut out = [get(&chunk[0]); VW];
    for (o, r) in out.iter_mut().zip(chunk) {
        *o = get(r);
    }
    Lanes(out)
}

/// A chunk's headings' `(sin θ, cos θ)` ([`Lanes::sin_cos`]), from their
/// states.
#[inline(always)]
fn sense_chunk(chunk: &mut [Robot]) {
    let (sin, cos) = gather(chunk, |r| r.state.theta).sin_cos();
    for (k, r) in chunk.iter_mut().enumerate() {
        r.heading = [sin.0[k], cos.0[k]];
    }
}

/// Velocity bases: every robot of `robots` one step under its applied
/// command (limited by the base, as [`crate::model::base::VelocityBase::rk4_step`]
/// is given it), then sensed.
struct VelocityStep<'a> {
    c: &'a VConsts,
    config: &'a EnvConfig,
    robots: &'a mut [Robot],
}

impl WithSimd for VelocityStep<'_> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: Simd>(self, _: S) {
        let base = &self.config.base;
        for chunk in self.robots.chunks_mut(VW) {
            let mut cmd = [[0.0; VW]; 2];
            for (l, r) in chunk.iter().enumerate() {
                let (c, _) = base.limit(VelocityCommand {
                    v: r.applied[0],
                    omega: r.applied[1],
                });
                (cmd[0][l], cmd[1][l]) = (c.v, c.omega);
            }
            for l in chunk.len()..VW {
                (cmd[0][l], cmd[1][l]) = (cmd[0][0], cmd[1][0]);
            }
            let cmd = cmd.map(Lanes);
            let sc = (
                gather(chunk, |r| r.heading[0]),
                gather(chunk, |r| r.heading[1]),
            );
            let mut x = [
                gather(chunk, |r| r.state.x),
                gather(chunk, |r| r.state.y),
                gather(chunk, |r| r.state.theta),
                gather(chunk, |r| r.state.v),
                gather(chunk, |r| r.state.omega),
            ];
            held_step(self.c, &mut x, sc, &cmd);
            for (l, r) in chunk.iter_mut().enumerate() {
                r.state = State {
                    x: x[0].0[l],
                    y: x[1].0[l],
                    theta: x[2].0[l],
                    v: x[3].0[l],
                    omega: x[4].0[l],
                };
            }
            sense_chunk(chunk);
        }
    }
}

/// Every robot of `robots` one step under its applied command (`(v, ω)`
/// on velocity bases, `(τ_r, τ_l)` on torque robots), then [`sense`]d.
pub(super) fn advance(config: &EnvConfig, c: &VConsts, arch: Arch, robots: &mut [Robot]) {
    match &config.robot {
        None => arch.dispatch(VelocityStep { c, config, robots }),
        Some(robot) => {
            for r in robots.iter_mut() {
                let u = robot.inputs(Torques {
                    right: r.applied[0],
                    left: r.applied[1],
                });
                r.state = robot.rk4_step(&r.state, robot.actuate(u).0, config.dt);
            }
            sense(robots);
        }
    }
}

/// Every robot's `(sin θ, cos θ)` ([`Lanes::sin_cos`]), from its state.
pub(super) fn sense(robots: &mut [Robot]) {
    for chunk in robots.chunks_mut(VW) {
        sense_chunk(chunk);
    }
}

/// One environment's robots' points `l` ahead (as [`crate::safety::point`]
/// puts them, from their states and [`sense`]d headings) into `points`:
/// every `x`, then every `y`, so that the neighbour search reads each in
/// vectors.
#[inline(always)]
pub(super) fn place(robots: &[Robot], l: f64, points: &mut [f64]) {
    let (xs, ys) = points.split_at_mut(robots.len());
    for ((r, x), y) in robots.iter().zip(xs).zip(ys) {
        let [sin, cos] = r.heading;
        *x = r.state.x + l * cos;
        *y = r.state.y + l * sin;
    }
}
