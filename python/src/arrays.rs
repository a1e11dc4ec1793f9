//! Array arguments, every one checked by the same helper before anything is
//! read or written: a numpy float64 array of one of the shapes it may have,
//! C-contiguous, and writeable when the call writes into it. A wrong one is
//! a `ValueError` that names the argument, says what it must be and what it
//! got (`out must be a float64 array of shape (3, 5), C-contiguous and
//! writeable, got float32 array of shape (3, 5)`), and changes nothing.

use numpy::ndarray::Dimension;
use numpy::{
    PyArray, PyArrayDescrMethods, PyArrayMethods, PyReadonlyArray, PyReadwriteArray,
    PyUntypedArray, PyUntypedArrayMethods,
};
use pyo3::prelude::*;

use crate::errors;

/// One extent of an expected shape: a number, or any (named in messages:
/// `m` in `(m, 3)`).
#[derive(Debug, Clone, Copy)]
pub(crate) enum Dim {
    Is(usize),
    Any(&'static str),
}

/// `(4, 2)`, `(5,)`, `(m, 3)`: a shape as Python writes it.
fn shape_text<T>(dims: &[T], one: impl Fn(&T) -> String) -> String {
    match dims {
        [d] => format!("({},)", one(d)),
        _ => format!("({})", dims.iter().map(one).collect::<Vec<_>>().join(", ")),
    }
}

fn dim_text(d: &Dim) -> String {
    match d {
        Dim::Is(k) => k.to_string(),
        Dim::Any(name) => (*name).to_owned(),
    }
}

fn fits(want: &[Dim], got: &[usize]) -> bool {
    want.len() == got.len()
        && want.iter().zip(got).all(|(w, &g)| match *w {
            Dim::Is(k) => k == g,
            Dim::Any(_) => true,
        })
}

/// The array argument `name` (`obj`) as a float64 array of dimension `D`,
/// after checking it is one of `shapes` (alternatives of `D::NDIM` extents
/// each), C-contiguous and, when `write`, writeable.
fn checked<'py, D: Dimension>(
    name: &str,
    obj: &Bound<'py, PyAny>,
    shapes: &[&[Dim]],
    write: bool,
) -> PyResult<Bound<'py, PyArray<f64, D>>> {
    debug_assert!(shapes.iter().all(|s| D::NDIM == Some(s.len())));
    let refuse = |got: String| {
        let shapes: Vec<String> = shapes.iter().map(|s| shape_text(s, dim_text)).collect();
        let layout = if write {
            "C-contiguous and writeable"
        } else {
            "C-contiguous"
        };
        errors::value(format!(
            "{name} must be a float64 array of shape {}, {layout}, got {got}",
            shapes.join(" or ")
        ))
    };
    let Ok(a) = obj.cast::<PyUntypedArray>() else {
        let kind = obj
            .get_type()
            .name()
            .map_or_else(|_| "?".to_owned(), |n| n.to_string());
        return Err(refuse(kind));
    };
    let got = || {
        format!(
            "{} array of shape {}",
            a.dtype(),
            shape_text(a.shape(), usize::to_string)
        )
    };
    if !a.dtype().is_equiv_to(&numpy::dtype::<f64>(obj.py()))
        || !shapes.iter().any(|s| fits(s, a.shape()))
    {
        return Err(refuse(got()));
    }
    if !a.is_c_contiguous() {
        return Err(refuse(format!(
            "a {} that is not C-contiguous (np.ascontiguousarray makes a copy that is)",
            got()
        )));
    }
    if write
        && !a
            .getattr("flags")?
            .getattr("writeable")?
            .extract::<bool>()?
    {
        return Err(refuse(format!("a read-only {}", got())));
    }
    a.cast::<PyArray<f64, D>>()
        .cloned()
        .map_err(|e| refuse(format!("{} ({e})", got())))
}

/// The array argument `name`, read: see [`checked`].
pub(crate) fn readonly<'py, D: Dimension>(
    name: &str,
    obj: &Bound<'py, PyAny>,
    shapes: &[&[Dim]],
) -> PyResult<PyReadonlyArray<'py, f64, D>> {
    checked::<D>(name, obj, shapes, false)?
        .try_readonly()
        .map_err(|e| errors::value(format!("{name}: {e}")))
}

/// The array argument `name`, written into: see [`checked`].
pub(crate) fn readwrite<'py, D: Dimension>(
    name: &str,
    obj: &Bound<'py, PyAny>,
    shapes: &[&[Dim]],
) -> PyResult<PyReadwriteArray<'py, f64, D>> {
    checked::<D>(name, obj, shapes, true)?
        .try_readwrite()
        .map_err(|e| errors::value(format!("{name}: {e}")))
}

/// Every value of the array argument `name` finite, or the first one that
/// is not: `poses: NaN is not finite`.
pub(crate) fn finite<'a>(name: &str, values: impl IntoIterator<Item = &'a f64>) -> PyResult<()> {
    match values.into_iter().find(|v| !v.is_finite()) {
        Some(bad) => Err(errors::value(format!("{name}: {bad} is not finite"))),
        None => Ok(()),
    }
}
