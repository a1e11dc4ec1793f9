//! The torque [`Kernel`]: the law of eqs. 7–13 on the dynamic model (eq. 3)
//! in lanes, a star's blocks and a chain's through `kernel.rs`'s tiles.

use std::fmt::Debug;

use pulp::{Arch, Simd, WithSimd};

use crate::model::State;
use crate::reference::{Order, Reference, Trajectory};

use super::kernel::Probe;
use super::kernel::{Block, Carry, Consts, Scratch, W};
use super::{Columns, Kernel, PAR_BLOCKS, SEGMENT, Topology, fill_reference};
use super::{kernel, sealed};

/// The torque kernel: robots of eq. 3 under the dynamic law (eqs. 7–13).
#[derive(Debug, Clone, Copy)]
pub enum Torque {}

/// A star tile's work for [`Arch::dispatch`]: compiled once per instruction
/// set (the kernel is inlined into each), run with the best this CPU has.
struct StarTile<'a> {
    c: &'a Consts,
    blocks: &'a mut [Block],
    refs: &'a [[Carry; 4]],
}

impl WithSimd for StarTile<'_> {
    type Output = Option<(usize, usize)>;
    #[inline(always)]
    fn with_simd<S: Simd>(self, _: S) -> Self::Output {
        kernel::star_tile(self.c, self.blocks, self.refs)
    }
}

/// A chain segment's tile for [`Arch::dispatch`].
struct ChainTile<'a> {
    c: &'a Consts,
    blocks: &'a mut [Block],
    scratch: &'a mut [Scratch],
    carries: &'a mut [[Carry; 4]],
}

impl WithSimd for ChainTile<'_> {
    type Output = Option<(usize, usize)>;
    #[inline(always)]
    fn with_simd<S: Simd>(self, _: S) -> Self::Output {
        kernel::chain_tile(self.c, self.blocks, self.scratch, self.carries)
    }
}

impl sealed::Sealed for Torque {}

impl Kernel for Torque {
    type Probe = Probe;
    type Consts = Consts;
    type Block = Block;
    type Scratch = Scratch;
    /// Per step, the leader at the four stages.
    type Tile = Vec<[Carry; 4]>;
    const LANES: usize = W;
    const SEGMENT: usize = SEGMENT;

    fn dt(c: &Consts) -> f64 {
        c.dt
    }

    fn state(b: &Block, l: usize) -> State {
        kernel::state_of(&b.x, l)
    }

    fn x_mut(b: &mut Block) -> &mut [kernel::V; 5] {
        &mut b.x
    }

    fn tile(steps: usize) -> Vec<[Carry; 4]> {
        vec![[Carry::default(); 4]; steps]
    }

    fn tile_bytes(t: &Vec<[Carry; 4]>) -> usize {
        t.capacity() * size_of::<[Carry; 4]>()
    }

    fn fill(t: &mut Vec<[Carry; 4]>, len: usize, reference: &Reference, step0: u64, dt: f64) {
        fill_reference(&mut t[..len], reference, step0, dt);
    }

    fn star(
        arch: Arch,
        c: &Consts,
        blocks: &mut [Block],
        t: &Vec<[Carry; 4]>,
        len: usize,
    ) -> Option<(usize, usize)> {
        arch.dispatch(StarTile {
            c,
            blocks,
            refs: &t[..len],
        })
    }

    fn chain(
        arch: Arch,
        c: &Consts,
        blocks: &mut [Block],
        scratch: &mut [Scratch],
        t: &mut Vec<[Carry; 4]>,
        len: usize,
    ) -> Option<(usize, usize)> {
        let scratch = &mut scratch[..blocks.len()];
        arch.dispatch(ChainTile {
            c,
            blocks,
            scratch,
            carries: &mut t[..len],
        })
    }

    fn probes(
        c: &Consts,
        topology: Topology,
        blocks: &[Block],
        reference: &Reference,
        t: f64,
    ) -> Vec<Probe> {
        let r = Carry::reference(&reference.eval(t, Order::Two));
        let mut out = Vec::with_capacity(blocks.len() * W);
        match topology {
            Topology::Star => kernel::star_probe(c, blocks, &r, &mut out),
            Topology::Chain => {
                let mut scratch = vec![Scratch::default(); blocks.len()];
                kernel::chain_probe(c, blocks, &mut scratch, &r, &mut out);
            }
        }
        out
    }
}

/// A star's tile, its blocks spread over the current rayon pool; the
/// earliest broken `(step, agent)`. With `cols`, the state is the caller's:
/// each task loads its blocks' lanes from the columns before its tile and
/// stores them back after it (once per tile of up to 64 steps; the blocks
/// keep a working copy, as they keep their own state without `cols`).
pub(super) fn star<K: Kernel>(
    arch: Arch,
    c: &K::Consts,
    blocks: &mut [K::Block],
    mut cols: Option<Columns<'_>>,
    t: &K::Tile,
    len: usize,
) -> Option<(usize, usize)> {
    if rayon::current_num_threads() <= 1 || blocks.len() <= PAR_BLOCKS {
        if let Some(cols) = &cols {
            cols.load::<K>(blocks);
        }
        let broke = K::star(arch, c, blocks, t, len);
        if let Some(cols) = &mut cols {
            cols.store::<K>(blocks);
        }
        return broke;
    }
    // Halves on whole tasks of `PAR_BLOCKS` blocks (what `par_chunks_mut`
    // does, with the columns split at the same agents).
    let mid = (blocks.len() / 2).div_ceil(PAR_BLOCKS) * PAR_BLOCKS;
    let (front, back) = blocks.split_at_mut(mid);
    let (cf, cb) = match cols {
        Some(cols) => {
            let (f, b) = cols.split_at(mid * K::LANES);
            (Some(f), Some(b))
        }
        None => (None, None),
    };
    let (a, b) = rayon::join(
        || star::<K>(arch, c, front, cf, t, len),
        || star::<K>(arch, c, back, cb, t, len),
    );
    let b = b.map(|(n, agent)| (n, mid * K::LANES + agent));
    match (a, b) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    }
}

/// A chain's tile, segment after segment, each led by the one before
/// through `t`; the earliest broken `(step, agent)`.
pub(super) fn chain<K: Kernel>(
    arch: Arch,
    c: &K::Consts,
    blocks: &mut [K::Block],
    scratch: &mut [K::Scratch],
    t: &mut K::Tile,
    len: usize,
) -> Option<(usize, usize)> {
    let mut first: Option<(usize, usize)> = None;
    let mut steps = len;
    for (si, seg) in blocks.chunks_mut(K::SEGMENT).enumerate() {
        if let Some((n, a)) = K::chain(arch, c, seg, scratch, t, steps) {
            // Later agents may break earlier: run them up to this step.
            let at = (n, si * K::SEGMENT * K::LANES + a);
            first = Some(first.map_or(at, |f| f.min(at)));
            steps = n + 1;
        }
    }
    first
}
