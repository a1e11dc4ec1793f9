//! A block's tile of steps: who leads whom ([`Leaders`]: a star or a
//! chain), the RK4 stages, and the blocks of a tile in turn.

use std::marker::PhantomData;

use pulp::{Simd, WithSimd};

use crate::engine::kernel::{broken, first_lane, turned_state};
use crate::math::lanes::{Lanes, Mask};

use super::{
    Cmd, Lead, Leads, Own, V4, VBlock, VConsts, VW, command, derivative, ly_of, settle, speeds,
    vectors,
};

/// How a block sees its leaders.
pub(crate) trait Leaders {
    /// `L_Y` when it depends on `lead` alone (a star: every agent follows
    /// it), to be shared by the stages that see the same leader.
    fn ly(c: &VConsts, own: &Own<VW>, lead: &Lead) -> Option<V4>;

    /// The leaders of the block's lanes at state `x` (heading `sc`) when the
    /// first lane's leader is `lead`, and the block's own last agent as a
    /// leader (a star's agents lead nobody: any value); `None` when a lane's
    /// leader depends on the command of the lane before (then
    /// [`Leaders::command`] goes lane by lane).
    fn leads(c: &VConsts, x: &[V4; 5], sc: (V4, V4), lead: &Lead) -> Option<(Leads<VW>, Lead)>;

    /// The block's command at state `x` (heading `sc`) when the first lane's
    /// leader is `lead` (at `L_Y = ly` when given), and the block's own last
    /// agent as a leader.
    #[inline(always)]
    fn command(
        c: &VConsts,
        own: &Own<VW>,
        x: &[V4; 5],
        sc: (V4, V4),
        lead: &Lead,
        ly: Option<V4>,
    ) -> (Cmd<VW>, Lead) {
        match Self::leads(c, x, sc, lead) {
            Some((l, me)) => {
                let ly = ly.unwrap_or_else(|| ly_of(c, own, &l));
                (command(c, own, x, sc, &l, ly), me)
            }
            None => lane_by_lane(c, own, x, sc, lead),
        }
    }
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
    fn leads(_: &VConsts, _: &[V4; 5], _: (V4, V4), lead: &Lead) -> Option<(Leads<VW>, Lead)> {
        Some((Leads::splat(lead), *lead))
    }
}

impl Leaders for Chain {
    #[inline(always)]
    fn ly(_: &VConsts, _: &Own<VW>, _: &Lead) -> Option<V4> {
        None
    }

    #[inline(always)]
    fn leads(c: &VConsts, x: &[V4; 5], sc: (V4, V4), lead: &Lead) -> Option<(Leads<VW>, Lead)> {
        // The leaders move at their states' speeds: one vector evaluation.
        // A leader moves at its command on an axis without lag: lane by lane.
        (c.lag[0] && c.lag[1]).then(|| {
            let mine = Leads::robots(x, sc, [x[3], x[4]]);
            (mine.shifted(lead), mine.lead(VW - 1))
        })
    }
}

/// A chain's command when a leader moves at its command (an axis without
/// lag): each lane's leader is the lane before, at the speeds its command
/// gives.
#[inline(always)]
fn lane_by_lane(
    c: &VConsts,
    own: &Own<VW>,
    x: &[V4; 5],
    sc: (V4, V4),
    lead: &Lead,
) -> (Cmd<VW>, Lead) {
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
        let (x2, sc2) = turned_state(&x, sc, &k1, h);
        let (c2, me) = L::command(c, own, &x2, sc2, &leads[0], ly23);
        t.put(n, 0, me);
        let k2 = derivative(c, &x2, sc2, &c2.cmd);
        let (x3, sc3) = turned_state(&x, sc, &k2, h);
        let (c3, me) = L::command(c, own, &x3, sc3, &leads[1], ly23);
        t.put(n, 1, me);
        let k3 = derivative(c, &x3, sc3, &c3.cmd);
        let (x4, sc4) = turned_state(&x, sc, &k3, dt);
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

/// A tile of blocks for [`Arch::dispatch`].
pub(super) struct Run<'a, L, T> {
    pub(super) c: &'a VConsts,
    pub(super) blocks: &'a mut [VBlock],
    pub(super) t: T,
    pub(super) len: usize,
    pub(super) leaders: PhantomData<L>,
}

impl<L: Leaders, T: Stages> WithSimd for Run<'_, L, T> {
    type Output = Option<(usize, usize)>;
    #[inline(always)]
    fn with_simd<S: Simd>(self, _: S) -> Self::Output {
        blocks_tile::<L, T>(self.c, self.blocks, self.t, self.len)
    }
}
