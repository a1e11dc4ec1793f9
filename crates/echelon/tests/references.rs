//! Every reference's exact derivatives agree with finite differences of its
//! positions (central differences, error O(h²)).
#![allow(clippy::unwrap_used)] // tests fail loudly by design

use echelon::reference::{Circle, Cubic, Jet, Lemniscate, Order, Trajectory, Waypoints};
use proptest::prelude::*;

/// Derivatives 1–4 of the position by central differences with step `h`.
fn central(r: &dyn Trajectory, t: f64, h: f64) -> [[f64; 2]; 4] {
    let p = |k: f64| r.eval(t + k * h, Order::Two).p;
    let (m2, m1, c, p1, p2) = (p(-2.0), p(-1.0), p(0.0), p(1.0), p(2.0));
    std::array::from_fn(|order| {
        std::array::from_fn(|i| match order {
            0 => (p1[i] - m1[i]) / (2.0 * h),
            1 => (p1[i] - 2.0 * c[i] + m1[i]) / (h * h),
            2 => (p2[i] - 2.0 * p1[i] + 2.0 * m1[i] - m2[i]) / (2.0 * h.powi(3)),
            _ => (p2[i] - 4.0 * p1[i] + 6.0 * c[i] - 4.0 * m1[i] + m2[i]) / h.powi(4),
        })
    })
}

/// Richardson-extrapolated central differences: error O(h⁴) instead of O(h²).
fn finite_differences(r: &dyn Trajectory, t: f64, h: f64) -> [[f64; 2]; 4] {
    let (fine, coarse) = (central(r, t, h), central(r, t, 2.0 * h));
    std::array::from_fn(|k| std::array::from_fn(|i| (4.0 * fine[k][i] - coarse[k][i]) / 3.0))
}

/// Checks jet derivatives 1..=`orders` against finite differences of positions.
/// The tolerance allows for the differences' own rounding error, which grows like
/// `ε · size / hⁿ` for the n-th derivative (`size` bounds the magnitude of the
/// quantities the position is computed from), and for their truncation error,
/// estimated as the change from step `2h` to `h` (it falls like `h⁴`, so it
/// is about 15 times the error left at `h`): a fast, large lemniscate's fourth
/// derivative differs from its differences at `h = 10 ms` by 2.5e-5 of its
/// size (checked against mpmath), more than a fixed relative tolerance allows.
fn check(r: &dyn Trajectory, t: f64, orders: usize) -> Result<(), TestCaseError> {
    let jet: Jet = r.eval(t, Order::Four);
    let exact = [jet.dp, jet.ddp, jet.d3p, jet.d4p];
    let steps = [1e-4, 1e-3, 5e-3, 1e-2];
    let size = 1.0 + jet.p[0].abs().max(jet.p[1].abs()) + t.abs() * (1.0 + jet.speed());
    for k in 0..orders {
        let h = steps[k];
        let fd = finite_differences(r, t, h)[k];
        let coarser = finite_differences(r, t, 2.0 * h)[k];
        let rounding = 64.0 * f64::EPSILON * size / h.powi(k as i32 + 1);
        for i in 0..2 {
            let truncation = (coarser[i] - fd[i]).abs();
            let tol = 1e-5 * exact[k][i].abs() + rounding + truncation;
            prop_assert!(
                (fd[i] - exact[k][i]).abs() <= tol,
                "t = {t}, derivative {}, axis {i}: exact {} vs finite difference {} (tolerance {tol:e})",
                k + 1,
                exact[k][i],
                fd[i]
            );
        }
    }
    // Order::Two gives the same first three terms.
    let two = r.eval(t, Order::Two);
    prop_assert_eq!((two.p, two.dp, two.ddp), (jet.p, jet.dp, jet.ddp));
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn circle(t in 0.0..100.0f64, v in 0.0..2.0f64, w in -1.5..1.5f64, th in -3.0..3.0f64) {
        check(&Circle::new([1.0, -2.0], th, v, w).unwrap(), t, 4)?;
    }

    #[test]
    fn straight_line(t in 0.0..100.0f64, v in 0.0..2.0f64, th in -3.0..3.0f64) {
        check(&Circle::new([0.5, 0.5], th, v, 0.0).unwrap(), t, 4)?;
    }

    #[test]
    fn lemniscate(t in 0.0..60.0f64, a in 0.5..10.0f64, c in 0.05..0.8f64) {
        check(&Lemniscate::new(a, c, [0.3, -0.2]).unwrap(), t, 4)?;
    }

    #[test]
    fn cubic_away_from_the_switch(t in 0.0..10.0f64) {
        prop_assume!((t - 4.0).abs() > 0.1);
        check(&Cubic::new(1.0 / 16.0, 4.0).unwrap(), t, 4)?;
    }

    #[test]
    fn waypoints_between_knots(t in 0.0..12.0f64) {
        let w = Waypoints::new(vec![
            [0.0, 0.0, 0.0], [2.0, 1.0, 0.5], [3.5, 2.0, 2.0], [6.0, 0.0, 3.0],
            [8.0, -1.0, 1.0], [12.0, 0.0, 0.0],
        ]).unwrap();
        // The snap jumps at the two end knots (the path is C³ there); elsewhere C⁶.
        prop_assume!(t > 0.1 && t < 11.9);
        check(&w, t, 4)?;
    }
}

#[test]
fn cubic_is_c2_at_the_switch_and_its_jerk_jumps() {
    let c = Cubic::new(1.0 / 16.0, 4.0).unwrap();
    let (a, b) = (
        c.eval(4.0 - 1e-9, Order::Four),
        c.eval(4.0 + 1e-9, Order::Four),
    );
    for i in 0..2 {
        assert!((a.p[i] - b.p[i]).abs() < 1e-12);
        assert!((a.dp[i] - b.dp[i]).abs() < 1e-12);
        assert!((a.ddp[i] - b.ddp[i]).abs() < 1e-9);
    }
    assert_eq!(a.d3p[1], 0.0);
    assert_eq!(b.d3p[1], 6.0 / 16.0);
}

#[test]
fn waypoints_stand_still_outside_their_times() {
    let w = Waypoints::new(vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]).unwrap();
    let before = w.eval(0.0, Order::Four);
    let after = w.eval(9.0, Order::Four);
    assert_eq!(before.p, [2.0, 3.0]);
    assert_eq!(after.p, [5.0, 6.0]);
    assert_eq!((before.dp, after.dp), ([0.0; 2], [0.0; 2]));
}

#[test]
fn lemniscate_fourth_derivative_matches_a_high_precision_value() {
    // mpmath, 50 digits: d⁴y/dt⁴ of eq. 19 (shifted by −0.2 in y) at this point.
    let (a, c, t) = (3.514547494889757, 0.7484132486715416, 21.87036945138806);
    let jet = Lemniscate::new(a, c, [0.3, -0.2])
        .unwrap()
        .eval(t, Order::Four);
    let want = -1.146_842_467_806_768_4;
    assert!(
        (jet.d4p[1] - want).abs() < 1e-12,
        "{} vs {want}",
        jet.d4p[1]
    );
}

/// The lemniscate that failed the fixed tolerance in CI's random sample
/// (a = 9.37 m, c = 0.757 rad/s, near its crossing): its fourth derivative
/// (mpmath: −1.474 061 136 793 818 5) is exact to 1e-12, and its differences
/// pass within their estimated truncation error.
#[test]
fn a_fast_large_lemniscate_passes_within_its_differences_error() {
    let (a, c, t) = (9.36642902278748, 0.7565722195046378, 0.38103171854126966);
    let r = Lemniscate::new(a, c, [0.3, -0.2]).unwrap();
    let jet = r.eval(t, Order::Four);
    assert!(
        (jet.d4p[0] - -1.474_061_136_793_818_5).abs() < 1e-12,
        "{}",
        jet.d4p[0]
    );
    check(&r, t, 4).unwrap();
}
