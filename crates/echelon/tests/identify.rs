//! Identification (issue 14): Table I robots recovered from noisy logs with
//! honest intervals, velocity-base lags, unexcited axes refused, the
//! identified robot reproducing a scenario, and bad logs refused.
//!
//! Measurement noise: zero-mean Gaussian, white, added to the logged
//! velocities: σ_v = 0.005 m/s, σ_ω = 0.01 rad/s (ChaCha8 seeded per case).
#![allow(clippy::unwrap_used)] // tests fail loudly by design

use echelon::RobotParams;
use echelon::follow::{LeaderView, follow};
use echelon::identify::{self, IdentifyError, Log, Model};
use echelon::model::{Input, State};
use echelon::output;
use echelon::reference::{Order, Trajectory};
use echelon::scenario::{Overrides, Scenario};
use echelon::sim::{AgentSpec, Frame, ObserverError, Simulation};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

const SIGMA_V: f64 = 0.005;
const SIGMA_OMEGA: f64 = 0.01;
const LOG_DT: f64 = 0.01;

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
        .map(|&t| robot.linear_friction * shape(t, 0.7, 2.3, 7.1))
        .collect();
    let u2 = t
        .iter()
        .map(|&t| 2.0 * robot.angular_friction * shape(t, 0.5, 1.7, 5.3))
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
            ("mass", robot.mass),
            ("linear_friction", robot.linear_friction),
            ("inertia", robot.inertia),
            ("angular_friction", robot.angular_friction),
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
            // Residuals are the measurement noise.
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
        (e.first_guess - robot.inertia).abs() / robot.inertia < 0.2,
        "{e:?}"
    );
    assert!((e.value - robot.inertia).abs() <= (e.first_guess - robot.inertia).abs());
}

#[test]
fn a_log_without_rotation_says_j_and_psi_are_not_identifiable_and_gives_no_number() {
    let robot = RobotParams::AGENT2;
    let id = identify::identify(&torque_log(&robot, 3, false), Model::Torque).unwrap();
    assert!(id.get("mass").is_some() && id.get("linear_friction").is_some());
    assert!(id.get("inertia").is_none() && id.get("angular_friction").is_none());
    assert!(
        id.warnings
            .iter()
            .any(|w| w.contains("J, ψ not identifiable") && w.contains("no rotation")),
        "{:?}",
        id.warnings
    );
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
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let (nv, nw) = (
        Normal::new(0.0, SIGMA_V).unwrap(),
        Normal::new(0.0, SIGMA_OMEGA).unwrap(),
    );
    let v: Vec<f64> = identify::simulate_axis(&t, &cv, tau_v, 1.0, 0.0)
        .into_iter()
        .map(|x| x + nv.sample(&mut rng))
        .collect();
    let omega: Vec<f64> = identify::simulate_axis(&t, &cw, tau_w, 1.0, 0.0)
        .into_iter()
        .map(|x| x + nw.sample(&mut rng))
        .collect();
    let log = Log {
        source: "synthetic base".into(),
        agent: 1,
        t,
        v,
        omega,
        cmd: Some([cv.clone(), cw.clone()]),
        applied: Some([cv, cw]),
        ..Log::default()
    };
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
    assert!(block.contains("# v_max: observed"), "{block}");
}

/// Runs `identify-excitation` (or a shorter part) into `dir`.
fn run_excitation(dir: &std::path::Path, duration: Option<f64>) {
    let mut run = Scenario::builtin("identify-excitation")
        .unwrap()
        .build(&Overrides {
            duration,
            ..Overrides::default()
        })
        .unwrap();
    let mut none = |_: &Frame<'_>| -> Result<(), ObserverError> { Ok(()) };
    output::run_to_dir(&mut run, dir, &mut none).unwrap();
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
            ("mass", truth.mass),
            ("linear_friction", truth.linear_friction),
            ("inertia", truth.inertia),
            ("angular_friction", truth.angular_friction),
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
        assert!((l - truth.half_wheelbase).abs() < 1e-9 && (r - truth.wheel_radius).abs() < 1e-9);

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
        let spec = &identified.simulation.agents()[agent - 1];
        assert_ne!(spec.torque_robot(), Some(&truth), "the block is in use");
        let with_identified = closed_loop_error(&identified.simulation, spec, &truth, 3.0);
        let reference = circle.build(&Overrides::default()).unwrap();
        let with_truth = closed_loop_error(
            &reference.simulation,
            &reference.simulation.agents()[agent - 1],
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
            1.15 * truth.mass,
            1.15 * truth.linear_friction,
            1.15 * truth.inertia,
            1.15 * truth.angular_friction,
            truth.half_wheelbase,
            truth.wheel_radius
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
            &wrong.simulation,
            &wrong.simulation.agents()[agent - 1],
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
    let mut s = spec.start;
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
    let mut run = Scenario::parse(&src, "lab.toml", None)
        .unwrap()
        .build(&Overrides::default())
        .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let mut none = |_: &Frame<'_>| -> Result<(), ObserverError> { Ok(()) };
    output::run_to_dir(&mut run, dir.path(), &mut none).unwrap();
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
    assert!(block.contains("# omega_max: observed"), "{block}");
    // The block is a valid velocity robot.
    let reuse = src.replace("[robots.lab]", "[robots.old]") + &block;
    Scenario::parse(&reuse, "reuse.toml", None)
        .unwrap()
        .build(&Overrides::default())
        .unwrap();
}

#[test]
fn an_acceleration_limit_that_acted_is_found_and_said_to_bias_the_lag() {
    let (_, dir) = velocity_run("tau_v = 0.1\ntau_omega = 0.1\nalpha_max = 4.0\n");
    let id = identify::identify(&Log::read_run(dir.path(), 1).unwrap(), Model::Velocity).unwrap();
    let alpha = id.limits.iter().find(|l| l.field == "alpha_max").unwrap();
    assert!(
        alpha.reached && (alpha.observed - 4.0).abs() < 1e-6,
        "{alpha:?}"
    );
    assert!(
        id.warnings
            .iter()
            .any(|w| w.contains("alpha_max = 4.0000 acted") && w.contains("tau_omega is biased")),
        "{:?}",
        id.warnings
    );
    assert!(
        !id.limits
            .iter()
            .find(|l| l.field == "a_max")
            .unwrap()
            .reached
    );
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
    assert!(
        id.warnings
            .iter()
            .any(|w| w.contains("noise-free log on the linear axis")),
        "{:?}",
        id.warnings
    );
    let block = id.robot_toml("x");
    assert_eq!(
        block.matches("interval not meaningful").count(),
        4,
        "{block}"
    );
    assert!(!block.contains("95 % interval"), "{block}");
    // Exact to rounding.
    let m = id.get("mass").unwrap().value;
    assert!((m / robot.mass - 1.0).abs() < 1e-9, "{m}");

    let noisy = identify::identify(&torque_log(&robot, 1, true), Model::Torque).unwrap();
    assert!(noisy.axes.iter().all(|a| !a.noise_free));
    assert_eq!(noisy.robot_toml("x").matches("95 % interval").count(), 4);
}
