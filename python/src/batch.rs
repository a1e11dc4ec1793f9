//! The batch engine from Python: `echelon bench`'s formation (or a
//! scenario's), stepped in Rust with the GIL released, on a `(5, n)` numpy
//! array the caller owns (stepped in place: `step`), or with its states
//! written into one (`run(steps, out)`).

use numpy::ndarray::Ix2;
use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadwriteArray2};
use pyo3::prelude::*;

use echelon::engine::{BenchFormation, Engine, Topology, VelocityEngine};
use echelon::error::num;

use crate::arrays::{self, Dim};
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
                "dt: {} must be a finite number > 0",
                num(dt)
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
                        "dt: {} s is longer than the velocity base's lag ({} = {} s, a \
                             Clearpath Jackal's): a lag cannot be integrated with a step longer \
                             than itself; use dt ≤ {}",
                        num(dt),
                        e.field,
                        num(e.value),
                        num(e.value)
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

    /// Steps `steps` RK4 steps with the GIL released (in chunks, Python's
    /// signal handlers run between them: Ctrl-C raises `KeyboardInterrupt`
    /// with the engine as of the last finished chunk); then, if `out` is
    /// given (`(n, 5)` float64, C-contiguous, writeable, owned by the
    /// caller), writes the states into it: x, y, θ, v, ω. A wrong `out` is
    /// refused before any step.
    #[pyo3(signature = (steps, out=None))]
    fn run(&mut self, py: Python<'_>, steps: u64, out: Option<&Bound<'_, PyAny>>) -> PyResult<()> {
        let out = out.map(|o| self.out(o)).transpose()?;
        let chunk = self.chunk();
        let engine = &mut self.engine;
        in_chunks(py, steps, chunk, |k| {
            py.detach(|| match engine {
                Kind::Torque(e) => e.run(k),
                Kind::Velocity(e) => e.run(k),
            })
            .map_err(|e| errors::sim(&e))
        })?;
        if let Some(out) = out {
            self.states_into(py, out);
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
    /// The steps run in chunks, Python's signal handlers between them: Ctrl-C
    /// raises `KeyboardInterrupt` with `state` (and the engine's time) as of
    /// the last finished chunk, the same bits as a call of that many steps.
    #[pyo3(signature = (state, steps=1))]
    fn step(&mut self, py: Python<'_>, state: &Bound<'_, PyAny>, steps: u64) -> PyResult<()> {
        let n = self.n();
        let mut state = arrays::readwrite::<Ix2>("state", state, &[&[Dim::Is(5), Dim::Is(n)]])?;
        let chunk = self.chunk();
        let engine = &mut self.engine;
        in_chunks(py, steps, chunk, |k| {
            // Borrowed for one chunk: the signal handlers between chunks
            // may touch the array.
            let buf = state
                .as_slice_mut()
                .map_err(|e| errors::value(format!("state: {e}")))?;
            py.detach(|| match engine {
                Kind::Torque(e) => e.run_on(buf, k),
                Kind::Velocity(e) => e.run_on(buf, k),
            })
            .map_err(|e| match e {
                echelon::engine::EngineError::Sim(e) => errors::sim(&e),
                other => errors::value(format!("state: {other}")),
            })
        })
    }

    /// Writes the states into `out` (`(n, 5)` float64, C-contiguous, writeable).
    fn states(&self, py: Python<'_>, out: &Bound<'_, PyAny>) -> PyResult<()> {
        let out = self.out(out)?;
        self.states_into(py, out);
        Ok(())
    }
}

impl PyBatchEngine {
    /// Steps per chunk of [`in_chunks`] for this engine's `n` agents (a
    /// step costs about as much for 1 agent as for a block of 8 lanes).
    fn chunk(&self) -> u64 {
        (CHUNK_AGENT_STEPS / self.n().max(8) as u64).max(1)
    }

    /// The buffer `out` (`(n, 5)`), checked.
    fn out<'py>(&self, out: &Bound<'py, PyAny>) -> PyResult<PyReadwriteArray2<'py, f64>> {
        arrays::readwrite::<Ix2>("out", out, &[&[Dim::Is(self.n()), Dim::Is(5)]])
    }

    /// Writes the states into `out`, checked by [`PyBatchEngine::out`].
    fn states_into(&self, py: Python<'_>, mut out: PyReadwriteArray2<'_, f64>) {
        let mut rows = out.as_array_mut();
        let engine = &self.engine;
        py.detach(|| {
            for (i, mut row) in rows.rows_mut().into_iter().enumerate() {
                let s = match engine {
                    Kind::Torque(e) => e.state(i),
                    Kind::Velocity(e) => e.state(i),
                };
                for (dst, v) in row.iter_mut().zip([s.x, s.y, s.theta, s.v, s.omega]) {
                    *dst = v;
                }
            }
        });
    }
}

/// Agent-steps between two looks at Python's signals: some milliseconds of
/// the engine's work at any `n` (about 40 ms in the unoptimised test build),
/// so Ctrl-C is prompt while a chunk's tens of microseconds of overhead
/// (the GIL taken back, the rayon tasks started) stay near 1 %.
const CHUNK_AGENT_STEPS: u64 = 1 << 18;

/// `steps` steps as calls `run(k)` of at most `chunk` steps each (each
/// releases the GIL while it steps); between two calls Python's signal
/// handlers run, and a `KeyboardInterrupt` they raise is returned with the
/// finished calls' steps kept. The first call that fails is the last. Zero
/// steps is one call of zero (it still checks its input).
fn in_chunks(
    py: Python<'_>,
    steps: u64,
    chunk: u64,
    mut run: impl FnMut(u64) -> PyResult<()>,
) -> PyResult<()> {
    let mut left = steps;
    loop {
        let k = left.min(chunk);
        run(k)?;
        left -= k;
        if left == 0 {
            return Ok(());
        }
        py.check_signals()?;
    }
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyBatchEngine>()
}
