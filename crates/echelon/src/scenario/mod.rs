//! Scenarios: TOML files describing robots, gains, reference, formation and run
//! settings, turned into a [`Simulation`]. The paper's setups ship in
//! `scenarios/` and are built into the library ([`builtin`]).
//!
//! Every problem is reported as a [`ScenarioError`] naming the file, line,
//! column and field, and why the value is refused.

mod fleet;
mod locate;
pub mod schema;

pub use fleet::{
    DEFAULT_CONTROL_RATE, DEFAULT_DECEL, DEFAULT_HOLD, DEFAULT_LINK_TIMEOUT,
    DEFAULT_REFERENCE_RATE, DEFAULT_STALE_AFTER, FleetSettings, LinkLoss, LinkPolicy,
    is_valid_fleet_name,
};

use std::fmt::Display;
use std::path::{Path, PathBuf};

use crate::control::{Gains, Variant};
use crate::error::{FormationError, Location, ParamError, ReferenceError, ScenarioError, SimError};
use crate::formation::Leader;
use crate::lycomp::{LyComp, LyDerivatives, Placement};
use crate::model::{RobotParams, State};
use crate::odometry::{ErrorModel, FixSchedule, FixSpec, Fusion, OdometrySpec, ZetaModel};
use crate::reference::{Circle, Cubic, Lemniscate, Reference, Waypoints};
use crate::sim::{AgentSpec, SimConfig, Simulation, Timing, whole_ratio};

use locate::{FieldPath, Spans, line_col};
use schema::{
    AgentSection, FixesSection, FusionName, LawName, LeaderSpec, LyCompName, LyDerivativesName,
    ModeName, OdometrySection, PoseSpec, ReferenceSection, RobotSection, ScenarioFile,
    ZetaModelName,
};

include!(concat!(env!("OUT_DIR"), "/builtin.rs"));

/// The scenarios built into echelon, as `(name, TOML source)`, from `scenarios/*.toml`.
pub fn builtin() -> &'static [(&'static str, &'static str)] {
    BUILTIN
}

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
}

/// Command-line style overrides of a scenario's settings.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Overrides {
    /// RK4 step, s.
    pub dt: Option<f64>,
    /// Simulated time, s.
    pub duration: Option<f64>,
    /// Logging period, s (0: every step).
    pub log_dt: Option<f64>,
    /// Law variant for every agent.
    pub law: Option<Variant>,
    /// Seed of the random models.
    pub seed: Option<u64>,
}

/// A scenario ready to run.
#[derive(Debug, Clone)]
pub struct Run {
    /// Scenario name.
    pub name: String,
    /// Its one-line description.
    pub description: Option<String>,
    /// The simulation, at `t = 0`.
    pub simulation: Simulation,
    /// Log every this many steps (1: every step).
    pub log_every: u64,
    /// Seed of the random models.
    pub seed: u64,
    /// The scenario as run: a comment header naming where it came from and the
    /// command-line overrides applied, then the exact TOML source.
    /// [`crate::output::run_to_dir`] writes it as `scenario.toml`.
    pub record: String,
}

impl std::fmt::Display for Overrides {
    /// The overrides as `echelon run` flags (`--dt 0.002 --law complete`), or `none`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mut flags = Vec::new();
        for (flag, v) in [
            ("--dt", self.dt),
            ("--duration", self.duration),
            ("--log-dt", self.log_dt),
        ] {
            if let Some(v) = v {
                flags.push(format!("{flag} {v}"));
            }
        }
        if let Some(seed) = self.seed {
            flags.push(format!("--seed {seed}"));
        }
        if let Some(law) = self.law {
            flags.push(match law {
                Variant::Paper => "--law paper".to_owned(),
                Variant::Complete => "--law complete".to_owned(),
            });
        }
        if flags.is_empty() {
            f.write_str("none")
        } else {
            f.write_str(&flags.join(" "))
        }
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
        let file: ScenarioFile = toml::from_str(source).map_err(|e| {
            let offset = e.span().map_or(0, |s| s.start);
            let spans = Spans::new(source);
            let mut field = spans.path_at(offset);
            // After a syntax error the recovered spans are only trusted when the
            // field's key is on the error's own line.
            let syntax_error = toml::de::DeTable::parse(source).is_err();
            let key_on_error_line = spans
                .key_span_of(&field)
                .is_some_and(|s| line_col(source, s.start).0 == line_col(source, offset).0);
            if syntax_error && !key_on_error_line {
                field = FieldPath::default();
            }
            let message = e.message().trim().to_owned();
            if let Some(missing) = message
                .strip_prefix("missing field `")
                .and_then(|m| m.strip_suffix('`'))
            {
                field = field.key(missing);
            }
            let (line, column) = e.span().map_or((0, 0), |s| line_col(source, s.start));
            ScenarioError {
                location: Location {
                    file: origin.to_owned(),
                    line,
                    column,
                },
                field: field.to_string(),
                message,
            }
        })?;
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
        })
    }

    /// Reads and parses a scenario file.
    pub fn load(path: &Path) -> Result<Scenario, ScenarioError> {
        let origin = path.display().to_string();
        let source = std::fs::read_to_string(path).map_err(|e| ScenarioError {
            location: Location {
                file: origin.clone(),
                line: 0,
                column: 0,
            },
            field: String::new(),
            message: format!("cannot read the file: {e}"),
        })?;
        Scenario::parse(&source, &origin, path.parent())
    }

    /// A built-in scenario by name.
    pub fn builtin(name: &str) -> Option<Scenario> {
        let (_, src) = BUILTIN.iter().find(|(n, _)| *n == name)?;
        Scenario::parse(src, &format!("builtin:{name}"), None).ok()
    }

    /// A built-in name, or a path to a `.toml` file (anything with a `.toml`
    /// extension or a path separator is taken as a path).
    pub fn resolve(name_or_path: &str) -> Result<Scenario, ScenarioError> {
        let is_path = name_or_path.ends_with(".toml")
            || name_or_path.contains('/')
            || name_or_path.contains(std::path::MAIN_SEPARATOR);
        if is_path {
            return Scenario::load(Path::new(name_or_path));
        }
        Scenario::builtin(name_or_path).ok_or_else(|| {
            let names: Vec<&str> = BUILTIN.iter().map(|(n, _)| *n).collect();
            ScenarioError {
                location: Location {
                    file: name_or_path.to_owned(),
                    line: 0,
                    column: 0,
                },
                field: String::new(),
                message: format!(
                    "no built-in scenario of that name (built-ins: {}; a file path must end in .toml)",
                    names.join(", ")
                ),
            }
        })
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

    /// An error at `path` in this file.
    fn error(&self, path: &FieldPath, message: impl Display) -> ScenarioError {
        let spans = Spans::new(&self.source);
        let (line, column) = spans
            .span_of(path)
            .map_or((0, 0), |s| line_col(&self.source, s.start));
        ScenarioError {
            location: Location {
                file: self.origin.clone(),
                line,
                column,
            },
            field: path.to_string(),
            message: message.to_string(),
        }
    }

    fn param_error(&self, section: &FieldPath, e: &ParamError) -> ScenarioError {
        self.error(&section.key(e.field), format!("{} {}", e.value, e.reason))
    }

    /// Resolves defaults, validates every value and builds the simulation.
    pub fn build(&self, ov: &Overrides) -> Result<Run, ScenarioError> {
        let f = &self.file;
        let sim = FieldPath::from("sim");
        let dt = self.setting(ov.dt, f.sim.dt, &sim.key("dt"), "--dt", false)?;
        let duration = self.setting(
            ov.duration,
            f.sim.duration,
            &sim.key("duration"),
            "--duration",
            false,
        )?;
        let log_dt = match ov.log_dt {
            Some(v) => self.setting(Some(v), v, &FieldPath::from("log.dt"), "--log-dt", true)?,
            None => {
                let v = f.log.dt.unwrap_or(DEFAULT_LOG_DT);
                self.setting(None, v, &FieldPath::from("log.dt"), "", true)?
            }
        };
        let log_every = if log_dt == 0.0 {
            1
        } else {
            whole_ratio(log_dt, dt).ok_or_else(|| {
                self.error(
                    &FieldPath::from("log.dt"),
                    format!(
                        "{log_dt} s is not 0 (every step) or a whole multiple of dt = {dt} s (on the command line: --log-dt)"
                    ),
                )
            })?
        };
        let timing = match f.sim.controller_period {
            None => Timing::Continuous,
            Some(p) => Timing::Sampled {
                period: self.period(p, &sim.key("controller_period"), dt)?,
            },
        };
        let reference = self.reference()?;
        let agents = f
            .agents
            .iter()
            .enumerate()
            .map(|(i, a)| self.agent(i, a, ov))
            .collect::<Result<Vec<_>, _>>()?;
        if agents.is_empty() {
            return Err(self.error(
                &FieldPath::from("agents"),
                "a scenario needs at least one agent",
            ));
        }
        let config = SimConfig {
            dt,
            duration,
            timing,
        };
        let odometry = f
            .agents
            .iter()
            .enumerate()
            .map(|(i, a)| self.odometry(i, a, dt, &timing))
            .collect::<Result<Vec<_>, _>>()?;
        let seed = ov.seed.or(f.seed).unwrap_or(0);
        let simulation = Simulation::new(agents, reference, config)
            .and_then(|s| s.with_odometry(odometry, seed))
            .map_err(|e| self.sim_error(e))?;
        Ok(Run {
            name: self.name.clone(),
            description: f.description.clone(),
            simulation,
            log_every,
            seed,
            record: self.record(ov),
        })
    }

    /// A sampling period at `path`: finite, > 0 and a whole multiple of `dt`.
    fn period(&self, p: f64, path: &FieldPath, dt: f64) -> Result<f64, ScenarioError> {
        if !(p.is_finite() && p > 0.0) {
            return Err(self.error(path, format!("{p} must be a finite number > 0")));
        }
        if whole_ratio(p, dt).is_none() {
            return Err(self.error(
                path,
                format!("{p} s is not a whole multiple of dt = {dt} s"),
            ));
        }
        Ok(p)
    }

    /// A timing value from the command line or the file, checked positive (or zero).
    fn setting(
        &self,
        over: Option<f64>,
        file: f64,
        path: &FieldPath,
        flag: &str,
        zero_ok: bool,
    ) -> Result<f64, ScenarioError> {
        let v = over.unwrap_or(file);
        let ok = v.is_finite() && (v > 0.0 || (zero_ok && v == 0.0));
        if ok {
            return Ok(v);
        }
        let need = if zero_ok { "≥ 0" } else { "> 0" };
        if over.is_some() {
            Err(ScenarioError {
                location: Location {
                    file: "command line".into(),
                    line: 0,
                    column: 0,
                },
                field: flag.to_owned(),
                message: format!("{v} must be a finite number {need}"),
            })
        } else {
            Err(self.error(path, format!("{v} must be a finite number {need}")))
        }
    }

    fn sim_error(&self, e: SimError) -> ScenarioError {
        let agent = |k: usize| FieldPath::from("agents").index(k - 1);
        match &e {
            SimError::Formation(fe) => match fe {
                FormationError::Cycle(c) => self.error(&agent(c[0]).key("leader"), fe),
                FormationError::Dangling { agent: a, .. }
                | FormationError::SelfLeader(a)
                | FormationError::ExactDerivativesNeedReference { agent: a, .. } => {
                    self.error(&agent(*a).key("leader"), fe)
                }
                FormationError::NonPositiveLx { agent: a, .. } => {
                    self.error(&agent(*a).key("offset").key("x"), fe)
                }
            },
            SimError::Timing(_) => self.error(&FieldPath::from("sim"), &e),
            _ => self.error(&FieldPath::default(), &e),
        }
    }

    fn pose(&self, p: &PoseSpec, path: &FieldPath, speeds: bool) -> Result<State, ScenarioError> {
        let theta = match (p.theta, p.theta_deg) {
            (Some(_), Some(_)) => {
                return Err(self.error(
                    &path.key("theta_deg"),
                    "give either theta (radians) or theta_deg (degrees), not both",
                ));
            }
            (Some(t), None) => t,
            (None, Some(d)) => d.to_radians(),
            (None, None) => {
                return Err(self.error(
                    path,
                    "missing field `theta` (radians) or `theta_deg` (degrees)",
                ));
            }
        };
        if !speeds && (p.v.is_some() || p.omega.is_some()) {
            let which = if p.v.is_some() { "v" } else { "omega" };
            return Err(self.error(
                &path.key(which),
                "a reference's start pose takes no speed: its motion comes from the reference",
            ));
        }
        let s = State {
            x: p.x,
            y: p.y,
            theta,
            v: p.v.unwrap_or(0.0),
            omega: p.omega.unwrap_or(0.0),
        };
        for (k, v) in [
            ("x", p.x),
            ("y", p.y),
            (
                if p.theta.is_some() {
                    "theta"
                } else {
                    "theta_deg"
                },
                theta,
            ),
            ("v", s.v),
            ("omega", s.omega),
        ] {
            if !v.is_finite() {
                return Err(self.error(&path.key(k), format!("{v} must be a finite number")));
            }
        }
        Ok(s)
    }

    fn reference(&self) -> Result<Reference, ScenarioError> {
        let root = FieldPath::from("reference");
        let section = |kind: &str| root.key(kind);
        let refmap = |kind: &str, e: ReferenceError| -> ScenarioError {
            let at = section(kind);
            match e {
                ReferenceError::Param(p) => {
                    let field = p
                        .field
                        .strip_prefix("start.")
                        .map_or_else(|| at.key(p.field), |f| at.key("start").key(f));
                    self.error(&field, format!("{} {}", p.value, p.reason))
                }
                ReferenceError::TimesNotIncreasing { index, .. }
                | ReferenceError::NonFiniteWaypoint { index } => {
                    self.error(&at.key("points").index(index - 1), e)
                }
                ReferenceError::TooFewWaypoints(_) => self.error(&at.key("points"), e),
            }
        };
        Ok(match &self.file.reference {
            ReferenceSection::Circle {
                speed,
                turn_rate,
                start,
            } => {
                let s = self.pose(start, &section("circle").key("start"), false)?;
                Reference::Circle(
                    Circle::new([s.x, s.y], s.theta, *speed, *turn_rate)
                        .map_err(|e| refmap("circle", e))?,
                )
            }
            ReferenceSection::Line { speed, start } => {
                let s = self.pose(start, &section("line").key("start"), false)?;
                Reference::Circle(
                    Circle::new([s.x, s.y], s.theta, *speed, 0.0).map_err(|e| refmap("line", e))?,
                )
            }
            ReferenceSection::Lemniscate { a, c, center } => Reference::Lemniscate(
                Lemniscate::new(*a, *c, center.unwrap_or([0.0, 0.0]))
                    .map_err(|e| refmap("lemniscate", e))?,
            ),
            ReferenceSection::Cubic { scale, t_switch } => {
                Reference::Cubic(Cubic::new(*scale, *t_switch).map_err(|e| refmap("cubic", e))?)
            }
            ReferenceSection::Waypoints { points, file } => {
                let at = section("waypoints");
                let pts = match (points, file) {
                    (Some(p), None) => p.clone(),
                    (None, Some(f)) => self.waypoint_file(f, &at.key("file"))?,
                    (Some(_), Some(_)) => {
                        return Err(
                            self.error(&at.key("file"), "give either points or file, not both")
                        );
                    }
                    (None, None) => {
                        return Err(self.error(&at, "missing field `points` (or `file`)"));
                    }
                };
                let via_file = file.is_some();
                Reference::Waypoints(Waypoints::new(pts).map_err(|e| {
                    if via_file {
                        self.error(&at.key("file"), e)
                    } else {
                        refmap("waypoints", e)
                    }
                })?)
            }
        })
    }

    /// Reads `t,x,y` rows from a CSV file next to the scenario.
    fn waypoint_file(&self, name: &str, path: &FieldPath) -> Result<Vec<[f64; 3]>, ScenarioError> {
        let full = match &self.base_dir {
            Some(d) => d.join(name),
            None => PathBuf::from(name),
        };
        let shown = full.display().to_string();
        let at = |line: usize, field: &str, message: String| ScenarioError {
            location: Location {
                file: shown.clone(),
                line,
                column: 0,
            },
            field: field.to_owned(),
            message,
        };
        let text = std::fs::read_to_string(&full)
            .map_err(|e| self.error(path, format!("cannot read `{shown}`: {e}")))?;
        let mut reader = csv::ReaderBuilder::new()
            .trim(csv::Trim::All)
            .comment(Some(b'#'))
            .from_reader(text.as_bytes());
        let headers = reader
            .headers()
            .map_err(|e| at(1, "", format!("bad CSV header: {e}")))?
            .clone();
        let col = |name: &str| -> Result<usize, ScenarioError> {
            headers.iter().position(|h| h == name).ok_or_else(|| {
                at(
                    1,
                    name,
                    format!(
                        "the header must name columns t, x and y (found: {})",
                        headers.iter().collect::<Vec<_>>().join(",")
                    ),
                )
            })
        };
        let idx = [col("t")?, col("x")?, col("y")?];
        let mut points = Vec::new();
        for record in reader.records() {
            let record = record.map_err(|e| {
                let line = e.position().map_or(0, |p| p.line() as usize);
                at(line, "", e.to_string())
            })?;
            let line = record.position().map_or(0, |p| p.line() as usize);
            let mut p = [0.0; 3];
            for (k, (&c, name)) in idx.iter().zip(["t", "x", "y"]).enumerate() {
                let cell = record.get(c).unwrap_or("");
                p[k] = cell
                    .parse()
                    .map_err(|_| at(line, name, format!("`{cell}` is not a number")))?;
            }
            points.push(p);
        }
        Ok(points)
    }

    fn robot(&self, name: &str, path: &FieldPath) -> Result<RobotParams, ScenarioError> {
        if let Some(r) = self.file.robots.get(name) {
            return self.robot_section(name, r);
        }
        RobotParams::preset(name).ok_or_else(|| {
            let mut known: Vec<&str> = RobotParams::PRESETS.iter().map(|(n, _)| *n).collect();
            known.extend(self.file.robots.keys().map(String::as_str));
            self.error(
                path,
                format!("unknown robot `{name}` (known: {})", known.join(", ")),
            )
        })
    }

    fn robot_section(&self, name: &str, r: &RobotSection) -> Result<RobotParams, ScenarioError> {
        let at = FieldPath::from("robots").key(name);
        let base = match &r.preset {
            Some(p) => Some(RobotParams::preset(p).ok_or_else(|| {
                self.error(
                    &at.key("preset"),
                    format!("unknown preset `{p}` (presets: agent1, agent2)"),
                )
            })?),
            None => None,
        };
        let field = |v: Option<f64>, from: Option<f64>, key: &str| -> Result<f64, ScenarioError> {
            v.or(from).ok_or_else(|| {
                self.error(
                    &at,
                    format!(
                        "missing field `{key}` (or start from a preset with `preset = \"agent1\"`)"
                    ),
                )
            })
        };
        let params = RobotParams {
            mass: field(r.mass, base.map(|b| b.mass), "mass")?,
            linear_friction: field(
                r.linear_friction,
                base.map(|b| b.linear_friction),
                "linear_friction",
            )?,
            inertia: field(r.inertia, base.map(|b| b.inertia), "inertia")?,
            angular_friction: field(
                r.angular_friction,
                base.map(|b| b.angular_friction),
                "angular_friction",
            )?,
            half_wheelbase: field(
                r.half_wheelbase,
                base.map(|b| b.half_wheelbase),
                "half_wheelbase",
            )?,
            wheel_radius: field(r.wheel_radius, base.map(|b| b.wheel_radius), "wheel_radius")?,
            torque_limit: r.torque_limit.or(base.and_then(|b| b.torque_limit)),
        };
        params.validate().map_err(|e| self.param_error(&at, &e))?;
        Ok(params)
    }

    /// Agent `i`'s odometry: its own `odometry`/`fixes` over the file's, field by
    /// field; `None` when neither asks for odometry (or `enabled = false`).
    fn odometry(
        &self,
        i: usize,
        a: &AgentSection,
        dt: f64,
        timing: &Timing,
    ) -> Result<Option<OdometrySpec>, ScenarioError> {
        let f = &self.file;
        let agent = FieldPath::from("agents").index(i);
        let odo = Merge::new(
            a.odometry.as_ref(),
            f.odometry.as_ref(),
            agent.key("odometry"),
            FieldPath::from("odometry"),
        );
        let fix = Merge::new(
            a.fixes.as_ref(),
            f.fixes.as_ref(),
            agent.key("fixes"),
            FieldPath::from("fixes"),
        );
        let odometry_off = odo.get(|s| s.enabled, "enabled").filter(|(e, _)| !e);
        let fixes_on = fix.any() && fix.get(|s| s.enabled, "enabled").is_none_or(|(e, _)| e);
        if let Some((_, path)) = odometry_off {
            // Global fixes simply do not apply; the agent's own would contradict.
            if fixes_on && a.fixes.is_some() {
                return Err(self.error(
                    &path,
                    "fixes correct an odometry estimate, but this agent's odometry is disabled",
                ));
            }
            return Ok(None);
        }
        if !odo.any() && !fixes_on {
            return Ok(None);
        }
        let period = match odo.get(|s| s.period, "period") {
            None => match timing {
                Timing::Sampled { period } => *period,
                Timing::Continuous => dt,
            },
            Some((p, path)) => self.period(p, &path, dt)?,
        };
        let num = |get: fn(&OdometrySection) -> Option<f64>, key: &str, default: f64| {
            odo.get(get, key).map_or(default, |(v, _)| v)
        };
        let errors = ErrorModel {
            zeta: num(|s| s.zeta, "zeta", 0.0),
            zeta_model: match odo.get(|s| s.zeta_model, "zeta_model") {
                Some((ZetaModelName::WorstCase, _)) => ZetaModel::WorstCase,
                _ => ZetaModel::Wheels,
            },
            wheel_diameter_ratio: num(|s| s.wheel_diameter_ratio, "wheel_diameter_ratio", 1.0),
            wheelbase_ratio: num(|s| s.wheelbase_ratio, "wheelbase_ratio", 1.0),
            slip: num(|s| s.slip, "slip", 0.0),
            ticks_per_rev: odo
                .get(|s| s.ticks_per_rev, "ticks_per_rev")
                .map(|(v, _)| v),
            speed_noise: num(|s| s.speed_noise, "speed_noise", 0.0),
            turn_rate_noise: num(|s| s.turn_rate_noise, "turn_rate_noise", 0.0),
        };
        errors
            .validate()
            .map_err(|e| self.error(&odo.path_of(e.field), format!("{} {}", e.value, e.reason)))?;
        let fixes = if fixes_on {
            let schedule = match (
                fix.get(|s| s.every_steps, "every_steps"),
                fix.get(|s| s.period, "period"),
            ) {
                (Some(_), Some((_, path))) => {
                    return Err(self.error(&path, "give either every_steps or period, not both"));
                }
                (None, None) => {
                    return Err(self.error(
                        &fix.table_path(),
                        "missing field `every_steps` (samples between fixes) or `period` (s)",
                    ));
                }
                (Some((n, path)), None) => {
                    if n == 0 {
                        return Err(self.error(&path, "0 must be ≥ 1"));
                    }
                    FixSchedule::EverySamples(n)
                }
                (None, Some((p, path))) => {
                    if !(p.is_finite() && p > 0.0) || whole_ratio(p, period).is_none() {
                        return Err(self.error(
                            &path,
                            format!(
                                "{p} s is not a whole multiple of the odometry period {period} s"
                            ),
                        ));
                    }
                    FixSchedule::Period(p)
                }
            };
            let value = |get: fn(&FixesSection) -> Option<f64>, key: &str| {
                fix.get(get, key).map(|(v, _)| v)
            };
            let spec = FixSpec {
                schedule,
                position_noise: value(|s| s.position_noise, "position_noise").unwrap_or(0.0),
                heading_noise: value(|s| s.heading_noise, "heading_noise"),
                latency: value(|s| s.latency, "latency").unwrap_or(0.0),
                fusion: match fix.get(|s| s.fusion, "fusion") {
                    Some((FusionName::Ekf, _)) => Fusion::Ekf,
                    _ => Fusion::Reset,
                },
            };
            spec.validate().map_err(|e| {
                self.error(&fix.path_of(e.field), format!("{} {}", e.value, e.reason))
            })?;
            Some(spec)
        } else {
            None
        };
        Ok(Some(OdometrySpec {
            period,
            errors,
            fixes,
        }))
    }

    fn agent(
        &self,
        i: usize,
        a: &AgentSection,
        ov: &Overrides,
    ) -> Result<AgentSpec, ScenarioError> {
        let at = FieldPath::from("agents").index(i);
        let n = self.file.agents.len();
        let name = a.name.clone().unwrap_or_else(|| format!("agent {}", i + 1));
        let robot = self.robot(a.robot.as_deref().unwrap_or("agent1"), &at.key("robot"))?;
        let start = self.pose(&a.start, &at.key("start"), true)?;
        let leader = match a.leader {
            LeaderSpec::Reference => Leader::Reference,
            LeaderSpec::Agent(k) if k >= 1 && (k as usize) <= n => Leader::Agent(k as usize - 1),
            LeaderSpec::Agent(k) => {
                return Err(self.error(
                    &at.key("leader"),
                    format!(
                        "agent {} follows agent {k}, which does not exist (agents are numbered 1..={n}, or \"reference\")",
                        i + 1
                    ),
                ));
            }
        };
        // Each control setting: the agent's own, else [control], else the paper's.
        let control = Merge::new(
            a.control.as_ref(),
            Some(&self.file.control),
            at.key("control"),
            FieldPath::from("control"),
        );
        let check_positive = |(v, path): (f64, FieldPath)| -> Result<f64, ScenarioError> {
            if v.is_finite() && v > 0.0 {
                Ok(v)
            } else {
                Err(self.error(&path, format!("{v} must be a finite number > 0")))
            }
        };
        let ke = check_positive(control.get_or(|c| c.ke, "ke", Gains::PAPER.ke))?;
        let kz = check_positive(control.get_or(|c| c.kz, "kz", Gains::PAPER.kz))?;
        let l = check_positive(control.get_or(|c| c.l, "l", 0.05))?;
        let (law, _) = control.get_or(|c| c.law, "law", LawName::Paper);
        let variant = ov.law.unwrap_or(match law {
            LawName::Paper => Variant::Paper,
            LawName::Complete => Variant::Complete,
        });
        let comp = match control.get_or(|c| c.lycomp, "lycomp", LyCompName::Fit).0 {
            LyCompName::Exact => LyComp::Exact,
            LyCompName::Fit => LyComp::Fit,
            LyCompName::None => LyComp::None,
        };
        let (derivatives, deriv_path) = control.get_or(
            |c| c.ly_derivatives,
            "ly_derivatives",
            LyDerivativesName::Neglect,
        );
        let derivatives = match derivatives {
            LyDerivativesName::Neglect => LyDerivatives::Neglect,
            LyDerivativesName::Exact => LyDerivatives::Exact,
        };
        let placement = match (a.mode.unwrap_or(ModeName::Formation), a.offset) {
            (ModeName::Tracking, None) => Placement::tracking(l),
            (ModeName::Tracking, Some(_)) => {
                return Err(self.error(
                    &at.key("offset"),
                    "pure tracking (mode = \"tracking\") takes no offset: the point L ahead of the robot tracks the leader",
                ));
            }
            (ModeName::Formation, None) => {
                return Err(self.error(
                    &at,
                    "missing field `offset` = { x = L_Xoff, y = L_Yoff } (or mode = \"tracking\")",
                ));
            }
            (ModeName::Formation, Some(o)) => {
                for (k, v) in [("x", o.x), ("y", o.y)] {
                    if !v.is_finite() {
                        return Err(self.error(
                            &at.key("offset").key(k),
                            format!("{v} must be a finite number"),
                        ));
                    }
                }
                if o.x + l <= 0.0 {
                    return Err(self.error(
                        &at.key("offset").key("x"),
                        FormationError::NonPositiveLx {
                            agent: i + 1,
                            lx: o.x + l,
                        },
                    ));
                }
                Placement::new(o.x, o.y, l, comp, derivatives)
            }
        };
        if let Leader::Agent(j) = leader
            && placement.uses_exact_derivatives()
        {
            return Err(self.error(
                &deriv_path,
                FormationError::ExactDerivativesNeedReference {
                    agent: i + 1,
                    leader: j + 1,
                },
            ));
        }
        Ok(AgentSpec {
            name,
            robot,
            leader,
            placement,
            gains: Gains { ke, kz },
            variant,
            start,
        })
    }
}

/// An agent's table over the file's, field by field, remembering where each
/// value came from.
struct Merge<'a, S> {
    own: Option<&'a S>,
    global: Option<&'a S>,
    own_path: FieldPath,
    global_path: FieldPath,
}

impl<'a, S: serde::Serialize> Merge<'a, S> {
    fn new(
        own: Option<&'a S>,
        global: Option<&'a S>,
        own_path: FieldPath,
        global_path: FieldPath,
    ) -> Self {
        Merge {
            own,
            global,
            own_path,
            global_path,
        }
    }

    /// Whether either table exists.
    fn any(&self) -> bool {
        self.own.is_some() || self.global.is_some()
    }

    /// The value of `key` and the path it was set at.
    fn get<T>(&self, get: fn(&S) -> Option<T>, key: &str) -> Option<(T, FieldPath)> {
        if let Some(v) = self.own.and_then(get) {
            return Some((v, self.own_path.key(key)));
        }
        self.global
            .and_then(get)
            .map(|v| (v, self.global_path.key(key)))
    }

    /// [`Merge::get`], else `default` (at the file's path, where it would be set).
    fn get_or<T>(&self, get: fn(&S) -> Option<T>, key: &str, default: T) -> (T, FieldPath) {
        self.get(get, key)
            .unwrap_or_else(|| (default, self.global_path.key(key)))
    }

    /// Where `key` is set: the agent's table if it sets it, else the file's.
    fn path_of(&self, key: &str) -> FieldPath {
        let sets = self
            .own
            .and_then(|s| toml::Table::try_from(s).ok())
            .is_some_and(|t| t.contains_key(key));
        if sets {
            self.own_path.key(key)
        } else {
            self.global_path.key(key)
        }
    }

    /// The table that applies (the agent's if it has one).
    fn table_path(&self) -> FieldPath {
        if self.own.is_some() {
            self.own_path.clone()
        } else {
            self.global_path.clone()
        }
    }
}
