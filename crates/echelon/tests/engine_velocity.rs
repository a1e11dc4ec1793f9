#![allow(clippy::unwrap_used)] // tests fail loudly by design
//! The velocity-base kernel of the batch engine against a scalar RK4
//! reference built from `base.rs` and `kinematic_law`: same states, `e`,
//! commands and saturated ticks to a relative 1e-9 after many steps, for
//! stars and short chains, on an ideal base, lagged and speed- and
//! acceleration-limited bases (joint and per-axis) and a base with one lagged
//! axis; the same bits on one thread or two.
//!
//! The reference evaluates the law in every RK4 stage (a continuous-time
//! controller), leaders first; a robot leader's `ṗ_d` and `L_Ycomp` come from
//! the speeds its base moves at (`VelocityBase::speeds`); each command is
//! limited (`VelocityBase::limit`) before `VelocityBase::derivative`, and the
//! state is settled (`VelocityBase::settle`) after each step with the command
//! at the step's end. A tick is saturated when the command at the step's start
//! exceeds a speed limit.

mod common;
use common::{assert_engine_agrees, relative, state_pairs};

use echelon::base::{AccelLimit, VelocityBase, VelocityBaseSpec, VelocityCommand};
use echelon::control::LeaderMotion;
use echelon::engine::{
    BenchFormation, EngineError, Member, Topology, VelocityBatch, VelocityEngine,
};
use echelon::kinematic::kinematic_law;
use echelon::model::State;
use echelon::reference::{Lemniscate, Order, Reference, Trajectory};

/// The scalar closed loop.
struct Scalar {
    base: VelocityBase,
    topology: Topology,
    reference: Reference,
    members: Vec<Member>,
    dt: f64,
    xs: Vec<State>,
    step: u64,
    saturated: Vec<u64>,
}

/// One agent's law at one instant: `e`, the law's command, the applied one.
type Out = ([f64; 2], VelocityCommand, VelocityCommand);

impl Scalar {
    fn new(
        base: VelocityBase,
        topology: Topology,
        reference: Reference,
        members: Vec<Member>,
        dt: f64,
    ) -> Scalar {
        let xs = members.iter().map(|m| m.start).collect();
        let saturated = vec![0; members.len()];
        Scalar {
            base,
            topology,
            reference,
            members,
            dt,
            xs,
            step: 0,
            saturated,
        }
    }

    /// Every agent's law at `(t, xs)`, leaders first.
    fn evaluate(&self, t: f64, xs: &[State]) -> Vec<Out> {
        let jet = self.reference.eval(t, Order::Two);
        let mut outs: Vec<Out> = Vec::with_capacity(xs.len());
        for (i, m) in self.members.iter().enumerate() {
            let (leader, off) = match (self.topology, i) {
                (Topology::Star, _) | (Topology::Chain, 0) => (
                    LeaderMotion::of_jet(&jet),
                    m.placement.offset_for_reference(&jet),
                ),
                (Topology::Chain, _) => {
                    let (v, omega) = self.base.speeds(&xs[i - 1], outs[i - 1].2);
                    let moving = State {
                        v,
                        omega,
                        ..xs[i - 1]
                    };
                    (
                        LeaderMotion::of_robot(&moving, 0.0),
                        m.placement.offset_for_robot(v, omega),
                    )
                }
            };
            let out = kinematic_law(&xs[i], &leader, &off, m.gains.ke());
            outs.push((out.e, out.cmd, self.base.limit(out.cmd).0));
        }
        outs
    }

    fn derivatives(&self, t: f64, xs: &[State]) -> Vec<State> {
        let outs = self.evaluate(t, xs);
        xs.iter()
            .zip(&outs)
            .map(|(x, o)| self.base.derivative(x, o.2))
            .collect()
    }

    fn step(&mut self) {
        let (dt, t) = (self.dt, self.step as f64 * self.dt);
        let add = |xs: &[State], ks: &[State], h: f64| -> Vec<State> {
            xs.iter().zip(ks).map(|(x, k)| x.add_scaled(k, h)).collect()
        };
        let start = self.evaluate(t, &self.xs);
        for (n, o) in self.saturated.iter_mut().zip(start) {
            *n += u64::from(self.base.limit(o.1).1);
        }
        let xs = &self.xs;
        let k1 = self.derivatives(t, xs);
        let k2 = self.derivatives(t + 0.5 * dt, &add(xs, &k1, 0.5 * dt));
        let k3 = self.derivatives(t + 0.5 * dt, &add(xs, &k2, 0.5 * dt));
        let k4 = self.derivatives(t + dt, &add(xs, &k3, dt));
        let next: Vec<State> = (0..xs.len())
            .map(|i| xs[i].rk4_combine([&k1[i], &k2[i], &k3[i], &k4[i]], dt / 6.0))
            .collect();
        let outs = self.evaluate(t + dt, &next);
        self.xs = next
            .iter()
            .zip(&outs)
            .map(|(x, o)| self.base.settle(x, o.2))
            .collect();
        self.step += 1;
    }
}

/// Steps both `steps` times in uneven pieces, comparing states, `e`,
/// commands and saturated ticks at every checkpoint; returns the largest
/// relative difference and the total of saturated ticks.
fn compare(
    base: VelocityBase,
    topology: Topology,
    reference: Reference,
    members: Vec<Member>,
    dt: f64,
    steps: u64,
) -> (f64, u64) {
    let batch = VelocityBatch::new(base, topology, reference.clone(), dt).unwrap();
    let mut engine = VelocityEngine::new(batch, members.clone()).unwrap();
    let mut scalar = Scalar::new(base, topology, reference, members, dt);
    let mut worst = 0.0f64;
    let mut check = |scalar: &Scalar, engine: &VelocityEngine| {
        assert_eq!(engine.step_index(), scalar.step);
        let t = scalar.step as f64 * dt;
        let outs = scalar.evaluate(t, &scalar.xs);
        let probes = engine.probes();
        assert_eq!(probes.len(), outs.len());
        for (i, ((s, o), p)) in scalar.xs.iter().zip(&outs).zip(&probes).enumerate() {
            let e = engine.state(i);
            let law = [
                (p.e[0], o.0[0]),
                (p.e[1], o.0[1]),
                (p.command.v, o.1.v),
                (p.command.omega, o.1.omega),
                (p.applied.v, o.2.v),
                (p.applied.omega, o.2.omega),
            ];
            let pairs = state_pairs(&e, s).into_iter().chain(law);
            worst = worst.max(assert_engine_agrees(pairs, i, t));
            assert_eq!(p.saturated, base.limit(o.1).1, "agent {} at t = {t}", i + 1);
            assert_eq!(
                engine.saturated_ticks(i),
                scalar.saturated[i],
                "agent {} at t = {t}",
                i + 1
            );
            // The limits hold in every state.
            assert!(e.v.abs() <= base.v_max() && e.omega.abs() <= base.omega_max());
        }
    };
    check(&scalar, &engine);
    let mut done = 0;
    for chunk in [1, 63, 64, 65, 200].iter().cycle() {
        let k = (*chunk).min(steps - done);
        for _ in 0..k {
            scalar.step();
        }
        engine.run(k).unwrap();
        done += k;
        check(&scalar, &engine);
        if done == steps {
            break;
        }
    }
    (worst, scalar.saturated.iter().sum())
}

fn formation(agents: usize, topology: Topology, seed: u64) -> BenchFormation {
    BenchFormation {
        agents,
        topology,
        seed,
    }
}

/// A slow base with unequal lags and tight limits (saturates often).
fn slow() -> VelocityBase {
    VelocityBase::new(VelocityBaseSpec {
        tau_v: 0.2,
        tau_omega: 0.05,
        v_max: 0.6,
        omega_max: 1.2,
        a_max: 1.0,
        alpha_max: 4.0,
        ..VelocityBase::IDEAL.spec()
    })
    .unwrap()
}

/// The bases every test runs: the ideal one, the benchmark's (Jackal), a slow
/// one with joint and with per-axis acceleration limits, and one whose `ω`
/// follows its command without lag (speed-limited).
fn bases() -> Vec<(&'static str, VelocityBase)> {
    vec![
        ("ideal", VelocityBase::IDEAL),
        ("jackal", VelocityBase::JACKAL),
        ("slow, joint", slow()),
        ("slow, per axis", slow().with_accel(AccelLimit::PerAxis)),
        (
            "ω without lag",
            VelocityBase::new(VelocityBaseSpec {
                tau_v: 0.2,
                v_max: 0.6,
                omega_max: 1.2,
                a_max: 1.0,
                ..VelocityBase::IDEAL.spec()
            })
            .unwrap(),
        ),
    ]
}

/// For every base and every formation `(agents, seed)` of `topology`: the
/// batch engine within 1e-9 of the scalar reference, and a limited base's
/// limits acting somewhere.
fn matches_the_scalar_reference(topology: Topology, formations: &[(usize, u64)]) {
    for (name, base) in bases() {
        let mut ticks = 0;
        for &(n, seed) in formations {
            let f = formation(n, topology, seed);
            let (worst, saturated) = compare(
                base,
                topology,
                f.reference(),
                f.members().collect(),
                0.01,
                1500,
            );
            eprintln!("{name}, {topology:?} of {n}: worst {worst:e}, {saturated} saturated ticks");
            assert!(worst < 1e-9, "{name}: {worst}");
            ticks += saturated;
        }
        if base.v_max().is_finite() {
            assert!(ticks > 0, "{name}: the limits never acted");
        }
    }
}

#[test]
fn star_matches_the_scalar_reference() {
    matches_the_scalar_reference(Topology::Star, &[(1, 1), (9, 4), (37, 5)]);
}

#[test]
fn chain_matches_the_scalar_reference() {
    matches_the_scalar_reference(Topology::Chain, &[(1, 11), (2, 12), (5, 13), (11, 14)]);
}

#[test]
fn a_lemniscate_and_exact_compensation_match() {
    use echelon::control::Gains;
    use echelon::lycomp::{LyComp, LyDerivatives, Placement, PlacementSpec};
    let reference = Reference::Lemniscate(Lemniscate::new(2.0, 0.2, [0.0, 0.0]).unwrap());
    for comp in [LyComp::Exact, LyComp::None] {
        let members: Vec<Member> = (0..6)
            .map(|i| {
                let k = f64::from(i);
                Member::new(
                    State {
                        x: -0.5 * k,
                        y: 0.3 - 0.1 * k,
                        theta: 0.2 * k,
                        v: 0.1,
                        omega: -0.05 * k,
                    },
                    Placement::new(PlacementSpec {
                        lx_off: 0.4,
                        ly_off: 0.2 * k - 0.5,
                        l: 0.05,
                        comp,
                        derivatives: LyDerivatives::Neglect,
                    })
                    .unwrap(),
                    Gains::new(1.0 + 0.2 * k, 10.0).unwrap(),
                )
                .unwrap()
            })
            .collect();
        for topology in [Topology::Star, Topology::Chain] {
            for (name, base) in [
                ("jackal", VelocityBase::JACKAL),
                ("ideal", VelocityBase::IDEAL),
            ] {
                let (worst, _) = compare(
                    base,
                    topology,
                    reference.clone(),
                    members.clone(),
                    0.005,
                    2000,
                );
                eprintln!("{comp:?}, {topology:?}, {name}: worst {worst:e}");
                assert!(worst < 1e-9, "{comp:?} {topology:?} {name}: {worst}");
            }
        }
    }
}

#[test]
fn results_do_not_depend_on_threads_or_stepping() {
    // A chain of 512 agents or more runs as two halves on two threads.
    for (topology, n) in [
        (Topology::Star, 203),
        (Topology::Chain, 203),
        (Topology::Chain, 600),
    ] {
        for base in [VelocityBase::JACKAL, VelocityBase::IDEAL] {
            let f = formation(n, topology, 9);
            let mut one = f.velocity_engine(base, 0.001).unwrap();
            let mut two = one.clone();
            let mut single = one.clone();
            let pool = |k| {
                rayon::ThreadPoolBuilder::new()
                    .num_threads(k)
                    .build()
                    .unwrap()
            };
            pool(1).install(|| one.run(300)).unwrap();
            pool(2).install(|| two.run(300)).unwrap();
            for _ in 0..300 {
                single.step().unwrap();
            }
            let bits = |e: &VelocityEngine| -> Vec<u64> {
                e.states()
                    .iter()
                    .flat_map(|s| [s.x, s.y, s.theta, s.v, s.omega].map(f64::to_bits))
                    .collect()
            };
            assert_eq!(bits(&one), bits(&two), "{topology:?}");
            assert_eq!(bits(&one), bits(&single), "{topology:?}");
            let ticks = |e: &VelocityEngine| {
                (0..e.len())
                    .map(|i| e.saturated_ticks(i))
                    .collect::<Vec<_>>()
            };
            assert_eq!(ticks(&one), ticks(&two));
        }
    }
}

#[test]
fn bad_batches_are_refused() {
    let f = formation(3, Topology::Star, 1);
    // A lag shorter than the step.
    let err =
        VelocityBatch::new(VelocityBase::JACKAL, Topology::Star, f.reference(), 0.1).unwrap_err();
    assert!(err.to_string().contains("tau_v"), "{err}");
    // A base with an impossible limit cannot even be built.
    let err = VelocityBase::new(VelocityBaseSpec {
        tau_v: 0.05,
        tau_omega: 0.05,
        v_max: -1.0,
        omega_max: 4.0,
        a_max: 20.0,
        alpha_max: 25.0,
        ..VelocityBase::IDEAL.spec()
    })
    .unwrap_err();
    assert!(err.to_string().contains("v_max"), "{err}");
    let batch =
        VelocityBatch::new(VelocityBase::JACKAL, Topology::Star, f.reference(), 0.001).unwrap();
    assert!(matches!(
        VelocityEngine::new(batch, std::iter::empty()),
        Err(EngineError::Unsupported(_))
    ));
}

#[test]
fn a_diverging_formation_fails_like_the_torque_engine() {
    // A gain so large that RK4 at this step is unstable on the ideal base.
    use echelon::control::Gains;
    let f = formation(10, Topology::Star, 3);
    let members: Vec<Member> = f
        .members()
        .map(|m| Member::new(m.start, m.placement, Gains::new(1e4, 10.0).unwrap()).unwrap())
        .collect();
    let batch =
        VelocityBatch::new(VelocityBase::IDEAL, Topology::Star, f.reference(), 0.01).unwrap();
    let mut e = VelocityEngine::new(batch, members).unwrap();
    let err = e.run(10_000).unwrap_err();
    assert!(err.to_string().contains("agent"), "{err}");
    assert!(e.run(1).is_err(), "a failed engine stays failed");
}

/// The batch engine against the scalar [`Simulation`] itself (not only the
/// reference above): the same velocity-base formations, built as scenario
/// agents (`AgentSpec::velocity`), give the same states, `e`, commands and
/// saturation flags to a relative 1e-9 after 1 500 steps, stars and chains,
/// ideal and limited bases.
#[test]
fn the_engine_agrees_with_the_simulator() {
    use echelon::base::VelocityRobot;
    use echelon::formation::Leader;
    use echelon::{AgentSpec, Plan, SimConfig, Simulation, Timing};
    let (dt, steps) = (0.01, 1500);
    for (name, base) in bases() {
        let mut ticks = 0;
        for (topology, n, seed) in [(Topology::Star, 9, 4), (Topology::Chain, 5, 13)] {
            let f = formation(n, topology, seed);
            // A base starts within its limits (AgentSpec::velocity refuses
            // anything else): the bench formation's starts are at rest.
            let members: Vec<Member> = f.members().collect();
            let agents: Vec<AgentSpec> = members
                .iter()
                .enumerate()
                .map(|(i, m)| {
                    let leader = match (topology, i) {
                        (Topology::Chain, i) if i > 0 => Leader::Agent(i - 1),
                        _ => Leader::Reference,
                    };
                    let robot = VelocityRobot::new(base, 0.15, 0.05).unwrap();
                    AgentSpec::velocity(
                        format!("agent {}", i + 1),
                        robot,
                        leader,
                        m.placement,
                        m.gains,
                        m.start,
                    )
                    .unwrap()
                })
                .collect();
            let config = SimConfig::new(dt, steps as f64 * dt, Timing::Continuous).unwrap();
            let mut sim = Simulation::new(&Plan::new(agents, f.reference(), config).unwrap());
            let batch = VelocityBatch::new(base, topology, f.reference(), dt).unwrap();
            let mut engine = VelocityEngine::new(batch, members).unwrap();
            let mut worst = 0.0f64;
            for chunk in [1, 37, 462, 1000] {
                for _ in 0..chunk {
                    sim.step().unwrap();
                }
                engine.run(chunk).unwrap();
                assert_eq!(engine.step_index(), sim.step_index());
                let probes = engine.probes();
                let frame = sim.frame();
                for (i, (s, o)) in frame.states.iter().zip(frame.outputs).enumerate() {
                    let e = engine.state(i);
                    let p = &probes[i];
                    let v = o.velocity.expect("a velocity agent reports its command");
                    for (a, b) in state_pairs(&e, s).into_iter().chain([
                        (p.e[0], o.e[0]),
                        (p.e[1], o.e[1]),
                        (p.command.v, v.command.v),
                        (p.command.omega, v.command.omega),
                        (p.applied.v, v.applied.v),
                        (p.applied.omega, v.applied.omega),
                    ]) {
                        worst = worst.max(relative(a, b));
                    }
                    assert_eq!(p.saturated, v.saturated, "{name}: agent {}", i + 1);
                    ticks += u64::from(v.saturated);
                }
            }
            eprintln!("{name}, {topology:?} of {n}: engine vs simulator, worst {worst:e}");
            assert!(worst < 1e-9, "{name}, {topology:?}: {worst}");
        }
        if base.v_max().is_finite() {
            assert!(
                ticks > 0,
                "{name}: the limits never acted at the checkpoints"
            );
        }
    }
}
