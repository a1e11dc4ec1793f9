//! A per-agent `max_accel` (m/s²): the act step keeps the linear
//! acceleration the law asks within it, on torque robots (eq. 3: `m v̇ =
//! u1 − η v`) and lagged velocity bases (`τ_v v̇ = v* − v`), in single steps
//! and along whole runs; impossible values are refused with their place.
#![allow(clippy::unwrap_used)] // tests fail loudly by design

use echelon::agent::Command;
use echelon::formation::Leader;
use echelon::model::Input;
use echelon::scenario::{Overrides, Scenario};
use echelon::sim::{Frame, ObserverError};
use echelon::{AgentSpec, RobotParams, State, Variant};
use proptest::prelude::*;

mod common;

fn torque_agent(a: f64) -> AgentSpec {
    common::agent(
        Leader::Reference,
        common::placement(
            0.3,
            0.0,
            echelon::lycomp::LyComp::Exact,
            echelon::lycomp::LyDerivatives::Neglect,
        ),
        State::at_rest(0.0, 0.0, 0.0),
        Variant::Paper,
    )
    .with_max_accel(Some(a))
    .unwrap()
}

proptest! {
    /// Any state and any nominal: the command's acceleration `(u1 − η v)/m`
    /// is within `±max_accel`, the command is unchanged when it already was,
    /// and the turn `u2` is never touched.
    #[test]
    fn a_torque_robot_is_asked_no_more_than_max_accel(
        a in 0.01..5.0f64,
        v in -2.0..2.0f64,
        u1 in -500.0..500.0f64,
        u2 in -50.0..50.0f64,
    ) {
        let spec = torque_agent(a);
        let robot = RobotParams::AGENT1;
        let me = State { v, ..State::at_rest(0.3, -0.2, 0.4) };
        let nominal = Input { u1, u2 };
        let Command::Torque(u) = spec.act(0.0, &me, Command::Torque(nominal), None).command else {
            panic!("a torque robot gets torques");
        };
        let accel = |u1: f64| (u1 - robot.linear_friction() * v) / robot.mass();
        prop_assert!(accel(u.u1).abs() <= a * (1.0 + 1e-12), "{} > {a}", accel(u.u1));
        prop_assert_eq!(u.u2, u2);
        if accel(u1).abs() <= a {
            prop_assert_eq!(u.u1, u1);
        } else {
            // Clamped to the bound on the side it asked for.
            prop_assert!((accel(u.u1).abs() - a).abs() <= 1e-9 * a);
            prop_assert_eq!(accel(u.u1).signum(), accel(u1).signum());
        }
    }
}

fn scenario(extra: &str, robot: &str) -> String {
    format!(
        r#"name = "max-accel"
[sim]
duration = 6.0
dt = 0.002
{robot}
[reference.circle]
speed = 0.5
turn_rate = 0.2
start = {{ x = 0.0, y = 0.0, theta = 0.0 }}

[[agents]]
start = {{ x = -1.5, y = -0.5, theta = 0.0 }}
leader = "reference"
offset = {{ x = 0.5, y = 0.0 }}
{extra}
"#
    )
}

/// The largest `|Δv|/Δt` over a run's samples (RK4 combines stage slopes
/// that are each within the bound, so the step's mean slope is too).
fn peak_accel(src: &str) -> f64 {
    let run = common::build(src).unwrap();
    let dt = run.plan.config().dt;
    let mut last: Option<f64> = None;
    let mut peak: f64 = 0.0;
    let mut log = |f: &Frame<'_>| -> Result<(), ObserverError> {
        let v = f.states[0].v;
        if let Some(l) = last {
            peak = peak.max((v - l).abs() / dt);
        }
        last = Some(v);
        Ok(())
    };
    run.simulation().run(&mut log).unwrap();
    peak
}

#[test]
fn runs_keep_max_accel_for_torque_robots_and_lagged_bases() {
    let base = "[robots.b]\ndrive = \"velocity\"\npreset = \"turtlebot4\"\n";
    for (robot, agent_robot) in [("", ""), (base, "robot = \"b\"\n")] {
        let free = peak_accel(&scenario(agent_robot, robot));
        for a in [0.05, 0.2] {
            let src = scenario(&format!("{agent_robot}max_accel = {a}\n"), robot);
            let limited = peak_accel(&src);
            assert!(
                limited <= a * (1.0 + 1e-6),
                "{robot}: peak |v̇| {limited} m/s² > max_accel {a}"
            );
            assert!(
                free > a,
                "{robot}: the law alone asks {free} ≤ {a}: test nothing"
            );
        }
    }
}

/// The batch engine runs the law alone: it refuses an agent it would run
/// without its limit rather than ignore it.
#[test]
fn the_batch_engine_refuses_max_accel() {
    let agents = [torque_agent(0.5)];
    let reference = Scenario::resolve("lemniscate-wedge")
        .unwrap()
        .build(&Overrides::default())
        .unwrap()
        .plan
        .reference()
        .clone();
    let e = echelon::engine::Engine::from_agents(&agents, reference, 1e-3)
        .err()
        .unwrap();
    assert!(e.to_string().contains("max_accel"), "{e}");
}

#[test]
fn impossible_max_accel_is_refused_with_its_place() {
    for (extra, robot, message) in [
        ("max_accel = -1.0\n", "", "max_accel"),
        ("max_accel = 0.0\n", "", "max_accel"),
        (
            "robot = \"b\"\nmax_accel = 0.5\n",
            "[robots.b]\ndrive = \"velocity\"\npreset = \"ideal\"\n",
            "tau_v > 0",
        ),
    ] {
        let Err(e) = common::build(&scenario(extra, robot)) else {
            panic!("max_accel with {extra} on {robot} is refused");
        };
        assert_eq!(e.field, "agents[1].max_accel", "{e}");
        assert!(
            e.location.line > 0 && e.to_string().contains(message),
            "{e}"
        );
    }
}
