//! A velocity base whose acceleration limit acted during the log: the lag
//! with its rate clamp in the loop (`crate::base`), fitted exactly from the
//! run's running integrals.
//!
//! The plant ([`crate::base::VelocityBase::accelerations`]) moves each
//! velocity at the lag's rate `(v_c − v)/τ` unless that exceeds the limit;
//! then at the limit `±a_max` exactly when this axis binds (per axis, or
//! jointly when this axis's ratio to its limit is the larger), or at the
//! lag's rate scaled by the other axis's limit (joint, the other axis
//! binding). Integrated over a log interval `[t_j, t_{j+1}]` of RK4 steps:
//!
//! - **free** (no stage limited): `Δx_j = (ΔI_j − ΔS_j)/τ`, the lag's
//!   integral form, exact whatever the input did in between (the integrals
//!   are RK4-weighted as the plant's steps are: [`super::fit_integral`]);
//! - **on the limit** (every stage of every step limited, this axis
//!   binding): `Δx_j = ±a h_j`, exact (RK4 of a constant rate);
//! - **unknown** (the limit took hold or let go inside the interval, or the
//!   other axis's limit scaled this one): `Δx_j` is left free, one nuisance
//!   parameter per such interval — the log splits into segments, each with
//!   its own offset.
//!
//! So `x_k = c_{seg(k)} + (1/τ) F_k + a L_k` with `F_k = Σ_{free j<k}(ΔI_j −
//! ΔS_j)`, `L_k = Σ_{limited j<k} sign_j h_j`: linear least squares in the
//! segments' offsets, `1/τ` and `a`, exact on a noise-free log, with white
//! residuals under measurement noise (so `σ² (XᵀX)⁻¹` is the covariance).
//!
//! Which interval is which follows from the model itself: the lag's rate at
//! the interval's ends (the fitted velocity at either end, under the logged
//! applied command at the start or at the end), over the limit by more than [`MARGIN`] on
//! both ends (and binding over the other axis by as much) is on the limit,
//! under it by as much on both ends (on both axes) is free, anything else
//! unknown; a free interval next to one that is not is left out too (a
//! step between the samples may ride the limit for less than an interval).
//! Classification and fit alternate until the classes repeat, from each
//! axis's limit alone and from both (an axis without a limit would shadow
//! the other's), and the start whose fit leaves the smallest residuals wins.

use super::{AxisData, AxisFit, AxisIntegrals, cost, inverse_spd, rcond};

/// Relative margin around a limit inside which an interval's class is left
/// unknown (it may have switched between the samples).
pub(crate) const MARGIN: f64 = 0.02;
/// Most classification passes.
const MAX_PASSES: usize = 60;

/// What the lag did over one log interval.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Class {
    /// Not limited: the lag's integral form.
    Free,
    /// On the limit, moving up (`+1`) or down (`−1`).
    Limited(f64),
    /// Switched inside, or scaled by the other axis's limit.
    Unknown,
}

/// The rate-limited fit of one axis.
#[derive(Debug, Clone)]
pub(crate) struct LimitedFit {
    /// The lag `[τ, 1]`, its covariance, prediction and residual RMS (as the
    /// lag-only fits give them).
    pub(crate) fit: AxisFit,
    /// The rate limit and its variance, when some interval rode it.
    pub(crate) limit: Option<(f64, f64)>,
    /// Intervals on the limit.
    pub(crate) limited: usize,
    /// Intervals left out (class unknown).
    pub(crate) unknown: usize,
}

/// The axis fitted for a given classification.
fn solve(d: &AxisData<'_>, w: &AxisIntegrals<'_>, classes: &[Class], guess: f64) -> LimitedFit {
    let n = d.t.len();
    // Cumulative regressors and the segments the unknown intervals cut.
    let (mut f, mut l, mut seg) = (vec![0.0; n], vec![0.0; n], vec![0usize; n]);
    let (mut limited, mut unknown) = (0, 0);
    for j in 0..n - 1 {
        let (mut df, mut dl, mut cut) = (0.0, 0.0, 0);
        match classes[j] {
            Class::Free => df = (w.i[j + 1] - w.i[j]) - (w.s[j + 1] - w.s[j]),
            Class::Limited(sign) => {
                dl = sign * (d.t[j + 1] - d.t[j]);
                limited += 1;
            }
            Class::Unknown => {
                cut = 1;
                unknown += 1;
            }
        }
        f[j + 1] = f[j] + df;
        l[j + 1] = l[j] + dl;
        seg[j + 1] = seg[j] + cut;
    }
    let segments = seg[n - 1] + 1;
    // Offsets projected out: each column less its segment's mean.
    let mut sums = vec![[0.0; 4]; segments];
    for k in 0..n {
        let s = &mut sums[seg[k]];
        s[0] += 1.0;
        s[1] += f[k];
        s[2] += l[k];
        s[3] += d.y[k];
    }
    let centred = |k: usize| {
        let s = sums[seg[k]];
        [f[k] - s[1] / s[0], l[k] - s[2] / s[0], d.y[k] - s[3] / s[0]]
    };
    let mut a = [[0.0; 2]; 2];
    let mut b = [0.0; 2];
    for k in 0..n {
        let [fc, lc, yc] = centred(k);
        a[0][0] += fc * fc;
        a[0][1] += fc * lc;
        a[1][1] += lc * lc;
        b[0] += fc * yc;
        b[1] += lc * yc;
    }
    a[1][0] = a[0][1];
    let with_limit = limited > 0;
    let (inv, rc) = if with_limit {
        (inverse_spd(&a), rcond(&a))
    } else {
        let ok = a[0][0] > 0.0;
        (
            ok.then(|| [[1.0 / a[0][0], 0.0], [0.0, 0.0]]),
            if ok { 1.0 } else { 0.0 },
        )
    };
    let inv = inv.unwrap_or([[f64::NAN; 2]; 2]);
    let beta = inv[0][0] * b[0] + inv[0][1] * b[1];
    let rate = if with_limit {
        inv[1][0] * b[0] + inv[1][1] * b[1]
    } else {
        0.0
    };
    let predicted: Vec<f64> = (0..n)
        .map(|k| {
            let s = sums[seg[k]];
            let [fc, lc, _] = centred(k);
            s[3] / s[0] + beta * fc + rate * lc
        })
        .collect();
    let c = cost(d.y, &predicted);
    let params = segments + 1 + usize::from(with_limit);
    let sigma2 = c / n.saturating_sub(params).max(1) as f64;
    let tau = 1.0 / beta;
    let var_tau = sigma2 * inv[0][0] / beta.powi(4);
    LimitedFit {
        fit: AxisFit {
            theta: [tau, 1.0],
            cov: [[var_tau, 0.0], [0.0, 0.0]],
            x0: predicted[0],
            first_guess: [guess, 1.0],
            rms: (c / n as f64).sqrt(),
            predicted,
            rcond: rc,
            between: None,
            segments: Some(seg),
        },
        limit: with_limit.then_some((rate, sigma2 * inv[1][1])),
        limited,
        unknown,
    }
}

/// The classes of both axes' intervals for lags `tau`, limits `limit`
/// (infinite: none) and the fitted velocities `x`.
fn classify(
    d: [&AxisData<'_>; 2],
    x: [&[f64]; 2],
    tau: [f64; 2],
    limit: [f64; 2],
) -> [Vec<Class>; 2] {
    let n = d[0].t.len();
    let mut out = [vec![Class::Unknown; n - 1], vec![Class::Unknown; n - 1]];
    for j in 0..n - 1 {
        // The lag's rates at the interval's start and end, under the
        // command logged at either (it may switch in between: the rate just
        // after is between the last two).
        let points = [(j, j), (j, j + 1), (j + 1, j), (j + 1, j + 1)];
        let ratio = |axis: usize, (ui, xi): (usize, usize)| {
            (d[axis].u[ui] - x[axis][xi]) / tau[axis] / limit[axis]
        };
        for axis in 0..2 {
            let other = 1 - axis;
            let mut free = true;
            let mut sign = 0.0;
            let mut on = true;
            for p in points {
                let (mine, theirs) = (ratio(axis, p), ratio(other, p));
                free &= mine.abs() <= 1.0 - MARGIN && theirs.abs() <= 1.0 - MARGIN;
                let s = mine.signum();
                on &= mine.abs() >= 1.0 + MARGIN
                    && mine.abs() >= (1.0 + MARGIN) * theirs.abs()
                    && (sign == 0.0 || s == sign);
                sign = s;
            }
            out[axis][j] = if free {
                Class::Free
            } else if on {
                Class::Limited(sign)
            } else {
                Class::Unknown
            };
        }
    }
    // A free interval next to one that is not: the command between the
    // samples is not logged, and may have reached the limit in between.
    for classes in &mut out {
        let was = classes.clone();
        for j in 0..n - 1 {
            let near = |k: Option<usize>| {
                k.and_then(|k| was.get(k))
                    .is_some_and(|c| *c != Class::Free)
            };
            if was[j] == Class::Free && (near(j.checked_sub(1)) || near(Some(j + 1))) {
                classes[j] = Class::Unknown;
            }
        }
    }
    out
}

/// Fits both axes of a velocity base with rate limits from the log's
/// integrals, starting from the lag-only fits `start` and the limits
/// `candidate` (the largest rate each axis showed; infinite: none).
/// `None` unless some interval rode a limit when the classes settled.
pub(crate) fn fit_limited(
    d: [&AxisData<'_>; 2],
    w: [&AxisIntegrals<'_>; 2],
    start: [&AxisFit; 2],
    candidate: [f64; 2],
) -> Option<[LimitedFit; 2]> {
    let n = d[0].t.len();
    if n < 3
        || start
            .iter()
            .any(|f| !(f.theta[0] > 0.0 && f.theta[0].is_finite()))
    {
        return None;
    }
    let guess = [start[0].theta[0], start[1].theta[0]];
    // First pass: the intervals whose measured rate (over 5 samples, noise
    // averaged) comes near the largest left out, so that the lag fitted
    // through the rest is not stretched by the limit.
    let span = 5.min(n - 1);
    let mut first = [vec![Class::Free; n - 1], vec![Class::Free; n - 1]];
    for axis in 0..2 {
        for i in 0..n - span {
            let r =
                ((d[axis].y[i + span] - d[axis].y[i]) / (d[axis].t[i + span] - d[axis].t[i])).abs();
            if r >= 0.7 * candidate[axis] {
                for c in &mut first[axis][i..i + span] {
                    *c = Class::Unknown;
                }
            }
        }
    }
    let first = [0, 1].map(|a| solve(d[a], w[a], &first[a], guess[a]));
    // Either axis's limit, or both: the largest rate an axis without a
    // limit showed is no limit, and would shadow the other's.
    let [cv, cw] = candidate;
    let inf = f64::INFINITY;
    let mut best: Option<([LimitedFit; 2], f64)> = None;
    for limit in [[cv, cw], [cv, inf], [inf, cw]] {
        let Some(fits) = settle(d, w, first.clone(), limit, guess) else {
            continue;
        };
        if fits.iter().all(|f| f.limited == 0) {
            continue;
        }
        // Residuals relative to the lag-only fits', summed over the axes.
        let score: f64 = (0..2)
            .map(|a| (fits[a].fit.rms / start[a].rms.max(f64::MIN_POSITIVE)).powi(2))
            .sum();
        if best.as_ref().is_none_or(|(_, s)| score < *s) {
            best = Some((fits, score));
        }
    }
    best.map(|(fits, _)| fits)
}

/// Alternates classification and fit from `fits` and the limits `limit`
/// until the classes repeat; `None` if a lag leaves the physical range.
fn settle(
    d: [&AxisData<'_>; 2],
    w: [&AxisIntegrals<'_>; 2],
    mut fits: [LimitedFit; 2],
    mut limit: [f64; 2],
    guess: [f64; 2],
) -> Option<[LimitedFit; 2]> {
    let mut last: Option<[Vec<Class>; 2]> = None;
    for _ in 0..MAX_PASSES {
        let tau = [fits[0].fit.theta[0], fits[1].fit.theta[0]];
        if tau.iter().any(|t| !(*t > 0.0 && t.is_finite())) {
            return None;
        }
        let classes = classify(
            d,
            [&fits[0].fit.predicted, &fits[1].fit.predicted],
            tau,
            limit,
        );
        if last.as_ref() == Some(&classes) {
            break;
        }
        fits = [0, 1].map(|a| solve(d[a], w[a], &classes[a], guess[a]));
        for a in 0..2 {
            limit[a] = match fits[a].limit {
                Some((r, _)) if r > 0.0 && r.is_finite() => r,
                _ => f64::INFINITY,
            };
        }
        last = Some(classes);
    }
    Some(fits)
}
