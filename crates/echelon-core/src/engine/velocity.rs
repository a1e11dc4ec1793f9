//! The velocity-base kernel: blocks of [`W`] agents on velocity-controlled
//! bases ([`crate::model::base::VelocityBase`]) driven by the kinematic law
//! ([`crate::law::kinematic`]), RK4 with the law in every stage, stepped by the
//! same driver as the torque kernel ([`super::BatchEngine`]).
//!
//! Every formula comes from the scalar code: the command from
//! [`crate::law::kinematic::kinematic_of`] (the generic function
//! `kinematic_law` calls), `L_Ycomp` as in the torque kernel
//! ([`super::kernel::compensation`]), the speed limiter, lags and acceleration
//! limits of [`crate::model::base::VelocityBase::limit`] and
//! [`crate::model::base::VelocityBase::derivative`] in lanes, and
//! [`crate::model::base::VelocityBase::settle`] after each step. The limiters decide
//! per lane exactly as the scalar code does (`|v| > v_max`, `|v̇| > a_max`, …)
//! and act through selects, min and max; the scaled values (one division for
//! the common scale factor, `1/τ`, `1/v_max`, … precomputed) are computed only
//! when some lane of the block needs them, which after the transients none
//! does. An infinite limit never binds, so an unlimited base takes the same
//! path at the cost of a comparison.
//!
//! Per step, a block evaluates the law four times: the RK4 stages 2–4 and
//! once at the new state, which both settles the step (an axis without lag
//! takes the command's velocity) and serves as the next step's stage 1 (the
//! command does not depend on the state's velocities). A star block runs its
//! steps in registers like the torque star (one `sin_cos` per step, stages 2–4
//! turned by their `δθ`, two `L_Ycomp` per step). A chain block runs its steps
//! given its leader's motion at every stage, read from the tile of leaders,
//! where it writes its own last agent's in their place for the block after:
//! the chain is walked block by block, a tile at a time, and a long chain's
//! two halves run one tile apart on two threads like the torque chain. When
//! both axes lag, a robot leader's speeds are its state's and a block's law is
//! one vector evaluation; when an axis has no lag the leader moves at its
//! command, so each agent's command waits for its leader's: the law then runs
//! lane after lane (the same generic code on one lane).

use std::marker::PhantomData;

use pulp::Arch;

use crate::check;
use crate::error::SimError;
use crate::law::lycomp::LyComp;
use crate::math::lanes::{Lanes, Mask};
use crate::model::State;
use crate::model::base::{AccelLimit, VelocityBase, VelocityCommand};
use crate::reference::{Jet, Order, Reference, Trajectory};

use super::kernel::{Block, W, shift_from, state_of};

/// Agents per velocity block, as the torque kernel packs them (blocks of
/// four, one AVX2 vector per quantity, compiled to ≈ 30 % more instructions
/// per agent-step: the vectoriser splits parts of the stage into halves).
pub(crate) const VW: usize = W;
/// `VW` agents' values of one quantity.
pub(crate) type V4 = Lanes<VW>;
use super::{BatchEngine, EngineError, Kernel, Member, Topology, VelocityEngine, pack, sealed};

mod law;
mod tile;
use super::kernel::vectors;
pub(crate) use law::held_step;
use law::{command, derivative, ly_of, settle, speeds};
use tile::Run;
pub(crate) use tile::Tile;
pub(crate) use tile::{Chain, Star, probe};

/// What every agent of a velocity batch shares: the base, in the form the
/// kernel uses.
#[derive(Debug, Clone, Copy)]
pub struct VConsts {
    pub(crate) comp: LyComp,
    pub(crate) dt: f64,
    /// Whether each axis lags (`τ > 0`); an axis without lag moves at the command.
    pub(crate) lag: [bool; 2],
    /// `1/τ_v`, `1/τ_ω` (0 without lag).
    pub(crate) inv_tau: [f64; 2],
    /// `v_max`, `ω_max` (may be infinite) and their inverses (0 if infinite).
    pub(crate) max: [f64; 2],
    pub(crate) inv_max: [f64; 2],
    /// `a_max`, `α_max` (may be infinite), their inverses, and how they act.
    pub(crate) acc: [f64; 2],
    pub(crate) inv_acc: [f64; 2],
    pub(crate) accel: AccelLimit,
}

impl VConsts {
    /// The constants of `base` stepped by `dt`, `L_Ycomp` by `comp`.
    pub(crate) fn new(base: &VelocityBase, dt: f64, comp: LyComp) -> VConsts {
        let b = base;
        let inv = |m: f64| if m.is_finite() { 1.0 / m } else { 0.0 };
        VConsts {
            comp,
            dt,
            lag: [b.tau_v() > 0.0, b.tau_omega() > 0.0],
            inv_tau: [b.tau_v(), b.tau_omega()].map(|t| if t > 0.0 { 1.0 / t } else { 0.0 }),
            max: [b.v_max(), b.omega_max()],
            inv_max: [inv(b.v_max()), inv(b.omega_max())],
            acc: [b.a_max(), b.alpha_max()],
            inv_acc: [inv(b.a_max()), inv(b.alpha_max())],
            accel: b.accel(),
        }
    }
}

/// `W` agents on velocity bases: states, constants and saturated-tick counts.
#[derive(Debug, Clone, Copy)]
pub struct VBlock {
    /// `x, y, θ, v, ω`.
    pub(crate) x: [V4; 5],
    pub(crate) own: Own<VW>,
    /// Lanes that hold an agent (the last block may be padded).
    pub(crate) live: Mask<VW>,
    /// Steps whose command (at the step's start) exceeded a speed limit.
    pub(crate) saturated: [u64; VW],
}

impl VBlock {
    /// The velocity blocks of a torque block's agents (same packing, half
    /// the lanes each; a half of padding alone is left out).
    pub(crate) fn of(b: &Block) -> impl Iterator<Item = VBlock> + '_ {
        (0..W / VW).filter_map(move |h| {
            let half = |v: Lanes<W>| -> V4 { Lanes::from_slice(&v.0[h * VW..]) };
            let live = Mask(std::array::from_fn(|l| b.live.0[h * VW + l]));
            live.any().then(|| VBlock {
                x: b.x.map(half),
                own: Own {
                    lx: half(b.lx),
                    inv_lx: half(b.inv_lx),
                    ly_off: half(b.ly_off),
                    ke: half(b.ke),
                    comp: b.comp.map(half),
                },
                live,
                saturated: [0; VW],
            })
        })
    }
}

/// An agent's own constants, in `N` lanes.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Own<const N: usize> {
    lx: Lanes<N>,
    inv_lx: Lanes<N>,
    ly_off: Lanes<N>,
    ke: Lanes<N>,
    /// `L_Ycomp` constants, as [`Block::comp`].
    comp: [Lanes<N>; 3],
}

impl Own<VW> {
    /// Lane `l` alone.
    #[inline(always)]
    fn lane(&self, l: usize) -> Own<1> {
        let one = |v: V4| Lanes([v.0[l]]);
        Own {
            lx: one(self.lx),
            inv_lx: one(self.inv_lx),
            ly_off: one(self.ly_off),
            ke: one(self.ke),
            comp: self.comp.map(one),
        }
    }
}

/// A leader as its followers see it: `p_d`, `ṗ_d` and the `(V_d, ω_d)`
/// `L_Ycomp` reads (a robot: its actual speeds, `V_d = max(v, 0)`).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct Lead {
    pub(crate) p: [f64; 2],
    pub(crate) dp: [f64; 2],
    pub(crate) vd: f64,
    pub(crate) wd: f64,
}

impl Lead {
    /// The virtual leader at one instant.
    pub(crate) fn reference(jet: &Jet) -> Lead {
        Lead {
            p: jet.p,
            dp: jet.dp,
            vd: jet.speed(),
            wd: jet.turn_rate(),
        }
    }
}

/// Leaders in `N` lanes.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Leads<const N: usize> {
    p: [Lanes<N>; 2],
    dp: [Lanes<N>; 2],
    vd: Lanes<N>,
    wd: Lanes<N>,
}

impl<const N: usize> Leads<N> {
    #[inline(always)]
    fn splat(l: &Lead) -> Leads<N> {
        let s = Lanes::splat;
        Leads {
            p: [s(l.p[0]), s(l.p[1])],
            dp: [s(l.dp[0]), s(l.dp[1])],
            vd: s(l.vd),
            wd: s(l.wd),
        }
    }

    /// Robots at `(x, y)`, heading `(sin, cos)`, moving at `(v, ω)`
    /// (`LeaderMotion::of_robot`'s `ṗ_d`, `Placement::offset_for_robot`'s
    /// `(max(v, 0), ω)`).
    #[inline(always)]
    fn robots(x: &[Lanes<N>; 5], (sin, cos): (Lanes<N>, Lanes<N>), speeds: [Lanes<N>; 2]) -> Self {
        Leads {
            p: [x[0], x[1]],
            dp: [speeds[0] * cos, speeds[0] * sin],
            vd: speeds[0].max(Lanes::splat(0.0)),
            wd: speeds[1],
        }
    }

    /// Lane `l`.
    #[inline(always)]
    fn lead(&self, l: usize) -> Lead {
        Lead {
            p: [self.p[0].0[l], self.p[1].0[l]],
            dp: [self.dp[0].0[l], self.dp[1].0[l]],
            vd: self.vd.0[l],
            wd: self.wd.0[l],
        }
    }
}

impl Leads<VW> {
    /// Each lane's leader: the lane before; the first lane's is `first`.
    #[inline(always)]
    fn shifted(&self, first: &Lead) -> Leads<VW> {
        let sh = |v: V4, c: f64| shift_from(v, V4::splat(c));
        Leads {
            p: [sh(self.p[0], first.p[0]), sh(self.p[1], first.p[1])],
            dp: [sh(self.dp[0], first.dp[0]), sh(self.dp[1], first.dp[1])],
            vd: sh(self.vd, first.vd),
            wd: sh(self.wd, first.wd),
        }
    }
}

/// The law's output at one stage, in `N` lanes.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Cmd<const N: usize> {
    /// `(v*, ω*)` before the limits.
    pub(crate) raw: [Lanes<N>; 2],
    /// The command the base follows (after the speed limits).
    pub(crate) cmd: [Lanes<N>; 2],
    /// `e` (eq. 7).
    pub(crate) e: [Lanes<N>; 2],
    /// Lanes whose command exceeded a speed limit.
    pub(crate) saturated: Mask<N>,
}

/// What the agents of a velocity batch share. Built by [`VelocityBatch::new`].
#[derive(Debug, Clone)]
#[non_exhaustive]
pub struct VelocityBatch {
    /// Every agent's base.
    pub base: VelocityBase,
    /// Who follows whom.
    pub topology: Topology,
    /// The virtual leader's path.
    pub reference: Reference,
    /// RK4 step, s.
    pub dt: f64,
}

impl VelocityBatch {
    /// What a velocity batch's agents share (the kinematic law on one base),
    /// (its base is possible by construction, [`VelocityBase::new`]), refusing
    /// a step that is not a finite number > 0 or one longer than a lag
    /// ([`VelocityBase::check_step`]).
    pub fn new(
        base: VelocityBase,
        topology: Topology,
        reference: Reference,
        dt: f64,
    ) -> Result<VelocityBatch, SimError> {
        check::positive("dt", dt).map_err(SimError::param("sim"))?;
        base.check_step(dt).map_err(SimError::param("base"))?;
        Ok(VelocityBatch {
            base,
            topology,
            reference,
            dt,
        })
    }
}

/// What one agent's kinematic law does at one instant.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct VelocityProbe {
    /// Tracking error `e` (eq. 7), body frame, m.
    pub e: [f64; 2],
    /// The law's command `(v*, ω*)`, before the speed limits.
    pub command: VelocityCommand,
    /// The command the base follows (after the speed limits).
    pub applied: VelocityCommand,
    /// Whether the speed limits cut the command.
    pub saturated: bool,
}

/// The velocity-base kernel of [`BatchEngine`]: velocity-controlled bases
/// under the kinematic law (see the module docs of `engine::velocity`).
#[derive(Debug, Clone, Copy)]
pub enum Velocity {}

impl sealed::Sealed for Velocity {}

impl Kernel for Velocity {
    type Probe = VelocityProbe;
    type Consts = VConsts;
    type Block = VBlock;
    /// A velocity chain needs no work space beyond its tile.
    type Scratch = ();
    type Tile = Tile;
    const LANES: usize = VW;
    /// A velocity chain walks its blocks one at a time (each a whole tile).
    const SEGMENT: usize = 1;

    fn dt(c: &VConsts) -> f64 {
        c.dt
    }

    fn state(b: &VBlock, l: usize) -> State {
        state_of(&b.x, l)
    }

    fn x_mut(b: &mut VBlock) -> &mut [V4; 5] {
        &mut b.x
    }

    fn tile(steps: usize) -> Tile {
        Tile {
            first: Lead::default(),
            steps: vec![[Lead::default(); 4]; steps],
        }
    }

    fn tile_bytes(t: &Tile) -> usize {
        t.steps.capacity() * size_of::<[Lead; 4]>()
    }

    /// The reference over the tile's `len` steps from `step0`: at `t_n` for
    /// the first step's start, then per step at `t_n + dt/2` (stages 2 and 3)
    /// and `t_{n+1}` (stage 4 and the step's end), as the torque engine's
    /// `fill_reference`.
    fn fill(tile: &mut Tile, len: usize, reference: &Reference, step0: u64, dt: f64) {
        let at = |t: f64| Lead::reference(&reference.eval(t, Order::Two));
        tile.first = at(step0 as f64 * dt);
        for (n, s) in (step0..).zip(tile.steps[..len].iter_mut()) {
            let half = at(n as f64 * dt + 0.5 * dt);
            let end = at((n + 1) as f64 * dt);
            *s = [half, half, end, end];
        }
    }

    fn star(
        arch: Arch,
        c: &VConsts,
        blocks: &mut [VBlock],
        t: &Tile,
        len: usize,
    ) -> Option<(usize, usize)> {
        arch.dispatch(Run::<Star, &Tile> {
            c,
            blocks,
            t,
            len,
            leaders: PhantomData,
        })
    }

    fn chain(
        arch: Arch,
        c: &VConsts,
        blocks: &mut [VBlock],
        _: &mut [()],
        t: &mut Tile,
        len: usize,
    ) -> Option<(usize, usize)> {
        arch.dispatch(Run::<Chain, &mut Tile> {
            c,
            blocks,
            t,
            len,
            leaders: PhantomData,
        })
    }

    fn probes(
        c: &VConsts,
        topology: Topology,
        blocks: &[VBlock],
        reference: &Reference,
        t: f64,
    ) -> Vec<VelocityProbe> {
        let first = Lead::reference(&reference.eval(t, Order::Two));
        let mut cmds = Vec::with_capacity(blocks.len());
        match topology {
            Topology::Star => probe::<Star>(c, blocks, first, &mut cmds),
            Topology::Chain => probe::<Chain>(c, blocks, first, &mut cmds),
        }
        cmds.iter()
            .flat_map(|k| {
                (0..VW).map(move |l| VelocityProbe {
                    e: [k.e[0].0[l], k.e[1].0[l]],
                    command: VelocityCommand {
                        v: k.raw[0].0[l],
                        omega: k.raw[1].0[l],
                    },
                    applied: VelocityCommand {
                        v: k.cmd[0].0[l],
                        omega: k.cmd[1].0[l],
                    },
                    saturated: k.saturated.0[l] != 0,
                })
            })
            .collect()
    }
}

impl VelocityEngine {
    /// Builds a velocity batch from values valid by construction
    /// ([`VelocityBatch::new`], [`Member::new`]; `K_z` is not used), refusing
    /// what the engine does not do.
    pub fn new(
        batch: VelocityBatch,
        members: impl IntoIterator<Item = Member>,
    ) -> Result<VelocityEngine, EngineError> {
        let (blocks, comp, n) = pack(members)?;
        let c = VConsts::new(&batch.base, batch.dt, comp);
        let blocks = blocks.iter().flat_map(VBlock::of).collect();
        Ok(BatchEngine::assemble(
            c,
            batch.topology,
            batch.reference,
            blocks,
            n,
        ))
    }

    /// Agent `i`'s number of steps whose command (at the step's start)
    /// exceeded a speed limit.
    pub fn saturated_ticks(&self, i: usize) -> u64 {
        self.blocks[i / VW].saturated[i % VW]
    }
}
