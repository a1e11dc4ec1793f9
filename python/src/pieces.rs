//! echelon's pieces as functions on arrays: the paper's law (eqs. 7–13) and
//! the kinematic law, Theorem 2 both ways, and identification from a log
//! (the safety filters: [`crate::safety`]).

use std::path::PathBuf;

use numpy::ndarray::Ix1;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use echelon::control::{self, Gains, LeaderMotion, Offset, Variant};
use echelon::error::num;
use echelon::identify::{self, Log, Model};
use echelon::kinematic::kinematic_law;
use echelon::model::{RobotParams, State};
use echelon::odometry::bound::{KinematicTheorem2, Theorem2};

use crate::arrays::{self, Dim};
use crate::errors;
use crate::simulation::state_of;

/// The array argument `field`: exactly `N` finite numbers.
fn fixed<const N: usize>(field: &str, a: &Bound<'_, PyAny>) -> PyResult<[f64; N]> {
    let a = arrays::readonly::<Ix1>(field, a, &[&[Dim::Is(N)]])?;
    let s = a.as_slice().map_err(errors::value)?;
    arrays::finite(field, s)?;
    s.try_into()
        .map_err(|_| errors::value(format!("{field}: {} numbers, expected {N}", s.len())))
}

/// The array argument `state`: `[x, y, θ]` or `[x, y, θ, v, ω]`, finite.
fn state_arg(state: &Bound<'_, PyAny>) -> PyResult<State> {
    let a = arrays::readonly::<Ix1>("state", state, &[&[Dim::Is(3)], &[Dim::Is(5)]])?;
    let s = a.as_slice().map_err(errors::value)?;
    arrays::finite("state", s)?;
    state_of(s)
}

/// The leader motion and offsets from their arrays.
fn leader(
    p: &Bound<'_, PyAny>,
    dp: &Bound<'_, PyAny>,
    ddp: Option<&Bound<'_, PyAny>>,
    offset: &Bound<'_, PyAny>,
) -> PyResult<(LeaderMotion, Offset)> {
    let [lx, ly, dly, ddly] = fixed::<4>("offset", offset)?;
    if !(lx > 0.0 && lx.is_finite()) {
        return Err(errors::value(format!(
            "offset: L_X = {} must be > 0 (eq. 4)",
            num(lx)
        )));
    }
    let motion = LeaderMotion {
        p: fixed::<2>("p", p)?,
        dp: fixed::<2>("dp", dp)?,
        ddp: match ddp {
            Some(a) => fixed::<2>("ddp", a)?,
            None => [0.0; 2],
        },
    };
    Ok((motion, Offset { lx, ly, dly, ddly }))
}

/// The paper's law (eqs. 7–13; `complete` cancels the cross term): returns
/// `(u, e, z)`, `u = [u1, u2]` before torque saturation.
#[pyfunction]
#[pyo3(signature = (state, p, dp, ddp, offset, robot_json, ke, kz, variant="paper"))]
#[allow(clippy::too_many_arguments)]
fn law_paper(
    state: &Bound<'_, PyAny>,
    p: &Bound<'_, PyAny>,
    dp: &Bound<'_, PyAny>,
    ddp: &Bound<'_, PyAny>,
    offset: &Bound<'_, PyAny>,
    robot_json: &str,
    ke: f64,
    kz: f64,
    variant: &str,
) -> PyResult<([f64; 2], [f64; 2], [f64; 2])> {
    let s = state_arg(state)?;
    let (motion, off) = leader(p, dp, Some(ddp), offset)?;
    let robot: RobotParams =
        serde_json::from_str(robot_json).map_err(|e| errors::value(format!("robot: {e}")))?;
    let gains = Gains::new(ke, kz).map_err(|e| errors::param(&e))?;
    let variant = match variant {
        "paper" => Variant::Paper,
        "complete" => Variant::Complete,
        other => {
            return Err(errors::value(format!(
                "variant: `{other}` (paper or complete)"
            )));
        }
    };
    let out = control::law(&robot, &s, &motion, &off, gains, variant);
    Ok(([out.u.u1, out.u.u2], out.e, out.z))
}

/// The kinematic law for a velocity base: returns `((v*, ω*), e, z)`.
#[pyfunction]
fn law_kinematic(
    state: &Bound<'_, PyAny>,
    p: &Bound<'_, PyAny>,
    dp: &Bound<'_, PyAny>,
    offset: &Bound<'_, PyAny>,
    ke: f64,
) -> PyResult<([f64; 2], [f64; 2], [f64; 2])> {
    let s = state_arg(state)?;
    let (motion, off) = leader(p, dp, None, offset)?;
    if !(ke > 0.0 && ke.is_finite()) {
        return Err(errors::value(format!(
            "ke: {} must be a finite number > 0",
            num(ke)
        )));
    }
    let k = kinematic_law(&s, &motion, &off, ke);
    Ok(([k.cmd.v, k.cmd.omega], k.e, k.z))
}

/// Theorem 2 forward (`steps` given: the bound) or inverse (`max_z` given:
/// the largest `N`), for the paper's law or the kinematic law; returns
/// `{z_bound, e_bound, steps, fix_period_s}`. Positional: `echelon.bound`
/// checks the arguments' types and holds the defaults.
#[pyfunction]
#[pyo3(signature = (ke, zeta, kz, omega_max, gamma, steps, max_z, max_e, ts, law, /))]
#[allow(clippy::too_many_arguments)]
fn bound<'py>(
    py: Python<'py>,
    ke: f64,
    zeta: f64,
    kz: Option<f64>,
    omega_max: Option<f64>,
    gamma: f64,
    steps: Option<u64>,
    max_z: Option<f64>,
    max_e: Option<f64>,
    ts: Option<f64>,
    law: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let given = [steps.is_some(), max_z.is_some(), max_e.is_some()];
    if given.iter().filter(|&&g| g).count() != 1 {
        return Err(errors::value(
            "give exactly one of steps (forward), max_z or max_e (inverse)",
        ));
    }
    if let Some(t) = ts {
        echelon::check::positive("ts", t).map_err(|e| errors::param(&e))?;
    }
    let period = |n: u64| ts.map(|t| t * n as f64);
    let (z_bound, steps, fix_period_s, e_bound) = match law {
        "paper" | "complete" | "dynamic" => {
            let (Some(kz), Some(omega_max)) = (kz, omega_max) else {
                return Err(errors::value(
                    "the paper's law's bound needs kz and omega_max",
                ));
            };
            if max_e.is_some() {
                return Err(errors::value(
                    "max_e: the paper's law's inverse takes max_z",
                ));
            }
            let th =
                Theorem2::new(ke, kz, zeta, omega_max, gamma).map_err(|e| errors::param(&e))?;
            let r = match (steps, max_z) {
                (Some(n), _) => th.forward(n, ts),
                (_, Some(z)) => th.inverse(z, ts).map_err(|e| errors::param(&e))?,
                _ => unreachable!("exactly one is given"),
            };
            (r.z_bound, r.steps, r.fix_period_s, r.z_bound / ke)
        }
        "kinematic" => {
            let th = KinematicTheorem2::new(ke, zeta, gamma).map_err(|e| errors::param(&e))?;
            let n = match (steps, max_z, max_e) {
                (Some(n), _, _) => n,
                (_, _, Some(e)) => th.max_steps(e).map_err(|e| errors::param(&e))?,
                _ => {
                    return Err(errors::value(
                        "max_z: the kinematic law's inverse takes max_e",
                    ));
                }
            };
            (th.z_bound(n), n, period(n), th.e_bound(n))
        }
        other => {
            return Err(errors::value(format!(
                "law: `{other}` (paper, complete or kinematic)"
            )));
        }
    };
    let d = PyDict::new(py);
    d.set_item("z_bound", z_bound)?;
    d.set_item("e_bound", e_bound)?;
    d.set_item("steps", steps)?;
    d.set_item("fix_period_s", fix_period_s)?;
    Ok(d)
}

/// The model to identify, by name or from the log's columns.
fn model_of(log: &Log, model: Option<&str>, agent: usize) -> PyResult<Model> {
    match model {
        Some("torque") => Ok(Model::Torque),
        Some("velocity") => Ok(Model::Velocity),
        Some(other) => Err(errors::value(format!("model: `{other}` (torque or velocity)"))),
        None => log.detect().ok_or_else(|| {
            errors::value(format!(
                "{}: missing columns: neither u1, u2 (torque model) nor v_applied, omega_applied / v_cmd, omega_cmd (velocity model) for agent {agent}",
                log.source
            ))
        }),
    }
}

/// Identifies a robot from a run directory or a trajectory CSV file (`path`)
/// or from CSV text (`csv`, with `trajectory.csv`'s columns): returns the
/// result as JSON and its `[robots.NAME]` TOML block.
#[pyfunction]
#[pyo3(signature = (*, path=None, csv=None, agent=1, model=None, name="identified"))]
fn identify_log(
    path: Option<PathBuf>,
    csv: Option<&str>,
    agent: usize,
    model: Option<&str>,
    name: &str,
) -> PyResult<(String, String)> {
    let log = match (path, csv) {
        (Some(p), None) => Log::read_run(&p, agent),
        (None, Some(text)) => Log::parse_csv(text, "<dataframe>", agent),
        _ => return Err(errors::value("give one of path or csv")),
    }
    .map_err(errors::value)?;
    let model = model_of(&log, model, agent)?;
    let id = identify::identify(&log, model).map_err(errors::value)?;
    let json = serde_json::to_string(&id).map_err(errors::value)?;
    Ok((json, id.robot_toml(name)))
}

/// A robot preset's eq. 3 parameters as JSON (`agent1`, `agent2`: Table I).
#[pyfunction]
fn robot_preset(name: &str) -> PyResult<String> {
    let robot = RobotParams::preset(name).ok_or_else(|| {
        let names: Vec<&str> = RobotParams::PRESETS.iter().map(|(n, _)| *n).collect();
        errors::value(format!(
            "robot: `{name}` is not a preset ({})",
            names.join(", ")
        ))
    })?;
    serde_json::to_string(&robot).map_err(errors::value)
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(law_paper, m)?)?;
    m.add_function(wrap_pyfunction!(law_kinematic, m)?)?;
    m.add_function(wrap_pyfunction!(robot_preset, m)?)?;
    m.add_function(wrap_pyfunction!(bound, m)?)?;
    m.add_function(wrap_pyfunction!(identify_log, m)?)?;
    Ok(())
}
