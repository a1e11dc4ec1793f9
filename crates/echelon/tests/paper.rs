//! The paper's simulations (section 4) reproduced from the built-in scenarios.
#![allow(clippy::unwrap_used)] // tests fail loudly by design

mod common;

use common::{norm, record_with};
use echelon::formation::Leader;
use echelon::lycomp::Placement;
use echelon::reference::{Order, Trajectory};
use echelon::scenario::{Overrides, Scenario};
use echelon::sim::{Frame, ObserverError};
use echelon::{Simulation, State, Timing};

fn built(name: &str) -> Simulation {
    Scenario::builtin(name)
        .unwrap_or_else(|| panic!("built-in {name}"))
        .build(&Overrides::default())
        .expect("built-in scenarios build")
        .simulation()
}

/// Runs to the end, returning the largest ‖e‖ per agent after `after` seconds.
fn run_max_error_after(sim: &mut Simulation, after: f64) -> Vec<f64> {
    let mut worst = vec![0.0f64; sim.agents().len()];
    let mut obs = |f: &Frame<'_>| -> Result<(), ObserverError> {
        if f.t >= after {
            for (w, o) in worst.iter_mut().zip(f.outputs) {
                *w = w.max(norm(o.e));
            }
        }
        Ok(())
    };
    sim.run(&mut obs).expect("run");
    worst
}

/// Runs `sim` (the built-in `name`) to the end and asserts that every
/// agent's ‖e‖ stays below `bound` from `after` s on.
fn assert_settles(name: &str, sim: &mut Simulation, after: f64, bound: f64) {
    for (i, w) in run_max_error_after(sim, after).iter().enumerate() {
        assert!(
            *w < bound,
            "{name} agent {}: max ‖e‖ from {after} s to the end = {w:e}",
            i + 1
        );
    }
}

#[test]
fn pure_tracking_of_the_nonfeasible_cubic_converges_by_ten_seconds() {
    // Section 4.2 / eq. 20: the robot starts 0.4 m off, facing away, and the
    // reference turns 45° on the spot at t = 4 s; ‖e‖ must be < 1e-3 by t = 10 s.
    let mut sim = built("nonfeasible");
    assert_eq!(sim.steps(), 10_000);
    let worst = run_max_error_after(&mut sim, 9.0);
    assert!(worst[0] < 1e-3, "max ‖e‖ over 9–10 s = {}", worst[0]);
}

#[test]
fn pure_tracking_error_is_the_point_l_ahead_minus_the_reference() {
    let mut sim = built("nonfeasible");
    let f = sim.frame();
    let s = f.states[0];
    // e = R(p − p_d) + [L, 0] is the body-frame offset of the point L ahead.
    let pd = echelon::reference::Cubic::new(1.0 / 16.0, 4.0)
        .unwrap()
        .eval(0.0, Order::Two)
        .p;
    let (sin, cos) = s.theta.sin_cos();
    let ahead = [s.x + 0.05 * cos - pd[0], s.y + 0.05 * sin - pd[1]];
    let e = f.outputs[0].e;
    assert!((norm(e) - norm(ahead)).abs() < 1e-12);
}

/// The leader's position in the follower's body frame.
fn leader_in_body(follower: &State, leader: [f64; 2]) -> [f64; 2] {
    let (sin, cos) = follower.theta.sin_cos();
    let d = [leader[0] - follower.x, leader[1] - follower.y];
    [cos * d[0] + sin * d[1], -sin * d[0] + cos * d[1]]
}

#[test]
fn circle_pentagon_converges_and_holds_the_x_separation_at_l_xoff_plus_l() {
    let mut sim = built("circle-pentagon");
    assert_settles("circle-pentagon", &mut sim, 50.0, 1e-6);
    let t = sim.time();
    let states = sim.states().to_vec();
    let reference = sim.reference().eval(t, Order::Two);
    for (i, a) in sim.agents().iter().enumerate() {
        let leader = match a.leader() {
            Leader::Reference => reference.p,
            Leader::Agent(j) => states[j].position(),
        };
        let rel = leader_in_body(&states[i], leader);
        // The paper's steady-state "error in x": the follower sits L = 0.05 m
        // farther back than L_Xoff.
        assert!(
            (rel[0] - (a.placement().lx_off() + 0.05)).abs() < 1e-6,
            "agent {}: leader {} m ahead, want {}",
            i + 1,
            rel[0],
            a.placement().lx_off() + 0.05
        );
        // Sideways: L_Yoff plus the eq. 6 compensation for the leader's turn.
        let (v, w) = match a.leader() {
            Leader::Reference => (reference.speed(), reference.turn_rate()),
            Leader::Agent(j) => (states[j].v, states[j].omega),
        };
        let ly = a.placement().ly_off() + a.placement().comp(v, w);
        assert!(
            (rel[1] - ly).abs() < 1e-6,
            "agent {}: {} vs {ly}",
            i + 1,
            rel[1]
        );
    }
}

#[test]
fn lemniscate_wedge_converges_to_within_the_neglected_l_y_derivatives() {
    // With L̇_Y and L̈_Y neglected (the paper's choice) the error does not vanish
    // where the curvature changes, but stays small: the paper's Fig. 11.
    assert_settles(
        "lemniscate-wedge",
        &mut built("lemniscate-wedge"),
        20.0,
        5e-3,
    );
}

#[test]
fn experiments_converge() {
    for name in ["experiment-circle", "experiment-lemniscate"] {
        assert_settles(name, &mut built(name), 60.0, 1e-4);
    }
}

#[test]
fn built_in_durations_cover_the_whole_manoeuvre() {
    use std::f64::consts::TAU;
    let lap = |name: &str, rate: f64| {
        let sim = built(name);
        assert!(sim.steps() as f64 * sim.config().dt >= TAU / rate, "{name}");
    };
    lap("circle-pentagon", 0.1);
    lap("lemniscate-wedge", 0.1);
    lap("experiment-circle", 0.04);
    lap("experiment-lemniscate", 0.02);
    assert_eq!(built("nonfeasible").config().duration, 10.0);
}

#[test]
fn sampled_controller_holds_its_command_between_samples() {
    let scenario = Scenario::builtin("nonfeasible").unwrap();
    let run = scenario.build(&Overrides::default()).unwrap();
    let agents = run.plan.agents().to_vec();
    let reference = run.plan.reference().clone();
    let period = 0.01;
    let held = record_with(
        agents.clone(),
        reference.clone(),
        1e-3,
        3.0,
        Timing::Sampled { period },
    );
    for w in held.windows(2) {
        let same_period = (w[0].t / period + 1e-9).floor() == (w[1].t / period + 1e-9).floor();
        if same_period {
            assert_eq!(
                w[0].outputs[0].command, w[1].outputs[0].command,
                "t = {}",
                w[1].t
            );
        }
    }
    let changes = held
        .windows(2)
        .filter(|w| w[0].outputs[0].command != w[1].outputs[0].command)
        .count();
    assert_eq!(changes, 300, "one new command per period");
    // A fast enough sampled controller still converges like the continuous one.
    let continuous = record_with(agents, reference, 1e-3, 3.0, Timing::Continuous);
    let (a, b) = (held.last().unwrap(), continuous.last().unwrap());
    assert!(norm(a.outputs[0].e) < 1e-2 && norm(b.outputs[0].e) < 1e-2);
}

#[test]
fn torque_saturation_limits_every_wheel() {
    let mut scenario = Scenario::builtin("nonfeasible").unwrap();
    scenario.file.robots.insert(
        "weak".into(),
        echelon::scenario::schema::RobotSection {
            preset: Some("agent1".into()),
            torque_limit: Some(5.0),
            ..Default::default()
        },
    );
    scenario.file.agents[0].robot = Some("weak".into());
    let run = scenario.build(&Overrides::default()).unwrap();
    let mut peak = 0.0f64;
    let mut obs = |f: &Frame<'_>| -> Result<(), ObserverError> {
        peak = peak.max(f.outputs[0].tau.peak());
        Ok(())
    };
    run.simulation().run(&mut obs).unwrap();
    assert!(peak <= 5.0 + 1e-12, "peak torque {peak}");
    assert!(peak > 4.99, "the limit is reached in this manoeuvre");
}

#[test]
fn tracking_placement_ignores_curvature() {
    let p = Placement::tracking(0.05).unwrap();
    assert_eq!(p.lx(), 0.05);
    assert_eq!(p.offset_for_robot(0.5, 3.0).ly, 0.0);
}
