//! `echelon._echelon`: the Rust side of the Python package `echelon`
//! (python/echelon). Thin: every number comes from the `echelon` crate; this
//! layer converts arrays and errors. The Python package wraps it in pandas
//! tables, matplotlib figures and Ray tasks.
//!
//! - `scenario`: scenarios, runs into a directory, sweeps;
//! - `simulation`: a scenario stepped under commands from Python;
//! - `pieces`: the law, Theorem 2 and identification as functions on arrays;
//! - `safety`: the safety filters (velocity and torque robots) on arrays;
//! - `batch`: the batch engine on caller-owned buffers;
//! - `envs`: the learning environments (`echelon::learn`) on caller-owned buffers;
//! - `arrays`: array arguments, each checked the same way;
//! - `errors`: Rust errors as Python exceptions.

#![cfg_attr(not(test), warn(clippy::too_many_lines))]

mod arrays;
mod batch;
mod envs;
mod errors;
mod pieces;
mod safety;
mod scenario;
mod simulation;

use pyo3::prelude::*;

/// The extension module.
#[pymodule]
fn _echelon(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("ScenarioError", py.get_type::<errors::ScenarioError>())?;
    m.add("SimulationError", py.get_type::<errors::SimulationError>())?;
    m.add("SWEEP_HEADER", echelon::sweep::SWEEP_HEADER)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    scenario::register(m)?;
    simulation::register(m)?;
    pieces::register(m)?;
    safety::register(m)?;
    batch::register(m)?;
    envs::register(m)?;
    Ok(())
}
