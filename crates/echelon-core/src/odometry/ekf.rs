//! An extended Kalman filter over the pose `(x, y, θ)`: odometry predicts
//! (through the exact arc update of eq. 22), absolute fixes correct.
//!
//! The mean is the odometer's estimate; the filter carries its covariance.

use crate::model::{Pose, wrap_angle};

type M3 = [[f64; 3]; 3];

fn mul(a: &M3, b: &M3) -> M3 {
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
}

fn transpose(a: &M3) -> M3 {
    std::array::from_fn(|i| std::array::from_fn(|j| a[j][i]))
}

/// `d/du (sin u / u)`, accurate near 0.
fn dsinc(u: f64) -> f64 {
    if u.abs() < 1e-3 {
        -u / 3.0 + u * u * u / 30.0
    } else {
        (u * u.cos() - u.sin()) / (u * u)
    }
}

/// A fix's innovation `ν` over the measured `rows`, the fix's variances and
/// `S⁻¹`.
struct Innovation {
    rows: &'static [usize],
    var: [f64; 3],
    nu: [f64; 3],
    s_inv: M3,
}

impl Innovation {
    fn distance_sq(&self) -> f64 {
        let m = self.rows.len();
        (0..m)
            .map(|a| {
                let na = self.nu[self.rows[a]];
                (0..m)
                    .map(|b| na * self.s_inv[a][b] * self.nu[self.rows[b]])
                    .sum::<f64>()
            })
            .sum()
    }
}

/// Pose covariance of the estimate.
#[derive(Debug, Clone, PartialEq)]
pub struct Ekf {
    p: M3,
}

impl Default for Ekf {
    fn default() -> Self {
        Ekf::new()
    }
}

impl Ekf {
    /// A filter whose start pose is known exactly.
    pub fn new() -> Ekf {
        Ekf { p: [[0.0; 3]; 3] }
    }

    /// The covariance of `(x, y, θ)`.
    pub fn covariance(&self) -> M3 {
        self.p
    }

    /// Propagates the covariance through one odometry step from `from` by
    /// `(Δ, Θ)`, with wheel displacement variances `wheel_var` (right, left).
    pub fn predict(
        &mut self,
        from: &Pose,
        delta: f64,
        big_theta: f64,
        l: f64,
        wheel_var: [f64; 2],
    ) {
        let half = 0.5 * big_theta;
        let sc = crate::math::sinc(half);
        let chord = delta * sc;
        let (s, c) = (from.theta + half).sin_cos();
        // Jacobian of eq. 22 with respect to the pose …
        let f: M3 = [
            [1.0, 0.0, -chord * s],
            [0.0, 1.0, chord * c],
            [0.0, 0.0, 1.0],
        ];
        // … and to (Δ, Θ).
        let dchord = 0.5 * delta * dsinc(half);
        let g = [
            [sc * c, dchord * c - 0.5 * chord * s],
            [sc * s, dchord * s + 0.5 * chord * c],
            [0.0, 1.0],
        ];
        // Covariance of (Δ, Θ) from independent wheels (eq. 21).
        let (vr, vl) = (wheel_var[0], wheel_var[1]);
        let k = 1.0 / (2.0 * l);
        let q = [
            [0.25 * (vr + vl), 0.5 * k * (vr - vl)],
            [0.5 * k * (vr - vl), k * k * (vr + vl)],
        ];
        let mut p = mul(&mul(&f, &self.p), &transpose(&f));
        for (i, row) in p.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                for a in 0..2 {
                    for b in 0..2 {
                        *v += g[i][a] * q[a][b] * g[j][b];
                    }
                }
            }
        }
        self.p = p;
    }

    /// The innovation of fix `z` against `estimate` and its covariance's
    /// inverse over the measured rows (`x, y`, and `θ` when `sd_heading`
    /// is given).
    fn innovation(
        &self,
        estimate: &Pose,
        z: &Pose,
        sd_pos: f64,
        sd_heading: Option<f64>,
    ) -> Innovation {
        let rows: &'static [usize] = if sd_heading.is_some() {
            &[0, 1, 2]
        } else {
            &[0, 1]
        };
        let m = rows.len();
        let var = [
            sd_pos * sd_pos,
            sd_pos * sd_pos,
            sd_heading.map_or(0.0, |s| s * s),
        ];
        let nu = [
            z.x - estimate.x,
            z.y - estimate.y,
            wrap_angle(z.theta - estimate.theta),
        ];
        // S = H P Hᵀ + R over the measured rows; solve with Gauss-Jordan (m ≤ 3).
        let mut s = [[0.0; 3]; 3];
        for (a, &i) in rows.iter().enumerate() {
            for (b, &j) in rows.iter().enumerate() {
                s[a][b] = self.p[i][j] + if a == b { var[i].max(1e-18) } else { 0.0 };
            }
        }
        Innovation {
            rows,
            var,
            nu,
            s_inv: crate::math::invert(&s, m),
        }
    }

    /// The squared Mahalanobis distance `νᵀ S⁻¹ ν` of fix `z` from
    /// `estimate` (`S = H P Hᵀ + R`): chi-square with 2 (or, with a heading,
    /// 3) degrees of freedom for a fix consistent with the filter.
    pub fn distance_sq(
        &self,
        estimate: &Pose,
        z: &Pose,
        sd_pos: f64,
        sd_heading: Option<f64>,
    ) -> f64 {
        self.innovation(estimate, z, sd_pos, sd_heading)
            .distance_sq()
    }

    /// The covariance after the estimate was replaced by a fix (a reset):
    /// the fix's own, `diag(σ², σ², σ_θ²)`; without a heading in the fix
    /// the heading keeps its variance (its correlations with the position
    /// are dropped, the position now being the fix's).
    pub fn reset_to(&mut self, sd_pos: f64, sd_heading: Option<f64>) {
        let var = sd_pos * sd_pos;
        let heading = sd_heading.map_or(self.p[2][2], |s| s * s);
        self.p = [[var, 0.0, 0.0], [0.0, var, 0.0], [0.0, 0.0, heading]];
    }

    /// Fuses an absolute fix `z` (position with standard deviation `sd_pos`, and
    /// the heading if `sd_heading` is given) into `estimate`; returns the new mean.
    pub fn update(
        &mut self,
        estimate: &Pose,
        z: &Pose,
        sd_pos: f64,
        sd_heading: Option<f64>,
    ) -> Pose {
        let Innovation {
            rows,
            var,
            nu: innovation,
            s_inv,
        } = self.innovation(estimate, z, sd_pos, sd_heading);
        let m = rows.len();
        // K = P Hᵀ S⁻¹ (3 × m).
        let mut k = [[0.0; 3]; 3];
        for (i, row) in k.iter_mut().enumerate() {
            for b in 0..m {
                row[b] = (0..m).map(|a| self.p[i][rows[a]] * s_inv[a][b]).sum();
            }
        }
        let mut mean = [estimate.x, estimate.y, estimate.theta];
        for (i, v) in mean.iter_mut().enumerate() {
            *v += (0..m).map(|b| k[i][b] * innovation[rows[b]]).sum::<f64>();
        }
        // Joseph form: P = (I − KH) P (I − KH)ᵀ + K R Kᵀ.
        let mut ikh: M3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        for (i, row) in ikh.iter_mut().enumerate() {
            for (b, &j) in rows.iter().enumerate() {
                row[j] -= k[i][b];
            }
        }
        let mut p = mul(&mul(&ikh, &self.p), &transpose(&ikh));
        for (i, row) in p.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v += (0..m)
                    .map(|b| k[i][b] * var[rows[b]] * k[j][b])
                    .sum::<f64>();
            }
        }
        self.p = p;
        Pose {
            x: mean[0],
            y: mean[1],
            theta: mean[2],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_perfect_fix_replaces_an_uncertain_estimate() {
        let mut f = Ekf::new();
        let start = Pose::default();
        for _ in 0..100 {
            f.predict(&start, 0.01, 0.0, 0.2, [1e-4, 1e-4]);
        }
        let est = Pose {
            x: 1.0,
            y: 0.0,
            theta: 0.0,
        };
        let z = Pose {
            x: 1.2,
            y: 0.1,
            theta: 0.0,
        };
        let out = f.update(&est, &z, 1e-9, None);
        assert!((out.x - 1.2).abs() < 1e-6 && (out.y - 0.1).abs() < 1e-6);
        assert!(f.covariance()[0][0] < 1e-12);
    }

    #[test]
    fn equal_uncertainties_average() {
        let mut f = Ekf {
            p: [[0.04, 0.0, 0.0], [0.0, 0.04, 0.0], [0.0, 0.0, 0.01]],
        };
        let est = Pose::default();
        let z = Pose {
            x: 1.0,
            y: -1.0,
            theta: 0.0,
        };
        let out = f.update(&est, &z, 0.2, None);
        assert!((out.x - 0.5).abs() < 1e-12 && (out.y + 0.5).abs() < 1e-12);
        assert!((f.covariance()[0][0] - 0.02).abs() < 1e-12);
    }

    #[test]
    fn jacobian_matches_finite_differences() {
        let from = Pose {
            x: 0.3,
            y: -0.2,
            theta: 0.8,
        };
        let (delta, th, l) = (0.05, 0.3, 0.2);
        let step = |p: &Pose, d: f64, t: f64| crate::odometry::arc_update(p, d, t);
        // Var of x from Δ alone: (∂x/∂Δ)² var(Δ), compare with a finite difference.
        let h = 1e-7;
        let dx_dd = (step(&from, delta + h, th).x - step(&from, delta - h, th).x) / (2.0 * h);
        let dx_dt = (step(&from, delta, th + h).x - step(&from, delta, th - h).x) / (2.0 * h);
        let mut f = Ekf::new();
        // Equal wheel variances v: var(Δ) = v/2, var(Θ) = v/(2l²), uncorrelated.
        let v = 1e-4;
        f.predict(&from, delta, th, l, [v, v]);
        let want = dx_dd * dx_dd * v / 2.0 + dx_dt * dx_dt * v / (2.0 * l * l);
        assert!(
            (f.covariance()[0][0] - want).abs() < 1e-9 * want.max(1e-12),
            "{} vs {want}",
            f.covariance()[0][0]
        );
    }
}
