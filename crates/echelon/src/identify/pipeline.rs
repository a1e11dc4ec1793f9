//! The steps of [`identify`](super::identify): the inputs, both axes' fits,
//! the verdict on each axis, and the answer assembled from them.

use super::fit::{self, AxisData, AxisFit};
use super::limits::{RateLimit, largest_rate, velocity_limits};
use super::{
    AxisSummary, Identified, IdentifyError, Log, MAX_REL_HALF_WIDTH, Model, Param, Prediction,
    Verdict, dead_time, geometry, no_lag,
};

/// The axes' names, as warnings and summaries give them.
const AXIS_NAMES: [&str; 2] = ["linear", "angular"];

/// The inputs `model` is fitted on: the torques, or the applied (else the
/// commanded) velocities.
pub(super) fn model_inputs(log: &Log, model: Model) -> Result<&[Vec<f64>; 2], IdentifyError> {
    match model {
        Model::Torque => log.u.as_ref(),
        Model::Velocity => log.applied.as_ref().or(log.cmd.as_ref()),
    }
    .ok_or_else(|| IdentifyError::Read {
        file: log.source.clone(),
        reason: "no inputs".to_owned(),
    })
}

/// A velocity base from a ROS 2 bag (the command messages' hold, no
/// integrals): lags, limits and dead time together (`fit::fit_bag`).
pub(super) fn bag_fit(log: &Log, model: Model) -> Option<fit::BagFit> {
    match (model, &log.hold, &log.integrals) {
        (Model::Velocity, Some(h), None) => Some(fit::fit_bag(&fit::BagData {
            t: &log.t,
            y: [&log.v, &log.omega],
            hold_t: &h.t,
            hold_u: [&h.u[0], &h.u[1]],
        })),
        _ => None,
    }
}

/// Whether the samples are farther apart than the plant's own input hold:
/// the sampled values do not hold over the intervals.
fn slower_than_hold(log: &Log) -> bool {
    log.input_period.is_some_and(|p| {
        let n = log.t.len();
        n > 1 && (log.t[n - 1] - log.t[0]) / (n - 1) as f64 > 1.5 * p
    })
}

/// A bag's axis whose lag is below what its odometry resolves: the bound,
/// an answer (an ideal axis), instead of a withheld estimate.
fn ideal_bound(b: &fit::BagFit, axis: usize) -> Option<f64> {
    if let Some(upper) = b.axes[axis].bound {
        return (upper < b.period).then_some(upper);
    }
    let f = &b.axes[axis].fit;
    let upper = f.theta[0] + fit::Z95 * f.cov[0][0].max(0.0).sqrt();
    let rel = fit::Z95 * f.cov[0][0].max(0.0).sqrt() / f.theta[0].abs();
    (upper.is_finite() && upper < b.period && (rel.is_nan() || rel > MAX_REL_HALF_WIDTH))
        .then_some(upper)
}

/// Both axes' data and fits, before any verdict on them.
pub(super) struct Fits<'a> {
    log: &'a Log,
    model: Model,
    inputs: &'a [Vec<f64>; 2],
    input_names: [&'static str; 2],
    bag: Option<&'a fit::BagFit>,
    data: [AxisData<'a>; 2],
    integrals: [Option<fit::AxisIntegrals<'a>>; 2],
    slower: bool,
    fits: [AxisFit; 2],
    no_lags: [Option<String>; 2],
    /// A velocity base's acceleration limit: the lag with the rate clamp in
    /// the loop, fitted from the integrals (`fit::fit_limited`), for the
    /// axes whose lag alone misfits.
    limited: Option<[fit::LimitedFit; 2]>,
    ideal: [Option<f64>; 2],
}

impl<'a> Fits<'a> {
    /// Fits both axes of `log` on `inputs` (or on `bag`'s, when a bag).
    pub(super) fn new(
        log: &'a Log,
        model: Model,
        inputs: &'a [Vec<f64>; 2],
        bag: Option<&'a fit::BagFit>,
    ) -> Fits<'a> {
        let fixed_gain = model == Model::Velocity;
        let measured = [&log.v, &log.omega];
        let input_names = match model {
            Model::Torque => ["u1", "u2"],
            Model::Velocity => ["v_applied", "omega_applied"],
        };
        let data: [AxisData<'_>; 2] = std::array::from_fn(|axis| AxisData {
            t: &log.t,
            // The bag's input as the fit saw it: shifted by the dead time.
            u: bag.map_or(&inputs[axis][..], |b| &b.axes[axis].u_shifted[..]),
            y: measured[axis],
            hold: log.hold.as_ref().map(|h| (&h.t[..], &h.u[axis][..])),
        });
        let integrals: [Option<fit::AxisIntegrals<'_>>; 2] = std::array::from_fn(|axis| {
            log.integrals.as_ref().map(|w| fit::AxisIntegrals {
                s: [&w.s, &w.theta][axis],
                i: &w.input[axis],
            })
        });
        let slower = slower_than_hold(log);
        let fits: [AxisFit; 2] = std::array::from_fn(|axis| match (&integrals[axis], bag) {
            (Some(w), _) => fit::fit_integral(&data[axis], w, fixed_gain),
            (None, Some(b)) => b.axes[axis].fit.clone(),
            (None, None) => fit::fit(&data[axis], fixed_gain, slower),
        });
        let no_lags: [Option<String>; 2] = std::array::from_fn(|axis| {
            integrals[axis]
                .as_ref()
                .filter(|_| fixed_gain)
                .and_then(|w| no_lag(w, input_names[axis]))
        });
        let limited = match (&integrals, fixed_gain) {
            ([Some(wv), Some(ww)], true) if no_lags.iter().all(Option::is_none) => {
                fit::fit_limited(
                    [&data[0], &data[1]],
                    [wv, ww],
                    [&fits[0], &fits[1]],
                    [0, 1].map(|a| largest_rate(&log.t, measured[a]).0),
                )
            }
            _ => None,
        };
        let ideal = std::array::from_fn(|axis| ideal_bound(bag?, axis));
        Fits {
            log,
            model,
            inputs,
            input_names,
            bag,
            data,
            integrals,
            slower,
            fits,
            no_lags,
            limited,
            ideal,
        }
    }

    /// The verdict on `axis`: its lag alone, or with the rate clamp in the
    /// loop when the lag alone misfits (returned with the verdict). A bag's
    /// limit goes to `rate_limit`.
    fn verdict(
        &self,
        axis: usize,
        rate_limit: &mut Option<RateLimit>,
    ) -> (Verdict, Option<&fit::LimitedFit>) {
        let d = &self.data[axis];
        let mut lag_only = Verdict::new(
            self.model,
            axis,
            d,
            self.fits[axis].clone(),
            &self.integrals[axis],
            self.no_lags[axis].clone(),
            self.input_names[axis],
            self.ideal[axis].is_some(),
        );
        if let Some(b) = self.bag {
            let a = &b.axes[axis];
            if a.limit.is_some() {
                lag_only.method = "command hold, rate limit";
            }
            let lag_identified = lag_only.why.is_none();
            *rate_limit = Some(match &a.no_limit {
                None => RateLimit::new(
                    &fit::LimitedFit {
                        fit: a.fit.clone(),
                        limit: a.limit,
                        limited: a.riding,
                        unknown: 0,
                    },
                    lag_only.noise_free,
                    lag_identified || self.ideal[axis].is_some(),
                ),
                Some(why) => RateLimit::not_reached(why.clone()),
            });
        }
        // Withheld for misfit, or for an interval the misfit widened.
        let misfit_alone = self.no_lags[axis].is_none() && lag_only.why.is_some();
        match &self.limited {
            Some(l) if misfit_alone => {
                let l = &l[axis];
                let mut v = Verdict::new(
                    self.model,
                    axis,
                    d,
                    l.fit.clone(),
                    &self.integrals[axis],
                    None,
                    self.input_names[axis],
                    false,
                );
                v.method = "integrals, rate limit";
                (v, Some(l))
            }
            _ => (lag_only, None),
        }
    }
}

/// What the axes' verdicts add up to, gathered axis by axis.
pub(super) struct Outcome {
    params: Vec<Param>,
    warnings: Vec<String>,
    axes: Vec<AxisSummary>,
    predicted: [Vec<f64>; 2],
    reasons: Vec<String>,
    /// Whether an excited axis was withheld for misfit (then the log is
    /// answered, with the reasons, rather than refused as unexcited).
    misfits: bool,
    rate_limits: [Option<RateLimit>; 2],
}

impl Outcome {
    /// Nothing gathered yet: the log's own notes as the first warnings.
    pub(super) fn new(log: &Log) -> Outcome {
        Outcome {
            params: Vec::new(),
            warnings: log.notes.clone(),
            axes: Vec::new(),
            predicted: Default::default(),
            reasons: Vec::new(),
            misfits: false,
            rate_limits: [None, None],
        }
    }

    /// Judges `axis` of `f` and gathers its parameters and warnings.
    pub(super) fn axis(&mut self, f: &Fits<'_>, axis: usize) {
        let (v, lim) = f.verdict(axis, &mut self.rate_limits[axis]);
        if let Some(b) = v.fit.between {
            let rel = |i: usize| (v.fit.theta[i] - b.held[i]).abs() / v.fit.theta[i].abs();
            self.warnings.push(format!(
                "the {} axis's inputs between samples are not in the log (no integrals.csv, and {}, cost ratio {:.3}): the fit interpolates them linearly and its intervals include the difference to holding them ({:.2} % on τ, {:.2} % on the gain)",
                AXIS_NAMES[axis],
                if f.slower {
                    "the samples are farther apart than the plant's input hold in summary.json"
                } else {
                    "holding the logged values does not fit better than interpolating them"
                },
                b.cost_ratio,
                100.0 * rel(0),
                100.0 * rel(1)
            ));
        }
        if let Some(l) = lim {
            self.rate_limits[axis] = Some(RateLimit::new(l, v.noise_free, v.why.is_none()));
            self.warnings.push(format!(
                "the {} axis was fitted with its acceleration limit in the loop: {} intervals on the limit, {} left out (the limit took hold or let go between samples, or the other axis's limit scaled this one)",
                AXIS_NAMES[axis],
                l.limited,
                l.unknown
            ));
        }
        self.record(f, axis, v);
    }

    /// Gathers the verdict `v` on `axis`: its reason or its prediction, its
    /// parameters (estimates, bounds or reasons) and its summary.
    fn record(&mut self, f: &Fits<'_>, axis: usize, v: Verdict) {
        let d = &f.data[axis];
        self.misfits |= v.unexcited.is_none() && v.why.is_some();
        let names = || v.symbols.iter().map(|s| s.1).collect::<Vec<_>>().join(", ");
        match &v.why {
            Some(reason) => {
                self.warnings
                    .push(format!("{} not identifiable: {reason}", names()));
                self.reasons
                    .push(format!("{} axis: {reason}", AXIS_NAMES[axis]));
            }
            None => {
                self.predicted[axis].clone_from(&v.fit.predicted);
                if v.noise_free {
                    self.warnings.push(format!(
                        "noise-free log on the {} axis (residual RMS {:.1e}): {} exact to rounding, intervals not meaningful",
                        AXIS_NAMES[axis],
                        v.fit.rms,
                        names()
                    ));
                }
            }
        }
        let bound = f.ideal[axis].filter(|_| v.why.is_none());
        if let (Some(upper), Some(b)) = (bound, f.bag) {
            self.warnings.push(format!(
                "{}: below one odometry period ({:.4} s): < {upper:.4} s at 95 %, an axis that follows its command at once as far as this odometry can tell",
                names(),
                b.period
            ));
        }
        for ((field, symbol, unit), e) in v.symbols.iter().zip(v.estimates) {
            self.params.push(Param {
                field,
                symbol,
                unit,
                estimate: (v.why.is_none() && bound.is_none()).then_some(e),
                upper_bound: bound,
                not_identifiable: v.why.clone(),
                noise_free: v.noise_free && v.why.is_none(),
            });
        }
        if v.why.is_some() {
            self.predicted[axis] = vec![f64::NAN; f.log.t.len()];
        }
        self.axes.push(AxisSummary {
            noise_free: v.noise_free,
            method: v.method,
            checks: v.checks,
            axis: AXIS_NAMES[axis],
            residual_rms: v.fit.rms,
            residual_max: d
                .y
                .iter()
                .zip(&v.fit.predicted)
                .map(|(y, p)| (y - p).abs())
                .fold(0.0, f64::max),
            rcond: v.fit.rcond,
            identifiable: v.why.is_none(),
        });
    }

    /// The answer: the dead time of a bag, the geometry and limits, or the
    /// refusal when no axis was excited.
    pub(super) fn finish(mut self, f: &Fits<'_>) -> Result<Identified, IdentifyError> {
        let (log, model) = (f.log, f.model);
        if let Some(b) = f.bag {
            self.params.push(dead_time(b, &self.axes));
        }
        if self.axes.iter().all(|a| !a.identifiable) && !self.misfits {
            return Err(IdentifyError::NoExcitation {
                file: log.source.clone(),
                reason: self.reasons.join("; "),
            });
        }
        let geometry = match (model, &log.u, &log.tau) {
            (Model::Torque, Some(u), Some(tau)) => geometry(u, tau),
            _ => None,
        };
        let limits = if model == Model::Velocity {
            velocity_limits(log, f.inputs, &self.rate_limits, &mut self.warnings)
        } else {
            Vec::new()
        };
        let [axis0, axis1]: [AxisSummary; 2] =
            self.axes.try_into().map_err(|_| IdentifyError::Read {
                file: log.source.clone(),
                reason: "internal: two axes".to_owned(),
            })?;
        let [v_model, omega_model] = self.predicted;
        Ok(Identified {
            model,
            source: log.source.clone(),
            agent: log.agent,
            samples: log.t.len(),
            duration: log.t[log.t.len() - 1] - log.t[0],
            params: self.params,
            axes: [axis0, axis1],
            geometry,
            limits,
            warnings: self.warnings,
            prediction: Prediction {
                t: log.t.clone(),
                v: log.v.clone(),
                v_model,
                omega: log.omega.clone(),
                omega_model,
            },
        })
    }
}
