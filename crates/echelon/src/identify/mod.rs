//! Identification: a robot's dynamic model (eq. 3c–d, Table I) or its
//! velocity base (lags and limits) from its own logs.
//!
//! Both models are two decoupled first-order axes:
//!
//! ```text
//! torque:   m v̇ + η v = u1        J ω̇ + ψ ω = u2          (eq. 3c–d)
//! velocity: τ_v v̇ + v = v_c       τ_ω ω̇ + ω = ω_c        (crate::base)
//! ```
//!
//! With the run's running integrals ([`Log::integrals`], a run directory's
//! `integrals.csv`: `∫v dt` or the heading, and `∫u dt`) each axis is fitted
//! exactly: the equation integrated from the first sample,
//! `x_k = x₀ + (k ΔI_k − ΔS_k)/τ`, holds whatever the input did between
//! samples, and is solved by linear least squares (`fit::fit_integral`).
//! Without them, in two steps (`fit::fit`): an equation-error least-squares
//! first guess on the equation integrated over short windows, then an
//! output-error Levenberg–Marquardt refinement that simulates the axis from
//! the logged input and fits the measured velocity. The input between samples
//! is then unknown: the axis is fitted with the input held and linearly
//! interpolated, and unless holding fits significantly better, the
//! interpolated fit is taken with the difference of the two added to its
//! covariance (a ROS 2 bag's command messages, [`Log::hold`], are integrated
//! exactly instead). Each parameter gets a 95 % interval from `σ² (XᵀX)⁻¹`
//! (σ² the residual variance, X the regressors or the output's
//! sensitivities), mapped to `m, η` (or `J, ψ`) by the delta method.
//!
//! A velocity base whose acceleration limit acted misfits the lag alone;
//! with the integrals such an axis is refitted with the rate clamp in the
//! loop (`fit::fit_limited`: the base's `VelocityBase::accelerations`
//! integrated over each log interval, exact), which also identifies the
//! limit that bound (`a_max`, `α_max`, [`Limit::estimate`]).
//!
//! A ROS 2 bag (a velocity base, [`Log::hold`] without integrals) is fitted
//! on its command messages' hold and its odometry grid with the base's
//! model in the loop (`fit::fit_bag`): the lags, a dead time shared by both
//! axes (command publication to odometry response) with its interval, and
//! an acceleration limit per axis claimed only on evidence of saturation (a
//! likelihood-ratio test of the clamp against the lag alone, and the clamp
//! holding on enough odometry intervals); a limit without that evidence is
//! "not reached (largest seen: X)". A lag far below the odometry period is
//! answered with its bound ([`Param::upper_bound`]), an ideal axis.
//!
//! A parameter is given no number, and the reason instead, when the input did
//! not excite it (no input, a badly conditioned information matrix or an
//! interval wider than ±[`MAX_REL_HALF_WIDTH`]) or when the model misfits the
//! log: on a log that is not noise-free, residuals that are not white
//! (Ljung–Box), that keep one sign over a stretch (a multi-scale scan of
//! their local means) or that exceed the noise the measurement shows by
//! itself (`misfit`).
//!
//! Input: a run directory's `trajectory.csv` ([`Log::read_run`]) or a log
//! built in memory ([`Log`]); output: [`Identified`], with
//! [`Identified::robot_toml`] for a `[robots.NAME]` block.

mod checks;
mod error;
pub mod excite;
mod fit;
mod identified;
mod limits;
mod log;
mod pipeline;

use serde::Serialize;

use fit::{AxisData, AxisFit};

use crate::model::RobotParams;

pub use checks::{MAX_RESIDUAL_OVER_NOISE, ResidualChecks, WHITENESS_LAGS};
use checks::{excitation, misfit};
pub use error::IdentifyError;
pub use identified::{AxisSummary, Estimate, Identified, Limit, Param, Prediction};
pub use log::{Hold, Integrals, Log, integrals_truncation};

/// Fewest samples a log must have.
pub const MIN_SAMPLES: usize = 50;

/// Largest relative 95 % half-width of an identified parameter; wider, the
/// parameter is reported as not identifiable. At ±1 %, a printed value more
/// than 2 % off the truth is a 4σ event.
pub const MAX_REL_HALF_WIDTH: f64 = 0.01;

/// Residual RMS, relative to the RMS of the measured velocity, below which a
/// log counts as noise-free: the residuals are rounding, `σ²` means nothing
/// and neither do the intervals built on it.
pub const NOISE_FREE_RELATIVE_RMS: f64 = 1e-9;

/// Smallest reciprocal condition number of the (scaled) information matrix.
const MIN_RCOND: f64 = 1e-9;

/// Which model to identify.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Model {
    /// The paper's torque-driven plant: `m, η, J, ψ` (eq. 3c–d).
    Torque,
    /// A velocity base: `τ_v, τ_ω` and its limits.
    Velocity,
}

impl std::fmt::Display for Model {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Model::Torque => "torque",
            Model::Velocity => "velocity",
        })
    }
}

/// Identifies `model` from `log`.
///
/// Errors: missing inputs, fewer than [`MIN_SAMPLES`] samples, non-finite
/// values, times that do not increase, or no axis excited at all.
pub fn identify(log: &Log, model: Model) -> Result<Identified, IdentifyError> {
    log.check(model)?;
    let inputs = pipeline::model_inputs(log, model)?;
    let bag = pipeline::bag_fit(log, model);
    let fits = pipeline::Fits::new(log, model, inputs, bag.as_ref());
    let mut outcome = pipeline::Outcome::new(log);
    for axis in 0..2 {
        outcome.axis(&fits, axis);
    }
    outcome.finish(&fits)
}

type Symbol = (&'static str, &'static str, &'static str);

/// One axis's fit and what it allows: the estimates, or why not.
struct Verdict {
    fit: AxisFit,
    noise_free: bool,
    checks: ResidualChecks,
    estimates: Vec<Estimate>,
    symbols: Vec<Symbol>,
    /// Why the input did not excite the axis (or it has no lag).
    unexcited: Option<String>,
    /// Why there is no number: `unexcited`, or the model misfits the log.
    why: Option<String>,
    method: &'static str,
}

impl Verdict {
    /// The verdict on fit `f` of `axis` (`no_lag`: the axis has none;
    /// `ideal`: a bag's lag below what its odometry resolves, bounded
    /// instead, so that its estimate's width and sign are not held against
    /// it).
    #[allow(clippy::too_many_arguments)]
    fn new(
        model: Model,
        axis: usize,
        d: &AxisData<'_>,
        f: AxisFit,
        integrals: &Option<fit::AxisIntegrals<'_>>,
        no_lag: Option<String>,
        input: &str,
        ideal: bool,
    ) -> Verdict {
        let y_rms = (d.y.iter().map(|y| y * y).sum::<f64>() / d.y.len() as f64).sqrt();
        let noise_free = f.rms <= NOISE_FREE_RELATIVE_RMS * y_rms;
        let checks = ResidualChecks::new(d, &f);
        let method = match (integrals, d.hold.is_some(), f.between.is_some()) {
            (Some(_), _, _) => "integrals",
            (None, true, _) => "command hold",
            (None, false, true) => "interpolated inputs",
            (None, false, false) => "held inputs",
        };
        let (estimates, symbols) = axis_params(model, axis, &f);
        // An ideal axis's estimate is a bound, not a value: its width and
        // sign are not held against it.
        let judged = if ideal { &[][..] } else { &estimates[..] };
        let misfits = || {
            (!noise_free)
                .then(|| misfit(&f, &checks, integrals.is_some() || d.hold.is_some()))
                .flatten()
        };
        // An input that drove the axis but left intervals too wide, on a
        // model that misfits the log: the misfit is why (it widens them),
        // not the input (a real base's bag, its timing jitter the residual,
        // was refused as "no excitation").
        let (unexcited, why) = match no_lag
            .map(|w| (w, false))
            .or_else(|| excitation(d, &f, judged, input))
        {
            Some((wide, true)) => match misfits() {
                Some(m) => (None, Some(m)),
                None => (Some(wide.clone()), Some(wide)),
            },
            Some((u, false)) => (Some(u.clone()), Some(u)),
            None => (None, misfits()),
        };
        Verdict {
            fit: f,
            noise_free,
            checks,
            estimates,
            symbols,
            unexcited,
            why,
            method,
        }
    }
}

/// A bag's dead time (command publication to odometry response) as a
/// parameter: its estimate, or why not (no lag identified to carry it, or an
/// interval wider than half an odometry period). Zero is an answer.
fn dead_time(b: &fit::BagFit, axes: &[AxisSummary]) -> Param {
    let (value, var) = b.dead_time;
    let e = Estimate::new(value, var, value);
    let half = fit::Z95 * e.std;
    let why = if axes.iter().all(|a| !a.identifiable) {
        Some("no axis was identified to carry it".to_owned())
    } else if !(value.is_finite() && half.is_finite()) {
        Some(format!("the fit gave a non-physical value ({value:.3e})"))
    } else if half > 0.5 * b.period {
        Some(format!(
            "95 % interval ±{:.1} ms, wider than half an odometry period ({:.1} ms)",
            1e3 * half,
            0.5e3 * b.period
        ))
    } else {
        None
    };
    Param {
        field: "dead_time",
        symbol: "d",
        unit: "s",
        estimate: why.is_none().then_some(e),
        upper_bound: None,
        not_identifiable: why,
        noise_free: axes.iter().all(|a| a.noise_free),
    }
}

/// Whether a velocity base has no lag on this axis: it moves at its command
/// (`input`), the integrals of both agree throughout.
fn no_lag(w: &fit::AxisIntegrals<'_>, input: &str) -> Option<String> {
    let top = w.i.iter().map(|x| (x - w.i[0]).abs()).fold(0.0, f64::max);
    let gap =
        w.i.iter()
            .zip(w.s)
            .map(|(i, s)| ((i - w.i[0]) - (s - w.s[0])).abs())
            .fold(0.0, f64::max);
    (top > 0.0 && gap <= 1e-9 * top).then(|| {
        format!(
            "the base moves at its {input} throughout (∫ of the command equals ∫ of the velocity): no lag on this axis"
        )
    })
}

/// The physical parameters of one axis from its `(τ, k)` fit, by the delta
/// method: torque `m = τ/k, η = 1/k` (or `J, ψ`); velocity `τ`.
fn axis_params(model: Model, axis: usize, f: &AxisFit) -> (Vec<Estimate>, Vec<Symbol>) {
    let [tau, k] = f.theta;
    let c = f.cov;
    let [g_tau, g_k] = f.first_guess;
    match model {
        Model::Torque => {
            // m = τ/k: ∇ = (1/k, −τ/k²); η = 1/k: ∇ = (0, −1/k²).
            let gm = [1.0 / k, -tau / (k * k)];
            let ge = [0.0, -1.0 / (k * k)];
            let var = |g: [f64; 2]| {
                g[0] * g[0] * c[0][0] + 2.0 * g[0] * g[1] * c[0][1] + g[1] * g[1] * c[1][1]
            };
            let est = vec![
                Estimate::new(tau / k, var(gm), g_tau / g_k),
                Estimate::new(1.0 / k, var(ge), 1.0 / g_k),
            ];
            let sym = if axis == 0 {
                vec![("mass", "m", "kg"), ("linear_friction", "η", "kg/s")]
            } else {
                vec![
                    ("inertia", "J", "kg m²"),
                    ("angular_friction", "ψ", "kg m²/s"),
                ]
            };
            (est, sym)
        }
        Model::Velocity => {
            let sym = if axis == 0 {
                ("tau_v", "τ_v", "s")
            } else {
                ("tau_omega", "τ_ω", "s")
            };
            (vec![Estimate::new(tau, c[0][0], g_tau)], vec![sym])
        }
    }
}

/// `l, r` from eq. 2, by least squares over the samples:
/// `τr + τl = r u1`, `τr − τl = (r/l) u2`.
fn geometry(u: &[Vec<f64>; 2], tau: &[Vec<f64>; 2]) -> Option<[f64; 2]> {
    let (mut su, mut sus, mut sw, mut swd) = (0.0, 0.0, 0.0, 0.0);
    for i in 0..u[0].len() {
        let (sum, diff) = (tau[0][i] + tau[1][i], tau[0][i] - tau[1][i]);
        if !(sum.is_finite() && diff.is_finite() && u[0][i].is_finite() && u[1][i].is_finite()) {
            return None;
        }
        su += u[0][i] * u[0][i];
        sus += u[0][i] * sum;
        sw += u[1][i] * u[1][i];
        swd += u[1][i] * diff;
    }
    if su <= 0.0 || sw <= 0.0 {
        return None;
    }
    let r = sus / su;
    let r_over_l = swd / sw;
    (r > 0.0 && r_over_l > 0.0).then(|| [r / r_over_l, r])
}

/// Simulates a first-order axis `τ ẋ + x = k u` (input held between
/// samples) from `x0`: the model [`identify`] fits, for tests and synthetic
/// logs. Torque: `τ = m/η, k = 1/η` (eq. 3c) or `τ = J/ψ, k = 1/ψ` (eq. 3d).
pub fn simulate_axis(t: &[f64], u: &[f64], tau: f64, k: f64, x0: f64) -> Vec<f64> {
    let mut x = Vec::with_capacity(t.len());
    if t.is_empty() {
        return x;
    }
    x.push(x0);
    for i in 0..t.len() - 1 {
        let a = (-(t[i + 1] - t[i]) / tau).exp();
        x.push(a * x[i] + (1.0 - a) * k * u[i]);
    }
    x
}

/// Eq. 3c–d for `robot` under held inputs `u1, u2`, from rest: `(v, ω)`.
pub fn simulate_torque(robot: &RobotParams, t: &[f64], u1: &[f64], u2: &[f64]) -> [Vec<f64>; 2] {
    [
        simulate_axis(
            t,
            u1,
            robot.mass() / robot.linear_friction(),
            1.0 / robot.linear_friction(),
            0.0,
        ),
        simulate_axis(
            t,
            u2,
            robot.inertia() / robot.angular_friction(),
            1.0 / robot.angular_friction(),
            0.0,
        ),
    ]
}
