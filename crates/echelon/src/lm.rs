//! Levenberg–Marquardt for small nonlinear least-squares problems (a few
//! parameters, any number of residuals): the identification's axis fits and
//! the report's refit of eq. 6 both minimise through [`minimise`].
//!
//! Each iteration solves `(JᵀJ + λ diag(JᵀJ)) δ = Jᵀr` (Marquardt's scaled
//! damping) for the residuals `r = data − model` at the current point and
//! tries `p + δ`: a step that does not raise the cost is taken and `λ` drops
//! tenfold (not below [`LAMBDA_FLOOR`]); a step that raises it, leaves the
//! model's domain or cannot be solved for raises `λ` tenfold and is tried
//! again, at most [`TRIES`] times. The search stops when an iteration finds
//! no step, or one that lowers the cost by a relative [`REL_TOL`] or less.

/// Starting damping `λ`.
pub const LAMBDA_START: f64 = 1e-3;
/// Smallest damping `λ`.
pub const LAMBDA_FLOOR: f64 = 1e-12;
/// Steps tried per iteration (each with ten times the damping of the last).
pub const TRIES: usize = 30;
/// An accepted step that lowers the cost by this fraction or less ends the
/// search.
pub const REL_TOL: f64 = 1e-14;

/// A least-squares problem in `N` parameters.
pub trait LeastSquares<const N: usize> {
    /// `JᵀJ` and `Jᵀr` at `p`, the point last accepted (the start, or the
    /// last trial followed by [`LeastSquares::accept`]), with `J` the
    /// Jacobian of the model and `r = data − model` its residuals (weighted
    /// as the cost weighs them).
    fn normal_equations(&self, p: &[f64; N]) -> ([[f64; N]; N], [f64; N]);

    /// The cost (weighted sum of squared residuals) at a trial point `p`;
    /// `None` outside the model's domain.
    fn trial(&mut self, p: &[f64; N]) -> Option<f64>;

    /// The last trial is the new point (a problem that keeps the model's
    /// values at its point swaps the trial's in).
    fn accept(&mut self) {}
}

/// Where [`minimise`] stopped.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Minimum<const N: usize> {
    /// The parameters.
    pub p: [f64; N],
    /// The cost there.
    pub cost: f64,
    /// Iterations run (each solves the normal equations once).
    pub iterations: usize,
}

/// Minimises `problem` from `p`, whose cost is `cost`, in at most `max_iter`
/// iterations (the module docs give the rule).
pub fn minimise<const N: usize>(
    problem: &mut impl LeastSquares<N>,
    mut p: [f64; N],
    mut cost: f64,
    max_iter: usize,
) -> Minimum<N> {
    let mut lambda = LAMBDA_START;
    let mut iterations = 0;
    for it in 0..max_iter {
        iterations = it + 1;
        let (jtj, jtr) = problem.normal_equations(&p);
        let mut improved = false;
        for _ in 0..TRIES {
            let mut a = jtj;
            for (i, row) in a.iter_mut().enumerate() {
                row[i] *= 1.0 + lambda;
            }
            let Some(step) = solve_spd(&a, &jtr) else {
                lambda *= 10.0;
                continue;
            };
            let next: [f64; N] = std::array::from_fn(|i| p[i] + step[i]);
            let Some(c) = problem.trial(&next) else {
                lambda *= 10.0;
                continue;
            };
            if c <= cost {
                let rel = (cost - c) / cost.max(f64::MIN_POSITIVE);
                (p, cost) = (next, c);
                problem.accept();
                lambda = (lambda / 10.0).max(LAMBDA_FLOOR);
                improved = rel > REL_TOL;
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    Minimum {
        p,
        cost,
        iterations,
    }
}

// Small dense linear algebra (n ≤ 3) reads best with explicit indices.
#[allow(clippy::needless_range_loop)]
/// Solves the symmetric positive definite `n × n` system `a x = b` (n ≤ 3) by
/// Cholesky; `None` if `a` is not positive definite.
pub(crate) fn solve_spd<const N: usize>(a: &[[f64; N]; N], b: &[f64; N]) -> Option<[f64; N]> {
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

#[cfg(test)]
mod tests {
    use super::*;

    /// `y = a e^{b t}` at fixed samples.
    struct Exponential {
        t: Vec<f64>,
        y: Vec<f64>,
    }

    impl Exponential {
        fn residuals(&self, [a, b]: [f64; 2]) -> impl Iterator<Item = (f64, [f64; 2])> + '_ {
            self.t.iter().zip(&self.y).map(move |(&t, &y)| {
                let e = (b * t).exp();
                (y - a * e, [e, a * t * e])
            })
        }
    }

    impl LeastSquares<2> for Exponential {
        fn normal_equations(&self, p: &[f64; 2]) -> ([[f64; 2]; 2], [f64; 2]) {
            let mut jtj = [[0.0; 2]; 2];
            let mut jtr = [0.0; 2];
            for (r, g) in self.residuals(*p) {
                for i in 0..2 {
                    jtr[i] += g[i] * r;
                    for j in 0..2 {
                        jtj[i][j] += g[i] * g[j];
                    }
                }
            }
            (jtj, jtr)
        }

        fn trial(&mut self, p: &[f64; 2]) -> Option<f64> {
            (p[0] > 0.0).then(|| self.residuals(*p).map(|(r, _)| r * r).sum())
        }
    }

    #[test]
    fn recovers_an_exact_model_and_stops() {
        let t: Vec<f64> = (0..50).map(|i| i as f64 * 0.1).collect();
        let y = t.iter().map(|t| 2.0 * (-0.7 * t).exp()).collect();
        let mut problem = Exponential { t, y };
        let start = [1.0, 0.0];
        let cost = problem.trial(&start).expect("a > 0");
        let m = minimise(&mut problem, start, cost, 200);
        assert!(
            (m.p[0] - 2.0).abs() < 1e-9 && (m.p[1] + 0.7).abs() < 1e-9,
            "{m:?}"
        );
        assert!(m.cost < 1e-18, "{m:?}");
        assert!(m.iterations < 200, "{m:?}");
        // From the optimum nothing improves: one iteration, the same point.
        let again = minimise(&mut problem, m.p, m.cost, 200);
        assert_eq!(again.iterations, 1);
        assert_eq!(again.p, m.p);
    }

    #[test]
    fn never_leaves_the_domain_or_raises_the_cost() {
        // Data that pull `a` towards 0 and below: every accepted point keeps
        // a > 0 and the cost only falls.
        let t: Vec<f64> = (0..20).map(|i| i as f64 * 0.1).collect();
        let y = t.iter().map(|t| -0.5 + 0.01 * t).collect();
        let mut problem = Exponential { t, y };
        let start = [1.0, 0.1];
        let cost = problem.trial(&start).expect("a > 0");
        let m = minimise(&mut problem, start, cost, 50);
        assert!(m.p[0] > 0.0, "{m:?}");
        assert!(m.cost <= cost, "{m:?}");
    }
}
