//! The learning environments' step (`echelon::learn`, what `echelon.envs`
//! wraps) under the baseline policy, without Python: one step of every
//! environment then `baseline` on its observations, as `echelon.envs.bench`
//! loops it (unicycle model, dt 0.01 s, 4 neighbours, no filter) at
//! 1000 × 10, 100 × 100 and 10000 × 1. `cargo bench -p echelon --bench
//! learn`; BENCHMARKS.md has the figures. Throughputs are in agent-steps.

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};

use echelon::learn::{EnvConfig, EnvFacts, VecFormation, baseline};

/// Gain of `echelon.envs.baseline_policy` on the unicycle model.
const KE: f64 = 1.0;

fn step_and_baseline(c: &mut Criterion) {
    let mut g = c.benchmark_group("learn/step + baseline (unicycle, dt 0.01 s)");
    g.sample_size(10).measurement_time(Duration::from_secs(4));
    for (e, n) in [(1000, 10), (100, 100), (10000, 1)] {
        let config = EnvConfig {
            dt: 0.01,
            ..EnvConfig::new(e, n)
        };
        let mut env = match VecFormation::new(config, 7) {
            Ok(env) => env,
            Err(err) => panic!("{err}"),
        };
        let d = env.obs_dim();
        let mut obs = vec![0.0; e * n * d];
        let mut actions = vec![0.0; e * n * 2];
        let (mut rewards, mut changed) = (vec![0.0; e * n], vec![0.0; e * n]);
        let mut facts = vec![EnvFacts::default(); e];
        env.observe(&mut obs);
        g.throughput(Throughput::Elements((e * n) as u64));
        g.bench_function(format!("{e} x {n}"), |b| {
            b.iter(|| {
                baseline(&obs, d, KE, &mut actions);
                env.step(&actions, &mut obs, &mut rewards, &mut changed, &mut facts);
                black_box(&facts);
            });
        });
    }
    g.finish();
}

criterion_group!(benches, step_and_baseline);
criterion_main!(benches);
