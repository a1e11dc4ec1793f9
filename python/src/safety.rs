//! The barrier-certificate safety filters ([`echelon::safety`],
//! `docs/safety.md`) on arrays, one filter per robot kept between calls
//! (their deadlock monitors remember): velocity bases (`ḣ ≥ −γ h`, on
//! `(v, ω)`) and torque-driven robots (the exponential barrier of relative
//! degree two on eq. 3's `(u1, u2)`, the speed envelope, the wheel torque
//! limit). Every robot filters, so each takes half of each pair constraint.

use numpy::ndarray::{Array2, Ix2};
use numpy::{IntoPyArray, PyArray2, PyReadonlyArray2};
use pyo3::exceptions::{PyMemoryError, PyTypeError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyString};

use echelon::State;
use echelon::base::{AccelLimit, VelocityBase, VelocityCommand, VelocityRobot};
use echelon::error::num;
use echelon::model::{Input, RobotParams};
use echelon::safety::{
    Envelope, INNER_RATE, Neighbour, Obstacle, Outcome, SafetyConfig, SafetyFilter,
};

use crate::arrays::{self, Dim};
use crate::errors;
use crate::simulation::state_of;

/// The filtered commands, each robot's outcome and its closest neighbour.
type Filtered<'py> = (Bound<'py, PyArray2<f64>>, Vec<&'static str>, Vec<f64>);

/// What both kinds share: the robots' filters, the obstacles, `L`, scratch.
#[derive(Debug)]
struct Filters {
    filters: Vec<SafetyFilter>,
    obstacles: Vec<Obstacle>,
    l: f64,
    states: Vec<State>,
    neighbours: Vec<Neighbour>,
    /// The commands (`(v, ω)`, or a torque robot's `(u1, u2)`) each robot's
    /// filter gave at the last call (empty before the first): a 3-column
    /// pose moves at it.
    last: Vec<[f64; 2]>,
}

/// What every filter of a set keeps: points `l` ahead `radius` apart, with
/// the barrier's `gain` γ and the sensing `range` (the Python arguments).
#[derive(Clone, Copy)]
struct Keep {
    radius: f64,
    gain: f64,
    range: f64,
    l: f64,
}

impl Keep {
    const fn new(radius: f64, gain: f64, range: f64, l: f64) -> Keep {
        Keep {
            radius,
            gain,
            range,
            l,
        }
    }
}

impl Filters {
    /// `n` filters keeping `keep`, obstacles as `(m, 3)` rows `x, y, r`,
    /// commands held `period` s (0: continuous).
    fn new(
        n: usize,
        keep: Keep,
        obstacles: Option<&Bound<'_, PyAny>>,
        period: f64,
    ) -> PyResult<Filters> {
        let Keep {
            radius,
            gain,
            range,
            l,
        } = keep;
        let config = SafetyConfig::new(radius, gain, range).map_err(|e| errors::param(&e))?;
        if !(l > 0.0 && l.is_finite()) {
            return Err(errors::value(format!(
                "l: {} must be a finite number > 0",
                num(l)
            )));
        }
        let mut obs = Vec::new();
        if let Some(o) = obstacles {
            let o = arrays::readonly::<Ix2>("obstacles", o, &[&[Dim::Any("m"), Dim::Is(3)]])?;
            let a = o.as_array();
            arrays::finite("obstacles", a.iter())?;
            for row in a.rows() {
                obs.push(Obstacle::new(row[0], row[1], row[2]).map_err(|e| errors::param(&e))?);
            }
        }
        // A count past memory is refused, not an abort of the interpreter.
        let mut filters = Vec::new();
        let mut states = Vec::new();
        let mut neighbours = Vec::new();
        let mut last = Vec::new();
        filters
            .try_reserve_exact(n)
            .and_then(|()| states.try_reserve_exact(n))
            .and_then(|()| neighbours.try_reserve_exact(n))
            .and_then(|()| last.try_reserve_exact(n))
            .map_err(|_| {
                PyMemoryError::new_err(format!(
                    "n: {n} robots' filters do not fit in memory ({} B each)",
                    size_of::<SafetyFilter>() + size_of::<State>() + size_of::<Neighbour>()
                ))
            })?;
        filters.extend((0..n).map(|_| SafetyFilter::new(config).with_period(period)));
        Ok(Filters {
            filters,
            obstacles: obs,
            l,
            states,
            neighbours,
            last,
        })
    }

    /// Checks the array arguments `poses` (named `name`: `(n, 5)`; or
    /// `(n, 3)` too when `at_command`) and `commands` (`(n, 2)`), and reads
    /// the poses into `states`. A 3-column pose (when `at_command`) moves at
    /// the command its filter gave at the last call, what the caller sent
    /// it (at the first call, at the command asked for now): taking the
    /// commands asked for as every robot's motion made each robot's share
    /// of a pair rest on motions the filters then refused, and robots in a
    /// dense swap came up to 96 mm inside the radius (issue trust2, item 4).
    fn read<'py>(
        &mut self,
        name: &str,
        poses: &Bound<'py, PyAny>,
        commands: &Bound<'py, PyAny>,
        at_command: bool,
    ) -> PyResult<PyReadonlyArray2<'py, f64>> {
        let n = self.filters.len();
        let [three, five] = [[Dim::Is(n), Dim::Is(3)], [Dim::Is(n), Dim::Is(5)]];
        let shapes: &[&[Dim]] = if at_command {
            &[&three, &five]
        } else {
            &[&five]
        };
        let poses = arrays::readonly::<Ix2>(name, poses, shapes)?;
        let commands = arrays::readonly::<Ix2>("commands", commands, &[&[Dim::Is(n), Dim::Is(2)]])?;
        let (p, c) = (poses.as_array(), commands.as_array());
        arrays::finite("commands", c.iter())?;
        arrays::finite(name, p.iter())?;
        self.states.clear();
        for (i, row) in p.rows().into_iter().enumerate() {
            let mut s = state_of(row.to_slice().unwrap_or_default())?;
            if at_command && row.len() == 3 {
                [s.v, s.omega] = self.last.get(i).copied().unwrap_or([c[[i, 0]], c[[i, 1]]]);
            }
            self.states.push(s);
        }
        Ok(commands)
    }

    /// The neighbours robot `i` sees: every other robot, cooperative; with
    /// `dv[j] = (v̇, ω̇)` under the command robot j's filter gave last (torque
    /// robots), shared ([`Neighbour::sharing`]).
    fn neighbours_of(&mut self, i: usize, dv: Option<&[[f64; 2]]>) {
        self.neighbours.clear();
        for (j, s) in self.states.iter().enumerate().filter(|&(j, _)| j != i) {
            let dv = dv.map(|d| d[j]);
            self.neighbours
                .push(Neighbour::of_state(s, self.l, dv, true).sharing(dv.is_some()));
        }
    }

    /// Every robot in turn: its neighbours ([`Filters::neighbours_of`]),
    /// then `one(i, its filter, its state, L, neighbours, obstacles)`, which
    /// filters its command; the answers gathered for Python.
    #[allow(clippy::type_complexity)]
    fn each<'py>(
        &mut self,
        py: Python<'py>,
        dv: Option<&[[f64; 2]]>,
        mut one: impl FnMut(
            usize,
            &mut SafetyFilter,
            &State,
            f64,
            &[Neighbour],
            &[Obstacle],
        ) -> ([f64; 2], Outcome, f64),
    ) -> Filtered<'py> {
        let n = self.filters.len();
        let mut out = Array2::zeros((n, 2));
        self.last.clear();
        let mut outcomes = Vec::with_capacity(n);
        let mut closest = Vec::with_capacity(n);
        for i in 0..n {
            self.neighbours_of(i, dv);
            let Filters {
                filters,
                obstacles,
                l,
                states,
                neighbours,
                ..
            } = self;
            let (c, outcome, d) = one(i, &mut filters[i], &states[i], *l, neighbours, obstacles);
            (out[[i, 0]], out[[i, 1]]) = (c[0], c[1]);
            self.last.push(c);
            outcomes.push(outcome_name(outcome));
            closest.push(d);
        }
        (out.into_pyarray(py), outcomes, closest)
    }
}

fn outcome_name(o: Outcome) -> &'static str {
    match o {
        Outcome::Nominal => "nominal",
        Outcome::Filtered => "filtered",
        Outcome::Braked => "braked",
    }
}

/// Safety filters for `n` velocity-controlled robots, one each.
#[pyclass(module = "echelon._echelon", name = "SafetyFilters")]
#[derive(Debug)]
struct PySafetyFilters {
    f: Filters,
    base: VelocityBase,
}

#[pymethods]
impl PySafetyFilters {
    /// `n` robots keeping their points `l` ahead `radius` apart and
    /// `radius` from obstacles' edges (`(m, 3)`: x, y, r); `gain` is the
    /// barrier's γ, `range` the sensing range, `period` the control
    /// period, `base` a velocity base preset (`ideal`, `jackal`, …) or a
    /// dict of its lags and limits ([`velocity_base`]).
    #[new]
    #[pyo3(signature = (n, radius, gain=1.0, range=f64::INFINITY, l=0.1, obstacles=None, period=0.01, base=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        n: usize,
        radius: f64,
        gain: f64,
        range: f64,
        l: f64,
        obstacles: Option<&Bound<'_, PyAny>>,
        period: f64,
        base: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        if !(period > 0.0 && period.is_finite()) {
            return Err(errors::value(format!(
                "period: {} must be a finite number > 0",
                num(period)
            )));
        }
        let base = match base {
            Some(b) => velocity_base(b)?,
            None => VelocityBase::IDEAL,
        };
        let f = Filters::new(n, Keep::new(radius, gain, range, l), obstacles, period)?;
        Ok(PySafetyFilters { f, base })
    }

    /// Filters `commands` (`(n, 2)`: v, ω) of robots in `poses` (`(n, 3)`:
    /// x, y, θ, moving at the commands this filter gave them last, at the
    /// first call at `commands`; or `(n, 5)` with v, ω) at time `t`:
    /// returns the filtered commands `(n, 2)`, each robot's outcome
    /// (`nominal`, `filtered`, `braked`) and the smallest distance from its
    /// point to a neighbour's.
    fn filter<'py>(
        &mut self,
        py: Python<'py>,
        t: f64,
        poses: &Bound<'py, PyAny>,
        commands: &Bound<'py, PyAny>,
    ) -> PyResult<Filtered<'py>> {
        let commands = self.f.read("poses", poses, commands, true)?;
        let (c, base) = (commands.as_array(), &self.base);
        Ok(self
            .f
            .each(py, None, |i, filter, me, l, neighbours, obstacles| {
                let nominal = VelocityCommand {
                    v: c[[i, 0]],
                    omega: c[[i, 1]],
                };
                let r = filter.velocity(t, me, l, nominal, base, neighbours, obstacles);
                ([r.command.v, r.command.omega], r.outcome, r.min_distance)
            }))
    }
}

/// The fields a velocity base's dict takes: those of a scenario's
/// `[robots.NAME]` with `drive = "velocity"` that bound its commands.
const BASE_FIELDS: [&str; 9] = [
    "preset",
    "drive",
    "tau_v",
    "tau_omega",
    "v_max",
    "omega_max",
    "a_max",
    "alpha_max",
    "accel",
];

/// The velocity base preset `name` (`field` names the argument in the error).
fn base_preset(field: &str, name: &str) -> PyResult<VelocityBase> {
    VelocityRobot::preset(name)
        .map(|r| r.base())
        .ok_or_else(|| {
            let names: Vec<&str> = VelocityRobot::PRESETS.iter().map(|(n, _)| *n).collect();
            errors::value(format!(
                "{field}: `{name}` is not a preset ({})",
                names.join(", ")
            ))
        })
}

/// A str `value` of `base.key`.
fn base_text(key: &str, value: &Bound<'_, PyAny>) -> PyResult<String> {
    value
        .cast::<PyString>()
        .map(|s| s.to_string())
        .map_err(|_| {
            PyTypeError::new_err(format!(
                "base.{key} must be a str, got {}",
                type_name(value)
            ))
        })
}

/// The type name of `value`, for a message.
fn type_name(value: &Bound<'_, PyAny>) -> String {
    value
        .get_type()
        .name()
        .map_or_else(|_| "?".to_owned(), |n| n.to_string())
}

/// `base` as a velocity base: a preset's name, or a dict spelled as a
/// scenario's `[robots.NAME]` velocity base: `preset` (default `ideal`)
/// overridden by `tau_v`, `tau_omega` (s), `v_max` (m/s), `omega_max`
/// (rad/s), `a_max` (m/s²), `alpha_max` (rad/s²) (infinite: no limit) and
/// `accel` (`joint`, `per-axis`); `drive` may say `velocity`. A key of
/// another kind, a value of the wrong type or out of its domain is refused
/// naming it (`base.v_max`).
fn velocity_base(base: &Bound<'_, PyAny>) -> PyResult<VelocityBase> {
    if let Ok(name) = base.cast::<PyString>() {
        return base_preset("base", name.to_str()?);
    }
    let Ok(fields) = base.cast::<PyDict>() else {
        return Err(PyTypeError::new_err(format!(
            "base must be a velocity base preset's name or a dict of its lags and limits, got {}",
            type_name(base)
        )));
    };
    let from = match fields.get_item("preset")? {
        Some(p) => base_preset("base.preset", &base_text("preset", &p)?)?,
        None => VelocityBase::IDEAL,
    };
    let mut spec = from.spec();
    for (key, value) in fields.iter() {
        let Ok(key) = key.cast::<PyString>().map(|k| k.to_string()) else {
            return Err(PyTypeError::new_err(format!(
                "base: keys must be str, got {}",
                type_name(&key)
            )));
        };
        let slot = match key.as_str() {
            "preset" => continue,
            "drive" => match base_text("drive", &value)?.as_str() {
                "velocity" => continue,
                other => {
                    return Err(errors::value(format!(
                        "base.drive: `{other}` is not `velocity` (a torque-driven robot's filter is TorqueFilter)"
                    )));
                }
            },
            "accel" => {
                spec.accel = match base_text("accel", &value)?.as_str() {
                    "joint" => AccelLimit::Joint,
                    "per-axis" => AccelLimit::PerAxis,
                    other => {
                        return Err(errors::value(format!(
                            "base.accel: `{other}` is neither `joint` nor `per-axis`"
                        )));
                    }
                };
                continue;
            }
            "tau_v" => &mut spec.tau_v,
            "tau_omega" => &mut spec.tau_omega,
            "v_max" => &mut spec.v_max,
            "omega_max" => &mut spec.omega_max,
            "a_max" => &mut spec.a_max,
            "alpha_max" => &mut spec.alpha_max,
            "reverse_limit" => {
                return Err(errors::value(
                    "base.reverse_limit: not taken: the filter keeps no backup budget \
                     (a Simulation of the scenario does); leave it out",
                ));
            }
            other => {
                return Err(errors::value(format!(
                    "base.{other}: not a velocity base field (fields: {})",
                    BASE_FIELDS.join(", ")
                )));
            }
        };
        if value.is_instance_of::<PyBool>() {
            return Err(PyTypeError::new_err(format!(
                "base.{key} must be a number, got bool"
            )));
        }
        *slot = value.extract::<f64>().map_err(|_| {
            PyTypeError::new_err(format!(
                "base.{key} must be a number, got {}",
                type_name(&value)
            ))
        })?;
    }
    VelocityBase::new(spec).map_err(|e| errors::value(format!("base.{e}")))
}

/// Safety filters for `n` torque-driven robots (eq. 3), one each.
#[pyclass(module = "echelon._echelon", name = "TorqueSafetyFilters")]
#[derive(Debug)]
struct PyTorqueSafetyFilters {
    f: Filters,
    robots: Vec<RobotParams>,
    /// Scratch: each robot's `(v̇, ω̇)` under the command its filter gave at
    /// the last call (zero before the first).
    dv: Vec<[f64; 2]>,
}

#[pymethods]
impl PyTorqueSafetyFilters {
    /// `n` torque-driven robots (`robots_json`: eq. 3's parameters as JSON,
    /// one for all or one per robot) keeping their points `l` ahead
    /// `radius` apart and `radius` from obstacles' edges (`(m, 3)`: x, y, r);
    /// `gain` is the barrier's γ, `range` the sensing range.
    #[new]
    #[pyo3(signature = (n, radius, robots_json, gain=1.0, range=f64::INFINITY, l=0.1, obstacles=None))]
    fn new(
        n: usize,
        radius: f64,
        robots_json: Vec<String>,
        gain: f64,
        range: f64,
        l: f64,
        obstacles: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let f = Filters::new(n, Keep::new(radius, gain, range, l), obstacles, 0.0)?;
        if !(robots_json.len() == 1 || robots_json.len() == n) {
            return Err(errors::value(format!(
                "robot: {} robots given for {n} (one for all, or one each)",
                robots_json.len()
            )));
        }
        let parsed = robots_json
            .iter()
            .map(|j| serde_json::from_str::<RobotParams>(j))
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| errors::value(format!("robot: {e}")))?;
        let robots = (0..n).map(|i| parsed[i.min(parsed.len() - 1)]).collect();
        Ok(PyTorqueSafetyFilters {
            f,
            robots,
            dv: vec![[0.0; 2]; n],
        })
    }

    /// Filters `commands` (`(n, 2)`: u1, u2 of eq. 3) of robots in `states`
    /// (`(n, 5)`: x, y, θ, v, ω) at time `t`; returns what
    /// `SafetyFilters.filter` does, torques for commands.
    fn filter<'py>(
        &mut self,
        py: Python<'py>,
        t: f64,
        states: &Bound<'py, PyAny>,
        commands: &Bound<'py, PyAny>,
    ) -> PyResult<Filtered<'py>> {
        let commands = self.f.read("states", states, commands, false)?;
        let c = commands.as_array();
        // What each robot's neighbours take as its acceleration: the one
        // under the command its filter gave last, what it carries out now
        // (they take over what it fell short of, `Neighbour::sharing`).
        for (((dv, robot), s), f) in self
            .dv
            .iter_mut()
            .zip(&self.robots)
            .zip(&self.f.states)
            .zip(&self.f.filters)
        {
            *dv = f.last_acceleration(s, robot);
        }
        let robots = &self.robots;
        Ok(self.f.each(
            py,
            Some(&self.dv),
            |i, filter, me, l, neighbours, obstacles| {
                let nominal = Input {
                    u1: c[[i, 0]],
                    u2: c[[i, 1]],
                };
                let r = filter.torque(t, me, l, &robots[i], nominal, neighbours, obstacles);
                ([r.command.u1, r.command.u2], r.outcome, r.min_distance)
            },
        ))
    }
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PySafetyFilters>()?;
    m.add_class::<PyTorqueSafetyFilters>()?;
    // The torque filter's fixed settings (echelon::safety::{INNER_RATE, Envelope}).
    m.add("TORQUE_INNER_RATE", INNER_RATE)?;
    let e = Envelope::DEFAULT;
    m.add(
        "TORQUE_ENVELOPE",
        (e.v_max, e.v_reverse, e.omega_max, e.rate),
    )?;
    Ok(())
}
