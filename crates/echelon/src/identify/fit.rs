//! One first-order axis, `τ ẋ + x = k u` with `u` held between samples:
//! an equation-error first guess from the integrated equation, then an
//! output-error Levenberg–Marquardt refinement of `(τ, k, x₀)`.
//!
//! Both of the robot's axes are of this form:
//!
//! - eq. 3c `m v̇ + η v = u1` is `τ = m/η`, `k = 1/η`;
//! - eq. 3d `J ω̇ + ψ ω = u2` is `τ = J/ψ`, `k = 1/ψ`;
//! - a velocity base's lag `τ_v v̇ + v = v_c` is `k = 1` (fixed).
//!
//! The input is held between samples (zero-order hold, as a sampled controller
//! applies it), so the exact discretisation over a step `h` is
//! `x⁺ = a x + (1 − a) k u` with `a = e^{−h/τ}`: the model simulated here is
//! exact for such a plant, whatever the sample spacing.

// Small dense linear algebra (n ≤ 3) reads best with explicit indices.
#![allow(clippy::needless_range_loop)]

/// Number of samples per window of the integrated equation (first guess).
const WINDOW: usize = 10;
/// Iterations of Levenberg–Marquardt at most.
const MAX_ITER: usize = 200;
/// The 97.5 % quantile of the standard normal: a 95 % two-sided interval.
pub(crate) const Z95: f64 = 1.959_963_984_540_054;

/// The data of one axis: sample times, the input held from each sample to the
/// next, and the measured output.
#[derive(Debug, Clone, Copy)]
pub(crate) struct AxisData<'a> {
    pub(crate) t: &'a [f64],
    pub(crate) u: &'a [f64],
    pub(crate) y: &'a [f64],
}

/// The fit of one axis.
#[derive(Debug, Clone)]
pub(crate) struct AxisFit {
    /// `[τ, k]` (k = 1 when fixed).
    pub(crate) theta: [f64; 2],
    /// Covariance of `[τ, k]` (zero row/column for a fixed k).
    pub(crate) cov: [[f64; 2]; 2],
    /// Estimated initial output.
    #[cfg_attr(not(test), expect(dead_code))]
    pub(crate) x0: f64,
    /// The equation-error first guess `[τ, k]`.
    pub(crate) first_guess: [f64; 2],
    /// RMS of the output-error residuals.
    pub(crate) rms: f64,
    /// The model's prediction at each sample.
    pub(crate) predicted: Vec<f64>,
    /// Reciprocal condition number of the normalised information matrix.
    pub(crate) rcond: f64,
}

/// Simulates the axis from `x0` for parameters `(tau, k)`, and the
/// sensitivities of the output to `(τ, k, x₀)`.
fn simulate(d: &AxisData<'_>, tau: f64, k: f64, x0: f64, x: &mut [f64], s: &mut [[f64; 3]]) {
    x[0] = x0;
    s[0] = [0.0, 0.0, 1.0];
    for i in 0..d.t.len() - 1 {
        let h = d.t[i + 1] - d.t[i];
        let a = (-h / tau).exp();
        let da_dtau = a * h / (tau * tau);
        let xi = x[i];
        x[i + 1] = a * xi + (1.0 - a) * k * d.u[i];
        let si = s[i];
        s[i + 1] = [
            a * si[0] + da_dtau * (xi - k * d.u[i]),
            a * si[1] + (1.0 - a) * d.u[i],
            a * si[2],
        ];
    }
}

/// Sum of squared residuals.
fn cost(y: &[f64], x: &[f64]) -> f64 {
    y.iter().zip(x).map(|(y, x)| (y - x) * (y - x)).sum()
}

/// Solves the symmetric positive definite `n × n` system `a x = b` (n ≤ 3) by
/// Cholesky; `None` if `a` is not positive definite.
fn solve_spd<const N: usize>(a: &[[f64; N]; N], b: &[f64; N]) -> Option<[f64; N]> {
    let mut l = [[0.0; N]; N];
    for i in 0..N {
        for j in 0..=i {
            let mut sum = a[i][j];
            for p in 0..j {
                sum -= l[i][p] * l[j][p];
            }
            if i == j {
                if sum.is_nan() || sum <= 0.0 {
                    return None;
                }
                l[i][i] = sum.sqrt();
            } else {
                l[i][j] = sum / l[j][j];
            }
        }
    }
    let mut z = [0.0; N];
    for i in 0..N {
        let mut sum = b[i];
        for p in 0..i {
            sum -= l[i][p] * z[p];
        }
        z[i] = sum / l[i][i];
    }
    let mut x = [0.0; N];
    for i in (0..N).rev() {
        let mut sum = z[i];
        for p in i + 1..N {
            sum -= l[p][i] * x[p];
        }
        x[i] = sum / l[i][i];
    }
    Some(x)
}

/// The inverse of a symmetric positive definite matrix, column by column.
fn inverse_spd<const N: usize>(a: &[[f64; N]; N]) -> Option<[[f64; N]; N]> {
    let mut inv = [[0.0; N]; N];
    for j in 0..N {
        let mut e = [0.0; N];
        e[j] = 1.0;
        let col = solve_spd(a, &e)?;
        for i in 0..N {
            inv[i][j] = col[i];
        }
    }
    Some(inv)
}

/// Reciprocal condition number (smallest over largest eigenvalue) of the
/// symmetric positive semi-definite `a` after scaling to unit diagonal, by
/// Jacobi rotations.
pub(crate) fn rcond<const N: usize>(a: &[[f64; N]; N]) -> f64 {
    let mut m = *a;
    let d: Vec<f64> = (0..N).map(|i| m[i][i].sqrt()).collect();
    if d.iter().any(|x| x.is_nan() || *x <= 0.0) {
        return 0.0;
    }
    for i in 0..N {
        for j in 0..N {
            m[i][j] /= d[i] * d[j];
        }
    }
    for _ in 0..50 {
        let mut off = 0.0;
        for p in 0..N {
            for q in p + 1..N {
                off += m[p][q] * m[p][q];
            }
        }
        if off < 1e-30 {
            break;
        }
        for p in 0..N {
            for q in p + 1..N {
                if m[p][q].abs() < 1e-300 {
                    continue;
                }
                let theta = (m[q][q] - m[p][p]) / (2.0 * m[p][q]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for r in 0..N {
                    let (mrp, mrq) = (m[r][p], m[r][q]);
                    m[r][p] = c * mrp - s * mrq;
                    m[r][q] = s * mrp + c * mrq;
                }
                for r in 0..N {
                    let (mpr, mqr) = (m[p][r], m[q][r]);
                    m[p][r] = c * mpr - s * mqr;
                    m[q][r] = s * mpr + c * mqr;
                }
            }
        }
    }
    let eig: Vec<f64> = (0..N).map(|i| m[i][i]).collect();
    let max = eig.iter().copied().fold(0.0_f64, f64::max);
    let min = eig.iter().copied().fold(f64::INFINITY, f64::min);
    if max > 0.0 { (min / max).max(0.0) } else { 0.0 }
}

/// Equation-error first guess from the integral of `τ ẋ + x = k u` over
/// windows of [`WINDOW`] samples: `∫x = k ∫u − τ Δx`, least squares in
/// `(τ, k)` (no numerical differentiation of the noisy output). Also returns
/// the reciprocal condition number of the regressor.
pub(crate) fn equation_error(d: &AxisData<'_>, fixed_gain: bool) -> ([f64; 2], f64) {
    let n = d.t.len();
    let mut g = [[0.0; 2]; 2];
    let mut rhs = [0.0; 2];
    let mut start = 0;
    while start + WINDOW < n {
        let end = start + WINDOW;
        let (mut ix, mut iu) = (0.0, 0.0);
        for i in start..end {
            let h = d.t[i + 1] - d.t[i];
            ix += 0.5 * h * (d.y[i] + d.y[i + 1]);
            iu += h * d.u[i];
        }
        let dx = d.y[end] - d.y[start];
        // Unknowns [τ, k]: −Δx τ + ∫u k = ∫x.
        let row = [-dx, iu];
        for p in 0..2 {
            for q in 0..2 {
                g[p][q] += row[p] * row[q];
            }
            rhs[p] += row[p] * ix;
        }
        start = end;
    }
    if fixed_gain {
        // −Δx τ = ∫x − ∫u.
        let tau = (rhs[0] - g[0][1]) / g[0][0];
        return ([tau, 1.0], if g[0][0] > 0.0 { 1.0 } else { 0.0 });
    }
    let rc = rcond(&g);
    let theta = solve_spd(&g, &rhs).unwrap_or([f64::NAN; 2]);
    (theta, rc)
}

/// Fits the axis: equation-error guess, then output-error Levenberg–Marquardt
/// on `(τ, k, x₀)` (`k` fixed at 1 when `fixed_gain`). `h_min` is the
/// smallest sample spacing, used to fall back when the first guess is not
/// physical.
pub(crate) fn fit(d: &AxisData<'_>, fixed_gain: bool) -> AxisFit {
    let n = d.t.len();
    let (guess, _) = equation_error(d, fixed_gain);
    let span = d.t[n - 1] - d.t[0];
    let h = span / (n - 1) as f64;
    let mut tau = if guess[0].is_finite() && guess[0] > 0.0 && guess[0] < span {
        guess[0]
    } else {
        10.0 * h
    };
    let mut k = if fixed_gain {
        1.0
    } else if guess[1].is_finite() && guess[1] != 0.0 {
        guess[1]
    } else {
        1.0
    };
    let mut x0 = d.y[0];
    let mut x = vec![0.0; n];
    let mut s = vec![[0.0; 3]; n];
    let mut x_try = vec![0.0; n];
    let mut s_try = vec![[0.0; 3]; n];
    simulate(d, tau, k, x0, &mut x, &mut s);
    let mut c = cost(d.y, &x);
    let mut lambda = 1e-3;
    // Free parameters: [τ, k, x₀] or [τ, x₀].
    let free: &[usize] = if fixed_gain { &[0, 2] } else { &[0, 1, 2] };
    for _ in 0..MAX_ITER {
        let mut jtj = [[0.0; 3]; 3];
        let mut jtr = [0.0; 3];
        for i in 0..n {
            let r = d.y[i] - x[i];
            for (p, &fp) in free.iter().enumerate() {
                jtr[p] += s[i][fp] * r;
                for (q, &fq) in free.iter().enumerate() {
                    jtj[p][q] += s[i][fp] * s[i][fq];
                }
            }
        }
        let mut improved = false;
        for _ in 0..30 {
            let step = if fixed_gain {
                let a = [
                    [jtj[0][0] * (1.0 + lambda), jtj[0][1]],
                    [jtj[1][0], jtj[1][1] * (1.0 + lambda)],
                ];
                solve_spd(&a, &[jtr[0], jtr[1]]).map(|d| [d[0], 0.0, d[1]])
            } else {
                let mut a = jtj;
                for (p, row) in a.iter_mut().enumerate() {
                    row[p] *= 1.0 + lambda;
                }
                solve_spd(&a, &jtr)
            };
            let Some(step) = step else {
                lambda *= 10.0;
                continue;
            };
            let (t2, k2, x2) = (tau + step[0], k + step[1], x0 + step[2]);
            if t2 <= 0.0 || !t2.is_finite() || !k2.is_finite() {
                lambda *= 10.0;
                continue;
            }
            simulate(d, t2, k2, x2, &mut x_try, &mut s_try);
            let c2 = cost(d.y, &x_try);
            if c2 <= c {
                let rel = (c - c2) / c.max(f64::MIN_POSITIVE);
                (tau, k, x0, c) = (t2, k2, x2, c2);
                std::mem::swap(&mut x, &mut x_try);
                std::mem::swap(&mut s, &mut s_try);
                lambda = (lambda / 10.0).max(1e-12);
                improved = rel > 1e-14;
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    // Covariance σ² (JᵀJ)⁻¹ at the optimum.
    let mut jtj = [[0.0; 3]; 3];
    for si in &s {
        for p in 0..3 {
            for q in 0..3 {
                jtj[p][q] += si[p] * si[q];
            }
        }
    }
    let dof = n.saturating_sub(free.len()).max(1) as f64;
    let sigma2 = c / dof;
    let mut cov = [[f64::INFINITY; 2]; 2];
    let rc;
    if fixed_gain {
        let a = [[jtj[0][0], jtj[0][2]], [jtj[2][0], jtj[2][2]]];
        rc = rcond(&a);
        if let Some(inv) = inverse_spd(&a) {
            cov = [[sigma2 * inv[0][0], 0.0], [0.0, 0.0]];
        }
    } else {
        rc = rcond(&jtj);
        if let Some(inv) = inverse_spd(&jtj) {
            cov = [
                [sigma2 * inv[0][0], sigma2 * inv[0][1]],
                [sigma2 * inv[1][0], sigma2 * inv[1][1]],
            ];
        }
    }
    AxisFit {
        theta: [tau, k],
        cov,
        x0,
        first_guess: guess,
        rms: (c / n as f64).sqrt(),
        predicted: x,
        rcond: rc,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cholesky_solves_and_inverts() {
        let a = [[4.0, 1.0, 0.5], [1.0, 3.0, 0.2], [0.5, 0.2, 2.0]];
        let b = [1.0, 2.0, 3.0];
        let x = solve_spd(&a, &b).expect("SPD");
        for i in 0..3 {
            let r: f64 = (0..3).map(|j| a[i][j] * x[j]).sum();
            assert!((r - b[i]).abs() < 1e-12);
        }
        assert!(solve_spd(&[[1.0, 2.0], [2.0, 1.0]], &[1.0, 1.0]).is_none());
    }

    #[test]
    fn rcond_of_known_matrices() {
        assert!((rcond(&[[2.0, 0.0], [0.0, 5.0]]) - 1.0).abs() < 1e-12);
        // Unit diagonal, off-diagonal 0.5: eigenvalues 1.5 and 0.5.
        assert!((rcond(&[[1.0, 0.5], [0.5, 1.0]]) - 1.0 / 3.0).abs() < 1e-12);
        assert_eq!(rcond(&[[1.0, 0.0], [0.0, 0.0]]), 0.0);
    }

    #[test]
    fn noiseless_axis_is_recovered_exactly() {
        let n = 2000;
        let t: Vec<f64> = (0..n).map(|i| i as f64 * 0.01).collect();
        let u: Vec<f64> = t
            .iter()
            .map(|t| (1.3 * t).sin() + 0.5 * (4.1 * t).sin().signum())
            .collect();
        let (tau, k, x0) = (0.15, 1.0 / 180.0, 0.01);
        let mut y = vec![0.0; n];
        let mut s = vec![[0.0; 3]; n];
        let d = AxisData {
            t: &t,
            u: &u,
            y: &[],
        };
        simulate(&d, tau, k, x0, &mut y, &mut s);
        let f = fit(&AxisData { y: &y, ..d }, false);
        assert!((f.theta[0] - tau).abs() < 1e-8 * tau, "{:?}", f.theta);
        assert!((f.theta[1] - k).abs() < 1e-8 * k, "{:?}", f.theta);
        assert!((f.x0 - x0).abs() < 1e-9);
        assert!(f.rms < 1e-10);
        // The integral first guess is exact up to the trapezoid rule.
        assert!(
            (f.first_guess[0] - tau).abs() < 0.02 * tau,
            "{:?}",
            f.first_guess
        );
    }
}
