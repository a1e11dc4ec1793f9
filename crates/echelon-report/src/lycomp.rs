//! `L_Ycomp`: eq. 5 (exact) against eq. 6 (the paper's smooth fit), the
//! paper's Fig. 5, and a least-squares refit of eq. 6's `G`, `δ`, `ε` for any
//! `L_Xoff = λ`.
//!
//! # The fit criterion
//!
//! Eq. 5 is self-similar: `L_Ycomp(R_C; λ) = λ h(R_C/λ)`. [`refit`] minimises
//!
//! ```text
//! Σ_i w_i (eq6(R_i; G, δ, ε) − eq5(R_i; λ))²,   R_i uniform on (0, 3λ],
//! w_i = 1 where R_i ≤ λ, 0.1 beyond
//! ```
//!
//! (both equations are odd in `R_C`, so positive radii suffice). Inside
//! `|R_C| ≤ λ` the placement is forced (`L_Ycomp = R_C`) and the fit must follow
//! it; beyond, eq. 5 drops with infinite slope, which no smooth eq. 6 can
//! follow, so those points weigh less (unweighted least squares drifts to
//! degenerate fits, `G` in the hundreds with `ε → 0`). The criterion scales
//! with `λ`, so the optimum does too: `G, δ, ε = λ (0.4274, 0.9016, 1.4046)`
//! for every `λ` (tested), with a worst error to eq. 5 of `0.244 λ` at
//! `R_C = λ`.
//!
//! The paper's polynomials are not proportional to `λ`: they were fitted some
//! other, unpublished way, and no uniform, logarithmic or curvature-spaced
//! grid, weighted or not, that we tried reproduces them. The refit lands within
//! `0.5 λ` of the paper's curve everywhere for `λ ∈ [0.1, 0.9]` (closest at the
//! small and large ends), peaks near `(λ, λ)` as eq. 5 and the paper's fit do,
//! and its worst error is never larger than the paper's (0.122 m against
//! 0.230 m at `λ = 0.5`). Levenberg–Marquardt reaches the same optimum from
//! the paper's coefficients as from the generic start of [`refit`].

use echelon::lm;
use echelon::lycomp::{FitCoefficients, exact, fit_rc};

use crate::ReportError;
use crate::figure::{Axis, Figure, Panel, Stroke};

/// Weight of the points beyond `R_C = λ` in [`refit`].
pub const TAIL_WEIGHT: f64 = 0.1;
/// [`refit`] samples `R_C` on `(0, FIT_SPAN · λ]`.
pub const FIT_SPAN: f64 = 3.0;
/// [`largest_gap`] looks at `0 < |R_C| ≤ GAP_SPAN · λ`.
pub const GAP_SPAN: f64 = 20.0;
/// Number of `R_C` samples in [`refit`].
pub const FIT_POINTS: usize = 600;

/// Eq. 5 at radius `rc` (m) for `L_Xoff = lambda`, computed as
/// `λ h(R_C/λ)` (self-similar, see the module doc) so that no `λ²`
/// overflows or underflows, whatever the finite `λ > 0`.
pub fn eq5(rc: f64, lambda: f64) -> f64 {
    if rc == 0.0 {
        return 0.0;
    }
    lambda * exact(1.0, lambda / rc, 1.0)
}

/// `c` in units of `λ` (`c / λ`), or back (`c · λ` with `scale = λ`).
fn scaled(c: &FitCoefficients, scale: f64) -> FitCoefficients {
    FitCoefficients {
        g: c.g * scale,
        delta: c.delta * scale,
        epsilon: c.epsilon * scale,
    }
}

/// Where eq. 6 with `c` is farthest from eq. 5.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gap {
    /// `|eq6 − eq5|`, m.
    pub gap: f64,
    /// At this `|R_C|`, m.
    pub at: f64,
    /// RMS of `eq6 − eq5` over the same samples, m.
    pub rms: f64,
}

/// The largest gap between eq. 6 (`c`) and eq. 5 over `0 < |R_C| ≤ 20 λ` ([`GAP_SPAN`]),
/// sampled every `λ/2000` (the curves are odd, so `R_C > 0` covers both signs).
pub fn largest_gap(c: &FitCoefficients, lambda: f64) -> Gap {
    // In units of λ (the curves are self-similar), then back to metres: no
    // overflow for a huge λ, no underflow for a tiny one.
    let g = unit_gap(&scaled(c, 1.0 / lambda));
    Gap {
        gap: g.gap * lambda,
        at: g.at * lambda,
        rms: g.rms * lambda,
    }
}

/// [`largest_gap`] for `λ = 1`.
fn unit_gap(c: &FitCoefficients) -> Gap {
    let lambda = 1.0;
    let n = 40_000;
    let mut g = Gap {
        gap: 0.0,
        at: 0.0,
        rms: 0.0,
    };
    let mut sum = 0.0;
    for i in 1..=n {
        let rc = GAP_SPAN * lambda * i as f64 / n as f64;
        let d = fit_rc(rc, c) - eq5(rc, lambda);
        sum += d * d;
        if d.abs() > g.gap {
            g.gap = d.abs();
            g.at = rc;
        }
    }
    g.rms = (sum / n as f64).sqrt();
    g
}

/// Eq. 6 and its partial derivatives in `G`, `δ`, `ε` at `rc`.
fn eq6_with_gradient(rc: f64, [g, d, e]: [f64; 3]) -> (f64, [f64; 3]) {
    let (a, b, c) = (rc, rc - e, rc + e);
    let s = 2.0 * (a / d).atan() - (b / d).atan() - (c / d).atan();
    let f = 2.0 * g * s;
    let dd = 2.0 * g * (-2.0 * a / (d * d + a * a) + b / (d * d + b * b) + c / (d * d + c * c));
    let de = 2.0 * g * (d / (d * d + b * b) - d / (d * d + c * c));
    (f, [2.0 * s, dd, de])
}

/// The outcome of [`refit`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Refit {
    /// The fitted coefficients.
    pub coefficients: FitCoefficients,
    /// The weighted sum of squares it reached.
    pub cost: f64,
    /// Levenberg–Marquardt iterations used.
    pub iterations: usize,
}

/// The weighted least-squares cost of `c` (see the module doc).
pub fn fit_cost(c: &FitCoefficients, lambda: f64) -> f64 {
    weighted_cost(samples(lambda), |rc| fit_rc(rc, c))
}

/// `Σ w (eq6(R_C) − eq. 5)²` over the samples `(R_C, w, eq. 5)`.
fn weighted_cost(samples: impl Iterator<Item = (f64, f64, f64)>, eq6: impl Fn(f64) -> f64) -> f64 {
    samples
        .map(|(rc, w, y)| {
            let r = eq6(rc) - y;
            w * r * r
        })
        .sum()
}

fn samples(lambda: f64) -> impl Iterator<Item = (f64, f64, f64)> {
    (1..=FIT_POINTS).map(move |i| {
        let rc = FIT_SPAN * lambda * i as f64 / FIT_POINTS as f64;
        let w = if rc <= lambda { 1.0 } else { TAIL_WEIGHT };
        (rc, w, eq5(rc, lambda))
    })
}

/// Levenberg–Marquardt iterations [`refit_from`] runs at most.
const MAX_ITERATIONS: usize = 500;

/// Eq. 6's `(G, δ, ε)` against eq. 5 at the samples `(R_C, w, eq. 5)`.
struct Eq6Fit {
    pts: Vec<(f64, f64, f64)>,
}

impl Eq6Fit {
    fn cost(&self, p: [f64; 3]) -> f64 {
        weighted_cost(self.pts.iter().copied(), |rc| eq6_with_gradient(rc, p).0)
    }
}

impl lm::LeastSquares<3> for Eq6Fit {
    fn normal_equations(&self, &p: &[f64; 3]) -> ([[f64; 3]; 3], [f64; 3]) {
        let mut jtj = [[0.0; 3]; 3];
        let mut jtr = [0.0; 3];
        for &(rc, w, y) in &self.pts {
            let (f, grad) = eq6_with_gradient(rc, p);
            let r = y - f;
            for i in 0..3 {
                jtr[i] += w * grad[i] * r;
                for j in 0..3 {
                    jtj[i][j] += w * grad[i] * grad[j];
                }
            }
        }
        (jtj, jtr)
    }

    /// Eq. 6 needs `δ > 0`.
    fn trial(&mut self, &p: &[f64; 3]) -> Option<f64> {
        (p[1] > 0.0).then(|| self.cost(p))
    }
}

/// Refits eq. 6's `G`, `δ`, `ε` to eq. 5 for `L_Xoff = lambda` by
/// Levenberg–Marquardt from `start` (the module doc gives the criterion).
pub fn refit_from(lambda: f64, start: FitCoefficients) -> Result<Refit, ReportError> {
    if !(lambda.is_finite() && lambda > 0.0) {
        return Err(ReportError::Invalid(format!(
            "L_Xoff = {lambda} m: the fit needs a finite L_Xoff > 0"
        )));
    }
    // Fitted in units of λ (the optimum scales with λ, see the module doc),
    // then back to metres: the same fit for a λ whose square overflows or
    // underflows.
    let unit = scaled(&start, 1.0 / lambda);
    let mut problem = Eq6Fit {
        pts: samples(1.0).collect(),
    };
    let p = [unit.g, unit.delta, unit.epsilon];
    let cost = problem.cost(p);
    let lm::Minimum {
        p,
        cost,
        iterations,
    } = lm::minimise(&mut problem, p, cost, MAX_ITERATIONS);
    if !p.iter().all(|v| v.is_finite()) || p[1] <= 0.0 {
        return Err(ReportError::Invalid(format!(
            "the eq. 6 fit for L_Xoff = {lambda} m did not converge"
        )));
    }
    let coefficients = scaled(
        &FitCoefficients {
            g: p[0],
            delta: p[1],
            epsilon: p[2],
        },
        lambda,
    );
    if ![coefficients.g, coefficients.delta, coefficients.epsilon]
        .iter()
        .all(|v| v.is_finite())
        || coefficients.delta <= 0.0
    {
        return Err(ReportError::Invalid(format!(
            "L_Xoff = {lambda} m: the eq. 6 fit's G, δ, ε (≈ λ, 2λ, 3λ) do not fit in a number"
        )));
    }
    Ok(Refit {
        coefficients,
        // The cost of squared metres.
        cost: cost * lambda * lambda,
        iterations,
    })
}

/// [`refit_from`] a start of the right shape for any `λ`: `λ (0.3, 0.5, 1.5)`.
pub fn refit(lambda: f64) -> Result<Refit, ReportError> {
    refit_from(
        lambda,
        FitCoefficients {
            g: 0.3 * lambda,
            delta: 0.5 * lambda,
            epsilon: 1.5 * lambda,
        },
    )
}

/// The paper's Fig. 5 for `λ`: eq. 5 and eq. 6 (`fits`, each named) over
/// `|R_C| ≤ 6λ`, and each fit's error below.
pub fn figure(lambda: f64, fits: &[(&str, FitCoefficients)]) -> Figure {
    let span = 6.0 * lambda;
    let n = 2400;
    let rcs: Vec<f64> = (0..=n)
        .map(|i| -span + 2.0 * span * i as f64 / n as f64)
        .collect();
    let mut top = Panel::new(Axis::new("R_C", "m"), Axis::new("L_Ycomp", "m"))
        .titled(&format!("L_Xoff = {lambda} m"));
    top.line(
        "eq. 5 (exact)",
        rcs.iter().map(|&r| (r, eq5(r, lambda))).collect(),
        Stroke::series(0),
    );
    let mut bottom = Panel::new(Axis::new("R_C", "m"), Axis::new("eq. 6 − eq. 5", "m"))
        .titled("error of the smooth fit");
    for (k, (name, c)) in fits.iter().enumerate() {
        let stroke = Stroke::series(k + 1).dashed(if k == 0 {
            crate::figure::Dash::Dashed
        } else {
            crate::figure::Dash::Solid
        });
        top.line(
            name,
            rcs.iter().map(|&r| (r, fit_rc(r, c))).collect(),
            stroke,
        );
        bottom.line(
            name,
            rcs.iter()
                .map(|&r| (r, fit_rc(r, c) - eq5(r, lambda)))
                .collect(),
            stroke,
        );
    }
    Figure::new(
        "L_Ycomp: eq. 5 against the smooth fit of eq. 6 (paper Fig. 5)",
        1000,
        900,
    )
    .with_panel(top)
    .with_panel(bottom)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gradient_matches_finite_differences() {
        let p = [0.14, 0.28, 0.9];
        for rc in [0.1, 0.5, 0.7, 2.0, -1.3] {
            let (_, g) = eq6_with_gradient(rc, p);
            for k in 0..3 {
                let h = 1e-6;
                let (mut a, mut b) = (p, p);
                a[k] += h;
                b[k] -= h;
                let fd = (eq6_with_gradient(rc, a).0 - eq6_with_gradient(rc, b).0) / (2.0 * h);
                assert!((g[k] - fd).abs() < 1e-6 * (1.0 + fd.abs()), "{rc} {k}");
            }
        }
    }

    #[test]
    fn eq6_gradient_is_the_papers_formula() {
        let c = FitCoefficients::paper(0.5);
        for rc in [0.2, 0.7, 3.0] {
            let (f, _) = eq6_with_gradient(rc, [c.g, c.delta, c.epsilon]);
            assert!((f - fit_rc(rc, &c)).abs() < 1e-15);
        }
    }
}
