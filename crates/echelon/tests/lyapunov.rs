//! The Lyapunov identities of control-law.md:
//! `V̇₂ = −K_e‖e‖² + eᵀz − K_z‖z‖²` (paper law) and `V̇₂ = −K_e‖e‖² − K_z‖z‖²`
//! (complete law), exact whenever `L̇_Y`, `L̈_Y` are the true derivatives of `L_Y`.
#![allow(clippy::unwrap_used)] // tests fail loudly by design

mod common;

use common::{Sample, agent, placement, record};
use echelon::control::{LeaderMotion, Offset, errors, law, lyapunov, lyapunov_rate};
use echelon::formation::Leader;
use echelon::lycomp::{LyComp, LyDerivatives};
use echelon::reference::{Circle, Lemniscate, Reference};
use echelon::{Gains, RobotParams, State, Variant};
use num_dual::{Dual64, DualNum};
use proptest::prelude::*;

/// Largest relative gap between the central difference of `V₂` along the run
/// and the identity, over samples where `V̇₂` is not negligible.
fn worst_identity_gap(samples: &[Sample], agent: usize, gains: Gains, variant: Variant) -> f64 {
    let dt = samples[1].t - samples[0].t;
    let v2: Vec<f64> = samples
        .iter()
        .map(|s| lyapunov(s.outputs[agent].e, s.outputs[agent].z))
        .collect();
    let mut worst: f64 = 0.0;
    for k in 1..samples.len() - 1 {
        let o = &samples[k].outputs[agent];
        let rate = lyapunov_rate(o.e, o.z, gains, variant);
        if rate.abs() < 1e-6 {
            continue;
        }
        let fd = (v2[k + 1] - v2[k - 1]) / (2.0 * dt);
        worst = worst.max((fd - rate).abs() / rate.abs());
    }
    worst
}

fn circle_run(variant: Variant) -> Vec<Sample> {
    let reference = Reference::Circle(Circle::new([0.0, 0.0], 0.0, 0.5, 0.1).unwrap());
    let agents = vec![
        // Follows the circle: L_Ycomp is constant on a circle (eq. 6 and eq. 5 alike).
        agent(
            Leader::Reference,
            placement(0.5, 0.8, LyComp::Fit, LyDerivatives::Neglect),
            State::at_rest(-0.3, -1.5, 0.0),
            variant,
        ),
        agent(
            Leader::Reference,
            placement(0.5, -0.8, LyComp::Exact, LyDerivatives::Neglect),
            State::at_rest(-0.2, 1.6, 0.3),
            variant,
        ),
        // Follows robot 1 with constant L_Y: p̈_d comes from robot 1's torques.
        agent(
            Leader::Agent(0),
            placement(0.5, -0.4, LyComp::None, LyDerivatives::Neglect),
            State::at_rest(-0.8, -0.2, 0.0),
            variant,
        ),
    ];
    record(agents, reference, 1e-4, 6.0)
}

/// Asserts the identity of `variant` along [`circle_run`] for each of its
/// three agents, to a relative 2e-6.
fn assert_identity_along_a_circle_run(variant: Variant) {
    let samples = circle_run(variant);
    for a in 0..3 {
        let gap = worst_identity_gap(&samples, a, Gains::PAPER, variant);
        eprintln!("agent {}: worst relative gap {gap:e}", a + 1);
        assert!(gap < 2e-6, "agent {}: relative gap {gap:e}", a + 1);
    }
}

#[test]
fn paper_identity_holds_along_a_circle_run() {
    assert_identity_along_a_circle_run(Variant::Paper);
}

#[test]
fn complete_identity_holds_along_a_circle_run() {
    assert_identity_along_a_circle_run(Variant::Complete);
}

#[test]
fn identity_holds_with_time_varying_l_y_when_its_derivatives_are_exact() {
    // On a lemniscate the curvature changes, so L_Y does: the identity is exact
    // only when L̇_Y and L̈_Y are the true derivatives.
    let reference = Reference::Lemniscate(Lemniscate::new(3.0, 0.3, [0.0, 0.0]).unwrap());
    let run = |derivatives| {
        let agents = vec![agent(
            Leader::Reference,
            placement(0.5, 0.5, LyComp::Exact, derivatives),
            State::at_rest(3.5, -0.6, 1.4),
            Variant::Complete,
        )];
        record(agents, reference.clone(), 1e-4, 8.0)
    };
    let exact = worst_identity_gap(
        &run(LyDerivatives::Exact),
        0,
        Gains::PAPER,
        Variant::Complete,
    );
    eprintln!("exact L_Y derivatives: worst relative gap {exact:e}");
    assert!(exact < 2e-6, "exact derivatives: relative gap {exact:e}");
    // The test has teeth: neglecting them (the paper's choice) breaks the identity.
    let neglected = worst_identity_gap(
        &run(LyDerivatives::Neglect),
        0,
        Gains::PAPER,
        Variant::Complete,
    );
    assert!(
        neglected > 1e-3,
        "neglected derivatives: relative gap only {neglected:e}"
    );
}

/// `V̇₂` and `ż` at one instant by automatic differentiation along the plant's
/// motion under the law's input, with `L_Y` moving at `L̇_Y`, `L̈_Y`.
struct Instant {
    e: [f64; 2],
    z: [f64; 2],
    de: [f64; 2],
    dz: [f64; 2],
}

#[allow(clippy::too_many_arguments)]
fn differentiate(
    robot: &RobotParams,
    s: State,
    pd: [f64; 2],
    dpd: [f64; 2],
    ddpd: [f64; 2],
    off: Offset,
    gains: Gains,
    variant: Variant,
) -> Instant {
    let leader = LeaderMotion {
        p: pd,
        dp: dpd,
        ddp: ddpd,
    };
    let out = law(robot, &s, &leader, &off, gains, variant);
    let ds = robot.derivative(&s, out.u);
    let d = Dual64::new;
    let theta = d(s.theta, ds.theta);
    let (e, z) = errors(
        d(s.x, ds.x),
        d(s.y, ds.y),
        (theta.sin(), theta.cos()),
        d(s.v, ds.v),
        d(s.omega, ds.omega),
        [d(pd[0], dpd[0]), d(pd[1], dpd[1])],
        [d(dpd[0], ddpd[0]), d(dpd[1], ddpd[1])],
        off.lx,
        d(off.ly, off.dly),
        d(off.dly, off.ddly),
        gains.ke(),
    );
    assert_eq!([e[0].re, e[1].re], out.e);
    assert_eq!([z[0].re, z[1].re], out.z);
    Instant {
        e: out.e,
        z: out.z,
        de: [e[0].eps, e[1].eps],
        dz: [z[0].eps, z[1].eps],
    }
}

fn vec2(r: f64) -> impl Strategy<Value = [f64; 2]> {
    [-r..r, -r..r]
}

prop_compose! {
    fn instant_inputs()(
        x in -5.0..5.0f64, y in -5.0..5.0f64, theta in -7.0..7.0f64,
        v in -1.5..1.5f64, omega in -2.0..2.0f64,
        pd in vec2(5.0), dpd in vec2(1.5), ddpd in vec2(1.0),
        lx_off in 0.0..1.0f64, l in 0.01..0.3f64,
        ly in -1.0..1.0f64, dly in -0.5..0.5f64, ddly in -0.5..0.5f64,
        agent2 in any::<bool>(),
    ) -> (RobotParams, State, [[f64; 2]; 3], Offset) {
        let robot = if agent2 { RobotParams::AGENT2 } else { RobotParams::AGENT1 };
        (robot, State { x, y, theta, v, omega }, [pd, dpd, ddpd],
         Offset { lx: lx_off + l, ly, dly, ddly })
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    /// The law's `h` and `B` (eq. 12, corrected) are exactly the time derivative
    /// of `z`: along the closed loop `ż = −K_z z` (paper) or `−K_z z − e` (complete),
    /// and `V̇₂` equals its identity. Checked by automatic differentiation.
    #[test]
    fn closed_loop_z_dot_and_v2_identity_are_exact(
        (robot, s, [pd, dpd, ddpd], off) in instant_inputs(),
        ke in 0.05..5.0f64, kz in 0.05..30.0f64, complete in any::<bool>(),
    ) {
        let variant = if complete { Variant::Complete } else { Variant::Paper };
        let gains = Gains::new(ke, kz).unwrap();
        let i = differentiate(&robot, s, pd, dpd, ddpd, off, gains, variant);
        let extra = if complete { [i.e[0], i.e[1]] } else { [0.0, 0.0] };
        for (k, extra) in extra.iter().enumerate() {
            let want = -kz * i.z[k] - extra;
            prop_assert!((i.dz[k] - want).abs() <= 1e-9 * (1.0 + want.abs()),
                "ż[{}] = {} but law promises {}", k, i.dz[k], want);
        }
        let vdot = i.e[0] * i.de[0] + i.e[1] * i.de[1] + i.z[0] * i.dz[0] + i.z[1] * i.dz[1];
        let rate = lyapunov_rate(i.e, i.z, gains, variant);
        prop_assert!((vdot - rate).abs() <= 1e-9 * (1.0 + rate.abs()), "{} vs {}", vdot, rate);
    }

    /// Theorem 1 for the paper's law: `V̇₂ < 0` away from the origin whenever `K_e K_z > 1/4`.
    #[test]
    fn paper_law_decreases_v2_when_ke_kz_exceeds_a_quarter(
        (robot, s, [pd, dpd, ddpd], off) in instant_inputs(),
        ke in 0.05..5.0f64, margin in 1.01..50.0f64,
    ) {
        let gains = Gains::new(ke, margin * 0.25 / ke).unwrap();
        let i = differentiate(&robot, s, pd, dpd, ddpd, off, gains, Variant::Paper);
        let vdot = i.e[0] * i.de[0] + i.e[1] * i.de[1] + i.z[0] * i.dz[0] + i.z[1] * i.dz[1];
        let size = i.e[0].powi(2) + i.e[1].powi(2) + i.z[0].powi(2) + i.z[1].powi(2);
        prop_assume!(size > 1e-12);
        prop_assert!(vdot < 0.0, "V̇₂ = {} with K_e K_z = {}", vdot, ke * gains.kz());
    }
}

#[test]
fn paper_law_can_increase_v2_when_ke_kz_is_below_a_quarter() {
    // The cross term eᵀz is real: with K_e K_z < 1/4 and e ∥ z, V̇₂ > 0.
    let gains = Gains::new(0.1, 0.5).unwrap();
    let (e, z) = ([1.0, 0.0], [1.0, 0.0]);
    assert!(lyapunov_rate(e, z, gains, Variant::Paper) > 0.0);
    assert!(lyapunov_rate(e, z, gains, Variant::Complete) < 0.0);
}
