#![allow(clippy::unwrap_used)]
//! The batch engine against the scalar simulator (the reference
//! implementation): same states and same `e`, `z`, `u` to a relative 1e-9 after
//! many steps, for stars and chains of several sizes and seeds; the same bits
//! on one thread or two, stepped at once or one step at a time.

mod common;
use common::{assert_engine_agrees, state_pairs};

use echelon::SimError;
use echelon::control::{Gains, Variant};
use echelon::engine::{BenchFormation, Engine, EngineError, Topology};
use echelon::formation::Leader;
use echelon::lycomp::{LyComp, LyDerivatives, Placement, PlacementSpec};
use echelon::model::{RobotParams, State};
use echelon::reference::{Lemniscate, Reference};
use echelon::rng::SplitMix64;
use echelon::{AgentSpec, Plan, SimConfig, Simulation, Timing};

/// Steps both `steps` times and compares states and controller outputs;
/// returns the largest relative difference seen.
fn compare(agents: Vec<AgentSpec>, reference: Reference, dt: f64, steps: u64) -> f64 {
    let config = SimConfig::new(dt, steps as f64 * dt, Timing::Continuous).unwrap();
    let plan = Plan::new(agents, reference, config).unwrap();
    let mut sim = Simulation::new(&plan);
    let mut engine = Engine::from_plan(&plan).unwrap();
    let mut worst = 0.0f64;
    let mut check = |sim: &mut Simulation, engine: &Engine| {
        let probes = engine.probes();
        let frame = sim.frame();
        assert_eq!(engine.step_index(), frame.step);
        assert_eq!(probes.len(), frame.states.len());
        for (i, ((s, o), p)) in frame
            .states
            .iter()
            .zip(frame.outputs)
            .zip(&probes)
            .enumerate()
        {
            let e = engine.state(i);
            let law = [
                (p.e[0], o.e[0]),
                (p.e[1], o.e[1]),
                (p.z[0], o.z[0]),
                (p.z[1], o.z[1]),
                (p.u[0], o.command.u1),
                (p.u[1], o.command.u2),
            ];
            let pairs = state_pairs(&e, s).into_iter().chain(law);
            worst = worst.max(assert_engine_agrees(pairs, i, frame.t));
        }
    };
    check(&mut sim, &engine);
    // Step in uneven pieces so that tiles and single steps both occur.
    let mut done = 0;
    for chunk in [1, 63, 64, 65, 200].iter().cycle() {
        let k = (*chunk).min(steps - done);
        for _ in 0..k {
            sim.step().unwrap();
        }
        engine.run(k).unwrap();
        done += k;
        check(&mut sim, &engine);
        if done == steps {
            break;
        }
    }
    worst
}

fn formation(agents: usize, topology: Topology, seed: u64) -> BenchFormation {
    BenchFormation {
        agents,
        topology,
        seed,
    }
}

#[test]
fn star_matches_the_scalar_simulator() {
    for (n, seed) in [(1, 1), (3, 2), (4, 3), (9, 4), (37, 5)] {
        let f = formation(n, Topology::Star, seed);
        let worst = compare(f.agent_specs(), f.reference(), 0.01, 2000);
        assert!(worst < 1e-9, "{worst}");
    }
}

#[test]
fn chain_matches_the_scalar_simulator() {
    // Random chains (the benchmark's column, random start poses).
    for (n, seed) in [(1, 11), (2, 12), (5, 13), (8, 14)] {
        let f = formation(n, Topology::Chain, seed);
        let worst = compare(f.agent_specs(), f.reference(), 0.01, 2000);
        assert!(worst < 1e-9, "{worst}");
    }
    // Columns that start near formation: 50 agents for 20 s; 270 (across the
    // boundary between two of the engine's 256-agent segments) for 0.5 s and
    // 600 (two halves on two threads when the pool has two) for 0.1 s, before
    // a long column's own sensitivity reaches 1e-9 (see below).
    for (n, seed, steps) in [(50, 3, 2000), (270, 4, 50), (600, 5, 10)] {
        let f = formation(n, Topology::Chain, seed);
        let worst = compare(near_formation(&f), f.reference(), 0.01, steps);
        assert!(worst < 1e-9, "{worst}");
    }
}

/// The column of `f` placed almost in formation: each robot `L_X` behind the
/// one before, within 0.1 m and 0.1 rad.
fn near_formation(f: &BenchFormation) -> Vec<AgentSpec> {
    let mut rng = SplitMix64::new(f.seed + 100);
    let mut x = 0.0;
    let mut specs = f.agent_specs();
    for s in &mut specs {
        x -= s.placement().lx();
        let start = State {
            x: x + rng.uniform(-0.1, 0.1),
            y: rng.uniform(-0.1, 0.1),
            theta: rng.uniform(-0.1, 0.1),
            ..s.start()
        };
        *s = s.clone().with_start(start).unwrap();
    }
    specs
}

/// Long chains are chaotic: a change of one unit in the last place of one
/// start coordinate grows to order one within seconds, in the scalar
/// simulator alone. No implementation that rounds differently can agree with
/// it to 1e-9 there; the engine agrees as well as that physics allows: its
/// distance from the scalar run stays within 100 times the distance between
/// two scalar runs one ulp apart, at every checkpoint.
#[test]
fn long_chains_agree_as_well_as_their_sensitivity_allows() {
    let f = formation(300, Topology::Chain, 21);
    let config = SimConfig::new(0.01, 20.0, Timing::Continuous).unwrap();
    let mut specs = f.agent_specs();
    let plan = Plan::new(specs.clone(), f.reference(), config).unwrap();
    let mut sim = Simulation::new(&plan);
    let mut engine = Engine::from_plan(&plan).unwrap();
    let first = specs[0].start();
    let nudge = State {
        x: first.x.next_up(),
        ..first
    };
    specs[0] = specs[0].clone().with_start(nudge).unwrap();
    let mut nudged = Simulation::new(&Plan::new(specs, f.reference(), config).unwrap());
    let distance = |a: &[State], b: &[State]| {
        a.iter()
            .zip(b)
            .flat_map(|(a, b)| [(a.x, b.x), (a.y, b.y), (a.theta, b.theta), (a.v, b.v)])
            .map(|(a, b)| (a - b).abs() / a.abs().max(b.abs()).max(1.0))
            .fold(0.0, f64::max)
    };
    let mut grew = false;
    for _ in 0..40 {
        for _ in 0..50 {
            sim.step().unwrap();
            nudged.step().unwrap();
        }
        engine.run(50).unwrap();
        let ours = distance(&engine.states(), sim.states());
        let physics = distance(nudged.states(), sim.states());
        grew |= physics > 1e-3;
        assert!(
            ours <= 100.0 * physics.max(1e-13),
            "t = {}: engine {ours:e} vs one ulp {physics:e}",
            sim.time()
        );
    }
    assert!(grew, "the chain is chaotic (one ulp grows past 1e-3)");
}

/// A variety the bench does not exercise: exact eq. 5, no compensation, the
/// complete law, torque limits, a lemniscate, agents not at rest.
#[test]
fn other_laws_placements_and_references_match() {
    let lemniscate = Reference::Lemniscate(Lemniscate::new(2.0, 0.2, [0.0, 0.0]).unwrap());
    let limited = RobotParams::AGENT2.with_torque_limit(Some(4.0)).unwrap();
    for (comp, variant, robot, leader_of) in [
        (LyComp::Exact, Variant::Paper, RobotParams::AGENT2, false),
        (LyComp::Exact, Variant::Complete, RobotParams::AGENT2, true),
        (LyComp::None, Variant::Complete, RobotParams::AGENT1, true),
        (LyComp::Fit, Variant::Paper, limited, false),
    ] {
        let agents: Vec<AgentSpec> = (0..6)
            .map(|i| {
                let k = i as f64;
                AgentSpec::new(
                    format!("agent {}", i + 1),
                    robot,
                    if leader_of && i > 0 {
                        Leader::Agent(i - 1)
                    } else {
                        Leader::Reference
                    },
                    Placement::new(PlacementSpec {
                        lx_off: 0.3 + 0.1 * k,
                        ly_off: 0.5 - 0.2 * k,
                        l: 0.05,
                        comp,
                        derivatives: LyDerivatives::Neglect,
                    })
                    .unwrap(),
                    Gains::new(1.0 + 0.2 * k, 8.0 + k).unwrap(),
                    variant,
                    State {
                        x: 1.5 - k,
                        y: -0.5 * k,
                        theta: 0.3 * k,
                        v: 0.1 * k,
                        omega: -0.05 * k,
                    },
                )
                .unwrap()
            })
            .collect();
        compare(agents, lemniscate.clone(), 0.005, 1500);
    }
}

fn bits(s: &[State]) -> Vec<u64> {
    s.iter()
        .flat_map(|s| [s.x, s.y, s.theta, s.v, s.omega].map(f64::to_bits))
        .collect()
}

fn on_threads_in_place(e: &mut Engine, threads: usize, steps: u64) {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| e.run(steps)).unwrap();
}

/// `steps` steps of `e` on a pool of `threads`, at once.
fn on_threads(mut e: Engine, threads: usize, steps: u64) -> Vec<State> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| e.run(steps)).unwrap();
    e.states()
}

#[test]
fn results_do_not_depend_on_threads_or_on_how_steps_are_grouped() {
    // A star spread over blocks; a chain long enough (≥ 512 agents) to run
    // as two halves one tile apart on two threads.
    for (f, steps) in [
        (formation(203, Topology::Star, 99), 500),
        (formation(1100, Topology::Chain, 98), 150),
    ] {
        let one = on_threads(f.engine(0.002).unwrap(), 1, steps);
        let two = on_threads(f.engine(0.002).unwrap(), 2, steps);
        assert_eq!(bits(&one), bits(&two), "{:?}", f.topology);
        let mut stepped = f.engine(0.002).unwrap();
        for _ in 0..steps {
            stepped.step().unwrap();
        }
        assert_eq!(bits(&one), bits(&stepped.states()), "{:?}", f.topology);
        let mut uneven = f.engine(0.002).unwrap();
        for k in [1, 100, steps - 101] {
            on_threads_in_place(&mut uneven, 2, k);
        }
        assert_eq!(bits(&one), bits(&uneven.states()), "{:?}", f.topology);
    }
    let f = formation(203, Topology::Star, 99);
    // The formation converges: the benchmark simulates something real.
    let e = f.engine(0.002).unwrap();
    let start_err = e
        .probes()
        .iter()
        .map(|p| p.e[0].hypot(p.e[1]))
        .fold(0.0, f64::max);
    let mut e = e;
    e.run(10_000).unwrap();
    let end_err = e
        .probes()
        .iter()
        .map(|p| p.e[0].hypot(p.e[1]))
        .fold(0.0, f64::max);
    assert!(start_err > 0.5 && end_err < 1e-3, "{start_err} → {end_err}");
}

#[test]
fn what_the_engine_cannot_do_is_refused() {
    let f = formation(4, Topology::Chain, 1);
    let mut specs = f.agent_specs();
    specs[2] = specs[2].clone().with_leader(Leader::Reference);
    let err = Engine::from_agents(&specs, f.reference(), 0.01).unwrap_err();
    assert!(matches!(err, EngineError::Unsupported(_)), "{err}");
    let mut specs = f.agent_specs();
    let s = &specs[1];
    specs[1] = AgentSpec::new(
        s.name(),
        RobotParams::AGENT2,
        s.leader(),
        s.placement(),
        s.gains(),
        echelon::Variant::Paper,
        s.start(),
    )
    .unwrap();
    assert!(Engine::from_agents(&specs, f.reference(), 0.01).is_err());
    let mut specs = f.agent_specs();
    let p = specs[3].placement();
    specs[3] = specs[3].clone().with_placement(
        Placement::new(PlacementSpec {
            derivatives: LyDerivatives::Exact,
            ..p.spec()
        })
        .unwrap(),
    );
    assert!(Engine::from_agents(&specs, f.reference(), 0.01).is_err());
    // Impossible values cannot reach the engine: the constructors refuse them.
    let err = Gains::new(1.5, -1.0).unwrap_err();
    assert_eq!(err.field, "kz", "{err}");
    assert!(Engine::from_agents(&[], f.reference(), 0.01).is_err());
    assert!(f.engine(0.0).is_err());
    let config = SimConfig::new(0.01, 1.0, Timing::Sampled { period: 0.02 }).unwrap();
    let plan = Plan::new(f.agent_specs(), f.reference(), config).unwrap();
    assert!(Engine::from_plan(&plan).is_err());
    // Odometry: the controllers act on estimates, which the engine does not model.
    let config = SimConfig::new(0.01, 1.0, Timing::Continuous).unwrap();
    let spec =
        echelon::odometry::OdometrySpec::new(0.01, echelon::odometry::ErrorModel::PERFECT, None)
            .unwrap();
    let plan = Plan::new(f.agent_specs(), f.reference(), config).unwrap();
    let with_odometry = plan
        .clone()
        .with_odometry(vec![Some(spec), None, None, None], 0)
        .unwrap();
    let err = Engine::from_plan(&with_odometry).unwrap_err();
    assert!(err.to_string().contains("odometry"), "{err}");
    // Safety filters: the engine has none.
    let safety = echelon::plan::SafetySpec {
        agents: vec![Some(echelon::safety::SafetyConfig::new(0.01, 1.0, 1.0).unwrap()); 4],
        obstacles: Vec::new(),
    };
    let err = Engine::from_plan(&plan.with_safety(safety).unwrap()).unwrap_err();
    assert!(err.to_string().contains("safety"), "{err}");
}

#[test]
fn a_blow_up_is_reported_like_the_scalar_simulator_does() {
    // L_X barely positive and huge gains with a large step: the law diverges.
    // In a star; and in the second half of a chain that runs on two threads.
    for (f, bad) in [
        (formation(6, Topology::Star, 3), 4),
        (formation(600, Topology::Chain, 3), 400),
    ] {
        let mut specs = f.agent_specs();
        specs[bad] = specs[bad]
            .clone()
            .with_placement(
                Placement::new(PlacementSpec {
                    lx_off: -0.049_999,
                    ly_off: 0.0,
                    l: 0.05,
                    comp: LyComp::Fit,
                    derivatives: LyDerivatives::Neglect,
                })
                .unwrap(),
            )
            .with_gains(Gains::new(50.0, 500.0).unwrap());
        let dt = 0.05;
        let config = SimConfig::new(dt, 100.0, Timing::Continuous).unwrap();
        let mut sim = Simulation::new(&Plan::new(specs.clone(), f.reference(), config).unwrap());
        let want = loop {
            if let Err(e) = sim.step() {
                break e;
            }
        };
        let mut engine = Engine::from_agents(&specs, f.reference(), dt).unwrap();
        let got = engine.run(2000).unwrap_err();
        // The same agent, time and quantity (the engine has no agent names;
        // its fused arithmetic differs from the scalar simulator in the last
        // bits, and a blown-up value shows it).
        let key = |e: &SimError| match e {
            SimError::Diverged {
                agent, t, breach, ..
            } => (*agent, *t, breach.quantity),
            other => panic!("not a divergence: {other}"),
        };
        assert_eq!(key(&got), key(&want), "{got} / {want}");
        assert_eq!(engine.run(1).unwrap_err(), got, "the engine stays failed");
    }
}
