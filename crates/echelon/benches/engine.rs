//! The speed suite: one law evaluation, one RK4 agent-step, stars and chains
//! of 4, 1 000 and 100 000 agents (each also on a state buffer the caller
//! owns, `run_on`), a sweep of 256 runs, and the velocity-base kernel (Jackal
//! bases, kinematic law) on stars and chains. `cargo bench -p echelon`;
//! BENCHMARKS.md has the figures. Throughputs are in agent-steps (elements).

use std::hint::black_box;
use std::time::Duration;

use criterion::{BatchSize, Criterion, Throughput, criterion_group, criterion_main};

use echelon::control::{Gains, LeaderMotion, Offset, Variant, law};
use echelon::engine::{self, BenchFormation, Engine, Topology};
use echelon::model::{RobotParams, State};
use echelon::{Plan, SimConfig, Simulation, Timing};

const DT: f64 = 0.001;

fn formation(agents: usize, topology: Topology) -> Engine {
    let f = BenchFormation {
        agents,
        topology,
        seed: 1,
    };
    match f.engine(DT) {
        Ok(e) => e,
        Err(e) => panic!("{e}"),
    }
}

fn law_evaluation(c: &mut Criterion) {
    let robot = RobotParams::AGENT1;
    let s = State {
        x: 0.3,
        y: -1.2,
        theta: 0.7,
        v: 0.4,
        omega: 0.05,
    };
    let leader = LeaderMotion {
        p: [1.0, 0.5],
        dp: [0.45, 0.2],
        ddp: [-0.02, 0.045],
    };
    let off = Offset {
        lx: 0.55,
        ly: 0.3,
        dly: 0.0,
        ddly: 0.0,
    };
    c.bench_function("law/one evaluation (eqs. 7-13, scalar)", |b| {
        b.iter(|| {
            law(
                black_box(&robot),
                black_box(&s),
                black_box(&leader),
                black_box(&off),
                Gains::PAPER,
                Variant::Paper,
            )
        })
    });
}

fn rk4_agent_step(c: &mut Criterion) {
    let mut g = c.benchmark_group("rk4 agent-step");
    // One block of eight agents, 64 steps (one tile) per iteration.
    g.throughput(Throughput::Elements(8 * 64));
    g.bench_function("engine, star of 8 (one block)", |b| {
        b.iter_batched_ref(
            || formation(8, Topology::Star),
            |e| e.run(64),
            BatchSize::SmallInput,
        )
    });
    // The scalar reference implementation, one agent, one step.
    let f = BenchFormation {
        agents: 1,
        topology: Topology::Star,
        seed: 1,
    };
    let config = SimConfig::new(DT, 1e6, Timing::Continuous).expect("valid settings");
    let mut sim =
        match Plan::new(f.agent_specs(), f.reference(), config).map(|p| Simulation::new(&p)) {
            Ok(s) => s,
            Err(e) => panic!("{e}"),
        };
    g.throughput(Throughput::Elements(1));
    g.bench_function("scalar Simulation, 1 agent", |b| b.iter(|| sim.step()));
    g.finish();
}

fn formations(c: &mut Criterion) {
    for topology in [Topology::Star, Topology::Chain] {
        let mut g = c.benchmark_group(format!("{topology:?}").to_lowercase());
        g.sample_size(10).measurement_time(Duration::from_secs(3));
        for (agents, steps) in [(4usize, 1000u64), (1000, 64), (100_000, 2)] {
            g.throughput(Throughput::Elements(agents as u64 * steps));
            let mut e = formation(agents, topology);
            g.bench_function(format!("N = {agents}"), |b| b.iter(|| e.run(steps)));
            // The same on a state buffer the caller owns (`run_on`).
            let mut e = formation(agents, topology);
            let mut state = e.columns();
            g.bench_function(format!("N = {agents}, caller's buffer"), |b| {
                b.iter(|| e.run_on(&mut state, steps))
            });
        }
        g.finish();
    }
}

fn sweep(c: &mut Criterion) {
    let mut g = c.benchmark_group("sweep");
    g.sample_size(10);
    let steps = 100;
    g.throughput(Throughput::Elements(256 * 4 * steps));
    let mut runs: Vec<Engine> = (0..256)
        .map(|seed| {
            let f = BenchFormation {
                agents: 4,
                topology: Topology::Star,
                seed,
            };
            match f.engine(DT) {
                Ok(e) => e,
                Err(e) => panic!("{e}"),
            }
        })
        .collect();
    g.bench_function("256 runs of 4 agents", |b| {
        b.iter(|| engine::sweep(&mut runs, steps))
    });
    g.finish();
}

fn velocity_formations(c: &mut Criterion) {
    for topology in [Topology::Star, Topology::Chain] {
        let mut g = c.benchmark_group(format!("velocity {topology:?}").to_lowercase());
        g.sample_size(10).measurement_time(Duration::from_secs(3));
        for (agents, steps) in [(1000usize, 64u64), (100_000, 2)] {
            g.throughput(Throughput::Elements(agents as u64 * steps));
            let f = BenchFormation {
                agents,
                topology,
                seed: 1,
            };
            let mut e = match f.velocity_engine(BenchFormation::BASE, DT) {
                Ok(e) => e,
                Err(e) => panic!("{e}"),
            };
            g.bench_function(format!("N = {agents}"), |b| b.iter(|| e.run(steps)));
        }
        g.finish();
    }
}

criterion_group!(
    benches,
    law_evaluation,
    rk4_agent_step,
    formations,
    sweep,
    velocity_formations
);
criterion_main!(benches);
