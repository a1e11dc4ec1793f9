//! The limits a velocity base's log shows: its speed limits, and its
//! acceleration limits as the rate-limited fit identified them or as
//! observed ([`super::identify`], `fit::fit_limited`).

use super::{Estimate, Limit, Log, MAX_REL_HALF_WIDTH, fit};

/// The acceleration limit of one axis as the rate-limited fit found it.
pub(super) struct RateLimit {
    /// The limit, when identified.
    estimate: Option<Estimate>,
    /// Why not, otherwise.
    why: Option<String>,
    noise_free: bool,
    /// Intervals on the limit.
    intervals: usize,
}

impl RateLimit {
    /// From the axis's rate-limited fit `l`, whose residuals are at rounding
    /// level (`noise_free`) or not, and whose lag was identified or not.
    pub(super) fn new(l: &fit::LimitedFit, noise_free: bool, lag_identified: bool) -> RateLimit {
        let e = l.limit.map(|(value, var)| Estimate::new(value, var, value));
        let why = match e {
            _ if !lag_identified => Some("the lag fitted with it is not identifiable".to_owned()),
            None => Some(if l.unknown > 0 {
                "it never bound on its own (the other axis's limit scaled this one, or the intervals where it took hold were left out)".to_owned()
            } else {
                "it never bound".to_owned()
            }),
            Some(e) if !(e.value.is_finite() && e.value > 0.0 && e.std.is_finite()) => Some(
                format!("the fit gave a non-physical value ({:.3e})", e.value),
            ),
            Some(e) if !noise_free && e.relative_half_width() > MAX_REL_HALF_WIDTH => {
                Some(format!(
                    "{} intervals on it are too few: 95 % interval ±{:.1} % of the value, more than ±{:.0} %",
                    l.limited,
                    100.0 * e.relative_half_width(),
                    100.0 * MAX_REL_HALF_WIDTH
                ))
            }
            Some(_) => None,
        };
        RateLimit {
            estimate: e.filter(|_| why.is_none()),
            why,
            noise_free,
            intervals: l.limited,
        }
    }
}

impl RateLimit {
    /// A limit the log gives no evidence of (`why`: the test's verdict).
    pub(super) fn not_reached(why: String) -> RateLimit {
        RateLimit {
            estimate: None,
            why: Some(why),
            noise_free: false,
            intervals: 0,
        }
    }
}

/// The largest rate of `y` over 5-sample spans (noise averaged) and how
/// many spans come within 0.5 % of it: a lag's rate only touches its peak,
/// a limited one rides it.
pub(super) fn largest_rate(t: &[f64], y: &[f64]) -> (f64, usize) {
    let w = 5;
    let rates: Vec<f64> = (0..t.len().saturating_sub(w))
        .map(|i| ((y[i + w] - y[i]) / (t[i + w] - t[i])).abs())
        .collect();
    let acc = rates.iter().fold(0.0_f64, |m, r| m.max(*r));
    let riding = rates.iter().filter(|r| **r >= 0.995 * acc).count();
    (acc, riding)
}

/// Observed speed and acceleration limits of a velocity base, with warnings.
pub(super) fn velocity_limits(
    log: &Log,
    applied: &[Vec<f64>; 2],
    rate_limits: &[Option<RateLimit>; 2],
    warnings: &mut Vec<String>,
) -> Vec<Limit> {
    let mut out = Vec::new();
    let measured = [&log.v, &log.omega];
    let tops = applied
        .each_ref()
        .map(|a| a.iter().fold(0.0_f64, |m, x| m.max(x.abs())));
    let at_top = |axis: usize, i: usize| applied[axis][i].abs() >= tops[axis] * (1.0 - 1e-6);
    for axis in 0..2 {
        let speed = ["v_max", "omega_max"][axis];
        let (a, top) = (&applied[axis], tops[axis]);
        // The base cut the command on this axis, at its largest applied
        // value, and this axis's limit did it. The limit scales `v` and `ω`
        // together (base.rs, `VelocityBase::limit`): when `v_max` binds, `ω`
        // is cut too, to whatever keeps the curvature. So the cut is this
        // axis's only where the other axis is below its own top (that
        // axis's limit, if it ever bound, is its top: it did not bind here).
        let other = 1 - axis;
        let reached =
            log.cmd.as_ref().is_some_and(|cmd| {
                cmd[axis].iter().zip(a).enumerate().any(|(i, (c, a))| {
                    c.abs() > a.abs() + 1e-9 && at_top(axis, i) && !at_top(other, i)
                })
            });
        let observed = if reached {
            top
        } else {
            measured[axis].iter().fold(0.0_f64, |m, x| m.max(x.abs()))
        };
        out.push(Limit {
            field: speed,
            observed,
            reached,
            estimate: None,
            noise_free: false,
        });
        if !reached {
            let cut = log.cmd.as_ref().is_some_and(|cmd| {
                cmd[axis]
                    .iter()
                    .zip(a)
                    .any(|(c, a)| c.abs() > a.abs() + 1e-9)
            });
            let why = if cut {
                format!(
                    "the command was cut only with {} at its top: the speed limit scales both together",
                    ["v", "ω"][other]
                )
            } else {
                "the command never exceeded it".to_owned()
            };
            warnings.push(format!(
                "{speed}: not reached (largest seen: {observed:.4}): {why}"
            ));
        }
        out.push(acceleration_limit(
            log,
            axis,
            rate_limits[axis].as_ref(),
            warnings,
        ));
    }
    out
}

/// The acceleration limit of `axis` as a [`Limit`], with its warning.
///
/// Acceleration: the rate-limited fit's, when it was fitted with the
/// lag; else the largest |Δv/Δt| of the measurement over 5-sample
/// spans (noise averaged). It is the limit when the rate sits on it
/// (within 0.5 %) for at least 10 samples: a lag's rate only touches
/// its peak, a limited one rides it.
fn acceleration_limit(
    log: &Log,
    axis: usize,
    rate_limit: Option<&RateLimit>,
    warnings: &mut Vec<String>,
) -> Limit {
    let accel = ["a_max", "alpha_max"][axis];
    let measured = [&log.v, &log.omega];
    let (acc, riding) = largest_rate(&log.t, measured[axis]);
    let not_reached = Limit {
        field: accel,
        observed: acc,
        reached: false,
        estimate: None,
        noise_free: false,
    };
    if let Some(r) = rate_limit {
        return match (&r.estimate, &r.why) {
            (Some(e), _) => {
                warnings.push(format!(
                    "{accel} = {:.4} identified with the lag ({} intervals on it){}",
                    e.value,
                    r.intervals,
                    if r.noise_free {
                        ": noise-free log, exact to rounding".to_owned()
                    } else {
                        format!(", 95 % interval ±{:.2} %", 100.0 * e.relative_half_width())
                    }
                ));
                Limit {
                    field: accel,
                    observed: e.value,
                    reached: true,
                    estimate: Some(*e),
                    noise_free: r.noise_free,
                }
            }
            (None, why) => {
                warnings.push(format!(
                    "{accel}: not reached (largest seen: {acc:.4}): {}",
                    why.as_deref().unwrap_or("no estimate")
                ));
                not_reached
            }
        };
    }
    // Without integrals or a bag's command hold there is no fit with
    // the limit in the loop, and so no evidence that tells a limit from
    // a lag: a rate that rides its peak over many spans is what a
    // limit does, but also what a lag does over repeated equal steps.
    // Never presented as the limit.
    if acc > 0.0 && riding >= 10 {
        warnings.push(format!(
            "{accel}: not reached (largest seen: {acc:.4}): the rate rode it on {riding} spans, as a limit would (then the first-order lag ignores it and {} is biased) or a lag over repeated equal steps; a run's integrals.csv or a ROS 2 bag tells them apart",
            ["tau_v", "tau_omega"][axis]
        ));
    } else {
        warnings.push(format!("{accel}: not reached (largest seen: {acc:.4})"));
    }
    not_reached
}
