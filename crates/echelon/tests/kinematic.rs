//! The kinematic law on velocity-controlled bases (control-law.md, "Kinematic
//! law"): with an ideal base `V̇₁ = −K_e‖e‖²` and `‖e(t)‖ = ‖e(0)‖ e^{−K_e t}`
//! along RK4 runs (circle, lemniscate with exact `L̇_Y`, a chained follower);
//! `V̇₁ = −K_e‖e‖² + eᵀz` for any base; the limiter keeps the curvature and the
//! limits; Theorem 2 for the kinematic law against a worst-case odometry run.
//!
//! The runs use a small standalone RK4 loop with the law evaluated in every
//! stage (a continuous-time controller, as the simulator does).
#![allow(clippy::unwrap_used)] // tests fail loudly by design

mod common;
use common::placement;

use echelon::base::{AccelLimit, VelocityBase, VelocityBaseSpec, VelocityCommand};
use echelon::control::{LeaderMotion, errors};
use echelon::follow::LeaderView;
use echelon::kinematic::{KinematicOutput, kinematic_law, lyapunov, lyapunov_rate};
use echelon::lycomp::{LyComp, LyDerivatives, Placement};
use echelon::odometry::bound::KinematicTheorem2;
use echelon::reference::{Circle, Lemniscate, Order, Reference, Trajectory};
use echelon::{State, control::Offset};
use num_dual::{Dual64, DualNum};
use proptest::prelude::*;

/// One follower: whom it follows (`None`: the reference; leaders come first),
/// where, and its gain.
struct Follower {
    leader: Option<usize>,
    placement: Placement,
    ke: f64,
}

/// The law's outputs and the applied commands for every agent at `(t, xs)`.
/// `fake` shifts the pose each controller sees (odometry error, world frame).
fn evaluate(
    base: &VelocityBase,
    reference: &Reference,
    agents: &[Follower],
    t: f64,
    xs: &[State],
    fake: [f64; 2],
) -> (Vec<KinematicOutput>, Vec<VelocityCommand>) {
    let mut outs = Vec::with_capacity(agents.len());
    let mut cmds: Vec<VelocityCommand> = Vec::with_capacity(agents.len());
    for (i, a) in agents.iter().enumerate() {
        let (leader, off) = match a.leader {
            None => LeaderView::Reference(&reference.eval(t, Order::Four)).resolve(&a.placement),
            Some(j) => {
                // The leader's base moves at the speeds it is commanded.
                let (v, omega) = base.speeds(&xs[j], cmds[j]);
                let moving = State { v, omega, ..xs[j] };
                LeaderView::Robot {
                    state: moving,
                    dv: 0.0,
                }
                .resolve(&a.placement)
            }
        };
        let seen = State {
            x: xs[i].x - fake[0],
            y: xs[i].y - fake[1],
            ..xs[i]
        };
        let out = kinematic_law(&seen, &leader, &off, a.ke);
        cmds.push(base.limit(out.cmd).0);
        // e and z of the true pose, at the velocities the base moves at.
        let (v, omega) = base.speeds(&xs[i], cmds[i]);
        let truth = kinematic_law(&State { v, omega, ..xs[i] }, &leader, &off, a.ke);
        outs.push(KinematicOutput {
            cmd: out.cmd,
            ..truth
        });
    }
    (outs, cmds)
}

/// One sample of a run: time and each agent's output at the step's start.
struct Sample {
    t: f64,
    outs: Vec<KinematicOutput>,
}

/// Classical RK4 of the closed loop, the law evaluated in every stage.
fn run(
    base: &VelocityBase,
    reference: &Reference,
    agents: &[Follower],
    start: &[State],
    dt: f64,
    duration: f64,
    fake: impl Fn(u64) -> [f64; 2],
) -> Vec<Sample> {
    let steps = (duration / dt).round() as u64;
    let mut xs = start.to_vec();
    let mut samples = Vec::with_capacity(steps as usize);
    let add = |xs: &[State], ks: &[State], h: f64| -> Vec<State> {
        xs.iter().zip(ks).map(|(x, k)| x.add_scaled(k, h)).collect()
    };
    for n in 0..steps {
        let t = n as f64 * dt;
        let f = fake(n);
        let deriv = |t: f64, xs: &[State]| -> (Vec<State>, Vec<KinematicOutput>) {
            let (outs, cmds) = evaluate(base, reference, agents, t, xs, f);
            let d = xs
                .iter()
                .zip(&cmds)
                .map(|(x, c)| base.derivative(x, *c))
                .collect();
            (d, outs)
        };
        let (k1, outs) = deriv(t, &xs);
        samples.push(Sample { t, outs });
        let (k2, _) = deriv(t + 0.5 * dt, &add(&xs, &k1, 0.5 * dt));
        let (k3, _) = deriv(t + 0.5 * dt, &add(&xs, &k2, 0.5 * dt));
        let (k4, _) = deriv(t + dt, &add(&xs, &k3, dt));
        let next: Vec<State> = (0..xs.len())
            .map(|i| xs[i].rk4_combine([&k1[i], &k2[i], &k3[i], &k4[i]], dt / 6.0))
            .collect();
        let (_, cmds) = evaluate(base, reference, agents, t + dt, &next, fake(n + 1));
        xs = next
            .iter()
            .zip(&cmds)
            .map(|(x, c)| base.settle(x, *c))
            .collect();
    }
    samples
}

fn norm(a: [f64; 2]) -> f64 {
    a[0].hypot(a[1])
}

/// Largest relative gaps of agent `a`'s run to the closed form
/// `‖e(t)‖ = ‖e(0)‖ e^{−K_e t}` and of the central difference of `V₁` to
/// `−K_e‖e‖²`.
fn gaps(samples: &[Sample], a: usize, ke: f64) -> (f64, f64) {
    let e0 = norm(samples[0].outs[a].e);
    let dt = samples[1].t - samples[0].t;
    let mut closed: f64 = 0.0;
    let mut rate: f64 = 0.0;
    for k in 0..samples.len() {
        let e = samples[k].outs[a].e;
        let want = e0 * (-ke * samples[k].t).exp();
        closed = closed.max((norm(e) - want).abs() / want);
        if k > 0 && k + 1 < samples.len() {
            let fd = (lyapunov(samples[k + 1].outs[a].e) - lyapunov(samples[k - 1].outs[a].e))
                / (2.0 * dt);
            let identity = lyapunov_rate(e, samples[k].outs[a].z, ke);
            rate = rate.max((fd - identity).abs() / identity.abs());
        }
    }
    (closed, rate)
}

#[test]
fn ideal_base_closed_form_along_a_circle_with_a_chained_follower() {
    let reference = Reference::Circle(Circle::new([0.0, 0.0], 0.0, 0.5, 0.1).unwrap());
    let agents = [
        Follower {
            leader: None,
            placement: placement(0.5, 0.8, LyComp::Exact, LyDerivatives::Neglect),
            ke: 1.5,
        },
        Follower {
            leader: None,
            placement: placement(0.5, -0.8, LyComp::Fit, LyDerivatives::Neglect),
            ke: 0.8,
        },
        // Follows robot 1 with constant L_Y: ṗ_d from robot 1's commanded speeds.
        Follower {
            leader: Some(0),
            placement: placement(0.5, -0.4, LyComp::None, LyDerivatives::Neglect),
            ke: 1.5,
        },
    ];
    let start = [
        State::at_rest(-0.3, -1.5, 0.0),
        State::at_rest(-0.2, 1.6, 0.3),
        State::at_rest(-0.8, -0.2, 0.0),
    ];
    let samples = run(
        &VelocityBase::IDEAL,
        &reference,
        &agents,
        &start,
        5e-4,
        6.0,
        |_| [0.0, 0.0],
    );
    closed_form_holds(&samples, &agents, "circle");
}

/// Every agent of an ideal-base run on its closed form and `V̇₁` identity
/// to 1e-6, with `z = 0` (the ideal base moves at the command).
fn closed_form_holds(samples: &[Sample], agents: &[Follower], what: &str) {
    for (a, f) in agents.iter().enumerate() {
        let (closed, rate) = gaps(samples, a, f.ke);
        eprintln!(
            "{what} agent {}: closed form {closed:e}, V̇₁ {rate:e}",
            a + 1
        );
        assert!(
            closed < 1e-6,
            "{what} agent {}: ‖e‖ off its closed form by {closed:e}",
            a + 1
        );
        assert!(
            rate < 1e-6,
            "{what} agent {}: V̇₁ off −K_e‖e‖² by {rate:e}",
            a + 1
        );
        assert!(samples.iter().all(|s| norm(s.outs[a].z) < 1e-12));
    }
}

/// Slots in the leader's frame (docs/control-law.md, "Offsets in the
/// leader's frame"): the slot's `q̇` is exact, so on an ideal base
/// `‖e(t)‖ = ‖e(0)‖ e^{−K_e t}` holds as for the paper's frame — along a
/// lemniscate (the leader's heading, turn rate and angular acceleration all
/// varying) and a circle, slots behind, beside and ahead of the leader,
/// robots starting turned away from their slots.
#[test]
fn ideal_base_closed_form_with_slots_in_the_leaders_frame() {
    let references = [
        Reference::Lemniscate(Lemniscate::new(2.4, 0.1, [0.0, 0.0]).unwrap()),
        Reference::Circle(Circle::new([0.0, 0.0], 0.3, 0.5, -0.2).unwrap()),
    ];
    for reference in &references {
        let agents =
            [(1.0, 0.5, 1.5), (-0.8, -0.6, 0.8), (0.0, 2.0, 1.2)].map(|(x, y, ke)| Follower {
                leader: None,
                placement: Placement::leader_frame(x, y, 0.05).unwrap(),
                ke,
            });
        let start = [
            State::at_rest(1.0, -1.5, 2.0),
            State::at_rest(3.2, 1.6, -2.5),
            State::at_rest(2.0, 0.5, 3.0),
        ];
        let samples = run(
            &VelocityBase::IDEAL,
            reference,
            &agents,
            &start,
            5e-4,
            6.0,
            |_| [0.0, 0.0],
        );
        closed_form_holds(&samples, &agents, &format!("{reference:?}"));
    }
}

#[test]
fn ideal_base_closed_form_with_time_varying_l_y_needs_exact_derivatives() {
    // On a lemniscate L_Ycomp follows the curvature, so L_Y varies: the
    // identity is exact only with the true L̇_Y.
    let reference = Reference::Lemniscate(Lemniscate::new(3.0, 0.3, [0.0, 0.0]).unwrap());
    let go = |derivatives| {
        let agents = [Follower {
            leader: None,
            placement: placement(0.5, 0.5, LyComp::Exact, derivatives),
            ke: 1.5,
        }];
        let samples = run(
            &VelocityBase::IDEAL,
            &reference,
            &agents,
            &[State::at_rest(3.5, -0.6, 1.4)],
            5e-4,
            6.0,
            |_| [0.0, 0.0],
        );
        gaps(&samples, 0, 1.5)
    };
    let (closed, rate) = go(LyDerivatives::Exact);
    eprintln!("exact L̇_Y: closed form {closed:e}, V̇₁ {rate:e}");
    assert!(closed < 1e-6 && rate < 1e-6, "{closed:e}, {rate:e}");
    // The test has teeth: neglecting L̇_Y breaks both.
    let (closed, rate) = go(LyDerivatives::Neglect);
    assert!(closed > 1e-3 && rate > 1e-3, "{closed:e}, {rate:e}");
}

#[test]
fn lagged_and_limited_base_keeps_its_limits_and_converges() {
    // A TurtleBot 3 following a gentle circle it can keep up with, starting
    // off its place far enough that the command saturates.
    let reference = Reference::Circle(Circle::new([0.0, 0.0], 0.0, 0.15, 0.05).unwrap());
    let agents = [Follower {
        leader: None,
        placement: placement(0.3, 0.2, LyComp::Exact, LyDerivatives::Neglect),
        ke: 1.0,
    }];
    let base = VelocityBase::TURTLEBOT3_BURGER;
    let samples = run(
        &base,
        &reference,
        &agents,
        &[State::at_rest(-1.0, 0.6, 0.5)],
        1e-3,
        60.0,
        |_| [0.0, 0.0],
    );
    let saturated = samples
        .iter()
        .filter(|s| base.limit(s.outs[0].cmd).1)
        .count();
    assert!(saturated > 100, "the command never saturated: {saturated}");
    let last = norm(samples.last().unwrap().outs[0].e);
    eprintln!("saturated ticks {saturated}, final ‖e‖ {last:e}");
    assert!(last < 1e-3, "final ‖e‖ = {last}");
}

#[test]
fn kinematic_theorem_2_holds_and_is_tight_under_the_worst_case() {
    // The controller's pose runs behind the truth by n ζ on both world axes,
    // n samples since the last fix (eq. 31), fixes every N samples.
    let (zeta, ts, fix_every, ke, gamma): (f64, f64, u64, f64, f64) = (1e-4, 0.01, 50, 1.5, 0.9);
    let dt: f64 = 1e-3;
    let per_sample = (ts / dt).round() as u64;
    let reference = Reference::Circle(Circle::new([0.0, 0.0], 0.0, 0.5, 0.1).unwrap());
    let agents = [Follower {
        leader: None,
        placement: placement(0.5, 0.3, LyComp::Exact, LyDerivatives::Neglect),
        ke,
    }];
    // Start at the formation place: e(0) = 0.
    let off = agents[0]
        .placement
        .offset_for_reference(&reference.eval(0.0, Order::Four));
    let start = State::at_rest(-off.lx, -off.ly, 0.0);
    let fake = |n: u64| {
        let k = (n / per_sample) % fix_every;
        [k as f64 * zeta, k as f64 * zeta]
    };
    let samples = run(
        &VelocityBase::IDEAL,
        &reference,
        &agents,
        &[start],
        dt,
        20.0,
        fake,
    );
    let bound = KinematicTheorem2::new(ke, zeta, gamma).unwrap();
    let z_max = samples
        .iter()
        .map(|s| norm(s.outs[0].z))
        .fold(0.0, f64::max);
    let e_max = samples
        .iter()
        .filter(|s| s.t > 5.0)
        .map(|s| norm(s.outs[0].e))
        .fold(0.0, f64::max);
    // Samples run from 0 to N − 1 between fixes.
    let (zb, eb) = (bound.z_bound(fix_every), bound.e_bound(fix_every));
    eprintln!("max ‖z‖ {z_max:e} ≤ {zb:e}, max ‖e‖ {e_max:e} ≤ {eb:e}");
    assert!(z_max <= zb && e_max <= eb);
    // Tight: z = K_e ẽ reaches √2 K_e (N − 1) ζ before each fix.
    assert!((z_max - bound.z_bound(fix_every - 1)).abs() < 1e-9 * zb);
    assert!(
        e_max > 0.2 * eb,
        "‖e‖ bound far from tight: {e_max:e} vs {eb:e}"
    );
}

fn vec2(r: f64) -> impl Strategy<Value = [f64; 2]> {
    [-r..r, -r..r]
}

prop_compose! {
    fn any_base()(
        tau_v in 0.02..0.5f64, tau_omega in 0.02..0.5f64,
        v_max in 0.05..3.0f64, omega_max in 0.1..5.0f64,
        a_max in 0.1..20.0f64, alpha_max in 0.1..30.0f64,
        per_axis in any::<bool>(),
    ) -> VelocityBase {
        VelocityBase::new(VelocityBaseSpec {
            tau_v, tau_omega, v_max, omega_max, a_max, alpha_max,
            accel: if per_axis { AccelLimit::PerAxis } else { AccelLimit::Joint },
        })
        .unwrap()
    }
}

/// A command: often within the limits, often far beyond, sometimes on an axis.
fn any_command() -> impl Strategy<Value = VelocityCommand> {
    let axis = prop_oneof![Just(0.0), -0.5..0.5f64, -20.0..20.0f64];
    (axis.clone(), axis).prop_map(|(v, omega)| VelocityCommand { v, omega })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    /// The limiter keeps the curvature and the sign of each axis, holds both
    /// limits, reaches the binding one (it scales no more than it must), and
    /// is the identity within the limits.
    #[test]
    fn limiter_keeps_the_curvature_and_holds_the_limits(
        base in any_base(), cmd in any_command(),
    ) {
        let (c, saturated) = base.limit(cmd);
        prop_assert!(c.v.abs() <= base.v_max() && c.omega.abs() <= base.omega_max());
        let within = cmd.v.abs() <= base.v_max() && cmd.omega.abs() <= base.omega_max();
        prop_assert_eq!(saturated, !within);
        if within {
            prop_assert_eq!(c, cmd);
        } else {
            // ω'/v' = ω/v: |ω' v − v' ω| within rounding of |ω v|.
            let cross = c.omega * cmd.v - c.v * cmd.omega;
            prop_assert!(cross.abs() <= 1e-15 * (cmd.omega * cmd.v).abs(), "{cross:e}");
            prop_assert!(c.v * cmd.v >= 0.0 && c.omega * cmd.omega >= 0.0);
            let reach = (c.v.abs() / base.v_max()).max(c.omega.abs() / base.omega_max());
            prop_assert!((reach - 1.0).abs() < 1e-15, "{reach}");
        }
    }

    /// Over one RK4 step with `dt ≤ τ` from a velocity within the limits: the
    /// velocity stays within them and changes by at most `a_max dt`, `α_max dt`;
    /// with joint limits and equal lags, a base on the command's ray (at rest,
    /// say) stays on it: the curvature is kept during the transient.
    #[test]
    fn a_step_holds_the_acceleration_and_speed_limits(
        base in any_base(), cmd in any_command(),
        v in -1.0..1.0f64, omega in -1.0..1.0f64, theta in -3.0..3.0f64,
        dt_share in 0.01..1.0f64, on_ray in 0.0..1.0f64,
    ) {
        let (c, _) = base.limit(cmd);
        let s = State { x: 0.0, y: 0.0, theta, v: v * base.v_max(), omega: omega * base.omega_max() };
        let dt = dt_share * base.tau_v().min(base.tau_omega());
        let next = base.rk4_step(&s, c, dt);
        let tol = 1e-12;
        // A change is the difference of two speeds: it carries their rounding
        // (a few ulps of the speed), whatever its own size.
        let ulps = |a: f64, b: f64| 4.0 * f64::EPSILON * a.abs().max(b.abs());
        prop_assert!(next.v.abs() <= base.v_max() && next.omega.abs() <= base.omega_max());
        prop_assert!(
            (next.v - s.v).abs() <= base.a_max() * dt * (1.0 + tol) + ulps(next.v, s.v),
            "{} > {}", (next.v - s.v).abs(), base.a_max() * dt
        );
        prop_assert!(
            (next.omega - s.omega).abs()
                <= base.alpha_max() * dt * (1.0 + tol) + ulps(next.omega, s.omega),
            "{} > {}", (next.omega - s.omega).abs(), base.alpha_max() * dt
        );
        // on the ray: equal lags, joint limits, a start at on_ray × command
        let joint = VelocityBase::new(VelocityBaseSpec {
            tau_omega: base.tau_v(),
            accel: AccelLimit::Joint,
            ..base.spec()
        }).unwrap();
        let s = State { v: on_ray * c.v, omega: on_ray * c.omega, ..s };
        let next = joint.rk4_step(&s, c, dt_share * joint.tau_v());
        let cross = next.omega * c.v - next.v * c.omega;
        prop_assert!(cross.abs() <= 1e-12 * (c.v * c.omega).abs().max(1e-300), "{cross:e}");
    }

    /// For any base, at any instant, `V̇₁ = −K_e‖e‖² + eᵀz` with `z` at the
    /// base's velocities (exact `L̇_Y`), by automatic differentiation of eq. 7
    /// along the base's motion; `z = 0` and `V̇₁ = −K_e‖e‖²` for the ideal base.
    #[test]
    fn v1_identity_holds_for_any_base(
        base in any_base(), ideal in any::<bool>(),
        x in -5.0..5.0f64, y in -5.0..5.0f64, theta in -7.0..7.0f64,
        v in -1.0..1.0f64, omega in -2.0..2.0f64,
        pd in vec2(5.0), dpd in vec2(1.5),
        lx_off in 0.0..1.0f64, l in 0.01..0.3f64,
        ly in -1.0..1.0f64, dly in -0.5..0.5f64, ke in 0.05..5.0f64,
    ) {
        let base = if ideal { VelocityBase::IDEAL } else { base };
        let s = State { x, y, theta, v, omega };
        let leader = LeaderMotion { p: pd, dp: dpd, ddp: [0.0, 0.0] };
        let off = Offset { lx: lx_off + l, ly, dly, ddly: 0.0 };
        let out = kinematic_law(&s, &leader, &off, ke);
        let (c, _) = base.limit(out.cmd);
        let ds = base.derivative(&s, c);
        let (bv, bw) = base.speeds(&s, c);
        let z = kinematic_law(&State { v: bv, omega: bw, ..s }, &leader, &off, ke).z;
        let d = Dual64::new;
        let th = d(theta, ds.theta);
        // e (eq. 7) along the motion; ṗ_d's own derivative does not enter e.
        let (e, _) = errors(
            d(x, ds.x), d(y, ds.y), (th.sin(), th.cos()),
            d(0.0, 0.0), d(0.0, 0.0),
            [d(pd[0], dpd[0]), d(pd[1], dpd[1])],
            [d(dpd[0], 0.0), d(dpd[1], 0.0)],
            off.lx, d(ly, dly), d(dly, 0.0), ke,
        );
        let v1_dot = e[0].re * e[0].eps + e[1].re * e[1].eps;
        let want = lyapunov_rate(out.e, z, ke);
        let scale = ke * (out.e[0].powi(2) + out.e[1].powi(2)) + norm(out.e) * norm(z) + 1e-12;
        prop_assert!((v1_dot - want).abs() <= 1e-12 * scale, "{v1_dot} vs {want}");
        if ideal {
            prop_assert!(norm(z) <= 1e-12 * (1.0 + norm([c.v, c.omega])));
        }
    }
}
