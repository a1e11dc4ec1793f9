//! The parsed document turned into a [`Simulation`]: defaults resolved, each
//! value given to its domain type's validating constructor, and each refusal
//! attached to the field it came from as it happens.

use std::path::{Path, PathBuf};

use super::locate::{FieldPath, Locator};
use super::merge::Merge;
use super::overrides::Overrides;
use super::plausible::{self, Part};
use super::schema::{
    AgentSection, FrameName, LeaderSpec, ModeName, OffsetSpec, ReferenceSection, ScenarioFile,
};
use super::waypoints::{self, ReadError};
use super::{DEFAULT_LOG_DT, Run, Scenario};
use crate::agent::{AgentSpec, Drive};
use crate::check;
use crate::control::{Gains, Law, Variant};
use crate::error::{FormationError, ParamError, ReferenceError, ScenarioError, num};
use crate::formation::Leader;
use crate::guard::Bounds;
use crate::lycomp::{LyComp, LyDerivatives, Placement, PlacementSpec};
use crate::math::whole_ratio;
use crate::plan::{Agents, Plan, SafetySpec, SimConfig, Timing};
use crate::reference::{Circle, Cubic, Lemniscate, Reference, Waypoints};
use crate::safety::{Obstacle, SafetyConfig};

mod odometry;
mod robot;
mod safety;

use robot::Body;

/// `L`, m, when neither the agent nor `[control]` sets it.
const DEFAULT_L: f64 = 0.05;

impl Scenario {
    /// Applies the command-line overrides to the document, resolves defaults,
    /// validates every value and resolves the [`Plan`].
    pub fn build(&self, ov: &Overrides) -> Result<Run, ScenarioError> {
        let mut file = self.file.clone();
        let mut flags = self.flags.clone();
        flags.extend(ov.apply(&mut file));
        let builder = Builder {
            file: &file,
            at: Locator::new(&self.source, &self.origin, &flags),
            base_dir: self.base_dir.as_deref(),
            file_step: self.file.sim.dt,
        };
        let (plan, log_every, seed, stiff) = builder.build()?;
        // Each value passed its own rules; now its plausible range.
        let mut warnings = plausible::check(&file, &builder.at, Part::Simulation)?;
        warnings.extend(stiff);
        Ok(Run {
            name: self.name.clone(),
            description: file.description.clone(),
            plan,
            log_every,
            seed,
            warnings,
            record: self.record(ov),
        })
    }
}

/// One build of a document (with the overrides applied).
struct Builder<'a> {
    file: &'a ScenarioFile,
    at: Locator<'a>,
    base_dir: Option<&'a Path>,
    /// `sim.dt` as the scenario gives it, before `--dt`.
    file_step: f64,
}

impl Builder<'_> {
    /// `r`, or its refusal at `path`.
    fn at<T>(&self, path: &FieldPath, r: Result<T, ParamError>) -> Result<T, ScenarioError> {
        r.map_err(|e| self.at.param(path, &e))
    }

    /// `r`, or its refusal at the field it names under `section`.
    fn within<T>(&self, section: &FieldPath, r: Result<T, ParamError>) -> Result<T, ScenarioError> {
        r.map_err(|e| self.at.param(&section.join(e.field), &e))
    }

    /// The value at `path` refused against the step `sim.dt` (`e`): at
    /// `path`, unless the command line set the step and not that value —
    /// then at the step's flag (`--dt`), naming the value and where it is.
    fn against_step(&self, path: &FieldPath, e: &ParamError) -> ScenarioError {
        let step = FieldPath::from("sim.dt");
        if self.at.flag(&step).is_none() || self.at.flag(path).is_some() {
            return self.at.param(path, e);
        }
        self.at.error(
            &step,
            format!(
                "{} s does not fit {path} ({}): {} {}",
                num(self.file.sim.dt),
                self.at.place(path),
                num(e.value),
                e.reason
            ),
        )
    }

    /// The refusal of a logging period `log_dt` that is not a whole multiple
    /// of the step `dt` (both s), at the value to blame: the one the command
    /// line changed (`--dt` when `--log-dt` fits the scenario's own step,
    /// else `--log-dt`), else the file's `log.dt`, naming where the other is.
    fn log_dt_misfit(&self, log_dt: f64, dt: f64) -> ScenarioError {
        let f = self.file;
        let (step, log) = (FieldPath::from("sim.dt"), FieldPath::from("log.dt"));
        let (dt_flag, log_flag) = (self.at.flag(&step), self.at.flag(&log));
        let misfit = |dt: f64| {
            format!(
                "s is not 0 (every step) or a whole multiple of dt = {} s",
                num(dt)
            )
        };
        let (dt_text, log_text) = (num(dt), num(log_dt));
        if f.log.dt.is_none() {
            // The default period is nowhere in the file: the step is.
            return self.at.error(
                &step,
                format!(
                    "{dt_text} s: the default logging period log.dt = {log_text} s is not a whole multiple of it (set [log] dt = 0 to log every step, or a multiple of dt; on the command line: --log-dt)"
                ),
            );
        }
        match (dt_flag, log_flag) {
            // `--dt` alone changed the step the file's log.dt fitted.
            (Some(_), None) => self.at.error(
                &step,
                format!(
                    "{dt_text} s does not fit log.dt ({}): {log_text} {} (change the logging period with --log-dt)",
                    self.at.place(&log),
                    misfit(dt)
                ),
            ),
            // Both flags, and --log-dt fits the scenario's own step: --dt broke it.
            (Some(_), Some(log_flag)) if whole_ratio(log_dt, self.file_step).is_some() => {
                self.at.error(
                    &step,
                    format!(
                        "{dt_text} s does not fit {log_flag} {log_text} s: {log_text} {} ({log_flag} fits the scenario's own dt = {} s)",
                        misfit(dt),
                        num(self.file_step)
                    ),
                )
            }
            (Some(dt_flag), Some(_)) => self.at.param(
                &log,
                &ParamError::new("dt", log_dt, format!("{} ({dt_flag})", misfit(dt))),
            ),
            // The step is the file's: name where it is.
            (None, _) => self.at.param(
                &log,
                &ParamError::new(
                    "dt",
                    log_dt,
                    format!("{} (sim.dt, {})", misfit(dt), self.at.place(&step)),
                ),
            ),
        }
    }

    /// The plan, the logging interval in steps, the seed and the
    /// warnings about gains the step cannot resolve.
    fn build(&self) -> Result<(Plan, u64, u64, Vec<String>), ScenarioError> {
        let f = self.file;
        let sim = FieldPath::from("sim");
        let timing = match f.sim.controller_period {
            None => Timing::Continuous,
            Some(period) => Timing::Sampled { period },
        };
        // `duration` (its number of steps) and `controller_period` are
        // checked against the step.
        let mut config =
            SimConfig::new(f.sim.dt, f.sim.duration, timing).map_err(|e| match e.field {
                "dt" => self.at.param(&sim.key("dt"), &e),
                field => self.against_step(&sim.key(field), &e),
            })?;
        if let Some(b) = f.sim.bounds {
            let d = Bounds::DEFAULT;
            let bounds = Bounds::new(
                b.speed.unwrap_or(d.speed),
                b.turn_rate.unwrap_or(d.turn_rate),
                b.distance.unwrap_or(d.distance),
            );
            config = config.with_bounds(self.within(&sim.key("bounds"), bounds)?);
        }
        let dt = config.dt;
        let log = FieldPath::from("log.dt");
        let log_dt = self.at(
            &log,
            check::non_negative("dt", f.log.dt.unwrap_or(DEFAULT_LOG_DT)),
        )?;
        let log_every = if log_dt == 0.0 {
            1
        } else {
            whole_ratio(log_dt, dt).ok_or_else(|| self.log_dt_misfit(log_dt, dt))?
        };
        let reference = self.reference()?;
        let specs = f
            .agents
            .iter()
            .enumerate()
            .map(|(i, a)| self.agent(i, a, dt))
            .collect::<Result<Vec<_>, _>>()?;
        if specs.is_empty() {
            return Err(self.at.error(
                &FieldPath::from("agents"),
                "a scenario needs at least one agent",
            ));
        }
        let stiff = self.stiff_gains(&specs, &timing, dt);
        let agents = Agents::new(specs).map_err(|e| self.formation_error(&e))?;
        let odometry = f
            .agents
            .iter()
            .enumerate()
            .map(|(i, a)| self.odometry(i, a, dt, &timing))
            .collect::<Result<Vec<_>, _>>()?;
        let seed = f.seed.unwrap_or(0);
        let safety = self.safety(&agents)?;
        agents
            .behind(&reference)
            .map_err(|e| self.formation_error(&e))?;
        let plan = Plan::of(agents, reference, config)
            .with_odometry(odometry, seed)
            .map_err(|e| self.at.error(&FieldPath::from("odometry"), e))?;
        let plan = match safety {
            None => plan,
            Some(spec) => plan
                .with_safety(spec)
                .map_err(|e| self.at.error(&FieldPath::from("safety"), e))?,
        };
        Ok((plan, log_every, seed, stiff))
    }

    /// A warning for each agent whose gain `K` makes `K h > 2`, `h` the
    /// controller's period (`dt` for a continuous one): the error then decays
    /// faster than the step can follow (`1 − K h < −1` for a held command, and
    /// RK4 is stable on `ė = −K e` only up to `K h ≈ 2.8`), and the run
    /// oscillates and diverges. Allowed: a run may be meant to diverge.
    fn stiff_gains(&self, specs: &[AgentSpec], timing: &Timing, dt: f64) -> Vec<String> {
        let h = match timing {
            Timing::Sampled { period } => *period,
            Timing::Continuous => dt,
        };
        let step = match timing {
            Timing::Sampled { .. } => "controller_period",
            Timing::Continuous => "dt",
        };
        let mut warnings = Vec::new();
        for (i, a) in specs.iter().enumerate() {
            let mut gains = vec![("ke", "K_e", a.gains().ke())];
            if a.law() != Law::Kinematic {
                gains.push(("kz", "K_z", a.gains().kz()));
            }
            let Some((key, symbol, k)) = gains
                .into_iter()
                .filter(|(_, _, k)| k * h > 2.0)
                .max_by(|a, b| a.2.total_cmp(&b.2))
            else {
                continue;
            };
            let e = self.at.error(
                &self.control(i).path_of(key),
                format!(
                    "agent {}: {symbol} {step} = {} > 2: the step {} s cannot follow the time scale 1/{symbol} = {} s and the run will oscillate and diverge (use {step} < {} s)",
                    i + 1,
                    num(k * h),
                    num(h),
                    num(1.0 / k),
                    num(2.0 / k),
                ),
            );
            warnings.push(e.to_string());
        }
        warnings
    }

    /// Where a formation-level refusal belongs: the leader that breaks the
    /// graph, or the setting that needs an analytic reference.
    fn formation_error(&self, e: &FormationError) -> ScenarioError {
        let agent = |k: usize| FieldPath::from("agents").index(k - 1);
        let path = match e {
            FormationError::Cycle(c) => agent(c[0]).key("leader"),
            FormationError::Dangling { agent: a, .. } | FormationError::SelfLeader(a) => {
                agent(*a).key("leader")
            }
            FormationError::ExactDerivativesNeedReference { agent: a, .. } => {
                self.control(*a - 1).path_of("ly_derivatives")
            }
            FormationError::NoLeaderAcceleration { agent: a, .. } => agent(*a).key("leader"),
            FormationError::LeaderFrameNeedsHeading { agent: a } => {
                agent(*a).key("offset").key("frame")
            }
        };
        self.at.error(&path, e)
    }

    /// Agent `i`'s control settings: its own, else `[control]`.
    fn control(&self, i: usize) -> Merge<'_, super::schema::ControlSection> {
        Merge::new(
            self.file.agents[i].control.as_ref(),
            Some(&self.file.control),
            FieldPath::from("agents").index(i).key("control"),
            FieldPath::from("control"),
        )
    }

    fn reference(&self) -> Result<Reference, ScenarioError> {
        let at = |kind: &str| FieldPath::from("reference").key(kind);
        // A reference's refusal at its field (`start.x`, `points[3]`, …).
        let located = |section: FieldPath, e: ReferenceError| -> ScenarioError {
            match e {
                ReferenceError::Param(p) => self.at.param(&section.join(p.field), &p),
                ReferenceError::TimesNotIncreasing { index, .. }
                | ReferenceError::WaypointsTooClose { index, .. }
                | ReferenceError::WaypointsTooFast { index, .. }
                | ReferenceError::WaypointsOvershoot { index, .. } => {
                    self.at.error(&section.key("points").index(index - 1), e)
                }
                ReferenceError::NonFiniteWaypoint {
                    index, coordinate, ..
                } => self
                    .at
                    .error(&section.key("points").index(index - 1).index(coordinate), e),
                ReferenceError::TooFewWaypoints(_) => self.at.error(&section.key("points"), e),
            }
        };
        Ok(match &self.file.reference {
            ReferenceSection::Circle {
                speed,
                turn_rate,
                start,
            } => {
                let s = self.at.pose(start, &at("circle").key("start"), false)?;
                Reference::Circle(
                    Circle::new([s.x, s.y], s.theta, *speed, *turn_rate)
                        .map_err(|e| located(at("circle"), e))?,
                )
            }
            ReferenceSection::Line { speed, start } => {
                let s = self.at.pose(start, &at("line").key("start"), false)?;
                Reference::Circle(
                    Circle::new([s.x, s.y], s.theta, *speed, 0.0)
                        .map_err(|e| located(at("line"), e))?,
                )
            }
            ReferenceSection::Lemniscate { a, c, center } => Reference::Lemniscate(
                Lemniscate::new(*a, *c, center.unwrap_or([0.0, 0.0]))
                    .map_err(|e| located(at("lemniscate"), e))?,
            ),
            ReferenceSection::Cubic { scale, t_switch } => Reference::Cubic(
                Cubic::new(*scale, *t_switch).map_err(|e| located(at("cubic"), e))?,
            ),
            ReferenceSection::Waypoints { points, file } => {
                let at = at("waypoints");
                let path = match (points, file) {
                    (Some(p), None) => {
                        Waypoints::new(p.clone()).map_err(|e| located(at.clone(), e))?
                    }
                    // The CSV file's refusals are at its rows.
                    (None, Some(f)) => {
                        let table = self.waypoint_file(f, &at.key("file"))?;
                        Waypoints::new(table.points.clone()).map_err(|e| table.error(&e))?
                    }
                    (Some(_), Some(_)) => {
                        return Err(self
                            .at
                            .error(&at.key("file"), "give either points or file, not both"));
                    }
                    (None, None) => {
                        return Err(self.at.error(&at, "missing field `points` (or `file`)"));
                    }
                };
                Reference::Waypoints(path)
            }
        })
    }

    /// Reads `t,x,y` rows from a CSV file next to the scenario.
    fn waypoint_file(
        &self,
        name: &str,
        path: &FieldPath,
    ) -> Result<waypoints::Table, ScenarioError> {
        let full = match self.base_dir {
            Some(d) => d.join(name),
            None => PathBuf::from(name),
        };
        waypoints::read(&full).map_err(|e| match e {
            ReadError::Unreadable(message) => self.at.error(path, message),
            ReadError::Csv(e) => e,
        })
    }

    /// Agent `i`'s drive: its robot `robot` (named `robot_name`) under the
    /// control law `law` (unset: the robot's default), checked against the
    /// step `dt` for a velocity base.
    fn drive(
        &self,
        i: usize,
        at: &FieldPath,
        robot_name: &str,
        robot: Body,
        law: Option<(Law, FieldPath)>,
        dt: f64,
    ) -> Result<Drive, ScenarioError> {
        Ok(match (robot, law) {
            (Body::Torque(robot), None) => Drive::Torque {
                robot,
                variant: Variant::Paper,
            },
            (Body::Velocity(r), None | Some((Law::Kinematic, _))) => {
                // Where the robot is defined: its section, else the agent's `robot`.
                let path = if self.file.robots.contains_key(robot_name) {
                    FieldPath::from("robots").key(robot_name)
                } else {
                    at.key("robot")
                };
                r.base()
                    .check_step(dt)
                    .map_err(|e| self.against_step(&path.join(e.field), &e))?;
                Drive::Velocity(r)
            }
            (Body::Torque(robot), Some((law, path))) => match law.variant() {
                Some(variant) => Drive::Torque { robot, variant },
                None => {
                    return Err(self.at.error(
                        &path,
                        format!(
                            "law = \"kinematic\" commands velocities, but agent {}'s robot `{robot_name}` is torque-driven (use a robot with drive = \"velocity\", or law = \"paper\" / \"complete\")",
                            i + 1
                        ),
                    ));
                }
            },
            (Body::Velocity(_), Some((law, path))) => {
                return Err(self.at.error(
                    &path,
                    format!(
                        "law = \"{}\" commands wheel torques, but agent {}'s robot `{robot_name}` is a velocity base (use law = \"kinematic\", its default)",
                        law.name(),
                        i + 1
                    ),
                ));
            }
        })
    }

    fn agent(&self, i: usize, a: &AgentSection, dt: f64) -> Result<AgentSpec, ScenarioError> {
        let at = FieldPath::from("agents").index(i);
        let n = self.file.agents.len();
        let name = a.name.clone().unwrap_or_else(|| format!("agent {}", i + 1));
        let robot_name = a.robot.as_deref().unwrap_or("agent1");
        let robot = self.robot(robot_name, &at.key("robot"))?;
        let start = self.at.pose(&a.start, &at.key("start"), true)?;
        let leader = match a.leader {
            LeaderSpec::Reference => Leader::Reference,
            LeaderSpec::Agent(k) if k >= 1 && (k as usize) <= n => Leader::Agent(k as usize - 1),
            LeaderSpec::Agent(k) => {
                return Err(self.at.error(
                    &at.key("leader"),
                    format!(
                        "agent {} follows agent {k}, which does not exist (agents are numbered 1..={n}, or \"reference\")",
                        i + 1
                    ),
                ));
            }
        };
        // Each control setting: the agent's own, else [control], else the paper's.
        let control = self.control(i);
        let (ke, _) = control.get_or(|c| c.ke, "ke", Gains::PAPER.ke());
        let (kz, _) = control.get_or(|c| c.kz, "kz", Gains::PAPER.kz());
        let gains = Gains::new(ke, kz).map_err(|e| self.at.param(&control.path_of(e.field), &e))?;
        let (l, l_path) = control.get_or(|c| c.l, "l", DEFAULT_L);
        self.at(&l_path, check::positive("l", l))?;
        let law = control.get(|c| c.law, "law");
        let drive = self.drive(i, &at, robot_name, robot, law, dt)?;
        let (comp, _) = control.get_or(|c| c.lycomp, "lycomp", LyComp::Fit);
        let (derivatives, _) = control.get_or(
            |c| c.ly_derivatives,
            "ly_derivatives",
            LyDerivatives::Neglect,
        );
        let placement = match (a.mode.unwrap_or(ModeName::Formation), a.offset) {
            (ModeName::Tracking, None) => Placement::tracking(l),
            (ModeName::Tracking, Some(_)) => {
                return Err(self.at.error(
                    &at.key("offset"),
                    "pure tracking (mode = \"tracking\") takes no offset: the point L ahead of the robot tracks the leader",
                ));
            }
            (ModeName::Formation, None) => {
                return Err(self.at.error(
                    &at,
                    "missing field `offset` = { x = L_Xoff, y = L_Yoff } (or mode = \"tracking\")",
                ));
            }
            (
                ModeName::Formation,
                Some(
                    o @ OffsetSpec {
                        frame: Some(FrameName::Leader),
                        ..
                    },
                ),
            ) => Placement::leader_frame(o.x, o.y, l),
            (ModeName::Formation, Some(o)) => Placement::new(PlacementSpec {
                lx_off: o.x,
                ly_off: o.y,
                l,
                comp,
                derivatives,
            }),
        };
        let placement = self.within(&at, placement)?;
        let spec = match drive {
            Drive::Torque { robot, variant } => {
                AgentSpec::new(name, robot, leader, placement, gains, variant, start)
            }
            Drive::Velocity(r) => AgentSpec::velocity(name, r, leader, placement, gains, start),
        };
        let spec = spec.and_then(|s| s.with_max_accel(a.max_accel));
        self.within(&at, spec)
    }
}
