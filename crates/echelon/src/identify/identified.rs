//! What identification answers ([`Identified`]): the estimates with their
//! intervals, per-axis summaries, limits and the model's prediction, and the
//! `[robots.NAME]` TOML block.

use std::fmt::Write as _;

use serde::Serialize;

use crate::model::{RobotParams, RobotParamsSpec};

use super::fit::Z95;
use super::{Model, ResidualChecks};

/// A parameter's estimate and its 95 % interval.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Estimate {
    /// Output-error estimate.
    pub value: f64,
    /// Standard deviation, from `σ² (JᵀJ)⁻¹`.
    pub std: f64,
    /// 95 % interval `value ± 1.96 std`.
    pub ci95: [f64; 2],
    /// The equation-error first guess.
    pub first_guess: f64,
}

impl Estimate {
    pub(super) fn new(value: f64, var: f64, first_guess: f64) -> Estimate {
        let std = var.max(0.0).sqrt();
        Estimate {
            value,
            std,
            ci95: [value - Z95 * std, value + Z95 * std],
            first_guess,
        }
    }

    /// Whether `x` lies in the 95 % interval.
    pub fn contains(&self, x: f64) -> bool {
        self.ci95[0] <= x && x <= self.ci95[1]
    }

    /// Half-width of the interval over the value.
    pub fn relative_half_width(&self) -> f64 {
        Z95 * self.std / self.value.abs()
    }
}

/// One identified parameter: its `[robots.NAME]` field, and its estimate or
/// why there is none.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Param {
    /// The `[robots.NAME]` field (`mass`, `tau_v`, …).
    pub field: &'static str,
    /// The paper's symbol.
    pub symbol: &'static str,
    /// SI unit.
    pub unit: &'static str,
    /// The estimate, `None` if not identifiable (or only bounded).
    pub estimate: Option<Estimate>,
    /// A 95 % upper bound instead of an estimate: the parameter is below
    /// what the log resolves (a bag's lag shorter than one odometry period:
    /// an ideal axis, written as 0).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub upper_bound: Option<f64>,
    /// Why it is not identifiable.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub not_identifiable: Option<String>,
    /// The log is noise-free on this parameter's axis: its interval is not
    /// meaningful (the estimate is exact to rounding).
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub noise_free: bool,
}

/// The fit of one axis.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AxisSummary {
    /// `linear` or `angular`.
    pub axis: &'static str,
    /// RMS of the output-error residuals (measured − predicted velocity).
    pub residual_rms: f64,
    /// Largest |residual|.
    pub residual_max: f64,
    /// Reciprocal condition number of the scaled information matrix.
    pub rcond: f64,
    /// Whether its parameters were identified.
    pub identifiable: bool,
    /// Residuals at rounding level ([`NOISE_FREE_RELATIVE_RMS`](super::NOISE_FREE_RELATIVE_RMS)): a
    /// simulated, noise-free log; the intervals are not meaningful.
    pub noise_free: bool,
    /// How the axis was fitted: `integrals` (exact, from `integrals.csv`),
    /// `integrals, rate limit` (exact, with the acceleration limit in the
    /// loop: the lag alone misfit),
    /// `command hold` (through the command messages of a ROS 2 bag),
    /// `held inputs` (the logged inputs held between samples: holding fitted
    /// significantly better) or `interpolated inputs` (linearly, the
    /// difference to holding them added to the covariance).
    pub method: &'static str,
    /// The residual checks (whiteness, runs, size against the noise).
    pub checks: ResidualChecks,
}

/// A speed or acceleration limit seen in the log.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Limit {
    /// The `[robots.NAME]` field (`v_max`, …).
    pub field: &'static str,
    /// Largest magnitude seen (the limit itself when `reached`).
    pub observed: f64,
    /// Whether the log shows it is the limit: the command exceeded it and
    /// the base cut it, or an acceleration limit identified with the lag
    /// (a run's integrals, or a bag whose data show saturation: see
    /// `docs/identify.md`). Otherwise the limit is "not reached (largest
    /// seen: `observed`)": only what the manoeuvre reached, never presented
    /// as the limit.
    pub reached: bool,
    /// An acceleration limit identified with the lag (the lag with its rate
    /// clamp fitted to the log): its estimate and 95 % interval.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub estimate: Option<Estimate>,
    /// The log is noise-free on this limit's axis: its interval is not
    /// meaningful.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub noise_free: bool,
}

/// Measured against model-predicted velocities, for the figure.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Prediction {
    /// Sample times, s.
    pub t: Vec<f64>,
    /// Measured `v`, m/s.
    pub v: Vec<f64>,
    /// Predicted `v`, m/s.
    pub v_model: Vec<f64>,
    /// Measured `ω`, rad/s.
    pub omega: Vec<f64>,
    /// Predicted `ω`, rad/s.
    pub omega_model: Vec<f64>,
}

/// What [`identify`](super::identify) found.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Identified {
    /// The model identified.
    pub model: Model,
    /// The log.
    pub source: String,
    /// The agent.
    pub agent: usize,
    /// Samples used.
    pub samples: usize,
    /// Duration of the log, s.
    pub duration: f64,
    /// The parameters, in `[robots.NAME]` order.
    pub params: Vec<Param>,
    /// Per-axis fit quality.
    pub axes: [AxisSummary; 2],
    /// Half wheelbase `l` and wheel radius `r` (m) when the log has both the
    /// generalised inputs and the wheel torques (eq. 2).
    pub geometry: Option<[f64; 2]>,
    /// Speed and acceleration limits seen (velocity model).
    pub limits: Vec<Limit>,
    /// Everything the user should know: unexcited parameters, observed limits.
    pub warnings: Vec<String>,
    /// Measured against predicted velocities.
    #[serde(skip)]
    pub prediction: Prediction,
}

impl Identified {
    /// A parameter's estimate by field name (`None` if not identified).
    pub fn get(&self, field: &str) -> Option<Estimate> {
        self.params
            .iter()
            .find(|p| p.field == field)
            .and_then(|p| p.estimate)
    }

    /// The identified torque-driven robot, when every parameter it needs is
    /// known (`m, η, J, ψ` and the geometry, taken from `geometry` or else
    /// `fallback`) and the robot they make is a valid one
    /// ([`RobotParams::new`]: a fit that gives a mass or a friction
    /// that is not > 0 gives no robot).
    pub fn robot_params(&self, fallback: Option<&RobotParams>) -> Option<RobotParams> {
        let [l, r] = self
            .geometry
            .or_else(|| fallback.map(|p| [p.half_wheelbase(), p.wheel_radius()]))?;
        RobotParams::new(RobotParamsSpec {
            mass: self.get("mass")?.value,
            linear_friction: self.get("linear_friction")?.value,
            inertia: self.get("inertia")?.value,
            angular_friction: self.get("angular_friction")?.value,
            half_wheelbase: l,
            wheel_radius: r,
            torque_limit: None,
        })
        .ok()
    }

    /// The `[robots.NAME]` block: identified parameters as fields, each with
    /// its 95 % interval as a comment; unidentifiable ones and limits that
    /// are only observed as comments, never as values.
    pub fn robot_toml(&self, name: &str) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "# Identified by `echelon identify` from {} (agent {}, {} samples, {:.3} s), {} model.",
            self.source, self.agent, self.samples, self.duration, self.model
        );
        let key = toml_key(name);
        let _ = writeln!(s, "[robots.{key}]");
        if self.model == Model::Velocity {
            let _ = writeln!(s, "drive = \"velocity\"");
        }
        for p in &self.params {
            write_param(&mut s, p);
        }
        for l in &self.limits {
            write_limit(&mut s, l);
        }
        match (self.geometry, self.model) {
            (Some([l, r]), _) => {
                let _ = writeln!(s, "half_wheelbase = {}    # l, m (eq. 2)", sig(l));
                let _ = writeln!(s, "wheel_radius = {}    # r, m (eq. 2)", sig(r));
            }
            (None, Model::Torque) => {
                let _ = writeln!(
                    s,
                    "# half_wheelbase, wheel_radius: not in the log (it has no wheel torques); measure them"
                );
            }
            (None, Model::Velocity) => {}
        }
        s
    }
}

/// `name` as a TOML key: bare when it may be, quoted otherwise.
fn toml_key(name: &str) -> String {
    if name
        .chars()
        .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
        && !name.is_empty()
    {
        name.to_owned()
    } else {
        format!("{name:?}")
    }
}

/// One parameter's line of the `[robots.NAME]` block: its value with its
/// interval, its bound, or why it has none (as a comment).
fn write_param(s: &mut String, p: &Param) {
    if !is_robot_field(p.field) {
        // Not a `[robots.NAME]` field (the bag's dead time): said,
        // never written as a value a scenario would refuse.
        let _ = match (&p.estimate, &p.not_identifiable) {
            (Some(e), _) => writeln!(
                s,
                "# {} ({}) = {} {}: {} (echelon's base model has none; a controller's latency budget should hold it)",
                p.field,
                p.symbol,
                sig(e.value),
                p.unit,
                interval(e, p.noise_free)
            ),
            (None, why) => writeln!(
                s,
                "# {} ({}): not identifiable from this log: {}",
                p.field,
                p.symbol,
                why.as_deref().unwrap_or("no estimate")
            ),
        };
        return;
    }
    if let Some(upper) = p.upper_bound {
        let _ = writeln!(
            s,
            "{} = 0.0    # {}, {}: below what the odometry resolves, < {} at 95 %",
            p.field,
            p.symbol,
            p.unit,
            sig(upper)
        );
        return;
    }
    match (&p.estimate, &p.not_identifiable) {
        (Some(e), _) => {
            let _ = writeln!(
                s,
                "{} = {}    # {}, {}: {}",
                p.field,
                sig(e.value),
                p.symbol,
                p.unit,
                interval(e, p.noise_free)
            );
        }
        (None, why) => {
            let _ = writeln!(
                s,
                "# {} ({}): not identifiable from this log: {}",
                p.field,
                p.symbol,
                why.as_deref().unwrap_or("no estimate")
            );
        }
    }
}

/// One limit's line of the `[robots.NAME]` block: identified, observed as
/// held, or not reached (as a comment).
fn write_limit(s: &mut String, l: &Limit) {
    let unit = match l.field {
        "a_max" => "a_max, m/s²",
        _ => "α_max, rad/s²",
    };
    if let Some(e) = l.estimate {
        let _ = writeln!(
            s,
            "{} = {}    # {unit}: identified with the lag, {}",
            l.field,
            sig(e.value),
            interval(&e, l.noise_free)
        );
    } else if l.reached {
        let _ = writeln!(
            s,
            "{} = {}    # the log shows the base held here",
            l.field,
            sig(l.observed)
        );
    } else {
        let _ = writeln!(
            s,
            "# {}: not reached (largest seen: {})",
            l.field,
            sig(l.observed)
        );
    }
}

/// Whether a parameter is a `[robots.NAME]` field (the bag's dead time is
/// not: echelon's base model has none).
fn is_robot_field(field: &str) -> bool {
    field != "dead_time"
}

/// What a printed estimate's comment says of its interval: none on a
/// noise-free log, else its 95 % interval.
fn interval(e: &Estimate, noise_free: bool) -> String {
    if noise_free {
        "noise-free log, interval not meaningful".to_owned()
    } else {
        format!("95 % interval [{}, {}]", sig(e.ci95[0]), sig(e.ci95[1]))
    }
}

/// A number to 6 significant digits, in TOML syntax.
fn sig(x: f64) -> String {
    let v: f64 = format!("{x:.5e}").parse().unwrap_or(x);
    let s = format!("{v}");
    if s.contains('.') || s.contains('e') || s.contains("inf") || s.contains("NaN") {
        s
    } else {
        format!("{s}.0")
    }
}
