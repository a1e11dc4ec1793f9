//! The exact fit of an axis from the run's running integrals:
//! `x_k = x₀ + (k ΔI_k − ΔS_k)/τ`, solved by linear least squares.

use super::{AxisData, AxisFit, cost, least_squares};

/// The integrals of one axis over the log, from `integrals.csv`: the
/// output's own integral `S` (distance `∫v dt` or heading `∫ω dt`) and the
/// input's `I = ∫u dt`, at the sample times.
#[derive(Debug, Clone, Copy)]
pub(crate) struct AxisIntegrals<'a> {
    pub(crate) s: &'a [f64],
    pub(crate) i: &'a [f64],
}

/// Fits the axis from its integrals: `τ ẋ + x = k u` integrated from the
/// first sample is `x_k = x₀ + (k I_k − S_k)/τ` (`I`, `S` counted from the
/// first sample), exact whatever the input did between samples. Linear least
/// squares in `(x₀, k/τ, 1/τ)` (or `(x₀, 1/τ)` with `k = 1`), by
/// Householder-free modified Gram–Schmidt on unit-scaled columns; the
/// measured output's noise is the residual, white, so `σ² (XᵀX)⁻¹` is the
/// covariance. `(τ, k)` and their covariance follow by the delta method.
pub(crate) fn fit_integral(d: &AxisData<'_>, w: &AxisIntegrals<'_>, fixed_gain: bool) -> AxisFit {
    let n = d.t.len();
    let (i0, s0) = (w.i[0], w.s[0]);
    // Columns: 1, I − I₀, −(S − S₀)   or   1, (I − I₀) − (S − S₀).
    let cols: Vec<Vec<f64>> = if fixed_gain {
        vec![
            vec![1.0; n],
            (0..n).map(|k| (w.i[k] - i0) - (w.s[k] - s0)).collect(),
        ]
    } else {
        vec![
            vec![1.0; n],
            (0..n).map(|k| w.i[k] - i0).collect(),
            (0..n).map(|k| -(w.s[k] - s0)).collect(),
        ]
    };
    let (beta, cov_b, rc) = least_squares(&cols, d.y);
    let predicted: Vec<f64> = (0..n)
        .map(|k| cols.iter().zip(&beta).map(|(c, b)| c[k] * b).sum())
        .collect();
    let c = cost(d.y, &predicted);
    let sigma2 = c / n.saturating_sub(cols.len()).max(1) as f64;
    let (theta, cov) = if fixed_gain {
        // τ = 1/γ.
        let g = beta[1];
        let var = sigma2 * cov_b[1][1] / g.powi(4);
        ([1.0 / g, 1.0], [[var, 0.0], [0.0, 0.0]])
    } else {
        // α = k/τ, β = 1/τ: τ = 1/β, k = α/β.
        let (a, b) = (beta[1], beta[2]);
        let jac = [[0.0, -1.0 / (b * b)], [1.0 / b, -a / (b * b)]];
        let cb = [[cov_b[1][1], cov_b[1][2]], [cov_b[2][1], cov_b[2][2]]];
        let mut cov = [[0.0; 2]; 2];
        for p in 0..2 {
            for q in 0..2 {
                for r in 0..2 {
                    for t in 0..2 {
                        cov[p][q] += sigma2 * jac[p][r] * cb[r][t] * jac[q][t];
                    }
                }
            }
        }
        ([1.0 / b, a / b], cov)
    };
    AxisFit {
        theta,
        cov,
        x0: beta[0],
        first_guess: theta,
        rms: (c / n as f64).sqrt(),
        predicted,
        rcond: rc,
        between: None,
        segments: None,
    }
}
