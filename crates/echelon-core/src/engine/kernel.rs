//! The stepping kernels: blocks of [`W`] agents, RK4 with the law in every
//! stage, as [`crate::sim::Simulation`] does it, in lanes.
//!
//! Every formula comes from the scalar code: eqs. 7–13 from
//! [`crate::law::control::law_partial`]/[`crate::law::control::law_finish`] (the same
//! generic functions `control::law` calls), a robot leader's motion from
//! [`crate::law::control::robot_leader`], eq. 5 and eq. 6 as in [`crate::law::lycomp`]
//! (eq. 6 as one angle instead of three, see [`fit`]), eq. 3 as in
//! [`crate::model`] with `1/m` and `1/J` precomputed.

use std::ops::{Add, Mul, Neg, Sub};

use crate::law::control::{Hold, LawRobot, Variant};
use crate::law::lycomp::LyComp;
use crate::math::lanes::{Lanes, Mask};
use crate::reference::Jet;

mod chain;
mod probe;
mod star;
use chain::Leaders;
pub(crate) use chain::Scratch;
pub(crate) use chain::{chain_stage, chain_tile, shift_from, shift_in};
pub use probe::Probe;
pub(crate) use probe::{chain_probe, star_probe, state_of};
pub(crate) use star::{star_stage, star_tile};

/// Agents per block (lanes per vector).
pub(crate) const W: usize = 8;
/// `W` agents' values of one quantity.
pub(crate) type V = Lanes<W>;

/// `W` agents: their states and their own constants, each quantity a vector
/// (structure of arrays, `W` at a time).
#[derive(Debug, Clone, Copy)]
pub struct Block {
    /// `x, y, θ, v, ω`.
    pub(crate) x: [V; 5],
    /// `L_X = L_Xoff + L`.
    pub(crate) lx: V,
    /// `1/L_X`.
    pub(crate) inv_lx: V,
    /// `L_Yoff`.
    pub(crate) ly_off: V,
    /// `K_e`.
    pub(crate) ke: V,
    /// `K_z`.
    pub(crate) kz: V,
    /// `L_Ycomp` constants: `[2G, 1/δ, (ε/δ)²]` (eq. 6) or `[λ, λ², 0]` (eq. 5).
    pub(crate) comp: [V; 3],
    /// Lanes that hold an agent (the last block may be padded).
    pub(crate) live: Mask<W>,
}

/// A torque limit and what it takes to apply it (eq. 2).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Limit {
    pub(crate) tau: f64,
    pub(crate) r: f64,
    pub(crate) l: f64,
}

/// What every agent of the batch shares.
#[derive(Debug, Clone, Copy)]
pub struct Consts {
    pub(crate) law: LawRobot,
    /// `η`, `ψ`, `1/m`, `1/J`.
    pub(crate) eta: f64,
    pub(crate) psi: f64,
    pub(crate) inv_m: f64,
    pub(crate) inv_j: f64,
    pub(crate) variant: Variant,
    pub(crate) comp: LyComp,
    pub(crate) limit: Option<Limit>,
    pub(crate) dt: f64,
}

/// A leader as its followers see it at one stage: `p_d`, `ṗ_d`, and
/// `p̈_d = q + v̇ g` (a robot: `g = [cos θ, sin θ]`; the reference: `g = 0`),
/// the `(V_d, ω_d)` that `L_Ycomp` reads, and `v̇` once known.
#[derive(Debug, Clone, Copy, Default)]
pub struct Carry {
    pub(crate) p: [f64; 2],
    pub(crate) dp: [f64; 2],
    pub(crate) q: [f64; 2],
    pub(crate) g: [f64; 2],
    pub(crate) vd: f64,
    pub(crate) wd: f64,
    pub(crate) dv: f64,
}

impl Carry {
    /// The virtual leader: the reference at one instant, as
    /// `Placement::offset_for_reference` reads it.
    pub(crate) fn reference(jet: &Jet) -> Carry {
        Carry {
            p: jet.p,
            dp: jet.dp,
            q: jet.ddp,
            g: [0.0; 2],
            vd: jet.speed(),
            wd: jet.turn_rate(),
            dv: 0.0,
        }
    }
}

/// A number `a + b v̇_L`, affine in a leader's (yet unknown) acceleration.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Aff {
    pub(crate) a: V,
    pub(crate) b: V,
}

impl Add for Aff {
    type Output = Aff;
    #[inline(always)]
    fn add(self, o: Aff) -> Aff {
        Aff {
            a: self.a + o.a,
            b: self.b + o.b,
        }
    }
}

/// `Aff ⊕ o` for a value `o` without a `v̇_L` term: `shift` moves `a` alone,
/// `scale` both parts.
macro_rules! aff_op {
    (shift $tr:ident, $f:ident, $o:ty, $op:tt) => {
        impl $tr<$o> for Aff {
            type Output = Aff;
            #[inline(always)]
            fn $f(self, o: $o) -> Aff {
                Aff { a: self.a $op o, b: self.b }
            }
        }
    };
    (scale $tr:ident, $f:ident, $o:ty, $op:tt) => {
        impl $tr<$o> for Aff {
            type Output = Aff;
            #[inline(always)]
            fn $f(self, o: $o) -> Aff {
                Aff { a: self.a $op o, b: self.b $op o }
            }
        }
    };
}
aff_op!(shift Add, add, V, +);
aff_op!(shift Sub, sub, V, -);
aff_op!(scale Mul, mul, V, *);
aff_op!(scale Mul, mul, f64, *);

impl Neg for Aff {
    type Output = Aff;
    #[inline(always)]
    fn neg(self) -> Aff {
        Aff {
            a: -self.a,
            b: -self.b,
        }
    }
}

/// Eq. 6 per lane with `R_C = V_d/ω_d` (0 where `ω_d = 0`, like
/// [`crate::law::lycomp::fit`]), `c = [2G, 1/δ, (ε/δ)²]`.
///
/// With `a = R_C/δ`, `k = ε/δ`, eq. 6's `2 atan a − atan(a − k) − atan(a + k)`
/// is the argument of `(1 + ia)² / ((1 + i(a − k))(1 + i(a + k)))`, i.e.
/// `atan2(2ak², (1 + a²)² + k²(1 − a²))`: the two differences `atan a −
/// atan(a ∓ k)` have opposite signs and lie in `(−π, π)`, so the sum does too
/// and the principal angle is exact. One `atan2` instead of three `atan`s,
/// and no cancellation between angles near `±π/2`. (`|a|` is capped at 10⁵⁰,
/// where the value is below 10⁻¹⁰⁰, to keep `(1 + a²)²` finite.)
#[inline(always)]
pub(crate) fn fit<const N: usize>(vd: Lanes<N>, wd: Lanes<N>, c: &[Lanes<N>; 3]) -> Lanes<N> {
    let zero = Lanes::splat(0.0);
    let straight = wd.eq_lanes(zero);
    let rc = vd / wd;
    let a = (rc * c[1]).max(Lanes::splat(-1e50)).min(Lanes::splat(1e50));
    let a2 = a * a;
    let s = a2 + 1.0;
    let k2 = c[2];
    let angle = Lanes::atan2(a * k2 * 2.0, s * s + k2 * (-a2 + 1.0));
    Lanes::select(straight, zero, angle * c[0])
}

/// Eq. 5 per lane, exactly [`crate::law::lycomp::exact`] in `f64`:
/// `κλ²/(1 + √(1 − κ²λ²))` with `κ = ω_d/V_d`, `R_C` where `|κ|λ ≥ 1`, 0 where
/// `ω_d = 0`; `c = [λ, λ², 0]`.
#[inline(always)]
pub(crate) fn exact<const N: usize>(vd: Lanes<N>, wd: Lanes<N>, c: &[Lanes<N>; 3]) -> Lanes<N> {
    let zero = Lanes::splat(0.0);
    let (lambda, lambda2) = (c[0], c[1]);
    let straight = wd.eq_lanes(zero);
    let tight = !(wd.abs() * lambda).lt(vd);
    let k = wd / vd;
    let kl = k * lambda;
    let smooth = k * lambda2 / ((Lanes::splat(1.0) - kl * kl).sqrt() + 1.0);
    Lanes::select(straight, zero, Lanes::select(tight, vd / wd, smooth))
}

/// `L_Ycomp` for leaders moving at `(V_d, ω_d)`, in any number of lanes.
#[inline(always)]
pub(crate) fn compensation<const N: usize>(
    mode: LyComp,
    vd: Lanes<N>,
    wd: Lanes<N>,
    c: &[Lanes<N>; 3],
) -> Lanes<N> {
    match mode {
        LyComp::Fit => fit(vd, wd, c),
        LyComp::Exact => exact(vd, wd, c),
        LyComp::None => Lanes::splat(0.0),
    }
}

/// `Placement::offset` in lanes: `L_X`, `1/L_X`, `L_Y = L_Yoff + L_Ycomp`,
/// `L̇_Y = L̈_Y = 0` (derivatives neglected).
#[inline(always)]
fn hold(c: &Consts, b: &Block, vd: V, wd: V) -> Hold<V> {
    hold_ly(b, b.ly_off + compensation(c.comp, vd, wd, &b.comp))
}

/// [`hold`] with `L_Y` already known.
#[inline(always)]
fn hold_ly(b: &Block, ly: V) -> Hold<V> {
    let zero = V::splat(0.0);
    Hold {
        lx: b.lx,
        inv_lx: b.inv_lx,
        ly,
        dly: zero,
        ddly: zero,
    }
}

/// `L_Y` of a star block's agents when the reference is `r`.
#[inline(always)]
fn star_ly(c: &Consts, b: &Block, r: &Carry) -> V {
    b.ly_off + compensation(c.comp, V::splat(r.vd), V::splat(r.wd), &b.comp)
}

/// The motors: what the plant receives for the commanded `u`
/// ([`crate::model::RobotParams::actuate`] in lanes).
#[inline(always)]
fn actuate(limit: Option<Limit>, u: [V; 2]) -> [V; 2] {
    let Some(Limit { tau, r, l }) = limit else {
        return u;
    };
    let turn = u[1] / l;
    let right = (u[0] + turn) * (0.5 * r);
    let left = (u[0] - turn) * (0.5 * r);
    let (lo, hi) = (V::splat(-tau), V::splat(tau));
    let (sr, sl) = (right.max(lo).min(hi), left.max(lo).min(hi));
    let changed = !(sr.eq_lanes(right) & sl.eq_lanes(left));
    let clamped = [(sr + sl) / r, (sr - sl) * l / r];
    [
        V::select(changed, clamped[0], u[0]),
        V::select(changed, clamped[1], u[1]),
    ]
}

/// `state + k d` (the RK4 stage update, `State::add_scaled`).
#[inline(always)]
pub(crate) fn add_scaled<const N: usize>(
    x: &[Lanes<N>; 5],
    d: &[Lanes<N>; 5],
    k: f64,
) -> [Lanes<N>; 5] {
    each(|i| x[i] + d[i] * k)
}

/// `[f(0), …, f(4)]`, written out (`std::array::from_fn` calls its closure
/// out of line in the dispatched kernels: a call per quantity, lanes spilled
/// around it).
#[inline(always)]
pub(crate) fn each<const N: usize>(f: impl Fn(usize) -> Lanes<N>) -> [Lanes<N>; 5] {
    [f(0), f(1), f(2), f(3), f(4)]
}

/// Puts a state in memory, whole vectors at a time. Without it the
/// vectoriser, seeing a whole RK4 step as one block of scalar operations,
/// splits parts of it into half vectors and shuffles (measured on both
/// kernels: BENCHMARKS.md).
#[inline(always)]
pub(crate) fn vectors<const N: usize>(x: &mut [Lanes<N>; 5]) {
    std::hint::black_box(x);
}

/// [`Lanes::sin_cos`] out of line: the rare fallback of an angle-sum turn
/// (some lane turned by 0.05 rad or more), kept out of the hot loop so that
/// the compiler keeps the kernel in vectors.
#[cold]
#[inline(never)]
pub(crate) fn sin_cos_cold<const N: usize>(theta: Lanes<N>) -> (Lanes<N>, Lanes<N>) {
    theta.sin_cos()
}

/// `x + d k` and the sines and cosines of its heading, turned from those of
/// `x` by `d[2] k` ([`Lanes::sin_cos_turned`]), or, when some lane turns by
/// 0.05 rad or more, from [`Lanes::sin_cos`] out of line ([`sin_cos_cold`]:
/// rare, and the kernel stays small enough for the compiler to keep it in
/// vectors). The new state goes through memory as whole vectors
/// ([`vectors`]). An RK4 stage's state in both engines' kernels.
#[inline(always)]
#[allow(clippy::type_complexity)]
pub(crate) fn turned_state<const N: usize>(
    x: &[Lanes<N>; 5],
    (sin, cos): (Lanes<N>, Lanes<N>),
    d: &[Lanes<N>; 5],
    k: f64,
) -> ([Lanes<N>; 5], (Lanes<N>, Lanes<N>)) {
    let mut next = add_scaled(x, d, k);
    vectors(&mut next);
    let turned = match (d[2] * k).sin_cos_turned(sin, cos) {
        Some(sc) => sc,
        None => sin_cos_cold(next[2]),
    };
    (next, turned)
}

/// `x + h/6 (k₁ + 2 (k₂ + k₃) + k₄)`, with `k23 = k₂ + k₃`.
#[inline(always)]
pub(crate) fn combine<const N: usize>(
    x: &[Lanes<N>; 5],
    k1: &[Lanes<N>; 5],
    k23: &[Lanes<N>; 5],
    k4: &[Lanes<N>; 5],
    h6: f64,
) -> [Lanes<N>; 5] {
    each(|i| x[i] + (k1[i] + k23[i] * 2.0 + k4[i]) * h6)
}

/// Lanes whose state is no longer finite or has left the divergence guard's
/// default bounds ([`crate::sim::guard::Bounds::DEFAULT`]: `|v|`, `|ω|`,
/// `‖(x, y)‖`); a NaN fails every comparison, so it is caught too.
#[inline(always)]
pub(crate) fn broken<const N: usize>(x: &[Lanes<N>; 5], live: Mask<N>) -> Mask<N> {
    let b = crate::sim::guard::Bounds::DEFAULT;
    let r2 = x[0] * x[0] + x[1] * x[1];
    let ok = r2.compare(Lanes::splat(b.distance * b.distance), |a, c| a <= c)
        & x[2].finite()
        & x[3].abs().compare(Lanes::splat(b.speed), |a, c| a <= c)
        & x[4].abs().compare(Lanes::splat(b.turn_rate), |a, c| a <= c);
    !ok & live
}

#[inline(always)]
pub(crate) fn first_lane<const N: usize>(m: Mask<N>) -> usize {
    m.0.iter().position(|&b| b != 0).unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::law::control::{Body, law_finish, law_partial};
    use crate::law::lycomp::{self, FitCoefficients};
    use proptest::prelude::*;

    fn lanes(v: &[f64]) -> V {
        V::from_slice(v)
    }

    fn w_of<T: std::fmt::Debug>(s: impl Strategy<Value = T>) -> impl Strategy<Value = Vec<T>> {
        prop::collection::vec(s, W)
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2000))]

        /// Eq. 6 as one angle equals eq. 6 as three: within 1e-12 of the
        /// scale `2|G|` (the three-angle form itself cancels angles near ±π/2),
        /// for every `L_Xoff` of the paper's range, any speed and turn rate.
        #[test]
        fn fit_as_one_angle_is_eq_6(
            lambda in 0.1..0.9f64,
            speed in w_of(0.0..5.0f64),
            turn in w_of(-3.0..3.0f64),
            tiny in any::<bool>(),
        ) {
            let turn: Vec<f64> = turn.iter().map(|w| if tiny { w * 1e-9 } else { *w }).collect();
            let f = FitCoefficients::paper(lambda);
            let k = f.epsilon / f.delta;
            let c = [V::splat(2.0 * f.g), V::splat(1.0 / f.delta), V::splat(k * k)];
            let got = fit(lanes(&speed), lanes(&turn), &c);
            for l in 0..W {
                let want: f64 = lycomp::fit(speed[l], turn[l], &f);
                prop_assert!(
                    (got.0[l] - want).abs() <= 1e-12 * (2.0 * f.g.abs()).max(1.0),
                    "λ = {lambda}, V = {}, ω = {}: {} vs {want}", speed[l], turn[l], got.0[l]
                );
            }
        }

        /// Eq. 5 in lanes is `lycomp::exact` bit for bit, in both branches and
        /// for straight lines.
        #[test]
        fn exact_in_lanes_is_eq_5_bit_for_bit(
            lambda in 0.05..2.0f64,
            speed in w_of(0.0..5.0f64),
            turn in w_of(-20.0..20.0f64),
            straight in 0..W,
        ) {
            let mut turn = turn;
            turn[straight] = 0.0;
            let c = [V::splat(lambda), V::splat(lambda * lambda), V::splat(0.0)];
            let got = exact(lanes(&speed), lanes(&turn), &c);
            for l in 0..W {
                let want: f64 = lycomp::exact(speed[l], turn[l], lambda);
                prop_assert_eq!(got.0[l].to_bits(), want.to_bits(), "V = {}, ω = {}", speed[l], turn[l]);
            }
        }
    }

    proptest! {
        /// Eqs. 7–13 in lanes are `control::law` bit for bit in every lane
        /// (given the same sines: the law is generic over the number type and
        /// lanes have no fused multiply-add).
        #[test]
        fn the_law_in_lanes_is_the_scalar_law(
            st in w_of(prop::array::uniform5(-3.0..3.0f64)),
            leader in w_of(prop::array::uniform6(-2.0..2.0f64)),
            hold in w_of((0.06..1.0f64, -1.0..1.0f64)),
            gains in w_of((0.1..5.0f64, 0.1..20.0f64)),
            complete in any::<bool>(),
        ) {
            use crate::law::control::{Gains, LeaderMotion, Offset, law};
            let variant = if complete { Variant::Complete } else { Variant::Paper };
            let robot = crate::model::RobotParams::AGENT2;
            let lr = LawRobot::new(&robot);
            let col = |f: &dyn Fn(usize) -> f64| Lanes(std::array::from_fn(f));
            let body = Body {
                x: col(&|i| st[i][0]),
                y: col(&|i| st[i][1]),
                sin: col(&|i| st[i][2].sin()),
                cos: col(&|i| st[i][2].cos()),
                v: col(&|i| st[i][3]),
                omega: col(&|i| st[i][4]),
            };
            let zero = V::splat(0.0);
            let h = Hold {
                lx: col(&|i| hold[i].0),
                inv_lx: col(&|i| 1.0 / hold[i].0),
                ly: col(&|i| hold[i].1),
                dly: zero,
                ddly: zero,
            };
            let pd = [col(&|i| leader[i][0]), col(&|i| leader[i][1])];
            let dpd = [col(&|i| leader[i][2]), col(&|i| leader[i][3])];
            let ddpd = [col(&|i| leader[i][4]), col(&|i| leader[i][5])];
            let p = law_partial(&lr, &body, pd, dpd, &h, col(&|i| gains[i].0));
            let u = law_finish(&lr, &p, ddpd, col(&|i| gains[i].1), variant);
            for i in 0..W {
                let s = crate::model::State {
                    x: st[i][0], y: st[i][1], theta: st[i][2], v: st[i][3], omega: st[i][4],
                };
                let m = LeaderMotion {
                    p: [leader[i][0], leader[i][1]],
                    dp: [leader[i][2], leader[i][3]],
                    ddp: [leader[i][4], leader[i][5]],
                };
                let off = Offset { lx: hold[i].0, ly: hold[i].1, dly: 0.0, ddly: 0.0 };
                let g = Gains::new(gains[i].0, gains[i].1).unwrap();
                let want = law(&robot, &s, &m, &off, g, variant);
                prop_assert_eq!(want.u.u1.to_bits(), u[0].0[i].to_bits());
                prop_assert_eq!(want.u.u2.to_bits(), u[1].0[i].to_bits());
                prop_assert_eq!(want.e.map(f64::to_bits), [p.e[0].0[i], p.e[1].0[i]].map(f64::to_bits));
                prop_assert_eq!(want.z.map(f64::to_bits), [p.z[0].0[i], p.z[1].0[i]].map(f64::to_bits));
            }
        }
    }

    /// The leader's motion in lanes is `LeaderMotion::of_robot` bit for bit.
    #[test]
    fn leaders_are_of_robot() {
        let x: [V; 5] = std::array::from_fn(|k| {
            Lanes(std::array::from_fn(|i| {
                ((k * W + i) as f64 * 0.77).sin() * 2.0
            }))
        });
        let (sin, cos) = (x[2].0.map(f64::sin), x[2].0.map(f64::cos));
        let l = Leaders::of(&x, lanes(&sin), lanes(&cos));
        for i in 0..W {
            let s = crate::model::State {
                x: x[0].0[i],
                y: x[1].0[i],
                theta: x[2].0[i],
                v: x[3].0[i],
                omega: x[4].0[i],
            };
            let dv = 0.37;
            let m = crate::law::control::LeaderMotion::of_robot(&s, dv);
            assert_eq!(m.p, [l.p[0].0[i], l.p[1].0[i]]);
            assert_eq!(m.dp, [l.dp[0].0[i], l.dp[1].0[i]]);
            let ddp = [
                l.q[0].0[i] + l.g[0].0[i] * dv,
                l.q[1].0[i] + l.g[1].0[i] * dv,
            ];
            assert_eq!(m.ddp, ddp);
        }
    }
}
