//! The velocity-base kernel: blocks of [`W`] agents on velocity-controlled
//! bases ([`crate::base::VelocityBase`]) driven by the kinematic law
//! ([`crate::kinematic`]), RK4 with the law in every stage, stepped by the
//! same driver as the torque kernel ([`super::BatchEngine`]).
//!
//! Every formula comes from the scalar code: the command from
//! [`crate::kinematic::kinematic_of`] (the generic function
//! `kinematic_law` calls), `L_Ycomp` as in the torque kernel
//! ([`super::kernel::compensation`]), the speed limiter, lags and acceleration
//! limits of [`crate::base::VelocityBase::limit`] and
//! [`crate::base::VelocityBase::derivative`] in lanes, and
//! [`crate::base::VelocityBase::settle`] after each step. The limiters decide
//! per lane exactly as the scalar code does (`|v| > v_max`, `|v̇| > a_max`, …)
//! and act through selects, min and max; the scaled values (one division for
//! the common scale factor, `1/τ`, `1/v_max`, … precomputed) are computed only
//! when some lane of the block needs them, which after the transients none
//! does. An infinite limit never binds, so an unlimited base takes the same
//! path at the cost of a comparison.
//!
//! Per step, a block evaluates the law four times: the RK4 stages 2–4 and
//! once at the new state, which both settles the step (an axis without lag
//! takes the command's velocity) and serves as the next step's stage 1 (the
//! command does not depend on the state's velocities). A star block runs its
//! steps in registers like the torque star (one `sin_cos` per step, stages 2–4
//! turned by their `δθ`, two `L_Ycomp` per step). A chain block runs its steps
//! given its leader's motion at every stage, read from the tile of leaders,
//! where it writes its own last agent's in their place for the block after:
//! the chain is walked block by block, a tile at a time, and a long chain's
//! two halves run one tile apart on two threads like the torque chain. When
//! both axes lag, a robot leader's speeds are its state's and a block's law is
//! one vector evaluation; when an axis has no lag the leader moves at its
//! command, so each agent's command waits for its leader's: the law then runs
//! lane after lane (the same generic code on one lane).

use std::marker::PhantomData;

use pulp::{Arch, Simd, WithSimd};

use crate::base::{AccelLimit, VelocityBase, VelocityCommand};
use crate::check;
use crate::control::Hold;
use crate::error::SimError;
use crate::kinematic::kinematic_of;
use crate::lanes::{Lanes, Mask};
use crate::lycomp::LyComp;
use crate::model::State;
use crate::reference::{Jet, Order, Reference, Trajectory};

use super::kernel::{Block, W, broken, compensation, first_lane, shift_from, state_of};

/// Agents per velocity block, as the torque kernel packs them (blocks of
/// four, one AVX2 vector per quantity, compiled to ≈ 30 % more instructions
/// per agent-step: the vectoriser splits parts of the stage into halves).
pub(crate) const VW: usize = W;
/// `VW` agents' values of one quantity.
pub(crate) type V4 = Lanes<VW>;
use super::{BatchEngine, EngineError, Kernel, Member, Topology, VelocityEngine, pack, sealed};

/// What every agent of a velocity batch shares: the base, in the form the
/// kernel uses.
#[derive(Debug, Clone, Copy)]
pub struct VConsts {
    pub(crate) comp: LyComp,
    pub(crate) dt: f64,
    /// Whether each axis lags (`τ > 0`); an axis without lag moves at the command.
    pub(crate) lag: [bool; 2],
    /// `1/τ_v`, `1/τ_ω` (0 without lag).
    pub(crate) inv_tau: [f64; 2],
    /// `v_max`, `ω_max` (may be infinite) and their inverses (0 if infinite).
    pub(crate) max: [f64; 2],
    pub(crate) inv_max: [f64; 2],
    /// `a_max`, `α_max` (may be infinite), their inverses, and how they act.
    pub(crate) acc: [f64; 2],
    pub(crate) inv_acc: [f64; 2],
    pub(crate) accel: AccelLimit,
}

/// `W` agents on velocity bases: states, constants and saturated-tick counts.
#[derive(Debug, Clone, Copy)]
pub struct VBlock {
    /// `x, y, θ, v, ω`.
    pub(crate) x: [V4; 5],
    pub(crate) own: Own<VW>,
    /// Lanes that hold an agent (the last block may be padded).
    pub(crate) live: Mask<VW>,
    /// Steps whose command (at the step's start) exceeded a speed limit.
    pub(crate) saturated: [u64; VW],
}

impl VBlock {
    /// The velocity blocks of a torque block's agents (same packing, half
    /// the lanes each; a half of padding alone is left out).
    pub(crate) fn of(b: &Block) -> impl Iterator<Item = VBlock> + '_ {
        (0..W / VW).filter_map(move |h| {
            let half = |v: Lanes<W>| -> V4 { Lanes::from_slice(&v.0[h * VW..]) };
            let live = Mask(std::array::from_fn(|l| b.live.0[h * VW + l]));
            live.any().then(|| VBlock {
                x: b.x.map(half),
                own: Own {
                    lx: half(b.lx),
                    inv_lx: half(b.inv_lx),
                    ly_off: half(b.ly_off),
                    ke: half(b.ke),
                    comp: b.comp.map(half),
                },
                live,
                saturated: [0; VW],
            })
        })
    }
}

/// An agent's own constants, in `N` lanes.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Own<const N: usize> {
    lx: Lanes<N>,
    inv_lx: Lanes<N>,
    ly_off: Lanes<N>,
    ke: Lanes<N>,
    /// `L_Ycomp` constants, as [`Block::comp`].
    comp: [Lanes<N>; 3],
}

impl Own<VW> {
    /// Lane `l` alone.
    #[inline(always)]
    fn lane(&self, l: usize) -> Own<1> {
        let one = |v: V4| Lanes([v.0[l]]);
        Own {
            lx: one(self.lx),
            inv_lx: one(self.inv_lx),
            ly_off: one(self.ly_off),
            ke: one(self.ke),
            comp: self.comp.map(one),
        }
    }
}

/// A leader as its followers see it: `p_d`, `ṗ_d` and the `(V_d, ω_d)`
/// `L_Ycomp` reads (a robot: its actual speeds, `V_d = max(v, 0)`).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct Lead {
    pub(crate) p: [f64; 2],
    pub(crate) dp: [f64; 2],
    pub(crate) vd: f64,
    pub(crate) wd: f64,
}

impl Lead {
    /// The virtual leader at one instant.
    pub(crate) fn reference(jet: &Jet) -> Lead {
        Lead {
            p: jet.p,
            dp: jet.dp,
            vd: jet.speed(),
            wd: jet.turn_rate(),
        }
    }
}

/// Leaders in `N` lanes.
#[derive(Debug, Clone, Copy)]
struct Leads<const N: usize> {
    p: [Lanes<N>; 2],
    dp: [Lanes<N>; 2],
    vd: Lanes<N>,
    wd: Lanes<N>,
}

impl<const N: usize> Leads<N> {
    #[inline(always)]
    fn splat(l: &Lead) -> Leads<N> {
        let s = Lanes::splat;
        Leads {
            p: [s(l.p[0]), s(l.p[1])],
            dp: [s(l.dp[0]), s(l.dp[1])],
            vd: s(l.vd),
            wd: s(l.wd),
        }
    }

    /// Robots at `(x, y)`, heading `(sin, cos)`, moving at `(v, ω)`
    /// (`LeaderMotion::of_robot`'s `ṗ_d`, `Placement::offset_for_robot`'s
    /// `(max(v, 0), ω)`).
    #[inline(always)]
    fn robots(x: &[Lanes<N>; 5], (sin, cos): (Lanes<N>, Lanes<N>), speeds: [Lanes<N>; 2]) -> Self {
        Leads {
            p: [x[0], x[1]],
            dp: [speeds[0] * cos, speeds[0] * sin],
            vd: speeds[0].max(Lanes::splat(0.0)),
            wd: speeds[1],
        }
    }

    /// Lane `l`.
    #[inline(always)]
    fn lead(&self, l: usize) -> Lead {
        Lead {
            p: [self.p[0].0[l], self.p[1].0[l]],
            dp: [self.dp[0].0[l], self.dp[1].0[l]],
            vd: self.vd.0[l],
            wd: self.wd.0[l],
        }
    }
}

impl Leads<VW> {
    /// Each lane's leader: the lane before; the first lane's is `first`.
    #[inline(always)]
    fn shifted(&self, first: &Lead) -> Leads<VW> {
        let sh = |v: V4, c: f64| shift_from(v, V4::splat(c));
        Leads {
            p: [sh(self.p[0], first.p[0]), sh(self.p[1], first.p[1])],
            dp: [sh(self.dp[0], first.dp[0]), sh(self.dp[1], first.dp[1])],
            vd: sh(self.vd, first.vd),
            wd: sh(self.wd, first.wd),
        }
    }
}

/// The law's output at one stage, in `N` lanes.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Cmd<const N: usize> {
    /// `(v*, ω*)` before the limits.
    pub(crate) raw: [Lanes<N>; 2],
    /// The command the base follows (after the speed limits).
    pub(crate) cmd: [Lanes<N>; 2],
    /// `e` (eq. 7).
    pub(crate) e: [Lanes<N>; 2],
    /// Lanes whose command exceeded a speed limit.
    pub(crate) saturated: Mask<N>,
}

/// `L_Y = L_Yoff + L_Ycomp` for leaders `l`.
#[inline(always)]
fn ly_of<const N: usize>(c: &VConsts, own: &Own<N>, l: &Leads<N>) -> Lanes<N> {
    own.ly_off + compensation(c.comp, l.vd, l.wd, &own.comp)
}

/// `a` clamped to `[−m, m]`.
#[inline(always)]
fn clamp<const N: usize>(a: Lanes<N>, m: Lanes<N>) -> Lanes<N> {
    a.max(-m).min(m)
}

/// The kinematic law and the speed limiter ([`crate::base::VelocityBase::limit`]:
/// where `|v| > v_max` or `|ω| > ω_max`, `(v, ω)` scaled by
/// `1 / max(|v|/v_max, |ω|/ω_max)`, then clamped against the last bit of
/// rounding; the scaling computed only when some lane needs it).
#[inline(always)]
fn command<const N: usize>(
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

/// The velocities the base moves at ([`crate::base::VelocityBase::speeds`]).
#[inline(always)]
fn speeds<const N: usize>(c: &VConsts, x: &[Lanes<N>; 5], cmd: &[Lanes<N>; 2]) -> [Lanes<N>; 2] {
    [
        if c.lag[0] { x[3] } else { cmd[0] },
        if c.lag[1] { x[4] } else { cmd[1] },
    ]
}

/// The state derivative ([`crate::base::VelocityBase::derivative`]): eq. 1
/// at the base's speeds, the lags' accelerations after their limits (where
/// `|v̇| > a_max` or `|ω̇| > α_max`; computed only when some lane needs it).
#[inline(always)]
fn derivative(c: &VConsts, x: &[V4; 5], (sin, cos): (V4, V4), cmd: &[V4; 2]) -> [V4; 5] {
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

/// `x + d k` and the sines and cosines of its heading, turned from those of
/// `x` by `d[2] k` ([`V4::sin_cos_turned`]), or, when some lane turns by
/// 0.05 rad or more, from [`V4::sin_cos`] out of line (rare: the kernel stays
/// small enough for the compiler to keep it in vectors).
#[inline(always)]
#[allow(clippy::type_complexity)]
fn turned(x: &[V4; 5], (sin, cos): (V4, V4), d: &[V4; 5], k: f64) -> ([V4; 5], (V4, V4)) {
    let mut next = [
        x[0] + d[0] * k,
        x[1] + d[1] * k,
        x[2] + d[2] * k,
        x[3] + d[3] * k,
        x[4] + d[4] * k,
    ];
    vectors(&mut next);
    let sc = match (d[2] * k).sin_cos_turned(sin, cos) {
        Some(sc) => sc,
        None => sin_cos_cold(next[2]),
    };
    (next, sc)
}

/// Puts a state in memory, whole vectors at a time. Without it the
/// vectoriser, seeing the entire step as one block of scalar operations,
/// splits parts of it into half vectors and shuffles (≈ 35 % more
/// instructions per agent-step, measured).
#[inline(always)]
fn vectors(x: &mut [V4; 5]) {
    std::hint::black_box(x);
}

#[cold]
#[inline(never)]
fn sin_cos_cold(theta: V4) -> (V4, V4) {
    theta.sin_cos()
}

/// The state after a step ([`crate::base::VelocityBase::settle`]), given the
/// command at its end.
#[inline(always)]
fn settle(c: &VConsts, x: &mut [V4; 5], cmd: &[V4; 2]) {
    let [v, w] = speeds(c, x, cmd);
    x[3] = clamp(v, V4::splat(c.max[0]));
    x[4] = clamp(w, V4::splat(c.max[1]));
}

/// How a block sees its leaders.
pub(crate) trait Leaders {
    /// `L_Y` when it depends on `lead` alone (a star: every agent follows
    /// it), to be shared by the stages that see the same leader.
    fn ly(c: &VConsts, own: &Own<VW>, lead: &Lead) -> Option<V4>;

    /// The block's command at state `x` (heading `sc`) when the first lane's
    /// leader is `lead` (at `L_Y = ly` when given), and the block's own last
    /// agent as a leader (a star's agents lead nobody: any value).
    fn command(
        c: &VConsts,
        own: &Own<VW>,
        x: &[V4; 5],
        sc: (V4, V4),
        lead: &Lead,
        ly: Option<V4>,
    ) -> (Cmd<VW>, Lead);
}

/// Every agent follows the virtual leader.
#[derive(Debug)]
pub(crate) struct Star;

/// Agent `i` follows agent `i − 1`.
#[derive(Debug)]
pub(crate) struct Chain;

impl Leaders for Star {
    #[inline(always)]
    fn ly(c: &VConsts, own: &Own<VW>, lead: &Lead) -> Option<V4> {
        Some(ly_of(c, own, &Leads::splat(lead)))
    }

    #[inline(always)]
    fn command(
        c: &VConsts,
        own: &Own<VW>,
        x: &[V4; 5],
        sc: (V4, V4),
        lead: &Lead,
        ly: Option<V4>,
    ) -> (Cmd<VW>, Lead) {
        let l = Leads::splat(lead);
        let ly = ly.unwrap_or_else(|| ly_of(c, own, &l));
        (command(c, own, x, sc, &l, ly), *lead)
    }
}

impl Leaders for Chain {
    #[inline(always)]
    fn ly(_: &VConsts, _: &Own<VW>, _: &Lead) -> Option<V4> {
        None
    }

    #[inline(always)]
    fn command(
        c: &VConsts,
        own: &Own<VW>,
        x: &[V4; 5],
        sc: (V4, V4),
        lead: &Lead,
        _: Option<V4>,
    ) -> (Cmd<VW>, Lead) {
        if c.lag[0] && c.lag[1] {
            // The leaders move at their states' speeds: one vector evaluation.
            let mine = Leads::robots(x, sc, [x[3], x[4]]);
            let l = mine.shifted(lead);
            return (
                command(c, own, x, sc, &l, ly_of(c, own, &l)),
                mine.lead(VW - 1),
            );
        }
        // A leader moves at its command on an axis without lag: lane by lane.
        let zero = V4::splat(0.0);
        let mut out = Cmd {
            raw: [zero; 2],
            cmd: [zero; 2],
            e: [zero; 2],
            saturated: Mask([0; VW]),
        };
        let one = |v: V4, i: usize| Lanes([v.0[i]]);
        let mut lead = *lead;
        for i in 0..VW {
            let xi = x.map(|v| one(v, i));
            let sci = (one(sc.0, i), one(sc.1, i));
            let l = Leads::<1>::splat(&lead);
            let oi = own.lane(i);
            let k = command(c, &oi, &xi, sci, &l, ly_of(c, &oi, &l));
            lead = Leads::<1>::robots(&xi, sci, speeds(c, &xi, &k.cmd)).lead(0);
            for j in 0..2 {
                out.raw[j].0[i] = k.raw[j].0[0];
                out.cmd[j].0[i] = k.cmd[j].0[0];
                out.e[j].0[i] = k.e[j].0[0];
            }
            out.saturated.0[i] = k.saturated.0[0];
        }
        (out, lead)
    }
}

/// The leaders over one tile: `first` at the first step's start; per step,
/// at stages 2, 3, 4 and at the step's end (the next step's start). A star's
/// blocks all read the reference from it; a chain's block reads its leader
/// at each stage and writes its own last agent there, for the block after.
#[derive(Debug, Clone)]
pub struct Tile {
    pub(crate) first: Lead,
    pub(crate) steps: Vec<[Lead; 4]>,
}

/// A tile of leaders as a block uses it.
trait Stages {
    fn tile(&self) -> &Tile;
    /// The block's last agent in place of the leader just read (a chain).
    fn put_first(&mut self, l: Lead);
    fn put(&mut self, n: usize, s: usize, l: Lead);
    #[inline(always)]
    fn first(&self) -> Lead {
        self.tile().first
    }
    #[inline(always)]
    fn at(&self, n: usize) -> [Lead; 4] {
        self.tile().steps[n]
    }
}

/// A star's tile: read by every block, written by none.
impl Stages for &Tile {
    #[inline(always)]
    fn tile(&self) -> &Tile {
        self
    }
    #[inline(always)]
    fn put_first(&mut self, _: Lead) {}
    #[inline(always)]
    fn put(&mut self, _: usize, _: usize, _: Lead) {}
}

/// A chain's tile: each block replaces its leader by its own last agent.
impl Stages for &mut Tile {
    #[inline(always)]
    fn tile(&self) -> &Tile {
        self
    }
    #[inline(always)]
    fn put_first(&mut self, l: Lead) {
        self.first = l;
    }
    #[inline(always)]
    fn put(&mut self, n: usize, s: usize, l: Lead) {
        self.steps[n][s] = l;
    }
}

/// Advances one block by `len` steps led by `t`. Returns the first step and
/// lane whose state stopped being finite, if any.
#[inline(always)]
fn block_tile<L: Leaders, T: Stages>(
    c: &VConsts,
    b: &mut VBlock,
    t: &mut T,
    len: usize,
) -> Option<(usize, usize)> {
    let (h, dt, h6) = (0.5 * c.dt, c.dt, c.dt / 6.0);
    let own = &b.own;
    let mut x = b.x;
    // Saturated ticks of this tile: a mask's all-ones lane is −1.
    let mut ticks = [0u64; VW];
    let mut sc = x[2].sin_cos();
    let first = t.first();
    let (mut cur, me) = L::command(c, own, &x, sc, &first, L::ly(c, own, &first));
    t.put_first(me);
    let mut broke = None;
    for n in 0..len {
        let leads = t.at(n);
        // A star's leader is the same at stages 2 and 3, and at stage 4
        // and the step's end (`fill`): one `L_Y` each.
        let ly23 = L::ly(c, own, &leads[0]);
        let ly4 = L::ly(c, own, &leads[2]);
        for (k, m) in ticks.iter_mut().zip(cur.saturated.0) {
            *k = k.wrapping_sub(m);
        }
        let k1 = derivative(c, &x, sc, &cur.cmd);
        let (x2, sc2) = turned(&x, sc, &k1, h);
        let (c2, me) = L::command(c, own, &x2, sc2, &leads[0], ly23);
        t.put(n, 0, me);
        let k2 = derivative(c, &x2, sc2, &c2.cmd);
        let (x3, sc3) = turned(&x, sc, &k2, h);
        let (c3, me) = L::command(c, own, &x3, sc3, &leads[1], ly23);
        t.put(n, 1, me);
        let k3 = derivative(c, &x3, sc3, &c3.cmd);
        let (x4, sc4) = turned(&x, sc, &k3, dt);
        let (c4, me) = L::command(c, own, &x4, sc4, &leads[2], ly4);
        t.put(n, 2, me);
        let k4 = derivative(c, &x4, sc4, &c4.cmd);
        // x + h/6 (k₁ + 2 (k₂ + k₃) + k₄), written out (`std::array::from_fn`
        // calls its closure out of line).
        let rk = |i: usize| x[i] + (k1[i] + (k2[i] + k3[i]) * 2.0 + k4[i]) * h6;
        x = [rk(0), rk(1), rk(2), rk(3), rk(4)];
        vectors(&mut x);
        sc = x[2].sin_cos();
        let (next, me) = L::command(c, own, &x, sc, &leads[3], ly4);
        t.put(n, 3, me);
        cur = next;
        settle(c, &mut x, &cur.cmd);
        let bad = broken(&x, b.live);
        if bad.any() {
            broke = Some((n, first_lane(bad)));
            break;
        }
    }
    b.x = x;
    for (s, k) in b.saturated.iter_mut().zip(ticks) {
        *s += k;
    }
    broke
}

/// Advances blocks by `len` steps, each led by `t` (a star's blocks all by
/// the reference; a chain's each by the one before, through `t`). Returns the
/// earliest broken step and agent (within `blocks`), if any.
#[inline(always)]
fn blocks_tile<L: Leaders, T: Stages>(
    c: &VConsts,
    blocks: &mut [VBlock],
    mut t: T,
    len: usize,
) -> Option<(usize, usize)> {
    let mut first: Option<(usize, usize)> = None;
    let mut steps = len;
    for (bi, b) in blocks.iter_mut().enumerate() {
        if let Some((n, lane)) = block_tile::<L, T>(c, b, &mut t, steps) {
            // Later agents may break earlier: run them up to this step.
            let at = (n, bi * VW + lane);
            first = Some(first.map_or(at, |f| f.min(at)));
            steps = n + 1;
        }
    }
    first
}

/// The blocks' commands at their current state; `first` leads the first
/// block (and, in a chain, each block the next).
pub(crate) fn probe<L: Leaders>(
    c: &VConsts,
    blocks: &[VBlock],
    mut first: Lead,
    out: &mut Vec<Cmd<VW>>,
) {
    for b in blocks {
        let (cmd, me) = L::command(c, &b.own, &b.x, b.x[2].sin_cos(), &first, None);
        out.push(cmd);
        first = me;
    }
}

/// What the agents of a velocity batch share. Built by [`VelocityBatch::new`].
#[derive(Debug, Clone)]
#[non_exhaustive]
pub struct VelocityBatch {
    /// Every agent's base.
    pub base: VelocityBase,
    /// Who follows whom.
    pub topology: Topology,
    /// The virtual leader's path.
    pub reference: Reference,
    /// RK4 step, s.
    pub dt: f64,
}

impl VelocityBatch {
    /// What a velocity batch's agents share (the kinematic law on one base),
    /// (its base is possible by construction, [`VelocityBase::new`]), refusing
    /// a step that is not a finite number > 0 or one longer than a lag
    /// ([`VelocityBase::check_step`]).
    pub fn new(
        base: VelocityBase,
        topology: Topology,
        reference: Reference,
        dt: f64,
    ) -> Result<VelocityBatch, SimError> {
        let param = |context: &str| {
            let context = context.to_owned();
            move |source| SimError::Param { context, source }
        };
        check::positive("dt", dt).map_err(param("sim"))?;
        base.check_step(dt).map_err(param("base"))?;
        Ok(VelocityBatch {
            base,
            topology,
            reference,
            dt,
        })
    }
}

/// What one agent's kinematic law does at one instant.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct VelocityProbe {
    /// Tracking error `e` (eq. 7), body frame, m.
    pub e: [f64; 2],
    /// The law's command `(v*, ω*)`, before the speed limits.
    pub command: VelocityCommand,
    /// The command the base follows (after the speed limits).
    pub applied: VelocityCommand,
    /// Whether the speed limits cut the command.
    pub saturated: bool,
}

/// The velocity-base kernel of [`BatchEngine`]: velocity-controlled bases
/// under the kinematic law (see the [module docs](self)).
#[derive(Debug, Clone, Copy)]
pub enum Velocity {}

impl sealed::Sealed for Velocity {}

impl Kernel for Velocity {
    type Probe = VelocityProbe;
    type Consts = VConsts;
    type Block = VBlock;
    /// A velocity chain needs no work space beyond its tile.
    type Scratch = ();
    type Tile = Tile;
    const LANES: usize = VW;
    /// A velocity chain walks its blocks one at a time (each a whole tile).
    const SEGMENT: usize = 1;

    fn dt(c: &VConsts) -> f64 {
        c.dt
    }

    fn state(b: &VBlock, l: usize) -> State {
        state_of(&b.x, l)
    }

    fn tile(steps: usize) -> Tile {
        Tile {
            first: Lead::default(),
            steps: vec![[Lead::default(); 4]; steps],
        }
    }

    fn tile_bytes(t: &Tile) -> usize {
        t.steps.capacity() * size_of::<[Lead; 4]>()
    }

    /// The reference over the tile's `len` steps from `step0`: at `t_n` for
    /// the first step's start, then per step at `t_n + dt/2` (stages 2 and 3)
    /// and `t_{n+1}` (stage 4 and the step's end), as the torque engine's
    /// `fill_reference`.
    fn fill(tile: &mut Tile, len: usize, reference: &Reference, step0: u64, dt: f64) {
        let at = |t: f64| Lead::reference(&reference.eval(t, Order::Two));
        tile.first = at(step0 as f64 * dt);
        for (n, s) in (step0..).zip(tile.steps[..len].iter_mut()) {
            let half = at(n as f64 * dt + 0.5 * dt);
            let end = at((n + 1) as f64 * dt);
            *s = [half, half, end, end];
        }
    }

    fn star(
        arch: Arch,
        c: &VConsts,
        blocks: &mut [VBlock],
        t: &Tile,
        len: usize,
    ) -> Option<(usize, usize)> {
        arch.dispatch(Run::<Star, &Tile> {
            c,
            blocks,
            t,
            len,
            leaders: PhantomData,
        })
    }

    fn chain(
        arch: Arch,
        c: &VConsts,
        blocks: &mut [VBlock],
        _: &mut [()],
        t: &mut Tile,
        len: usize,
    ) -> Option<(usize, usize)> {
        arch.dispatch(Run::<Chain, &mut Tile> {
            c,
            blocks,
            t,
            len,
            leaders: PhantomData,
        })
    }

    fn probes(
        c: &VConsts,
        topology: Topology,
        blocks: &[VBlock],
        reference: &Reference,
        t: f64,
    ) -> Vec<VelocityProbe> {
        let first = Lead::reference(&reference.eval(t, Order::Two));
        let mut cmds = Vec::with_capacity(blocks.len());
        match topology {
            Topology::Star => probe::<Star>(c, blocks, first, &mut cmds),
            Topology::Chain => probe::<Chain>(c, blocks, first, &mut cmds),
        }
        cmds.iter()
            .flat_map(|k| {
                (0..VW).map(move |l| VelocityProbe {
                    e: [k.e[0].0[l], k.e[1].0[l]],
                    command: VelocityCommand {
                        v: k.raw[0].0[l],
                        omega: k.raw[1].0[l],
                    },
                    applied: VelocityCommand {
                        v: k.cmd[0].0[l],
                        omega: k.cmd[1].0[l],
                    },
                    saturated: k.saturated.0[l] != 0,
                })
            })
            .collect()
    }
}

impl VelocityEngine {
    /// Builds a velocity batch from values valid by construction
    /// ([`VelocityBatch::new`], [`Member::new`]; `K_z` is not used), refusing
    /// what the engine does not do.
    pub fn new(
        batch: VelocityBatch,
        members: impl IntoIterator<Item = Member>,
    ) -> Result<VelocityEngine, EngineError> {
        let (blocks, comp, n) = pack(members)?;
        let b = batch.base;
        let inv = |m: f64| if m.is_finite() { 1.0 / m } else { 0.0 };
        let c = VConsts {
            comp,
            dt: batch.dt,
            lag: [b.tau_v() > 0.0, b.tau_omega() > 0.0],
            inv_tau: [b.tau_v(), b.tau_omega()].map(|t| if t > 0.0 { 1.0 / t } else { 0.0 }),
            max: [b.v_max(), b.omega_max()],
            inv_max: [inv(b.v_max()), inv(b.omega_max())],
            acc: [b.a_max(), b.alpha_max()],
            inv_acc: [inv(b.a_max()), inv(b.alpha_max())],
            accel: b.accel(),
        };
        let blocks = blocks.iter().flat_map(VBlock::of).collect();
        Ok(BatchEngine::assemble(
            c,
            batch.topology,
            batch.reference,
            blocks,
            n,
        ))
    }

    /// Agent `i`'s number of steps whose command (at the step's start)
    /// exceeded a speed limit.
    pub fn saturated_ticks(&self, i: usize) -> u64 {
        self.blocks[i / VW].saturated[i % VW]
    }
}

/// A tile of blocks for [`Arch::dispatch`].
struct Run<'a, L, T> {
    c: &'a VConsts,
    blocks: &'a mut [VBlock],
    t: T,
    len: usize,
    leaders: PhantomData<L>,
}

impl<L: Leaders, T: Stages> WithSimd for Run<'_, L, T> {
    type Output = Option<(usize, usize)>;
    #[inline(always)]
    fn with_simd<S: Simd>(self, _: S) -> Self::Output {
        blocks_tile::<L, T>(self.c, self.blocks, self.t, self.len)
    }
}
