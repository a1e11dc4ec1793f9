//! The batch engine from Python: `echelon bench`'s formation (or a
//! scenario's), stepped in Rust with the GIL released, on a `(5, n)` numpy
//! array the caller owns (stepped in place: `step`), or with its states
//! written into one (`run(steps, out)`).

use numpy::{
    PyArray1, PyArray2, PyArrayDescrMethods, PyArrayMethods, PyReadwriteArray2, PyUntypedArray,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;

use echelon::engine::{BenchFormation, Engine, Topology, VelocityEngine};

use crate::errors;
use crate::scenario::{OverrideArgs, PyScenario};

/// The engine of one drive.
#[derive(Debug, Clone)]
enum Kind {
    Torque(Engine),
    Velocity(VelocityEngine),
}

/// N agents stepped by the batch engine (SIMD lanes, all cores).
#[pyclass(module = "echelon._echelon", name = "BatchEngine")]
#[derive(Debug)]
struct PyBatchEngine {
    engine: Kind,
}

#[pymethods]
impl PyBatchEngine {
    /// `echelon bench`'s formation: `agents` robots at random poses (from
    /// `seed`), following a circle (`star`) or each the one before
    /// (`chain`); `torque` (the paper's robots and law) or `velocity`
    /// (Jackal bases, the kinematic law); RK4 step `dt`.
    #[staticmethod]
    #[pyo3(signature = (agents, topology="star", drive="torque", dt=0.001, seed=1))]
    fn bench(agents: usize, topology: &str, drive: &str, dt: f64, seed: u64) -> PyResult<Self> {
        if agents == 0 {
            return Err(errors::value("agents: must be ≥ 1"));
        }
        if !(dt.is_finite() && dt > 0.0) {
            return Err(errors::value(format!(
                "dt: {dt} must be a finite number > 0"
            )));
        }
        // Past it the allocation fails, which aborts the interpreter.
        if agents > BenchFormation::MAX_AGENTS {
            return Err(errors::value(format!(
                "agents: {agents} is more than {} (≈ {} GB of state)",
                BenchFormation::MAX_AGENTS,
                BenchFormation::MAX_AGENTS * Engine::BLOCK_BYTES_PER_AGENT / 1_000_000_000
            )));
        }
        let topology = match topology {
            "star" => Topology::Star,
            "chain" => Topology::Chain,
            other => {
                return Err(errors::value(format!(
                    "topology: `{other}` (star or chain)"
                )));
            }
        };
        let f = BenchFormation {
            agents,
            topology,
            seed,
        };
        let engine = match drive {
            "torque" => Kind::Torque(f.engine(dt).map_err(errors::value)?),
            "velocity" => {
                BenchFormation::BASE.check_step(dt).map_err(|e| {
                    errors::value(format!(
                        "dt: {dt} s is longer than the velocity base's lag ({} = {} s, a \
                             Clearpath Jackal's): a lag cannot be integrated with a step longer \
                             than itself; use dt ≤ {}",
                        e.field, e.value, e.value
                    ))
                })?;
                Kind::Velocity(
                    f.velocity_engine(BenchFormation::BASE, dt)
                        .map_err(errors::value)?,
                )
            }
            other => {
                return Err(errors::value(format!(
                    "drive: `{other}` (torque or velocity)"
                )));
            }
        };
        Ok(PyBatchEngine { engine })
    }

    /// The engine for a scenario's agents (same robot and law, a star or a
    /// chain, continuous control, no odometry or safety filter).
    #[staticmethod]
    #[pyo3(signature = (scenario, overrides=None))]
    fn from_scenario(
        py: Python<'_>,
        scenario: &PyScenario,
        overrides: Option<OverrideArgs>,
    ) -> PyResult<Self> {
        let run = scenario.build(py, overrides.as_ref())?;
        let engine = Engine::from_plan(&run.plan).map_err(errors::value)?;
        Ok(PyBatchEngine {
            engine: Kind::Torque(engine),
        })
    }

    /// Number of agents.
    #[getter]
    fn n(&self) -> usize {
        match &self.engine {
            Kind::Torque(e) => e.len(),
            Kind::Velocity(e) => e.len(),
        }
    }

    /// Current time, s.
    #[getter]
    fn time(&self) -> f64 {
        match &self.engine {
            Kind::Torque(e) => e.time(),
            Kind::Velocity(e) => e.time(),
        }
    }

    /// Steps `steps` RK4 steps with the GIL released; then, if `out` is
    /// given (`(n, 5)` float64, C-contiguous, owned by the caller), writes
    /// the states into it: x, y, θ, v, ω.
    #[pyo3(signature = (steps, out=None))]
    fn run(
        &mut self,
        py: Python<'_>,
        steps: u64,
        out: Option<PyReadwriteArray2<'_, f64>>,
    ) -> PyResult<()> {
        let engine = &mut self.engine;
        let result = py.detach(|| match engine {
            Kind::Torque(e) => e.run(steps),
            Kind::Velocity(e) => e.run(steps),
        });
        result.map_err(|e| errors::sim(&e))?;
        if let Some(out) = out {
            self.states_into(py, out)?;
        }
        Ok(())
    }

    /// A new `(5, n)` float64 array, yours, holding the current states as
    /// columns (rows x, y, θ, v, ω): the buffer `step` steps in place.
    fn state<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let cols = match &self.engine {
            Kind::Torque(e) => e.columns(),
            Kind::Velocity(e) => e.columns(),
        };
        PyArray1::from_vec(py, cols).reshape([5, self.n()])
    }

    /// Steps the states in `state` (a `(5, n)` float64 C-contiguous writeable
    /// array you own, rows x, y, θ, v, ω, as `state()` makes it) `steps` RK4
    /// steps in place: the engine reads and writes your memory, no copy, the
    /// GIL released. A wrong array (type, dtype, shape, layout, read-only, a
    /// value that is not finite) raises `ValueError` and changes nothing.
    #[pyo3(signature = (state, steps=1))]
    fn step(&mut self, py: Python<'_>, state: &Bound<'_, PyAny>, steps: u64) -> PyResult<()> {
        let n = self.n();
        let untyped = state.cast::<PyUntypedArray>().map_err(|_| {
            errors::value(format!(
                "state: a numpy array of shape (5, {n}) and dtype float64, not {}",
                state.get_type()
            ))
        })?;
        if !untyped.dtype().is_equiv_to(&numpy::dtype::<f64>(py)) {
            return Err(errors::value(format!(
                "state: dtype {}, expected float64",
                untyped.dtype()
            )));
        }
        if untyped.shape() != [5, n] {
            return Err(errors::value(format!(
                "state: shape {:?}, expected (5, {n}) (rows x, y, θ, v, ω)",
                untyped.shape()
            )));
        }
        if !untyped.is_c_contiguous() {
            return Err(errors::value(
                "state: must be C-contiguous (np.ascontiguousarray makes a copy the engine can step)",
            ));
        }
        let array = state
            .cast::<PyArray2<f64>>()
            .map_err(|e| errors::value(format!("state: {e}")))?;
        let mut rw = array
            .try_readwrite()
            .map_err(|e| errors::value(format!("state: not writeable ({e})")))?;
        let buf = rw
            .as_slice_mut()
            .map_err(|_| errors::value("state: must be C-contiguous"))?;
        let engine = &mut self.engine;
        let result = py.detach(|| match engine {
            Kind::Torque(e) => e.run_on(buf, steps),
            Kind::Velocity(e) => e.run_on(buf, steps),
        });
        result.map_err(|e| match e {
            echelon::engine::EngineError::Sim(e) => errors::sim(&e),
            other => errors::value(other),
        })
    }

    /// Writes the states into `out` (`(n, 5)` float64, C-contiguous).
    fn states(&self, py: Python<'_>, out: PyReadwriteArray2<'_, f64>) -> PyResult<()> {
        self.states_into(py, out)
    }
}

impl PyBatchEngine {
    fn states_into(&self, py: Python<'_>, mut out: PyReadwriteArray2<'_, f64>) -> PyResult<()> {
        let n = self.n();
        if out.as_array().shape() != [n, 5] {
            return Err(errors::value(format!(
                "out: shape {:?}, expected ({n}, 5)",
                out.as_array().shape()
            )));
        }
        let buf = out
            .as_slice_mut()
            .map_err(|_| errors::value("out: must be C-contiguous"))?;
        let engine = &self.engine;
        py.detach(|| {
            for (i, row) in buf.chunks_exact_mut(5).enumerate() {
                let s = match engine {
                    Kind::Torque(e) => e.state(i),
                    Kind::Velocity(e) => e.state(i),
                };
                row.copy_from_slice(&[s.x, s.y, s.theta, s.v, s.omega]);
            }
        });
        Ok(())
    }
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyBatchEngine>()
}
