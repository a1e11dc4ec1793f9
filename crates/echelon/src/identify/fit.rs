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
//! The output-error model holds the input between samples (zero-order hold,
//! as a sampled controller applies it: `x⁺ = a x + (1 − a) k u` with
//! `a = e^{−h/τ}`, exact for such a plant whatever the sample spacing) or
//! interpolates it linearly (`x⁺ = a x + (1 − a) k u + k Δu b`,
//! `b = 1 − (τ/h)(1 − a)`, exact for a ramp); [`fit`] decides which the log
//! supports. With the input's own hold grid (`AxisData::hold`) it is
//! integrated through every switch. With the running integrals of the input
//! and the output ([`fit_integral`]) no assumption on the input between
//! samples is needed at all.

// Small dense linear algebra (n ≤ 3) reads best with explicit indices.
#![allow(clippy::needless_range_loop)]

mod bag;
mod integral;
mod limited;
mod linalg;
mod residuals;
pub(crate) use bag::{BagData, BagFit, fit_bag};
pub(crate) use integral::{AxisIntegrals, fit_integral};
pub(crate) use limited::{LimitedFit, fit_limited};
pub(crate) use linalg::rcond;
use linalg::{inverse_spd, least_squares, solve_spd};

use crate::lm;
pub(crate) use residuals::{
    ljung_box, ljung_box_segmented, noise_from_differences, scan, transients,
};

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
    /// The input's own zero-order hold (switch times, values), when known
    /// apart from the samples: the output error is then integrated on it.
    pub(crate) hold: Option<(&'a [f64], &'a [f64])>,
}

/// The grid the output-error model is integrated on: the sample times and,
/// with a hold, its switch times between them; the input held over each
/// step, and where each sample sits on the grid.
struct Grid {
    t: Vec<f64>,
    u: Vec<f64>,
    at: Vec<usize>,
}

impl Grid {
    fn new(d: &AxisData<'_>) -> Grid {
        let Some((ht, hu)) = d.hold else {
            return Grid {
                t: d.t.to_vec(),
                u: d.u.to_vec(),
                at: (0..d.t.len()).collect(),
            };
        };
        let n = d.t.len();
        let mut g = Grid {
            t: Vec::with_capacity(n + ht.len()),
            u: Vec::with_capacity(n + ht.len()),
            at: Vec::with_capacity(n),
        };
        // The hold's value at time t: the last switch at or before it.
        let value = |t: f64| -> f64 {
            let j = ht.partition_point(|s| *s <= t);
            hu[j.saturating_sub(1)]
        };
        let mut j = ht.partition_point(|s| *s <= d.t[0]);
        for k in 0..n {
            g.at.push(g.t.len());
            g.t.push(d.t[k]);
            g.u.push(value(d.t[k]));
            if k + 1 < n {
                while j < ht.len() && ht[j] < d.t[k + 1] {
                    if ht[j] > d.t[k] {
                        g.t.push(ht[j]);
                        g.u.push(hu[j]);
                    }
                    j += 1;
                }
            }
        }
        g
    }
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
    /// Set when the inputs between samples were unknown ([`fit`]).
    pub(crate) between: Option<Between>,
    /// The segment of each sample when the fit gave each segment its own
    /// offset (the rate-limited fit, [`fit_limited`]); its residuals then
    /// sum to zero over each segment.
    pub(crate) segments: Option<Vec<usize>>,
}

/// Simulates the axis on `g` from `x0` for parameters `(tau, k)`, and the
/// sensitivities of the output to `(τ, k, x₀)`, at the samples.
///
/// With `foh` the input is instead interpolated linearly from each grid
/// point's value to the next's (first-order hold), exactly integrated.
#[allow(clippy::too_many_arguments)]
fn simulate(g: &Grid, foh: bool, tau: f64, k: f64, x0: f64, x: &mut [f64], s: &mut [[f64; 3]]) {
    let (mut xi, mut si) = (x0, [0.0, 0.0, 1.0]);
    let mut next = 0;
    for i in 0..g.t.len() {
        if g.at.get(next) == Some(&i) {
            x[next] = xi;
            s[next] = si;
            next += 1;
        }
        if i + 1 == g.t.len() {
            break;
        }
        let h = g.t[i + 1] - g.t[i];
        let a = (-h / tau).exp();
        let da_dtau = a * h / (tau * tau);
        // The ramp's share: x⁺ gains k Δu b, b = 1 − (τ/h)(1 − a).
        let du = if foh { g.u[i + 1] - g.u[i] } else { 0.0 };
        let b = 1.0 - tau / h * (1.0 - a);
        let db_dtau = a / tau - (1.0 - a) / h;
        si = [
            a * si[0] + da_dtau * (xi - k * g.u[i]) + k * du * db_dtau,
            a * si[1] + (1.0 - a) * g.u[i] + du * b,
            a * si[2],
        ];
        xi = a * xi + (1.0 - a) * k * g.u[i] + k * du * b;
    }
}

/// Sum of squared residuals.
fn cost(y: &[f64], x: &[f64]) -> f64 {
    y.iter().zip(x).map(|(y, x)| (y - x) * (y - x)).sum()
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
pub(crate) fn fit(d: &AxisData<'_>, fixed_gain: bool, slower_than_hold: bool) -> AxisFit {
    let held = fit_with(d, fixed_gain, false);
    if d.hold.is_some() {
        return held;
    }
    if slower_than_hold {
        return unknown_between(d, fixed_gain, held);
    }
    // The log has the inputs' values at the samples only. Held between
    // samples (a sampled controller logged at its period) or varying (a
    // continuous-time one, or logged slower than it runs)? Fit both a hold
    // and a linear interpolation: unless the hold fits significantly better,
    // the interpolated fit is taken and the difference between the two is
    // added to its covariance (the input between samples is unknown).
    let ramp = fit_with(d, fixed_gain, true);
    let n = d.t.len();
    let dof = n.saturating_sub(if fixed_gain { 2 } else { 3 }).max(1) as f64;
    let (cz, cf) = (held.rms.powi(2) * n as f64, ramp.rms.powi(2) * n as f64);
    let sigma2 = cz.min(cf) / dof;
    let hold_fits_better = cf - cz > CHI2_1_999 * sigma2;
    if !hold_fits_better && ramp.theta.iter().all(|x| x.is_finite()) {
        let mut f = ramp;
        widen(&mut f, held.theta);
        f.between = Some(Between {
            held: held.theta,
            cost_ratio: cz / cf.max(f64::MIN_POSITIVE),
        });
        return f;
    }
    held
}

/// Adds to `f`'s covariance the outer product of its distance to `other`
/// (another fit of the same axis under another assumption on the input).
fn widen(f: &mut AxisFit, other: [f64; 2]) {
    let delta = [f.theta[0] - other[0], f.theta[1] - other[1]];
    for p in 0..2 {
        for q in 0..2 {
            f.cov[p][q] += delta[p] * delta[q];
        }
    }
}

/// The inputs between samples are unknown and not held over them (the log
/// is slower than the plant's input hold): the ramp's fit, with the spread
/// of the forward hold's and the backward hold's (each sampled value held
/// over the interval before it) around it joined to its covariance.
fn unknown_between(d: &AxisData<'_>, fixed_gain: bool, held: AxisFit) -> AxisFit {
    let n = d.t.len();
    let ramp = fit_with(d, fixed_gain, true);
    let ahead: Vec<f64> = (0..n).map(|i| d.u[(i + 1).min(n - 1)]).collect();
    let back = fit_with(
        &AxisData {
            u: &ahead,
            hold: None,
            ..*d
        },
        fixed_gain,
        false,
    );
    let (cz, cf) = (held.rms.powi(2), ramp.rms.powi(2));
    let mut f = ramp;
    for other in [held.theta, back.theta] {
        if other.iter().all(|x| x.is_finite()) {
            widen(&mut f, other);
        } else {
            // A variant that does not fit at all: nothing is known.
            f.cov = [[f64::INFINITY; 2]; 2];
        }
    }
    f.between = Some(Between {
        held: held.theta,
        cost_ratio: cz / cf.max(f64::MIN_POSITIVE),
    });
    f
}

/// The 95 % quantile of χ² with one degree of freedom.
const CHI2_1_95: f64 = 3.841;
/// The 99.9 % quantile of χ² with one degree of freedom.
const CHI2_1_999: f64 = 10.828;

/// When the inputs between samples are unknown and the fit interpolated
/// them: the held-input fit `[τ, k]` whose difference was added to the
/// covariance, and the held fit's cost over the interpolated one's.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Between {
    pub(crate) held: [f64; 2],
    pub(crate) cost_ratio: f64,
}

/// One axis's output-error fit: the data, and the simulated output and its
/// sensitivities to `(τ, k, x₀)` at the current point and at the last trial.
struct Axis<'a> {
    grid: &'a Grid,
    foh: bool,
    y: &'a [f64],
    x: Vec<f64>,
    s: Vec<[f64; 3]>,
    x_try: Vec<f64>,
    s_try: Vec<[f64; 3]>,
}

/// [`Axis`] as a least-squares problem in the `N` parameters `free` (indices
/// into `(τ, k, x₀)`; `k` is 1 when not free).
struct Free<'a, 'b, const N: usize> {
    axis: &'b mut Axis<'a>,
    free: [usize; N],
}

impl<const N: usize> lm::LeastSquares<N> for Free<'_, '_, N> {
    fn normal_equations(&self, _: &[f64; N]) -> ([[f64; N]; N], [f64; N]) {
        let Axis { y, x, s, .. } = &*self.axis;
        let mut jtj = [[0.0; N]; N];
        let mut jtr = [0.0; N];
        for i in 0..x.len() {
            let r = y[i] - x[i];
            for (p, &fp) in self.free.iter().enumerate() {
                jtr[p] += s[i][fp] * r;
                for (q, &fq) in self.free.iter().enumerate() {
                    jtj[p][q] += s[i][fp] * s[i][fq];
                }
            }
        }
        (jtj, jtr)
    }

    fn trial(&mut self, p: &[f64; N]) -> Option<f64> {
        let mut full = [0.0, 1.0, 0.0];
        for (&f, &v) in self.free.iter().zip(p) {
            full[f] = v;
        }
        let [tau, k, x0] = full;
        if tau <= 0.0 || !tau.is_finite() || !k.is_finite() {
            return None;
        }
        let a = &mut *self.axis;
        simulate(a.grid, a.foh, tau, k, x0, &mut a.x_try, &mut a.s_try);
        Some(cost(a.y, &a.x_try))
    }

    fn accept(&mut self) {
        let a = &mut *self.axis;
        std::mem::swap(&mut a.x, &mut a.x_try);
        std::mem::swap(&mut a.s, &mut a.s_try);
    }
}

fn fit_with(d: &AxisData<'_>, fixed_gain: bool, foh: bool) -> AxisFit {
    let n = d.t.len();
    let (guess, _) = equation_error(d, fixed_gain);
    let span = d.t[n - 1] - d.t[0];
    let h = span / (n - 1) as f64;
    let tau = if guess[0].is_finite() && guess[0] > 0.0 && guess[0] < span {
        guess[0]
    } else {
        10.0 * h
    };
    let k = if fixed_gain {
        1.0
    } else if guess[1].is_finite() && guess[1] != 0.0 {
        guess[1]
    } else {
        1.0
    };
    let x0 = d.y[0];
    let grid = Grid::new(d);
    let mut axis = Axis {
        grid: &grid,
        foh,
        y: d.y,
        x: vec![0.0; n],
        s: vec![[0.0; 3]; n],
        x_try: vec![0.0; n],
        s_try: vec![[0.0; 3]; n],
    };
    simulate(&grid, foh, tau, k, x0, &mut axis.x, &mut axis.s);
    let c = cost(d.y, &axis.x);
    // Free parameters: [τ, k, x₀] or [τ, x₀].
    let (n_free, [tau, k, x0], c) = if fixed_gain {
        let m = lm::minimise(
            &mut Free {
                axis: &mut axis,
                free: [0, 2],
            },
            [tau, x0],
            c,
            MAX_ITER,
        );
        (2, [m.p[0], 1.0, m.p[1]], m.cost)
    } else {
        let m = lm::minimise(
            &mut Free {
                axis: &mut axis,
                free: [0, 1, 2],
            },
            [tau, k, x0],
            c,
            MAX_ITER,
        );
        (3, m.p, m.cost)
    };
    let Axis { x, s, .. } = axis;
    // Covariance σ² (JᵀJ)⁻¹ at the optimum.
    let mut jtj = [[0.0; 3]; 3];
    for si in &s {
        for p in 0..3 {
            for q in 0..3 {
                jtj[p][q] += si[p] * si[q];
            }
        }
    }
    let dof = n.saturating_sub(n_free).max(1) as f64;
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
        between: None,
        segments: None,
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
            hold: None,
        };
        simulate(&Grid::new(&d), false, tau, k, x0, &mut y, &mut s);
        let f = fit(&AxisData { y: &y, ..d }, false, false);
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
