//! The stepping kernels: blocks of [`W`] agents, RK4 with the law in every
//! stage, as [`crate::sim::Simulation`] does it, in lanes.
//!
//! Every formula comes from the scalar code: eqs. 7–13 from
//! [`crate::control::law_partial`]/[`crate::control::law_finish`] (the same
//! generic functions `control::law` calls), a robot leader's motion from
//! [`crate::control::robot_leader`], eq. 5 and eq. 6 as in [`crate::lycomp`]
//! (eq. 6 as one angle instead of three, see [`fit`]), eq. 3 as in
//! [`crate::model`] with `1/m` and `1/J` precomputed.

use std::ops::{Add, Mul, Neg, Sub};

use crate::control::{Body, Hold, LawRobot, Variant, law_finish, law_partial, robot_leader};
use crate::lanes::{Lanes, Mask};
use crate::lycomp::LyComp;
use crate::reference::Jet;

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
/// [`crate::lycomp::fit`]), `c = [2G, 1/δ, (ε/δ)²]`.
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

/// Eq. 5 per lane, exactly [`crate::lycomp::exact`] in `f64`:
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

/// `[f(0), …, f(4)]`.
#[inline(always)]
pub(crate) fn each<const N: usize>(f: impl Fn(usize) -> Lanes<N>) -> [Lanes<N>; 5] {
    std::array::from_fn(f)
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
/// default bounds ([`crate::guard::Bounds::DEFAULT`]: `|v|`, `|ω|`,
/// `‖(x, y)‖`); a NaN fails every comparison, so it is caught too.
#[inline(always)]
pub(crate) fn broken<const N: usize>(x: &[Lanes<N>; 5], live: Mask<N>) -> Mask<N> {
    let b = crate::guard::Bounds::DEFAULT;
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

/// What a star agent's controller and plant do at one stage.
#[derive(Debug, Clone, Copy)]
pub(crate) struct StageOut {
    pub(crate) dx: [V; 5],
    pub(crate) e: [V; 2],
    pub(crate) z: [V; 2],
    pub(crate) u: [V; 2],
}

/// One stage of a block following the reference `r`, at which the agents
/// hold it at `ly` ([`star_ly`]): the law (eqs. 7–13), the motors, and the
/// plant's derivative (eq. 3). `sin`, `cos` are those of the heading `x[2]`.
#[inline(always)]
pub(crate) fn star_stage(
    c: &Consts,
    b: &Block,
    x: &[V; 5],
    (sin, cos): (V, V),
    r: &Carry,
    ly: V,
) -> StageOut {
    let body = Body::of(x, sin, cos);
    let hold = hold_ly(b, ly);
    let splat2 = |a: [f64; 2]| [V::splat(a[0]), V::splat(a[1])];
    let p = law_partial(&c.law, &body, splat2(r.p), splat2(r.dp), &hold, b.ke);
    let u = law_finish(&c.law, &p, splat2(r.q), b.kz, c.variant);
    let applied = actuate(c.limit, u);
    let dv = (applied[0] - x[3] * c.eta) * c.inv_m;
    let dw = (applied[1] - x[4] * c.psi) * c.inv_j;
    StageOut {
        dx: [x[3] * cos, x[3] * sin, x[4], dv, dw],
        e: p.e,
        z: p.z,
        u,
    }
}

/// `x + d k` and the sines and cosines of its heading, from those of `x`
/// ([`V::sin_cos_turned`]: the stage turns the robot by `d[2] k`).
#[inline(always)]
#[allow(clippy::type_complexity)]
pub(crate) fn turned_state<const N: usize>(
    x: &[Lanes<N>; 5],
    (sin, cos): (Lanes<N>, Lanes<N>),
    d: &[Lanes<N>; 5],
    k: f64,
) -> ([Lanes<N>; 5], (Lanes<N>, Lanes<N>)) {
    let next = add_scaled(x, d, k);
    let turned = (d[2] * k)
        .sin_cos_turned(sin, cos)
        .unwrap_or_else(|| next[2].sin_cos());
    (next, turned)
}

/// Advances star blocks by `refs.len()` steps; `refs[n]` is the reference at
/// `t_n`, `t_n + dt/2` (twice) and `t_{n+1}`. Each block runs all its steps in
/// registers. Returns the first step (within this call) and agent (within
/// `blocks`) whose state stopped being finite, if any.
///
/// Per step and agent: one `sin_cos` (stage 1; stages 2–4 turn it by their
/// small `δθ`), and two `L_Y`, since stages 2 and 3 see the reference at the
/// same instant and stage 4's instant is the next step's stage 1
/// (`refs[n][3] == refs[n + 1][0]`, as `fill_reference` makes them).
#[inline(always)]
pub(crate) fn star_tile(
    c: &Consts,
    blocks: &mut [Block],
    refs: &[[Carry; 4]],
) -> Option<(usize, usize)> {
    let (h, dt, h6) = (0.5 * c.dt, c.dt, c.dt / 6.0);
    let mut first: Option<(usize, usize)> = None;
    for (bi, b) in blocks.iter_mut().enumerate() {
        let mut x = b.x;
        let mut ly1 = refs.first().map_or(b.ly_off, |r| star_ly(c, b, &r[0]));
        for (n, r) in refs.iter().enumerate() {
            let (ly23, ly4) = (star_ly(c, b, &r[1]), star_ly(c, b, &r[3]));
            let sc1 = x[2].sin_cos();
            let k1 = star_stage(c, b, &x, sc1, &r[0], ly1).dx;
            let (x2, sc2) = turned_state(&x, sc1, &k1, h);
            let k2 = star_stage(c, b, &x2, sc2, &r[1], ly23).dx;
            let (x3, sc3) = turned_state(&x, sc1, &k2, h);
            let k3 = star_stage(c, b, &x3, sc3, &r[2], ly23).dx;
            let (x4, sc4) = turned_state(&x, sc1, &k3, dt);
            let k4 = star_stage(c, b, &x4, sc4, &r[3], ly4).dx;
            let k23 = each(|i| k2[i] + k3[i]);
            x = combine(&x, &k1, &k23, &k4, h6);
            ly1 = ly4;
            let bad = broken(&x, b.live);
            if bad.any() {
                let at = (n, bi * W + first_lane(bad));
                first = Some(first.map_or(at, |f| f.min(at)));
                break;
            }
        }
        b.x = x;
    }
    first
}

/// Per-block work space of a chain stage.
#[derive(Debug, Clone, Copy)]
pub struct Scratch {
    /// This stage's derivative (the previous stage's until overwritten).
    k: [V; 5],
    k1: [V; 5],
    /// `k₂ + k₃`.
    k23: [V; 5],
    /// `v̇ = α + β v̇_L`, `ω̇ = γ + δ v̇_L`.
    dv: Aff,
    dw: Aff,
}

impl Default for Scratch {
    fn default() -> Scratch {
        let z = V::splat(0.0);
        Scratch {
            k: [z; 5],
            k1: [z; 5],
            k23: [z; 5],
            dv: Aff { a: z, b: z },
            dw: Aff { a: z, b: z },
        }
    }
}

/// `[prev_{W−1}, own₀, …, own_{W−2}]`: each lane's leader is the lane before.
#[inline(always)]
pub(crate) fn shift_from<const N: usize>(own: Lanes<N>, prev: Lanes<N>) -> Lanes<N> {
    let mut r = [prev.0[N - 1]; N];
    r[1..].copy_from_slice(&own.0[..N - 1]);
    Lanes(r)
}

/// `[carry, own₀, …, own_{W−2}]`.
#[inline(always)]
pub(crate) fn shift_in(own: V, carry: f64) -> V {
    shift_from(own, V::splat(carry))
}

/// A block's agents as leaders (their followers' [`Carry`]s), in lanes.
#[derive(Debug, Clone, Copy)]
struct Leaders {
    p: [V; 2],
    dp: [V; 2],
    q: [V; 2],
    g: [V; 2],
    vd: V,
    wd: V,
}

impl Leaders {
    /// Robots at `x` with heading `(sin, cos)` as leaders:
    /// `LeaderMotion::of_robot` and `Placement::offset_for_robot`'s
    /// `(max(v, 0), ω)`.
    #[inline(always)]
    fn of(x: &[V; 5], sin: V, cos: V) -> Leaders {
        let unit = Aff {
            a: V::splat(0.0),
            b: V::splat(1.0),
        };
        let (dp, ddp) = robot_leader(sin, cos, x[3], x[4], unit);
        Leaders {
            p: [x[0], x[1]],
            dp,
            q: [ddp[0].a, ddp[1].a],
            g: [ddp[0].b, ddp[1].b],
            vd: x[3].max(V::splat(0.0)),
            wd: x[4],
        }
    }

    /// A carried leader in every lane.
    #[inline(always)]
    fn splat(c: &Carry) -> Leaders {
        let s2 = |k: [f64; 2]| [V::splat(k[0]), V::splat(k[1])];
        Leaders {
            p: s2(c.p),
            dp: s2(c.dp),
            q: s2(c.q),
            g: s2(c.g),
            vd: V::splat(c.vd),
            wd: V::splat(c.wd),
        }
    }

    /// Each lane's leader: the lane before, the first lane's the last lane
    /// of `prev` (the block before).
    #[inline(always)]
    fn shifted(&self, prev: &Leaders) -> Leaders {
        let s2 = |v: [V; 2], k: [V; 2]| [shift_from(v[0], k[0]), shift_from(v[1], k[1])];
        Leaders {
            p: s2(self.p, prev.p),
            dp: s2(self.dp, prev.dp),
            q: s2(self.q, prev.q),
            g: s2(self.g, prev.g),
            vd: shift_from(self.vd, prev.vd),
            wd: shift_from(self.wd, prev.wd),
        }
    }

    /// The last lane, for the next block's first agent.
    #[inline(always)]
    fn last(&self) -> Carry {
        let l = W - 1;
        Carry {
            p: [self.p[0].0[l], self.p[1].0[l]],
            dp: [self.dp[0].0[l], self.dp[1].0[l]],
            q: [self.q[0].0[l], self.q[1].0[l]],
            g: [self.g[0].0[l], self.g[1].0[l]],
            vd: self.vd.0[l],
            wd: self.wd.0[l],
            dv: 0.0,
        }
    }
}

/// A chain block's law at one stage, with the leaders' accelerations left
/// open: `v̇`, `ω̇` as affine functions of `v̇_L` (eqs. 7–13 and 3 are affine
/// in `p̈_d`, which is affine in `v̇_L`).
#[inline(always)]
fn chain_block(c: &Consts, b: &Block, x: &[V; 5], sin: V, cos: V, l: &Leaders) -> (Aff, Aff) {
    let body = Body::of(x, sin, cos);
    let hold = hold(c, b, l.vd, l.wd);
    let p = law_partial(&c.law, &body, l.p, l.dp, &hold, b.ke);
    let ddp = [
        Aff {
            a: l.q[0],
            b: l.g[0],
        },
        Aff {
            a: l.q[1],
            b: l.g[1],
        },
    ];
    let u = law_finish(&c.law, &p, ddp, b.kz, c.variant);
    (
        (u[0] - x[3] * c.eta) * c.inv_m,
        (u[1] - x[4] * c.psi) * c.inv_j,
    )
}

/// The chain stage update coefficients: stage `s` evaluates at `x + a_s k_{s−1}`.
#[inline(always)]
fn stage_state(b: &Block, sc: &Scratch, s: usize, dt: f64) -> [V; 5] {
    match s {
        0 => b.x,
        3 => add_scaled(&b.x, &sc.k, dt),
        _ => add_scaled(&b.x, &sc.k, 0.5 * dt),
    }
}

/// One stage of a chain segment whose first agent follows `cin`: every
/// derivative into `scratch[..].k`; returns the last agent as a leader (with
/// its `v̇`). Vectorised except for `v̇ᵢ = αᵢ + βᵢ v̇ᵢ₋₁`, one multiply-add per
/// agent in order.
#[inline(always)]
pub(crate) fn chain_stage(
    c: &Consts,
    blocks: &[Block],
    scratch: &mut [Scratch],
    s: usize,
    cin: &Carry,
) -> Carry {
    let mut prev = Leaders::splat(cin);
    for (b, sc) in blocks.iter().zip(scratch.iter_mut()) {
        let x = stage_state(b, sc, s, c.dt);
        let (sin, cos) = x[2].sin_cos();
        let own = Leaders::of(&x, sin, cos);
        let leaders = own.shifted(&prev);
        prev = own;
        let (dv, dw) = chain_block(c, b, &x, sin, cos, &leaders);
        sc.k[0] = x[3] * cos;
        sc.k[1] = x[3] * sin;
        sc.k[2] = x[4];
        sc.dv = dv;
        sc.dw = dw;
    }
    // The only sequential part: each v̇ needs the one before.
    let mut dvl = cin.dv;
    for sc in scratch.iter_mut() {
        let lead = dvl;
        let mut dv = [0.0; W];
        for (l, d) in dv.iter_mut().enumerate() {
            dvl = sc.dv.a.0[l] + sc.dv.b.0[l] * dvl;
            *d = dvl;
        }
        let dv = Lanes(dv);
        sc.k[3] = dv;
        sc.k[4] = sc.dw.a + sc.dw.b * shift_in(dv, lead);
    }
    let mut carry = prev.last();
    carry.dv = dvl;
    carry
}

/// Advances a chain segment by `carries.len()` steps. `carries[n][s]` is the
/// leader of the segment's first agent at step `n`, stage `s`, and is replaced
/// by the segment's last agent (the next segment's leader). Returns the first
/// broken step and agent (within the segment), if any.
#[inline(always)]
pub(crate) fn chain_tile(
    c: &Consts,
    blocks: &mut [Block],
    scratch: &mut [Scratch],
    carries: &mut [[Carry; 4]],
) -> Option<(usize, usize)> {
    let h6 = c.dt / 6.0;
    for (n, stages) in carries.iter_mut().enumerate() {
        for (s, carry) in stages.iter_mut().enumerate() {
            *carry = chain_stage(c, blocks, scratch, s, carry);
            for sc in scratch.iter_mut() {
                match s {
                    0 => sc.k1 = sc.k,
                    1 => sc.k23 = sc.k,
                    2 => sc.k23 = each(|i| sc.k23[i] + sc.k[i]),
                    _ => {}
                }
            }
        }
        let mut first = None;
        for (bi, (b, sc)) in blocks.iter_mut().zip(scratch.iter()).enumerate() {
            b.x = combine(&b.x, &sc.k1, &sc.k23, &sc.k, h6);
            let bad = broken(&b.x, b.live);
            if first.is_none() && bad.any() {
                first = Some((n, bi * W + first_lane(bad)));
            }
        }
        if first.is_some() {
            return first;
        }
    }
    None
}

/// What one agent's controller does at one instant.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Probe {
    /// Tracking error `e` (eq. 7), body frame, m.
    pub e: [f64; 2],
    /// Backstepping error `z` (eq. 10), body frame, m/s.
    pub z: [f64; 2],
    /// The commanded input `u` (eq. 13), before any torque saturation.
    pub u: [f64; 2],
}

/// Lane `l` of a block's state.
#[inline]
pub(crate) fn state_of<const N: usize>(x: &[Lanes<N>; 5], l: usize) -> crate::model::State {
    crate::model::State {
        x: x[0].0[l],
        y: x[1].0[l],
        theta: x[2].0[l],
        v: x[3].0[l],
        omega: x[4].0[l],
    }
}

fn unpack(out: &mut Vec<Probe>, e: [V; 2], z: [V; 2], u: [V; 2]) {
    for l in 0..W {
        out.push(Probe {
            e: [e[0].0[l], e[1].0[l]],
            z: [z[0].0[l], z[1].0[l]],
            u: [u[0].0[l], u[1].0[l]],
        });
    }
}

/// The star's controllers at the blocks' current state (reference `r`).
pub(crate) fn star_probe(c: &Consts, blocks: &[Block], r: &Carry, out: &mut Vec<Probe>) {
    for b in blocks {
        let o = star_stage(c, b, &b.x, b.x[2].sin_cos(), r, star_ly(c, b, r));
        unpack(out, o.e, o.z, o.u);
    }
}

/// A chain's controllers at the blocks' current state: the first stage, then
/// the law once more per block with every leader's `v̇` known.
pub(crate) fn chain_probe(
    c: &Consts,
    blocks: &[Block],
    scratch: &mut [Scratch],
    r: &Carry,
    out: &mut Vec<Probe>,
) {
    chain_stage(c, blocks, scratch, 0, r);
    let (mut prev, mut lead_dv) = (Leaders::splat(r), r.dv);
    for (b, sc) in blocks.iter().zip(scratch.iter()) {
        let (sin, cos) = b.x[2].sin_cos();
        let own = Leaders::of(&b.x, sin, cos);
        let l = own.shifted(&prev);
        prev = own;
        let dvl = shift_in(sc.k[3], lead_dv);
        lead_dv = sc.k[3].0[W - 1];
        let body = Body::of(&b.x, sin, cos);
        let hold = hold(c, b, l.vd, l.wd);
        let p = law_partial(&c.law, &body, l.p, l.dp, &hold, b.ke);
        let ddp = [l.q[0] + l.g[0] * dvl, l.q[1] + l.g[1] * dvl];
        let u = law_finish(&c.law, &p, ddp, b.kz, c.variant);
        unpack(out, p.e, p.z, u);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lycomp::{self, FitCoefficients};
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
            use crate::control::{Gains, LeaderMotion, Offset, law};
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
            let m = crate::control::LeaderMotion::of_robot(&s, dv);
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
