//! A scenario's simulation stepped under commands from Python
//! ([`echelon::Simulation::step_with`]): the caller's controller in place of
//! the law, echelon's robots, limits and odometry.

use numpy::ndarray::Array2;
use numpy::ndarray::Ix2;
use numpy::{IntoPyArray, PyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use echelon::agent::{Command, Drive};
use echelon::base::VelocityCommand;
use echelon::control::{LeaderMotion, Offset};
use echelon::formation::Leader;
use echelon::model::{Input, State};
use echelon::safety::Outcome;
use echelon::sim::StepByError;
use echelon::{SimError, Simulation};

use crate::arrays::{self, Dim};
use crate::errors;
use crate::scenario::{OverrideArgs, PyScenario};

/// A running simulation of a scenario.
#[pyclass(module = "echelon._echelon", name = "Simulation")]
#[derive(Debug)]
pub(crate) struct PySimulation {
    sim: Simulation,
    /// Scratch: the commands of one step.
    commands: Vec<Command>,
    /// Whether the safety filter ran at the last step.
    filtered: bool,
}

/// `[x, y, θ, v, ω]` rows.
pub(crate) fn state_rows(states: impl ExactSizeIterator<Item = State>) -> Array2<f64> {
    let n = states.len();
    let mut out = Array2::zeros((n, 5));
    for (i, s) in states.enumerate() {
        for (k, v) in [s.x, s.y, s.theta, s.v, s.omega].into_iter().enumerate() {
            out[[i, k]] = v;
        }
    }
    out
}

/// A state from `[x, y, θ]` or `[x, y, θ, v, ω]`.
pub(crate) fn state_of(row: &[f64]) -> PyResult<State> {
    match *row {
        [x, y, theta] => Ok(State::at_rest(x, y, theta)),
        [x, y, theta, v, omega] => Ok(State {
            x,
            y,
            theta,
            v,
            omega,
        }),
        _ => Err(errors::value(format!(
            "a state is [x, y, θ] or [x, y, θ, v, ω], not {} numbers",
            row.len()
        ))),
    }
}

/// One command per agent in its drive's terms, from an `(n, 2)` array.
fn commands_into(
    sim: &Simulation,
    commands: &Bound<'_, PyAny>,
    out: &mut Vec<Command>,
) -> PyResult<()> {
    let n = sim.agents().len();
    let commands = arrays::readonly::<Ix2>("commands", commands, &[&[Dim::Is(n), Dim::Is(2)]])?;
    let a = commands.as_array();
    out.clear();
    for (i, agent) in sim.agents().iter().enumerate() {
        let (c0, c1) = (a[[i, 0]], a[[i, 1]]);
        if !(c0.is_finite() && c1.is_finite()) {
            return Err(errors::value(format!(
                "commands[{i}]: ({c0}, {c1}) is not finite"
            )));
        }
        out.push(match agent.drive() {
            Drive::Torque { .. } => Command::Torque(Input { u1: c0, u2: c1 }),
            Drive::Velocity(_) => Command::Velocity(VelocityCommand { v: c0, omega: c1 }),
        });
    }
    Ok(())
}

#[pymethods]
impl PySimulation {
    /// The simulation of `scenario` (under `echelon run`'s overrides) at `t = 0`.
    #[new]
    #[pyo3(signature = (scenario, overrides=None))]
    fn new(
        py: Python<'_>,
        scenario: &PyScenario,
        overrides: Option<OverrideArgs>,
    ) -> PyResult<Self> {
        let run = scenario.build(py, overrides.as_ref())?;
        let sim = run.simulation();
        let n = sim.agents().len();
        Ok(PySimulation {
            sim,
            commands: Vec::with_capacity(n),
            filtered: false,
        })
    }

    /// Number of agents.
    #[getter]
    fn n(&self) -> usize {
        self.sim.agents().len()
    }

    /// Current time, s.
    #[getter]
    fn time(&self) -> f64 {
        self.sim.time()
    }

    /// Steps taken.
    #[getter]
    fn step_index(&self) -> u64 {
        self.sim.step_index()
    }

    /// Steps of the whole run (its duration over dt).
    #[getter]
    fn steps(&self) -> u64 {
        self.sim.steps()
    }

    /// RK4 step, s.
    #[getter]
    fn dt(&self) -> f64 {
        self.sim.config().dt
    }

    /// Whether the run has reached its duration.
    #[getter]
    fn done(&self) -> bool {
        self.sim.is_done()
    }

    /// Evaluation order: every leader before its followers (0-based).
    #[getter]
    fn order(&self) -> Vec<usize> {
        self.sim.formation().order().to_vec()
    }

    /// The true states, `(n, 5)`: x, y, θ, v, ω.
    #[getter]
    fn poses<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        state_rows(self.sim.states().iter().copied()).into_pyarray(py)
    }

    /// What each controller senses of itself, `(n, 5)`: the odometry
    /// estimate of an agent that dead-reckons, else its true state.
    #[getter]
    fn sensed<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let n = self.sim.agents().len();
        state_rows((0..n).map(|i| self.sim.sensed(i))).into_pyarray(py)
    }

    /// Each agent as a dict: name, drive (`torque` or `velocity`), leader
    /// (an agent's 0-based index, or None for the reference), ke, kz, l,
    /// law (`paper`, `complete` or `kinematic`), robot (eq. 3's parameters,
    /// torque-driven agents) and max_accel.
    #[getter]
    fn agents<'py>(&self, py: Python<'py>) -> PyResult<Vec<Bound<'py, PyDict>>> {
        let mut out = Vec::new();
        for a in self.sim.agents() {
            let d = PyDict::new(py);
            d.set_item("name", a.name())?;
            d.set_item(
                "drive",
                match a.drive() {
                    Drive::Torque { .. } => "torque",
                    Drive::Velocity(_) => "velocity",
                },
            )?;
            d.set_item(
                "leader",
                match a.leader() {
                    Leader::Reference => None,
                    Leader::Agent(j) => Some(j),
                },
            )?;
            d.set_item("ke", a.gains().ke())?;
            d.set_item("kz", a.gains().kz())?;
            d.set_item("l", a.placement().l())?;
            d.set_item("law", a.law().name())?;
            d.set_item("max_accel", a.max_accel())?;
            let robot = match a.torque_robot() {
                Some(r) => Some(serde_json::to_string(r).map_err(errors::value)?),
                None => None,
            };
            d.set_item("robot_json", robot)?;
            out.push(d);
        }
        Ok(out)
    }

    /// What agent `i`'s law is given now, as in `echelon run`: a dict of the
    /// leader motion `p`, `dp`, `ddp` (`p_d, ṗ_d, p̈_d`) and the offsets `lx`,
    /// `ly`, `dly`, `ddly` (eqs. 4–6). A robot leader is seen accelerating
    /// under its row of `commands` (`(n, 2)`; compute leaders first, in
    /// `order`).
    fn leader<'py>(
        &mut self,
        py: Python<'py>,
        i: usize,
        commands: &Bound<'_, PyAny>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let n = self.sim.agents().len();
        if i >= n {
            return Err(errors::value(format!("agent {i}: there are {n} (0-based)")));
        }
        let mut scratch = std::mem::take(&mut self.commands);
        let result = commands_into(&self.sim, commands, &mut scratch);
        let view = result.map(|()| self.sim.leader_view(i, &scratch));
        self.commands = scratch;
        let (motion, offset) = view?;
        leader_dict(py, &motion, &offset)
    }

    /// One RK4 step under `commands`, `(n, 2)`: `(u1, u2)` (eq. 3c–d) for a
    /// torque-driven agent, `(v*, ω*)` for a velocity base; through the
    /// agent's acceleration limit, the scenario's safety filter (when it has
    /// `[safety]` and `filter`), its torque limit or base limits, the plant
    /// and its odometry, as `echelon run` applies its law's.
    fn step(&mut self, py: Python<'_>, commands: &Bound<'_, PyAny>, filter: bool) -> PyResult<()> {
        let mut scratch = std::mem::take(&mut self.commands);
        let result = commands_into(&self.sim, commands, &mut scratch);
        let sim = &mut self.sim;
        let stepped = result.and_then(|()| {
            let r = py.detach(|| sim.step_with(&scratch, filter));
            r.map_err(|e| errors::sim(&e))
        });
        self.commands = scratch;
        self.filtered = stepped?;
        Ok(())
    }

    /// One RK4 step of a continuous-time controller: `law(i, t, state,
    /// leader)` is called for every agent (leaders first) in each of RK4's
    /// four stages (and at the new state, for velocity bases), where
    /// `echelon run` evaluates its own law; `state` is what the agent senses
    /// (`[x, y, θ, v, ω]`), `leader` the dict of [`PySimulation::leader`] at
    /// the stage; it returns the agent's `(u1, u2)` or `(v*, ω*)`. An
    /// exception raised by `law` stops the step (nothing moves) and is
    /// raised here.
    fn step_by(&mut self, py: Python<'_>, law: Bound<'_, PyAny>) -> PyResult<()> {
        let drives: Vec<bool> = self
            .sim
            .agents()
            .iter()
            .map(|a| matches!(a.drive(), Drive::Torque { .. }))
            .collect();
        let call =
            |i: usize, t: f64, me: &State, m: &LeaderMotion, o: &Offset| -> PyResult<Command> {
                let state = vec![me.x, me.y, me.theta, me.v, me.omega].into_pyarray(py);
                let leader = leader_dict(py, m, o)?;
                let got: Vec<f64> = law.call1((i, t, state, leader))?.extract()?;
                let [c0, c1] = got[..] else {
                    return Err(errors::value(format!(
                        "law: agent {i}'s command has {} numbers, expected 2",
                        got.len()
                    )));
                };
                if !(c0.is_finite() && c1.is_finite()) {
                    return Err(errors::value(format!(
                        "law: agent {i}'s command ({c0}, {c1}) is not finite"
                    )));
                }
                Ok(if drives[i] {
                    Command::Torque(Input { u1: c0, u2: c1 })
                } else {
                    Command::Velocity(VelocityCommand { v: c0, omega: c1 })
                })
            };
        match self.sim.step_by(call) {
            Ok(()) => Ok(()),
            Err(StepByError::Law(e)) => Err(e),
            Err(StepByError::Sim(SimError::Timing(m))) => Err(errors::value(m)),
            Err(StepByError::Sim(e)) => Err(errors::sim(&e)),
        }
    }

    /// Whether the scenario has a safety filter (`[safety]`).
    #[getter]
    fn has_safety(&self) -> bool {
        self.sim.has_safety()
    }

    /// What the safety filter did at the last step, or None when it did not
    /// run (no `[safety]`, turned off, or no step yet): per agent whether it
    /// ran, its outcome (`nominal`, `filtered`, `braked`; `off` for an agent
    /// without a filter), whether it broke a deadlock, the command given
    /// (after the acceleration limit) and the command sent, `(n, 2)` each,
    /// and the distance to the nearest neighbour's point in range, m.
    #[allow(clippy::type_complexity)]
    fn safety_step<'py>(
        &self,
        py: Python<'py>,
    ) -> Option<(
        Vec<bool>,
        Vec<&'static str>,
        Vec<bool>,
        Bound<'py, PyArray2<f64>>,
        Bound<'py, PyArray2<f64>>,
        Vec<f64>,
    )> {
        if !self.filtered {
            return None;
        }
        let out = self.sim.safety_outputs();
        let n = out.len();
        let (mut nominal, mut filtered) = (Array2::zeros((n, 2)), Array2::zeros((n, 2)));
        for (i, o) in out.iter().enumerate() {
            for k in 0..2 {
                nominal[[i, k]] = o.nominal[k];
                filtered[[i, k]] = o.filtered[k];
            }
        }
        let outcome = out
            .iter()
            .map(|o| match (o.enabled, o.outcome) {
                (false, _) => "off",
                (true, Outcome::Nominal) => "nominal",
                (true, Outcome::Filtered) => "filtered",
                (true, Outcome::Braked) => "braked",
            })
            .collect();
        Some((
            out.iter().map(|o| o.enabled).collect(),
            outcome,
            out.iter().map(|o| o.deadlock).collect(),
            nominal.into_pyarray(py),
            filtered.into_pyarray(py),
            out.iter().map(|o| o.min_distance).collect(),
        ))
    }

    /// The true tracking errors now: `e` (eq. 7) and `z` (eq. 10), `(n, 2)` each.
    fn errors<'py>(
        &mut self,
        py: Python<'py>,
    ) -> (Bound<'py, PyArray2<f64>>, Bound<'py, PyArray2<f64>>) {
        let frame = self.sim.frame();
        let n = frame.outputs.len();
        let mut e = Array2::zeros((n, 2));
        let mut z = Array2::zeros((n, 2));
        for (i, o) in frame.outputs.iter().enumerate() {
            for k in 0..2 {
                e[[i, k]] = o.e[k];
                z[[i, k]] = o.z[k];
            }
        }
        (e.into_pyarray(py), z.into_pyarray(py))
    }
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PySimulation>()
}

/// What an agent's law is given of its leader ([`PySimulation::leader`]):
/// the leader motion `p, ṗ, p̈` and the offset `L_X, L_Y, L̇_Y, L̈_Y`.
fn leader_dict<'py>(py: Python<'py>, m: &LeaderMotion, o: &Offset) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("p", m.p)?;
    d.set_item("dp", m.dp)?;
    d.set_item("ddp", m.ddp)?;
    d.set_item("lx", o.lx)?;
    d.set_item("ly", o.ly)?;
    d.set_item("dly", o.dly)?;
    d.set_item("ddly", o.ddly)?;
    Ok(d)
}
