use super::*;

#[test]
fn presets_are_valid_and_named() {
    for (name, robot) in VelocityRobot::PRESETS {
        let base = robot.base;
        assert_eq!(VelocityBase::new(base.spec()), Ok(base), "{name}");
        let rebuilt = VelocityRobot::new(base, robot.half_wheelbase, robot.wheel_radius)
            .and_then(|r| r.with_reverse_limit(robot.reverse_limit));
        assert_eq!(rebuilt, Ok(robot), "{name}");
        assert_eq!(VelocityRobot::preset(name), Some(robot));
    }
    assert!(VelocityBase::IDEAL.is_ideal());
    assert!(!VelocityBase::TURTLEBOT3_BURGER.is_ideal());
    assert_eq!(VelocityRobot::preset("husky"), None);
    // The Create 3's own facts (iRobot's Create 3 documentation): its
    // safe-mode top speed, its wheels' acceleration (and so the turn's,
    // on its 235 mm track), its backup limit.
    let c3 = VelocityRobot::TURTLEBOT4;
    let spec = c3.base().spec();
    assert_eq!((spec.v_max, spec.a_max), (0.306, 0.9));
    assert!((spec.alpha_max - 0.9 / c3.half_wheelbase()).abs() < 1e-12);
    assert_eq!(c3.reverse_limit(), CREATE3_BACKUP_LIMIT);
    for r in [
        VelocityRobot::IDEAL,
        VelocityRobot::TURTLEBOT3_BURGER,
        VelocityRobot::JACKAL,
    ] {
        assert!(r.reverse_limit().is_infinite());
    }
    assert!(c3.with_reverse_limit(0.0).is_err() && c3.with_reverse_limit(f64::NAN).is_err());
}

#[test]
fn invalid_parameters_are_refused_by_name() {
    let tb3 = VelocityBase::TURTLEBOT3_BURGER;
    // TurtleBot 3's values with one replaced.
    let field = |change: fn(&mut VelocityBaseSpec)| {
        let mut spec = tb3.spec();
        change(&mut spec);
        VelocityBase::new(spec).unwrap_err().field
    };
    assert_eq!(field(|b| b.tau_v = -0.1), "tau_v");
    assert_eq!(field(|b| b.tau_omega = f64::NAN), "tau_omega");
    assert_eq!(field(|b| b.v_max = 0.0), "v_max");
    assert_eq!(field(|b| b.omega_max = -1.0), "omega_max");
    assert_eq!(field(|b| b.a_max = f64::NAN), "a_max");
    assert_eq!(field(|b| b.alpha_max = 0.0), "alpha_max");
    // An acceleration limit without a lag is refused on its own axis.
    assert_eq!(field(|b| b.tau_v = 0.0), "a_max");
    assert_eq!(field(|b| b.tau_omega = 0.0), "alpha_max");
    assert!(
        VelocityBase::new(VelocityBaseSpec {
            v_max: 0.22,
            omega_max: 2.84,
            ..VelocityBase::IDEAL.spec()
        })
        .is_ok()
    );
    assert_eq!(field(|b| b.tau_v = -1.0), "tau_v");
    assert_eq!(
        VelocityRobot::new(tb3, 0.0, 0.033).unwrap_err().field,
        "half_wheelbase"
    );
    assert_eq!(
        VelocityRobot::new(tb3, 0.08, f64::NAN).unwrap_err().field,
        "wheel_radius"
    );
    // Steps longer than a lag are refused; ideal axes take any step.
    assert_eq!(tb3.check_step(0.2).unwrap_err().field, "tau_v");
    assert!(tb3.check_step(0.01).is_ok());
    assert!(VelocityBase::IDEAL.check_step(10.0).is_ok());
}

#[test]
fn limit_scales_both_axes_by_the_binding_one() {
    let tb3 = VelocityBase::TURTLEBOT3_BURGER;
    // v binds: 0.44 → 0.22 halves ω too.
    let (c, sat) = tb3.limit(VelocityCommand {
        v: 0.44,
        omega: 1.0,
    });
    assert!(sat);
    assert_eq!(c.v, 0.22);
    assert!((c.omega - 0.5).abs() < 1e-15);
    // ω binds.
    let (c, sat) = tb3.limit(VelocityCommand {
        v: -0.1,
        omega: -5.68,
    });
    assert!(sat);
    assert_eq!(c.omega, -2.84);
    assert!((c.v + 0.05).abs() < 1e-15);
    // Within limits: untouched.
    let cmd = VelocityCommand {
        v: 0.2,
        omega: -2.0,
    };
    assert_eq!(tb3.limit(cmd), (cmd, false));
}

#[test]
fn ideal_base_moves_at_the_command() {
    let b = VelocityBase::IDEAL;
    let cmd = VelocityCommand {
        v: 0.5,
        omega: 0.25,
    };
    let mut s = State::at_rest(0.0, 0.0, 0.0);
    let dt = 0.01;
    for _ in 0..400 {
        s = b.rk4_step(&s, cmd, dt);
    }
    // An arc of radius 2 for 4 s: θ = 1, p = 2 (sin 1, 1 − cos 1).
    assert_eq!((s.v, s.omega), (0.5, 0.25));
    assert!((s.theta - 1.0).abs() < 1e-12);
    assert!((s.x - 2.0 * 1f64.sin()).abs() < 1e-10);
    assert!((s.y - 2.0 * (1.0 - 1f64.cos())).abs() < 1e-10);
}

#[test]
fn lagged_base_matches_the_closed_form_below_the_acceleration_limit() {
    // v(t) = v_c (1 − e^{−t/τ}) while |v̇| = (v_c − v)/τ stays ≤ a_max.
    let b = VelocityBase::new(VelocityBaseSpec {
        tau_v: 0.2,
        tau_omega: 0.1,
        v_max: 1.0,
        omega_max: 2.0,
        a_max: 5.0,
        alpha_max: 10.0,
        accel: AccelLimit::Joint,
    })
    .unwrap();
    let cmd = VelocityCommand {
        v: 0.5,
        omega: -0.8,
    };
    let mut s = State::default();
    let dt = 0.001;
    for _ in 0..1000 {
        s = b.rk4_step(&s, cmd, dt);
    }
    assert!((s.v - 0.5 * (1.0 - (-1.0f64 / 0.2).exp())).abs() < 1e-12);
    assert!((s.omega + 0.8 * (1.0 - (-1.0f64 / 0.1).exp())).abs() < 1e-12);
}

#[test]
fn acceleration_limit_gives_a_ramp_and_joint_keeps_the_direction() {
    // From rest to a command far beyond what a_max allows in the lag: the
    // lag asks for (v_c/τ, ω_c/τ) = (5, 10); joint limits scale both by
    // min(1/5, 4/10) = 0.2, so the base ramps at (1, 2) and ω/v = 2 = ω_c/v_c.
    let b = VelocityBase::new(VelocityBaseSpec {
        tau_v: 0.1,
        tau_omega: 0.1,
        v_max: 1.0,
        omega_max: 2.0,
        a_max: 1.0,
        alpha_max: 4.0,
        accel: AccelLimit::Joint,
    })
    .unwrap();
    let cmd = VelocityCommand { v: 0.5, omega: 1.0 };
    let s = b.rk4_step(&State::default(), cmd, 0.01);
    assert!((s.v - 0.01).abs() < 1e-15 && (s.omega - 0.02).abs() < 1e-15);
    assert!(b.accel_limited(&State::default(), cmd));
    // Per-axis: ω ramps at 4 rad/s² (its own limit), v at 1: the path bends.
    let p = b.with_accel(AccelLimit::PerAxis);
    let s = p.rk4_step(&State::default(), cmd, 0.01);
    assert!((s.v - 0.01).abs() < 1e-15 && (s.omega - 0.04).abs() < 1e-15);
}
