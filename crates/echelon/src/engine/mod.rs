//! A batch engine for large formations: the same system as
//! [`crate::sim::Simulation`], many agents at a time.
//!
//! [`Engine`] steps formations of agents that share one robot model and one
//! law variant, following one reference either all directly (a [`Topology::Star`])
//! or one behind the other (a [`Topology::Chain`]). Like the scalar simulator it
//! integrates with fixed-step RK4 and evaluates the continuous-time law in
//! every stage, leaders first; unlike it, it keeps the agents in blocks of
//! eight lanes (structure of arrays), evaluates the reference once per stage
//! for everyone, never allocates while stepping, runs each block through a
//! tile of 64 steps in registers, and spreads the work over the rayon pool
//! it runs in: a star's blocks, or a long chain's two halves, one tile
//! apart. Results do not depend on the number of threads (each
//! block is computed the same way wherever it runs) and match the scalar
//! simulator to a relative 10⁻⁹ (`tests/engine.rs`), except on long chains,
//! which are chaotic: there the two stay as close as two scalar runs one
//! ulp apart (the same test file).
//!
//! Where the two differ: sines, cosines and `atan2` come from branch-free
//! polynomials ([`crate::lanes`]), eq. 6 is evaluated as one angle
//! (an exact identity, `engine/kernel.rs`), a star's RK4 stages 2–4 turn
//! stage 1's `sin θ`, `cos θ` by their small `δθ` (angle-sum formulas) and
//! take stage 4's reference at `t_{n+1}` rather than `t_n + dt` (so that its
//! `L_Y` serves the next step's stage 1), `1/m`, `1/J`, `1/L_X` are precomputed, and a chain's
//! accelerations are solved as a recurrence `v̇ᵢ = αᵢ + βᵢ v̇ᵢ₋₁` (the law is
//! affine in the leader's acceleration). Not supported: sampled controllers,
//! exact `L̇_Y`, `L̈_Y`, mixed robots or laws, other leader graphs, and torque
//! limits in a chain ([`EngineError::Unsupported`]).
//!
//! [`VelocityEngine`] does the same for velocity-controlled bases
//! ([`crate::base::VelocityBase`]) under the kinematic law
//! ([`crate::kinematic`]), built from a [`VelocityBatch`] and the same
//! [`Member`]s (`K_z` unused): the speed limiter, lags, acceleration limits
//! and `settle` of `base.rs` in lanes, saturated ticks counted per agent, a
//! robot leader's `ṗ_d` from the speeds its base moves at (`engine/velocity.rs`).
//!
//! Both are one [`BatchEngine`] driver over a [`Kernel`]: the driver owns
//! the tile loop (the reference filled once per tile of 64 steps), spreads a
//! star's blocks over the pool, walks a chain segment by segment (a long
//! chain as two halves on two threads, one tile apart), and turns the first
//! non-finite state into the scalar simulator's error; a kernel ([`Torque`],
//! [`Velocity`]) supplies its blocks, its tile of leaders and the work of one
//! tile on them.

mod bench;
mod kernel;
mod velocity;

use std::fmt::Debug;

use pulp::{Arch, Simd, WithSimd};
use rayon::prelude::*;

use crate::agent::AgentSpec;
use crate::check;
use crate::control::{Gains, LawRobot, Variant};
use crate::error::Breach;
use crate::error::{ParamError, SimError};
use crate::formation::Leader;
use crate::guard::Bounds;
use crate::lanes::{Lanes, Mask};
use crate::lycomp::{LyComp, Placement};
use crate::model::{RobotParams, State};
use crate::plan::{Plan, Timing};
use crate::reference::{Order, Reference, Trajectory};

pub use bench::BenchFormation;
pub use kernel::Probe;
use kernel::{Block, Carry, Consts, Limit, Scratch, V, W};
pub use velocity::{Velocity, VelocityBatch, VelocityProbe};

/// Steps each block runs in registers before the next block's turn.
const TILE: usize = 64;
/// Blocks of a chain processed together, all stages of a tile, before the
/// next segment (their work space stays in cache).
const SEGMENT: usize = 32;
/// Blocks per parallel task of a star.
const PAR_BLOCKS: usize = 4;

/// Who follows whom.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Topology {
    /// Every agent follows the reference.
    Star,
    /// Agent 1 follows the reference, agent `i` follows agent `i − 1`.
    Chain,
}

/// What the agents of a batch share. Built by [`Batch::new`].
#[derive(Debug, Clone)]
#[non_exhaustive]
pub struct Batch {
    /// Every agent's body.
    pub robot: RobotParams,
    /// Every agent's law.
    pub variant: Variant,
    /// Who follows whom.
    pub topology: Topology,
    /// The virtual leader's path.
    pub reference: Reference,
    /// RK4 step, s.
    pub dt: f64,
}

/// One agent of a batch. Built by [`Member::new`].
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub struct Member {
    /// Initial state.
    pub start: State,
    /// `L_Xoff`, `L_Yoff`, `L`, `L_Ycomp` (derivatives must be neglected).
    pub placement: Placement,
    /// `K_e`, `K_z`.
    pub gains: Gains,
}

/// Why a batch cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EngineError {
    /// A value the scalar simulator would refuse too.
    #[error(transparent)]
    Sim(#[from] SimError),
    /// Something the scalar simulator does that the engine does not.
    #[error("the batch engine does not support {0}")]
    Unsupported(String),
}

mod sealed {
    /// Only this crate's kernels are [`super::Kernel`]s.
    pub trait Sealed {}
}

/// What a [`BatchEngine`] steps: the [`Torque`] kernel (the paper's plant
/// under the dynamic law) or the [`Velocity`] kernel (velocity-controlled
/// bases under the kinematic law). The engine's driver (the tile loop, a
/// star's blocks over the rayon pool, a chain's segments and its two halves
/// on two cores, failures) is shared; a kernel supplies its blocks, its tile
/// of leaders and the work of one tile. Implemented by this crate only.
pub trait Kernel: sealed::Sealed + Sized {
    /// What [`BatchEngine::probes`] reports for one agent.
    type Probe;
    #[doc(hidden)]
    type Consts: Clone + Debug + Send + Sync;
    #[doc(hidden)]
    type Block: Clone + Debug + Send + Sync;
    #[doc(hidden)]
    type Scratch: Clone + Debug + Default + Send + Sync;
    #[doc(hidden)]
    type Tile: Clone + Debug + Send + Sync;
    /// Agents per block.
    #[doc(hidden)]
    const LANES: usize;
    /// Blocks of a chain walked together (one dispatch, one scratch).
    #[doc(hidden)]
    const SEGMENT: usize;
    #[doc(hidden)]
    fn dt(c: &Self::Consts) -> f64;
    /// Lane `l` of a block's state.
    #[doc(hidden)]
    fn state(b: &Self::Block, l: usize) -> State;
    /// A tile of leaders for `steps` steps.
    #[doc(hidden)]
    fn tile(steps: usize) -> Self::Tile;
    #[doc(hidden)]
    fn tile_bytes(t: &Self::Tile) -> usize;
    /// The reference over the `len` steps from `step0` (the leader of a
    /// star's agents, of a chain's first).
    #[doc(hidden)]
    fn fill(t: &mut Self::Tile, len: usize, reference: &Reference, step0: u64, dt: f64);
    /// `len` steps of star blocks led by `t`; the earliest broken `(step,
    /// agent)` within `blocks`.
    #[doc(hidden)]
    fn star(
        arch: Arch,
        c: &Self::Consts,
        blocks: &mut [Self::Block],
        t: &Self::Tile,
        len: usize,
    ) -> Option<(usize, usize)>;
    /// `len` steps of a chain segment whose first agent is led by `t`, which
    /// is replaced by the segment's last agent (the next segment's leader).
    #[doc(hidden)]
    fn chain(
        arch: Arch,
        c: &Self::Consts,
        blocks: &mut [Self::Block],
        scratch: &mut [Self::Scratch],
        t: &mut Self::Tile,
        len: usize,
    ) -> Option<(usize, usize)>;
    /// Every lane's probe at the blocks' current state (padding included).
    #[doc(hidden)]
    fn probes(
        c: &Self::Consts,
        topology: Topology,
        blocks: &[Self::Block],
        reference: &Reference,
        t: f64,
    ) -> Vec<Self::Probe>;
}

/// The torque kernel: robots of eq. 3 under the dynamic law (eqs. 7–13).
#[derive(Debug, Clone, Copy)]
pub enum Torque {}

/// A formation stepped in blocks of lanes by kernel `K`; see the
/// [module docs](self). [`Engine`] and [`VelocityEngine`] name its two kinds.
#[derive(Debug, Clone)]
pub struct BatchEngine<K: Kernel> {
    consts: K::Consts,
    topology: Topology,
    reference: Reference,
    n: usize,
    step: u64,
    blocks: Vec<K::Block>,
    /// The leaders over a tile, and a chain's second tile buffer (two halves
    /// of a chain run one tile apart; empty in a star).
    tiles: [K::Tile; 2],
    /// A chain's per-segment work space (two segments: one per half).
    scratch: Vec<K::Scratch>,
    failed: Option<SimError>,
    /// The widest instruction set this CPU has (AVX2 on x86-64 when present).
    arch: Arch,
}

/// The batch engine of torque-driven robots (the paper's plant and law).
pub type Engine = BatchEngine<Torque>;

/// The batch engine of velocity-controlled bases under the kinematic law
/// (`engine/velocity.rs`).
pub type VelocityEngine = BatchEngine<Velocity>;

impl Batch {
    /// What a batch's agents share (its robot is valid by construction,
    /// [`RobotParams::new`]), refusing a step that is not a finite number > 0.
    pub fn new(
        robot: RobotParams,
        variant: Variant,
        topology: Topology,
        reference: Reference,
        dt: f64,
    ) -> Result<Batch, SimError> {
        let param = |context: &str| {
            let context = context.to_owned();
            move |source| SimError::Param { context, source }
        };
        check::positive("dt", dt).map_err(param("sim"))?;
        Ok(Batch {
            robot,
            variant,
            topology,
            reference,
            dt,
        })
    }
}

impl Member {
    /// One agent, refusing a start state that is not finite and what
    /// [`Placement::new`] and [`Gains::new`] refuse.
    pub fn new(start: State, placement: Placement, gains: Gains) -> Result<Member, ParamError> {
        start.validate_start()?;
        Ok(Member {
            start,
            placement,
            gains,
        })
    }
}

impl Engine {
    /// Builds a batch from values valid by construction ([`Batch::new`],
    /// [`Member::new`]), refusing what the engine does not do.
    pub fn new(
        batch: Batch,
        members: impl IntoIterator<Item = Member>,
    ) -> Result<Engine, EngineError> {
        let limit = batch.robot.torque_limit().map(|tau| Limit {
            tau,
            r: batch.robot.wheel_radius(),
            l: batch.robot.half_wheelbase(),
        });
        if limit.is_some() && batch.topology == Topology::Chain {
            return Err(EngineError::Unsupported(
                "torque limits in a chain (saturation breaks the recurrence between accelerations)"
                    .into(),
            ));
        }
        let (blocks, comp, n) = pack(members)?;
        let r = &batch.robot;
        let consts = Consts {
            law: LawRobot::new(r),
            eta: r.linear_friction(),
            psi: r.angular_friction(),
            inv_m: 1.0 / r.mass(),
            inv_j: 1.0 / r.inertia(),
            variant: batch.variant,
            comp,
            limit,
            dt: batch.dt,
        };
        Ok(Engine::assemble(
            consts,
            batch.topology,
            batch.reference,
            blocks,
            n,
        ))
    }

    /// The engine for agents given as the scalar simulator takes them: they
    /// must share robot and law, and follow the reference (a star) or each the
    /// one before (a chain).
    pub fn from_agents(
        agents: &[AgentSpec],
        reference: Reference,
        dt: f64,
    ) -> Result<Engine, EngineError> {
        let Some(first) = agents.first() else {
            return Err(EngineError::Unsupported("an empty formation".into()));
        };
        if agents.iter().any(|a| a.max_accel().is_some()) {
            // The kernels run the law alone, not the act step's limits.
            return Err(EngineError::Unsupported("max_accel".into()));
        }
        let star = agents.iter().all(|a| a.leader == Leader::Reference);
        let chain = agents.iter().enumerate().all(|(i, a)| {
            a.leader
                == if i == 0 {
                    Leader::Reference
                } else {
                    Leader::Agent(i - 1)
                }
        });
        let topology = match (star, chain) {
            (true, _) => Topology::Star,
            (false, true) => Topology::Chain,
            _ => {
                return Err(EngineError::Unsupported(
                    "this leader graph (only all-follow-the-reference and each-follows-the-previous)".into(),
                ));
            }
        };
        let torque = |i: usize, a: &AgentSpec| match a.drive {
            crate::agent::Drive::Torque { robot, variant } => Ok((robot, variant)),
            crate::agent::Drive::Velocity(_) => Err(EngineError::Unsupported(format!(
                "velocity bases (agent {} is one)",
                i + 1
            ))),
        };
        let (robot, variant) = torque(0, first)?;
        for (i, a) in agents.iter().enumerate() {
            let (a_robot, a_variant) = torque(i, a)?;
            if a_robot != robot {
                return Err(EngineError::Unsupported(format!(
                    "mixed robots (agent {} differs from agent 1)",
                    i + 1
                )));
            }
            if a_variant != variant {
                return Err(EngineError::Unsupported(format!(
                    "mixed laws (agent {} differs from agent 1)",
                    i + 1
                )));
            }
        }
        let batch = Batch::new(robot, variant, topology, reference, dt)?;
        // Each agent is valid by construction (`AgentSpec::new`).
        Engine::new(
            batch,
            agents.iter().map(|a| Member {
                start: a.start,
                placement: a.placement,
                gains: a.gains,
            }),
        )
    }

    /// The engine for a plan (what [`crate::sim::Simulation::new`] runs):
    /// same agents, reference and step. The controller must be continuous,
    /// without odometry or safety filters.
    pub fn from_plan(plan: &Plan) -> Result<Engine, EngineError> {
        if plan.config().timing != Timing::Continuous {
            return Err(EngineError::Unsupported("sampled controllers".into()));
        }
        if plan.odometers().iter().any(Option::is_some) {
            return Err(EngineError::Unsupported(
                "odometry (controllers acting on estimated poses)".into(),
            ));
        }
        if plan.safety().is_some() {
            return Err(EngineError::Unsupported("safety filters".into()));
        }
        Engine::from_agents(plan.agents(), plan.reference().clone(), plan.config().dt)
    }
}

impl<K: Kernel> BatchEngine<K> {
    /// An engine at step 0 with its work space.
    fn assemble(
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
        let broke = if self.topology == Topology::Chain
            && rayon::current_num_threads() >= 2
            && self.blocks.len() * K::LANES >= 2 * SEGMENT * W
        {
            self.run_chain_on_two_cores(steps)
        } else {
            self.run_tiles(steps)
        };
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
    fn run_tiles(&mut self, steps: u64) -> Option<(u64, usize)> {
        let (arch, dt) = (self.arch, self.dt());
        let mut left = steps;
        while left > 0 {
            let len = left.min(TILE as u64) as usize;
            let tile = &mut self.tiles[0];
            K::fill(tile, len, &self.reference, self.step, dt);
            let c = &self.consts;
            let broke = match self.topology {
                Topology::Star => star::<K>(arch, c, &mut self.blocks, tile, len),
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

/// Runs every engine `steps` steps, in parallel on the current rayon pool
/// (Monte Carlo sweeps: independent runs).
pub fn sweep<K: Kernel>(engines: &mut [BatchEngine<K>], steps: u64) -> Vec<Result<(), SimError>> {
    engines.par_iter_mut().map(|e| e.run(steps)).collect()
}

/// Packs members into blocks of `W` lanes (the last one padded with copies of
/// the last member), refusing what neither kernel does. Returns the blocks,
/// the shared `L_Ycomp` mode and the number of agents.
fn pack(
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
fn fill_reference(carries: &mut [[Carry; 4]], reference: &Reference, step0: u64, dt: f64) {
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
/// earliest broken `(step, agent)`.
fn star<K: Kernel>(
    arch: Arch,
    c: &K::Consts,
    blocks: &mut [K::Block],
    t: &K::Tile,
    len: usize,
) -> Option<(usize, usize)> {
    if rayon::current_num_threads() <= 1 || blocks.len() <= PAR_BLOCKS {
        return K::star(arch, c, blocks, t, len);
    }
    blocks
        .par_chunks_mut(PAR_BLOCKS)
        .enumerate()
        .filter_map(|(i, chunk)| {
            K::star(arch, c, chunk, t, len).map(|(n, a)| (n, i * PAR_BLOCKS * K::LANES + a))
        })
        .min()
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The AVX2 kernels (when this CPU has AVX2) and the baseline SSE2 ones
    /// compute the same bits: no fused multiply-add, same operations.
    #[test]
    fn every_instruction_set_gives_the_same_bits() {
        for topology in [Topology::Star, Topology::Chain] {
            let f = BenchFormation {
                agents: 37,
                topology,
                seed: 5,
            };
            let mut best = f.engine(0.01).unwrap_or_else(|e| panic!("{e}"));
            let mut baseline = best.clone();
            baseline.arch = Arch::Scalar;
            assert!(best.run(300).is_ok() && baseline.run(300).is_ok());
            let bits = |e: &Engine| -> Vec<u64> {
                e.states()
                    .iter()
                    .flat_map(|s| [s.x, s.y, s.theta, s.v, s.omega].map(f64::to_bits))
                    .collect()
            };
            assert_eq!(bits(&best), bits(&baseline), "{topology:?}");
        }
    }
}
