//! A star block's stage and tile: every agent follows the reference.

use crate::law::control::{Body, law_finish, law_partial};

use super::{
    Block, Carry, Consts, V, W, actuate, broken, combine, each, first_lane, hold_ly, star_ly,
    turned_state, vectors,
};

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
            vectors(&mut x);
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
