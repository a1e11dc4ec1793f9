//! Barrier-certificate safety (issue 15): the crossing and obstacle built-ins
//! with and without the filter, head-on deadlocks (velocity bases and torques),
//! and bad `[safety]` input.
#![allow(clippy::unwrap_used)] // tests fail loudly by design

mod common;

use echelon::base::{VelocityBase, VelocityBaseSpec, VelocityCommand};
use echelon::model::{Input, RobotParams};
use echelon::safety::{Neighbour, SafetyConfig, SafetyFilter, point};
use echelon::scenario::{Overrides, Scenario};
use echelon::sim::{Frame, ObserverError};
use echelon::stats::{SafetyReport, SafetyWatch, Summary};
use echelon::{Observer, State};

/// Runs a built-in (with `safety` removed when `filter` is false), watching
/// every step: the safety report (if any), the smallest distance between two
/// robots' points over the run, the smallest clearance from an obstacle edge
/// (the scenario's obstacles, filter or not) and the final ‖e‖ of each agent.
fn run(name: &str, filter: bool) -> (Option<SafetyReport>, f64, f64, Vec<f64>) {
    let mut s = Scenario::builtin(name).unwrap();
    let obstacles: Vec<[f64; 3]> = s
        .file
        .safety
        .as_ref()
        .and_then(|s| s.obstacles.clone())
        .unwrap_or_default()
        .iter()
        .map(|o| [o.x, o.y, o.r])
        .collect();
    if !filter {
        s.file.safety = None;
    }
    let run = s.build(&Overrides::default()).unwrap();
    let sim = &mut run.simulation();
    assert_eq!(sim.has_safety(), filter);
    let l: Vec<f64> = sim.agents().iter().map(|a| a.placement().l()).collect();
    let (mut closest, mut clearance) = (f64::INFINITY, f64::INFINITY);
    let mut every = |f: &Frame<'_>| -> Result<(), ObserverError> {
        closest = closest.min(SafetyWatch::closest_pair(f.states, &l).unwrap().0);
        for (st, &l) in f.states.iter().zip(&l) {
            let p = point(st, l);
            for o in &obstacles {
                clearance = clearance.min((p[0] - o[0]).hypot(p[1] - o[1]) - o[2]);
            }
        }
        Ok(())
    };
    let mut watch = SafetyWatch::default();
    let mut summary = Summary::new(sim.agents().len(), Summary::SETTLE_TOLERANCE);
    sim.run(&mut [&mut every as &mut dyn Observer, &mut watch, &mut summary])
        .unwrap();
    let finals = summary
        .agents(sim.agents())
        .iter()
        .map(|a| a.final_error)
        .collect();
    (watch.report().cloned(), closest, clearance, finals)
}

#[test]
fn crossing_keeps_every_pair_apart_and_the_formation_still_converges() {
    let (report, closest, _, finals) = run("crossing", true);
    let report = report.unwrap();
    // Every step, true states: at least radius − 1 mm (0.3000528 m measured).
    assert!(closest >= 0.3 - 1e-3, "closest {closest}");
    assert_eq!(report.closest.min_distance, closest);
    assert_eq!(report.infeasible, 0);
    assert!(report.active > 0);
    // The columns' heads meet in perfect symmetry: the deadlock rule acts.
    assert!(report.deadlock_breaks > 0, "{report:?}");
    // The formation converges afterwards (final ‖e‖ < 1e-4 m for all six).
    for (i, e) in finals.iter().enumerate() {
        assert!(*e < 1e-3, "agent {}: final ‖e‖ = {e}", i + 1);
    }
    // Without the filter the nominal law drives robots within 0.1 m.
    let (none, closest, _, _) = run("crossing", false);
    assert!(none.is_none());
    assert!(closest < 0.1, "closest without the filter {closest}");
}

#[test]
fn the_torque_column_goes_around_the_posts() {
    let (report, _, clearance, finals) = run("obstacle-slalom", true);
    let report = report.unwrap();
    // Exponential barrier on (u1, u2): clearance ≥ radius − 1 mm (0.15002 m measured).
    assert!(clearance >= 0.15 - 1e-3, "clearance {clearance}");
    assert_eq!(report.closest.min_obstacle_clearance, Some(clearance));
    assert!(report.closest.min_distance >= 0.15 - 1e-3);
    assert_eq!(report.infeasible, 0);
    for (i, e) in finals.iter().enumerate() {
        assert!(*e < 1e-3, "agent {}: final ‖e‖ = {e}", i + 1);
    }
    // Without the filter the robots' points pass through the posts.
    let (_, _, clearance, _) = run("obstacle-slalom", false);
    assert!(clearance < 0.0, "clearance without the filter {clearance}");
}

/// The velocity command that moves the point `l` ahead of a robot in state
/// `me` at the world velocity `want` (`R(θ) want`, its turn divided by `l`).
fn towards(me: &State, l: f64, want: [f64; 2]) -> VelocityCommand {
    let (s, c) = me.theta.sin_cos();
    VelocityCommand {
        v: c * want[0] + s * want[1],
        omega: (-s * want[0] + c * want[1]) / l,
    }
}

/// Moves `r` along the exact unicycle arc of the constant command `c` for
/// `dt`; its speeds become `c`'s.
fn unicycle_step(r: &mut State, c: VelocityCommand, dt: f64) {
    let th = r.theta + c.omega * dt;
    if c.omega.abs() > 1e-12 {
        r.x += c.v / c.omega * (th.sin() - r.theta.sin());
        r.y -= c.v / c.omega * (th.cos() - r.theta.cos());
    } else {
        r.x += c.v * dt * r.theta.cos();
        r.y += c.v * dt * r.theta.sin();
    }
    (r.theta, r.v, r.omega) = (th, c.v, c.omega);
}

/// Two ideal velocity bases head-on, each driving its point toward a goal
/// behind the other (`ṗ = −k (p − goal)`, the nominal mapped to `(v, ω)`),
/// in perfect mirror symmetry. Without the deadlock rule they would stop
/// nose to nose; with it both keep right, pass and reach their goals.
#[test]
fn a_head_on_deadlock_is_broken_and_both_robots_arrive() {
    let l = 0.1;
    let config = SafetyConfig::new(0.4, 1.0, f64::INFINITY).unwrap();
    let base = VelocityBase::new(VelocityBaseSpec {
        v_max: 0.5,
        omega_max: 4.0,
        ..VelocityBase::IDEAL.spec()
    })
    .unwrap();
    let mut robots = [
        State::at_rest(-2.0, 0.0, 0.0),
        State::at_rest(2.0, 0.0, std::f64::consts::PI),
    ];
    let goals = [[2.0, 0.0], [-2.0, 0.0]];
    let mut filters = [SafetyFilter::new(config), SafetyFilter::new(config)];
    let dt = 0.01;
    let mut closest = f64::INFINITY;
    for step in 0..6000 {
        let t = step as f64 * dt;
        let seen = robots;
        for i in 0..2 {
            let me = &seen[i];
            let other = Neighbour::of_state(&seen[1 - i], l, None, true);
            let p = point(me, l);
            let want = [-(p[0] - goals[i][0]), -(p[1] - goals[i][1])];
            let nominal = towards(me, l, want);
            let f = filters[i].velocity(t, me, l, nominal, &base, &[other], &[]);
            unicycle_step(&mut robots[i], f.command, dt);
        }
        let (a, b) = (point(&robots[0], l), point(&robots[1], l));
        closest = closest.min((a[0] - b[0]).hypot(a[1] - b[1]));
    }
    // Safe all the way (the ZOH over dt costs well under a millimetre).
    assert!(closest >= 0.4 - 1e-3, "closest {closest}");
    for (i, f) in filters.iter().enumerate() {
        assert!(
            f.deadlock_breaks() >= 1,
            "robot {i} never broke the deadlock"
        );
        let p = point(&robots[i], l);
        let miss = (p[0] - goals[i][0]).hypot(p[1] - goals[i][1]);
        assert!(miss < 1e-3, "robot {i} is {miss} m from its goal");
    }
    // Keep right: robot 1 (heading +x) swerved to −y, so it passed robot 2
    // on its left-hand side, and so did robot 2; mirror symmetry is kept.
}

/// The torque-driven version (Table I's agent 1, eq. 3): each robot drives its
/// point toward a goal behind the other with a saturated PD on the point's
/// acceleration, mapped to `(u1, u2)` through eq. 3, in perfect mirror
/// symmetry; the exponential barriers see the neighbour's measured velocity
/// and acceleration. With γ = 6 the barrier holds the points at the radius
/// (closest 0.40027 m for 0.4). The head-on stand-off is broken by the same
/// keep-right rule (on the desired acceleration), and both arrive.
#[test]
fn a_torque_head_on_deadlock_is_broken_and_both_robots_arrive() {
    let l = 0.1;
    let robot = RobotParams::AGENT1;
    let config = SafetyConfig::new(0.4, 6.0, f64::INFINITY).unwrap();
    let mut robots = [
        State::at_rest(-2.0, 0.0, 0.0),
        State::at_rest(2.0, 0.0, std::f64::consts::PI),
    ];
    // (v̇, ω̇) of each robot over the last step, as its neighbour measures it.
    let mut accelerations = [[0.0; 2]; 2];
    let goals = [[2.0, 0.0], [-2.0, 0.0]];
    let mut filters = [SafetyFilter::new(config), SafetyFilter::new(config)];
    let (m, j) = (robot.mass(), robot.inertia());
    let (eta, psi) = (robot.linear_friction(), robot.angular_friction());
    let dt = 0.01;
    let mut closest = f64::INFINITY;
    for step in 0..8000 {
        let t = step as f64 * dt;
        let seen = (robots, accelerations);
        for i in 0..2 {
            let me = &seen.0[i];
            let other = Neighbour::of_state(&seen.0[1 - i], l, Some(seen.1[1 - i]), true);
            let own = Neighbour::of_state(me, l, None, true);
            // Saturated PD on the point: p̈ = −(p − goal) − 2ṗ, ‖p̈‖ ≤ 0.5 m/s².
            let mut want = [
                -(own.p[0] - goals[i][0]) - 2.0 * own.dp[0],
                -(own.p[1] - goals[i][1]) - 2.0 * own.dp[1],
            ];
            let norm = want[0].hypot(want[1]);
            if norm > 0.5 {
                want = [want[0] * 0.5 / norm, want[1] * 0.5 / norm];
            }
            // Eq. 3: p̈ = f + R(θ)(u1/m, L u2/J), f the part u does not set.
            let (v, w) = (me.v, me.omega);
            let (s, c) = me.theta.sin_cos();
            let along = -eta * v / m - l * w * w;
            let across = v * w - l * psi * w / j;
            let f = [along * c - across * s, along * s + across * c];
            let d = [want[0] - f[0], want[1] - f[1]];
            let nominal = Input {
                u1: m * (c * d[0] + s * d[1]),
                u2: j * (-s * d[0] + c * d[1]) / l,
            };
            let u = filters[i]
                .torque(t, me, l, &robot, nominal, &[other], &[])
                .command;
            accelerations[i] = [(u.u1 - eta * v) / m, (u.u2 - psi * w) / j];
            robots[i] = robot.rk4_step(me, u, dt);
        }
        let (a, b) = (point(&robots[0], l), point(&robots[1], l));
        closest = closest.min((a[0] - b[0]).hypot(a[1] - b[1]));
    }
    // Safe all the way (the torques held over dt cost well under a millimetre).
    assert!(closest >= 0.4 - 1e-3, "closest {closest}");
    let breaks: Vec<u64> = filters.iter().map(SafetyFilter::deadlock_breaks).collect();
    // One keep-right start is enough: whichever robot is stuck first (cos π
    // and sin π are not exactly −1 and 0) swerves, and the other is free.
    assert!(breaks.iter().sum::<u64>() >= 1, "nobody broke the deadlock");
    for i in 0..2 {
        let p = point(&robots[i], l);
        let miss = (p[0] - goals[i][0]).hypot(p[1] - goals[i][1]);
        assert!(miss < 1e-3, "robot {i} is {miss} m from its goal");
    }
}

const BASE: &str = include_str!("fixtures/safety-base.toml");

use common::{build, expect_errors_in};

#[test]
fn the_base_builds_with_a_filter_per_agent() {
    let run = build(BASE).unwrap();
    assert!(run.plan.safety().is_some());
    assert_eq!(run.plan.obstacles().len(), 1);
    assert_eq!(run.plan.safety_radius(), Some(0.3));
}

#[test]
fn bad_safety_input_names_file_line_column_and_field() {
    let cases: [(&str, &str, usize, &str, &str); 8] = [
        ("radius = 0.3", "radius = 0.0", 11, "safety.radius", "> 0"),
        ("gain = 1.0", "gain = -1.0", 12, "safety.gain", "> 0"),
        ("r = 0.2 }", "r = 0.0 }", 13, "safety.obstacles[1].r", "> 0"),
        (
            "gain = 2.0 }",
            "gain = 0.0 }",
            24,
            "agents[2].safety.gain",
            "> 0",
        ),
        (
            "gain = 2.0 }",
            "radius = 0.5 }",
            24,
            "agents[2].safety.radius",
            "[safety]",
        ),
        (
            "gain = 2.0 }",
            "speed = 1.0 }",
            24,
            "agents[2].safety.speed",
            "unknown field",
        ),
        // A robot inside an obstacle, and one within radius of another.
        (
            "x = -0.5, y = -0.5, theta",
            "x = 2.9, y = 0.0, theta",
            21,
            "agents[2].start",
            "obstacle 1",
        ),
        (
            "x = -0.5, y = -0.5, theta",
            "x = -0.5, y = 0.3, theta",
            21,
            "agents[2].start",
            "agent 1",
        ),
    ];
    expect_errors_in(BASE, &cases);
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(48))]

    /// A neighbour's `margin` (the fleet's position uncertainty,
    /// `uncertainty_margin`) widens the pair's radius: a robot driving its
    /// point at a resting neighbour from any side, at any speed, with any
    /// margin, stops at `radius + margin` from it (the exact unicycle step
    /// costs well under a millimetre), and never closer.
    #[test]
    fn a_margin_widens_the_pairs_radius(
        heading in -3.1..3.1f64, side in -0.5..0.5f64, v_max in 0.1..1.0f64,
        sigma_me in 0.0..0.05f64, sigma_other in 0.0..0.05f64,
    ) {
        let (l, radius) = (0.1, 0.3);
        let margin = echelon::safety::uncertainty_margin(sigma_me, sigma_other);
        proptest::prop_assert!((margin - 3.0 * (sigma_me + sigma_other)).abs() < 1e-15);
        let config = SafetyConfig::new(radius, 1.0, f64::INFINITY).unwrap();
        let base = VelocityBase::new(VelocityBaseSpec { v_max, omega_max: 4.0, ..VelocityBase::IDEAL.spec() }).unwrap();
        let other = State::at_rest(0.0, 0.0, 0.0);
        let seen = Neighbour::of_state(&other, l, None, false).with_margin(margin);
        let q = point(&other, l);
        // Two metres out, facing the neighbour's point (a little aside).
        let (s, c) = heading.sin_cos();
        let mut r = State::at_rest(q[0] + 2.0 * c - side * s, q[1] + 2.0 * s + side * c, heading + std::f64::consts::PI);
        let mut filter = SafetyFilter::new(config);
        let dt = 0.01;
        let mut closest = f64::INFINITY;
        for step in 0..2000 {
            let p = point(&r, l);
            // Straight through the neighbour, to a goal beyond it.
            let goal = [2.0 * q[0] - p[0], 2.0 * q[1] - p[1]];
            let want = [goal[0] - p[0], goal[1] - p[1]];
            let nominal = towards(&r, l, want);
            let cmd = filter.velocity(step as f64 * dt, &r, l, nominal, &base, &[seen], &[]).command;
            unicycle_step(&mut r, cmd, dt);
            let p = point(&r, l);
            closest = closest.min((p[0] - q[0]).hypot(p[1] - q[1]));
        }
        proptest::prop_assert!(closest >= radius + margin - 1e-3, "closest {} for {}", closest, radius + margin);
        // It did come close: the margin, not caution, set the distance.
        proptest::prop_assert!(closest <= radius + margin + 0.05, "closest {} for {}", closest, radius + margin);
    }
}
