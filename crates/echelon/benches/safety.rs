//! The safety filter's cost per call (issue 15): one robot, five cooperative
//! neighbours and one obstacle, for a velocity base and a torque-driven robot,
//! when the nominal command is already safe (no QP) and when the QP is solved
//! (clarabel builds its solver on every solve). `cargo bench -p echelon --bench safety`.

use std::fmt::Debug;
use std::hint::black_box;

use criterion::measurement::WallTime;
use criterion::{BenchmarkGroup, Criterion, criterion_group, criterion_main};

use echelon::base::{VelocityBase, VelocityBaseSpec, VelocityCommand};
use echelon::model::{Input, RobotParams, State};
use echelon::safety::{Filtered, Neighbour, Obstacle, SafetyConfig, SafetyFilter};

const L: f64 = 0.05;

fn scene() -> (State, Vec<Neighbour>, Vec<Obstacle>) {
    let me = State {
        x: 0.0,
        y: 0.0,
        theta: 0.1,
        v: 0.0,
        omega: 0.0,
    };
    // Five neighbours at rest around, the nearest 0.6 m ahead.
    let ns = [
        (0.6, 0.05, 3.1),
        (0.5, -0.6, 2.5),
        (-0.7, 0.2, 0.0),
        (0.1, 0.9, -1.5),
        (-0.3, -0.8, 1.2),
    ]
    .map(|(x, y, theta)| {
        let s = State {
            x,
            y,
            theta,
            v: 0.0,
            omega: 0.0,
        };
        Neighbour::of_state(&s, L, Some([0.0, 0.0]), true)
    })
    .to_vec();
    let obstacles = vec![Obstacle::new(1.0, 1.0, 0.2).expect("a valid obstacle")];
    (me, ns, obstacles)
}

/// Benchmarks `filter` on each `(name, command)` case, after checking that
/// the filter is active exactly on the cases whose name ends with "QP".
fn bench_cases<C: Copy + Debug>(
    g: &mut BenchmarkGroup<'_, WallTime>,
    cases: [(&str, C); 2],
    mut filter: impl FnMut(C) -> Filtered<C>,
) {
    for (name, cmd) in cases {
        let out = filter(cmd);
        assert_eq!(out.active(), name.ends_with("QP"), "{name}: {out:?}");
        g.bench_function(name, |b| b.iter(|| filter(cmd)));
    }
}

fn safety(c: &mut Criterion) {
    let config = match SafetyConfig::new(0.3, 1.0, 2.0) {
        Ok(c) => c,
        Err(e) => panic!("{e}"),
    };
    let (me, ns, obstacles) = scene();
    let base = VelocityBase::new(VelocityBaseSpec {
        v_max: 0.5,
        omega_max: 3.0,
        ..VelocityBase::IDEAL.spec()
    })
    .expect("an ideal base with speed limits");
    let robot = RobotParams::AGENT1
        .with_torque_limit(Some(3.0))
        .expect("3 N m is a valid torque limit");
    let mut f = SafetyFilter::new(config);
    let mut g = c.benchmark_group("safety/one call, 5 neighbours + 1 obstacle");
    let velocity_cases = [
        (
            "velocity, nominal safe",
            VelocityCommand {
                v: 0.05,
                omega: 0.0,
            },
        ),
        ("velocity, QP", VelocityCommand { v: 0.5, omega: 0.0 }),
    ];
    bench_cases(&mut g, velocity_cases, |cmd| {
        f.velocity(
            0.0,
            black_box(&me),
            L,
            black_box(cmd),
            &base,
            black_box(&ns),
            &obstacles,
        )
    });
    let torque_cases = [
        ("torque, nominal safe", Input { u1: 1.0, u2: 0.0 }),
        ("torque, QP", Input { u1: 80.0, u2: 0.0 }),
    ];
    bench_cases(&mut g, torque_cases, |u| {
        f.torque(
            0.0,
            black_box(&me),
            L,
            &robot,
            black_box(u),
            black_box(&ns),
            &obstacles,
        )
    });
    g.finish();
}

criterion_group!(benches, safety);
criterion_main!(benches);
