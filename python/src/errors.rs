//! Rust errors as Python exceptions: a scenario error keeps its file, line,
//! column and field as attributes; a refused value is a `ValueError` naming
//! the field; a run that failed is a `SimulationError`.

use pyo3::create_exception;
use pyo3::exceptions::{PyOSError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;

create_exception!(
    _echelon,
    ScenarioError,
    PyValueError,
    "A scenario that cannot be loaded or built. Attributes: file, line, column \
     (1-based; 0 when unknown), field (dotted path, e.g. `agents[2].gains.ke`; \
     empty for the whole file), message, and path (None; for a dict document \
     given to `Scenario.from_dict`, the keys and 0-based indices into it, \
     `field` then being that path, e.g. `agents[1].gains.ke`, and line, column 0). \
     str() is `file:line:column: field: message`."
);
create_exception!(
    _echelon,
    SimulationError,
    PyRuntimeError,
    "A run that failed: it diverged (a state left its bounds) or an output could not be written."
);

/// The error as a Python caller set the value: one the core places on the
/// command line (`command line: --zeta: …`, a flag of `echelon sweep`) was
/// set by a keyword argument or a grid key here, which Python spells
/// `zeta`, `fix_every`, `log_dt`: `arguments: zeta: …`.
fn as_python(e: &echelon::ScenarioError) -> echelon::ScenarioError {
    let mut e = e.clone();
    if e.location.file == echelon::error::Location::COMMAND_LINE {
        e.location.file = "arguments".into();
        if let Some(key) = keyword(&e.field) {
            e.field = key;
        }
    }
    e
}

/// The Python keyword of a command-line flag: `--fix-every` → `fix_every`
/// (`None` for a name that is not a flag).
pub(crate) fn keyword(flag: &str) -> Option<String> {
    flag.strip_prefix("--").map(|f| f.replace('-', "_"))
}

/// A scenario error as a [`ScenarioError`] carrying its location.
pub(crate) fn scenario(py: Python<'_>, e: &echelon::ScenarioError) -> PyErr {
    let e = &as_python(e);
    let err = ScenarioError::new_err(e.to_string());
    let value = err.value(py);
    let attrs = [
        (
            "file",
            e.location
                .file
                .clone()
                .into_pyobject(py)
                .map(|o| o.into_any()),
        ),
        (
            "line",
            e.location.line.into_pyobject(py).map(|o| o.into_any()),
        ),
        (
            "column",
            e.location.column.into_pyobject(py).map(|o| o.into_any()),
        ),
        (
            "field",
            e.field.clone().into_pyobject(py).map(|o| o.into_any()),
        ),
        (
            "message",
            e.message.clone().into_pyobject(py).map(|o| o.into_any()),
        ),
    ];
    if let Err(e) = value.setattr("path", py.None()) {
        return e;
    }
    for (name, v) in attrs {
        match v {
            Ok(v) => {
                if let Err(e) = value.setattr(name, v) {
                    return e;
                }
            }
            Err(e) => return e.into(),
        }
    }
    err
}

/// A refused parameter (names its field) as a `ValueError`.
pub(crate) fn param(e: &echelon::ParamError) -> PyErr {
    PyValueError::new_err(e.to_string())
}

/// A grid value refused, as a `ValueError` naming the grid key that set it
/// (`eb = -1: …`: the keyword of its `echelon sweep` flag).
pub(crate) fn grid_param(e: &echelon::ParamError) -> PyErr {
    match echelon::sweep::GridSpec::flag(e.field).and_then(keyword) {
        Some(key) if e.reason == echelon::sweep::EMPTY_LIST => {
            PyValueError::new_err(format!("{key}: {}", echelon::sweep::GridSpec::refusal(e)))
        }
        Some(key) => PyValueError::new_err(format!("{key} = {}: {}", e.value, e.reason)),
        None => param(e),
    }
}

/// A failed simulation as a [`SimulationError`].
pub(crate) fn sim(e: &echelon::SimError) -> PyErr {
    SimulationError::new_err(e.to_string())
}

/// An output error: I/O as `OSError`, the rest as [`SimulationError`].
pub(crate) fn output(e: &echelon::OutputError) -> PyErr {
    match e {
        echelon::OutputError::Io { .. } => PyOSError::new_err(e.to_string()),
        _ => SimulationError::new_err(e.to_string()),
    }
}

/// Any other error, by its message, as a `ValueError`.
pub(crate) fn value(e: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(e.to_string())
}
