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
//! polynomials ([`crate::math::lanes`]), eq. 6 is evaluated as one angle
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
//! ([`crate::model::base::VelocityBase`]) under the kinematic law
//! ([`crate::law::kinematic`]), built from a [`VelocityBatch`] and the same
//! [`Member`]s (`K_z` unused): the speed limiter, lags, acceleration limits
//! and `settle` of `base.rs` in lanes, saturated ticks counted per agent, a
//! robot leader's `ṗ_d` from the speeds its base moves at (`engine/velocity.rs`).
//!
//! The state can live in a buffer the caller owns: [`BatchEngine::run_on`]
//! steps five columns (x, y, θ, v, ω of every agent, as
//! [`BatchEngine::columns`] lays them out) in place, with the same bits as
//! [`BatchEngine::run`] (what the Python `BatchEngine.step` does on a numpy
//! array).
//!
//! Both are one [`BatchEngine`] driver over a [`Kernel`]: the driver owns
//! the tile loop (the reference filled once per tile of 64 steps), spreads a
//! star's blocks over the pool, walks a chain segment by segment (a long
//! chain as two halves on two threads, one tile apart), and turns the first
//! non-finite state into the scalar simulator's error; a kernel ([`Torque`],
//! [`Velocity`]) supplies its blocks, its tile of leaders and the work of one
//! tile on them.

mod bench;
mod driver;
mod kernel;
mod torque;
mod velocity;

use std::fmt::Debug;

use pulp::Arch;

use crate::check;
use crate::error::{ParamError, SimError};
use crate::formation::Leader;
use crate::formation::agent::AgentSpec;
use crate::law::control::{Gains, LawRobot, Variant};
use crate::law::lycomp::Placement;
use crate::model::{RobotParams, State};
use crate::reference::Reference;
use crate::sim::plan::{Plan, Timing};

pub use bench::BenchFormation;
pub use driver::sweep;
use driver::{fill_reference, pack};
pub use kernel::Probe;
use kernel::{Consts, Limit};
pub use torque::Torque;
pub(crate) use velocity::{V4, VConsts, VW, held_step};
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
    /// A caller's state buffer the engine cannot step
    /// ([`BatchEngine::run_on`]): wrong length or a value that is not finite.
    #[error("state buffer: {0}")]
    Buffer(String),
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
    /// A block's state, `x, y, θ, v, ω` in lanes (what [`Columns`](driver::Columns) load and store).
    #[doc(hidden)]
    fn x_mut(b: &mut Self::Block) -> &mut [kernel::V; 5];
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
    /// The widest instruction set this CPU has (on x86-64: AVX-512, else AVX2,
    /// else the baseline).
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
        check::positive("dt", dt).map_err(SimError::param("sim"))?;
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
        Ok(Member {
            start: start.start()?,
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
        // The kernels run the law alone, not the rest of the act step.
        if let Some(what) = agents.iter().find_map(AgentSpec::beyond_law) {
            return Err(EngineError::Unsupported(what.into()));
        }
        let star = agents.iter().all(|a| a.leader() == Leader::Reference);
        let chain = agents.iter().enumerate().all(|(i, a)| {
            a.leader()
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
        let torque = |i: usize, a: &AgentSpec| match a.drive() {
            crate::formation::agent::Drive::Torque { robot, variant } => Ok((*robot, *variant)),
            crate::formation::agent::Drive::Velocity(_) => Err(EngineError::Unsupported(format!(
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
                start: a.start(),
                placement: a.placement(),
                gains: a.gains(),
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The AVX-512 kernels, the AVX2 ones (each when this CPU has it) and
    /// the baseline SSE2 ones compute the same bits: no fused multiply-add,
    /// same operations.
    #[test]
    fn every_instruction_set_gives_the_same_bits() {
        let mut arches = vec![Arch::Scalar];
        #[cfg(target_arch = "x86_64")]
        {
            arches.extend(pulp::x86::V3::try_new().map(Arch::V3));
            arches.extend(pulp::x86::V4::try_new().map(Arch::V4));
        }
        for topology in [Topology::Star, Topology::Chain] {
            let f = BenchFormation {
                agents: 37,
                topology,
                seed: 5,
            };
            let bits = |arch: Arch| -> Vec<u64> {
                let mut e = f.engine(0.01).unwrap_or_else(|e| panic!("{e}"));
                e.arch = arch;
                assert!(e.run(300).is_ok());
                e.states()
                    .iter()
                    .flat_map(|s| [s.x, s.y, s.theta, s.v, s.omega].map(f64::to_bits))
                    .collect()
            };
            let baseline = bits(Arch::Scalar);
            for &arch in &arches {
                assert_eq!(bits(arch), baseline, "{topology:?} {arch:?}");
            }
        }
    }

    fn column_bits(c: &[f64]) -> Vec<u64> {
        c.iter().map(|v| v.to_bits()).collect()
    }

    /// `run_on` a caller's columns, in uneven calls, on 1 and 2 threads;
    /// `run` on the engine's own state in one call on one thread.
    fn run_on_agrees<K: Kernel>(make: &dyn Fn() -> BatchEngine<K>, calls: &[u64]) {
        let steps: u64 = calls.iter().sum();
        let mut own = make();
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        one.install(|| own.run(steps)).unwrap();
        for threads in [1, 2] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let mut e = make();
            let mut buf = e.columns();
            for &k in calls {
                pool.install(|| e.run_on(&mut buf, k)).unwrap();
            }
            assert_eq!(column_bits(&buf), column_bits(&own.columns()));
            // The engine's own states are the buffer's too.
            assert_eq!(column_bits(&e.columns()), column_bits(&buf));
            assert_eq!(e.step_index(), steps);
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(24))]

        /// Stepping the caller's buffer is stepping the engine: the same bits
        /// for any number of agents (partial blocks, parallel tasks, a chain
        /// in two halves), drive, topology, and grouping of steps.
        #[test]
        fn run_on_the_callers_columns_is_run(
            agents in 1usize..700,
            chain in proptest::bool::ANY,
            velocity in proptest::bool::ANY,
            seed in 0u64..1000,
            calls in proptest::collection::vec(1u64..150, 1..4),
        ) {
            let f = BenchFormation {
                agents,
                topology: if chain { Topology::Chain } else { Topology::Star },
                seed,
            };
            if velocity {
                run_on_agrees(&|| f.velocity_engine(BenchFormation::BASE, 0.001).unwrap(), &calls);
            } else {
                run_on_agrees(&|| f.engine(0.001).unwrap(), &calls);
            }
        }
    }

    /// A buffer of the wrong length or with a value that is not finite is
    /// refused; neither it nor the engine changes.
    #[test]
    fn a_bad_buffer_is_refused_and_changes_nothing() {
        let f = BenchFormation {
            agents: 10,
            topology: Topology::Star,
            seed: 3,
        };
        let mut e = f.engine(0.001).unwrap();
        let mut good = e.columns();
        e.run_on(&mut good, 7).unwrap();
        let before = (e.columns(), e.step_index());
        for len in [0, 49, 51, 100] {
            let mut short = vec![0.5; len];
            let err = e.run_on(&mut short, 3).unwrap_err();
            assert!(
                matches!(&err, EngineError::Buffer(m) if m.contains("expected 5 × 10")),
                "{err}"
            );
            assert!(short.iter().all(|&v| v == 0.5));
        }
        for (at, bad) in [(0, f64::NAN), (23, f64::INFINITY), (49, f64::NEG_INFINITY)] {
            let mut buf = good.clone();
            buf[at] = bad;
            let copy = column_bits(&buf);
            let err = e.run_on(&mut buf, 3).unwrap_err();
            let what = format!(
                "{} of agent {}",
                ["x", "y", "θ", "v", "ω"][at / 10],
                at % 10 + 1
            );
            assert!(
                matches!(&err, EngineError::Buffer(m) if m.contains(&what)),
                "{err}"
            );
            assert_eq!(column_bits(&buf), copy);
        }
        assert_eq!(column_bits(&e.columns()), column_bits(&before.0));
        assert_eq!(e.step_index(), before.1);
    }
}
