//! The benchmark formation of `echelon bench`: seeded, random, reproducible.

use super::{Batch, Engine, EngineError, Member, Topology, VelocityBatch, VelocityEngine};
use crate::formation::Leader;
use crate::formation::agent::AgentSpec;
use crate::law::control::{Gains, Variant};
use crate::law::lycomp::{LyComp, LyDerivatives, Placement, PlacementSpec};
use crate::math::rng::SplitMix64;
use crate::model::base::VelocityBase;
use crate::model::{RobotParams, State};
use crate::reference::{Circle, Reference};

/// `echelon bench`'s formation: `agents` robots of Table I (agent 1), paper
/// law with `K_e = 1.5`, `K_z = 10`, `L = 0.05 m` and `L_Ycomp` by eq. 6, behind a
/// virtual leader on a circle (`V_d = 0.5 m/s`, `ω_d = 0.1 rad/s`, from the
/// origin heading along x). Each robot starts at rest at a random pose (x, y
/// uniform in ±2 m, heading uniform in [−π, π)) with random offsets
/// (`L_Xoff` uniform in 0.2–0.8 m, `L_Yoff` in ±1 m), drawn in agent order from
/// [`SplitMix64`]`(seed)`: the same seed gives the same formation, whatever
/// else (threads) changes.
///
/// A chain is a column: the same draws, but `L_Yoff = 0`, each robot straight
/// behind the one before. With lateral offsets a chain of robots at rest is
/// not string stable: the law feeds the leader's acceleration forward,
/// `v̇ᵢ = αᵢ + βᵢ v̇ᵢ₋₁` with `βᵢ = cos Δᵢ − (L_Y/L_X) sin Δᵢ` (`Δᵢ` the heading
/// difference), and `|βᵢ| > 1` compounds down the chain: with `L_Yoff` in ±1 m
/// a random chain of 1 000 overflows at agent 540 within 0.04 s, in the scalar
/// simulator as in the engine. With `L_Y = 0` (up to the small `L_Ycomp`),
/// `|βᵢ| = |cos Δᵢ| ≤ 1`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BenchFormation {
    /// Number of robots.
    pub agents: usize,
    /// Who follows whom.
    pub topology: Topology,
    /// Seed of the random poses and offsets.
    pub seed: u64,
}

impl BenchFormation {
    /// The most agents a bench builds in all (`echelon bench`'s agents ×
    /// runs, Python's `BatchEngine.bench`): ≈ 11 GB of state, past which the
    /// allocation fails and aborts the process.
    pub const MAX_AGENTS: usize = 100_000_000;

    /// The robot: Table I, agent 1.
    pub const ROBOT: RobotParams = RobotParams::AGENT1;
    /// `L`, m.
    pub const L: f64 = 0.05;

    /// The virtual leader: eq. 18 with `V_d = 0.5 m/s`, `ω_d = 0.1 rad/s`.
    pub fn reference(&self) -> Reference {
        Reference::Circle(
            Circle::new([0.0, 0.0], 0.0, 0.5, 0.1).expect("the bench's circle is valid"),
        )
    }

    /// The robots, in order.
    pub fn members(&self) -> impl Iterator<Item = Member> + use<> {
        let mut rng = SplitMix64::new(self.seed);
        let topology = self.topology;
        (0..self.agents).map(move |_| {
            let x = rng.uniform(-2.0, 2.0);
            let y = rng.uniform(-2.0, 2.0);
            let theta = rng.uniform(-std::f64::consts::PI, std::f64::consts::PI);
            let lx_off = rng.uniform(0.2, 0.8);
            let ly_off = match topology {
                Topology::Star => rng.uniform(-1.0, 1.0),
                Topology::Chain => {
                    rng.uniform(-1.0, 1.0);
                    0.0
                }
            };
            // 0.2 ≤ L_Xoff ≤ 0.8 and L > 0: valid, in the range of the eq. 6 fit.
            let placement = Placement::new(PlacementSpec {
                lx_off,
                ly_off,
                l: Self::L,
                comp: LyComp::Fit,
                derivatives: LyDerivatives::Neglect,
            })
            .expect("a placement in the fit's range is valid");
            Member {
                start: State::at_rest(x, y, theta),
                placement,
                gains: Gains::PAPER,
            }
        })
    }

    /// The same robots as the scalar simulator takes them.
    pub fn agent_specs(&self) -> Vec<AgentSpec> {
        self.members()
            .enumerate()
            .map(|(i, m)| {
                let leader = match (self.topology, i) {
                    (Topology::Chain, 1..) => Leader::Agent(i - 1),
                    _ => Leader::Reference,
                };
                AgentSpec::new(
                    format!("agent {}", i + 1),
                    Self::ROBOT,
                    leader,
                    m.placement,
                    m.gains,
                    Variant::Paper,
                    m.start,
                )
                .expect("the bench's members are valid agents")
            })
            .collect()
    }

    /// The batch engine for this formation at step `dt`.
    pub fn engine(&self, dt: f64) -> Result<Engine, EngineError> {
        let batch = Batch::new(
            Self::ROBOT,
            Variant::Paper,
            self.topology,
            self.reference(),
            dt,
        )?;
        Engine::new(batch, self.members())
    }

    /// `echelon bench --drive velocity`'s base: a Clearpath Jackal
    /// ([`VelocityBase::JACKAL`]: lags of 0.05 s, 2 m/s, 4 rad/s, 20 m/s²,
    /// 25 rad/s²), fast enough for the circle, limited enough that the random
    /// starts saturate it.
    pub const BASE: VelocityBase = VelocityBase::JACKAL;

    /// The same robots on velocity bases under the kinematic law (`K_e = 1.5`;
    /// `K_z` is not used), at step `dt`.
    pub fn velocity_engine(
        &self,
        base: VelocityBase,
        dt: f64,
    ) -> Result<VelocityEngine, EngineError> {
        let batch = VelocityBatch::new(base, self.topology, self.reference(), dt)?;
        VelocityEngine::new(batch, self.members())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_formation_is_a_function_of_the_seed_and_in_range() {
        let f = BenchFormation {
            agents: 500,
            topology: Topology::Star,
            seed: 7,
        };
        let a: Vec<Member> = f.members().collect();
        assert_eq!(a, f.members().collect::<Vec<_>>());
        let other: Vec<Member> = BenchFormation { seed: 8, ..f }.members().collect();
        assert_ne!(a, other);
        for m in &a {
            assert!(m.start.x.abs() <= 2.0 && m.start.y.abs() <= 2.0);
            assert!(m.start.theta.abs() <= std::f64::consts::PI);
            assert!((0.2..0.8).contains(&m.placement.lx_off()));
            assert!(m.placement.ly_off().abs() <= 1.0);
            assert_eq!((m.start.v, m.start.omega), (0.0, 0.0));
        }
        // Uniform draws: the means are near the middles.
        let mean = |f: &dyn Fn(&Member) -> f64| a.iter().map(f).sum::<f64>() / a.len() as f64;
        assert!(mean(&|m| m.start.x).abs() < 0.2);
        assert!((mean(&|m| m.placement.lx_off()) - 0.5).abs() < 0.03);
    }
}
