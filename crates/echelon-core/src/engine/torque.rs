//! The torque [`Kernel`]: the law of eqs. 7–13 on the dynamic model (eq. 3)
//! in lanes, a star's blocks and a chain's through `kernel.rs`'s tiles.

use std::fmt::Debug;

use pulp::{Arch, Simd, WithSimd};

use crate::model::State;
use crate::reference::{Order, Reference, Trajectory};

use super::kernel::Probe;
use super::kernel::{Block, Carry, Consts, Scratch, W};
use super::{Kernel, SEGMENT, Topology, fill_reference};
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
