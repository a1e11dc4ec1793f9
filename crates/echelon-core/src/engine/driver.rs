//! The [`BatchEngine`] driver over any [`Kernel`]: the tile loop with the
//! reference filled once per tile, a star's blocks over the pool, a chain
//! segment by segment; and packing the members into blocks of lanes.

use pulp::Arch;
use rayon::prelude::*;

use crate::error::Breach;
use crate::error::SimError;
use crate::law::lycomp::{LyComp, OffsetFrame};
use crate::math::lanes::{Lanes, Mask};
use crate::model::State;
use crate::reference::{Order, Reference, Trajectory};
use crate::sim::guard::Bounds;

use super::kernel::{Block, Carry, V, W};
use super::{BatchEngine, EngineError, Kernel, Member, PAR_BLOCKS, SEGMENT, TILE, Topology};

impl<K: Kernel> BatchEngine<K> {
    /// An engine at step 0 with its work space.
    pub(super) fn assemble(
        consts: K::Consts,
        topology: Topology,
        reference: Reference,
        blocks: Vec<K::Block>,
        n: usize,
    ) -> BatchEngine<K> {
        let chain = topology == Topology::Chain;
        let scratch = match chain {
            true => vec![K::Scratch::default(); blocks.len().min(2 * K::SEGMENT)],
            false => Vec::new(),
        };
        BatchEngine {
            consts,
            topology,
            reference,
            n,
            step: 0,
            blocks,
            tiles: [K::tile(TILE), K::tile(if chain { TILE } else { 0 })],
            scratch,
            failed: None,
            arch: Arch::new(),
        }
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
        K::dt(&self.consts)
    }

    /// Steps taken.
    pub fn step_index(&self) -> u64 {
        self.step
    }

    /// Current time, s (`step · dt`, as the scalar simulator counts).
    pub fn time(&self) -> f64 {
        self.step as f64 * self.dt()
    }

    /// Heap bytes per agent: states and per-agent constants, plus the fixed
    /// work space spread over the agents.
    pub fn bytes_per_agent(&self) -> f64 {
        let bytes = self.blocks.capacity() * size_of::<K::Block>()
            + self.tiles.iter().map(K::tile_bytes).sum::<usize>()
            + self.scratch.capacity() * size_of::<K::Scratch>();
        bytes as f64 / self.n as f64
    }

    /// Bytes per agent of state and constants alone (what grows with `N`).
    pub const BLOCK_BYTES_PER_AGENT: usize = size_of::<K::Block>() / K::LANES;

    /// Agent `i`'s state.
    pub fn state(&self, i: usize) -> State {
        K::state(&self.blocks[i / K::LANES], i % K::LANES)
    }

    /// Every agent's state.
    pub fn states(&self) -> Vec<State> {
        (0..self.n).map(|i| self.state(i)).collect()
    }

    /// Every agent's controller at the current state, computed by the
    /// engine's own kernels.
    pub fn probes(&self) -> Vec<K::Probe> {
        let mut out = K::probes(
            &self.consts,
            self.topology,
            &self.blocks,
            &self.reference,
            self.time(),
        );
        out.truncate(self.n);
        out
    }

    /// One RK4 step.
    pub fn step(&mut self) -> Result<(), SimError> {
        self.run(1)
    }

    /// Every agent's state as five columns of [`len`](Self::len) values
    /// (x, y, θ, v, ω: column `q` at `q n .. (q + 1) n`), the layout of
    /// [`BatchEngine::run_on`]'s buffer.
    pub fn columns(&self) -> Vec<f64> {
        let n = self.n;
        let mut out = vec![0.0; 5 * n];
        for (i, s) in self.states().iter().enumerate() {
            for (q, v) in [s.x, s.y, s.theta, s.v, s.omega].into_iter().enumerate() {
                out[q * n + i] = v;
            }
        }
        out
    }

    /// `steps` RK4 steps of the states in `state`, a buffer the caller owns
    /// (five columns of `n`, as [`BatchEngine::columns`] lays them out), in
    /// place: the same computation as [`BatchEngine::run`] with the state
    /// read from and written to the caller's memory (a star's blocks load
    /// their lanes at the start of each tile of up to 64 steps and store them
    /// at its end, in the task that steps them; a chain at the call's start
    /// and end), no allocation. Afterwards the engine's own states
    /// ([`BatchEngine::state`], [`BatchEngine::probes`]) are `state`'s too.
    ///
    /// A buffer of the wrong length, or holding a value that is not finite,
    /// is refused ([`EngineError::Buffer`]) and nothing changes, neither the
    /// buffer nor the engine.
    pub fn run_on(&mut self, state: &mut [f64], steps: u64) -> Result<(), EngineError> {
        let n = self.n;
        if state.len() != 5 * n {
            return Err(EngineError::Buffer(format!(
                "{} values, expected 5 × {n} (columns x, y, θ, v, ω of {n} agents)",
                state.len()
            )));
        }
        // A branch-free pass (it vectorises); the first bad value only if any.
        let finite = state.iter().fold(true, |ok, v| ok & v.is_finite());
        if let Some(k) = (!finite)
            .then(|| state.iter().position(|v| !v.is_finite()))
            .flatten()
        {
            return Err(EngineError::Buffer(format!(
                "{} of agent {} is {} (must be finite)",
                ["x", "y", "θ", "v", "ω"][k / n],
                k % n + 1,
                state[k]
            )));
        }
        if let Some(e) = &self.failed {
            return Err(e.clone().into());
        }
        let mut cols = Columns::new(state, n);
        let broke = match self.topology {
            Topology::Star => self.run_tiles(steps, Some(cols)),
            Topology::Chain => {
                cols.load::<K>(&mut self.blocks);
                let broke = self.run_chain(steps);
                cols.store::<K>(&mut self.blocks);
                broke
            }
        };
        Ok(self.fail_at(broke)?)
    }

    /// `steps` RK4 steps, the law in every stage. A star spreads its blocks,
    /// a chain of 512 agents or more its two halves, over the current rayon
    /// pool (`pool.install(|| engine.run(n))`); the
    /// result is the same bits on any number of threads, and the same as
    /// `steps` calls of [`BatchEngine::step`]. Fails like the scalar simulator
    /// when a state stops being finite; the engine then stays failed.
    pub fn run(&mut self, steps: u64) -> Result<(), SimError> {
        if let Some(e) = &self.failed {
            return Err(e.clone());
        }
        let broke = match self.topology {
            Topology::Star => self.run_tiles(steps, None),
            Topology::Chain => self.run_chain(steps),
        };
        self.fail_at(broke)
    }

    /// A chain's `steps` steps: as two halves on two threads when it is long
    /// and the pool has them.
    fn run_chain(&mut self, steps: u64) -> Option<(u64, usize)> {
        if rayon::current_num_threads() >= 2 && self.blocks.len() * K::LANES >= 2 * SEGMENT * W {
            self.run_chain_on_two_cores(steps)
        } else {
            self.run_tiles(steps, None)
        }
    }

    /// The scalar simulator's error for the first broken `(step, agent)`, if
    /// any; the engine then stays failed.
    fn fail_at(&mut self, broke: Option<(u64, usize)>) -> Result<(), SimError> {
        if let Some((n, agent)) = broke {
            let state = self.state(agent);
            let e = SimError::Diverged {
                agent: agent + 1,
                name: format!("agent {}", agent + 1),
                t: (n + 1) as f64 * self.dt(),
                breach: Bounds::DEFAULT.check(&state).unwrap_or(Breach {
                    quantity: "state",
                    value: f64::NAN,
                    bound: f64::INFINITY,
                    unit: "",
                }),
            };
            self.failed = Some(e.clone());
            return Err(e);
        }
        Ok(())
    }

    /// `steps` steps a tile at a time; the first broken `(step, agent)`.
    /// With `cols` (a star only), the state is the caller's.
    fn run_tiles(&mut self, steps: u64, mut cols: Option<Columns<'_>>) -> Option<(u64, usize)> {
        let (arch, dt) = (self.arch, self.dt());
        let mut left = steps;
        while left > 0 {
            let len = left.min(TILE as u64) as usize;
            let tile = &mut self.tiles[0];
            K::fill(tile, len, &self.reference, self.step, dt);
            let c = &self.consts;
            let broke = match self.topology {
                Topology::Star => star::<K>(
                    arch,
                    c,
                    &mut self.blocks,
                    cols.as_mut().map(Columns::reborrow),
                    tile,
                    len,
                ),
                Topology::Chain => {
                    chain::<K>(arch, c, &mut self.blocks, &mut self.scratch, tile, len)
                }
            };
            if let Some((n, agent)) = broke {
                return Some((self.step + n as u64, agent));
            }
            self.step += len as u64;
            left -= len as u64;
        }
        None
    }

    /// A chain on two cores: the first half of the agents runs tile `m` while
    /// the second half runs tile `m − 1`, led by the first half's last agent
    /// as recorded in the previous tile (a wavefront; the two tile buffers
    /// swap each tile). Every agent computes exactly what it would on one
    /// core.
    fn run_chain_on_two_cores(&mut self, steps: u64) -> Option<(u64, usize)> {
        let split = self.blocks.len() / 2;
        let (arch, dt) = (self.arch, self.dt());
        let (c, reference) = (&self.consts, &self.reference);
        let (front, back) = self.blocks.split_at_mut(split);
        let (scratch_a, scratch_b) = self.scratch.split_at_mut(K::SEGMENT);
        let [x, y] = &mut self.tiles;
        let (mut x, mut y) = (x, y);
        // The tile waiting in `y` for the back half: (first step, length).
        let mut pending: Option<(u64, usize)> = None;
        let (mut step, mut left) = (self.step, steps);
        let mut broke: Option<(u64, usize)> = None;
        fn note(broke: &mut Option<(u64, usize)>, at: (u64, usize)) {
            *broke = Some(broke.map_or(at, |b| b.min(at)));
        }
        while left > 0 || pending.is_some() {
            let next = (left > 0).then(|| {
                let len = left.min(TILE as u64) as usize;
                K::fill(x, len, reference, step, dt);
                (step, len)
            });
            let (a, b) = rayon::join(
                || next.and_then(|(_, len)| chain::<K>(arch, c, front, scratch_a, x, len)),
                || pending.and_then(|(_, len)| chain::<K>(arch, c, back, scratch_b, y, len)),
            );
            if let (Some((n, agent)), Some((s0, _))) = (b, pending) {
                note(&mut broke, (s0 + n as u64, split * K::LANES + agent));
            }
            if let (Some((n, agent)), Some((s0, _))) = (a, next) {
                note(&mut broke, (s0 + n as u64, agent));
                // The back half may break earlier within this tile.
                if let Some((m, agent)) = chain::<K>(arch, c, back, scratch_b, x, n + 1) {
                    note(&mut broke, (s0 + m as u64, split * K::LANES + agent));
                }
            }
            if broke.is_some() {
                return broke;
            }
            std::mem::swap(&mut x, &mut y);
            pending = next;
            if let Some((_, len)) = next {
                step += len as u64;
                left -= len as u64;
            }
        }
        self.step += steps;
        None
    }
}

/// A star's tile, its blocks spread over the current rayon pool; the
/// earliest broken `(step, agent)`. With `cols`, the state is the caller's:
/// each task loads its blocks' lanes from the columns before its tile and
/// stores them back after it (once per tile of up to 64 steps; the blocks
/// keep a working copy, as they keep their own state without `cols`).
fn star<K: Kernel>(
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
fn chain<K: Kernel>(
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

/// Five state columns (x, y, θ, v, ω) of the same agents, a caller's buffer
/// ([`BatchEngine::run_on`]): agent `i`'s quantity `q` at `cols[q][i]`.
pub(super) struct Columns<'a>([&'a mut [f64]; 5]);

impl<'a> Columns<'a> {
    /// The columns of `buf` (`5 n` values).
    pub(super) fn new(buf: &'a mut [f64], n: usize) -> Columns<'a> {
        let (x, rest) = buf.split_at_mut(n);
        let (y, rest) = rest.split_at_mut(n);
        let (theta, rest) = rest.split_at_mut(n);
        let (v, omega) = rest.split_at_mut(n);
        Columns([x, y, theta, v, omega])
    }

    /// The same columns, borrowed for a shorter while.
    pub(super) fn reborrow<'b>(&'b mut self) -> Columns<'b> {
        let [a, b, c, d, e] = &mut self.0;
        Columns([&mut **a, &mut **b, &mut **c, &mut **d, &mut **e])
    }

    /// Agents `..at` and `at..`.
    pub(super) fn split_at(self, at: usize) -> (Columns<'a>, Columns<'a>) {
        let at = at.min(self.0[0].len());
        let [a, b, c, d, e] = self.0.map(|col| col.split_at_mut(at));
        (
            Columns([a.0, b.0, c.0, d.0, e.0]),
            Columns([a.1, b.1, c.1, d.1, e.1]),
        )
    }

    /// The blocks' live lanes from the columns (the blocks start at agent 0
    /// of the columns; padding lanes keep their own values).
    pub(super) fn load<K: Kernel>(&self, blocks: &mut [K::Block]) {
        for (bi, b) in blocks.iter_mut().enumerate() {
            let x = K::x_mut(b);
            for (q, col) in self.0.iter().enumerate() {
                if let Some(lanes) = col.get(bi * K::LANES..) {
                    let live = lanes.len().min(K::LANES);
                    x[q].0[..live].copy_from_slice(&lanes[..live]);
                }
            }
        }
    }

    /// The blocks' live lanes into the columns.
    pub(super) fn store<K: Kernel>(&mut self, blocks: &mut [K::Block]) {
        for (bi, b) in blocks.iter_mut().enumerate() {
            let x = K::x_mut(b);
            for (q, col) in self.0.iter_mut().enumerate() {
                if let Some(lanes) = col.get_mut(bi * K::LANES..) {
                    let live = lanes.len().min(K::LANES);
                    lanes[..live].copy_from_slice(&x[q].0[..live]);
                }
            }
        }
    }
}

/// Runs every engine `steps` steps, in parallel on the current rayon pool
/// (Monte Carlo sweeps: independent runs).
pub fn sweep<K: Kernel>(engines: &mut [BatchEngine<K>], steps: u64) -> Vec<Result<(), SimError>> {
    engines.par_iter_mut().map(|e| e.run(steps)).collect()
}

/// Packs members into blocks of `W` lanes (the last one padded with copies of
/// the last member), refusing what neither kernel does. Returns the blocks,
/// the shared `L_Ycomp` mode and the number of agents.
pub(super) fn pack(
    members: impl IntoIterator<Item = Member>,
) -> Result<(Vec<Block>, LyComp, usize), EngineError> {
    let mut comp = None;
    let mut blocks: Vec<Block> = Vec::new();
    let mut lanes: Vec<Member> = Vec::with_capacity(W);
    let mut n = 0usize;
    for m in members {
        n += 1;
        if m.placement.uses_exact_derivatives() {
            return Err(EngineError::Unsupported(format!(
                "exact L_Y derivatives (agent {n}; use ly_derivatives = \"neglect\")"
            )));
        }
        if m.placement.frame() == OffsetFrame::Leader {
            return Err(EngineError::Unsupported(format!(
                "offsets in the leader's frame (agent {n}; the kernels hold the paper's, eq. 7)"
            )));
        }
        match comp {
            None => comp = Some(m.placement.lycomp()),
            Some(c) if c != m.placement.lycomp() => {
                return Err(EngineError::Unsupported(format!(
                    "mixed L_Ycomp modes (agent {n} differs from agent 1)"
                )));
            }
            Some(_) => {}
        }
        lanes.push(m);
        if lanes.len() == W {
            blocks.push(block(&lanes, W));
            lanes.clear();
        }
    }
    let Some(comp) = comp else {
        return Err(EngineError::Unsupported("an empty formation".into()));
    };
    if !lanes.is_empty() {
        let live = lanes.len();
        while lanes.len() < W {
            lanes.push(lanes[live - 1]);
        }
        blocks.push(block(&lanes, live));
    }
    blocks.shrink_to_fit();
    Ok((blocks, comp, n))
}

/// Packs up to `W` members (padded by the caller) into a block; the first
/// `live` lanes are agents.
fn block(m: &[Member], live: usize) -> Block {
    let lane = |f: &dyn Fn(&Member) -> f64| -> V { Lanes(std::array::from_fn(|l| f(&m[l]))) };
    let comp: [V; 3] = match m[0].placement.lycomp() {
        LyComp::Fit => [
            lane(&|a| 2.0 * a.placement.fit().g),
            lane(&|a| 1.0 / a.placement.fit().delta),
            lane(&|a| {
                let k = a.placement.fit().epsilon / a.placement.fit().delta;
                k * k
            }),
        ],
        LyComp::Exact => [
            lane(&|a| a.placement.lx_off()),
            lane(&|a| a.placement.lx_off() * a.placement.lx_off()),
            lane(&|_| 0.0),
        ],
        LyComp::None => [lane(&|_| 0.0); 3],
    };
    Block {
        x: [
            lane(&|a| a.start.x),
            lane(&|a| a.start.y),
            lane(&|a| a.start.theta),
            lane(&|a| a.start.v),
            lane(&|a| a.start.omega),
        ],
        lx: lane(&|a| a.placement.lx()),
        inv_lx: lane(&|a| 1.0 / a.placement.lx()),
        ly_off: lane(&|a| a.placement.ly_off()),
        ke: lane(&|a| a.gains.ke()),
        kz: lane(&|a| a.gains.kz()),
        comp,
        live: Mask(std::array::from_fn(|l| if l < live { u64::MAX } else { 0 })),
    }
}

/// The reference at every stage of the tile's steps: `t_n`, `t_n + dt/2`
/// (stages 2 and 3 share it), `t_{n+1}`, with `t_n = n · dt` as the scalar
/// simulator computes it. Stage 4 is at `t_{n+1}`, not `t_n + dt` (the scalar
/// simulator's, an ulp of `t` away): one reference value, and one `L_Y` per
/// agent, serve stage 4 of a step and stage 1 of the next.
pub(super) fn fill_reference(
    carries: &mut [[Carry; 4]],
    reference: &Reference,
    step0: u64,
    dt: f64,
) {
    let at = |n: u64| Carry::reference(&reference.eval(n as f64 * dt, Order::Two));
    let mut a = at(step0);
    for (n, c) in (step0..).zip(carries.iter_mut()) {
        let t = n as f64 * dt;
        let b = Carry::reference(&reference.eval(t + 0.5 * dt, Order::Two));
        let d = at(n + 1);
        *c = [a, b, b, d];
        a = d;
    }
}
