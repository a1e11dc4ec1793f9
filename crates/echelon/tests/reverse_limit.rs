//! A base's backup limit (`reverse_limit`, the TurtleBot 4 preset's
//! 0.1 m: the Create 3 refuses to back up further without its safety
//! override) holds whatever the law and the safety filter ask, over
//! randomized scenarios where they ask a lot: robots that start ahead of
//! their slots (the law backs them up), a leader that drives out and turns
//! back on itself, and two columns swapping sides under the safety filter.
//!
//! Measured independently of `Backup`: from the simulated states, how far
//! each robot is behind the furthest point it reached along its path
//! (displacement projected on its heading, step by step).

use echelon::scenario::{Overrides, Scenario};
use echelon::sim::Simulation;
use proptest::prelude::*;

/// The worst backward travel in one go of each agent over the run, m.
fn worst_reversals(toml: &str) -> Vec<f64> {
    let s = Scenario::parse(toml, "reverse.toml", None).unwrap_or_else(|e| panic!("{e}\n{toml}"));
    let run = s
        .build(&Overrides::default())
        .unwrap_or_else(|e| panic!("{e}"));
    let mut sim = Simulation::new(&run.plan);
    let n = sim.states().len();
    let mut behind = vec![0.0f64; n];
    let mut worst = vec![0.0f64; n];
    while !sim.is_done() {
        let before = sim.states().to_vec();
        sim.step().unwrap_or_else(|e| panic!("{e}"));
        for (i, (a, b)) in before.iter().zip(sim.states()).enumerate() {
            let (sin, cos) = a.theta.sin_cos();
            let ds = (b.x - a.x) * cos + (b.y - a.y) * sin;
            behind[i] = (behind[i] - ds).max(0.0);
            worst[i] = worst[i].max(behind[i]);
        }
    }
    worst
}

/// A velocity base with these lags and limits, and a backup limit when given.
fn robot(tau_v: f64, a_max: f64, limit: Option<f64>) -> String {
    let limit = limit.map_or(String::new(), |l| format!("reverse_limit = {l}\n"));
    format!(
        "[robots.tb]\ndrive = \"velocity\"\npreset = \"ideal\"\ntau_v = {tau_v}\ntau_omega = 0.1\nv_max = 0.306\nomega_max = 1.9\na_max = {a_max}\nalpha_max = 7.66\n{limit}"
    )
}

const HEAD: &str = "[control]\nlaw = \"kinematic\"\nke = 1.0\nl = 0.05\nlycomp = \"none\"\n";

/// Robots `ahead` m in front of their slots behind a slow line.
fn ahead(robot: &str, ahead: f64, speed: f64, rate: Option<f64>) -> String {
    // A sampled controller: a whole number of 10 ms steps.
    let sample = rate.map_or(String::new(), |r| {
        format!(
            "controller_period = {:.2}\n",
            ((1.0 / r) / 0.01).round().max(1.0) * 0.01
        )
    });
    format!(
        "name = \"ahead\"\n[sim]\nduration = 20.0\ndt = 0.01\n{sample}{HEAD}{robot}\n[reference.line]\nspeed = {speed}\nstart = {{ x = 0.0, y = 0.0, theta = 0.0 }}\n\
         [[agents]]\nrobot = \"tb\"\nstart = {{ x = {x1}, y = 0.3, theta = 0.0 }}\nleader = \"reference\"\noffset = {{ x = 0.5, y = 0.3 }}\n\
         [[agents]]\nrobot = \"tb\"\nstart = {{ x = {x2}, y = 0.3, theta = 0.0 }}\nleader = 1\noffset = {{ x = 0.5, y = 0.0 }}\n",
        x1 = -0.5 + ahead,
        x2 = -1.0 + 0.5 * ahead,
    )
}

/// A leader that drives `out` m along x and comes back the same way.
fn turns_back(robot: &str, out: f64, t: f64) -> String {
    format!(
        "name = \"back\"\n[sim]\nduration = {d}\ndt = 0.01\n{HEAD}{robot}\n[reference.waypoints]\npoints = [[0.0, 0.0, 0.0], [{t}, {out}, 0.0], [{t2}, 0.0, 0.0]]\n\
         [[agents]]\nrobot = \"tb\"\nstart = {{ x = -0.4, y = 0.0, theta = 0.0 }}\nleader = \"reference\"\noffset = {{ x = 0.4, y = 0.0 }}\n",
        d = 2.0 * t + 5.0,
        t2 = 2.0 * t,
    )
}

/// Two robots swapping sides (the crossing) under the safety filter.
fn swap(robot: &str, radius: f64) -> String {
    format!(
        "name = \"swap\"\n[sim]\nduration = 30.0\ndt = 0.01\n{HEAD}{robot}\n[reference.line]\nspeed = 0.1\nstart = {{ x = 0.0, y = 0.0, theta = 0.0 }}\n\
         [safety]\nradius = {radius}\ngain = 1.0\nrange = 1.5\n\
         [[agents]]\nrobot = \"tb\"\nstart = {{ x = -0.5, y = 0.5, theta = 0.0 }}\nleader = \"reference\"\noffset = {{ x = 0.5, y = -0.5 }}\n\
         [[agents]]\nrobot = \"tb\"\nstart = {{ x = -0.5, y = -0.5, theta = 0.0 }}\nleader = \"reference\"\noffset = {{ x = 0.5, y = 0.5 }}\n"
    )
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 32, ..ProptestConfig::default() })]

    #[test]
    fn no_robot_backs_up_beyond_its_limit(
        kind in 0u8..3,
        // 0 (ideal) or at least five 10 ms steps (the simulator wants dt ≤ τ).
        tau_v in prop_oneof![Just(0.0), 0.05f64..0.3],
        a_max in 0.3f64..3.0,
        limit in 0.03f64..0.15,
        ahead_by in 0.2f64..0.8,
        rate in prop_oneof![Just(None), (5.0f64..50.0).prop_map(Some)],
        out in 0.5f64..1.5,
        radius in 0.2f64..0.35,
    ) {
        let scenario = |limit: Option<f64>| {
            let r = robot(tau_v, if tau_v == 0.0 { 1e9 } else { a_max }, limit).replace("a_max = 1000000000\n", "");
            match kind {
                0 => ahead(&r, ahead_by, 0.05, rate),
                1 => turns_back(&r, out, 8.0),
                _ => swap(&r, radius),
            }
        };
        let free = worst_reversals(&scenario(None));
        let held = worst_reversals(&scenario(Some(limit)));
        for (i, (f, h)) in free.iter().zip(&held).enumerate() {
            prop_assert!(*h <= limit * (1.0 + 1e-3) + 1e-4, "agent {}: backed up {h} m > {limit} (free: {f})", i + 1);
        }
        // Not vacuous: robots that start well ahead of their slots back up
        // beyond the limit without it (each case says so).
        if kind == 0 {
            prop_assert!(free[0] > limit, "the law backed agent 1 up only {} m", free[0]);
        }
    }
}
