//! Whether a fitted parameter gets a number: the input excited it
//! ([`excitation`]) and the model fits the log ([`misfit`], the residual
//! checks).

use serde::Serialize;

use super::fit;
use super::fit::{AxisData, AxisFit};
use super::{Estimate, MAX_REL_HALF_WIDTH, MIN_RCOND};

/// Why an axis's parameters are not identifiable, or `None` if they are;
/// with it, whether the input drove the axis and only the intervals came
/// out wider than [`MAX_REL_HALF_WIDTH`] (`true`: a model that misfits the
/// log widens them too, and then the misfit is the reason, not the input).
pub(super) fn excitation(
    d: &AxisData<'_>,
    f: &AxisFit,
    estimates: &[Estimate],
    input: &str,
) -> Option<(String, bool)> {
    unexcited(d, f, input)
        .map(|why| (why, false))
        .or_else(|| too_wide(f, estimates).map(|why| (why, true)))
}

/// Why the input could not identify the axis at all: zero, constant, a badly
/// conditioned regressor.
fn unexcited(d: &AxisData<'_>, f: &AxisFit, input: &str) -> Option<String> {
    let u_max = d.u.iter().fold(0.0_f64, |m, u| m.max(u.abs()));
    let u_min = d.u.iter().fold(f64::INFINITY, |m, u| m.min(*u));
    let u_top = d.u.iter().fold(f64::NEG_INFINITY, |m, u| m.max(*u));
    if u_max <= 1e-12 {
        return Some(format!(
            "{input} is zero throughout (nothing drove this axis; a log with no rotation cannot give J, ψ)"
        ));
    }
    if u_top - u_min <= 1e-9 * u_max {
        return Some(format!(
            "{input} is constant: a step or chirp is needed to separate the lag from the gain"
        ));
    }
    if f.rcond.is_nan() || f.rcond < MIN_RCOND {
        return Some(format!(
            "the regressor is badly conditioned (reciprocal condition number {:.1e})",
            f.rcond
        ));
    }
    None
}

/// Why the estimates get no number although the input drove the axis: a
/// non-physical value, or a 95 % interval wider than [`MAX_REL_HALF_WIDTH`].
fn too_wide(f: &AxisFit, estimates: &[Estimate]) -> Option<String> {
    for e in estimates {
        if !e.value.is_finite() || e.value <= 0.0 || !e.std.is_finite() {
            return Some(format!(
                "the fit gave a non-physical value ({:.3e})",
                e.value
            ));
        }
        let rel = e.relative_half_width();
        if rel > MAX_REL_HALF_WIDTH {
            return Some(if f.between.is_some() {
                format!(
                    "95 % interval ±{:.1} % of the value, more than ±{:.0} %: it includes the difference between holding and interpolating the inputs between samples, which the log does not have (log every control step, or identify from a run directory with its integrals.csv)",
                    100.0 * rel,
                    100.0 * MAX_REL_HALF_WIDTH
                )
            } else {
                format!(
                    "the input did not excite it enough: 95 % interval ±{:.1} % of the value, more than ±{:.0} %",
                    100.0 * rel,
                    100.0 * MAX_REL_HALF_WIDTH
                )
            });
        }
    }
    None
}

/// Lags of the Ljung–Box whiteness test.
pub const WHITENESS_LAGS: usize = 10;

/// Largest ratio of the residual RMS to the noise the measurement shows by
/// itself (RMS of its second differences over `√6`, an upper bound of white
/// noise's RMS); larger, the residuals are not noise but misfit.
pub const MAX_RESIDUAL_OVER_NOISE: f64 = 1.5;

/// The residual checks of one axis (`misfit`), as `identify.json`
/// reports them.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ResidualChecks {
    /// Ljung–Box statistic over [`WHITENESS_LAGS`] lags.
    pub ljung_box_q: f64,
    /// Its 99.9 % bound (χ², Wilson–Hilferty).
    pub ljung_box_bound: f64,
    /// Lag-1 autocorrelation of the residuals.
    pub lag1_autocorrelation: f64,
    /// Largest local mean of the residuals, in standard errors.
    pub scan_z: f64,
    /// Its 99.9 % bound (Bonferroni over the windows).
    pub scan_bound: f64,
    /// Where it was found, `[from, to]` s.
    pub scan_window: [f64; 2],
    /// The noise the measurement shows by itself (second differences).
    pub noise_from_differences: f64,
    /// A score test of the lag against a limit on its rate (an acceleration
    /// limit, or a delay, slowing the fastest transients), in standard
    /// errors: the largest over the limits tried (see `transient_bound`).
    pub transient_z: f64,
    /// Its 99.9 % bound (Bonferroni over the limits tried).
    pub transient_bound: f64,
    /// The rate limit it was found at (m/s² or rad/s² on a velocity base).
    pub transient_rate: f64,
}

impl ResidualChecks {
    pub(super) fn new(d: &AxisData<'_>, f: &AxisFit) -> ResidualChecks {
        let r: Vec<f64> = d.y.iter().zip(&f.predicted).map(|(y, p)| y - p).collect();
        let (ljung_box_q, ljung_box_bound, lag1_autocorrelation) = match &f.segments {
            Some(seg) => fit::ljung_box_segmented(&r, seg, WHITENESS_LAGS),
            None => fit::ljung_box(&r, WHITENESS_LAGS),
        };
        let (scan_z, scan_bound, [a, b]) = fit::scan(&r);
        let gain = f.cov[1][1] > 0.0;
        let (transient_z, transient_bound, transient_rate) =
            fit::transients(d.t, (d.u, &f.predicted, &r), (f.theta[0], f.theta[1]), gain);
        ResidualChecks {
            ljung_box_q,
            ljung_box_bound,
            lag1_autocorrelation,
            scan_z,
            scan_bound,
            scan_window: [d.t[a], d.t[b]],
            noise_from_differences: fit::noise_from_differences(d.y),
            transient_z,
            transient_bound,
            transient_rate,
        }
    }
}

/// Why the model misfits the log (its residuals are not the measurement's
/// white noise), or `None`. Called on logs that are not noise-free: a
/// noise-free log whose residuals are not at rounding level is misfit, and
/// shows as residuals far above the (rounding-level) noise and not white.
pub(super) fn misfit(f: &AxisFit, c: &ResidualChecks, exact: bool) -> Option<String> {
    let (q, crit, rho1) = (c.ljung_box_q, c.ljung_box_bound, c.lag1_autocorrelation);
    let noise = c.noise_from_differences;
    let hint = if exact {
        " (the model does not describe this plant)"
    } else {
        " (the input varies between samples and the log holds only its sampled values: \
         log every control step, or identify from a run directory with its integrals.csv)"
    };
    if q > crit {
        return Some(format!(
            "the model misfits this log: its residuals are not white (Ljung–Box Q = {q:.0} over {WHITENESS_LAGS} lags, 99.9 % bound {crit:.1}; lag-1 autocorrelation {rho1:.2}){hint}"
        ));
    }
    let (z, bound, [a, b]) = (c.scan_z, c.scan_bound, c.scan_window);
    if z > bound {
        return Some(format!(
            "the model misfits this log: its residuals keep one sign from t = {a:.3} s to {b:.3} s (local mean {z:.1} standard errors, 99.9 % bound {bound:.1}){hint}"
        ));
    }
    let (z, bound) = (c.transient_z, c.transient_bound);
    if z.abs() > bound {
        return Some(format!(
            "the model misfits this log on its fastest transients: its residuals follow what a limit of {:.3} on the rate would change ({:.1} standard errors, 99.9 % bound {bound:.1}) — an acceleration limit or a delay acted there, and the lag fitted through them is biased (log gentler steps){hint}",
            c.transient_rate,
            z.abs()
        ));
    }
    if f.rms > MAX_RESIDUAL_OVER_NOISE * noise {
        return Some(format!(
            "the model misfits this log: its residual RMS {:.2e} is {:.1} times the noise the measurement shows by itself ({noise:.2e}){hint}",
            f.rms,
            f.rms / noise
        ));
    }
    None
}
