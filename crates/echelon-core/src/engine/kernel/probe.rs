//! The law's outputs of a block at its current state (what the engine
//! reports at a probe), star and chain.

use crate::law::control::{Body, law_finish, law_partial};
use crate::math::lanes::Lanes;

use super::{
    Block, Carry, Consts, Leaders, Scratch, V, W, chain_stage, hold, shift_in, star_ly, star_stage,
};

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
