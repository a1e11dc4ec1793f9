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
    let h = lags as f64;
    // z for a 0.1 % upper tail.
    let z = 3.090_232_306_167_813;
    let a = 2.0 / (9.0 * h);
    let crit = h * (1.0 - a + z * a.sqrt()).powi(3);
    (q, crit, rho(1))
}

/// A multi-scale scan of the residuals' local means: the largest
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
    let bound = (2.0 * (2.0 * windows.max(1) as f64 / 1e-3).ln()).sqrt();
    if sigma > 0.0 {
        (best, bound, at)
    } else {
        (0.0, bound, at)
    }
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
