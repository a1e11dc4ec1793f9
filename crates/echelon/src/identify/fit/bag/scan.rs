//! The bounds stage 3 of the bag fit falls back on (`super::refine`): the
//! dead time by a likelihood-ratio scan when no lagged axis is left, and an
//! unresolved lag's 95 % upper bound from the profile of its cost.

use super::super::Z95;
use super::{BagData, CHI2_1_95, MAX_DELAY, P, simulate, tau_at};

/// Spacing of the likelihood-ratio scan of the dead time, s.
const SCAN_STEP: f64 = 2e-4;

/// The dead time of axes `axes` (their other parameters held at `p`) by a
/// scan over `[0, MAX_DELAY]`: the delay minimising `Σ n ln(cost)`, and the
/// variance that makes its 95 % interval the delays whose statistic is
/// within χ²₁'s 95 % quantile of the minimum (at least a scan step wide).
pub(super) fn delay_scan(d: &BagData<'_>, p: &[f64; P], axes: &[usize]) -> (f64, f64) {
    let n = d.t.len();
    let mut x = vec![0.0; n];
    let steps = (MAX_DELAY / SCAN_STEP).round() as usize;
    let scores: Vec<(f64, f64)> = (0..=steps)
        .map(|k| {
            let mut q = *p;
            q[0] = k as f64 * SCAN_STEP;
            let score = axes
                .iter()
                .map(|&a| {
                    simulate(d, a, &q, &mut x);
                    let c: f64 = d.y[a].iter().zip(&x).map(|(y, x)| (y - x).powi(2)).sum();
                    n as f64 * c.max(f64::MIN_POSITIVE).ln()
                })
                .sum();
            (q[0], score)
        })
        .collect();
    let best = scores.iter().fold(
        (f64::NAN, f64::INFINITY),
        |m, s| if s.1 < m.1 { *s } else { m },
    );
    let within = scores.iter().filter(|s| s.1 - best.1 <= CHI2_1_95);
    let (lo, hi) = within.fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), s| {
        (l.min(s.0), h.max(s.0))
    });
    let half = (0.5 * (hi - lo)).max(SCAN_STEP);
    (0.5 * (lo + hi), (half / Z95).powi(2))
}

/// The 95 % upper bound of axis `axis`'s lag from the profile of its cost
/// (the other parameters held at `p`): the lag at which the cost rises by
/// χ²₁'s 95 % quantile times the residual variance; infinite if even two
/// odometry periods fit as well.
pub(super) fn lag_bound(d: &BagData<'_>, axis: usize, p: &[f64; P]) -> f64 {
    let n = d.t.len();
    let i = tau_at(axis);
    let mut x = vec![0.0; n];
    let mut cost = |tau: f64| {
        let mut q = *p;
        q[i] = tau;
        simulate(d, axis, &q, &mut x);
        d.y[axis]
            .iter()
            .zip(&x)
            .map(|(y, x)| (y - x).powi(2))
            .sum::<f64>()
    };
    let c0 = cost(p[i]);
    let limit = c0 + CHI2_1_95 * c0 / n.saturating_sub(3).max(1) as f64;
    let mut period: Vec<f64> = d.t.windows(2).map(|w| w[1] - w[0]).collect();
    period.sort_by(f64::total_cmp);
    let hi0 = 2.0 * period.get(period.len() / 2).copied().unwrap_or(0.0);
    let top = cost(hi0);
    if top.is_nan() || top <= limit {
        return f64::INFINITY;
    }
    let (mut lo, mut hi) = (p[i], hi0);
    for _ in 0..40 {
        let mid = 0.5 * (lo + hi);
        if cost(mid) > limit {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    hi
}
