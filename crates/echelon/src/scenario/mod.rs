//! Scenarios: TOML files describing robots, gains, reference, formation and run
//! settings, turned into a [`Simulation`]. The paper's setups ship in
//! `scenarios/` and are built into the library ([`builtin`]).
//!
//! Every problem is reported as a [`ScenarioError`] naming the file, line,
//! column and field, and why the value is refused.
//!
//! - [`schema`]: the file format;
//! - `builtin`: the built-in scenarios and finding one by name or path;
//! - `overrides`: command-line overrides, applied to the parsed document;
//! - `build`: the document turned into a [`Simulation`], field by field through
//!   the domain types' validating constructors;
//! - `merge`: per-agent tables over the file's;
//! - `waypoints`: the waypoint CSV reader;
//! - `locate`: field paths to `file:line:column`;
//! - `plausible`: the plausible range of every number ([`PLAUSIBLE`]);
//! - `fleet`: the `[fleet]` section.

mod build;
mod builtin;
mod fields;
mod fleet;
mod locate;
mod merge;
mod overrides;
mod plausible;
pub mod schema;
mod waypoints;

pub use builtin::builtin;
pub use fleet::{
    DEFAULT_CMD_VEL_TIMEOUT, DEFAULT_CONTROL_RATE, DEFAULT_DECEL, DEFAULT_HOLD,
    DEFAULT_LINK_TIMEOUT, DEFAULT_NAMESPACE, DEFAULT_ODOM_RATE, DEFAULT_ODOM_TIMEOUT,
    DEFAULT_REFERENCE_RATE, DEFAULT_STALE_AFTER, ENDPOINT_PROTOCOLS, FixSource, FleetSettings,
    LinkLoss, LinkPolicy, MAX_DOMAIN_ID, Placement, Ros2Link, check_endpoint,
    check_listen_endpoint, endpoint_address, endpoint_host_port, endpoint_port,
    is_valid_fleet_name,
};
pub use overrides::{OdometryOverrides, Overrides};
pub use plausible::{PLAUSIBLE, Plausible};

use std::fmt::Display;
use std::path::{Path, PathBuf};

use crate::error::ScenarioError;
use crate::plan::Plan;
use crate::sim::Simulation;

use locate::{FieldPath, Locator, Origins, whole_file_error};
use merge::Merge;
use schema::ScenarioFile;

/// Default logging period, s.
pub const DEFAULT_LOG_DT: f64 = 0.01;

/// A parsed scenario file, with what is needed to locate errors in it.
#[derive(Debug, Clone)]
pub struct Scenario {
    /// The parsed contents.
    pub file: ScenarioFile,
    name: String,
    origin: String,
    source: String,
    base_dir: Option<PathBuf>,
    /// Fields set on behalf of a command-line flag ([`OdometryOverrides`]),
    /// whose errors name the flag.
    flags: Origins,
}

/// A scenario ready to run.
#[derive(Debug, Clone)]
pub struct Run {
    /// Scenario name.
    pub name: String,
    /// Its one-line description.
    pub description: Option<String>,
    /// What to run, resolved and checked.
    pub plan: Plan,
    /// Log every this many steps (1: every step).
    pub log_every: u64,
    /// Seed of the random models.
    pub seed: u64,
    /// Values that are allowed but outside their usual range ([`PLAUSIBLE`]),
    /// one line each: `file:line:column: field: message`. The simulation's
    /// own warnings are [`Plan::warnings`].
    pub warnings: Vec<String>,
    /// The scenario as run: a comment header naming where it came from and the
    /// command-line overrides applied, then the exact TOML source.
    /// [`crate::output::run_to_dir`] writes it as `scenario.toml`.
    pub record: String,
}

impl Run {
    /// A new simulation of the plan, at `t = 0`.
    pub fn simulation(&self) -> Simulation {
        Simulation::new(&self.plan)
    }
}

impl Scenario {
    /// Parses a scenario from TOML source. `origin` names it in errors (a path or
    /// `builtin:NAME`); `base_dir` resolves relative file references.
    pub fn parse(
        source: &str,
        origin: &str,
        base_dir: Option<&Path>,
    ) -> Result<Scenario, ScenarioError> {
        let file: ScenarioFile = toml::from_str(source)
            .map_err(|e| Locator::new(source, origin, &[]).parse_error(&e))?;
        let name = file.name.clone().unwrap_or_else(|| {
            Path::new(origin)
                .file_stem()
                .map_or_else(|| origin.to_owned(), |s| s.to_string_lossy().into_owned())
        });
        Ok(Scenario {
            file,
            name,
            origin: origin.to_owned(),
            source: source.to_owned(),
            base_dir: base_dir.map(Path::to_path_buf),
            flags: Origins::new(),
        })
    }

    /// Reads and parses a scenario file.
    pub fn load(path: &Path) -> Result<Scenario, ScenarioError> {
        let origin = path.display().to_string();
        let source = std::fs::read_to_string(path)
            .map_err(|e| whole_file_error(&origin, format!("cannot read the file: {e}")))?;
        Scenario::parse(&source, &origin, path.parent())
    }

    /// The scenario's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The TOML source it was parsed from.
    pub fn source(&self) -> &str {
        &self.source
    }

    /// The source with a header recording its origin and `ov` (see [`Run::record`]).
    fn record(&self, ov: &Overrides) -> String {
        let mut out = format!(
            "# Written by echelon: the scenario this run used, verbatim below this header.\n\
             # origin: {}\n\
             # overrides: {ov}\n\n",
            self.origin
        );
        out.push_str(&self.source);
        if !out.ends_with('\n') {
            out.push('\n');
        }
        out
    }

    /// Locates errors in this file (no command-line overrides).
    fn locator(&self) -> Locator<'_> {
        Locator::new(&self.source, &self.origin, &[])
    }

    /// An error at `path` in this file.
    fn error(&self, path: &FieldPath, message: impl Display) -> ScenarioError {
        self.locator().error(path, message)
    }
}
