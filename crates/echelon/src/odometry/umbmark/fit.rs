//! The refined UMBmark estimate: the `(E_d, E_b)` for which the exact
//! square kinematics reproduce the observed centres of gravity, searched
//! over every error a square test can tell apart (not only near Borenstein's
//! first-order estimate, whose neighbourhood holds wrong local minima once
//! the errors are large), and how well it reproduces them.

use rand::SeedableRng;

use super::{ChaCha8Rng, Direction, SquareTest, Systematic};
use crate::odometry::ErrorModel;

/// The `E_d` searched: `[0.67, 1.5]` (one wheel up to half as large again
/// as the other).
pub const ED_RANGE: [f64; 2] = [0.67, 1.5];
/// The `E_b` searched: `[0.6, 2]`. Within these ranges the four centres of
/// gravity give one `(E_d, E_b)` (a property test checks it on random
/// squares); beyond them other errors can drive the same return errors:
/// at `E_b = 2/3` a commanded 90° turn turns 135°, and `E_d` = 1.53 or 0.57
/// (just outside) closes the square as a perfect robot does; at `E_b = 1/2`
/// (180°) every `E_d` does; below `1/4` `E_b` cannot be told from
/// `1 / (1/E_b − 4)`.
pub const EB_RANGE: [f64; 2] = [0.6, 2.0];
/// Grid of starting points per axis, even in the robot's turn per commanded
/// turn `1/E_b` and in its curvature on a leg `(E_d − 1)/(E_d + 1)`, where
/// the basins are about as wide everywhere.
const GRID: usize = 121;
/// Starts refined to the end (of those screened, the lowest after
/// [`SCREEN`] iterations), and the line scan's minima taken as starts.
const STARTS: usize = 32;
/// Two solutions closer than this (relative, on either error) are one.
const SAME: f64 = 1e-4;

/// The centres of gravity `[x_cw, y_cw, x_ccw, y_ccw]` an error-free-but-
/// systematic robot would produce: the model the refinement inverts (`None`
/// for impossible errors, `E_d` or `E_b` ≤ 0).
fn model(geometry: &SquareTest, [ed, eb]: [f64; 2]) -> Option<[f64; 4]> {
    let t = geometry.one_run(ErrorModel::systematic(ed, eb).ok()?);
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let (a, b) = (
        t.drive(Direction::Cw, &mut rng),
        t.drive(Direction::Ccw, &mut rng),
    );
    let f = [a.0.x - a.1.x, a.0.y - a.1.y, b.0.x - b.1.x, b.0.y - b.1.y];
    f.iter().all(|v| v.is_finite()).then_some(f)
}

/// Sum of squared residuals at `p` (infinite where the model is undefined).
fn cost(geometry: &SquareTest, observed: &[f64; 4], p: [f64; 2]) -> f64 {
    model(geometry, p).map_or(f64::INFINITY, |f| {
        f.iter().zip(observed).map(|(f, o)| (f - o) * (f - o)).sum()
    })
}

/// A box of errors searched: `[E_d range, E_b range]`.
pub(super) type Ranges = [[f64; 2]; 2];

/// The ranges the refined estimate is searched in.
pub(super) const SEARCHED: Ranges = [ED_RANGE, EB_RANGE];

/// The wider box searched for aliases beyond [`SEARCHED`]: errors a robot
/// can hardly have (a wheel up to three times the other's size, a turn of a
/// third to six times the commanded), where runs that the searched ranges
/// also explain may come from (`super::estimate` says so).
pub(super) const BEYOND: Ranges = [[0.35, 3.0], [0.3, 6.0]];

/// Whether `p` is inside `r`.
pub(super) fn inside(r: &Ranges, [ed, eb]: [f64; 2]) -> bool {
    (r[0][0]..=r[0][1]).contains(&ed) && (r[1][0]..=r[1][1]).contains(&eb)
}

/// `p` moved into `r`.
fn clamp(r: &Ranges, [ed, eb]: [f64; 2]) -> [f64; 2] {
    [ed.clamp(r[0][0], r[0][1]), eb.clamp(r[1][0], r[1][1])]
}

/// Step `i` of `n` over `r`'s `E_d` range, even in the curvature on a leg
/// `w = (E_d − 1)/(E_d + 1)` (the grid's and the line scan's spacing).
fn ed_step(r: &Ranges, n: usize, i: usize) -> f64 {
    let w = |ed: f64| (ed - 1.0) / (ed + 1.0);
    let (lo, hi) = (w(r[0][0]), w(r[0][1]));
    let w = lo + (hi - lo) * i as f64 / (n - 1) as f64;
    (1.0 + w) / (1.0 - w)
}

/// Points of the fine line scan in `E_d`.
const LINE: usize = 4001;

/// The local minima of the cost along `E_d` at `E_b = eb` (clamped into
/// `r`), on a scan [`LINE`] points fine, lowest first ([`STARTS`] of them):
/// a robot whose wheels differ much drives whole circles on each leg, and
/// the basins of those runs narrow with the square's side (about 0.05 in
/// `E_d` on an 8 m square) below the grid's spacing, so a grid start can
/// miss them (E_d = 0.544, E_b = 1.011 on a 7.4 m square).
fn line_minima(geometry: &SquareTest, observed: &[f64; 4], r: &Ranges, eb: f64) -> Vec<[f64; 2]> {
    let eb = eb.clamp(r[1][0], r[1][1]);
    let ed_at = |i: usize| ed_step(r, LINE, i);
    let costs: Vec<f64> = (0..LINE)
        .map(|i| cost(geometry, observed, [ed_at(i), eb]))
        .collect();
    let mut minima: Vec<(f64, [f64; 2])> = (1..LINE - 1)
        .filter(|&i| costs[i].is_finite() && costs[i] <= costs[i - 1] && costs[i] < costs[i + 1])
        .map(|i| (costs[i], [ed_at(i), eb]))
        .collect();
    minima.sort_by(|a, b| a.0.total_cmp(&b.0));
    minima.into_iter().take(STARTS).map(|m| m.1).collect()
}

/// Levenberg–Marquardt iterations a start is screened with before the
/// [`STARTS`] best are refined to the end: a start in the robot's basin
/// is within rounding by then (the convergence is quadratic there), one
/// in a wrong valley crawls along it.
const SCREEN: usize = 12;

/// Levenberg–Marquardt from `p` within `within`, at most `iterations`: the
/// local minimum (or where the budget ended) and its cost.
fn descend(
    geometry: &SquareTest,
    observed: &[f64; 4],
    within: &Ranges,
    mut p: [f64; 2],
    iterations: usize,
) -> ([f64; 2], f64) {
    let mut c = cost(geometry, observed, p);
    let mut lambda = 1e-3;
    for _ in 0..iterations {
        let Some(f) = model(geometry, p) else { break };
        let r: [f64; 4] = std::array::from_fn(|i| f[i] - observed[i]);
        // Jacobian by central differences of the (smooth) kinematic model.
        let mut j = [[0.0; 2]; 4];
        for k in 0..2 {
            let h = 1e-7 * p[k];
            let (mut lo, mut hi) = (p, p);
            lo[k] -= h;
            hi[k] += h;
            let (Some(fl), Some(fh)) = (model(geometry, lo), model(geometry, hi)) else {
                return (p, c);
            };
            for i in 0..4 {
                j[i][k] = (fh[i] - fl[i]) / (2.0 * h);
            }
        }
        // (JᵀJ + λ diag JᵀJ) δ = −Jᵀr.
        let mut a = [[0.0; 2]; 2];
        let mut g = [0.0; 2];
        for i in 0..4 {
            for k in 0..2 {
                g[k] -= j[i][k] * r[i];
                for m in 0..2 {
                    a[k][m] += j[i][k] * j[i][m];
                }
            }
        }
        let mut moved = false;
        while lambda < 1e12 {
            let d00 = a[0][0] * (1.0 + lambda);
            let d11 = a[1][1] * (1.0 + lambda);
            let det = d00 * d11 - a[0][1] * a[1][0];
            if det.abs() > 0.0 && det.is_finite() {
                let d = [
                    (d11 * g[0] - a[0][1] * g[1]) / det,
                    (d00 * g[1] - a[1][0] * g[0]) / det,
                ];
                // Projected onto the ranges: a minimum on their edge is
                // reached along it.
                let q = clamp(within, [p[0] + d[0], p[1] + d[1]]);
                let cq = cost(geometry, observed, q);
                if cq < c {
                    let small =
                        (q[0] - p[0]).abs() < 1e-14 * p[0] && (q[1] - p[1]).abs() < 1e-14 * p[1];
                    (p, c) = (q, cq);
                    lambda = (lambda * 0.3).max(1e-12);
                    moved = !small;
                    break;
                }
            }
            lambda *= 10.0;
        }
        if !moved || c == 0.0 {
            break;
        }
    }
    (p, c)
}

/// The least-squares fits of the exact square kinematics to the centres of
/// gravity `observed` within `r` (`E_d` × `E_b`), each with its
/// root-mean-square residual over the four coordinates (m), best first:
/// from every local minimum of a grid, a fine line scan's and `start`
/// (Borenstein's estimate), each refined by Levenberg–Marquardt; distinct local minima
/// are kept apart. Empty only if the model is undefined everywhere.
pub(super) fn fits(
    geometry: &SquareTest,
    observed: [f64; 4],
    start: Systematic,
    r: &Ranges,
) -> Vec<(Systematic, f64)> {
    // Even steps of `w = (E_d − 1)/(E_d + 1)` and `u = 1/E_b`.
    let step = |lo: f64, hi: f64, i: usize| lo + (hi - lo) * i as f64 / (GRID - 1) as f64;
    let eds: [f64; GRID] = std::array::from_fn(|i| ed_step(r, GRID, i));
    let ebs: [f64; GRID] = std::array::from_fn(|i| 1.0 / step(1.0 / r[1][1], 1.0 / r[1][0], i));
    let mut grid = [[0.0; GRID]; GRID];
    for (i, &ed) in eds.iter().enumerate() {
        for (k, &eb) in ebs.iter().enumerate() {
            grid[i][k] = cost(geometry, &observed, [ed, eb]);
        }
    }
    // The grid's local minima (no lower neighbour), lowest first.
    let mut minima = Vec::new();
    for i in 0..GRID {
        for k in 0..GRID {
            let c = grid[i][k];
            let lower_near = (i.saturating_sub(1)..=(i + 1).min(GRID - 1)).any(|a| {
                (k.saturating_sub(1)..=(k + 1).min(GRID - 1))
                    .any(|b| (a, b) != (i, k) && grid[a][b] < c)
            });
            if c.is_finite() && !lower_near {
                minima.push((c, [eds[i], ebs[k]]));
            }
        }
    }
    // Every one of them, not the lowest few: near a robot whose legs are
    // long arcs the cost is steep, so the grid points around its basin cost
    // more than a shallow wrong valley's (E_d 1.344, E_b 1.982 on a 7.3 m
    // square: its basin's grid minima ranked 70th and 73rd of 87).
    let mut starts: Vec<[f64; 2]> = minima.iter().map(|m| m.1).collect();
    if inside(r, [start.ed, start.eb]) {
        starts.push([start.ed, start.eb]);
    }
    starts.extend(line_minima(geometry, &observed, r, start.eb));
    // Every start screened, the best refined to the end.
    let mut screened: Vec<([f64; 2], f64)> = starts
        .into_iter()
        .map(|s| descend(geometry, &observed, r, s, SCREEN))
        .collect();
    screened.sort_by(|a, b| a.1.total_cmp(&b.1));
    let mut found: Vec<([f64; 2], f64)> = Vec::new();
    for (s, _) in screened.into_iter().take(STARTS) {
        let (p, c) = descend(geometry, &observed, r, s, 200);
        let same = |q: &[f64; 2]| (0..2).all(|k| (q[k] - p[k]).abs() <= SAME * p[k]);
        match found.iter_mut().find(|(q, _)| same(q)) {
            Some(f) if c < f.1 => *f = (p, c),
            Some(_) => {}
            None => found.push((p, c)),
        }
    }
    found.sort_by(|a, b| a.1.total_cmp(&b.1));
    found
        .into_iter()
        .map(|([ed, eb], c)| (Systematic { ed, eb }, (c / 4.0).sqrt()))
        .collect()
}
