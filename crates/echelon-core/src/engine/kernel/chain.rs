//! A chain block's stage and tile: agent `i` follows agent `i − 1`, the
//! accelerations solved as a recurrence `v̇ᵢ = αᵢ + βᵢ v̇ᵢ₋₁` (the law is affine
//! in the leader's acceleration).

use crate::law::control::{Body, law_finish, law_partial, robot_leader};
use crate::math::lanes::Lanes;

use super::{
    Aff, Block, Carry, Consts, V, W, add_scaled, broken, combine, each, first_lane, hold,
    sin_cos_cold,
};

/// Per-block work space of a chain stage.
#[derive(Debug, Clone, Copy)]
pub struct Scratch {
    /// This stage's derivative (the previous stage's until overwritten).
    pub(super) k: [V; 5],
    pub(super) k1: [V; 5],
    /// `k₂ + k₃`.
    pub(super) k23: [V; 5],
    /// `v̇ = α + β v̇_L`, `ω̇ = γ + δ v̇_L`.
    pub(super) dv: Aff,
    pub(super) dw: Aff,
    /// `sin θ`, `cos θ` at stage 1 (stages 2–4 turn them).
    pub(super) sc1: (V, V),
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
            sc1: (z, z),
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

/// The chain stage update coefficients: stage `s` evaluates at `x + a_s k_{s−1}`.
#[inline(always)]
fn stage_state(b: &Block, sc: &Scratch, s: usize, dt: f64) -> [V; 5] {
    match s {
        0 => b.x,
        3 => add_scaled(&b.x, &sc.k, dt),
        _ => add_scaled(&b.x, &sc.k, 0.5 * dt),
    }
}

/// `sin θ`, `cos θ` of stage `s`'s state `x`: stage 1's from
/// [`Lanes::sin_cos`] (kept in the scratch), stages 2–4's turned from them by
/// the stage's `δθ` ([`V::sin_cos_turned`], as a star's stages are; out of line
/// when some lane turns by 0.05 rad or more).
#[inline(always)]
fn stage_sin_cos(sc: &mut Scratch, x: &[V; 5], s: usize, dt: f64) -> (V, V) {
    let a = match s {
        0 => {
            sc.sc1 = x[2].sin_cos();
            return sc.sc1;
        }
        3 => dt,
        _ => 0.5 * dt,
    };
    // The `δθ` that `stage_state` added to θ.
    match (sc.k[2] * a).sin_cos_turned(sc.sc1.0, sc.sc1.1) {
        Some(turned) => turned,
        None => sin_cos_cold(x[2]),
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
        let (sin, cos) = stage_sin_cos(sc, &x, s, c.dt);
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
