//! The kinematic law and the velocity base in lanes: the command, the
//! speed limiter, lags and acceleration limits, and the plant's derivative.

use crate::engine::kernel::{compensation, turned_state, vectors};
use crate::law::control::Hold;
use crate::law::kinematic::kinematic_of;
use crate::math::lanes::Lanes;
use crate::model::base::AccelLimit;

use super::{Cmd, Leads, Own, V4, VConsts};

/// `L_Y = L_Yoff + L_Ycomp` for leaders `l`.
#[inline(always)]
pub(super) fn ly_of<const N: usize>(c: &VConsts, own: &Own<N>, l: &Leads<N>) -> Lanes<N> {
    own.ly_off + compensation(c.comp, l.vd, l.wd, &own.comp)
}

/// `a` clamped to `[−m, m]`.
#[inline(always)]
fn clamp<const N: usize>(a: Lanes<N>, m: Lanes<N>) -> Lanes<N> {
    a.max(-m).min(m)
}

/// The kinematic law and the speed limiter ([`crate::model::base::VelocityBase::limit`]:
/// where `|v| > v_max` or `|ω| > ω_max`, `(v, ω)` scaled by
/// `1 / max(|v|/v_max, |ω|/ω_max)`, then clamped against the last bit of
/// rounding; the scaling computed only when some lane needs it).
#[inline(always)]
pub(super) fn command<const N: usize>(
    c: &VConsts,
    own: &Own<N>,
    x: &[Lanes<N>; 5],
    sc: (Lanes<N>, Lanes<N>),
    l: &Leads<N>,
    ly: Lanes<N>,
) -> Cmd<N> {
    let zero = Lanes::splat(0.0);
    let hold = Hold {
        lx: own.lx,
        inv_lx: own.inv_lx,
        ly,
        dly: zero,
        ddly: zero,
    };
    let (raw, e) = kinematic_of(x[0], x[1], sc, l.p, l.dp, &hold, own.ke);
    let (av, aw) = (raw[0].abs(), raw[1].abs());
    let (mv, mw) = (Lanes::splat(c.max[0]), Lanes::splat(c.max[1]));
    let over = av.gt(mv) | aw.gt(mw);
    let mut cmd = raw;
    if over.any() {
        let k = Lanes::splat(1.0) / (av * c.inv_max[0]).max(aw * c.inv_max[1]);
        cmd = [
            Lanes::select(over, clamp(raw[0] * k, mv), raw[0]),
            Lanes::select(over, clamp(raw[1] * k, mw), raw[1]),
        ];
    }
    Cmd {
        raw,
        cmd,
        e,
        saturated: over,
    }
}

/// The velocities the base moves at ([`crate::model::base::VelocityBase::speeds`]).
#[inline(always)]
pub(super) fn speeds<const N: usize>(
    c: &VConsts,
    x: &[Lanes<N>; 5],
    cmd: &[Lanes<N>; 2],
) -> [Lanes<N>; 2] {
    [
        if c.lag[0] { x[3] } else { cmd[0] },
        if c.lag[1] { x[4] } else { cmd[1] },
    ]
}

/// The state derivative ([`crate::model::base::VelocityBase::derivative`]): eq. 1
/// at the base's speeds, the lags' accelerations after their limits (where
/// `|v̇| > a_max` or `|ω̇| > α_max`; computed only when some lane needs it).
#[inline(always)]
pub(super) fn derivative(c: &VConsts, x: &[V4; 5], (sin, cos): (V4, V4), cmd: &[V4; 2]) -> [V4; 5] {
    let [v, w] = speeds(c, x, cmd);
    let zero = V4::splat(0.0);
    let mut dv = if c.lag[0] {
        (cmd[0] - x[3]) * c.inv_tau[0]
    } else {
        zero
    };
    let mut dw = if c.lag[1] {
        (cmd[1] - x[4]) * c.inv_tau[1]
    } else {
        zero
    };
    let (ma, mb) = (V4::splat(c.acc[0]), V4::splat(c.acc[1]));
    let (adv, adw) = (dv.abs(), dw.abs());
    let over = adv.gt(ma) | adw.gt(mb);
    if over.any() {
        let (lv, lw) = match c.accel {
            AccelLimit::Joint => {
                let s = (adv * c.inv_acc[0])
                    .max(adw * c.inv_acc[1])
                    .max(V4::splat(1.0));
                let k = V4::splat(1.0) / s;
                (clamp(dv * k, ma), clamp(dw * k, mb))
            }
            AccelLimit::PerAxis => (clamp(dv, ma), clamp(dw, mb)),
        };
        (dv, dw) = (V4::select(over, lv, dv), V4::select(over, lw, dw));
    }
    [v * cos, v * sin, w, dv, dw]
}

/// The state after a step ([`crate::model::base::VelocityBase::settle`]), given the
/// command at its end.
#[inline(always)]
pub(super) fn settle(c: &VConsts, x: &mut [V4; 5], cmd: &[V4; 2]) {
    let [v, w] = speeds(c, x, cmd);
    x[3] = clamp(v, V4::splat(c.max[0]));
    x[4] = clamp(w, V4::splat(c.max[1]));
}

/// One RK4 step of the base over `c.dt` under `cmd` held (zero-order hold;
/// [`crate::model::base::VelocityBase::rk4_step`] in lanes, `cmd` already
/// limited), from `x` whose heading's sines and cosines are `sc`: stages 2–4
/// turned from `sc` ([`turned_state`]), then [`settle`]d.
#[inline(always)]
pub(crate) fn held_step(c: &VConsts, x: &mut [V4; 5], sc: (V4, V4), cmd: &[V4; 2]) {
    let (dt, h) = (c.dt, 0.5 * c.dt);
    let k1 = derivative(c, x, sc, cmd);
    let (x2, sc2) = turned_state(x, sc, &k1, h);
    let k2 = derivative(c, &x2, sc2, cmd);
    let (x3, sc3) = turned_state(x, sc, &k2, h);
    let k3 = derivative(c, &x3, sc3, cmd);
    let (x4, sc4) = turned_state(x, sc, &k3, dt);
    let k4 = derivative(c, &x4, sc4, cmd);
    let h6 = dt / 6.0;
    let rk = |i: usize| x[i] + (k1[i] + (k2[i] + k3[i]) * 2.0 + k4[i]) * h6;
    *x = [rk(0), rk(1), rk(2), rk(3), rk(4)];
    vectors(x);
    settle(c, x, cmd);
}
