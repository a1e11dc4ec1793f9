//! The linear algebra of the fits: symmetric positive definite solves and
//! inverses, the reciprocal condition number, and linear least squares.

// Small dense linear algebra (n ≤ 3) reads best with explicit indices.
#![allow(clippy::needless_range_loop)]

pub(super) use crate::lm::solve_spd;

/// The inverse of a symmetric positive definite matrix, column by column.
pub(super) fn inverse_spd<const N: usize>(a: &[[f64; N]; N]) -> Option<[[f64; N]; N]> {
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

/// Least squares `y ≈ Σ βⱼ colsⱼ` by modified Gram–Schmidt on unit-scaled
/// columns: `β`, `(XᵀX)⁻¹` (3 × 3, the unused part zero) and the estimate
/// `(min Rᵢᵢ / max Rᵢᵢ)²` of the reciprocal condition number of the scaled
/// `XᵀX` (NaN coefficients when a column is degenerate).
pub(super) fn least_squares(cols: &[Vec<f64>], y: &[f64]) -> ([f64; 3], [[f64; 3]; 3], f64) {
    let p = cols.len();
    let degenerate = ([f64::NAN; 3], [[f64::NAN; 3]; 3], 0.0);
    let scale: Vec<f64> = cols
        .iter()
        .map(|c| c.iter().map(|x| x * x).sum::<f64>().sqrt())
        .collect();
    if scale.iter().any(|s| s.is_nan() || *s <= 0.0) {
        return degenerate;
    }
    let mut q: Vec<Vec<f64>> = cols
        .iter()
        .zip(&scale)
        .map(|(c, s)| c.iter().map(|x| x / s).collect())
        .collect();
    let mut r = [[0.0; 3]; 3];
    for j in 0..p {
        for i in 0..j {
            let dot: f64 = q[i].iter().zip(&q[j]).map(|(a, b)| a * b).sum();
            r[i][j] = dot;
            let (done, rest) = q.split_at_mut(j);
            rest[0]
                .iter_mut()
                .zip(&done[i])
                .for_each(|(x, a)| *x -= dot * a);
        }
        let norm = q[j].iter().map(|x| x * x).sum::<f64>().sqrt();
        if norm.is_nan() || norm <= 1e-15 {
            return degenerate;
        }
        r[j][j] = norm;
        q[j].iter_mut().for_each(|x| *x /= norm);
    }
    let diag: Vec<f64> = (0..p).map(|i| r[i][i]).collect();
    let (lo, hi) = diag.iter().fold((f64::INFINITY, 0.0_f64), |(lo, hi), d| {
        (lo.min(*d), hi.max(*d))
    });
    let rc = if hi > 0.0 { (lo / hi).powi(2) } else { 0.0 };
    // Back substitution: R b = Qᵀ y; R⁻¹ for the covariance.
    let qty: Vec<f64> = q
        .iter()
        .map(|qj| qj.iter().zip(y).map(|(a, b)| a * b).sum())
        .collect();
    let mut rinv = [[0.0; 3]; 3];
    for j in 0..p {
        let mut e = [0.0; 3];
        e[j] = 1.0;
        for i in (0..p).rev() {
            let mut sum = e[i];
            for k in i + 1..p {
                sum -= r[i][k] * rinv[k][j];
            }
            rinv[i][j] = sum / r[i][i];
        }
    }
    let mut beta = [0.0; 3];
    let mut cov = [[0.0; 3]; 3];
    for i in 0..p {
        beta[i] = (0..p).map(|k| rinv[i][k] * qty[k]).sum::<f64>() / scale[i];
        for j in 0..p {
            cov[i][j] =
                (0..p).map(|k| rinv[i][k] * rinv[j][k]).sum::<f64>() / (scale[i] * scale[j]);
        }
    }
    (beta, cov, rc)
}
