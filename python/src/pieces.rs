//! echelon's pieces as functions on arrays: the paper's law (eqs. 7–13) and
//! the kinematic law, the barrier-certificate safety filter for velocity
//! robots, Theorem 2 both ways, and identification from a log.

use std::path::PathBuf;

use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;

use echelon::base::{VelocityBase, VelocityCommand, VelocityRobot};
use echelon::control::{self, Gains, LeaderMotion, Offset, Variant};
use echelon::identify::{self, Log, Model};
use echelon::kinematic::kinematic_law;
use echelon::model::RobotParams;
use echelon::odometry::bound::{KinematicTheorem2, Theorem2};
use echelon::safety::{Neighbour, Obstacle, SafetyConfig, SafetyFilter};

use crate::errors;
use crate::simulation::state_of;

/// Exactly `N` numbers.
fn fixed<const N: usize>(field: &str, a: &PyReadonlyArray1<'_, f64>) -> PyResult<[f64; N]> {
    let s = a.as_slice().map_err(errors::value)?;
    s.try_into()
        .map_err(|_| errors::value(format!("{field}: {} numbers, expected {N}", s.len())))
}

/// The leader motion and offsets from their arrays.
fn leader(
    p: &PyReadonlyArray1<'_, f64>,
    dp: &PyReadonlyArray1<'_, f64>,
    ddp: Option<&PyReadonlyArray1<'_, f64>>,
    offset: &PyReadonlyArray1<'_, f64>,
) -> PyResult<(LeaderMotion, Offset)> {
    let [lx, ly, dly, ddly] = fixed::<4>("offset", offset)?;
    if !(lx > 0.0 && lx.is_finite()) {
        return Err(errors::value(format!(
            "offset: L_X = {lx} must be > 0 (eq. 4)"
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
    state: PyReadonlyArray1<'_, f64>,
    p: PyReadonlyArray1<'_, f64>,
    dp: PyReadonlyArray1<'_, f64>,
    ddp: PyReadonlyArray1<'_, f64>,
    offset: PyReadonlyArray1<'_, f64>,
    robot_json: &str,
    ke: f64,
    kz: f64,
    variant: &str,
) -> PyResult<([f64; 2], [f64; 2], [f64; 2])> {
    let s = state_of(state.as_slice().map_err(errors::value)?)?;
    let (motion, off) = leader(&p, &dp, Some(&ddp), &offset)?;
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
    state: PyReadonlyArray1<'_, f64>,
    p: PyReadonlyArray1<'_, f64>,
    dp: PyReadonlyArray1<'_, f64>,
    offset: PyReadonlyArray1<'_, f64>,
    ke: f64,
) -> PyResult<([f64; 2], [f64; 2], [f64; 2])> {
    let s = state_of(state.as_slice().map_err(errors::value)?)?;
    let (motion, off) = leader(&p, &dp, None, &offset)?;
    if !(ke > 0.0 && ke.is_finite()) {
        return Err(errors::value(format!(
            "ke: {ke} must be a finite number > 0"
        )));
    }
    let k = kinematic_law(&s, &motion, &off, ke);
    Ok(([k.cmd.v, k.cmd.omega], k.e, k.z))
}

/// The filtered commands, each robot's outcome and its closest neighbour.
type Filtered<'py> = (Bound<'py, PyArray2<f64>>, Vec<&'static str>, Vec<f64>);

/// Safety filters for `n` velocity-controlled robots, one each (their
/// deadlock monitors keep state between calls).
#[pyclass(module = "echelon._echelon", name = "SafetyFilters")]
#[derive(Debug)]
struct PySafetyFilters {
    filters: Vec<SafetyFilter>,
    obstacles: Vec<Obstacle>,
    base: VelocityBase,
    l: f64,
    // Scratch.
    states: Vec<echelon::State>,
    neighbours: Vec<Neighbour>,
}

#[pymethods]
impl PySafetyFilters {
    /// `n` robots keeping their points `l` ahead `radius` apart and
    /// `radius` from obstacles' edges (`(m, 3)`: x, y, r); `gain` is the
    /// barrier's γ, `range` the sensing range, `period` the control
    /// period, `base` a velocity base preset (`ideal`, `jackal`, …).
    #[new]
    #[pyo3(signature = (n, radius, gain=1.0, range=f64::INFINITY, l=0.1, obstacles=None, period=0.01, base="ideal"))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        n: usize,
        radius: f64,
        gain: f64,
        range: f64,
        l: f64,
        obstacles: Option<PyReadonlyArray2<'_, f64>>,
        period: f64,
        base: &str,
    ) -> PyResult<Self> {
        let config = SafetyConfig::new(radius, gain, range).map_err(|e| errors::param(&e))?;
        if !(l > 0.0 && l.is_finite()) {
            return Err(errors::value(format!("l: {l} must be a finite number > 0")));
        }
        if !(period > 0.0 && period.is_finite()) {
            return Err(errors::value(format!(
                "period: {period} must be a finite number > 0"
            )));
        }
        let base = VelocityRobot::preset(base)
            .map(|r| r.base())
            .ok_or_else(|| {
                let names: Vec<&str> = VelocityRobot::PRESETS.iter().map(|(n, _)| *n).collect();
                errors::value(format!(
                    "base: `{base}` is not a preset ({})",
                    names.join(", ")
                ))
            })?;
        let mut obs = Vec::new();
        if let Some(o) = obstacles {
            let a = o.as_array();
            if a.ncols() != 3 {
                return Err(errors::value("obstacles: expected rows of (x, y, r)"));
            }
            for row in a.rows() {
                obs.push(Obstacle::new(row[0], row[1], row[2]).map_err(|e| errors::param(&e))?);
            }
        }
        Ok(PySafetyFilters {
            filters: (0..n)
                .map(|_| SafetyFilter::new(config).with_period(period))
                .collect(),
            obstacles: obs,
            base,
            l,
            states: Vec::with_capacity(n),
            neighbours: Vec::with_capacity(n),
        })
    }

    /// Filters `commands` (`(n, 2)`: v, ω) of robots in `poses` (`(n, 3)`:
    /// x, y, θ, moving at their commands; or `(n, 5)` with v, ω) at time `t`:
    /// returns the filtered commands `(n, 2)`, each robot's outcome
    /// (`nominal`, `filtered`, `braked`) and the smallest distance from its
    /// point to a neighbour's.
    fn filter<'py>(
        &mut self,
        py: Python<'py>,
        t: f64,
        poses: PyReadonlyArray2<'_, f64>,
        commands: PyReadonlyArray2<'_, f64>,
    ) -> PyResult<Filtered<'py>> {
        let (p, c) = (poses.as_array(), commands.as_array());
        let n = self.filters.len();
        if p.nrows() != n || !(p.ncols() == 3 || p.ncols() == 5) {
            return Err(errors::value(format!(
                "poses: shape {:?}, expected ({n}, 3) or ({n}, 5)",
                p.shape()
            )));
        }
        if c.shape() != [n, 2] {
            return Err(errors::value(format!(
                "commands: shape {:?}, expected ({n}, 2)",
                c.shape()
            )));
        }
        self.states.clear();
        for i in 0..n {
            let row: Vec<f64> = p.row(i).to_vec();
            let mut s = state_of(&row)?;
            if row.len() == 3 {
                (s.v, s.omega) = (c[[i, 0]], c[[i, 1]]);
            }
            self.states.push(s);
        }
        let mut out = Array2::zeros((n, 2));
        let mut outcomes = Vec::with_capacity(n);
        let mut closest = Vec::with_capacity(n);
        for i in 0..n {
            self.neighbours.clear();
            for j in (0..n).filter(|&j| j != i) {
                self.neighbours
                    .push(Neighbour::of_state(&self.states[j], self.l, None, true));
            }
            let nominal = VelocityCommand {
                v: c[[i, 0]],
                omega: c[[i, 1]],
            };
            let f = self.filters[i].velocity(
                t,
                &self.states[i],
                self.l,
                nominal,
                &self.base,
                &self.neighbours,
                &self.obstacles,
            );
            out[[i, 0]] = f.command.v;
            out[[i, 1]] = f.command.omega;
            outcomes.push(match f.outcome {
                echelon::safety::Outcome::Nominal => "nominal",
                echelon::safety::Outcome::Filtered => "filtered",
                echelon::safety::Outcome::Braked => "braked",
            });
            closest.push(f.min_distance);
        }
        Ok((out.into_pyarray(py), outcomes, closest))
    }
}

/// Theorem 2 forward (`steps` given: the bound) or inverse (`max_z` given:
/// the largest `N`), for the paper's law or the kinematic law; returns
/// `(z_bound, steps, fix_period_s, e_bound)`.
#[pyfunction]
#[pyo3(signature = (ke, zeta, *, kz=None, omega_max=None, gamma=0.99, steps=None, max_z=None, max_e=None, ts=None, law="paper"))]
#[allow(clippy::too_many_arguments)]
fn bound(
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
) -> PyResult<(f64, u64, Option<f64>, f64)> {
    let given = [steps.is_some(), max_z.is_some(), max_e.is_some()];
    if given.iter().filter(|&&g| g).count() != 1 {
        return Err(errors::value(
            "give exactly one of steps (forward), max_z or max_e (inverse)",
        ));
    }
    let period = |n: u64| ts.map(|t| t * n as f64);
    match law {
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
            Ok((r.z_bound, r.steps, r.fix_period_s, r.z_bound / ke))
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
            Ok((th.z_bound(n), n, period(n), th.e_bound(n)))
        }
        other => Err(errors::value(format!(
            "law: `{other}` (paper, complete or kinematic)"
        ))),
    }
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
    m.add_class::<PySafetyFilters>()?;
    m.add_function(wrap_pyfunction!(robot_preset, m)?)?;
    m.add_function(wrap_pyfunction!(bound, m)?)?;
    m.add_function(wrap_pyfunction!(identify_log, m)?)?;
    Ok(())
}
