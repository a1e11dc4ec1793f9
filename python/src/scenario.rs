//! Scenarios from Python: the built-ins, files and documents; a run into an
//! output directory (what `echelon run` writes, read back by the Python side
//! with pandas); the figures and report of `echelon plot`; and sweeps, whole
//! or one case at a time (what a Ray task runs).

use std::path::{Path, PathBuf};

use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use echelon::error::{Location, num};
use echelon::odometry::ZetaModel;
use echelon::scenario::{self as sc, Overrides};
use echelon::sweep::{self, Grid, GridSpec};
use echelon::{Scenario, Variant};

use crate::errors;

/// What a scenario is rebuilt from: source, origin, base directory.
type SourceParts = (String, String, Option<PathBuf>);

/// A figure written: its name, SVG and PNG paths.
type Figure = (String, PathBuf, PathBuf);

/// A parsed scenario (`echelon.Scenario` wraps it with its overrides).
#[pyclass(module = "echelon._echelon", name = "Scenario", frozen)]
#[derive(Debug, Clone)]
pub(crate) struct PyScenario {
    pub(crate) inner: Scenario,
    origin: String,
    base_dir: Option<PathBuf>,
}

/// `echelon run`'s flags as a dict (`dt`, `duration`, `log_dt`, `law`,
/// `seed`; absent or None: the scenario's own).
#[derive(Debug, Clone, Default)]
pub(crate) struct OverrideArgs {
    dt: Option<f64>,
    duration: Option<f64>,
    log_dt: Option<f64>,
    law: Option<String>,
    seed: Option<u64>,
}

impl<'a, 'py> FromPyObject<'a, 'py> for OverrideArgs {
    type Error = PyErr;

    fn extract(ob: Borrowed<'a, 'py, PyAny>) -> PyResult<Self> {
        let d = ob.cast::<PyDict>()?;
        for key in d.keys() {
            let key: String = key.extract()?;
            if !OVERRIDES.contains(&key.as_str()) {
                return Err(PyTypeError::new_err(format!(
                    "unknown override `{key}` (the overrides are {})",
                    OVERRIDES.join(", ")
                )));
            }
        }
        fn item<'py, T: FromPyObjectOwned<'py>>(
            d: &Bound<'py, PyDict>,
            key: &str,
        ) -> PyResult<Option<T>> {
            match d.get_item(key)? {
                Some(v) if !v.is_none() => v.extract().map(Some).map_err(Into::into),
                _ => Ok(None),
            }
        }
        Ok(OverrideArgs {
            dt: item(&d, "dt")?,
            duration: item(&d, "duration")?,
            log_dt: item(&d, "log_dt")?,
            law: item(&d, "law")?,
            seed: item(&d, "seed")?,
        })
    }
}

/// The keys of [`OverrideArgs`].
const OVERRIDES: [&str; 5] = ["dt", "duration", "log_dt", "law", "seed"];

impl OverrideArgs {
    /// The overrides, checked as `echelon run` checks its flags.
    pub(crate) fn resolve(&self) -> PyResult<Overrides> {
        let law = match self.law.as_deref() {
            None => None,
            Some("paper") => Some(Variant::Paper),
            Some("complete") => Some(Variant::Complete),
            Some(other) => {
                return Err(errors::value(format!(
                    "law: `{other}` is not a law (paper or complete)"
                )));
            }
        };
        for (field, v, zero_ok) in [
            ("dt", self.dt, false),
            ("duration", self.duration, false),
            ("log_dt", self.log_dt, true),
        ] {
            if let Some(v) = v
                && !(v.is_finite() && (v > 0.0 || (zero_ok && v == 0.0)))
            {
                let want = if zero_ok { "≥ 0" } else { "> 0" };
                return Err(errors::value(format!(
                    "{field}: {} must be a finite number {want}",
                    num(v)
                )));
            }
        }
        Ok(Overrides {
            dt: self.dt,
            duration: self.duration,
            log_dt: self.log_dt,
            law,
            seed: self.seed,
        })
    }
}

/// A sweep grid as a dict: `echelon sweep`'s lists, `gamma`, `transient`
/// (None: half the duration) and the `dt`, `duration` overrides.
#[derive(Debug, Clone, FromPyObject)]
#[pyo3(from_item_all)]
pub(crate) struct GridArgs {
    zeta: Vec<f64>,
    zeta_model: String,
    ed: Vec<f64>,
    eb: Vec<f64>,
    slip: Vec<f64>,
    fix_every: Vec<u64>,
    seeds: Vec<u64>,
    gamma: f64,
    #[pyo3(default)]
    transient: Option<f64>,
    #[pyo3(default)]
    dt: Option<f64>,
    #[pyo3(default)]
    duration: Option<f64>,
}

impl PyScenario {
    fn parse(
        source: &str,
        origin: &str,
        base_dir: Option<PathBuf>,
    ) -> Result<Self, echelon::ScenarioError> {
        let inner = Scenario::parse(source, origin, base_dir.as_deref())?;
        Ok(PyScenario {
            inner,
            origin: origin.to_owned(),
            base_dir,
        })
    }

    /// The run of this scenario under the overrides, or the scenario error.
    pub(crate) fn build(&self, py: Python<'_>, ov: Option<&OverrideArgs>) -> PyResult<sc::Run> {
        let ov = ov.map_or_else(|| Ok(Overrides::default()), OverrideArgs::resolve)?;
        self.inner.build(&ov).map_err(|e| errors::scenario(py, &e))
    }
}

#[pymethods]
impl PyScenario {
    /// Parses TOML `source`; `origin` names it in errors, `base_dir` resolves
    /// relative file references (waypoints).
    #[staticmethod]
    #[pyo3(signature = (source, origin, base_dir=None))]
    fn from_source(
        py: Python<'_>,
        source: &str,
        origin: &str,
        base_dir: Option<PathBuf>,
    ) -> PyResult<Self> {
        Self::parse(source, origin, base_dir).map_err(|e| errors::scenario(py, &e))
    }

    /// A document given as a Python dict (as `tomllib.load` gives it),
    /// turned into TOML and parsed. Its values keep their meaning: a NaN or
    /// an infinity reaches the scenario's own checks, which name its field;
    /// a value TOML has no form for is refused naming its path (as the
    /// file's fields are named, indices from 1). numpy scalars and arrays
    /// are their `tolist()`.
    #[staticmethod]
    #[pyo3(signature = (document, origin, base_dir=None))]
    fn from_dict(
        py: Python<'_>,
        document: &Bound<'_, PyAny>,
        origin: &str,
        base_dir: Option<PathBuf>,
    ) -> PyResult<Self> {
        let value = toml_value(document, &mut String::new(), 0).map_err(|(field, message)| {
            errors::scenario(
                py,
                &echelon::ScenarioError {
                    field,
                    ..whole(origin, message)
                },
            )
        })?;
        if !value.is_table() {
            return Err(PyTypeError::new_err(format!(
                "not a scenario document: a dict of the scenario's tables, not a {}",
                document.get_type().name()?
            )));
        }
        let source = toml::to_string(&value).map_err(|e| {
            errors::scenario(py, &whole(origin, format!("not a scenario document: {e}")))
        })?;
        Self::from_source(py, &source, origin, base_dir)
    }

    /// A built-in scenario.
    #[staticmethod]
    fn builtin(py: Python<'_>, name: &str) -> PyResult<Self> {
        let Some((_, src)) = sc::builtin().iter().find(|(n, _)| *n == name) else {
            let names: Vec<&str> = sc::builtin().iter().map(|(n, _)| *n).collect();
            return Err(errors::scenario(
                py,
                &whole(
                    name,
                    format!(
                        "no built-in scenario of that name (built-ins: {})",
                        names.join(", ")
                    ),
                ),
            ));
        };
        Self::from_source(py, src, &format!("builtin:{name}"), None)
    }

    /// The built-in scenarios' names.
    #[staticmethod]
    fn builtins() -> Vec<&'static str> {
        sc::builtin().iter().map(|(n, _)| *n).collect()
    }

    /// Reads and parses a scenario file.
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        let inner = Scenario::load(&path).map_err(|e| errors::scenario(py, &e))?;
        Ok(PyScenario {
            inner,
            origin: path.display().to_string(),
            base_dir: path.parent().map(Path::to_path_buf),
        })
    }

    /// The scenario's name.
    #[getter]
    fn name(&self) -> &str {
        self.inner.name()
    }

    /// The TOML source.
    #[getter]
    fn source(&self) -> &str {
        self.inner.source()
    }

    /// Where it came from (a path or `builtin:NAME`).
    #[getter]
    fn origin(&self) -> &str {
        &self.origin
    }

    /// The directory relative references resolve against.
    #[getter]
    fn base_dir(&self) -> Option<PathBuf> {
        self.base_dir.clone()
    }

    /// Builds the scenario under the overrides; returns its warnings
    /// (raises `ScenarioError` when it does not build).
    #[pyo3(signature = (overrides=None))]
    fn check(&self, py: Python<'_>, overrides: Option<OverrideArgs>) -> PyResult<Vec<String>> {
        let run = self.build(py, overrides.as_ref())?;
        Ok(run
            .warnings
            .iter()
            .chain(run.plan.warnings())
            .cloned()
            .collect())
    }

    /// Runs the scenario into `dir` (`echelon run --out DIR`: trajectory.csv,
    /// reference.csv, integrals.csv, summary.json, scenario.toml, and
    /// odometry.csv / safety.csv when present), the GIL released; returns
    /// summary.json's text. A run that diverged keeps its outputs up to the
    /// last state within bounds and raises `SimulationError`.
    #[pyo3(signature = (dir, overrides=None))]
    fn run(
        &self,
        py: Python<'_>,
        dir: PathBuf,
        overrides: Option<OverrideArgs>,
    ) -> PyResult<String> {
        let mut run = self.build(py, overrides.as_ref())?;
        let summary = py
            .detach(|| echelon::output::run_to_dir(&mut run, &dir, &mut []))
            .map_err(|e| errors::output(&e))?;
        serde_json::to_string(&summary).map_err(errors::value)
    }

    /// The number of cases of a sweep grid.
    fn sweep_len(&self, py: Python<'_>, grid: GridArgs) -> PyResult<usize> {
        let (grid, _) = self.grid(py, &grid)?;
        Ok(grid.cases().len())
    }

    /// `echelon sweep`'s `sweep.csv` for the grid, every case on all cores
    /// (the GIL released). `cases` limits it to those indices (grid order),
    /// without the header: what one Ray task computes; joined in order after
    /// the header they are the same bytes.
    #[pyo3(signature = (grid, cases=None, threads=None))]
    fn sweep_csv(
        &self,
        py: Python<'_>,
        grid: GridArgs,
        cases: Option<Vec<usize>>,
        threads: Option<usize>,
    ) -> PyResult<String> {
        let (grid, ov) = self.grid(py, &grid)?;
        let scenario = &self.inner;
        let pool = {
            let mut b = rayon::ThreadPoolBuilder::new();
            if let Some(k) = threads {
                if k == 0 {
                    return Err(errors::value("threads: must be ≥ 1"));
                }
                b = b.num_threads(k);
            }
            b.build().map_err(errors::value)?
        };
        let rows = py.detach(|| {
            pool.install(|| match &cases {
                None => sweep::run(scenario, &ov, &grid, &|| ()),
                Some(idx) => {
                    use rayon::prelude::*;
                    let all = grid.cases();
                    let picked: Vec<_> = idx
                        .iter()
                        .map(|&k| all.get(k).copied().ok_or(k))
                        .collect::<Result<_, usize>>()
                        .map_err(|k| {
                            sweep::SweepError::Param(echelon::ParamError::new(
                                "cases",
                                k as f64,
                                format!("past the grid's {} cases", all.len()),
                            ))
                        })?;
                    picked
                        .par_iter()
                        .map(|c| sweep::run_case(scenario, &ov, &grid, c))
                        .collect()
                }
            })
        });
        let rows = rows.map_err(|e| match e {
            sweep::SweepError::Scenario(e) => errors::scenario(py, &e),
            sweep::SweepError::Sim(e) => errors::sim(&e),
            sweep::SweepError::Param(e) => errors::grid_param(&e),
        })?;
        let mut bytes = Vec::new();
        sweep::write_csv(&mut bytes, &rows, grid.spec().zeta_model).map_err(errors::value)?;
        let text = String::from_utf8(bytes).map_err(errors::value)?;
        Ok(match cases {
            // Without the header line.
            Some(_) => text
                .split_once('\n')
                .map_or(String::new(), |(_, rest)| rest.to_owned()),
            None => text,
        })
    }

    /// Pickles as its source, origin and base directory (a Ray task gets it so).
    fn __reduce__(slf: &Bound<'_, Self>) -> PyResult<(Py<PyAny>, SourceParts)> {
        let this = slf.get();
        let ctor = slf.get_type().getattr("from_source")?.unbind();
        Ok((
            ctor,
            (
                this.inner.source().to_owned(),
                this.origin.clone(),
                this.base_dir.clone(),
            ),
        ))
    }

    fn __repr__(&self) -> String {
        format!(
            "<echelon._echelon.Scenario {} from {}>",
            self.inner.name(),
            self.origin
        )
    }
}

impl PyScenario {
    /// The sweep grid and overrides, as `echelon sweep` builds them
    /// (`transient` defaults to half the run's duration).
    fn grid(&self, py: Python<'_>, g: &GridArgs) -> PyResult<(Grid, Overrides)> {
        let zeta_model = match g.zeta_model.as_str() {
            "wheels" => ZetaModel::Wheels,
            "worst-case" => ZetaModel::WorstCase,
            other => {
                return Err(errors::value(format!(
                    "zeta_model: `{other}` is not a model (wheels or worst-case)"
                )));
            }
        };
        let ov = OverrideArgs {
            dt: g.dt,
            duration: g.duration,
            ..OverrideArgs::default()
        };
        let probe = self.build(py, Some(&ov))?;
        let duration = probe.plan.steps() as f64 * probe.plan.config().dt;
        let grid = Grid::new(GridSpec {
            zeta: g.zeta.clone(),
            zeta_model,
            wheel_diameter_ratio: g.ed.clone(),
            wheelbase_ratio: g.eb.clone(),
            slip: g.slip.clone(),
            fix_every: g.fix_every.clone(),
            seeds: g.seeds.clone(),
            gamma: g.gamma,
            transient: g.transient.unwrap_or(0.5 * duration),
        })
        .map_err(|e| errors::grid_param(&e))?;
        Ok((grid, ov.resolve()?))
    }
}

/// Deepest nesting of a dict document (a scenario's is 4 levels; a list
/// that holds itself would otherwise recurse forever).
const MAX_DEPTH: usize = 32;

/// A Python value as TOML, or the path of the first value that has no TOML
/// form (`agents[3].offset`, indices from 1 as in the file's field names)
/// and why.
fn toml_value(
    v: &Bound<'_, PyAny>,
    path: &mut String,
    depth: usize,
) -> Result<toml::Value, (String, String)> {
    use pyo3::types::{PyBool, PyFloat, PyInt, PyList, PyString, PyTuple};
    let at = |path: &String, message: String| (path.clone(), message);
    if depth > MAX_DEPTH {
        return Err(at(
            path,
            format!("nested deeper than {MAX_DEPTH} levels (a list or dict that holds itself?)"),
        ));
    }
    let type_name = || {
        v.get_type()
            .name()
            .map_or_else(|_| "?".to_owned(), |n| n.to_string())
    };
    if v.is_instance_of::<PyBool>() {
        return Ok(toml::Value::Boolean(
            v.is_truthy().map_err(|e| at(path, e.to_string()))?,
        ));
    }
    if v.is_instance_of::<PyInt>() {
        return v.extract::<i64>().map(toml::Value::Integer).map_err(|_| {
            at(
                path,
                format!("{v} is beyond a TOML integer's range (64 bits)"),
            )
        });
    }
    if v.is_instance_of::<PyFloat>() {
        return v
            .extract::<f64>()
            .map(toml::Value::Float)
            .map_err(|e| at(path, e.to_string()));
    }
    if let Ok(text) = v.cast::<PyString>() {
        return Ok(toml::Value::String(text.to_string()));
    }
    if let Ok(dict) = v.cast::<PyDict>() {
        let mut table = toml::Table::new();
        for (key, item) in dict.iter() {
            let Ok(key) = key.cast::<PyString>().map(|k| k.to_string()) else {
                return Err(at(
                    path,
                    format!(
                        "the key {key} (of type {}) is not text (TOML keys are text)",
                        key.get_type()
                            .name()
                            .map_or_else(|_| "?".to_owned(), |n| n.to_string())
                    ),
                ));
            };
            let len = path.len();
            if !path.is_empty() {
                path.push('.');
            }
            path.push_str(&key);
            let item = toml_value(&item, path, depth + 1)?;
            path.truncate(len);
            table.insert(key, item);
        }
        return Ok(toml::Value::Table(table));
    }
    if v.is_instance_of::<PyList>() || v.is_instance_of::<PyTuple>() {
        let mut array = Vec::new();
        for (i, item) in v
            .try_iter()
            .map_err(|e| at(path, e.to_string()))?
            .enumerate()
        {
            let item = item.map_err(|e| at(path, e.to_string()))?;
            let len = path.len();
            path.push_str(&format!("[{}]", i + 1));
            array.push(toml_value(&item, path, depth + 1)?);
            path.truncate(len);
        }
        return Ok(toml::Value::Array(array));
    }
    if v.is_none() {
        return Err(at(
            path,
            "None has no TOML form: leave the key out for its default".to_owned(),
        ));
    }
    // numpy scalars and arrays: their Python values.
    if let Ok(tolist) = v.getattr("tolist")
        && let Ok(plain) = tolist.call0()
        && !plain.is(v)
    {
        return toml_value(&plain, path, depth + 1);
    }
    Err(at(
        path,
        format!(
            "a value of type {} has no TOML form (a scenario holds numbers, text, booleans, lists and dicts)",
            type_name()
        ),
    ))
}

/// An error about a whole document (no line).
fn whole(file: &str, message: String) -> echelon::ScenarioError {
    echelon::ScenarioError {
        location: Location {
            file: file.to_owned(),
            line: 0,
            column: 0,
        },
        field: String::new(),
        message,
    }
}

/// `echelon plot DIR`: the run's figures (SVG and PNG) and report.html;
/// returns the PNG paths by figure name and the report's path.
#[pyfunction]
fn plot_dir(py: Python<'_>, dir: PathBuf) -> PyResult<(Vec<Figure>, PathBuf)> {
    let written = py
        .detach(|| echelon_report::write_all(&dir))
        .map_err(errors::value)?;
    let figures = written
        .figures
        .into_iter()
        .map(|f| {
            let stem = f
                .png
                .file_stem()
                .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
            (stem, f.svg, f.png)
        })
        .collect();
    Ok((figures, written.report))
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyScenario>()?;
    m.add_function(wrap_pyfunction!(plot_dir, m)?)?;
    Ok(())
}
