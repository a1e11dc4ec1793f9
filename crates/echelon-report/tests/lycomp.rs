//! `L_Ycomp`: the paper's fit (eq. 6) against eq. 5, and the least-squares refit.
#![allow(clippy::unwrap_used)]

use echelon::lycomp::{FitCoefficients, fit_rc};
use echelon_report::lycomp::{eq5, fit_cost, largest_gap, refit, refit_from};

const LAMBDAS: [f64; 9] = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9];

#[test]
fn the_papers_fit_has_the_gap_control_law_md_states() {
    // docs/control-law.md: at λ = 0.5 the largest gap is 0.23 m, near |R_C| = 0.7.
    let gap = largest_gap(&FitCoefficients::paper(0.5), 0.5);
    assert!((gap.gap - 0.23).abs() < 0.005, "{gap:?}");
    assert!((gap.at - 0.7).abs() < 0.02, "{gap:?}");
}

#[test]
fn eq5_is_odd_linear_inside_lambda_and_zero_on_a_line() {
    for rc in [0.05, 0.3, 0.49] {
        assert_eq!(eq5(rc, 0.5), rc);
        assert_eq!(eq5(-rc, 0.5), -rc);
    }
    assert_eq!(eq5(0.0, 0.5), 0.0);
    let far = eq5(1e6, 0.5);
    assert!(far > 0.0 && (far - 0.25 / 2e6).abs() < 1e-15, "{far}");
}

#[test]
fn the_refit_is_a_least_squares_optimum_at_least_as_good_as_the_paper() {
    for lambda in LAMBDAS {
        let fit = refit(lambda).unwrap();
        let c = fit.coefficients;
        let paper = FitCoefficients::paper(lambda);
        assert!(
            fit.cost < fit_cost(&paper, lambda),
            "λ = {lambda}: {} vs paper {}",
            fit.cost,
            fit_cost(&paper, lambda)
        );
        assert!((fit.cost - fit_cost(&c, lambda)).abs() <= 1e-12 * fit.cost);
        // First-order optimality: the cost's gradient vanishes (relative to its scale).
        let p = [c.g, c.delta, c.epsilon];
        for k in 0..3 {
            let h = 1e-6 * p[k].abs();
            let at = |d: f64| {
                let mut q = p;
                q[k] += d;
                fit_cost(
                    &FitCoefficients {
                        g: q[0],
                        delta: q[1],
                        epsilon: q[2],
                    },
                    lambda,
                )
            };
            let grad = (at(h) - at(-h)) / (2.0 * h) * p[k].abs();
            assert!(
                grad.abs() < 1e-6 * fit.cost.max(1e-12) + 1e-12,
                "λ = {lambda}, ∂{k}: {grad}"
            );
        }
        // Started from the paper's coefficients, LM reaches the same optimum.
        let from_paper = refit_from(lambda, paper).unwrap();
        assert!(
            (from_paper.cost - fit.cost).abs() <= 1e-8 * fit.cost,
            "λ = {lambda}: {} vs {}",
            from_paper.cost,
            fit.cost
        );
    }
}

#[test]
fn the_refit_scales_with_lambda_like_eq_5() {
    // L_Ycomp(R; λ) = λ h(R/λ) and the criterion scales with λ: so do G, δ, ε.
    let unit = refit(1.0).unwrap().coefficients;
    for lambda in LAMBDAS.iter().copied().chain([0.05, 2.0, 7.5]) {
        let c = refit(lambda).unwrap().coefficients;
        for (a, b) in [
            (c.g, unit.g),
            (c.delta, unit.delta),
            (c.epsilon, unit.epsilon),
        ] {
            assert!(
                (a / lambda - b).abs() < 1e-6 * b,
                "λ = {lambda}: {c:?} vs {unit:?}"
            );
        }
    }
}

#[test]
fn the_refit_lands_close_to_the_papers_curve_with_a_smaller_worst_error() {
    // Tolerance, stated: the refit's curve is within 0.5 λ of the paper's
    // everywhere (the largest difference, 0.47 λ, is at λ = 0.2), and its
    // largest gap to eq. 5 is never larger than the paper's (0.122 m against
    // 0.230 m at λ = 0.5).
    for lambda in LAMBDAS {
        let c = refit(lambda).unwrap().coefficients;
        let paper = FitCoefficients::paper(lambda);
        let diff = (1..=20_000)
            .map(|i| 10.0 * lambda * f64::from(i) / 20_000.0)
            .map(|rc| (fit_rc(rc, &c) - fit_rc(rc, &paper)).abs())
            .fold(0.0, f64::max);
        assert!(
            diff <= 0.5 * lambda,
            "λ = {lambda}: curves differ by {diff}"
        );
        let (mine, theirs) = (largest_gap(&c, lambda), largest_gap(&paper, lambda));
        assert!(
            mine.gap <= theirs.gap,
            "λ = {lambda}: {mine:?} vs {theirs:?}"
        );
        // Both peak near R_C = λ at nearly λ, as eq. 5 does.
        let peak = |c: &FitCoefficients| {
            (1..=20_000)
                .map(|i| 3.0 * lambda * f64::from(i) / 20_000.0)
                .map(|rc| (fit_rc(rc, c), rc))
                .fold((0.0, 0.0), |a, b| if b.0 > a.0 { b } else { a })
        };
        let (h, at) = peak(&c);
        assert!(
            (at - lambda).abs() < 0.2 * lambda && (h - lambda).abs() < 0.3 * lambda,
            "λ = {lambda}: peak {h} at {at}"
        );
    }
    let half = refit(0.5).unwrap().coefficients;
    assert!((largest_gap(&half, 0.5).gap - 0.122).abs() < 0.002);
}

#[test]
fn impossible_offsets_are_refused() {
    for bad in [0.0, -0.5, f64::NAN, f64::INFINITY] {
        assert!(refit(bad).is_err(), "{bad}");
    }
}

/// `echelon lycomp --lxoff 1e300` printed a "fit" after one iteration with
/// an infinite gap (λ² overflowed), `1e-300` one of zeros (λ² underflowed):
/// the refit and the gap are computed in units of λ, so for every finite
/// λ > 0 they are the λ = 1 ones scaled by λ.
#[test]
fn the_refit_and_its_gap_hold_for_any_finite_lambda() {
    let unit = refit(1.0).unwrap().coefficients;
    let unit_gap = largest_gap(&unit, 1.0);
    let mut lcg = 0x2545_f491_4f6c_dd1du64;
    for _ in 0..40 {
        lcg = lcg
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        // log10 λ uniform on [-300, 300].
        let lambda = 10f64.powf(((lcg >> 11) as f64 / (1u64 << 53) as f64) * 600.0 - 300.0);
        let r = refit(lambda).unwrap();
        let c = r.coefficients;
        for (got, want) in [
            (c.g, unit.g),
            (c.delta, unit.delta),
            (c.epsilon, unit.epsilon),
        ] {
            assert!(
                (got / lambda - want).abs() < 1e-9 * want,
                "λ = {lambda:e}: {c:?} against λ · {unit:?}"
            );
        }
        // The cost is in m²: past λ ≈ 1e154 that is infinite, never NaN.
        assert!(
            !r.cost.is_nan() && r.iterations > 1,
            "λ = {lambda:e}: {r:?}"
        );
        let gap = largest_gap(&c, lambda);
        assert!(
            (gap.gap / lambda - unit_gap.gap).abs() < 1e-9 * unit_gap.gap
                && (gap.at / lambda - unit_gap.at).abs() < 1e-9 * unit_gap.at,
            "λ = {lambda:e}: {gap:?} against λ · {unit_gap:?}"
        );
        assert!(eq5(0.5 * lambda, lambda) == 0.5 * lambda && eq5(1e3 * lambda, lambda) > 0.0);
    }
}
