//! Identification (issue 14): Table I robots recovered from noisy logs with
//! honest intervals, velocity-base lags, unexcited axes refused, the
//! identified robot reproducing a scenario, and bad logs refused.
//!
//! Measurement noise: zero-mean Gaussian, white, added to the logged
//! velocities: σ_v = 0.005 m/s, σ_ω = 0.01 rad/s (ChaCha8 seeded per case).
#![allow(clippy::unwrap_used)] // tests fail loudly by design

mod common;
use common::fixed_sample;

use echelon::RobotParams;
use echelon::agent::AgentSpec;
use echelon::follow::{LeaderView, follow};
use echelon::identify::{self, IdentifyError, Log, Model};
use echelon::model::{Input, State};
use echelon::reference::{Order, Trajectory};
use echelon::scenario::{Overrides, Scenario};
use echelon::sim::Simulation;
use proptest::prelude::*;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

const SIGMA_V: f64 = 0.005;
const SIGMA_OMEGA: f64 = 0.01;
const LOG_DT: f64 = 0.01;

/// The log of a base that follows `applied` through first-order lags
/// `taus` (s) on each axis, measured with the noise of `SIGMA_V` and
/// `SIGMA_OMEGA` (drawn from `seed`), `cmd` logged as commanded.
fn lagged_base_log(
    source: &str,
    t: Vec<f64>,
    cmd: [Vec<f64>; 2],
    applied: [Vec<f64>; 2],
    (tau_v, tau_w): (f64, f64),
    seed: u64,
) -> Log {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (nv, nw) = (
        Normal::new(0.0, SIGMA_V).unwrap(),
        Normal::new(0.0, SIGMA_OMEGA).unwrap(),
    );
    let v: Vec<f64> = identify::simulate_axis(&t, &applied[0], tau_v, 1.0, 0.0)
        .into_iter()
        .map(|x| x + nv.sample(&mut rng))
        .collect();
    let omega: Vec<f64> = identify::simulate_axis(&t, &applied[1], tau_w, 1.0, 0.0)
        .into_iter()
        .map(|x| x + nw.sample(&mut rng))
        .collect();
    Log {
        source: source.into(),
        agent: 1,
        t,
        v,
        omega,
        cmd: Some(cmd),
        applied: Some(applied),
        ..Log::default()
    }
}

/// Asserts that one of `id`'s warnings says every one of `parts`.
fn assert_warns(id: &identify::Identified, parts: &[&str]) {
    assert!(
        id.warnings
            .iter()
            .any(|w| parts.iter().all(|p| w.contains(p))),
        "{:?}",
        id.warnings
    );
}

/// The simulation settings `scenario` builds to without overrides.
fn settings(scenario: &Scenario) -> echelon::SimConfig {
    *scenario.build(&Overrides::default()).unwrap().plan.config()
}

/// A 60 s excitation held every 10 ms: steps of a square wave over slow and
/// fast sines, sized for `|v| ≲ 0.6 m/s`, `|ω| ≲ 1.2 rad/s` on the robot.
fn excitation(robot: &RobotParams) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let n = 6000;
    let t: Vec<f64> = (0..n).map(|i| i as f64 * LOG_DT).collect();
    let shape = |t: f64, a: f64, b: f64, c: f64| {
        0.25 * (a * t).sin() + 0.2 * (b * t).sin().signum() + 0.1 * (c * t).sin()
    };
    let u1 = t
        .iter()
        .map(|&t| robot.linear_friction() * shape(t, 0.7, 2.3, 7.1))
        .collect();
    let u2 = t
        .iter()
        .map(|&t| 2.0 * robot.angular_friction() * shape(t, 0.5, 1.7, 5.3))
        .collect();
    (t, u1, u2)
}

/// Eq. 3 integrated by the plant's own RK4 (10 steps per log sample, input
/// held), measured with noise: a log as a torque robot would write it.
fn torque_log(robot: &RobotParams, seed: u64, rotate: bool) -> Log {
    let (t, u1, mut u2) = excitation(robot);
    if !rotate {
        u2.iter_mut().for_each(|u| *u = 0.0);
    }
    let mut s = State::default();
    let (mut v, mut omega) = (Vec::new(), Vec::new());
    for i in 0..t.len() {
        v.push(s.v);
        omega.push(s.omega);
        let u = Input {
            u1: u1[i],
            u2: u2[i],
        };
        for _ in 0..10 {
            s = robot.rk4_step(&s, u, LOG_DT / 10.0);
        }
    }
    let mut log = Log {
        source: format!("synthetic seed {seed}"),
        agent: 1,
        t,
        v,
        omega,
        u: Some([u1, u2]),
        ..Log::default()
    };
    add_noise(&mut log, seed);
    log
}

#[test]
fn table_i_robots_within_2_percent_and_intervals_cover_the_truth_in_90_percent_of_50_seeds() {
    for (name, robot) in RobotParams::PRESETS {
        let truth = [
            ("mass", robot.mass()),
            ("linear_friction", robot.linear_friction()),
            ("inertia", robot.inertia()),
            ("angular_friction", robot.angular_friction()),
        ];
        let mut covered = [0; 4];
        let mut worst = [0.0_f64; 4];
        for seed in 0..50 {
            let id = identify::identify(&torque_log(&robot, seed, true), Model::Torque).unwrap();
            assert!(id.warnings.is_empty(), "{name}: {:?}", id.warnings);
            for (i, (field, want)) in truth.iter().enumerate() {
                let e = id.get(field).unwrap();
                let rel = (e.value - want).abs() / want;
                worst[i] = worst[i].max(rel);
                assert!(
                    rel < 0.02,
                    "{name} seed {seed}: {field} = {} vs {want}",
                    e.value
                );
                covered[i] += usize::from(e.contains(*want));
            }
            // Held inputs (a zero-order hold logged at its period), found
            // as such; residuals are the measurement noise.
            assert!(id.axes.iter().all(|a| a.method == "held inputs"));
            assert!((id.axes[0].residual_rms / SIGMA_V - 1.0).abs() < 0.1);
            assert!((id.axes[1].residual_rms / SIGMA_OMEGA - 1.0).abs() < 0.1);
        }
        eprintln!(
            "{name}: worst relative errors {worst:?}, 95 % intervals covered {covered:?} / 50"
        );
        for (i, (field, _)) in truth.iter().enumerate() {
            assert!(
                covered[i] >= 45,
                "{name}: {field} covered in {} of 50",
                covered[i]
            );
        }
    }
}

#[test]
fn the_equation_error_guess_is_close_and_the_output_error_fit_is_closer() {
    let robot = RobotParams::AGENT1;
    let id = identify::identify(&torque_log(&robot, 7, true), Model::Torque).unwrap();
    let e = id.get("inertia").unwrap();
    assert!(
        (e.first_guess - robot.inertia()).abs() / robot.inertia() < 0.2,
        "{e:?}"
    );
    assert!((e.value - robot.inertia()).abs() <= (e.first_guess - robot.inertia()).abs());
}

#[test]
fn a_log_without_rotation_says_j_and_psi_are_not_identifiable_and_gives_no_number() {
    let robot = RobotParams::AGENT2;
    let id = identify::identify(&torque_log(&robot, 3, false), Model::Torque).unwrap();
    assert!(id.get("mass").is_some() && id.get("linear_friction").is_some());
    assert!(id.get("inertia").is_none() && id.get("angular_friction").is_none());
    assert_warns(&id, &["J, ψ not identifiable", "no rotation"]);
    let block = id.robot_toml("new");
    assert!(
        !block
            .lines()
            .any(|l| l.starts_with("inertia") || l.starts_with("angular_friction"))
    );
    assert!(block.contains("# inertia (J): not identifiable"), "{block}");
    assert!(id.robot_params(Some(&robot)).is_none());
}

#[test]
fn velocity_base_lags_are_recovered_within_5_percent() {
    let (tau_v, tau_w) = (0.1, 0.07);
    let t: Vec<f64> = (0..4000).map(|i| i as f64 * LOG_DT).collect();
    let cv: Vec<f64> = t
        .iter()
        .map(|&t| 0.15 * (0.9 * t).sin() + 0.1 * (2.9 * t).sin().signum())
        .collect();
    let cw: Vec<f64> = t
        .iter()
        .map(|&t| 0.8 * (0.6 * t).sin() + 0.6 * (2.1 * t).sin().signum())
        .collect();
    let log = lagged_base_log(
        "synthetic base",
        t,
        [cv.clone(), cw.clone()],
        [cv, cw],
        (tau_v, tau_w),
        11,
    );
    let id = identify::identify(&log, Model::Velocity).unwrap();
    for (field, want) in [("tau_v", tau_v), ("tau_omega", tau_w)] {
        let e = id.get(field).unwrap();
        eprintln!("{field}: {e:?}");
        assert!((e.value - want).abs() / want < 0.05, "{field}: {e:?}");
        assert!(e.contains(want), "{field}: {e:?}");
    }
    // The command never exceeded anything: limits are only observed.
    assert!(id.limits.iter().all(|l| !l.reached));
    let block = id.robot_toml("base");
    assert!(block.contains("drive = \"velocity\"") && block.contains("tau_v = "));
    assert!(
        block.contains("# v_max: not reached (largest seen: "),
        "{block}"
    );
}

/// Runs `identify-excitation` (or a shorter part) into `dir`.
fn run_excitation(dir: &std::path::Path, duration: Option<f64>) {
    let overrides = Overrides {
        duration,
        ..Overrides::default()
    };
    common::run_to_dir(
        &Scenario::builtin("identify-excitation").unwrap(),
        &overrides,
        dir,
    );
}

/// Adds the stated noise to `v`, `omega` of a read log.
fn add_noise(log: &mut Log, seed: u64) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (nv, nw) = (
        Normal::new(0.0, SIGMA_V).unwrap(),
        Normal::new(0.0, SIGMA_OMEGA).unwrap(),
    );
    log.v.iter_mut().for_each(|x| *x += nv.sample(&mut rng));
    log.omega.iter_mut().for_each(|x| *x += nw.sample(&mut rng));
}

#[test]
fn an_echelon_run_log_gives_table_i_and_the_identified_robot_reproduces_a_scenario() {
    let dir = tempfile::tempdir().unwrap();
    run_excitation(dir.path(), None);
    for (agent, truth) in [(1, RobotParams::AGENT1), (2, RobotParams::AGENT2)] {
        let mut log = Log::read_run(dir.path(), agent).unwrap();
        assert_eq!(log.detect(), Some(Model::Torque));
        add_noise(&mut log, 100 + agent as u64);
        let id = identify::identify(&log, Model::Torque).unwrap();
        for (field, want) in [
            ("mass", truth.mass()),
            ("linear_friction", truth.linear_friction()),
            ("inertia", truth.inertia()),
            ("angular_friction", truth.angular_friction()),
        ] {
            let e = id.get(field).unwrap();
            eprintln!("agent {agent} {field}: {e:?} (truth {want})");
            assert!(
                (e.value - want).abs() / want < 0.02,
                "agent {agent} {field}: {e:?}"
            );
        }
        // l and r come back from eq. 2 (u and τ logged).
        let [l, r] = id.geometry.unwrap();
        assert!(
            (l - truth.half_wheelbase()).abs() < 1e-9 && (r - truth.wheel_radius()).abs() < 1e-9
        );

        // Round trip: the identified block pasted into the circle experiment
        // (the controller then uses the identified m, η, J, ψ) drives the
        // true robot to the same ‖e‖ after 3 s (mid-transient) within 5 % as
        // the controller that knows the truth.
        let block = id.robot_toml("identified");
        let circle = Scenario::builtin("experiment-circle").unwrap();
        let mut src = circle.source().replace(
            &format!("robot = \"agent{agent}\""),
            "robot = \"identified\"",
        );
        src.push('\n');
        src.push_str(&block);
        let identified = Scenario::parse(&src, "round-trip.toml", None)
            .unwrap()
            .build(&Overrides::default())
            .unwrap();
        let spec = &identified.plan.agents()[agent - 1];
        assert_ne!(spec.torque_robot(), Some(&truth), "the block is in use");
        let with_identified = closed_loop_error(&identified.simulation(), spec, &truth, 3.0);
        let reference = circle.build(&Overrides::default()).unwrap();
        let with_truth = closed_loop_error(
            &reference.simulation(),
            &reference.plan.agents()[agent - 1],
            &truth,
            3.0,
        );
        eprintln!(
            "agent {agent}: ‖e(3 s)‖ {with_truth} (true model) vs {with_identified} (identified)"
        );
        assert!(with_truth > 1e-3, "mid-transient: {with_truth}");
        // The check can fail: the true model with m, η, J, ψ all 15 % high
        // in the law misses by more than 5 %.
        let off = format!(
            "\n[robots.off]\nmass = {}\nlinear_friction = {}\ninertia = {}\nangular_friction = {}\n\
             half_wheelbase = {}\nwheel_radius = {}\n",
            1.15 * truth.mass(),
            1.15 * truth.linear_friction(),
            1.15 * truth.inertia(),
            1.15 * truth.angular_friction(),
            truth.half_wheelbase(),
            truth.wheel_radius()
        );
        let wrong = Scenario::parse(
            &(circle
                .source()
                .replace(&format!("robot = \"agent{agent}\""), "robot = \"off\"")
                + &off),
            "wrong.toml",
            None,
        )
        .unwrap()
        .build(&Overrides::default())
        .unwrap();
        let with_wrong = closed_loop_error(
            &wrong.simulation(),
            &wrong.plan.agents()[agent - 1],
            &truth,
            3.0,
        );
        eprintln!("agent {agent}: ‖e(3 s)‖ with a model 15 % off {with_wrong}");
        assert!((with_wrong - with_truth).abs() > 0.05 * with_truth);
        assert!(
            (with_identified - with_truth).abs() <= 0.05 * with_truth,
            "agent {agent}: {with_identified} vs {with_truth}"
        );
    }
}

/// ‖e‖ at `t_end` of `spec`'s law (with the robot model it holds) driving
/// `plant` behind the simulation's reference: RK4 at 1 ms, input held per step.
fn closed_loop_error(sim: &Simulation, spec: &AgentSpec, plant: &RobotParams, t_end: f64) -> f64 {
    let dt = 1e-3;
    let mut s = spec.start();
    let steps = (t_end / dt).round() as usize;
    let eval = |t: f64, s: &State| {
        let jet = sim.reference().eval(t, Order::Two);
        follow(spec, s, LeaderView::Reference(&jet)).law
    };
    for k in 0..steps {
        let u = eval(k as f64 * dt, &s).u;
        s = plant.rk4_step(&s, u, dt);
    }
    let e = eval(t_end, &s).e;
    e[0].hypot(e[1])
}

#[test]
fn bad_logs_are_refused_with_the_file_and_what_is_wrong() {
    let dir = tempfile::tempdir().unwrap();
    run_excitation(dir.path(), Some(2.0));
    let file = dir.path().join("trajectory.csv");
    let text = std::fs::read_to_string(&file).unwrap();
    let name = file.display().to_string();

    // A torque log has no velocity-base columns.
    let log = Log::read_run(dir.path(), 1).unwrap();
    let e = identify::identify(&log, Model::Velocity).unwrap_err();
    assert!(matches!(e, IdentifyError::MissingColumns { .. }), "{e}");
    assert!(
        e.to_string().starts_with(&name) && e.to_string().contains("v_applied"),
        "{e}"
    );

    // Missing u1, u2.
    let no_u: String = text
        .lines()
        .map(|l| l.split(',').take(11).collect::<Vec<_>>().join(","))
        .collect::<Vec<_>>()
        .join("\n");
    let log = Log::parse_csv(&no_u, &name, 1).unwrap();
    let e = identify::identify(&log, Model::Torque).unwrap_err();
    assert!(e.to_string().contains("missing column(s) u1, u2"), "{e}");

    // Too short.
    let short: String = text.lines().take(41).collect::<Vec<_>>().join("\n");
    let e =
        identify::identify(&Log::parse_csv(&short, &name, 1).unwrap(), Model::Torque).unwrap_err();
    assert!(
        matches!(e, IdentifyError::TooShort { samples: 20, .. }),
        "{e}"
    );

    // Non-finite.
    let mut log = Log::read_run(dir.path(), 1).unwrap();
    log.omega[30] = f64::NAN;
    let e = identify::identify(&log, Model::Torque).unwrap_err();
    assert!(
        e.to_string()
            .contains("non-finite omega = NaN at t = 0.3 s"),
        "{e}"
    );

    // No such agent; missing base columns.
    let e = Log::read_run(dir.path(), 9).unwrap_err();
    assert!(
        e.to_string()
            .contains("no rows for agent 9 (agents in the log: 1, 2)"),
        "{e}"
    );
    let e = Log::parse_csv("t,x\n0,1\n", &name, 1).unwrap_err();
    assert!(
        e.to_string().contains("missing column(s) agent, v, omega"),
        "{e}"
    );

    // No excitation at all: the robot stands still.
    let mut log = Log::read_run(dir.path(), 1).unwrap();
    for s in [&mut log.v, &mut log.omega] {
        s.iter_mut().for_each(|x| *x = 0.0);
    }
    if let Some(u) = &mut log.u {
        u.iter_mut()
            .for_each(|s| s.iter_mut().for_each(|x| *x = 0.0));
    }
    let e = identify::identify(&log, Model::Torque).unwrap_err();
    assert!(matches!(e, IdentifyError::NoExcitation { .. }), "{e}");
}

/// The excitation manoeuvre on velocity bases `[robots.lab]` (`base` holds
/// its fields) under the kinematic law, run into a temporary directory.
fn velocity_run(base: &str) -> (String, tempfile::TempDir) {
    let src = Scenario::builtin("identify-excitation")
        .unwrap()
        .source()
        .replace("law = \"paper\"", "law = \"kinematic\"")
        .replace("robot = \"agent1\"", "robot = \"lab\"")
        .replace("robot = \"agent2\"", "robot = \"lab\"")
        + "\n[robots.lab]\ndrive = \"velocity\"\n"
        + base;
    let dir = tempfile::tempdir().unwrap();
    let scenario = Scenario::parse(&src, "lab.toml", None).unwrap();
    common::run_to_dir(&scenario, &Overrides::default(), dir.path());
    (src, dir)
}

#[test]
fn a_velocity_base_run_gives_its_lags_within_5_percent_and_the_speed_limit_it_hit() {
    let (tau_v, tau_w, v_max) = (0.1, 0.08, 0.6);
    let (src, dir) = velocity_run(&format!(
        "tau_v = {tau_v}\ntau_omega = {tau_w}\nv_max = {v_max}\nomega_max = 3.0\n"
    ));
    let mut log = Log::read_run(dir.path(), 1).unwrap();
    assert_eq!(log.detect(), Some(Model::Velocity));
    add_noise(&mut log, 5);
    let id = identify::identify(&log, Model::Velocity).unwrap();
    for (field, want) in [("tau_v", tau_v), ("tau_omega", tau_w)] {
        let e = id.get(field).unwrap();
        eprintln!("{field}: {e:?} (truth {want})");
        assert!((e.value - want).abs() / want < 0.05, "{field}: {e:?}");
    }
    let limit = |f: &str| id.limits.iter().find(|l| l.field == f).unwrap().clone();
    let v = limit("v_max");
    assert!(v.reached && (v.observed - v_max).abs() < 1e-12, "{v:?}");
    let w = limit("omega_max");
    assert!(!w.reached && w.observed < 3.0, "{w:?}");
    assert!(!limit("a_max").reached && !limit("alpha_max").reached);
    let block = id.robot_toml("lab");
    assert!(block.contains("v_max = 0.6 "), "{block}");
    assert!(
        block.contains("# omega_max: not reached (largest seen: "),
        "{block}"
    );
    // The block is a valid velocity robot.
    let reuse = src.replace("[robots.lab]", "[robots.old]") + &block;
    Scenario::parse(&reuse, "reuse.toml", None)
        .unwrap()
        .build(&Overrides::default())
        .unwrap();
}

#[test]
fn an_acceleration_limit_that_acted_is_identified_with_the_lags() {
    // Until the lag was fitted with its rate clamp, this log's lags were
    // withheld as misfit (the joint limit scales both axes together) and
    // `alpha_max` only said to have acted.
    let (_, dir) = velocity_run("tau_v = 0.1\ntau_omega = 0.1\nalpha_max = 4.0\n");
    let id = identify::identify(&Log::read_run(dir.path(), 1).unwrap(), Model::Velocity).unwrap();
    let alpha = id.limits.iter().find(|l| l.field == "alpha_max").unwrap();
    assert!(
        alpha.reached && alpha.estimate.is_some_and(|e| (e.value - 4.0).abs() < 1e-6),
        "{alpha:?}"
    );
    assert_warns(&id, &["alpha_max = 4.0000 identified with the lag"]);
    for field in ["tau_v", "tau_omega"] {
        let e = id.get(field).unwrap();
        assert!((e.value - 0.1).abs() < 1e-7, "{field}: {e:?}");
    }
    let block = id.robot_toml("lab");
    assert!(block.contains("\ntau_omega = 0.1 "), "{block}");
    assert!(block.contains("\nalpha_max = 4.0 "), "{block}");
    // a_max never bound on its own: only observed.
    let a = id.limits.iter().find(|l| l.field == "a_max").unwrap();
    assert!(!a.reached && a.estimate.is_none(), "{a:?}");
}

#[test]
fn a_noise_free_log_says_its_intervals_mean_nothing_and_a_noisy_one_does_not() {
    let robot = RobotParams::PRESETS[0].1;
    let mut clean = torque_log(&robot, 0, true);
    // torque_log adds noise: take it off again by re-simulating.
    let (t, u1, u2) = excitation(&robot);
    let [v, omega] = identify::simulate_torque(&robot, &t, &u1, &u2);
    clean.v = v;
    clean.omega = omega;
    let id = identify::identify(&clean, Model::Torque).unwrap();
    assert!(id.axes.iter().all(|a| a.noise_free), "{:?}", id.axes);
    assert!(id.params.iter().all(|p| p.noise_free));
    assert_warns(&id, &["noise-free log on the linear axis"]);
    let block = id.robot_toml("x");
    assert_eq!(
        block.matches("interval not meaningful").count(),
        4,
        "{block}"
    );
    assert!(!block.contains("95 % interval"), "{block}");
    // Exact to rounding.
    let m = id.get("mass").unwrap().value;
    assert!((m / robot.mass() - 1.0).abs() < 1e-9, "{m}");

    let noisy = identify::identify(&torque_log(&robot, 1, true), Model::Torque).unwrap();
    assert!(noisy.axes.iter().all(|a| !a.noise_free));
    assert_eq!(noisy.robot_toml("x").matches("95 % interval").count(), 4);
}

// ---------------------------------------------------------------------------
// Issue 20 item 3: the built-ins, every agent, robots swapped, logged every
// 1–20 ms, noise-free and noisy.

/// Built-in `name`, its torque robots' presets swapped (`agent1` ↔ `agent2`)
/// when `swap`, run for at most `max_duration` s and logged every `log_dt` s
/// into a temporary directory; with the truth of each agent (`None` for a
/// velocity base).
fn builtin_run(
    name: &str,
    swap: bool,
    log_dt: f64,
    max_duration: f64,
) -> (tempfile::TempDir, Vec<AgentSpec>) {
    let scenario = Scenario::builtin(name).unwrap();
    let mut src = scenario.source().to_owned();
    if swap {
        src = src
            .replace("robot = \"agent1\"", "robot = \"@swap@\"")
            .replace("robot = \"agent2\"", "robot = \"agent1\"")
            .replace("robot = \"@swap@\"", "robot = \"agent2\"");
    }
    let parsed = Scenario::parse(&src, &format!("{name}.toml"), None).unwrap();
    let full = settings(&parsed).duration;
    let mut run = parsed
        .build(&Overrides {
            duration: Some(full.min(max_duration)),
            log_dt: Some(log_dt),
            ..Overrides::default()
        })
        .unwrap();
    let specs = run.plan.agents().to_vec();
    let dir = tempfile::tempdir().unwrap();
    common::write_run(&mut run, dir.path());
    (dir, specs)
}

/// The built-ins whose agents include torque robots (`torque`) or velocity
/// bases (`!torque`).
fn builtins(torque: bool) -> Vec<&'static str> {
    echelon::scenario::builtin()
        .iter()
        .map(|(n, _)| *n)
        .filter(|n| {
            let run = Scenario::builtin(n)
                .unwrap()
                .build(&Overrides::default())
                .unwrap();
            run.plan.agents().iter().any(|a| {
                if torque {
                    a.torque_robot().is_some()
                } else {
                    a.velocity_robot().is_some()
                }
            })
        })
        .collect()
}

/// The truth an identification of `spec` is checked against.
fn truth_of(spec: &AgentSpec) -> Vec<(&'static str, f64)> {
    match (spec.torque_robot(), spec.velocity_robot()) {
        (Some(r), _) => vec![
            ("mass", r.mass()),
            ("linear_friction", r.linear_friction()),
            ("inertia", r.inertia()),
            ("angular_friction", r.angular_friction()),
        ],
        (None, Some(b)) => vec![
            ("tau_v", b.base().tau_v()),
            ("tau_omega", b.base().tau_omega()),
        ],
        (None, None) => unreachable!(),
    }
}

/// What 50 noise seeds (and the noise-free log) gave for one agent's
/// parameter: printed in how many seeds, covered in how many of those, the
/// worst relative error printed, the noise-free log's relative error (`None`
/// when withheld) and a reason it was withheld.
#[derive(Debug, Default, Clone)]
struct Tally {
    printed: usize,
    covered: usize,
    worst: f64,
    clean: Option<f64>,
    why: Option<String>,
}

/// Identifies agent `agent` of the run in `dir` noise-free and with `seeds`
/// noise seeds (`seed0`, `seed0 + 1`, …), with or without its integrals;
/// one tally per parameter.
fn tally(
    dir: &std::path::Path,
    agent: usize,
    spec: &AgentSpec,
    integrals: bool,
    (seed0, seeds): (u64, u64),
) -> Vec<(&'static str, Tally)> {
    let model = if spec.torque_robot().is_some() {
        Model::Torque
    } else {
        Model::Velocity
    };
    let mut log = Log::read_run(dir, agent).unwrap();
    assert!(log.integrals.is_some(), "integrals.csv read");
    if !integrals {
        log.integrals = None;
    }
    let truth = truth_of(spec);
    let mut out: Vec<(&'static str, Tally)> =
        truth.iter().map(|(f, _)| (*f, Tally::default())).collect();
    let record = |id: &Result<identify::Identified, IdentifyError>,
                  out: &mut Vec<(&'static str, Tally)>,
                  clean: bool| {
        for ((field, want), (_, t)) in truth.iter().zip(out.iter_mut()) {
            let Ok(id) = id else {
                t.why
                    .get_or_insert_with(|| format!("{:?}", id.as_ref().err()));
                continue;
            };
            let p = id.params.iter().find(|p| p.field == *field).unwrap();
            match p.estimate {
                Some(e) => {
                    let rel = (e.value - want).abs() / want;
                    if clean {
                        t.clean = Some(rel);
                    } else {
                        t.printed += 1;
                        t.covered += usize::from(e.contains(*want));
                        t.worst = t.worst.max(rel);
                    }
                }
                None => {
                    t.why
                        .get_or_insert_with(|| p.not_identifiable.clone().unwrap_or_default());
                }
            }
        }
    };
    record(&identify::identify(&log, model), &mut out, true);
    for seed in seed0..seed0 + seeds {
        let mut noisy = log.clone();
        add_noise(&mut noisy, seed);
        record(&identify::identify(&noisy, model), &mut out, false);
    }
    out
}

/// Checks one run's tallies: every printed parameter within 2 % of the truth
/// (noise-free and in every noise seed), every parameter not printed has a
/// reason, and each interval covers the truth in at least 80 % of the seeds
/// it was printed in (when printed in at least 20). Returns the seeds
/// printed and covered, summed, for the 90 % check over a whole case.
///
/// Why 80 % per parameter and 90 % pooled: a calibrated 95 % interval
/// covers in fewer than 45 of 50 seeds with probability 3.8 % (binomial),
/// so asserting 45 / 50 for each of the hundreds of parameters a run of
/// this file checks would fail by chance; fewer than 40 of 50 has
/// probability 2·10⁻⁵. Pooled over a case (200–800 intervals) 90 % is
/// 4–7 standard deviations below 95 %: a systematic under-coverage fails it.
fn assert_tallies(case: &str, agent: usize, tallies: &[(&'static str, Tally)]) -> [usize; 2] {
    let mut sum = [0, 0];
    for (field, t) in tallies {
        let what = format!("{case} agent {agent} {field}: {t:?}");
        if let Some(rel) = t.clean {
            assert!(rel < 0.02, "noise-free: {what}");
        }
        assert!(t.worst < 0.02, "noisy: {what}");
        if t.printed >= 20 {
            assert!(5 * t.covered >= 4 * t.printed, "coverage: {what}");
        }
        if t.clean.is_none() || t.printed < 50 {
            assert!(t.why.as_deref().is_some_and(|w| !w.is_empty()), "{what}");
        }
        sum[0] += t.printed;
        sum[1] += t.covered;
    }
    sum
}

/// The pooled 90 % coverage of a case ([`assert_tallies`]), when it printed
/// at least 100 intervals.
fn assert_pooled(case: &str, [printed, covered]: [usize; 2]) {
    eprintln!("{case}: {covered} of {printed} intervals cover the truth");
    if printed >= 100 {
        assert!(
            10 * covered >= 9 * printed,
            "{case}: {covered} of {printed}"
        );
    }
}

/// Noise seeds per agent and log, as the issue asks.
const SEEDS: u64 = 50;

/// The runs a property case draws: built-in, robots swapped, log interval
/// in whole ms from 1 to 20 (a multiple of the built-in's step).
fn run_case(torque: bool) -> impl Strategy<Value = (&'static str, bool, u32)> {
    let names = builtins(torque);
    (proptest::sample::select(names), any::<bool>(), 1_u32..=20)
}

/// Runs a case and checks every agent of the model asked for, with and (for
/// the torque model) without the integrals. Durations are capped at 20 s
/// (the transients that excite the robots; the experiments run 157–314 s).
fn check_case(name: &str, swap: bool, log_ms: u32, torque: bool) {
    let scenario = Scenario::builtin(name).unwrap();
    let step = settings(&scenario).dt;
    // The log interval is a whole multiple of the step.
    let k = ((f64::from(log_ms) * 1e-3 / step).round() as u32).max(1);
    let log_dt = f64::from(k) * step;
    let (dir, specs) = builtin_run(name, swap, log_dt, 20.0);
    let case = format!("{name} (swapped {swap}) logged every {log_dt} s");
    let mut pooled = [0, 0];
    for (i, spec) in specs.iter().enumerate() {
        if spec.torque_robot().is_some() != torque {
            continue;
        }
        for integrals in [true, false] {
            if !integrals && !torque {
                continue;
            }
            // Noise seeds of their own per run and agent, so that a case's
            // pooled coverage counts independent draws.
            let seed0 = (u64::from(log_ms) << 32)
                + (u64::from(swap) << 31)
                + ((i as u64) << 24)
                + name.len() as u64 * 1000;
            let t = tally(dir.path(), i + 1, spec, integrals, (seed0, SEEDS));
            eprintln!("{case} agent {} integrals {integrals}: {t:?}", i + 1);
            let [p, c] = assert_tallies(&format!("{case} integrals {integrals}"), i + 1, &t);
            pooled = [pooled[0] + p, pooled[1] + c];
        }
    }
    assert_pooled(&case, pooled);
}

/// Checks `cases` runs drawn by [`run_case`] for the torque (`torque`) or
/// the velocity model with [`check_case`] for the same model, from the fixed
/// RNG seed `seed` (CI reruns the same sample); a failing case is shrunk and
/// reported as `proptest!` reports it.
fn check_sample(torque: bool, cases: u32, seed: u64) {
    let config = proptest::test_runner::contextualize_config(fixed_sample(cases, seed));
    let result = proptest::test_runner::TestRunner::new(config).run(
        &run_case(torque),
        |(name, swap, log_ms)| {
            check_case(name, swap, log_ms, torque);
            Ok(())
        },
    );
    if let Err(e) = result {
        panic!("{e}");
    }
}

#[test]
fn torque_builtins_every_agent_any_log_interval_within_2_percent_or_withheld() {
    // 24 cases × every torque agent of the run (1–4) × 51 logs (noise-free
    // and 50 seeds) × with and without integrals.csv.
    check_sample(true, 24, 20);
}

#[test]
fn velocity_builtins_every_agent_any_log_interval_within_2_percent_or_withheld() {
    // 12 cases × every velocity agent (2–6) × 51 logs.
    check_sample(false, 12, 21);
}

#[test]
fn nonfeasible_agent2_logged_every_10_ms_is_exact_with_its_integrals_and_withheld_without() {
    // The case: the on-the-spot turn at t = 4 s under the
    // continuous-time law; agent2's truth.
    let (dir, specs) = builtin_run("nonfeasible", true, 0.01, 1e9);
    assert_eq!(specs[0].torque_robot(), Some(&RobotParams::AGENT2));
    let with = tally(dir.path(), 1, &specs[0], true, (0, SEEDS));
    for (field, t) in &with {
        // Exact to rounding noise-free, printed in every seed.
        assert!(t.clean.is_some_and(|r| r < 1e-9), "{field}: {t:?}");
        assert_eq!(t.printed, 50, "{field}: {t:?}");
    }
    let pooled = assert_tallies("nonfeasible agent2 10 ms", 1, &with);
    assert_pooled("nonfeasible agent2 10 ms", pooled);
    // Without integrals.csv (an older or a fleet log) the sampled inputs
    // misfit: noise-free, every parameter is withheld with the reason; with
    // noise, what is printed interpolates the inputs and its interval
    // includes the difference to holding them.
    let without = tally(dir.path(), 1, &specs[0], false, (0, SEEDS));
    eprintln!("with integrals: {with:?}\nwithout: {without:?}");
    for (field, t) in &without {
        assert!(t.clean.is_none(), "{field}: {t:?}");
        let why = t.why.as_deref().unwrap();
        assert!(
            (why.contains("misfits") || why.contains("between samples"))
                && why.contains("integrals.csv"),
            "{field}: {why}"
        );
    }
    let pooled = assert_tallies("nonfeasible agent2 10 ms, no integrals", 1, &without);
    assert_pooled("nonfeasible agent2 10 ms, no integrals", pooled);
    let mut log = Log::read_run(dir.path(), 1).unwrap();
    let exact = identify::identify(&log, Model::Torque).unwrap();
    assert!(exact.axes.iter().all(|a| a.method == "integrals"));
    log.integrals = None;
    add_noise(&mut log, 7);
    let id = identify::identify(&log, Model::Torque).unwrap();
    assert_eq!(id.axes[1].method, "interpolated inputs", "{:?}", id.axes);
    assert_warns(
        &id,
        &["angular axis's inputs between samples are not in the log"],
    );
}

/// What a [`bag_log`]'s base does beyond its lags.
#[derive(Debug, Clone, Copy)]
struct Quirks {
    /// Latency: each command applies this long after its stamp, ms.
    late_ms: usize,
    /// `[a_max, α_max]`: the largest rate of each axis (per axis).
    a_max: [f64; 2],
}

impl Quirks {
    /// A first-order lag on each axis, nothing else.
    const NONE: Quirks = Quirks {
        late_ms: 0,
        a_max: [f64::INFINITY; 2],
    };
}

/// A ROS 2 bag's velocity-base log as `echelon identify` builds it
/// (echelon-mcap's `velocity_log`, rebuilt here on the same rules): a base
/// with lags `taus` integrated exactly on a 1 ms grid, commands published
/// every `cmd_ms` (random steps held 0.3–1.5 s, a chirp of ω in the middle
/// third, a stop for the last second, as `scripts/ros2/lagged_base_bag.py`),
/// odometry every `odom_ms` offset by `offset_ms` with noise σ_v = 0.01 m/s,
/// σ_ω = 0.02 rad/s (noise-free when `seed` is `None`); the base's
/// [`Quirks`]: it applies each command `late_ms` after its stamp (latency),
/// and clamps each axis's rate at `a_max` (per axis, as
/// diff_drive_controller's speed limiter). The grid is the
/// odometry's times, the input of each interval the commands' hold averaged
/// over it, and `hold` the command messages themselves.
fn bag_log(
    taus: [f64; 2],
    cmd_ms: usize,
    odom_ms: usize,
    offset_ms: usize,
    profile_seed: u64,
    seed: Option<u64>,
    quirks: Quirks,
) -> Log {
    let Quirks { late_ms, a_max } = quirks;
    use rand::Rng;
    let duration_ms = 40_000;
    let mut rng = ChaCha8Rng::seed_from_u64(profile_seed);
    let (mut pv, mut pw) = (vec![0.0; duration_ms], vec![0.0; duration_ms]);
    let mut t = 500;
    while t < duration_ms {
        let hold = rng.random_range(300..=1500);
        let (vs, ws) = (rng.random_range(-0.5..0.5), rng.random_range(-1.2..1.2));
        for k in t..(t + hold).min(duration_ms) {
            (pv[k], pw[k]) = (vs, ws);
        }
        t += hold;
    }
    let third = duration_ms / 3;
    for (k, w) in pw.iter_mut().enumerate().take(2 * third).skip(third) {
        let s = (k - third) as f64 / 1000.0;
        *w = 0.8 * (2.0 * std::f64::consts::PI * (0.2 * s + 0.05 * s * s)).sin();
    }
    for k in duration_ms - 1000..duration_ms {
        (pv[k], pw[k]) = (0.0, 0.0);
    }
    let mut noise = seed.map(ChaCha8Rng::seed_from_u64);
    let (nv, nw) = (
        Normal::new(0.0, 0.01).unwrap(),
        Normal::new(0.0, 0.02).unwrap(),
    );
    let a = taus.map(|tau| (-0.001 / tau).exp());
    let (mut x, mut held) = ([0.0; 2], [0.0; 2]);
    let mut cmd: Vec<(usize, [f64; 2])> = Vec::new();
    let mut odom: Vec<(usize, [f64; 2])> = Vec::new();
    for k in 0..duration_ms {
        if k % cmd_ms == 0 {
            cmd.push((k, [pv[k], pw[k]]));
        }
        if k >= late_ms && (k - late_ms).is_multiple_of(cmd_ms) {
            held = [pv[k - late_ms], pw[k - late_ms]];
        }
        if k % odom_ms == offset_ms {
            let m = match &mut noise {
                Some(r) => [x[0] + nv.sample(r), x[1] + nw.sample(r)],
                None => x,
            };
            odom.push((k, m));
        }
        for i in 0..2 {
            let (lagged, most) = (a[i] * x[i] + (1.0 - a[i]) * held[i], a_max[i] * 1e-3);
            x[i] = if (lagged - x[i]).abs() <= most {
                lagged
            } else {
                x[i] + most.copysign(lagged - x[i])
            };
        }
    }
    // The log: odometry from the first command on (the last is a stop).
    let t0 = odom[0].0;
    let last_at = |t: usize| cmd.partition_point(|c| c.0 <= t) - 1;
    let average = |from: usize, to: usize| -> [f64; 2] {
        let mut acc = [0.0; 2];
        for k in from..to {
            let c = cmd[last_at(k)].1;
            acc[0] += c[0];
            acc[1] += c[1];
        }
        acc.map(|a| a / (to - from) as f64)
    };
    let mut log = Log {
        source: "in-memory bag".into(),
        agent: 1,
        ..Log::default()
    };
    let mut u: [Vec<f64>; 2] = Default::default();
    for (i, (k, m)) in odom.iter().enumerate() {
        log.t.push((k - t0) as f64 * 1e-3);
        log.v.push(m[0]);
        log.omega.push(m[1]);
        let avg = match odom.get(i + 1) {
            Some((next, _)) => average(*k, *next),
            None => cmd[last_at(*k)].1,
        };
        u[0].push(avg[0]);
        u[1].push(avg[1]);
    }
    log.cmd = Some(u);
    let mut hold = identify::Hold::default();
    for (k, c) in &cmd[last_at(t0)..] {
        hold.t.push((*k as f64 - t0 as f64) * 1e-3);
        hold.u[0].push(c[0]);
        hold.u[1].push(c[1]);
    }
    log.hold = Some(hold);
    log
}

/// The bags the lag properties draw: lags `[τ_v, τ_ω]` of 0.05–0.4 s,
/// odometry every 20 or 50 ms offset by a whole ms within that, and the
/// seed of the command profile.
fn bag_case() -> impl Strategy<Value = ([f64; 2], usize, usize, u64)> {
    (
        0.05_f64..0.4,
        0.05_f64..0.4,
        any::<bool>(),
        1_usize..20,
        0_u64..1000,
    )
        .prop_map(|(tau_v, tau_w, fifty, offset, profile)| {
            let odom_ms = if fifty { 20 } else { 50 };
            ([tau_v, tau_w], odom_ms, offset % odom_ms, profile)
        })
}

/// The velocity lags `[τ_v, τ_ω]` identified from [`bag_log`]'s noise-free
/// log and its [`SEEDS`] noisy ones (commands every 50 ms, odometry every
/// `odom_ms` + `offset` ms, the base's `quirks`), tallied against `truth`:
/// one tally per lag.
fn tally_bag_lags(
    truth: [f64; 2],
    odom_ms: usize,
    offset: usize,
    profile: u64,
    quirks: Quirks,
) -> Vec<(&'static str, Tally)> {
    let mut tallies: Vec<(&'static str, Tally)> = ["tau_v", "tau_omega"]
        .map(|f| (f, Tally::default()))
        .to_vec();
    let logs = std::iter::once(None).chain((0..SEEDS).map(|s| Some(profile * 100 + s)));
    for seed in logs {
        let log = bag_log(truth, 50, odom_ms, offset, profile, seed, quirks);
        let id = identify::identify(&log, Model::Velocity);
        for (want, (field, t)) in truth.iter().zip(tallies.iter_mut()) {
            let p = id
                .as_ref()
                .ok()
                .and_then(|id| id.params.iter().find(|p| p.field == *field));
            match p.and_then(|p| p.estimate) {
                Some(e) if seed.is_none() => t.clean = Some((e.value / want - 1.0).abs()),
                Some(e) => {
                    t.printed += 1;
                    t.covered += usize::from(e.contains(*want));
                    t.worst = t.worst.max((e.value / want - 1.0).abs());
                }
                None => {
                    let why = match (&id, p) {
                        (Err(e), _) => e.to_string(),
                        (Ok(_), p) => p
                            .and_then(|p| p.not_identifiable.clone())
                            .unwrap_or_default(),
                    };
                    t.why.get_or_insert(why);
                }
            }
        }
    }
    tallies
}

proptest! {
    // 12 cases × (noise-free + 50 seeds): ROS 2 bags at 20 and 50 Hz
    // odometry, 20 Hz commands, lags 0.05–0.4 s.
    #![proptest_config(fixed_sample(12, 22))]
    #[test]
    fn ros2_bag_lags_at_20_and_50_hz_within_2_percent_and_covered(
        ([tau_v, tau_w], odom_ms, offset, profile) in bag_case(),
    ) {
        let case = format!("τ = {tau_v:.3}, {tau_w:.3} s, odometry every {odom_ms} ms + {offset}");
        let tallies = tally_bag_lags([tau_v, tau_w], odom_ms, offset, profile, Quirks::NONE);
        // Noise-free: exact, through the hold.
        for (field, t) in &tallies {
            prop_assert!(t.clean.is_some_and(|e| e < 1e-6), "{case}: {field} {t:?}");
        }
        eprintln!("{case}: {tallies:?}");
        let pooled = assert_tallies(&case, 1, &tallies);
        assert_pooled(&case, pooled);
    }
}

proptest! {
    // 12 cases × (noise-free + 50 seeds): the bags above from a base whose
    // acceleration limit (per axis) acts on its larger steps only: `a_max`
    // a random fraction (0.3–1.2) of the largest step's initial rate
    // (1 m/s and 2.4 rad/s over the lag), so that from a few to most
    // transients are cut for a few milliseconds. The lag fitted through them
    // stretches to follow: before the transient check it was printed 3–4 %
    // long with a ±0.8 % interval (τ_v = 0.05 s, a_max = 12 m/s²).
    #![proptest_config(fixed_sample(12, 24))]
    #[test]
    fn a_base_whose_acceleration_limit_cuts_its_largest_steps_gets_lags_within_2_percent_or_withheld(
        ([tau_v, tau_w], odom_ms, offset, profile) in bag_case(),
        cut in 0.3_f64..1.2,
    ) {
        let quirks = Quirks { a_max: [cut * 1.0 / tau_v, cut * 2.4 / tau_w], ..Quirks::NONE };
        let case = format!(
            "τ = {tau_v:.3}, {tau_w:.3} s, a_max = {:.2}, {:.2}, odometry every {odom_ms} ms + {offset}, profile {profile}",
            quirks.a_max[0], quirks.a_max[1]
        );
        let tallies = tally_bag_lags([tau_v, tau_w], odom_ms, offset, profile, quirks);
        eprintln!("{case}: {tallies:?}");
        let pooled = assert_tallies(&case, 1, &tallies);
        assert_pooled(&case, pooled);
    }
}

#[test]
fn a_base_that_applies_its_commands_late_gets_its_dead_time_when_the_log_is_noise_free() {
    // The base acts on each command 1–5 ms after its stamp: a dead time,
    // which a bag's fit now has (it was a misfit, both lags withheld, before
    // the dead time was identified). Noise-free, the lags and the dead time
    // come out to the fit's convergence.
    for late in [0, 1, 2, 5] {
        let log = bag_log(
            [0.1, 0.15],
            50,
            20,
            7,
            1,
            None,
            Quirks {
                late_ms: late,
                ..Quirks::NONE
            },
        );
        let id = identify::identify(&log, Model::Velocity).unwrap();
        assert!(id.axes.iter().all(|a| a.method == "command hold"));
        let d = id.get("dead_time").unwrap();
        assert!(
            (d.value - late as f64 * 1e-3).abs() < 1e-6,
            "late {late} ms: {d:?}"
        );
        assert!((id.get("tau_v").unwrap().value / 0.1 - 1.0).abs() < 1e-6);
        assert!((id.get("tau_omega").unwrap().value / 0.15 - 1.0).abs() < 1e-6);
    }
}

proptest! {
    #![proptest_config(fixed_sample(64, 31))]

    /// A base's speed limit scales `v` and `ω` together: when one axis's
    /// limit binds, the other axis's applied value is cut too. A speed
    /// limit `identify` says the log shows is the true one, whichever axis
    /// bound and whatever the commands (random sinusoids and steps, up to
    /// 3× either limit), never the cut value of the other axis (the
    /// `turtlebot-circle` log gave `omega_max = 0.39` for a Burger's 2.84).
    #[test]
    fn a_speed_limit_said_to_be_shown_is_the_true_one(
        v_max in 0.1_f64..2.0,
        omega_max in 0.2_f64..5.0,
        amp in (0.2_f64..3.0, 0.2_f64..3.0),
        freq in (0.1_f64..2.0, 0.1_f64..2.0),
        steps in any::<bool>(),
        seed in any::<u64>(),
    ) {
        use echelon::base::{VelocityBase, VelocityBaseSpec, VelocityCommand};
        let base = VelocityBase::new(VelocityBaseSpec {
            v_max,
            omega_max,
            ..VelocityBase::IDEAL.spec()
        })
        .unwrap();
        let (tau_v, tau_w) = (0.1, 0.07);
        let t: Vec<f64> = (0..3000).map(|i| i as f64 * LOG_DT).collect();
        let wave = |t: f64, f: f64, phase: f64| {
            let s = (f * t + phase).sin();
            if steps { s.signum() * (0.5 + 0.5 * (3.1 * f * t).sin().abs()) } else { s }
        };
        let cmd: Vec<VelocityCommand> = t
            .iter()
            .map(|&t| VelocityCommand {
                v: amp.0 * v_max * wave(t, freq.0, 0.0),
                omega: amp.1 * omega_max * wave(t, freq.1, 1.3),
            })
            .collect();
        let applied: Vec<VelocityCommand> = cmd.iter().map(|c| base.limit(*c).0).collect();
        let axis = |f: fn(&VelocityCommand) -> f64, c: &[VelocityCommand]| -> Vec<f64> {
            c.iter().map(f).collect()
        };
        let (cv, cw) = (axis(|c| c.v, &cmd), axis(|c| c.omega, &cmd));
        let (av, aw) = (axis(|c| c.v, &applied), axis(|c| c.omega, &applied));
        let log = lagged_base_log(
            "synthetic limited base",
            t,
            [cv, cw],
            [av, aw],
            (tau_v, tau_w),
            seed,
        );
        let Ok(id) = identify::identify(&log, Model::Velocity) else {
            return Ok(());
        };
        for (field, truth) in [("v_max", v_max), ("omega_max", omega_max)] {
            let l = id.limits.iter().find(|l| l.field == field).unwrap();
            if l.reached {
                prop_assert!(
                    (l.observed - truth).abs() <= 1e-9 * truth,
                    "{field} = {} said shown, truth {truth}",
                    l.observed
                );
            }
        }
    }
}

// ---------------------------------------------------------------------------
// A velocity base whose acceleration limit acted: the lag fitted with its
// rate clamp in the loop, from the run's integrals.

/// How [`limited_base_log`] drives and measures its base.
#[derive(Debug, Clone, Copy)]
struct Drive {
    /// Each axis's steps: `[lo, hi)` of the step over `limit · τ` (the lag's
    /// initial rate over the limit); above 1 the limit cuts the step.
    cut: [(f64, f64); 2],
    /// `[a_max τ_v, α_max τ_ω]` of the limits the steps are drawn against.
    scale: [f64; 2],
    /// Measurement noise `[σ_v, σ_ω]` (zero: noise-free).
    sigma: [f64; 2],
    /// The base acts on each command this many plant steps late (a delay).
    late: usize,
}

/// The log of `base` driven through its own step (`VelocityBase::rk4_step`,
/// 1 ms, the command held) by random steps on each axis at their own times
/// (held 0.4–1.2 s, sizes drawn as `drive.cut` says, kept within 0.8 of the
/// speed limit), logged every 10 ms for 40 s from rest with the running
/// integrals an `echelon run` writes (`∫v dt`, `∫ω dt` with RK4's weights of
/// the plant's stages, `∫` of the applied command).
fn limited_base_log(base: echelon::base::VelocityBase, drive: Drive, seed: u64) -> Log {
    use echelon::base::VelocityCommand;
    use rand::Rng;
    use std::cell::Cell;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (dt, every, steps) = (1e-3, 10, 40_000);
    let tops: Vec<f64> = (0..2)
        .map(|a| {
            let m = [base.v_max(), base.omega_max()][a];
            if m.is_finite() {
                0.8 * m
            } else {
                4.0 * drive.scale[a]
            }
        })
        .collect();
    // The applied command, per plant step.
    let mut u = [vec![0.0; steps], vec![0.0; steps]];
    for axis in 0..2 {
        let (mut k, mut level) = (200, 0.0_f64);
        while k < steps {
            let hold = rng.random_range(400..1200);
            let (lo, hi) = drive.cut[axis];
            let size = rng.random_range(lo..hi) * drive.scale[axis];
            let up = if level + size > tops[axis] {
                false
            } else if level - size < -tops[axis] {
                true
            } else {
                rng.random_bool(0.5)
            };
            level = if up { level + size } else { level - size }.clamp(-tops[axis], tops[axis]);
            for x in &mut u[axis][k..(k + hold).min(steps)] {
                *x = level;
            }
            k += hold;
        }
    }
    let noise = drive
        .sigma
        .map(|s| Normal::new(0.0, s.max(f64::MIN_POSITIVE)).unwrap());
    let mut s = State::default();
    let (mut dist, mut int) = (0.0, [0.0; 2]);
    let mut log = Log {
        source: "in-memory limited base".into(),
        agent: 1,
        ..Log::default()
    };
    let (mut applied, mut ints): ([Vec<f64>; 2], identify::Integrals) = Default::default();
    for k in 0..steps {
        if k % every == 0 {
            log.t.push(k as f64 * dt);
            let m = [s.v, s.omega];
            let noisy: Vec<f64> = (0..2)
                .map(|a| {
                    m[a] + if drive.sigma[a] > 0.0 {
                        noise[a].sample(&mut rng)
                    } else {
                        0.0
                    }
                })
                .collect();
            log.v.push(noisy[0]);
            log.omega.push(noisy[1]);
            for a in 0..2 {
                applied[a].push(u[a][k]);
                ints.input[a].push(int[a]);
            }
            ints.s.push(dist);
            ints.theta.push(s.theta);
        }
        let acting = k.saturating_sub(drive.late);
        let cmd = VelocityCommand {
            v: u[0][acting],
            omega: u[1][acting],
        };
        // The distance with the weights RK4 gives the stages' speeds.
        let (stage, sum) = (Cell::new(0), Cell::new(0.0));
        let _ = s.rk4_step(dt, |x| {
            let w = [1.0, 2.0, 2.0, 1.0][stage.get()];
            stage.set(stage.get() + 1);
            sum.set(sum.get() + w * x.v);
            base.derivative(x, cmd)
        });
        dist += dt / 6.0 * sum.get();
        int[0] += dt * u[0][k];
        int[1] += dt * u[1][k];
        s = base.rk4_step(&s, cmd, dt);
    }
    log.cmd = Some(applied.clone());
    log.applied = Some(applied);
    log.integrals = Some(ints);
    log
}

/// Random bases well outside the presets: lags 0.02–0.6 s, acceleration
/// limits 0.1–5 m/s² and 0.3–10 rad/s², speed limits (or none), joint or
/// per-axis limits.
fn random_base() -> impl Strategy<Value = echelon::base::VelocityBase> {
    (
        (0.02_f64..0.6, 0.02_f64..0.6),
        (0.1_f64..5.0, 0.3_f64..10.0),
        (
            prop_oneof![Just(f64::INFINITY), 2.0_f64..6.0],
            prop_oneof![Just(f64::INFINITY), 2.0_f64..6.0],
        ),
        any::<bool>(),
    )
        .prop_map(
            |((tau_v, tau_omega), (a_max, alpha_max), (v_top, omega_top), joint)| {
                // Speed limits 2–6 times the largest step the limit lets
                // through uncut (or none), so that larger steps fit under them.
                let (v_max, omega_max) = (v_top * a_max * tau_v, omega_top * alpha_max * tau_omega);
                let accel = if joint {
                    echelon::base::AccelLimit::Joint
                } else {
                    echelon::base::AccelLimit::PerAxis
                };
                let limits = [tau_v, tau_omega, v_max, omega_max, a_max, alpha_max];
                common::velocity_base(limits, accel).unwrap()
            },
        )
}

/// `[a_max τ_v, α_max τ_ω]`: the largest step each axis takes uncut from rest.
fn scale(base: &echelon::base::VelocityBase) -> [f64; 2] {
    [
        base.a_max() * base.tau_v(),
        base.alpha_max() * base.tau_omega(),
    ]
}

/// Steps of 0.2–3.5 times what the limit allows: it cuts some, not all.
const SOME_CUT: [(f64, f64); 2] = [(0.2, 3.5), (0.2, 3.5)];

fn limit_of(id: &identify::Identified, field: &str) -> identify::Limit {
    id.limits.iter().find(|l| l.field == field).unwrap().clone()
}

proptest! {
    #![proptest_config(fixed_sample(24, 31))]
    #[test]
    fn a_base_whose_acceleration_limit_acted_gets_its_lags_and_limits_noise_free_to_1e_6(
        base in random_base(),
        seed in 0_u64..1000,
    ) {
        let log = limited_base_log(base, Drive { cut: SOME_CUT, scale: scale(&base), sigma: [0.0; 2], late: 0 }, seed);
        let id = identify::identify(&log, Model::Velocity).unwrap();
        let case = format!("{base:?}, seed {seed}: {:?}", id.warnings);
        for (field, want) in [("tau_v", base.tau_v()), ("tau_omega", base.tau_omega())] {
            let e = id.get(field);
            prop_assert!(e.is_some_and(|e| (e.value / want - 1.0).abs() < 1e-6), "{field} {e:?} {case}");
        }
        prop_assert!(id.axes.iter().all(|a| a.noise_free), "{case}");
        prop_assert!(id.axes.iter().any(|a| a.method == "integrals, rate limit"), "{case}");
        // A limit the steps rode is identified, exactly; one that never
        // bound on its own (the other axis's scaled it) is only observed.
        let mut identified = 0;
        for (field, want) in [("a_max", base.a_max()), ("alpha_max", base.alpha_max())] {
            let l = limit_of(&id, field);
            if let Some(e) = l.estimate {
                identified += 1;
                prop_assert!(l.reached && l.noise_free && (e.value / want - 1.0).abs() < 1e-6, "{field} {l:?} {case}");
            }
        }
        prop_assert!(identified > 0, "{case}");
        let block = id.robot_toml("b");
        prop_assert!(block.contains("identified with the lag"), "{block}");
    }
}

proptest! {
    #![proptest_config(fixed_sample(12, 32))]
    #[test]
    fn with_noise_the_lags_and_limits_printed_are_within_2_percent(
        base in random_base(),
        seed in 0_u64..1000,
    ) {
        // Noise of 0.5 % of the axis's largest step (small, not rounding).
        let sigma = scale(&base).map(|s| 0.005 * 3.5 * s);
        let log = limited_base_log(base, Drive { cut: SOME_CUT, scale: scale(&base), sigma, late: 0 }, seed);
        let id = identify::identify(&log, Model::Velocity).unwrap();
        let case = format!("{base:?}, seed {seed}: {:?}", id.warnings);
        // Printed within 2 %, or withheld with the reason: never
        // confidently wrong.
        for (field, want) in [("tau_v", base.tau_v()), ("tau_omega", base.tau_omega())] {
            let p = id.params.iter().find(|p| p.field == field).unwrap();
            match p.estimate {
                Some(e) => prop_assert!((e.value / want - 1.0).abs() < 0.02, "{field} {e:?} {case}"),
                None => prop_assert!(p.not_identifiable.is_some(), "{p:?} {case}"),
            }
        }
        for (field, want) in [("a_max", base.a_max()), ("alpha_max", base.alpha_max())] {
            let l = limit_of(&id, field);
            // Printed within 2 %, or not claimed to be the limit.
            match l.estimate {
                Some(e) => prop_assert!((e.value / want - 1.0).abs() < 0.02 && l.reached, "{field} {l:?} {case}"),
                None => prop_assert!(id.warnings.iter().any(|w| w.starts_with(&format!("{field}: observed"))), "{field} {l:?} {case}"),
            }
        }
    }
}

proptest! {
    #![proptest_config(fixed_sample(12, 33))]
    #[test]
    fn a_base_whose_limit_never_acted_is_fitted_as_before(
        base in random_base(),
        seed in 0_u64..1000,
        noisy in any::<bool>(),
    ) {
        // The same steps as above, on the base without its acceleration
        // limits: the lag alone, fitted as before (the lag-only fit, its
        // method `integrals`), and no acceleration limit claimed.
        let sigma = if noisy { scale(&base).map(|s| 0.005 * 3.5 * s) } else { [0.0; 2] };
        let free = echelon::base::VelocityBase::new(echelon::base::VelocityBaseSpec {
            a_max: f64::INFINITY,
            alpha_max: f64::INFINITY,
            ..base.spec()
        })
        .unwrap();
        let log = limited_base_log(free, Drive { cut: SOME_CUT, scale: scale(&base), sigma, late: 0 }, seed);
        let id = identify::identify(&log, Model::Velocity).unwrap();
        let case = format!("{base:?}, seed {seed}: {:?}", id.warnings);
        prop_assert!(id.axes.iter().all(|a| a.method == "integrals"), "{case}");
        prop_assert!(id.limits.iter().all(|l| l.estimate.is_none()), "{case}");
        for (field, want) in [("tau_v", base.tau_v()), ("tau_omega", base.tau_omega())] {
            let e = id.get(field);
            let tol = if noisy { 0.02 } else { 1e-6 };
            prop_assert!(e.is_some_and(|e| (e.value / want - 1.0).abs() < tol), "{field} {e:?} {case}");
        }
    }
}

#[test]
fn a_limited_base_that_acts_late_is_still_a_misfit() {
    // A 5 ms delay on top of the limit: the model (lag and clamp) does not
    // describe it; noise-free, the residuals show it and no lag is printed.
    let base = echelon::base::VelocityBase::new(echelon::base::VelocityBaseSpec {
        tau_v: 0.1,
        tau_omega: 0.08,
        a_max: 1.0,
        alpha_max: 4.0,
        ..echelon::base::VelocityBase::IDEAL.spec()
    })
    .unwrap();
    for late in [5, 20] {
        let drive = Drive {
            cut: SOME_CUT,
            scale: scale(&base),
            sigma: [0.0; 2],
            late,
        };
        let id = identify::identify(&limited_base_log(base, drive, 7), Model::Velocity).unwrap();
        for field in ["tau_v", "tau_omega"] {
            let p = id.params.iter().find(|p| p.field == field).unwrap();
            assert!(
                p.estimate.is_none()
                    && p.not_identifiable
                        .as_deref()
                        .is_some_and(|w| w.contains("misfits")),
                "late {late}: {p:?}"
            );
        }
        assert!(
            id.limits.iter().all(|l| l.estimate.is_none()),
            "{:?}",
            id.limits
        );
    }
}

#[test]
fn the_limited_builtins_give_their_lags_and_the_limits_that_bound() {
    // experiment-circle-velocity and turtlebot-circle: the acceleration
    // limits act while the robots catch up from rest. Noise-free: every lag
    // exact, and the limit that bound identified; with noise the lags
    // within 2 %.
    for name in ["experiment-circle-velocity", "turtlebot-circle"] {
        let (dir, specs) = builtin_run(name, false, 0.01, 20.0);
        for (i, spec) in specs.iter().enumerate() {
            let b = spec.velocity_robot().unwrap().base();
            let log = Log::read_run(dir.path(), i + 1).unwrap();
            let id = identify::identify(&log, Model::Velocity).unwrap();
            let case = format!("{name} agent {}: {:?}", i + 1, id.warnings);
            for (field, want) in [("tau_v", b.tau_v()), ("tau_omega", b.tau_omega())] {
                let e = id.get(field);
                assert!(
                    e.is_some_and(|e| (e.value / want - 1.0).abs() < 1e-6),
                    "{field} {e:?} {case}"
                );
            }
            let bound: Vec<_> = id.limits.iter().filter(|l| l.estimate.is_some()).collect();
            assert!(!bound.is_empty(), "{case}");
            for l in bound {
                let want = if l.field == "a_max" {
                    b.a_max()
                } else {
                    b.alpha_max()
                };
                assert!((l.observed / want - 1.0).abs() < 1e-6, "{l:?} {case}");
            }
            let mut noisy = log.clone();
            add_noise(&mut noisy, 3 + i as u64);
            let id = identify::identify(&noisy, Model::Velocity).unwrap();
            for (field, want) in [("tau_v", b.tau_v()), ("tau_omega", b.tau_omega())] {
                let p = id.params.iter().find(|p| p.field == field).unwrap();
                // Printed within 2 %, or withheld with the reason (the
                // circle hardly turns: σ_ω = 0.01 rad/s on ω ≈ 0.04 rad/s).
                match p.estimate {
                    Some(e) => assert!((e.value / want - 1.0).abs() < 0.02, "noisy {p:?} {case}"),
                    None => assert!(p.not_identifiable.is_some(), "noisy {p:?} {case}"),
                }
            }
        }
    }
}

#[test]
fn noisy_limited_bases_print_most_lags_and_limits_within_2_percent_and_covered() {
    // 40 random bases (fixed sample) with the noise above: pooled, most
    // lags and limits are printed (the rest withheld with a reason), every
    // one within 2 %, and their 95 % intervals cover the truth about as
    // often as they say.
    use proptest::strategy::ValueTree;
    let mut runner = proptest::test_runner::TestRunner::deterministic();
    let (mut printed, mut covered, mut total, mut worst) = (0, 0, 0, 0.0_f64);
    for seed in 0..40_u64 {
        let base = random_base().new_tree(&mut runner).unwrap().current();
        let sigma = scale(&base).map(|s| 0.005 * 3.5 * s);
        let drive = Drive {
            cut: SOME_CUT,
            scale: scale(&base),
            sigma,
            late: 0,
        };
        let id = identify::identify(&limited_base_log(base, drive, seed), Model::Velocity).unwrap();
        let estimates = [
            (id.get("tau_v"), base.tau_v()),
            (id.get("tau_omega"), base.tau_omega()),
            (limit_of(&id, "a_max").estimate, base.a_max()),
            (limit_of(&id, "alpha_max").estimate, base.alpha_max()),
        ];
        for (e, want) in estimates {
            total += 1;
            if let Some(e) = e {
                printed += 1;
                covered += usize::from(e.contains(want));
                worst = worst.max((e.value / want - 1.0).abs());
                assert!(
                    (e.value / want - 1.0).abs() < 0.02,
                    "{base:?} seed {seed}: {e:?} for {want}"
                );
            }
        }
    }
    eprintln!("printed {printed} of {total}, covered {covered}, worst {worst:.4}");
    assert!(printed * 4 >= total * 3, "printed {printed} of {total}");
    assert!(
        covered * 100 >= printed * 90,
        "covered {covered} of {printed}"
    );
}

/// A bag's command hold that cannot drive the fit is refused with what is
/// wrong with it, never indexed out of bounds nor fitted.
#[test]
fn a_bad_command_hold_is_refused_naming_the_hold() {
    let good = bag_log([0.1, 0.15], 50, 20, 7, 1, None, Quirks::NONE);
    let hold = good.hold.clone().unwrap();
    let cases: Vec<(identify::Hold, &str)> = vec![
        (identify::Hold::default(), "has no switch"),
        (
            identify::Hold {
                u: [hold.u[0][1..].to_vec(), hold.u[1].clone()],
                ..hold.clone()
            },
            "switch times but",
        ),
        (
            identify::Hold {
                t: hold.t.iter().map(|t| t + 0.5).collect(),
                ..hold.clone()
            },
            "after the first sample",
        ),
        (
            identify::Hold {
                t: hold.t.iter().rev().copied().collect(),
                ..hold.clone()
            },
            "do not increase",
        ),
    ];
    for (bad, want) in cases {
        let log = Log {
            hold: Some(bad),
            ..good.clone()
        };
        let e = identify::identify(&log, Model::Velocity)
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("in-memory bag: the command hold (Log::hold) ") && e.contains(want),
            "{want}: {e}"
        );
    }
    assert!(identify::identify(&good, Model::Velocity).is_ok());
}
