//! The first stage's guesses: the largest rate seen, the hold shifted by a
//! dead time, the median odometry period, a first lag and the dead-time grid.

use super::*;

/// The largest rate of `y` over 5-sample spans, the start of the limit.
pub(super) fn largest_rate(t: &[f64], y: &[f64]) -> f64 {
    crate::identify::limits::largest_rate(t, y).0
}

/// The hold shifted by `delay`, averaged over each odometry interval (the
/// last sample: the value in force there).
pub(super) fn shifted_average(d: &BagData<'_>, axis: usize, delay: f64) -> Vec<f64> {
    let (ht, hu, t) = (d.hold_t, d.hold_u[axis], d.t);
    let in_force = |s: f64| ht.partition_point(|h| *h + delay <= s).saturating_sub(1);
    let mut out = Vec::with_capacity(t.len());
    for k in 0..t.len() {
        let Some(&end) = t.get(k + 1) else {
            out.push(hu[in_force(t[k])]);
            break;
        };
        let mut j = in_force(t[k]);
        let (mut from, mut acc) = (t[k], 0.0);
        loop {
            let to = match ht.get(j + 1) {
                Some(h) if h + delay < end => (h + delay).max(from),
                _ => end,
            };
            acc += (to - from) * hu[j];
            from = to;
            if to >= end {
                break;
            }
            j += 1;
        }
        out.push(acc / (end - t[k]));
    }
    out
}

/// The median odometry period, s.
pub(super) fn median_period(t: &[f64]) -> f64 {
    let mut periods: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    periods.sort_by(f64::total_cmp);
    periods.get(periods.len() / 2).copied().unwrap_or(f64::NAN)
}

/// The first guess of the joint vector at no dead time: each axis's lag by
/// equation error (0.1 s when that gives nothing plausible), its first
/// sample as `x₀`, no limit.
pub(super) fn first_guess(d: &BagData<'_>) -> [f64; P] {
    let mut p = [0.0; P];
    for a in 0..2 {
        let guess = equation_error(
            &super::super::AxisData {
                t: d.t,
                u: &shifted_average(d, a, 0.0),
                y: d.y[a],
                hold: None,
            },
            true,
        )
        .0[0];
        p[tau_at(a)] = if guess.is_finite() && guess > 0.0 && guess < 5.0 {
            guess
        } else {
            0.1
        };
        p[tau_at(a) + 2] = d.y[a][0];
    }
    p
}

/// Stage 1: the dead time on the [`DELAY_STEP`] grid, the lags alone fitted
/// at each delay warm-started from the previous one; the vector that
/// minimises the profile likelihood `Σ_axis ln(cost)`.
pub(super) fn delay_grid(d: &BagData<'_>, mut p: [f64; P]) -> [f64; P] {
    let mut best: Option<([f64; P], f64)> = None;
    let steps = (MAX_DELAY / DELAY_STEP).round() as usize;
    for k in 0..=steps {
        p[0] = k as f64 * DELAY_STEP;
        let mut score = 0.0;
        for a in 0..2 {
            let (q, c) = fit_axis(d, a, p, false);
            p = q;
            score += c.max(f64::MIN_POSITIVE).ln();
        }
        if best.as_ref().is_none_or(|(_, s)| score < *s) {
            best = Some((p, score));
        }
    }
    let Some((p, _)) = best else {
        unreachable!("the grid has at least one point")
    };
    p
}
