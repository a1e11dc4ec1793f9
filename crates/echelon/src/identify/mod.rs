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

mod fit;

use std::fmt::Write as _;
use std::path::Path;

use serde::Serialize;

use fit::{AxisData, AxisFit, Z95};

use crate::model::RobotParams;

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

/// Why a log cannot be identified. Every message names the log.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum IdentifyError {
    /// The log could not be read or parsed.
    #[error("{file}: {reason}")]
    Read {
        /// The log.
        file: String,
        /// What went wrong.
        reason: String,
    },
    /// Columns the model needs are absent.
    #[error("{file}: missing column(s) {columns} (the {model} model needs {needed})")]
    MissingColumns {
        /// The log.
        file: String,
        /// The absent columns, comma-separated.
        columns: String,
        /// The model asked for.
        model: Model,
        /// Every column it needs.
        needed: String,
    },
    /// The chosen agent has no rows.
    #[error("{file}: no rows for agent {agent} (agents in the log: {present})")]
    NoAgent {
        /// The log.
        file: String,
        /// The agent asked for.
        agent: usize,
        /// The agents present.
        present: String,
    },
    /// Too few samples.
    #[error("{file}: log too short: {samples} samples of agent {agent}, at least {min} needed")]
    TooShort {
        /// The log.
        file: String,
        /// The agent.
        agent: usize,
        /// Samples found.
        samples: usize,
        /// Samples needed ([`MIN_SAMPLES`]).
        min: usize,
    },
    /// A needed value is NaN or infinite.
    #[error("{file}: non-finite {column} = {value} at t = {t} s (agent {agent})")]
    NonFinite {
        /// The log.
        file: String,
        /// The column.
        column: &'static str,
        /// The value.
        value: f64,
        /// Its time.
        t: f64,
        /// The agent.
        agent: usize,
    },
    /// Sample times do not increase.
    #[error("{file}: time does not increase at t = {t} s (agent {agent})")]
    Time {
        /// The log.
        file: String,
        /// The time that does not follow its predecessor.
        t: f64,
        /// The agent.
        agent: usize,
    },
    /// An MCAP log lacks the channels the model needs.
    #[error("{file}: missing {what} (topics in the file: {present})")]
    MissingTopics {
        /// The log.
        file: String,
        /// What is missing.
        what: String,
        /// The topics it has, comma-separated.
        present: String,
    },
    /// Neither axis was excited: nothing can be identified.
    #[error("{file}: no excitation: {reason}")]
    NoExcitation {
        /// The log.
        file: String,
        /// Why, per axis.
        reason: String,
    },
}

/// A logged manoeuvre of one robot: velocities measured at the sample times
/// and the inputs held from each sample to the next.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Log {
    /// Where it came from (in errors and the summary).
    pub source: String,
    /// The agent number, from 1.
    pub agent: usize,
    /// Sample times, s, increasing.
    pub t: Vec<f64>,
    /// Measured linear speed, m/s.
    pub v: Vec<f64>,
    /// Measured angular speed, rad/s.
    pub omega: Vec<f64>,
    /// Torque inputs `u1` (N), `u2` (N m), if logged.
    pub u: Option<[Vec<f64>; 2]>,
    /// Wheel torques `τr, τl`, N m, if logged (give `l`, `r` with `u`).
    pub tau: Option<[Vec<f64>; 2]>,
    /// Commanded `(v*, ω*)`, if logged.
    pub cmd: Option<[Vec<f64>; 2]>,
    /// The command after the base's speed limits, if logged.
    pub applied: Option<[Vec<f64>; 2]>,
    /// The running integrals at the sample times (a run's `integrals.csv`),
    /// if logged: with them the fit is exact whatever the input did between
    /// samples.
    pub integrals: Option<Integrals>,
    /// What reading the log found worth saying (copied into the warnings).
    pub notes: Vec<String>,
    /// The inputs' own zero-order hold when it is known apart from the
    /// samples (a ROS 2 bag's command messages): the output-error fit then
    /// integrates the model exactly on it, instead of holding the inputs'
    /// per-sample values (`cmd`, `applied`, `u`) over each interval.
    pub hold: Option<Hold>,
    /// The period over which the plant's input was held, s, when the log
    /// says (a run directory's `summary.json`: the controller period, or
    /// `dt` when a safety filter holds each step's command; `None` for a
    /// continuous-time law or an unknown source). A log slower than this
    /// hold, without integrals, cannot know the input between its samples:
    /// holding the sampled values is then not taken as exact
    /// ([`fit`](self)), and the spread of the hold, the backward hold and
    /// the ramp joins each interval.
    pub input_period: Option<f64>,
}

/// Inputs held from each switch time to the next.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Hold {
    /// Switch times, s, on the clock of [`Log::t`], increasing; the first at
    /// or before the first sample.
    pub t: Vec<f64>,
    /// The two inputs' values held from each switch time.
    pub u: [Vec<f64>; 2],
}

/// Running integrals of one agent at the sample times
/// ([`crate::output::INTEGRALS_HEADER`]); only their differences are used.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Integrals {
    /// Distance travelled `∫v dt`, m.
    pub s: Vec<f64>,
    /// Heading, not wrapped (`θ₀ + ∫ω dt`), rad.
    pub theta: Vec<f64>,
    /// `∫ input dt` of the plant's inputs: `u1, u2` (torque) or the applied
    /// `v, ω` command (velocity base).
    pub input: [Vec<f64>; 2],
}

/// Reads a CSV column set into per-agent series.
fn column(header: &csv::StringRecord, name: &str) -> Option<usize> {
    header.iter().position(|h| h.trim() == name)
}

impl Log {
    /// Reads agent `agent`'s rows of `DIR/trajectory.csv` (an `echelon run`
    /// directory), or of the CSV file itself if `path` is a file.
    pub fn read_run(path: &Path, agent: usize) -> Result<Log, IdentifyError> {
        let file = if path.is_dir() {
            path.join(crate::output::TRAJECTORY_FILE)
        } else {
            path.to_path_buf()
        };
        let origin = file.display().to_string();
        let text = std::fs::read_to_string(&file).map_err(|e| IdentifyError::Read {
            file: origin.clone(),
            reason: format!("cannot read: {e}"),
        })?;
        let mut log = Log::parse_csv(&text, &origin, agent)?;
        log.input_period = file
            .parent()
            .and_then(|d| std::fs::read_to_string(d.join(crate::output::SUMMARY_FILE)).ok())
            .and_then(|text| serde_json::from_str::<serde_json::Value>(&text).ok())
            .and_then(|s| {
                let dt = s["dt"].as_f64();
                s["controller_period"]
                    .as_f64()
                    .or_else(|| s.get("safety").and(dt))
            });
        let beside = file.parent().map(|d| d.join(crate::output::INTEGRALS_FILE));
        if let Some(path) = beside.filter(|p| p.is_file()) {
            match std::fs::read_to_string(&path)
                .map_err(|e| e.to_string())
                .and_then(|text| log.attach_integrals(&text))
            {
                Ok(()) => {}
                Err(why) => log.notes.push(format!(
                    "{} not used: {why}; the fit falls back to the sampled inputs",
                    path.display()
                )),
            }
        }
        Ok(log)
    }

    /// Attaches this agent's rows of an `integrals.csv` (header
    /// [`crate::output::INTEGRALS_HEADER`]); they must be at the log's
    /// sample times.
    pub fn attach_integrals(&mut self, text: &str) -> Result<(), String> {
        let mut rdr = csv::ReaderBuilder::new().from_reader(text.as_bytes());
        let header = rdr.headers().map_err(|e| e.to_string())?.clone();
        let names = ["t", "agent", "s", "theta", "int_1", "int_2"];
        let idx: Vec<usize> = names
            .iter()
            .map(|c| column(&header, c).ok_or_else(|| format!("no column {c}")))
            .collect::<Result<_, _>>()?;
        let mut cols: [Vec<f64>; 5] = Default::default();
        for (line, rec) in rdr.records().enumerate() {
            let rec = rec.map_err(|e| format!("line {}: {e}", line + 2))?;
            let num = |k: usize| -> Result<f64, String> {
                let cell = rec.get(idx[k]).unwrap_or("");
                cell.trim()
                    .parse::<f64>()
                    .map_err(|_| format!("line {}: {} = `{cell}`", line + 2, names[k]))
            };
            if num(1)? != self.agent as f64 {
                continue;
            }
            for (k, c) in [0, 2, 3, 4, 5].into_iter().zip(cols.iter_mut()) {
                c.push(num(k)?);
            }
        }
        let [t, s, theta, i1, i2] = cols;
        if t.len() != self.t.len() || t.iter().zip(&self.t).any(|(a, b)| (a - b).abs() > 1e-9) {
            return Err(format!(
                "its {} rows of agent {} are not at the log's {} sample times",
                t.len(),
                self.agent,
                self.t.len()
            ));
        }
        if [&s, &theta, &i1, &i2]
            .iter()
            .any(|c| c.iter().any(|x| !x.is_finite()))
        {
            return Err("non-finite values".to_owned());
        }
        self.integrals = Some(Integrals {
            s,
            theta,
            input: [i1, i2],
        });
        Ok(())
    }

    /// Parses a `trajectory.csv` (header with `t, agent, v, omega` and some of
    /// `u1, u2, tau_r, tau_l, v_cmd, omega_cmd, v_applied, omega_applied`).
    pub fn parse_csv(text: &str, origin: &str, agent: usize) -> Result<Log, IdentifyError> {
        let read_err = |reason: String| IdentifyError::Read {
            file: origin.to_owned(),
            reason,
        };
        let mut rdr = csv::ReaderBuilder::new().from_reader(text.as_bytes());
        let header = rdr
            .headers()
            .map_err(|e| read_err(format!("not a CSV file: {e}")))?
            .clone();
        let base = ["t", "agent", "v", "omega"];
        let missing: Vec<&str> = base
            .iter()
            .copied()
            .filter(|c| column(&header, c).is_none())
            .collect();
        if !missing.is_empty() {
            return Err(read_err(format!(
                "missing column(s) {} (a trajectory.csv has t, agent, v, omega)",
                missing.join(", ")
            )));
        }
        let idx = |c: &str| column(&header, c);
        let pair = |a: &str, b: &str| idx(a).zip(idx(b));
        let (it, ia, iv, iw) = (idx("t"), idx("agent"), idx("v"), idx("omega"));
        let groups = [
            pair("u1", "u2"),
            pair("tau_r", "tau_l"),
            pair("v_cmd", "omega_cmd"),
            pair("v_applied", "omega_applied"),
        ];
        let mut log = Log {
            source: origin.to_owned(),
            agent,
            ..Log::default()
        };
        let mut cols: [[Vec<f64>; 2]; 4] = Default::default();
        let mut agents = std::collections::BTreeSet::new();
        for (line, rec) in rdr.records().enumerate() {
            let rec = rec.map_err(|e| read_err(format!("line {}: {e}", line + 2)))?;
            let num = |i: Option<usize>, name: &str| -> Result<f64, IdentifyError> {
                let cell = i.and_then(|i| rec.get(i)).unwrap_or("");
                cell.trim().parse::<f64>().map_err(|_| {
                    read_err(format!(
                        "line {}: {name} = `{cell}` is not a number",
                        line + 2
                    ))
                })
            };
            let a = num(ia, "agent")?;
            agents.insert(a as i64);
            if a != agent as f64 {
                continue;
            }
            log.t.push(num(it, "t")?);
            log.v.push(num(iv, "v")?);
            log.omega.push(num(iw, "omega")?);
            for (g, cols) in groups.iter().zip(cols.iter_mut()) {
                if let Some((i0, i1)) = g {
                    cols[0].push(num(Some(*i0), &header[*i0])?);
                    cols[1].push(num(Some(*i1), &header[*i1])?);
                }
            }
        }
        if log.t.is_empty() {
            let present: Vec<String> = agents.iter().map(i64::to_string).collect();
            return Err(IdentifyError::NoAgent {
                file: origin.to_owned(),
                agent,
                present: if present.is_empty() {
                    "none".to_owned()
                } else {
                    present.join(", ")
                },
            });
        }
        let [u, tau, cmd, applied] = cols;
        // A group is present if logged and not all NaN (a torque agent's
        // velocity cells and a velocity agent's torque cells are NaN).
        let keep = |g: Option<(usize, usize)>, c: [Vec<f64>; 2]| {
            (g.is_some() && !c[0].iter().all(|x| x.is_nan())).then_some(c)
        };
        log.u = keep(groups[0], u);
        log.tau = keep(groups[1], tau);
        log.cmd = keep(groups[2], cmd);
        log.applied = keep(groups[3], applied);
        Ok(log)
    }

    /// The model this log can serve: torque if it has `u1, u2`, velocity if
    /// it has the applied command, `None` if neither.
    pub fn detect(&self) -> Option<Model> {
        if self.u.is_some() {
            Some(Model::Torque)
        } else if self.applied.is_some() || self.cmd.is_some() {
            Some(Model::Velocity)
        } else {
            None
        }
    }

    fn check(&self, model: Model) -> Result<(), IdentifyError> {
        let file = || self.source.clone();
        let (names, inputs) = match model {
            Model::Torque => (["u1", "u2"], self.u.as_ref()),
            Model::Velocity => (
                ["v_applied", "omega_applied"],
                self.applied.as_ref().or(self.cmd.as_ref()),
            ),
        };
        let needed = match model {
            Model::Torque => "t, agent, v, omega, u1, u2",
            Model::Velocity => {
                "t, agent, v, omega and v_applied, omega_applied (or v_cmd, omega_cmd)"
            }
        };
        let Some(inputs) = inputs else {
            return Err(IdentifyError::MissingColumns {
                file: file(),
                columns: names.join(", "),
                model,
                needed: needed.to_owned(),
            });
        };
        let n = self.t.len();
        if n < MIN_SAMPLES {
            return Err(IdentifyError::TooShort {
                file: file(),
                agent: self.agent,
                samples: n,
                min: MIN_SAMPLES,
            });
        }
        let series: [(&'static str, &[f64]); 5] = [
            ("t", &self.t),
            ("v", &self.v),
            ("omega", &self.omega),
            (
                if model == Model::Torque {
                    "u1"
                } else {
                    "v_applied"
                },
                &inputs[0],
            ),
            (
                if model == Model::Torque {
                    "u2"
                } else {
                    "omega_applied"
                },
                &inputs[1],
            ),
        ];
        for (column, s) in series {
            if let Some(i) = s.iter().position(|x| !x.is_finite()) {
                return Err(IdentifyError::NonFinite {
                    file: file(),
                    column,
                    value: s[i],
                    t: self.t[i],
                    agent: self.agent,
                });
            }
        }
        if let Some(i) = self.t.windows(2).position(|w| w[1] <= w[0]) {
            return Err(IdentifyError::Time {
                file: file(),
                t: self.t[i + 1],
                agent: self.agent,
            });
        }
        Ok(())
    }
}

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
    fn new(value: f64, var: f64, first_guess: f64) -> Estimate {
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
    /// The estimate, `None` if not identifiable.
    pub estimate: Option<Estimate>,
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
    /// Residuals at rounding level ([`NOISE_FREE_RELATIVE_RMS`]): a
    /// simulated, noise-free log; the intervals are not meaningful.
    pub noise_free: bool,
    /// How the axis was fitted: `integrals` (exact, from `integrals.csv`),
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
    /// Largest magnitude seen.
    pub observed: f64,
    /// Whether the log shows it is the limit (the command exceeded it and the
    /// base cut it); otherwise it is only what the manoeuvre reached.
    pub reached: bool,
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

/// What [`identify`] found.
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
        RobotParams::new(
            self.get("mass")?.value,
            self.get("linear_friction")?.value,
            self.get("inertia")?.value,
            self.get("angular_friction")?.value,
            l,
            r,
        )
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
        let key = if name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
            && !name.is_empty()
        {
            name.to_owned()
        } else {
            format!("{name:?}")
        };
        let _ = writeln!(s, "[robots.{key}]");
        if self.model == Model::Velocity {
            let _ = writeln!(s, "drive = \"velocity\"");
        }
        for p in &self.params {
            match (&p.estimate, &p.not_identifiable) {
                (Some(e), _) if p.noise_free => {
                    let _ = writeln!(
                        s,
                        "{} = {}    # {}, {}: noise-free log, interval not meaningful",
                        p.field,
                        sig(e.value),
                        p.symbol,
                        p.unit
                    );
                }
                (Some(e), _) => {
                    let _ = writeln!(
                        s,
                        "{} = {}    # {}, {}: 95 % interval [{}, {}]",
                        p.field,
                        sig(e.value),
                        p.symbol,
                        p.unit,
                        sig(e.ci95[0]),
                        sig(e.ci95[1])
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
        for l in &self.limits {
            if l.reached {
                let _ = writeln!(
                    s,
                    "{} = {}    # the log shows the base held here",
                    l.field,
                    sig(l.observed)
                );
            } else {
                let _ = writeln!(
                    s,
                    "# {}: observed {}, not necessarily the limit",
                    l.field,
                    sig(l.observed)
                );
            }
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

/// Identifies `model` from `log`.
///
/// Errors: missing inputs, fewer than [`MIN_SAMPLES`] samples, non-finite
/// values, times that do not increase, or no axis excited at all.
pub fn identify(log: &Log, model: Model) -> Result<Identified, IdentifyError> {
    log.check(model)?;
    let inputs = match model {
        Model::Torque => log.u.as_ref(),
        Model::Velocity => log.applied.as_ref().or(log.cmd.as_ref()),
    }
    .ok_or_else(|| IdentifyError::Read {
        file: log.source.clone(),
        reason: "no inputs".to_owned(),
    })?;
    let fixed_gain = model == Model::Velocity;
    let measured = [&log.v, &log.omega];
    let input_names = match model {
        Model::Torque => ["u1", "u2"],
        Model::Velocity => ["v_applied", "omega_applied"],
    };
    let mut params = Vec::new();
    let mut warnings = log.notes.clone();
    let mut axes = Vec::new();
    let mut predicted: [Vec<f64>; 2] = Default::default();
    let mut reasons = Vec::new();
    // Whether an excited axis was withheld for misfit (then the log is
    // answered, with the reasons, rather than refused as unexcited).
    let mut misfits = false;
    for axis in 0..2 {
        let d = AxisData {
            t: &log.t,
            u: &inputs[axis],
            y: measured[axis],
            hold: log.hold.as_ref().map(|h| (&h.t[..], &h.u[axis][..])),
        };
        let integrals = log.integrals.as_ref().map(|w| fit::AxisIntegrals {
            s: [&w.s, &w.theta][axis],
            i: &w.input[axis],
        });
        // Samples farther apart than the plant's own input hold: the
        // sampled values do not hold over the intervals.
        let slower = log.input_period.is_some_and(|p| {
            let n = log.t.len();
            n > 1 && (log.t[n - 1] - log.t[0]) / (n - 1) as f64 > 1.5 * p
        });
        let f = match &integrals {
            Some(w) => fit::fit_integral(&d, w, fixed_gain),
            None => fit::fit(&d, fixed_gain, slower),
        };
        let y_rms = (d.y.iter().map(|y| y * y).sum::<f64>() / d.y.len() as f64).sqrt();
        let noise_free = f.rms <= NOISE_FREE_RELATIVE_RMS * y_rms;
        if let Some(b) = f.between {
            let rel = |i: usize| (f.theta[i] - b.held[i]).abs() / f.theta[i].abs();
            warnings.push(format!(
                "the {} axis's inputs between samples are not in the log (no integrals.csv, and {}, cost ratio {:.3}): the fit interpolates them linearly and its intervals include the difference to holding them ({:.2} % on τ, {:.2} % on the gain)",
                ["linear", "angular"][axis],
                if slower {
                    "the samples are farther apart than the plant's input hold in summary.json"
                } else {
                    "holding the logged values does not fit better than interpolating them"
                },
                b.cost_ratio,
                100.0 * rel(0),
                100.0 * rel(1)
            ));
        }
        let checks = ResidualChecks::new(&d, &f);
        let method = match (&integrals, d.hold.is_some(), f.between.is_some()) {
            (Some(_), _, _) => "integrals",
            (None, true, _) => "command hold",
            (None, false, true) => "interpolated inputs",
            (None, false, false) => "held inputs",
        };
        let summary = |identifiable| AxisSummary {
            noise_free,
            method,
            checks,
            axis: ["linear", "angular"][axis],
            residual_rms: f.rms,
            residual_max: d
                .y
                .iter()
                .zip(&f.predicted)
                .map(|(y, p)| (y - p).abs())
                .fold(0.0, f64::max),
            rcond: f.rcond,
            identifiable,
        };
        let (estimates, symbols) = axis_params(model, axis, &f);
        // A velocity base without lag on this axis moves at its command:
        // the integrals of both agree throughout and there is no τ.
        let no_lag = match (&integrals, fixed_gain) {
            (Some(w), true) => {
                let top = w.i.iter().map(|x| (x - w.i[0]).abs()).fold(0.0, f64::max);
                let gap =
                    w.i.iter()
                        .zip(w.s)
                        .map(|(i, s)| ((i - w.i[0]) - (s - w.s[0])).abs())
                        .fold(0.0, f64::max);
                (top > 0.0 && gap <= 1e-9 * top).then(|| {
                    format!(
                        "the base moves at its {} throughout (∫ of the command equals ∫ of the velocity): no lag on this axis",
                        input_names[axis]
                    )
                })
            }
            _ => None,
        };
        let unexcited = no_lag.or_else(|| excitation(&d, &f, &estimates, input_names[axis]));
        let why = unexcited.clone().or_else(|| {
            (!noise_free)
                .then(|| misfit(&f, &checks, integrals.is_some() || d.hold.is_some()))
                .flatten()
        });
        misfits |= unexcited.is_none() && why.is_some();
        match &why {
            Some(reason) => {
                warnings.push(format!(
                    "{} not identifiable: {reason}",
                    symbols.iter().map(|s| s.1).collect::<Vec<_>>().join(", ")
                ));
                reasons.push(format!("{} axis: {reason}", ["linear", "angular"][axis]));
            }
            None => {
                predicted[axis].clone_from(&f.predicted);
                if noise_free {
                    warnings.push(format!(
                        "noise-free log on the {} axis (residual RMS {:.1e}): {} exact to rounding, intervals not meaningful",
                        ["linear", "angular"][axis],
                        f.rms,
                        symbols.iter().map(|s| s.1).collect::<Vec<_>>().join(", ")
                    ));
                }
            }
        }
        for ((field, symbol, unit), e) in symbols.iter().zip(estimates) {
            params.push(Param {
                field,
                symbol,
                unit,
                estimate: why.is_none().then_some(e),
                not_identifiable: why.clone(),
                noise_free: noise_free && why.is_none(),
            });
        }
        if why.is_some() {
            predicted[axis] = vec![f64::NAN; log.t.len()];
        }
        axes.push(summary(why.is_none()));
    }
    if axes.iter().all(|a| !a.identifiable) && !misfits {
        return Err(IdentifyError::NoExcitation {
            file: log.source.clone(),
            reason: reasons.join("; "),
        });
    }
    let geometry = match (model, &log.u, &log.tau) {
        (Model::Torque, Some(u), Some(tau)) => geometry(u, tau),
        _ => None,
    };
    let limits = if model == Model::Velocity {
        velocity_limits(log, inputs, &mut warnings)
    } else {
        Vec::new()
    };
    let [axis0, axis1]: [AxisSummary; 2] = axes.try_into().map_err(|_| IdentifyError::Read {
        file: log.source.clone(),
        reason: "internal: two axes".to_owned(),
    })?;
    let [v_model, omega_model] = predicted;
    Ok(Identified {
        model,
        source: log.source.clone(),
        agent: log.agent,
        samples: log.t.len(),
        duration: log.t[log.t.len() - 1] - log.t[0],
        params,
        axes: [axis0, axis1],
        geometry,
        limits,
        warnings,
        prediction: Prediction {
            t: log.t.clone(),
            v: log.v.clone(),
            v_model,
            omega: log.omega.clone(),
            omega_model,
        },
    })
}

type Symbol = (&'static str, &'static str, &'static str);

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

/// Why an axis's parameters are not identifiable, or `None` if they are.
fn excitation(
    d: &AxisData<'_>,
    f: &AxisFit,
    estimates: &[Estimate],
    input: &str,
) -> Option<String> {
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

/// The residual checks of one axis ([`misfit`]), as `identify.json`
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
}

impl ResidualChecks {
    fn new(d: &AxisData<'_>, f: &AxisFit) -> ResidualChecks {
        let r: Vec<f64> = d.y.iter().zip(&f.predicted).map(|(y, p)| y - p).collect();
        let (ljung_box_q, ljung_box_bound, lag1_autocorrelation) =
            fit::ljung_box(&r, WHITENESS_LAGS);
        let (scan_z, scan_bound, [a, b]) = fit::scan(&r);
        ResidualChecks {
            ljung_box_q,
            ljung_box_bound,
            lag1_autocorrelation,
            scan_z,
            scan_bound,
            scan_window: [d.t[a], d.t[b]],
            noise_from_differences: fit::noise_from_differences(d.y),
        }
    }
}

/// Why the model misfits the log (its residuals are not the measurement's
/// white noise), or `None`. Called on logs that are not noise-free: a
/// noise-free log whose residuals are not at rounding level is misfit, and
/// shows as residuals far above the (rounding-level) noise and not white.
fn misfit(f: &AxisFit, c: &ResidualChecks, exact: bool) -> Option<String> {
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
    if f.rms > MAX_RESIDUAL_OVER_NOISE * noise {
        return Some(format!(
            "the model misfits this log: its residual RMS {:.2e} is {:.1} times the noise the measurement shows by itself ({noise:.2e}){hint}",
            f.rms,
            f.rms / noise
        ));
    }
    None
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

/// Observed speed and acceleration limits of a velocity base, with warnings.
fn velocity_limits(log: &Log, applied: &[Vec<f64>; 2], warnings: &mut Vec<String>) -> Vec<Limit> {
    let mut out = Vec::new();
    let measured = [&log.v, &log.omega];
    for axis in 0..2 {
        let (speed, accel) = [("v_max", "a_max"), ("omega_max", "alpha_max")][axis];
        let a = &applied[axis];
        let top = a.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
        // The base cut the command on this axis, at its largest applied value.
        let reached = log.cmd.as_ref().is_some_and(|cmd| {
            cmd[axis]
                .iter()
                .zip(a)
                .any(|(c, a)| c.abs() > a.abs() + 1e-9 && a.abs() >= top * (1.0 - 1e-6))
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
        });
        if !reached {
            warnings.push(format!(
                "{speed}: observed {observed:.4}, not necessarily the limit (the command never exceeded it)"
            ));
        }
        // Acceleration: the largest |Δv/Δt| of the measurement over 5-sample
        // spans (noise averaged). It is the limit when the rate sits on it
        // (within 0.5 %) for at least 10 samples: a lag's rate only touches
        // its peak, a limited one rides it.
        let w = 5;
        let rates: Vec<f64> = (0..log.t.len().saturating_sub(w))
            .map(|i| {
                ((measured[axis][i + w] - measured[axis][i]) / (log.t[i + w] - log.t[i])).abs()
            })
            .collect();
        let acc = rates.iter().fold(0.0_f64, |m, r| m.max(*r));
        let riding = rates.iter().filter(|r| **r >= 0.995 * acc).count();
        let reached = acc > 0.0 && riding >= 10;
        out.push(Limit {
            field: accel,
            observed: acc,
            reached,
        });
        if reached {
            warnings.push(format!(
                "{accel} = {acc:.4} acted during the log ({riding} samples on it): the first-order lag ignores it, so {} is biased; log gentler steps to identify the lag",
                ["tau_v", "tau_omega"][axis]
            ));
        } else {
            warnings.push(format!(
                "{accel}: observed {acc:.4}, not necessarily the limit"
            ));
        }
    }
    out
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
