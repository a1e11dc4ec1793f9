//! The safety filter's cost per call (issue 15): one robot, five cooperative
//! neighbours and one obstacle, for a velocity base and a torque-driven robot,
//! when the nominal command is already safe (no QP) and when the QP is solved
//! (clarabel builds its solver on every solve). `cargo bench -p echelon --bench safety`.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};

use echelon::base::{VelocityBase, VelocityCommand};
use echelon::model::{Input, RobotParams, State};
use echelon::safety::{Neighbour, Obstacle, SafetyConfig, SafetyFilter};

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

fn safety(c: &mut Criterion) {
    let config = match SafetyConfig::new(0.3, 1.0, 2.0) {
        Ok(c) => c,
        Err(e) => panic!("{e}"),
    };
    let (me, ns, obstacles) = scene();
    let base = VelocityBase::new(0.0, 0.0, 0.5, 3.0, f64::INFINITY, f64::INFINITY)
        .expect("an ideal base with speed limits");
    let robot = RobotParams::AGENT1
        .with_torque_limit(Some(3.0))
        .expect("3 N m is a valid torque limit");
    let mut f = SafetyFilter::new(config);
    let mut g = c.benchmark_group("safety/one call, 5 neighbours + 1 obstacle");
    for (name, cmd) in [
        (
            "velocity, nominal safe",
            VelocityCommand {
                v: 0.05,
                omega: 0.0,
            },
        ),
        ("velocity, QP", VelocityCommand { v: 0.5, omega: 0.0 }),
    ] {
        let out = f.velocity(0.0, &me, L, cmd, &base, &ns, &obstacles);
        assert_eq!(out.active(), name.ends_with("QP"), "{name}: {out:?}");
        g.bench_function(name, |b| {
            b.iter(|| {
                f.velocity(
                    0.0,
                    black_box(&me),
                    L,
                    black_box(cmd),
                    &base,
                    black_box(&ns),
                    &obstacles,
                )
            })
        });
    }
    for (name, u) in [
        ("torque, nominal safe", Input { u1: 1.0, u2: 0.0 }),
        ("torque, QP", Input { u1: 80.0, u2: 0.0 }),
    ] {
        let out = f.torque(0.0, &me, L, &robot, u, &ns, &obstacles);
        assert_eq!(out.active(), name.ends_with("QP"), "{name}: {out:?}");
        g.bench_function(name, |b| {
            b.iter(|| {
                f.torque(
                    0.0,
                    black_box(&me),
                    L,
                    &robot,
                    black_box(u),
                    black_box(&ns),
                    &obstacles,
                )
            })
        });
    }
    g.finish();
}

criterion_group!(benches, safety);
criterion_main!(benches);
