//! A chain block's stage and tile: agent `i` follows agent `i − 1`, the
//! accelerations solved as a recurrence `v̇ᵢ = αᵢ + βᵢ v̇ᵢ₋₁` (the law is affine
//! in the leader's acceleration).

use crate::control::{Body, law_finish, law_partial, robot_leader};
use crate::lanes::Lanes;

use super::{Aff, Block, Carry, Consts, Stages, V, W, broken, first_lane, hold, rk4_step};

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
pub(super) struct Leaders {
    pub(super) p: [V; 2],
    pub(super) dp: [V; 2],
    pub(super) q: [V; 2],
    pub(super) g: [V; 2],
    pub(super) vd: V,
    pub(super) wd: V,
}

impl Leaders {
    /// Robots at `x` with heading `(sin, cos)` as leaders:
    /// `LeaderMotion::of_robot` and `Placement::offset_for_robot`'s
    /// `(max(v, 0), ω)`.
    #[inline(always)]
    pub(super) fn of(x: &[V; 5], sin: V, cos: V) -> Leaders {
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
    pub(super) fn splat(c: &Carry) -> Leaders {
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
    pub(super) fn shifted(&self, prev: &Leaders) -> Leaders {
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

/// One stage of a chain block at state `x` (heading `(sin, cos)`) whose
/// first agent follows `carry`: the derivative of every lane, and `carry`
/// replaced by the block's last agent as a leader (with its `v̇`), the next
/// block's first agent's leader. Vectorised except for `v̇ᵢ = αᵢ + βᵢ v̇ᵢ₋₁`,
/// one multiply-add per agent in order.
#[inline(always)]
pub(crate) fn chain_stage(
    c: &Consts,
    b: &Block,
    x: &[V; 5],
    (sin, cos): (V, V),
    carry: &mut Carry,
) -> [V; 5] {
    let own = Leaders::of(x, sin, cos);
    let leaders = own.shifted(&Leaders::splat(carry));
    let (dv, dw) = chain_block(c, b, x, sin, cos, &leaders);
    // The only sequential part: each v̇ needs the one before.
    let lead = carry.dv;
    let mut dvl = lead;
    let mut acc = [0.0; W];
    for (l, d) in acc.iter_mut().enumerate() {
        dvl = dv.a.0[l] + dv.b.0[l] * dvl;
        *d = dvl;
    }
    let acc = Lanes(acc);
    *carry = own.last();
    carry.dv = dvl;
    [
        x[3] * cos,
        x[3] * sin,
        x[4],
        acc,
        dw.a + dw.b * shift_in(acc, lead),
    ]
}

/// A chain block's stages at one step: its first agent's leader at each,
/// replaced by its last agent.
struct ChainStages<'a> {
    c: &'a Consts,
    b: &'a Block,
    stages: &'a mut [Carry; 4],
}

impl Stages for ChainStages<'_> {
    #[inline(always)]
    fn stage(&mut self, s: usize, x: &[V; 5], sc: (V, V)) -> [V; 5] {
        chain_stage(self.c, self.b, x, sc, &mut self.stages[s])
    }
}

/// Advances chain blocks by `carries.len()` steps. `carries[n][s]` is the
/// leader of the first block's first agent at step `n`, stage `s`, and is
/// replaced by the last block's last agent (the next segment's leader).
///
/// Block after block, each running all its steps in registers as a star's
/// does: a block at step `n` needs only the block before at step `n` (its
/// last agent, at each stage, is what `carries[n]` holds when the block
/// reads it) and itself at step `n − 1`. Every agent computes exactly what a
/// stage-by-stage walk over all blocks computes. Returns the first broken
/// step and agent (within `blocks`), if any; the blocks after a broken one
/// stop at its step.
#[inline(always)]
pub(crate) fn chain_tile(
    c: &Consts,
    blocks: &mut [Block],
    carries: &mut [[Carry; 4]],
) -> Option<(usize, usize)> {
    let mut first: Option<(usize, usize)> = None;
    let mut steps = carries.len();
    for (bi, b) in blocks.iter_mut().enumerate() {
        let mut x = b.x;
        for (n, stages) in carries[..steps].iter_mut().enumerate() {
            x = rk4_step(&x, c.dt, &mut ChainStages { c, b, stages });
            let bad = broken(&x, b.live);
            if bad.any() {
                let at = (n, bi * W + first_lane(bad));
                first = Some(first.map_or(at, |f| f.min(at)));
                steps = n + 1;
                break;
            }
        }
        b.x = x;
    }
    first
}
