//! The kinematic leader-follower law: the first backstepping step of the
//! paper (eqs. 7–10) used as the command of a velocity-controlled base
//! ([`crate::model::base`]), as derived in `docs/control-law.md`, "Kinematic law".
//!
//! With the same `e` (eq. 7), `ξ = [v − ω L_Y, ω L_X]ᵀ` and the virtual control
//! of eq. 10 as the command:
//!
//! ```text
//! ξ* = R ṗ_d − [0, L̇_Y]ᵀ − K_e e
//! ω* = ξ*₂ / L_X          v* = ξ*₁ + ω* L_Y
//! ```
//!
//! so that `ξ(v*, ω*) = ξ*`. With an ideal base (`v = v*`, `ω = ω*`),
//! eq. 8 gives `ė = −S e − K_e e` and `V̇₁ = −K_e‖e‖²` exactly (`S` is skew), i.e.
//! `‖e(t)‖ = ‖e(0)‖ e^{−K_e t}`. With any other base, `z = ξ(v, ω) − ξ*` (eq. 10
//! with the base's actual velocities) measures how far the base is from the
//! command and `V̇₁ = −K_e‖e‖² + eᵀz` ([`lyapunov_rate`]).
//!
//! `L_X`, `L_Y`, `L̇_Y` come from [`crate::law::lycomp::Placement`] exactly as for the
//! dynamic law (`L_Ycomp`, chained leaders, pure tracking with `L_X = L`,
//! `L_Y = 0`); `p̈_d` and `L̈_Y` are not needed.

use crate::law::control::{Body, Hold, LeaderMotion, Offset, errors_at};
use crate::math::lanes::Real;
use crate::model::State;
use crate::model::base::VelocityCommand;

/// The kinematic law's output at one instant.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct KinematicOutput {
    /// The commanded velocities `(v*, ω*)` (before the base's limits).
    pub cmd: VelocityCommand,
    /// Tracking error `e` (eq. 7), follower body frame, m.
    pub e: [f64; 2],
    /// `z = ξ(v, ω) − ξ*` (eq. 10) at the state's velocities, m/s: zero when
    /// the base moves at the command (an ideal base, after
    /// [`crate::model::base::VelocityBase::settle`]).
    pub z: [f64; 2],
}

/// `(v*, ω*)` and `e` in any number type (`f64`, SIMD lanes): the state's
/// velocities do not enter the command.
///
/// Evaluated through eq. 10 at `v = ω = 0`, where `ξ = 0` and so `z = −ξ*`:
/// one rotation, the same rounding as writing `ξ*` out.
#[inline(always)]
pub(crate) fn kinematic_of<V: Real>(
    x: V,
    y: V,
    (sin, cos): (V, V),
    pd: [V; 2],
    dpd: [V; 2],
    hold: &Hold<V>,
    ke: V,
) -> ([V; 2], [V; 2]) {
    let zero = V::from(0.0);
    let body = Body {
        x,
        y,
        sin,
        cos,
        v: zero,
        omega: zero,
    };
    let (e, minus_xi) = errors_at(&body, pd, dpd, hold, ke);
    // ω* = ξ*₂ / L_X,  v* = ξ*₁ + ω* L_Y
    let omega = -minus_xi[1] * hold.inv_lx;
    let v = -minus_xi[0] + omega * hold.ly;
    ([v, omega], e)
}

/// The kinematic leader-follower law for a follower in state `me` (pure
/// tracking when `off = [L, 0, 0, ·]`). `leader.ddp` and `off.ddly` are not
/// used.
///
/// For a robot leader, build `leader` from the velocities the leader's base
/// actually moves at ([`crate::model::base::VelocityBase::speeds`]), not a stale
/// state: `LeaderMotion::of_robot(&State { v, omega, ..s }, dv)`.
#[inline]
pub fn kinematic_law(me: &State, leader: &LeaderMotion, off: &Offset, ke: f64) -> KinematicOutput {
    let hold = Hold::of(off);
    let ([v, omega], e) = kinematic_of(
        me.x,
        me.y,
        me.theta.sin_cos(),
        leader.p,
        leader.dp,
        &hold,
        ke,
    );
    // ξ* = ξ(v*, ω*); z = ξ(v, ω) − ξ*.
    let z = [
        (me.v - v) - (me.omega - omega) * off.ly,
        (me.omega - omega) * off.lx,
    ];
    KinematicOutput {
        cmd: VelocityCommand { v, omega },
        e,
        z,
    }
}

/// `V₁ = ½‖e‖²`, the first-step Lyapunov function.
#[inline]
pub fn lyapunov(e: [f64; 2]) -> f64 {
    0.5 * (e[0] * e[0] + e[1] * e[1])
}

/// What `V̇₁` must equal under the kinematic law when the base moves at
/// velocities whose `ξ` differs from the command's by `z`:
/// `−K_e‖e‖² + eᵀz` (`−K_e‖e‖²` for an ideal base, `z = 0`).
#[inline]
pub fn lyapunov_rate(e: [f64; 2], z: [f64; 2], ke: f64) -> f64 {
    -ke * (e[0] * e[0] + e[1] * e[1]) + e[0] * z[0] + e[1] * z[1]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_command_makes_xi_equal_the_virtual_control() {
        // ξ(v*, ω*) = R ṗ_d − [0, L̇_Y] − K_e e, written out by hand.
        let me = State {
            x: 0.3,
            y: -0.4,
            theta: 0.7,
            v: 0.2,
            omega: -0.1,
        };
        let leader = LeaderMotion {
            p: [1.0, 0.5],
            dp: [0.4, 0.3],
            ddp: [9.0, 9.0],
        };
        let off = Offset {
            lx: 0.55,
            ly: -0.3,
            dly: 0.02,
            ddly: 7.0,
        };
        let ke = 1.5;
        let out = kinematic_law(&me, &leader, &off, ke);
        let (s, c) = me.theta.sin_cos();
        let rot = |a: [f64; 2]| [c * a[0] + s * a[1], -s * a[0] + c * a[1]];
        let d = rot([me.x - leader.p[0], me.y - leader.p[1]]);
        let e = [d[0] + off.lx, d[1] + off.ly];
        let r = rot(leader.dp);
        let xi_star = [r[0] - ke * e[0], r[1] - off.dly - ke * e[1]];
        let xi = [out.cmd.v - out.cmd.omega * off.ly, out.cmd.omega * off.lx];
        for i in 0..2 {
            assert!((out.e[i] - e[i]).abs() < 1e-15);
            assert!((xi[i] - xi_star[i]).abs() < 1e-15, "{xi:?} vs {xi_star:?}");
        }
        // z at the state's velocities is ξ(v, ω) − ξ*.
        let xi_me = [me.v - me.omega * off.ly, me.omega * off.lx];
        for i in 0..2 {
            assert!((out.z[i] - (xi_me[i] - xi_star[i])).abs() < 1e-15);
        }
        // At the command's velocities, z = 0.
        let at_cmd = State {
            v: out.cmd.v,
            omega: out.cmd.omega,
            ..me
        };
        let z = kinematic_law(&at_cmd, &leader, &off, ke).z;
        assert!(z[0].abs() < 1e-15 && z[1].abs() < 1e-15);
    }

    #[test]
    fn pure_tracking_steers_the_point_l_ahead() {
        // L_X = L, L_Y = 0: the point p + L [cos θ, sin θ] moves at ṗ_d − K_e e
        // in the world frame, and e is that point's offset from p_d.
        let me = State::at_rest(-1.0, 0.5, -0.4);
        let leader = LeaderMotion {
            p: [0.2, 0.1],
            dp: [0.5, -0.2],
            ddp: [0.0, 0.0],
        };
        let l = 0.05;
        let off = Offset {
            lx: l,
            ..Offset::default()
        };
        let out = kinematic_law(&me, &leader, &off, 2.0);
        let (s, c) = me.theta.sin_cos();
        let point = [me.x + l * c, me.y + l * s];
        // the point's world velocity for (v, ω)
        let vel = [
            out.cmd.v * c - l * out.cmd.omega * s,
            out.cmd.v * s + l * out.cmd.omega * c,
        ];
        for i in 0..2 {
            let want = leader.dp[i] - 2.0 * (point[i] - leader.p[i]);
            assert!((vel[i] - want).abs() < 1e-13, "{vel:?}");
        }
    }
}
