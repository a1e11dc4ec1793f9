//! A velocity base from a ROS 2 bag: its lags, acceleration limits and the
//! dead time between a command's publication and the odometry's response,
//! fitted on the command messages' own zero-order hold and the odometry's
//! sample grid (no integrals: a bag has none).
//!
//! Each axis is the base's (`crate::base`, per-axis limit as
//! `diff_drive_controller`'s speed limiter):
//!
//! ```text
//! ẋ(t) = clamp((u(t − d) − x(t))/τ, −a, a)
//! ```
//!
//! `u` the command hold, `d` the dead time (one for both axes: one transport
//! path), `τ ≥ 0` the lag (0: the velocity follows the command at once),
//! `a` the limit (∞: none; fitted as `b = 1/a ≥ 0`). Between two events
//! (samples, or command switches shifted by `d`) the input is constant and
//! the axis is integrated exactly: on the limit at rate `±a` until the error
//! `|u − x|` comes down to `aτ`, then the lag's exponential ([`step`]).
//!
//! The fit, in three stages:
//!
//! 1. **dead time**: the lag alone (`τ, x₀` per axis) fitted for each `d`
//!    on a [`DELAY_STEP`] grid up to [`MAX_DELAY`], warm-started from the
//!    previous `d`; the `d` that minimises the profile likelihood
//!    `Σ_axis ln(cost)` (each axis its own noise) starts a joint fit of `d`
//!    and the lags ([`refine`]);
//! 2. **limit or lag, per axis**, at that `d`, unless the lag's residuals
//!    show no sign of a clamp on its fastest transients (the score test
//!    `super::transients` under [`SCORE_GATE`]): the lag alone against the lag
//!    with the rate clamp (`τ, b, x₀`, from eight starts: limits at and
//!    below the largest rate seen, the lag as fitted and half of it). The
//!    two models differ only where the clamp acts: a lag's response rate is
//!    proportional to the error, a limit's is constant while the error is
//!    large. The limit is kept when the likelihood-ratio statistic
//!    `n ln(cost_lag / cost_limit)` exceeds χ²₁'s 99.9 % quantile *and* the
//!    clamp held on at least [`MIN_RIDING`] odometry intervals (the
//!    commanded change exceeded what the response could follow over that
//!    many samples);
//! 3. **all together**: Levenberg–Marquardt over `d` and every axis's kept
//!    parameters, the residuals weighed by each axis's noise. Each variance
//!    is the larger of the model's `σ² (JᵀJ)⁻¹` and the sandwich
//!    `(JᵀJ)⁻¹ M (JᵀJ)⁻¹`, `M` the Newey–West sum of the scores `rᵢ Jᵢ`
//!    over a window of `3 τ + 0.1 s`: built from the residuals of the real
//!    sampling, it holds when the errors are not of one size (arrival jitter
//!    of the odometry makes errors in proportion to the response's slope)
//!    and when a command's timing error shifts a whole transient.
//!
//! An axis whose lag comes out below [`IDEAL_FRACTION`] of the odometry
//! period gets a bound instead ([`refine`], [`lag_bound`]).

// Small dense linear algebra reads best with explicit indices.
#![allow(clippy::needless_range_loop)]

use super::{AxisFit, CHI2_1_95, CHI2_1_999, equation_error};
use crate::lm;

mod guess;
mod joint;
mod scan;

use guess::{delay_grid, first_guess, largest_rate, median_period, shifted_average};
use joint::refine;
use scan::{delay_scan, lag_bound};

/// Largest dead time searched, s.
pub(crate) const MAX_DELAY: f64 = 0.25;
/// Spacing of the dead-time grid of the first stage, s.
pub(crate) const DELAY_STEP: f64 = 0.01;
/// Fewest odometry intervals the rate clamp must hold on for a limit to be
/// claimed.
pub(crate) const MIN_RIDING: usize = 10;
/// Below this score (standard errors) of the lag's residuals against a rate
/// limit (`super::transients`), no limit is searched for.
const SCORE_GATE: f64 = 2.0;
/// A lag below this fraction of the odometry period is not resolved: its
/// bound is given ([`lag_bound`]).
pub(crate) const IDEAL_FRACTION: f64 = 0.1;
/// Levenberg–Marquardt iterations per fit at most.
const MAX_ITER: usize = 100;

/// The joint parameter vector: `[d, τ_v, b_v, x0_v, τ_ω, b_ω, x0_ω]`.
const P: usize = 7;
/// Index of an axis's `τ`, `b`, `x₀` in the joint vector.
const fn tau_at(axis: usize) -> usize {
    1 + 3 * axis
}

/// A bag's data: the odometry's sample times and measured velocities, and
/// the command hold (switch times on the same clock, values per axis).
#[derive(Debug, Clone, Copy)]
pub(crate) struct BagData<'a> {
    pub(crate) t: &'a [f64],
    pub(crate) y: [&'a [f64]; 2],
    pub(crate) hold_t: &'a [f64],
    pub(crate) hold_u: [&'a [f64]; 2],
}

/// One axis of the bag fit.
#[derive(Debug, Clone)]
pub(crate) struct BagAxis {
    /// The lag as the other fits give it (`[τ, 1]`, covariance, prediction,
    /// residual RMS).
    pub(crate) fit: AxisFit,
    /// The limit `a` and its variance, when the evidence kept it.
    pub(crate) limit: Option<(f64, f64)>,
    /// Odometry intervals the clamp held on, in the limited model.
    pub(crate) riding: usize,
    /// Why no limit was kept (evidence of the test), when none was.
    pub(crate) no_limit: Option<String>,
    /// The lag's 95 % upper bound when it came out far below the odometry
    /// period ([`IDEAL_FRACTION`]): the samples do not resolve it, and `τ`
    /// was held (infinite when even a lag of two periods fits as well).
    pub(crate) bound: Option<f64>,
    /// The command hold shifted by the dead time, averaged over each
    /// odometry interval (what the residual checks take as the input).
    pub(crate) u_shifted: Vec<f64>,
}

/// The bag fit: both axes and the dead time.
#[derive(Debug, Clone)]
pub(crate) struct BagFit {
    pub(crate) axes: [BagAxis; 2],
    /// The dead time and its variance, s, s².
    pub(crate) dead_time: (f64, f64),
    /// The median odometry period, s.
    pub(crate) period: f64,
}

/// Integrates one axis over `h` from `x` under the constant input `u`:
/// returns the new value and the time spent on the limit.
pub(crate) fn step(x: f64, u: f64, h: f64, tau: f64, b: f64) -> (f64, f64) {
    let e = u - x;
    let mut x = x;
    let mut left = h;
    let mut ride = 0.0;
    if b > 0.0 {
        // The error below which the lag's rate |e|/τ is within the limit.
        let edge = tau / b;
        if e.abs() > edge {
            let t1 = (e.abs() - edge) * b;
            if h <= t1 {
                return (x + e.signum() * h / b, h);
            }
            x = u - e.signum() * edge;
            left = h - t1;
            ride = t1;
        }
    }
    let next = if tau > 0.0 {
        u - (u - x) * (-left / tau).exp()
    } else {
        u
    };
    (next, ride)
}

/// Simulates axis `axis` of `p` at the sample times into `out`; returns the
/// odometry intervals during which the clamp held on for at least half of
/// the interval.
fn simulate(d: &BagData<'_>, axis: usize, p: &[f64; P], out: &mut [f64]) -> usize {
    let (delay, tau, b, x0) = (
        p[0],
        p[tau_at(axis)],
        p[tau_at(axis) + 1],
        p[tau_at(axis) + 2],
    );
    let (ht, hu) = (d.hold_t, d.hold_u[axis]);
    let t = d.t;
    let mut j = ht.partition_point(|s| *s + delay <= t[0]).saturating_sub(1);
    let (mut x, mut s) = (x0, t[0]);
    out[0] = x;
    let mut riding = 0;
    for k in 1..t.len() {
        let mut ride = 0.0;
        while j + 1 < ht.len() && ht[j + 1] + delay < t[k] {
            let next = ht[j + 1] + delay;
            let (nx, r) = step(x, hu[j], next - s, tau, b);
            (x, s, ride) = (nx, next, ride + r);
            j += 1;
        }
        let (nx, r) = step(x, hu[j], t[k] - s, tau, b);
        (x, s) = (nx, t[k]);
        ride += r;
        out[k] = x;
        if ride >= 0.5 * (t[k] - t[k - 1]) {
            riding += 1;
        }
    }
    riding
}

/// A least-squares problem over the free parameters `free` of the joint
/// vector (the others held at `base`), on the axes `axes`, each axis's
/// residuals divided by `scale[axis]`.
struct Problem<'a, 'b, const N: usize> {
    d: &'b BagData<'a>,
    base: [f64; P],
    free: [usize; N],
    axes: &'b [usize],
    scale: [f64; 2],
}

impl<const N: usize> Problem<'_, '_, N> {
    fn full(&self, p: &[f64; N]) -> [f64; P] {
        let mut full = self.base;
        for (&i, &v) in self.free.iter().zip(p) {
            full[i] = v;
        }
        full
    }

    /// The weighted residuals of `full`, axis after axis.
    fn residuals(&self, full: &[f64; P]) -> Vec<f64> {
        let n = self.d.t.len();
        let mut r = Vec::with_capacity(n * self.axes.len());
        let mut x = vec![0.0; n];
        for &a in self.axes {
            simulate(self.d, a, full, &mut x);
            r.extend(
                self.d.y[a]
                    .iter()
                    .zip(&x)
                    .map(|(y, x)| (y - x) / self.scale[a]),
            );
        }
        r
    }

    /// The residuals at `p` and their Jacobian with respect to the free
    /// parameters (of the model, so the negative of the residuals'), by
    /// forward differences.
    fn jacobian(&self, p: &[f64; N]) -> (Vec<f64>, Vec<[f64; N]>) {
        let r = self.residuals(&self.full(p));
        let mut j = vec![[0.0; N]; r.len()];
        for q in 0..N {
            let i = self.free[q];
            let h = match i {
                0 => 1e-6,
                _ => 1e-6 * p[q].abs().max(1e-3),
            };
            let mut pq = *p;
            pq[q] += h;
            let rq = self.residuals(&self.full(&pq));
            for (row, (a, b)) in j.iter_mut().zip(r.iter().zip(&rq)) {
                row[q] = (a - b) / h;
            }
        }
        (r, j)
    }
}

impl<const N: usize> lm::LeastSquares<N> for Problem<'_, '_, N> {
    fn normal_equations(&self, p: &[f64; N]) -> ([[f64; N]; N], [f64; N]) {
        let (r, j) = self.jacobian(p);
        let mut jtj = [[0.0; N]; N];
        let mut jtr = [0.0; N];
        for (ri, ji) in r.iter().zip(&j) {
            for a in 0..N {
                jtr[a] += ji[a] * ri;
                for b in 0..N {
                    jtj[a][b] += ji[a] * ji[b];
                }
            }
        }
        (jtj, jtr)
    }

    fn trial(&mut self, p: &[f64; N]) -> Option<f64> {
        let full = self.full(p);
        let physical = (0..2).all(|a| full[tau_at(a)] >= 0.0 && full[tau_at(a) + 1] >= 0.0)
            && full[0].abs() <= MAX_DELAY
            && full.iter().all(|x| x.is_finite());
        physical.then(|| self.residuals(&full).iter().map(|r| r * r).sum())
    }
}

/// Minimises `problem` from `p`: the parameters and the cost.
fn minimise<const N: usize>(problem: &mut Problem<'_, '_, N>, p: [f64; N]) -> ([f64; N], f64) {
    let c: f64 = problem
        .residuals(&problem.full(&p))
        .iter()
        .map(|r| r * r)
        .sum();
    let m = lm::minimise(problem, p, c, MAX_ITER);
    (m.p, m.cost)
}

/// Fits one axis at the delay and start `base`: the lag alone (`limit`
/// false) or with the clamp. Returns the joint vector and the cost.
fn fit_axis(d: &BagData<'_>, axis: usize, base: [f64; P], limit: bool) -> ([f64; P], f64) {
    let i = tau_at(axis);
    let axes = [axis];
    if limit {
        let mut pr = Problem {
            d,
            base,
            free: [i, i + 1, i + 2],
            axes: &axes,
            scale: [1.0; 2],
        };
        let (p, c) = minimise(&mut pr, [base[i], base[i + 1], base[i + 2]]);
        (pr.full(&p), c)
    } else {
        let mut base = base;
        base[i + 1] = 0.0;
        let mut pr = Problem {
            d,
            base,
            free: [i, i + 2],
            axes: &axes,
            scale: [1.0; 2],
        };
        let (p, c) = minimise(&mut pr, [base[i], base[i + 2]]);
        (pr.full(&p), c)
    }
}

/// Stage 2's answer for one axis: whether the limit was kept, the odometry
/// intervals the clamp held on, and why no limit was kept.
struct LimitChoice {
    kept: bool,
    riding: usize,
    no_limit: Option<String>,
}

/// The best of the limited fits of axis `a` from eight starts around the
/// lag-only fit `lag` and the largest rate `top` seen, when there is one.
fn best_limited(d: &BagData<'_>, a: usize, lag: [f64; P], top: f64) -> Option<([f64; P], f64)> {
    let i = tau_at(a);
    let mut limited: Option<([f64; P], f64)> = None;
    if top > 0.0 && top.is_finite() {
        // From limits at and below the largest rate seen (noise raises
        // it), and shorter lags than the lag alone took (a lag fitted
        // through clamped transients stretches): a clamp that never acts
        // from its start has no gradient to find it by.
        let starts = [1.0, 0.6, 0.35, 0.2]
            .into_iter()
            .flat_map(|f| [1.0, 0.5].map(|g| (f, g)));
        for (f, g) in starts {
            let mut start = lag;
            start[i + 1] = 1.0 / (f * top);
            start[i] = g * lag[i];
            let (q, c) = fit_axis(d, a, start, true);
            if limited.as_ref().is_none_or(|(_, s)| c < *s) {
                limited = Some((q, c));
            }
        }
    }
    limited
}

/// Stage 2 for one excited, resolved axis `a`: the lag alone against the lag
/// with the rate clamp (module docs), the kept parameters written into `p`
/// (`x`: scratch for a simulation).
fn limit_or_lag(d: &BagData<'_>, a: usize, p: &mut [f64; P], x: &mut [f64]) -> LimitChoice {
    let n = d.t.len();
    let i = tau_at(a);
    let (lag, c_lag) = fit_axis(d, a, *p, false);
    // The score test of the lag against a rate limit gates the search:
    // residuals with no sign of a clamp on the fastest transients need
    // no limited fit (most bases; it is the costly part).
    simulate(d, a, &lag, x);
    let r: Vec<f64> = d.y[a].iter().zip(&*x).map(|(y, x)| y - x).collect();
    let u = shifted_average(d, a, lag[0]);
    let (z, _, _) = super::transients(d.t, (&u, &*x, &r), (lag[i], 1.0), false);
    if z.abs() < SCORE_GATE {
        p[i..i + 3].copy_from_slice(&lag[i..i + 3]);
        return LimitChoice {
            kept: false,
            riding: 0,
            no_limit: Some(format!(
                "the lag's residuals show no sign of a rate limit on its fastest transients (score {z:.1} standard errors, below {SCORE_GATE})"
            )),
        };
    }
    let top = largest_rate(d.t, d.y[a]);
    let (q, c_lim) = best_limited(d, a, lag, top).unwrap_or((lag, c_lag));
    let lr = n as f64 * (c_lag / c_lim.max(f64::MIN_POSITIVE)).ln();
    let rides = if q[i + 1] > 0.0 {
        simulate(d, a, &q, x)
    } else {
        0
    };
    if lr > CHI2_1_999 && rides >= MIN_RIDING {
        p[i..i + 3].copy_from_slice(&q[i..i + 3]);
        return LimitChoice {
            kept: true,
            riding: rides,
            no_limit: None,
        };
    }
    p[i..i + 3].copy_from_slice(&lag[i..i + 3]);
    LimitChoice {
        kept: false,
        riding: rides,
        no_limit: Some(if lr <= CHI2_1_999 {
            format!(
                "a lag alone fits as well as a lag with a rate limit (likelihood ratio {:.1}, 99.9 % bound {CHI2_1_999:.1})",
                lr.max(0.0)
            )
        } else {
            format!(
                "the rate limit that fits best holds on {rides} odometry intervals, fewer than {MIN_RIDING}"
            )
        }),
    }
}

/// The joint fit of stage 3: the parameters, the covariance of the free
/// ones, the reciprocal condition number, the free parameters' indices.
struct Joint {
    p: [f64; P],
    cov: Vec<Vec<f64>>,
    rcond: f64,
    free: Vec<usize>,
}

impl Joint {
    /// The variance of joint parameter `k` (infinite when held).
    fn var(&self, k: usize) -> f64 {
        self.free
            .iter()
            .position(|f| *f == k)
            .map_or(f64::INFINITY, |q| self.cov[q][q])
    }

    /// Axis `a` of the joint fit (`bound`: its lag's bound, when unresolved;
    /// `choice`: stage 2's answer for it).
    fn axis(&self, d: &BagData<'_>, a: usize, bound: Option<f64>, choice: &LimitChoice) -> BagAxis {
        let (n, p) = (d.t.len(), &self.p);
        let i = tau_at(a);
        let mut predicted = vec![0.0; n];
        let rides = simulate(d, a, p, &mut predicted);
        let c: f64 = d.y[a]
            .iter()
            .zip(&predicted)
            .map(|(y, x)| (y - x).powi(2))
            .sum();
        // A held (unresolved) lag has no variance of its own: its bound
        // answers for it, or nothing does.
        let (tau, var_tau) = (
            p[i],
            if bound.is_some() {
                f64::INFINITY
            } else {
                self.var(i)
            },
        );
        let limit = choice.kept.then(|| {
            // a = 1/b: var a = var b / b⁴.
            let b = p[i + 1];
            (1.0 / b, self.var(i + 1) / b.powi(4))
        });
        BagAxis {
            fit: AxisFit {
                theta: [tau, 1.0],
                cov: [[var_tau, 0.0], [0.0, 0.0]],
                x0: p[i + 2],
                first_guess: [tau, 1.0],
                rms: (c / n as f64).sqrt(),
                predicted,
                rcond: self.rcond,
                between: None,
                segments: None,
            },
            limit,
            riding: if choice.kept { rides } else { choice.riding },
            no_limit: choice.no_limit.clone(),
            bound,
            u_shifted: shifted_average(d, a, p[0]),
        }
    }
}

/// Fits a velocity base to a bag (module docs).
pub(crate) fn fit_bag(d: &BagData<'_>) -> BagFit {
    let period = median_period(d.t);
    // Stage 1: the dead time on a grid, the lag alone.
    let mut p = delay_grid(d, first_guess(d));
    // An axis whose command never changes has no lag to fit (and would
    // make the information singular): only its offset.
    let excited: [bool; 2] = std::array::from_fn(|a| {
        let u = d.hold_u[a];
        u.iter().any(|x| (x - u[0]).abs() > 1e-12)
    });
    // Stage 1b: the dead time refined with the lags alone.
    let mut bound: [Option<f64>; 2] = [None, None];
    p = refine(d, p, [false; 2], &mut bound, excited, period).0;
    // Stage 2: limit or lag, per axis.
    let mut x = vec![0.0; d.t.len()];
    let choices: [LimitChoice; 2] = std::array::from_fn(|a| {
        if !excited[a] || bound[a].is_some() {
            return LimitChoice {
                kept: false,
                riding: 0,
                no_limit: Some("no lag resolved to fit it with".to_owned()),
            };
        }
        limit_or_lag(d, a, &mut p, &mut x)
    });
    // Stage 3: all together, each axis weighed by its noise.
    let kept = [choices[0].kept, choices[1].kept];
    let (p, cov, rcond, free) = refine(d, p, kept, &mut bound, excited, period);
    let joint = Joint {
        p,
        cov,
        rcond,
        free,
    };
    BagFit {
        axes: std::array::from_fn(|a| joint.axis(d, a, bound[a], &choices[a])),
        dead_time: (joint.p[0], joint.var(0)),
        period,
    }
}

#[cfg(test)]
mod tests;
