//! Tests of a fit's residuals: Ljung–Box whiteness, the multi-scale scan of
//! their local means, and the noise the measurement shows by itself.

/// Whiteness of residuals: the Ljung–Box statistic over `lags` lags, its
/// 99.9 % critical value (χ² with `lags` degrees of freedom, Wilson–Hilferty)
/// and the lag-1 autocorrelation.
pub(crate) fn ljung_box(r: &[f64], lags: usize) -> (f64, f64, f64) {
    let n = r.len();
    let mean = r.iter().sum::<f64>() / n as f64;
    let c0: f64 = r.iter().map(|x| (x - mean) * (x - mean)).sum();
    let rho = |j: usize| -> f64 {
        if c0 <= 0.0 {
            return 0.0;
        }
        (0..n - j)
            .map(|k| (r[k] - mean) * (r[k + j] - mean))
            .sum::<f64>()
            / c0
    };
    let nf = n as f64;
    let q = nf
        * (nf + 2.0)
        * (1..=lags)
            .map(|j| rho(j).powi(2) / (nf - j as f64))
            .sum::<f64>();
    (q, ljung_box_bound(lags), rho(1))
}

/// The 99.9 % critical value of χ² with `lags` degrees of freedom
/// (Wilson–Hilferty).
fn ljung_box_bound(lags: usize) -> f64 {
    let h = lags as f64;
    // z for a 0.1 % upper tail.
    let z = 3.090_232_306_167_813;
    let a = 2.0 / (9.0 * h);
    h * (1.0 - a + z * a.sqrt()).powi(3)
}

/// [`ljung_box`] for residuals of a fit that gave each segment of samples
/// its own offset (`seg`: each sample's segment, non-decreasing): their
/// autocovariance is that of white noise less `σ²/L` between any two
/// samples of a segment of `L`, which short segments make large; that
/// expected part is added back before the statistic is formed.
pub(crate) fn ljung_box_segmented(r: &[f64], seg: &[usize], lags: usize) -> (f64, f64, f64) {
    let n = r.len().min(seg.len());
    let segments = seg[..n].last().map_or(0, |s| s + 1);
    let mut len = vec![0usize; segments];
    for s in &seg[..n] {
        len[*s] += 1;
    }
    let c0: f64 = r[..n].iter().map(|x| x * x).sum();
    let sigma2 = c0 / n.saturating_sub(segments).max(1) as f64;
    let rho = |j: usize| -> f64 {
        if c0 <= 0.0 {
            return 0.0;
        }
        let raw: f64 = (0..n - j).map(|k| r[k] * r[k + j]).sum();
        let expected: f64 = -sigma2
            * len
                .iter()
                .map(|l| l.saturating_sub(j) as f64 / (*l).max(1) as f64)
                .sum::<f64>();
        (raw - expected) / c0
    };
    let nf = n as f64;
    let q = nf
        * (nf + 2.0)
        * (1..=lags.min(n.saturating_sub(1)))
            .map(|j| rho(j).powi(2) / (nf - j as f64))
            .sum::<f64>();
    (q, ljung_box_bound(lags), rho(1))
}

/// A multi-scale scan of the residuals' local means: the largest
/// The 99.9 % bound on the largest `|z|` of `tests` standard normal
/// statistics (Bonferroni, with the Gaussian tail bound):
/// `√(2 ln(2M/0.001))` for `M = tests` (at least one).
fn bonferroni_999(tests: usize) -> f64 {
    (2.0 * (2.0 * tests.max(1) as f64 / 1e-3).ln()).sqrt()
}

/// `|Σ r| / (σ √L)` over windows of `L = 8, 16, …` samples (up to half the
/// log) at strides of `L/2`, `σ` the residual RMS; with its 99.9 % bound
/// (Bonferroni over the windows: `√(2 ln(2M/0.001))` for `M` windows) and
/// the window `[first, last]` sample it was found in. White residuals stay
/// under the bound; a misfit confined to a transient (which a whiteness test
/// over the whole log dilutes) shows as a run of residuals of one sign.
pub(crate) fn scan(r: &[f64]) -> (f64, f64, [usize; 2]) {
    let n = r.len();
    let sigma = (r.iter().map(|x| x * x).sum::<f64>() / n as f64).sqrt();
    let mut prefix = Vec::with_capacity(n + 1);
    prefix.push(0.0);
    for x in r {
        prefix.push(prefix[prefix.len() - 1] + x);
    }
    let (mut best, mut at, mut windows) = (0.0_f64, [0, 0], 0_usize);
    let mut len = 8;
    while len <= n / 2 {
        let stride = len / 2;
        let mut start = 0;
        while start + len <= n {
            windows += 1;
            let z = (prefix[start + len] - prefix[start]).abs() / (sigma * (len as f64).sqrt());
            if z > best {
                (best, at) = (z, [start, start + len - 1]);
            }
            start += stride;
        }
        len *= 2;
    }
    let bound = bonferroni_999(windows);
    if sigma > 0.0 {
        (best, bound, at)
    } else {
        (0.0, bound, at)
    }
}

/// Rate limits [`transients`] tries: `0.8, 0.8², … 0.8⁹` of the model's
/// largest rate (down to 13 %).
const LIMITS: usize = 9;
/// The ratio between two tried limits.
const LIMIT_RATIO: f64 = 0.8;

/// A score test of the lag against a rate limit (or anything that slows the
/// axis on its fastest transients, as a delay): for each tried limit `A`,
/// the output change the limit would make to first order, `g` (the model's
/// rate beyond `A`, `sign(ẋ) max(|ẋ| − A, 0)`, through the lag), with the
/// part the fitted parameters can absorb projected out (the sensitivities
/// of the output to `τ`, to the gain when it is fitted, and to `x₀`); then
/// `z = gᵀr / (σ ‖g‖)`, `σ` the residual RMS. Under the model the residuals
/// `r` are white and `z` a standard normal for each `A`. A fit through
/// transients that a limit cut stretches its lag to follow them and leaves
/// residuals along `g`, which a whiteness test over the whole log dilutes.
///
/// `t`, `u`, `x`: the samples' times, inputs and the model's prediction;
/// `tau`, `k`: the fit; `gain`: whether `k` was fitted. Returns the largest
/// `|z|` (signed), its 99.9 % bound (Bonferroni over the limits, as
/// [`scan`]'s) and the limit `A` it was found at.
pub(crate) fn transients(
    t: &[f64],
    (u, x, r): (&[f64], &[f64], &[f64]),
    (tau, k): (f64, f64),
    gain: bool,
) -> (f64, f64, f64) {
    let n = t.len().min(u.len()).min(x.len()).min(r.len());
    let bound = bonferroni_999(LIMITS);
    let rate: Vec<f64> = (0..n).map(|i| (k * u[i] - x[i]) / tau).collect();
    let top = rate.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
    let sigma = (r[..n].iter().map(|x| x * x).sum::<f64>() / n.max(1) as f64).sqrt();
    if n < 3 || !(sigma > 0.0 && top > 0.0 && top.is_finite() && tau > 0.0) {
        return (0.0, bound, top);
    }
    // The lag as a filter: `y_{i+1} = a y_i + (1 − a) w_i`, `a = e^{−Δt/τ}`.
    let lag = |w: &dyn Fn(usize) -> f64| -> Vec<f64> {
        let mut y = vec![0.0; n];
        for i in 0..n - 1 {
            let a = (-(t[i + 1] - t[i]) / tau).exp();
            y[i + 1] = a * y[i] + (1.0 - a) * w(i);
        }
        y
    };
    // What the fit absorbs, orthonormalised (Gram–Schmidt).
    let mut basis: Vec<Vec<f64>> = Vec::new();
    let mut directions = vec![lag(&|i| rate[i])];
    if gain {
        directions.push(lag(&|i| u[i]));
    }
    directions.push((0..n).map(|i| (-(t[i] - t[0]) / tau).exp()).collect());
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(p, q)| p * q).sum::<f64>();
    let project_out = |v: &mut Vec<f64>, basis: &[Vec<f64>]| {
        for e in basis {
            let c = dot(v, e);
            v.iter_mut().zip(e).for_each(|(p, q)| *p -= c * q);
        }
    };
    for mut d in directions {
        let before = dot(&d, &d).sqrt();
        project_out(&mut d, &basis);
        let norm = dot(&d, &d).sqrt();
        if norm > 1e-9 * before && norm > 0.0 {
            d.iter_mut().for_each(|p| *p /= norm);
            basis.push(d);
        }
    }
    let (mut best, mut at) = (0.0_f64, top);
    for j in 1..=LIMITS {
        let limit = top * LIMIT_RATIO.powi(j as i32);
        let mut g = lag(&|i| rate[i].signum() * (rate[i].abs() - limit).max(0.0));
        let before = dot(&g, &g).sqrt();
        project_out(&mut g, &basis);
        let norm = dot(&g, &g).sqrt();
        if !(norm > 1e-6 * before && norm > 0.0) {
            continue;
        }
        let z = dot(&g, &r[..n]) / (sigma * norm);
        if z.abs() > best.abs() {
            (best, at) = (z, limit);
        }
    }
    (best, bound, at)
}

/// The measurement noise the output shows by itself, model-free: the RMS of
/// its second differences over `√6` (white noise of RMS σ gives
/// `E[(y₊ − 2y + y₋)²] = 6σ²`; a smooth signal adds its curvature, so this
/// is an upper bound).
pub(crate) fn noise_from_differences(y: &[f64]) -> f64 {
    let n = y.len();
    if n < 3 {
        return f64::NAN;
    }
    let s: f64 = (1..n - 1)
        .map(|k| (y[k + 1] - 2.0 * y[k] + y[k - 1]).powi(2))
        .sum();
    (s / (6.0 * (n - 2) as f64)).sqrt()
}
