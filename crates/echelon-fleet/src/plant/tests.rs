use super::*;
use echelon::base::{VelocityBase, VelocityBaseSpec, VelocityRobot};
use echelon::control::Variant;
use echelon::model::{Input, RobotParams};
use echelon::scenario::{Overrides, Scenario};
use proptest::prelude::*;

/// A velocity base on Table I's wheels.
fn on_wheels(base: VelocityBase) -> Drive {
    Drive::Velocity(VelocityRobot::new(base, 0.15, 0.05).expect("Table I's wheels"))
}

#[test]
fn advancing_in_pieces_equals_advancing_at_once() {
    let drive = Drive::Torque {
        robot: RobotParams::AGENT2,
        variant: Variant::Paper,
    };
    let mut a = SimulatedDrive::new(drive, State::at_rest(0.0, 0.0, 0.5), 0.0, 1e-3);
    let mut b = a.clone();
    let u = Command::Torque(Input { u1: 30.0, u2: 1.0 });
    a.command(u);
    b.command(u);
    a.advance(0.1);
    for k in 1..=10 {
        b.advance(0.01 * k as f64);
    }
    let (sa, sb) = (a.true_state(), b.true_state());
    assert!((sa.x - sb.x).abs() < 1e-12 && (sa.theta - sb.theta).abs() < 1e-12);
    assert!(sa.v > 0.0 && sa.omega > 0.0);
    // Going back in time does nothing.
    a.advance(0.05);
    assert_eq!(a.true_state(), sa);
}

/// The fleet's base is the simulator's: an ideal base turns exactly on
/// the commanded circle; a lagged one approaches the command as
/// `1 − e^{−t/τ}` (its closed form) while staying within its limits.
#[test]
fn a_velocity_base_follows_its_command_as_the_model_says() {
    let ideal = on_wheels(VelocityBase::IDEAL);
    let mut b = SimulatedDrive::new(ideal, State::at_rest(0.0, 0.0, 0.0), 0.0, 1e-3);
    let c = VelocityCommand { v: 0.4, omega: 0.5 };
    let act = b.command(Command::Velocity(c));
    assert_eq!(act.velocity, Some((c, false)));
    b.advance(1.0);
    let s = b.true_state();
    let r = 0.4 / 0.5;
    assert!((s.x - r * 0.5f64.sin()).abs() < 1e-9, "{s:?}");
    assert!((s.y - r * (1.0 - 0.5f64.cos())).abs() < 1e-9, "{s:?}");
    assert_eq!((s.v, s.omega), (0.4, 0.5));

    let lagged = VelocityBase::new(VelocityBaseSpec {
        tau_v: 0.2,
        tau_omega: 0.1,
        ..VelocityBase::IDEAL.spec()
    })
    .expect("a lagged base");
    let mut b = SimulatedDrive::new(on_wheels(lagged), State::at_rest(0.0, 0.0, 0.0), 0.0, 1e-3);
    b.command(Command::Velocity(c));
    b.advance(0.3);
    let s = b.true_state();
    assert!(
        (s.v - 0.4 * (1.0 - (-0.3f64 / 0.2).exp())).abs() < 1e-9,
        "{s:?}"
    );
    assert!(
        (s.omega - 0.5 * (1.0 - (-0.3f64 / 0.1).exp())).abs() < 1e-9,
        "{s:?}"
    );
    // Beyond the limits: scaled together (curvature kept), and held.
    let limited = VelocityBase::new(VelocityBaseSpec {
        tau_v: 0.2,
        tau_omega: 0.1,
        v_max: 0.2,
        omega_max: 1.0,
        ..VelocityBase::IDEAL.spec()
    })
    .expect("a lagged base with speed limits");
    let mut b = SimulatedDrive::new(on_wheels(limited), State::at_rest(0.0, 0.0, 0.0), 0.0, 1e-3);
    let (applied, saturated) = b.follow(c);
    assert!(saturated);
    assert_eq!(applied.v, 0.2);
    assert!((applied.omega / applied.v - c.omega / c.v).abs() < 1e-12);
    b.advance(5.0);
    assert!(b.true_state().v <= 0.2);
    b.stop();
    assert_eq!(
        b.applied().velocity,
        Some((VelocityCommand::default(), false))
    );
}

/// The simulator's step, `1/128` s: a power of two, so the fleet's
/// sub-step `(t_{k+1} − t_k)/1` is the simulator's `dt` exactly.
const DT: f64 = 1.0 / 128.0;

/// A `[robots.r]` table: a torque-driven robot (eq. 3) with random mass,
/// friction, inertia, wheels and torque limit, or a velocity base with
/// random lags (some zero), speed and acceleration limits (some absent).
fn robot_table() -> impl Strategy<Value = String> {
    let opt = |lo: f64, hi: f64| prop::option::of(lo..hi);
    let torque = (
        (0.5..30.0f64, 0.05..5.0f64, 0.005..2.0f64, 0.001..1.0f64),
        (0.05..0.4f64, 0.02..0.2f64, opt(0.05, 3.0)),
    )
        .prop_map(|((m, eta, j, psi), (l, r, limit))| {
            let limit = limit.map_or(String::new(), |t| format!("torque_limit = {t:?}\n"));
            format!(
                "mass = {m:?}\nlinear_friction = {eta:?}\ninertia = {j:?}\n\
                 angular_friction = {psi:?}\nhalf_wheelbase = {l:?}\nwheel_radius = {r:?}\n{limit}"
            )
        });
    // A lag of 0 (ideal axis) or one of at least two steps.
    let lag = prop_oneof![Just(0.0), 2.0 * DT..0.5];
    let velocity = (
        (lag.clone(), lag, opt(0.1, 2.0), opt(0.3, 6.0)),
        (opt(0.2, 5.0), opt(0.5, 20.0), any::<bool>()),
    )
        .prop_map(|((tv, tw, v_max, w_max), (a_max, alpha_max, per_axis))| {
            let mut t = format!("drive = \"velocity\"\ntau_v = {tv:?}\ntau_omega = {tw:?}\n");
            let mut put = |key: &str, value: Option<f64>| {
                if let Some(x) = value {
                    t.push_str(&format!("{key} = {x:?}\n"));
                }
            };
            put("v_max", v_max);
            put("omega_max", w_max);
            // An acceleration limit needs the lag.
            put("a_max", a_max.filter(|_| tv > 0.0));
            put("alpha_max", alpha_max.filter(|_| tw > 0.0));
            if per_axis {
                t.push_str("accel = \"per-axis\"\n");
            }
            t.push_str("half_wheelbase = 0.15\nwheel_radius = 0.05\n");
            t
        });
    prop_oneof![torque, velocity]
}

/// The bits of every component of `s`.
fn bits(s: &State) -> [u64; 5] {
    [s.x, s.y, s.theta, s.v, s.omega].map(f64::to_bits)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(96))]

    /// The fleet's simulated robot and the simulator's single agent are one
    /// robot: under the same random commands (held one step each, torques
    /// or velocity commands well beyond the limits), from the same random
    /// start, a [`SimulatedDrive`] stepping in the fleet's sub-steps and
    /// [`echelon::sim::Simulation::step_with`] reach bit-identical states,
    /// step after step, and apply the same commands.
    #[test]
    fn a_simulated_drive_moves_as_the_simulators_agent(
        table in robot_table(),
        (x, y, theta) in (-50.0..50.0f64, -50.0..50.0f64, -7.0..7.0f64),
        (fv, fw) in (-1.0..1.0f64, -1.0..1.0f64),
        commands in prop::collection::vec((-8.0..8.0f64, -8.0..8.0f64), 1..96),
    ) {
        // Start speeds within any base's limits (the smallest drawn).
        let (v0, w0) = (0.1 * fv, 0.3 * fw);
        let src = format!(
            "[sim]\nduration = 1.0\ndt = {DT:?}\n[log]\ndt = 0\n\
             [robots.r]\n{table}\n\
             [reference.line]\nspeed = 0.1\nstart = {{ x = 0.0, y = 0.0, theta = 0.0 }}\n\
             [[agents]]\nrobot = \"r\"\nleader = \"reference\"\nmode = \"tracking\"\n\
             start = {{ x = {x:?}, y = {y:?}, theta = {theta:?}, v = {v0:?}, omega = {w0:?} }}\n"
        );
        let run = Scenario::parse(&src, "plant-prop", None)
            .and_then(|s| s.build(&Overrides::default()))
            .unwrap_or_else(|e| panic!("{e}\n{src}"));
        let spec = &run.plan.agents()[0];
        let mut sim = run.simulation();
        let mut plant = SimulatedDrive::of(spec, 0.0, DT);
        prop_assert_eq!(bits(&plant.true_state()), bits(&sim.states()[0]));
        for (k, &(a, b)) in commands.iter().enumerate() {
            let cmd = match spec.drive() {
                Drive::Torque { .. } => Command::Torque(Input { u1: a, u2: 0.25 * b }),
                Drive::Velocity(_) => Command::Velocity(VelocityCommand { v: a, omega: b }),
            };
            let t = k as f64 * DT;
            // The simulator's act step, as the fleet robot's.
            let held = spec.act(t, &plant.true_state(), cmd, None).command;
            plant.command(held);
            plant.advance(t + DT);
            sim.step_with(&[cmd], false).unwrap_or_else(|e| panic!("{e}\n{src}"));
            prop_assert_eq!(
                bits(&plant.true_state()),
                bits(&sim.states()[0]),
                "step {}: {:?} vs {:?}\n{}",
                k,
                plant.true_state(),
                sim.states()[0],
                src
            );
            let out = sim.frame().outputs[0];
            let applied = plant.applied();
            prop_assert_eq!((applied.u, applied.tau), (out.u, out.tau));
            prop_assert_eq!(applied.velocity, out.velocity.map(|v| (v.applied, v.saturated)));
        }
    }
}
