//! Septic interpolating spline: C⁶ between the waypoints, and at rest (zero
//! velocity, acceleration and jerk) at the first and last one, so that the
//! reference — standing still before and after — is C³ over all time, as pure
//! tracking requires (Remark 4).
//!
//! Each segment is the degree-7 Hermite polynomial fixed by position and the
//! first three derivatives at its two knots. Requiring the 4th, 5th and 6th
//! derivatives to be continuous at every interior knot gives three equations
//! per knot for the three unknown derivatives there; with zero end derivatives
//! the system is square and banded, solved in O(n).

use crate::error::ReferenceError;

/// Shortest time between consecutive waypoints, s: closer ones ask the
/// spline for absurd speeds and its derivatives for absurd values.
pub(crate) const MIN_GAP: f64 = 1e-6;
/// Largest speed of the spline, and so of the average between consecutive
/// waypoints, m/s: the plausible speed of a reference (the scenario's
/// `reference.*.speed`).
pub(crate) const MAX_SPEED: f64 = 100.0;

/// Derivatives fixed at each knot (1: velocity, 2: acceleration, 3: jerk).
const M: usize = 3;
/// Coefficients per segment (degree `2M + 1`).
const N: usize = 2 * M + 2;

/// One coordinate of the spline: knot times and per-segment coefficients.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Septic {
    times: Vec<f64>,
    /// `c[k][j]`: coefficient of `τ^j` on segment `k`, `τ = t − t_k`.
    coeffs: Vec<[f64; N]>,
    /// The last waypoint's value, held after the last time.
    last: f64,
}

fn factorial(n: usize) -> f64 {
    (1..=n).map(|k| k as f64).product()
}

/// `j! / (j − k)!`: the factor of `s^(j−k)` in the k-th derivative of `s^j`.
fn falling(j: usize, k: usize) -> f64 {
    if k > j {
        0.0
    } else {
        ((j - k + 1)..=j).map(|x| x as f64).product()
    }
}

/// Inverse of the `(M+1)×(M+1)` matrix `A[k][i] = falling(M+1+i, k)` that maps
/// the upper coefficients of the unit-interval polynomial to its derivatives at
/// `s = 1` (the matrix is fixed and small).
fn upper_inverse() -> [[f64; M + 1]; M + 1] {
    let a: [[f64; M + 1]; M + 1] =
        std::array::from_fn(|k| std::array::from_fn(|i| falling(M + 1 + i, k)));
    crate::math::invert(&a, M + 1)
}

/// Coefficients in `τ ∈ [0, h]` of the Hermite polynomial with derivatives
/// `left[k]`, `right[k]` (k = 0..=M) at its two ends.
fn hermite(
    left: &[f64; M + 1],
    right: &[f64; M + 1],
    h: f64,
    inv: &[[f64; M + 1]; M + 1],
) -> [f64; N] {
    // On s = τ/h ∈ [0, 1]: the k-th s-derivative is h^k times the τ-derivative.
    let mut d = [0.0; N];
    let mut hk = 1.0;
    let mut rhs = [0.0; M + 1];
    for k in 0..=M {
        d[k] = left[k] * hk / factorial(k);
        rhs[k] = right[k] * hk;
        hk *= h;
    }
    for (k, r) in rhs.iter_mut().enumerate() {
        for (j, dj) in d.iter().enumerate().take(M + 1) {
            *r -= falling(j, k) * dj;
        }
    }
    for i in 0..=M {
        d[M + 1 + i] = (0..=M).map(|k| inv[i][k] * rhs[k]).sum();
    }
    // Back to τ: c_j = d_j / h^j.
    let mut hj = 1.0;
    for dj in d.iter_mut() {
        *dj /= hj;
        hj *= h;
    }
    d
}

/// The k-th derivative of the polynomial `c` at `τ`.
fn derivative(c: &[f64; N], tau: f64, k: usize) -> f64 {
    (k..N)
        .rev()
        .fold(0.0, |acc, j| acc * tau + falling(j, k) * c[j])
}

impl Septic {
    /// Interpolates `values` at strictly increasing `times` (checked by the caller).
    pub(crate) fn new(times: &[f64], values: &[f64]) -> Septic {
        let inv = upper_inverse();
        let n = times.len() - 1; // segments
        let unknowns = M * (n - 1); // derivatives 1..=M at interior knots
        let mut band = Banded::new(unknowns, 2 * M - 1, 2 * M - 1);
        let mut rhs = vec![0.0; unknowns];
        // Derivatives M+1..=2M at the start and end of a segment, for given end data.
        let ends = |l: &[f64; M + 1], r: &[f64; M + 1], h: f64| {
            let c = hermite(l, r, h, &inv);
            let start: [f64; M] = std::array::from_fn(|q| derivative(&c, 0.0, M + 1 + q));
            let end: [f64; M] = std::array::from_fn(|q| derivative(&c, h, M + 1 + q));
            (start, end)
        };
        let unit =
            |k: usize| -> [f64; M + 1] { std::array::from_fn(|i| f64::from(u8::from(i == k))) };
        let zero = [0.0; M + 1];
        for i in 1..n {
            let (hl, hr) = (times[i] - times[i - 1], times[i + 1] - times[i]);
            let row0 = M * (i - 1);
            // Residual of the continuity equations from the positions alone.
            let (_, left_end) = ends(
                &[values[i - 1], 0.0, 0.0, 0.0],
                &[values[i], 0.0, 0.0, 0.0],
                hl,
            );
            let (right_start, _) = ends(
                &[values[i], 0.0, 0.0, 0.0],
                &[values[i + 1], 0.0, 0.0, 0.0],
                hr,
            );
            for q in 0..M {
                rhs[row0 + q] = right_start[q] - left_end[q];
            }
            // Coefficients of the unknown derivatives at knots i−1, i, i+1.
            for k in 1..=M {
                let e = unit(k);
                let contributions = [
                    (i - 1, ends(&e, &zero, hl).1, [0.0; M]),
                    (i, ends(&zero, &e, hl).1, ends(&e, &zero, hr).0),
                    (i + 1, [0.0; M], ends(&zero, &e, hr).0),
                ];
                for (knot, from_left, from_right) in contributions {
                    if knot == 0 || knot == n {
                        continue; // end derivatives are zero
                    }
                    let col = M * (knot - 1) + (k - 1);
                    for q in 0..M {
                        band.add(row0 + q, col, from_left[q] - from_right[q]);
                    }
                }
            }
        }
        let x = band.solve(rhs);
        let data = |i: usize| -> [f64; M + 1] {
            let mut d = [values[i], 0.0, 0.0, 0.0];
            if i > 0 && i < n {
                d[1..].copy_from_slice(&x[M * (i - 1)..M * i]);
            }
            d
        };
        let coeffs = (0..n)
            .map(|k| hermite(&data(k), &data(k + 1), times[k + 1] - times[k], &inv))
            .collect();
        Septic {
            times: times.to_vec(),
            coeffs,
            last: values[n],
        }
    }

    /// Value and derivatives 1–4 at `t`; at rest outside the knots.
    pub(crate) fn eval(&self, t: f64) -> [f64; 5] {
        let last = self.times.len() - 1;
        if t <= self.times[0] {
            return [self.coeffs[0][0], 0.0, 0.0, 0.0, 0.0];
        }
        if t >= self.times[last] {
            return [self.last, 0.0, 0.0, 0.0, 0.0];
        }
        // Segment k with times[k] < t < times[k+1] (or t at an interior knot).
        let k = self.times.partition_point(|&tk| tk <= t) - 1;
        let c = &self.coeffs[k];
        let s = t - self.times[k];
        std::array::from_fn(|d| derivative(c, s, d))
    }
}

/// A square banded matrix, solved by Gaussian elimination with partial pivoting.
/// Row `q` stores columns `q − kl ..= q + kl + ku` (room for the fill-in of pivoting).
struct Banded {
    n: usize,
    kl: usize,
    width: usize,
    data: Vec<f64>,
}

impl Banded {
    fn new(n: usize, kl: usize, ku: usize) -> Banded {
        let width = 2 * kl + ku + 1;
        Banded {
            n,
            kl,
            width,
            data: vec![0.0; n * width],
        }
    }

    /// Storage index of `(row, col)`, `None` if outside the row's window.
    fn idx(&self, row: usize, col: usize) -> Option<usize> {
        let offset = (col + self.kl).checked_sub(row)?;
        (offset < self.width && col < self.n).then_some(row * self.width + offset)
    }

    fn get(&self, row: usize, col: usize) -> f64 {
        self.idx(row, col).map_or(0.0, |i| self.data[i])
    }

    fn set(&mut self, row: usize, col: usize, value: f64) {
        if let Some(i) = self.idx(row, col) {
            self.data[i] = value;
        }
    }

    fn add(&mut self, row: usize, col: usize, value: f64) {
        let v = self.get(row, col);
        self.set(row, col, v + value);
    }

    fn solve(mut self, mut b: Vec<f64>) -> Vec<f64> {
        let n = self.n;
        let reach = self.width - self.kl; // columns i .. i+reach hold row i's nonzeros
        for i in 0..n {
            let last_row = (i + self.kl).min(n - 1);
            let pivot = (i..=last_row)
                .max_by(|&a, &c| self.get(a, i).abs().total_cmp(&self.get(c, i).abs()))
                .unwrap_or(i);
            if pivot != i {
                for c in i..(i + reach).min(n) {
                    let (a, p) = (self.get(i, c), self.get(pivot, c));
                    self.set(i, c, p);
                    self.set(pivot, c, a);
                }
                b.swap(i, pivot);
            }
            let d = self.get(i, i);
            for q in i + 1..=last_row {
                let f = self.get(q, i) / d;
                if f == 0.0 {
                    continue;
                }
                self.set(q, i, 0.0);
                for c in i + 1..(i + reach).min(n) {
                    let v = self.get(q, c) - f * self.get(i, c);
                    self.set(q, c, v);
                }
                b[q] -= f * b[i];
            }
        }
        for i in (0..n).rev() {
            let end = (i + reach).min(n);
            let s: f64 = (i + 1..end).map(|c| self.get(i, c) * b[c]).sum();
            b[i] = (b[i] - s) / self.get(i, i);
        }
        b
    }
}

/// Checks waypoint data: at least two points, finite, strictly increasing
/// times at least [`MIN_GAP`] apart, and no average speed between
/// two consecutive points above [`MAX_SPEED`]. Indices in the
/// errors are 1-based.
pub(crate) fn check_waypoints(points: &[[f64; 3]]) -> Result<(), ReferenceError> {
    if points.len() < 2 {
        return Err(ReferenceError::TooFewWaypoints(points.len()));
    }
    for (i, p) in points.iter().enumerate() {
        if let Some(coordinate) = p.iter().position(|v| !v.is_finite()) {
            return Err(ReferenceError::NonFiniteWaypoint {
                index: i + 1,
                coordinate,
                value: p[coordinate],
            });
        }
        let Some(q) = i.checked_sub(1).map(|k| points[k]) else {
            continue;
        };
        let (t, previous) = (p[0], q[0]);
        if t <= previous {
            return Err(ReferenceError::TimesNotIncreasing {
                index: i + 1,
                t,
                previous,
            });
        }
        // `t − previous` rounds: compare the gap as the spline will see it.
        let gap = t - previous;
        if gap < MIN_GAP {
            return Err(ReferenceError::WaypointsTooClose {
                index: i + 1,
                t,
                previous,
                min_gap: MIN_GAP,
            });
        }
        let distance = (p[1] - q[1]).hypot(p[2] - q[2]);
        let speed = distance / gap;
        // An overflowing distance is infinite; NaN is refused too.
        if speed.is_nan() || speed > MAX_SPEED {
            return Err(ReferenceError::WaypointsTooFast {
                index: i + 1,
                t,
                previous,
                distance,
                speed,
                max_speed: MAX_SPEED,
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `p = s⁴(35 − 84s + 70s² − 20s³)`, `s = t/T`: at rest with zero jerk at both ends.
    fn smoothstep(t: f64, big_t: f64) -> [f64; 5] {
        let s = t / big_t;
        let p = [0.0, 0.0, 0.0, 0.0, 35.0, -84.0, 70.0, -20.0];
        std::array::from_fn(|k| derivative(&p, s, k) / big_t.powi(k as i32))
    }

    /// `got` agrees with `want` in `p` and its first four derivatives within
    /// `tol` relative to `want`; at an end knot (`end`) the snap, which jumps
    /// there (C³ at the ends, by design), is left out.
    fn assert_derivatives(got: [f64; 5], want: [f64; 5], end: bool, tol: f64, at: &str) {
        let orders = if end { 4 } else { 5 };
        for d in 0..orders {
            assert!(
                (got[d] - want[d]).abs() < tol * (1.0 + want[d].abs()),
                "{at}, derivative {d}: {} vs {}",
                got[d],
                want[d]
            );
        }
    }

    #[test]
    fn reproduces_a_septic_at_rest_at_both_ends() {
        let times = [0.0, 0.13, 0.4, 0.45, 0.8, 1.1, 2.0];
        let values: Vec<f64> = times.iter().map(|&t| smoothstep(t, 2.0)[0]).collect();
        let q = Septic::new(&times, &values);
        for i in 0..=400 {
            let t = i as f64 / 200.0;
            let (got, want) = (q.eval(t), smoothstep(t, 2.0));
            let end = t == 0.0 || t == 2.0;
            assert_derivatives(got, want, end, 1e-8, &format!("t = {t}"));
        }
    }

    #[test]
    fn is_c4_inside_c3_at_the_ends_and_interpolates() {
        let times = [0.0, 1.0, 2.5, 3.0, 4.2, 6.0, 7.0];
        let values = [0.0, 2.0, -1.0, 0.5, 3.0, 3.0, -2.0];
        let q = Septic::new(&times, &values);
        for (t, v) in times.iter().zip(values) {
            assert!((q.eval(*t)[0] - v).abs() < 1e-12);
        }
        for &t in &times {
            let (before, after) = (q.eval(t - 1e-9), q.eval(t + 1e-9));
            let end = t == 0.0 || t == 7.0;
            assert_derivatives(after, before, end, 1e-5, &format!("jump at knot {t}"));
        }
        for t in [0.0, 7.0] {
            let e = q.eval(t);
            assert!(e[1].abs() < 1e-9 && e[2].abs() < 1e-9 && e[3].abs() < 1e-9);
        }
    }

    #[test]
    fn two_points_give_the_smoothstep() {
        let q = Septic::new(&[0.0, 2.0], &[0.0, 1.0]);
        for i in 0..=20 {
            let t = i as f64 * 0.1;
            assert!((q.eval(t)[0] - smoothstep(t, 2.0)[0]).abs() < 1e-12);
        }
    }

    #[test]
    fn many_waypoints_stay_accurate() {
        // 2000 knots on a sine: the banded solve must stay well conditioned.
        let times: Vec<f64> = (0..2000).map(|i| i as f64 * 0.05).collect();
        let values: Vec<f64> = times.iter().map(|t| (0.3 * t).sin()).collect();
        let q = Septic::new(&times, &values);
        let mid = q.eval(50.025);
        assert!((mid[0] - (0.3f64 * 50.025).sin()).abs() < 1e-9);
        assert!((mid[1] - 0.3 * (0.3f64 * 50.025).cos()).abs() < 1e-7);
    }

    #[test]
    fn waypoint_checks() {
        assert_eq!(
            check_waypoints(&[[0.0, 0.0, 0.0]]),
            Err(ReferenceError::TooFewWaypoints(1))
        );
        assert!(matches!(
            check_waypoints(&[[0.0, 0.0, 0.0], [0.0, 1.0, 1.0]]),
            Err(ReferenceError::TimesNotIncreasing { index: 2, .. })
        ));
        assert!(matches!(
            check_waypoints(&[[0.0, 0.0, 0.0], [1.0, f64::NAN, 1.0]]),
            Err(ReferenceError::NonFiniteWaypoint {
                index: 2,
                coordinate: 1,
                ..
            })
        ));
    }

    proptest::proptest! {
        /// Consecutive waypoints closer than `MIN_GAP` in time, or farther
        /// apart than `MAX_SPEED` allows, are refused naming the later one;
        /// any others are accepted and the spline through them is finite
        /// (value and derivatives 1–4) everywhere.
        #[test]
        fn gaps_and_speeds_decide_and_the_accepted_spline_is_finite(
            gaps in proptest::collection::vec(
                proptest::prop_oneof![1 => 1e-12..1e-6f64, 4 => 1e-6..1e-3f64, 8 => 1e-3..1e4f64],
                1..12,
            ),
            steps in proptest::collection::vec(
                (-1.0..1.0f64, -1.0..1.0f64, proptest::prop_oneof![8 => 0.0..1.0f64, 1 => 1.0..1e9f64]),
                12,
            ),
            t0 in -1e5..1e5f64,
        ) {
            // Each step's average speed is a factor of the limit, now and then above 1.
            let mut points = vec![[t0, 0.0, 0.0]];
            for (g, (dx, dy, f)) in gaps.iter().zip(&steps) {
                let last = points[points.len() - 1];
                let norm = dx.hypot(*dy).max(1e-12);
                let d = f * MAX_SPEED * g;
                points.push([last[0] + g, last[1] + d * dx / norm, last[2] + d * dy / norm]);
            }
            let first_bad = points.windows(2).position(|w| {
                let gap = w[1][0] - w[0][0];
                gap < MIN_GAP
                    || (w[1][1] - w[0][1]).hypot(w[1][2] - w[0][2]) / gap > MAX_SPEED
            });
            match (check_waypoints(&points), first_bad) {
                (Ok(()), None) => {
                    let times: Vec<f64> = points.iter().map(|p| p[0]).collect();
                    for k in [1, 2] {
                        let values: Vec<f64> = points.iter().map(|p| p[k]).collect();
                        let q = Septic::new(&times, &values);
                        for w in times.windows(2) {
                            for s in [0.0, 0.1, 0.5, 0.9] {
                                let e = q.eval(w[0] + s * (w[1] - w[0]));
                                proptest::prop_assert!(e.iter().all(|v| v.is_finite()), "{e:?} in {points:?}");
                            }
                        }
                    }
                }
                (Err(
                    ReferenceError::TimesNotIncreasing { index, .. }
                    | ReferenceError::WaypointsTooClose { index, .. }
                    | ReferenceError::WaypointsTooFast { index, .. },
                ), Some(k)) => proptest::prop_assert_eq!(index, k + 2),
                (got, want) => proptest::prop_assert!(false, "{got:?}, first bad pair {want:?}: {points:?}"),
            }
        }
    }
}
