//! The velocity-base kernel: blocks of [`W`] agents on velocity-controlled
//! bases ([`crate::base::VelocityBase`]) driven by the kinematic law
//! ([`crate::kinematic`]), RK4 with the law in every stage.
//!
//! Every formula comes from the scalar code: the command from
//! [`crate::kinematic::kinematic_of`] (the generic function
//! `kinematic_law` calls), `L_Ycomp` as in the torque kernel
//! ([`super::kernel::compensation`]), the speed limiter, lags and acceleration
//! limits of [`crate::base::VelocityBase::limit`] and
//! [`crate::base::VelocityBase::derivative`] in lanes, branch-free
//! (`1/τ`, `1/v_max`, … precomputed, one division for the common scale factor
//! instead of two), and [`crate::base::VelocityBase::settle`] after each step.
//!
//! Per step, a block evaluates the law five times: the four RK4 stages and
//! once at the new state, which both settles the step (an axis without lag
//! takes the command's velocity) and serves as the next step's stage 1 (the
//! command does not depend on the state's velocities). A star block runs its
//! steps in registers like the torque star (one `sin_cos` per step, stages 2–4
//! turned by their `δθ`, two `L_Ycomp` per step). A chain block runs its steps
//! given its leader's motion at every stage, recorded by the block before, and
//! records its own last agent's for the block after: the chain is walked block
//! by block, a tile at a time. When both axes lag, a robot leader's speeds are
//! its state's and a block's law is one vector evaluation; when an axis has
//! no lag the leader moves at its command, so each agent's command waits for
//! its leader's: the law then runs lane after lane (the same generic code on
//! one lane).

use std::marker::PhantomData;

use pulp::{Arch, Simd, WithSimd};
use rayon::prelude::*;

use crate::base::{AccelLimit, VelocityBase, VelocityCommand};
use crate::check;
use crate::control::Hold;
use crate::error::SimError;
use crate::kinematic::kinematic_of;
use crate::lanes::{Lanes, Mask};
use crate::lycomp::LyComp;
use crate::model::State;
use crate::reference::{Jet, Order, Reference, Trajectory};

use super::kernel::{Block, V, W, compensation};
use super::{EngineError, Member, PAR_BLOCKS, TILE, Topology, pack};

/// What every agent of a velocity batch shares: the base, in the form the
/// kernel uses.
#[derive(Debug, Clone, Copy)]
pub(crate) struct VConsts {
    pub(crate) comp: LyComp,
    pub(crate) dt: f64,
    /// Whether each axis lags (`τ > 0`); an axis without lag moves at the command.
    pub(crate) lag: [bool; 2],
    /// `1/τ_v`, `1/τ_ω` (0 without lag).
    pub(crate) inv_tau: [f64; 2],
    /// `v_max`, `ω_max` (may be infinite), and whether either is finite.
    pub(crate) max: [f64; 2],
    pub(crate) inv_max: [f64; 2],
    pub(crate) speed_limited: bool,
    /// `a_max`, `α_max`, their inverses, whether either is finite, and how
    /// they act.
    pub(crate) acc: [f64; 2],
    pub(crate) inv_acc: [f64; 2],
    pub(crate) acc_limited: bool,
    pub(crate) accel: AccelLimit,
}

/// `W` agents on velocity bases: states, constants and saturated-tick counts.
#[derive(Debug, Clone, Copy)]
pub(crate) struct VBlock {
    /// `x, y, θ, v, ω`.
    pub(crate) x: [V; 5],
    pub(crate) own: Own<W>,
    /// Lanes that hold an agent (the last block may be padded).
    pub(crate) live: Mask<W>,
    /// Steps whose command (at the step's start) exceeded a speed limit.
    pub(crate) saturated: [u64; W],
}

impl VBlock {
    /// The velocity block of a torque block's agents (same packing).
    pub(crate) fn of(b: &Block) -> VBlock {
        VBlock {
            x: b.x,
            own: Own {
                lx: b.lx,
                inv_lx: b.inv_lx,
                ly_off: b.ly_off,
                ke: b.ke,
                comp: b.comp,
            },
            live: b.live,
            saturated: [0; W],
        }
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

impl Own<W> {
    /// Lane `l` alone.
    #[inline(always)]
    fn lane(&self, l: usize) -> Own<1> {
        let one = |v: V| Lanes([v.0[l]]);
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
}

impl Leads<W> {
    /// Each lane's leader: the lane before; the first lane's is `first`.
    #[inline(always)]
    fn shifted(&self, first: &Lead) -> Leads<W> {
        let sh = |v: V, c: f64| Lanes(std::array::from_fn(|i| if i == 0 { c } else { v.0[i - 1] }));
        Leads {
            p: [sh(self.p[0], first.p[0]), sh(self.p[1], first.p[1])],
            dp: [sh(self.dp[0], first.dp[0]), sh(self.dp[1], first.dp[1])],
            vd: sh(self.vd, first.vd),
            wd: sh(self.wd, first.wd),
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

/// The kinematic law and the speed limiter ([`crate::base::VelocityBase::limit`]:
/// `(v, ω)` scaled by `1 / max(|v|/v_max, |ω|/ω_max)` where that exceeds 1,
/// then clamped against the last bit of rounding).
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
    if !c.speed_limited {
        return Cmd {
            raw,
            cmd: raw,
            e,
            saturated: Mask([0; N]),
        };
    }
    let (av, aw) = (raw[0].abs(), raw[1].abs());
    let (mv, mw) = (Lanes::splat(c.max[0]), Lanes::splat(c.max[1]));
    let over = av.gt(mv) | aw.gt(mw);
    let k = Lanes::splat(1.0) / (av * c.inv_max[0]).max(aw * c.inv_max[1]);
    let clamp = |a: Lanes<N>, m: Lanes<N>| a.max(-m).min(m);
    let limited = [clamp(raw[0] * k, mv), clamp(raw[1] * k, mw)];
    Cmd {
        raw,
        cmd: [
            Lanes::select(over, limited[0], raw[0]),
            Lanes::select(over, limited[1], raw[1]),
        ],
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
/// at the base's speeds, the lags' accelerations after their limits.
#[inline(always)]
fn derivative(c: &VConsts, x: &[V; 5], (sin, cos): (V, V), cmd: &[V; 2]) -> [V; 5] {
    let [v, w] = speeds(c, x, cmd);
    let zero = V::splat(0.0);
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
    if c.acc_limited {
        let (ma, mb) = (V::splat(c.acc[0]), V::splat(c.acc[1]));
        let clamp = |a: V, m: V| a.max(-m).min(m);
        if c.accel == AccelLimit::Joint {
            let s = (dv.abs() * c.inv_acc[0])
                .max(dw.abs() * c.inv_acc[1])
                .max(V::splat(1.0));
            let k = V::splat(1.0) / s;
            (dv, dw) = (dv * k, dw * k);
        }
        (dv, dw) = (clamp(dv, ma), clamp(dw, mb));
    }
    [v * cos, v * sin, w, dv, dw]
}

/// The state after a step ([`crate::base::VelocityBase::settle`]), given the
/// command at its end.
#[inline(always)]
fn settle(c: &VConsts, x: &mut [V; 5], cmd: &[V; 2]) {
    let [v, w] = speeds(c, x, cmd);
    let clamp = |a: V, m: f64| a.max(V::splat(-m)).min(V::splat(m));
    x[3] = clamp(v, c.max[0]);
    x[4] = clamp(w, c.max[1]);
}

/// `x + d k` and the sines and cosines of its heading, turned from those of
/// `x` by `d[2] k` when that is small.
#[inline(always)]
fn turned(x: &[V; 5], (sin, cos): (V, V), d: &[V; 5], k: f64) -> ([V; 5], (V, V)) {
    let next: [V; 5] = std::array::from_fn(|i| x[i] + d[i] * k);
    let sc = (d[2] * k)
        .sin_cos_turned(sin, cos)
        .unwrap_or_else(|| next[2].sin_cos());
    (next, sc)
}

/// Lanes whose state is no longer finite.
#[inline(always)]
fn broken(x: &[V; 5], live: Mask<W>) -> Mask<W> {
    let ok = x[0].finite() & x[1].finite() & x[2].finite() & x[3].finite() & x[4].finite();
    !ok & live
}

/// How a block sees its leaders.
pub(crate) trait Leaders {
    /// `L_Y` when it depends on `lead` alone (a star: every agent follows
    /// it), to be shared by the stages that see the same leader.
    fn ly(c: &VConsts, own: &Own<W>, lead: &Lead) -> Option<V>;

    /// The block's command at state `x` (heading `sc`) when the first lane's
    /// leader is `lead` (at `L_Y = ly` when given), and the block's own last
    /// agent as a leader (a star's agents lead nobody: any value).
    fn command(
        c: &VConsts,
        own: &Own<W>,
        x: &[V; 5],
        sc: (V, V),
        lead: &Lead,
        ly: Option<V>,
    ) -> (Cmd<W>, Lead);
}

/// Every agent follows the virtual leader.
#[derive(Debug)]
pub(crate) struct Star;

/// Agent `i` follows agent `i − 1`.
#[derive(Debug)]
pub(crate) struct Chain;

impl Leaders for Star {
    #[inline(always)]
    fn ly(c: &VConsts, own: &Own<W>, lead: &Lead) -> Option<V> {
        Some(ly_of(c, own, &Leads::splat(lead)))
    }

    #[inline(always)]
    fn command(
        c: &VConsts,
        own: &Own<W>,
        x: &[V; 5],
        sc: (V, V),
        lead: &Lead,
        ly: Option<V>,
    ) -> (Cmd<W>, Lead) {
        let l = Leads::splat(lead);
        let ly = ly.unwrap_or_else(|| ly_of(c, own, &l));
        (command(c, own, x, sc, &l, ly), *lead)
    }
}

impl Leaders for Chain {
    #[inline(always)]
    fn ly(_: &VConsts, _: &Own<W>, _: &Lead) -> Option<V> {
        None
    }

    #[inline(always)]
    fn command(
        c: &VConsts,
        own: &Own<W>,
        x: &[V; 5],
        sc: (V, V),
        lead: &Lead,
        _: Option<V>,
    ) -> (Cmd<W>, Lead) {
        if c.lag[0] && c.lag[1] {
            // The leaders move at their states' speeds: one vector evaluation.
            let mine = Leads::robots(x, sc, [x[3], x[4]]);
            let l = mine.shifted(lead);
            return (
                command(c, own, x, sc, &l, ly_of(c, own, &l)),
                mine.lead(W - 1),
            );
        }
        // A leader moves at its command on an axis without lag: lane by lane.
        let zero = V::splat(0.0);
        let mut out = Cmd {
            raw: [zero; 2],
            cmd: [zero; 2],
            e: [zero; 2],
            saturated: Mask([0; W]),
        };
        let one = |v: V, i: usize| Lanes([v.0[i]]);
        let mut lead = *lead;
        for i in 0..W {
            let xi = x.map(|v| one(v, i));
            let sci = (one(sc.0, i), one(sc.1, i));
            let l = Leads::<1>::splat(&lead);
            let oi = own.lane(i);
            let k = command(c, &oi, &xi, sci, &l, ly_of(c, &oi, &l));
            let me = Leads::<1>::robots(&xi, sci, speeds(c, &xi, &k.cmd));
            lead = Lead {
                p: [me.p[0].0[0], me.p[1].0[0]],
                dp: [me.dp[0].0[0], me.dp[1].0[0]],
                vd: me.vd.0[0],
                wd: me.wd.0[0],
            };
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

/// The leaders of one tile: `first` at the first step's start; per step,
/// at stages 2, 3, 4 and at the step's end (the next step's start).
#[derive(Debug, Clone)]
pub(crate) struct Tile {
    pub(crate) first: Lead,
    pub(crate) steps: Vec<[Lead; 4]>,
}

impl Tile {
    pub(crate) fn new(len: usize) -> Tile {
        Tile {
            first: Lead::default(),
            steps: vec![[Lead::default(); 4]; len],
        }
    }
}

/// Where a block's last agent's motion goes (its followers' [`Tile`]).
pub(crate) trait Record {
    fn first(&mut self, l: Lead);
    fn put(&mut self, n: usize, s: usize, l: Lead);
}

/// A star's agents lead nobody.
impl Record for () {
    #[inline(always)]
    fn first(&mut self, _: Lead) {}
    #[inline(always)]
    fn put(&mut self, _: usize, _: usize, _: Lead) {}
}

impl Record for &mut Tile {
    #[inline(always)]
    fn first(&mut self, l: Lead) {
        self.first = l;
    }
    #[inline(always)]
    fn put(&mut self, n: usize, s: usize, l: Lead) {
        self.steps[n][s] = l;
    }
}

/// Advances blocks by `steps.len()` steps, each led by `first` and `steps`
/// (a star's blocks all by the reference; a chain passes one block at a time,
/// and `rec` takes its last agent's motion). Returns the first step and agent
/// (within `blocks`) whose state stopped being finite, if any.
#[inline(always)]
pub(crate) fn tile<L: Leaders, R: Record>(
    c: &VConsts,
    blocks: &mut [VBlock],
    first: &Lead,
    steps: &[[Lead; 4]],
    mut rec: R,
) -> Option<(usize, usize)> {
    let (h, dt, h6) = (0.5 * c.dt, c.dt, c.dt / 6.0);
    let mut broke: Option<(usize, usize)> = None;
    for (bi, b) in blocks.iter_mut().enumerate() {
        let own = &b.own;
        let mut x = b.x;
        let mut sc = x[2].sin_cos();
        let (mut cur, me) = L::command(c, own, &x, sc, first, L::ly(c, own, first));
        rec.first(me);
        for (n, leads) in steps.iter().enumerate() {
            // A star's leader is the same at stages 2 and 3, and at stage 4
            // and the step's end (`fill`): one `L_Y` each.
            let ly23 = L::ly(c, own, &leads[0]);
            let ly4 = L::ly(c, own, &leads[2]);
            for (s, m) in b.saturated.iter_mut().zip(cur.saturated.0) {
                *s += m & 1;
            }
            let k1 = derivative(c, &x, sc, &cur.cmd);
            let (x2, sc2) = turned(&x, sc, &k1, h);
            let (c2, me) = L::command(c, own, &x2, sc2, &leads[0], ly23);
            rec.put(n, 0, me);
            let k2 = derivative(c, &x2, sc2, &c2.cmd);
            let (x3, sc3) = turned(&x, sc, &k2, h);
            let (c3, me) = L::command(c, own, &x3, sc3, &leads[1], ly23);
            rec.put(n, 1, me);
            let k3 = derivative(c, &x3, sc3, &c3.cmd);
            let (x4, sc4) = turned(&x, sc, &k3, dt);
            let (c4, me) = L::command(c, own, &x4, sc4, &leads[2], ly4);
            rec.put(n, 2, me);
            let k4 = derivative(c, &x4, sc4, &c4.cmd);
            x = std::array::from_fn(|i| x[i] + (k1[i] + (k2[i] + k3[i]) * 2.0 + k4[i]) * h6);
            sc = x[2].sin_cos();
            let (next, me) = L::command(c, own, &x, sc, &leads[3], ly4);
            rec.put(n, 3, me);
            cur = next;
            settle(c, &mut x, &cur.cmd);
            let bad = broken(&x, b.live);
            if bad.any() {
                let lane = bad.0.iter().position(|&m| m != 0).unwrap_or(0);
                let at = (n, bi * W + lane);
                broke = Some(broke.map_or(at, |f| f.min(at)));
                break;
            }
        }
        b.x = x;
    }
    broke
}

/// The blocks' commands at their current state; `first` leads the first
/// block (and, in a chain, each block the next).
pub(crate) fn probe<L: Leaders>(
    c: &VConsts,
    blocks: &[VBlock],
    mut first: Lead,
    out: &mut Vec<Cmd<W>>,
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
    /// refusing an impossible base ([`VelocityBase::validate`]), a step that
    /// is not a finite number > 0 or one longer than a lag
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
        base.validate().map_err(param("base"))?;
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

/// A formation of velocity-controlled bases under the kinematic law, stepped
/// in blocks of lanes: the [`Engine`](super::Engine) of velocity bases (see
/// the [module docs](self)). Same stepping rules as the torque engine (RK4,
/// the law in every stage, leaders first, no allocation while stepping, the
/// same bits on any number of threads); a chain runs on one thread.
#[derive(Debug, Clone)]
pub struct VelocityEngine {
    c: VConsts,
    topology: Topology,
    reference: Reference,
    n: usize,
    step: u64,
    blocks: Vec<VBlock>,
    /// The reference over a tile, and a chain's two tiles of leaders.
    tiles: [Tile; 3],
    failed: Option<SimError>,
    arch: Arch,
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
            lag: [b.tau_v > 0.0, b.tau_omega > 0.0],
            inv_tau: [b.tau_v, b.tau_omega].map(|t| if t > 0.0 { 1.0 / t } else { 0.0 }),
            max: [b.v_max, b.omega_max],
            inv_max: [inv(b.v_max), inv(b.omega_max)],
            speed_limited: b.v_max.is_finite() || b.omega_max.is_finite(),
            acc: [b.a_max, b.alpha_max],
            inv_acc: [inv(b.a_max), inv(b.alpha_max)],
            acc_limited: b.a_max.is_finite() || b.alpha_max.is_finite(),
            accel: b.accel,
        };
        let tile = Tile::new(TILE);
        Ok(VelocityEngine {
            c,
            topology: batch.topology,
            reference: batch.reference,
            n,
            step: 0,
            blocks: blocks.iter().map(VBlock::of).collect(),
            tiles: [tile.clone(), tile.clone(), tile],
            failed: None,
            arch: Arch::new(),
        })
    }

    /// Number of agents.
    pub fn len(&self) -> usize {
        self.n
    }

    /// Whether there are no agents (never: an empty batch is refused).
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// Who follows whom.
    pub fn topology(&self) -> Topology {
        self.topology
    }

    /// RK4 step, s.
    pub fn dt(&self) -> f64 {
        self.c.dt
    }

    /// Steps taken.
    pub fn step_index(&self) -> u64 {
        self.step
    }

    /// Current time, s (`step · dt`).
    pub fn time(&self) -> f64 {
        self.step as f64 * self.c.dt
    }

    /// Bytes per agent of state, constants and saturation counts.
    pub const BLOCK_BYTES_PER_AGENT: usize = size_of::<VBlock>() / W;

    /// Heap bytes per agent: blocks plus the fixed work space spread over
    /// the agents.
    pub fn bytes_per_agent(&self) -> f64 {
        let tiles: usize = self
            .tiles
            .iter()
            .map(|t| t.steps.capacity() * size_of::<[Lead; 4]>())
            .sum();
        (self.blocks.capacity() * size_of::<VBlock>() + tiles) as f64 / self.n as f64
    }

    /// Agent `i`'s state (after [`crate::base::VelocityBase::settle`]).
    pub fn state(&self, i: usize) -> State {
        let b = &self.blocks[i / W];
        let l = i % W;
        State {
            x: b.x[0].0[l],
            y: b.x[1].0[l],
            theta: b.x[2].0[l],
            v: b.x[3].0[l],
            omega: b.x[4].0[l],
        }
    }

    /// Every agent's state.
    pub fn states(&self) -> Vec<State> {
        (0..self.n).map(|i| self.state(i)).collect()
    }

    /// Agent `i`'s number of steps whose command (at the step's start)
    /// exceeded a speed limit.
    pub fn saturated_ticks(&self, i: usize) -> u64 {
        self.blocks[i / W].saturated[i % W]
    }

    /// Every agent's laws at the current state, computed by the engine's own
    /// kernel.
    pub fn probes(&self) -> Vec<VelocityProbe> {
        let first = Lead::reference(&self.reference.eval(self.time(), Order::Two));
        let mut cmds = Vec::with_capacity(self.blocks.len());
        match self.topology {
            Topology::Star => probe::<Star>(&self.c, &self.blocks, first, &mut cmds),
            Topology::Chain => probe::<Chain>(&self.c, &self.blocks, first, &mut cmds),
        }
        let mut out: Vec<VelocityProbe> = cmds
            .iter()
            .flat_map(|k| {
                (0..W).map(move |l| VelocityProbe {
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
            .collect();
        out.truncate(self.n);
        out
    }

    /// One RK4 step.
    pub fn step(&mut self) -> Result<(), SimError> {
        self.run(1)
    }

    /// `steps` RK4 steps, the law in every stage. A star spreads its blocks
    /// over the current rayon pool; the result is the same bits on any number
    /// of threads, and the same as `steps` calls of
    /// [`VelocityEngine::step`]. Fails when a state stops being finite; the
    /// engine then stays failed.
    pub fn run(&mut self, steps: u64) -> Result<(), SimError> {
        if let Some(e) = &self.failed {
            return Err(e.clone());
        }
        let mut left = steps;
        while left > 0 {
            let len = left.min(TILE as u64) as usize;
            let [r, a, b] = &mut self.tiles;
            fill(r, len, &self.reference, self.step, self.c.dt);
            let broke = match self.topology {
                Topology::Star => star(self.arch, &self.c, &mut self.blocks, r, len),
                Topology::Chain => chain(self.arch, &self.c, &mut self.blocks, [r, a, b], len),
            };
            if let Some((n, agent)) = broke {
                let e = SimError::NonFinite {
                    agent: agent + 1,
                    t: (self.step + n as u64 + 1) as f64 * self.c.dt,
                };
                self.failed = Some(e.clone());
                return Err(e);
            }
            self.step += len as u64;
            left -= len as u64;
        }
        Ok(())
    }
}

/// The reference over the tile's `len` steps from `step0`: at `t_n` for the
/// first step's start, then per step at `t_n + dt/2` (stages 2 and 3) and
/// `t_{n+1}` (stage 4 and the step's end), as the torque engine's
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

/// A tile of blocks for [`Arch::dispatch`].
struct Run<'a, L, R> {
    c: &'a VConsts,
    blocks: &'a mut [VBlock],
    first: &'a Lead,
    steps: &'a [[Lead; 4]],
    rec: R,
    leaders: PhantomData<L>,
}

impl<L: Leaders, R: Record> WithSimd for Run<'_, L, R> {
    type Output = Option<(usize, usize)>;
    #[inline(always)]
    fn with_simd<S: Simd>(self, _: S) -> Self::Output {
        tile::<L, R>(self.c, self.blocks, self.first, self.steps, self.rec)
    }
}

/// A star's tile, over the current rayon pool; the earliest broken
/// `(step, agent)`.
fn star(
    arch: Arch,
    c: &VConsts,
    blocks: &mut [VBlock],
    r: &Tile,
    len: usize,
) -> Option<(usize, usize)> {
    let run = |blocks: &mut [VBlock]| {
        arch.dispatch(Run::<Star, ()> {
            c,
            blocks,
            first: &r.first,
            steps: &r.steps[..len],
            rec: (),
            leaders: PhantomData,
        })
    };
    if rayon::current_num_threads() <= 1 || blocks.len() <= PAR_BLOCKS {
        return run(blocks);
    }
    blocks
        .par_chunks_mut(PAR_BLOCKS)
        .enumerate()
        .filter_map(|(i, chunk)| run(chunk).map(|(n, a)| (n, i * PAR_BLOCKS * W + a)))
        .min()
}

/// A chain's tile, block after block, each led by the one before (the
/// reference, then two tiles taking turns); the earliest broken
/// `(step, agent)`.
fn chain(
    arch: Arch,
    c: &VConsts,
    blocks: &mut [VBlock],
    [r, a, b]: [&mut Tile; 3],
    len: usize,
) -> Option<(usize, usize)> {
    let mut first: Option<(usize, usize)> = None;
    let mut steps = len;
    let (mut from, mut to): (&mut Tile, &mut Tile) = (a, b);
    for (bi, block) in blocks.chunks_mut(1).enumerate() {
        let lead: &Tile = if bi == 0 { r } else { from };
        let broke = arch.dispatch(Run::<Chain, &mut Tile> {
            c,
            blocks: block,
            first: &lead.first,
            steps: &lead.steps[..steps],
            rec: &mut *to,
            leaders: PhantomData,
        });
        if let Some((n, l)) = broke {
            // Later agents may break earlier: run them up to this step.
            let at = (n, bi * W + l);
            first = Some(first.map_or(at, |f| f.min(at)));
            steps = n + 1;
        }
        std::mem::swap(&mut from, &mut to);
    }
    first
}
