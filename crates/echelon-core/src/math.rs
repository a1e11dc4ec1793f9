//! Small numerical helpers shared by the references, the odometry and the
//! simulator.

pub mod lanes;
pub mod rng;

/// `sin(x)/x`, accurate near 0 (where it uses its Taylor series).
#[inline]
pub fn sinc(x: f64) -> f64 {
    if x.abs() < 1e-4 {
        1.0 - x * x / 6.0
    } else {
        x.sin() / x
    }
}

/// Inverse of the leading `m × m` block of `a` (`m ≤ N`; the rest of the
/// result is 0), by Gauss–Jordan elimination with partial pivoting: for small
/// fixed matrices (a spline's derivative map, an EKF innovation covariance).
pub fn invert<const N: usize>(a: &[[f64; N]; N], m: usize) -> [[f64; N]; N] {
    // `[l | r]` starts as `[A | I]` and ends as `[I | A⁻¹]`.
    let mut l = [[0.0; N]; N];
    let mut r = [[0.0; N]; N];
    for i in 0..m {
        l[i][..m].copy_from_slice(&a[i][..m]);
        r[i][i] = 1.0;
    }
    for c in 0..m {
        let p = (c..m)
            .max_by(|&x, &y| l[x][c].abs().total_cmp(&l[y][c].abs()))
            .unwrap_or(c);
        l.swap(c, p);
        r.swap(c, p);
        let d = l[c][c];
        for v in l[c][..m].iter_mut().chain(&mut r[c][..m]) {
            *v /= d;
        }
        let (pl, pr) = (l[c], r[c]);
        for row in 0..m {
            if row != c {
                let f = l[row][c];
                for (v, pv) in l[row][..m].iter_mut().zip(pl) {
                    *v -= f * pv;
                }
                for (v, pv) in r[row][..m].iter_mut().zip(pr) {
                    *v -= f * pv;
                }
            }
        }
    }
    r
}

/// `a / b` as a whole number ≥ 1 when it is one (to 1e-9 relative), else `None`.
pub fn whole_ratio(a: f64, b: f64) -> Option<u64> {
    let r = (a / b).round();
    ((a - r * b).abs() <= 1e-9 * a.abs().max(b) && r >= 1.0).then_some(r as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn series_and_closed_forms_agree_at_the_switch() {
        for x in [0.99e-4, 1.01e-4, -1.01e-4] {
            assert!((sinc(x) - x.sin() / x).abs() < 1e-15);
        }
        assert_eq!(sinc(0.0), 1.0);
    }
}
