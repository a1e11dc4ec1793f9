//! Run outputs: `trajectory.csv`, `reference.csv`, `summary.json` and `scenario.toml`.
//!
//! Numbers are written in their shortest round-trip form (the same bits read
//! back), so the same run gives the same bytes.

use std::io::{self, Write};

use serde::Serialize;

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use crate::agent::AgentSpec;
use crate::csv::CsvWriter;
use crate::error::{OutputError, SimError};
use crate::model::wrap_angle;
use crate::plan::Timing;
use crate::reference::{Order, Reference, Trajectory};
use crate::safety::Outcome;
use crate::sample::AgentSample;
use crate::scenario::Run;
use crate::sim::{Every, Frame, Observer, ObserverError, Simulation};
use crate::stats::{AgentSummary, Divergence, SafetyReport, SafetyWatch, Summary};

/// The header of `trajectory.csv`: one row per agent per logged sample
/// ([`AgentSample`], its fields [`sample::COLUMNS`](crate::sample::COLUMNS)),
/// SI units, radians, `e` and `z` in the follower's body frame, agents
/// numbered from 1.
pub const TRAJECTORY_HEADER: &str = "t,agent,x,y,theta,v,omega,ex,ey,zx,zy,u1,u2,tau_r,tau_l";

/// The header of `trajectory.csv` when some agent is on a velocity base:
/// [`TRAJECTORY_HEADER`] and the commanded `(v*, ω*)`, the command after the
/// base's speed limits and whether they cut it (`sat`, 0 or 1): the fields
/// of [`VelocitySample`](crate::sample::VelocitySample). A velocity agent's
/// `u1,u2,tau_r,tau_l` are `NaN`, a torque agent's five new cells too.
pub const TRAJECTORY_HEADER_VELOCITY: &str = "t,agent,x,y,theta,v,omega,ex,ey,zx,zy,u1,u2,tau_r,tau_l,v_cmd,omega_cmd,v_applied,omega_applied,sat";

/// What a [`CsvLog`] writes: a header and, for each frame it is shown, its rows.
pub trait FrameRows {
    /// The header line.
    fn header(&self) -> &'static str;

    /// Called when the run starts (e.g. to take the run's reference).
    fn start(&mut self, _sim: &Simulation) {}

    /// Writes the rows of one frame.
    fn write<W: Write>(&mut self, frame: &Frame<'_>, csv: &mut CsvWriter<W>) -> io::Result<()>;
}

/// `trajectory.csv`: one [`AgentSample`] per agent per frame; with the
/// velocity-base columns when `velocity` ([`TRAJECTORY_HEADER_VELOCITY`]).
/// The simulator and the fleet collector write it alike.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TrajectoryRows {
    /// Whether to write the velocity-base columns.
    pub velocity: bool,
}

impl TrajectoryRows {
    /// The table for `agents`: with the velocity-base columns when some
    /// agent is on a velocity base, else exactly [`TRAJECTORY_HEADER`].
    pub fn for_agents(agents: &[AgentSpec]) -> TrajectoryRows {
        TrajectoryRows {
            velocity: agents.iter().any(|a| a.velocity_robot().is_some()),
        }
    }

    /// Writes one sample's row.
    pub fn row<W: Write>(&self, sample: &AgentSample, csv: &mut CsvWriter<W>) -> io::Result<()> {
        sample.write_csv(csv, self.velocity)
    }
}

impl FrameRows for TrajectoryRows {
    fn header(&self) -> &'static str {
        if self.velocity {
            TRAJECTORY_HEADER_VELOCITY
        } else {
            TRAJECTORY_HEADER
        }
    }

    fn write<W: Write>(&mut self, frame: &Frame<'_>, csv: &mut CsvWriter<W>) -> io::Result<()> {
        for sample in AgentSample::all(frame) {
            self.row(&sample, csv)?;
        }
        Ok(())
    }
}

/// The header of `reference.csv`: the virtual leader `p_d(t)` at the same logged
/// instants as `trajectory.csv`: position, heading `atan2(ẏ_d, ẋ_d)` (0 at
/// standstill), speed `V_d` and turn rate `ω_d`.
pub const REFERENCE_HEADER: &str = "t,x,y,theta,v,omega";

/// `reference.csv`: the run's reference (taken when the run starts) at each frame.
#[derive(Debug, Clone, Default)]
pub struct ReferenceRows {
    reference: Option<Reference>,
}

impl FrameRows for ReferenceRows {
    fn header(&self) -> &'static str {
        REFERENCE_HEADER
    }

    fn start(&mut self, sim: &Simulation) {
        self.reference = Some(sim.reference().clone());
    }

    fn write<W: Write>(&mut self, frame: &Frame<'_>, csv: &mut CsvWriter<W>) -> io::Result<()> {
        let reference = self.reference.as_ref().ok_or_else(|| {
            io::Error::other("reference.csv: shown a frame before the run started")
        })?;
        let jet = reference.eval(frame.t, Order::Two);
        csv.time(frame.t).nums([
            jet.p[0],
            jet.p[1],
            jet.heading(),
            jet.speed(),
            jet.turn_rate(),
        ]);
        csv.end_row()
    }
}

/// The header of `integrals.csv`: per agent, at the same logged instants as
/// `trajectory.csv`, the running integrals since `t = 0` that make a log
/// exact for identification whatever its logging period
/// ([`crate::identify`]): `s = ∫v dt` (m, the true distance travelled),
/// `theta` the true heading not wrapped (`θ(0) + ∫ω dt`, rad), and
/// `int_1, int_2` the integral of the input the plant received: `∫u1 dt`
/// (N s) and `∫u2 dt` (N m s) for a torque robot, `∫v dt` (m) and `∫ω dt`
/// (rad) of the applied command for a velocity base. They are summed with
/// RK4's weights ([`Frame::input_integral`]), so between any two rows of a
/// torque robot `m Δv + η Δs = Δint_1` and `J Δω + ψ Δθ = Δint_2` hold to
/// rounding, however the input varied in between.
pub const INTEGRALS_HEADER: &str = "t,agent,s,theta,int_1,int_2";

/// `integrals.csv`: one row per agent per frame ([`INTEGRALS_HEADER`]).
#[derive(Debug, Clone, Copy, Default)]
pub struct IntegralRows;

impl FrameRows for IntegralRows {
    fn header(&self) -> &'static str {
        INTEGRALS_HEADER
    }

    fn write<W: Write>(&mut self, frame: &Frame<'_>, csv: &mut CsvWriter<W>) -> io::Result<()> {
        for (i, state) in frame.states.iter().enumerate() {
            let s = frame.distance.get(i).copied().unwrap_or(f64::NAN);
            let [i1, i2] = frame
                .input_integral
                .get(i)
                .copied()
                .unwrap_or([f64::NAN; 2]);
            csv.time(frame.t)
                .int(i as u64 + 1)
                .nums([s, state.theta, i1, i2]);
            csv.end_row()?;
        }
        Ok(())
    }
}

/// The header of `odometry.csv`: what each dead-reckoning agent's controller
/// believed — its pose estimate and `ê`, `ẑ` (eqs. 33, 35) — and `fix`, the
/// number of absolute fixes applied since the previous row. Only agents with
/// odometry have rows.
pub const ODOMETRY_HEADER: &str = "t,agent,x_hat,y_hat,theta_hat,ex_hat,ey_hat,zx_hat,zy_hat,fix";

/// `odometry.csv`: one row per dead-reckoning agent per frame.
#[derive(Debug, Clone, Default)]
pub struct OdometryRows {
    fixes: Vec<u64>,
}

impl FrameRows for OdometryRows {
    fn header(&self) -> &'static str {
        ODOMETRY_HEADER
    }

    fn write<W: Write>(&mut self, frame: &Frame<'_>, csv: &mut CsvWriter<W>) -> io::Result<()> {
        self.fixes.resize(frame.odometers.len(), 0);
        for (i, (odometer, o)) in frame.odometers.iter().zip(frame.outputs).enumerate() {
            let Some(odometer) = odometer else { continue };
            let est = odometer.believed(&frame.states[i]);
            let applied = odometer.fixes_applied();
            csv.time(frame.t)
                .int((i + 1) as u64)
                .nums([
                    est.x,
                    est.y,
                    wrap_angle(est.theta),
                    o.e_hat[0],
                    o.e_hat[1],
                    o.z_hat[0],
                    o.z_hat[1],
                ])
                .int(applied - self.fixes[i]);
            self.fixes[i] = applied;
            csv.end_row()?;
        }
        Ok(())
    }
}

/// The header of `safety.csv` (written when a safety filter runs): per
/// filtering agent per logged frame, `outcome` (0 nominal command, 1
/// filtered, 2 braked: the QP was infeasible), `deadlock` (0 or 1: breaking a
/// deadlock), the law's command and the filtered one (`(v, ω)` for a velocity
/// base, `(u1, u2)` for a torque-driven robot), `min_distance`: the true
/// distance from this robot's point `L` ahead to the nearest other robot's
/// point, and `radius`.
pub const SAFETY_HEADER: &str =
    "t,agent,outcome,deadlock,nominal_1,nominal_2,command_1,command_2,min_distance,radius";

/// `safety.csv`: one row per filtering agent per frame.
#[derive(Debug, Clone, Default)]
pub struct SafetyRows {
    l: Vec<f64>,
    radius: f64,
    points: Vec<[f64; 2]>,
}

impl FrameRows for SafetyRows {
    fn header(&self) -> &'static str {
        SAFETY_HEADER
    }

    fn start(&mut self, sim: &Simulation) {
        self.l = sim.agents().iter().map(|a| a.placement.l()).collect();
        self.radius = sim.safety_radius().unwrap_or(f64::NAN);
    }

    fn write<W: Write>(&mut self, frame: &Frame<'_>, csv: &mut CsvWriter<W>) -> io::Result<()> {
        self.points.clear();
        self.points.extend(
            frame
                .states
                .iter()
                .zip(&self.l)
                .map(|(s, &l)| crate::safety::point(s, l)),
        );
        for (i, o) in frame.safety.iter().enumerate() {
            if !o.enabled {
                continue;
            }
            let p = self.points[i];
            let nearest = self
                .points
                .iter()
                .enumerate()
                .filter(|&(j, _)| j != i)
                .map(|(_, q)| (p[0] - q[0]).hypot(p[1] - q[1]))
                .fold(f64::INFINITY, f64::min);
            let outcome = match o.outcome {
                Outcome::Nominal => 0,
                Outcome::Filtered => 1,
                Outcome::Braked => 2,
            };
            csv.time(frame.t)
                .int((i + 1) as u64)
                .int(outcome)
                .int(u64::from(o.deadlock))
                .nums(o.nominal)
                .nums(o.filtered)
                .opt(nearest.is_finite().then_some(nearest))
                .num(self.radius);
            csv.end_row()?;
        }
        Ok(())
    }
}

/// An [`Observer`] writing a CSV log of the frames it is shown (attach it
/// with [`Every`](crate::sim::Every) for a logging period): the header when
/// created, [`FrameRows`] for each frame, a flush when the run finishes.
#[derive(Debug)]
pub struct CsvLog<W: Write, R> {
    csv: CsvWriter<W>,
    table: R,
    path: Option<PathBuf>,
}

/// The `trajectory.csv` log.
pub type TrajectoryCsv<W> = CsvLog<W, TrajectoryRows>;
/// The `reference.csv` log.
pub type ReferenceCsv<W> = CsvLog<W, ReferenceRows>;
/// The `odometry.csv` log.
pub type OdometryCsv<W> = CsvLog<W, OdometryRows>;

impl<W: Write, R: FrameRows> CsvLog<W, R> {
    /// Writes the header of `table` to `out`.
    pub fn new(out: W, table: R) -> io::Result<Self> {
        Ok(CsvLog {
            csv: CsvWriter::new(out, table.header())?,
            table,
            path: None,
        })
    }

    /// Number of data rows written.
    pub fn rows(&self) -> u64 {
        self.csv.rows()
    }

    /// Flushes and returns the writer.
    pub fn into_inner(self) -> io::Result<W> {
        self.csv.into_inner()
    }

    fn failed(&self, source: io::Error) -> ObserverError {
        match &self.path {
            Some(path) => Box::new(OutputError::Io {
                path: path.clone(),
                source,
            }),
            None => Box::new(source),
        }
    }
}

impl<R: FrameRows> CsvLog<BufWriter<File>, R> {
    /// Creates (truncates) the file `path`, named in every error, and writes the header.
    pub fn create(path: &Path, table: R) -> Result<Self, OutputError> {
        let file = File::create(path).map_err(io_error(path))?;
        let mut log =
            CsvLog::new(BufWriter::with_capacity(1 << 16, file), table).map_err(io_error(path))?;
        log.path = Some(path.to_path_buf());
        Ok(log)
    }
}

impl<W: Write, R: FrameRows> Observer for CsvLog<W, R> {
    fn start(&mut self, sim: &Simulation) -> Result<(), ObserverError> {
        self.table.start(sim);
        Ok(())
    }

    fn observe(&mut self, frame: &Frame<'_>) -> Result<(), ObserverError> {
        self.table
            .write(frame, &mut self.csv)
            .map_err(|e| self.failed(e))
    }

    fn finish(&mut self) -> Result<(), ObserverError> {
        self.csv.flush().map_err(|e| self.failed(e))
    }
}

/// A CSV of numbers with a header line, as echelon writes them.
#[derive(Debug, Clone, PartialEq)]
pub struct Table {
    /// Column names.
    pub header: Vec<String>,
    /// Rows of numbers, one per line after the header.
    pub rows: Vec<Vec<f64>>,
}

impl Table {
    /// Reads a numeric CSV; every error names the file and line.
    pub fn read(path: &Path) -> Result<Table, OutputError> {
        let text = std::fs::read_to_string(path).map_err(io_error(path))?;
        Table::parse(path, &text)
    }

    /// Parses the text of the numeric CSV `path` (named in errors): a header
    /// line, then rows of numbers with as many cells; blank lines are skipped
    /// and cells trimmed.
    pub fn parse(path: &Path, text: &str) -> Result<Table, OutputError> {
        let parse = |line: usize, message: String| OutputError::Parse {
            path: path.to_path_buf(),
            line,
            message,
        };
        // The line of a record from its byte offset: the reader's own line
        // count leaves out the empty lines it skips, and its offset is where
        // they begin.
        let line_at = |pos: Option<&csv::Position>| {
            pos.map_or(0, |p| {
                let bytes = text.as_bytes();
                let mut end = (p.byte() as usize).min(bytes.len());
                while end < bytes.len() && matches!(bytes[end], b'\n' | b'\r') {
                    end += 1;
                }
                1 + bytes[..end].iter().filter(|&&b| b == b'\n').count()
            })
        };
        let line_of = |e: &csv::Error| line_at(e.position());
        let mut reader = csv::ReaderBuilder::new()
            .trim(csv::Trim::All)
            .flexible(true)
            .from_reader(text.as_bytes());
        let header: Vec<String> = reader
            .headers()
            .map_err(|e| parse(line_of(&e), e.to_string()))?
            .iter()
            .map(str::to_owned)
            .collect();
        if header.is_empty() {
            return Err(parse(1, "empty file: expected a header".into()));
        }
        let mut rows = Vec::new();
        for record in reader.records() {
            let record = record.map_err(|e| parse(line_of(&e), e.to_string()))?;
            if record.iter().all(str::is_empty) {
                continue;
            }
            let line = || line_at(record.position());
            let row = record
                .iter()
                .map(str::parse::<f64>)
                .collect::<Result<Vec<f64>, _>>()
                .map_err(|e| parse(line(), format!("not a number: {e}")))?;
            if row.len() != header.len() {
                return Err(parse(
                    line(),
                    format!(
                        "{} columns where the header has {}",
                        row.len(),
                        header.len()
                    ),
                ));
            }
            rows.push(row);
        }
        Ok(Table { header, rows })
    }

    /// Checks that the header is exactly `expected` (a file echelon wrote).
    pub fn expect_header(&self, path: &Path, expected: &str) -> Result<(), OutputError> {
        let found = self.header.join(",");
        if found == expected {
            Ok(())
        } else {
            Err(OutputError::Parse {
                path: path.to_path_buf(),
                line: 1,
                message: format!("expected the header `{expected}`, found `{found}`"),
            })
        }
    }

    /// The index of column `name`, or an error naming the file.
    pub fn column(&self, name: &str, path: &Path) -> Result<usize, OutputError> {
        self.header
            .iter()
            .position(|h| h == name)
            .ok_or_else(|| OutputError::Parse {
                path: path.to_path_buf(),
                line: 1,
                message: format!("no column `{name}` (found: {})", self.header.join(",")),
            })
    }
}

/// Everything `summary.json` holds.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RunSummary {
    /// Scenario name.
    pub scenario: String,
    /// Simulated time, s.
    pub duration: f64,
    /// RK4 step, s.
    pub dt: f64,
    /// Number of steps.
    pub steps: u64,
    /// Controller sampling period, s (`None`: continuous-time).
    pub controller_period: Option<f64>,
    /// Tolerance on ‖e‖ for `settle_time`, m.
    pub settle_tolerance: f64,
    /// Warnings raised when the scenario was built.
    pub warnings: Vec<String>,
    /// Per-agent results.
    pub agents: Vec<AgentSummary>,
    /// The safety filter's statistics (absent without `[safety]`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub safety: Option<SafetyReport>,
    /// Present when the run diverged: it stopped there, and `agents` hold
    /// statistics up to the last state within bounds, not results.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub diverged: Option<Divergence>,
}

/// The files a run writes into its output directory.
pub const TRAJECTORY_FILE: &str = "trajectory.csv";
/// See [`TRAJECTORY_FILE`].
pub const SUMMARY_FILE: &str = "summary.json";
/// See [`TRAJECTORY_FILE`]; header [`REFERENCE_HEADER`].
pub const REFERENCE_FILE: &str = "reference.csv";
/// See [`TRAJECTORY_FILE`]: the scenario source as run ([`Run::record`]).
pub const SCENARIO_FILE: &str = "scenario.toml";
/// See [`TRAJECTORY_FILE`]; header [`INTEGRALS_HEADER`].
pub const INTEGRALS_FILE: &str = "integrals.csv";
/// Written when any agent dead-reckons; see [`ODOMETRY_HEADER`].
pub const ODOMETRY_FILE: &str = "odometry.csv";
/// Written when a safety filter runs; see [`SAFETY_HEADER`].
pub const SAFETY_FILE: &str = "safety.csv";

fn io_error(path: &Path) -> impl FnOnce(io::Error) -> OutputError + '_ {
    move |source| OutputError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Where a file is written before it is renamed to `path` when complete
/// (`dir/.name.part`), so that a reader never sees half a file.
pub fn part_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map_or_else(|| "out".into(), |n| n.to_string_lossy().into_owned());
    path.with_file_name(format!(".{name}.part"))
}

/// Runs `run` to its end, writing `dir/trajectory.csv`, `dir/reference.csv`,
/// `dir/integrals.csv`, `dir/summary.json` and `dir/scenario.toml`; `extra` sees every frame too
/// (e.g. a progress bar). Files are written under temporary names and renamed
/// only when the run succeeds, so a failed run leaves no half-written output.
pub fn run_to_dir(
    run: &mut Run,
    dir: &Path,
    extra: &mut dyn Observer,
) -> Result<RunSummary, OutputError> {
    std::fs::create_dir_all(dir).map_err(io_error(dir))?;
    let mut simulation = run.simulation();
    let mut names = vec![
        TRAJECTORY_FILE,
        REFERENCE_FILE,
        SUMMARY_FILE,
        SCENARIO_FILE,
        INTEGRALS_FILE,
    ];
    let odometry_at = (!simulation.odometers().is_empty()).then(|| {
        names.push(ODOMETRY_FILE);
        names.len() - 1
    });
    let safety_at = simulation.has_safety().then(|| {
        names.push(SAFETY_FILE);
        names.len() - 1
    });
    let parts: Vec<PathBuf> = names.iter().map(|n| part_path(&dir.join(n))).collect();
    let (summary_part, scenario_part) = (&parts[2], &parts[3]);
    let remove_parts = || {
        for p in &parts {
            let _ = std::fs::remove_file(p);
        }
    };
    let mut trajectory =
        CsvLog::create(&parts[0], TrajectoryRows::for_agents(simulation.agents()))?;
    let mut reference = CsvLog::create(&parts[1], ReferenceRows::default())?;
    let mut integrals = CsvLog::create(&parts[4], IntegralRows)?;
    let mut odometry = match odometry_at {
        Some(k) => Some(CsvLog::create(&parts[k], OdometryRows::default())?),
        None => None,
    };
    let mut safety = match safety_at {
        Some(k) => Some(CsvLog::create(&parts[k], SafetyRows::default())?),
        None => None,
    };
    let mut summary = Summary::new(simulation.agents().len(), Summary::SETTLE_TOLERANCE);
    let mut watch = SafetyWatch::default();
    let sim = &mut simulation;
    let mut logs = Every::new(
        run.log_every,
        [
            &mut trajectory as &mut dyn Observer,
            &mut reference,
            &mut integrals,
            &mut odometry,
            &mut safety,
        ],
    );
    let result = sim.run(&mut [
        &mut logs as &mut dyn Observer,
        &mut summary,
        &mut watch,
        extra,
    ]);
    // A diverged run keeps what it wrote up to its last state within bounds
    // (the observers were not finished: flush them here), and says so.
    let diverged = match result {
        Ok(()) => None,
        Err(e) => match Divergence::of(&e) {
            Some(d) => {
                if let Err(f) = logs.finish() {
                    remove_parts();
                    return Err(SimError::Observer(f.to_string()).into());
                }
                Some((d, e))
            }
            None => {
                remove_parts();
                return Err(e.into());
            }
        },
    };
    let config = *sim.config();
    let report = RunSummary {
        scenario: run.name.clone(),
        duration: sim.time(),
        dt: config.dt,
        steps: sim.steps(),
        controller_period: match config.timing {
            Timing::Continuous => None,
            Timing::Sampled { period } => Some(period),
        },
        settle_tolerance: Summary::SETTLE_TOLERANCE,
        warnings: run.warnings.iter().chain(sim.warnings()).cloned().collect(),
        agents: summary.agents(sim.agents()),
        safety: watch.report().cloned(),
        diverged: diverged.as_ref().map(|(d, _)| d.clone()),
    };
    let mut json = serde_json::to_string_pretty(&report).map_err(|e| OutputError::Io {
        path: summary_part.clone(),
        source: e.into(),
    })?;
    json.push('\n');
    std::fs::write(summary_part, json).map_err(io_error(summary_part))?;
    std::fs::write(scenario_part, &run.record).map_err(io_error(scenario_part))?;
    for (from, to) in parts.iter().zip(&names) {
        let to = dir.join(to);
        std::fs::rename(from, &to).map_err(io_error(&to))?;
    }
    match diverged {
        None => Ok(report),
        Some((_, error)) => Err(OutputError::Diverged {
            error,
            until: sim.time() - config.dt,
            dir: dir.to_path_buf(),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::csv::{push_f64, push_time};

    #[test]
    fn times_are_written_without_noise() {
        for (t, want) in [
            (0.0, "0"),
            (3.0 * 0.01, "0.03"),
            (62.832, "62.832"),
            (1.0, "1"),
            (1e-4 * 7.0, "0.0007"),
        ] {
            let mut s = String::new();
            push_time(&mut s, t);
            assert_eq!(s, want);
        }
    }

    #[test]
    fn tables_parse_and_errors_name_the_line() {
        let path = Path::new("t.csv");
        let t = Table::parse(path, "t, x\n0,1.5\n\n  \n0.5 , -2e-3\n").unwrap();
        assert_eq!(t.header, ["t", "x"]);
        assert_eq!(t.rows, [vec![0.0, 1.5], vec![0.5, -2e-3]]);
        let err = |text: &str| Table::parse(path, text).unwrap_err().to_string();
        assert_eq!(err(""), "t.csv:1: empty file: expected a header");
        let e = err("t,x\n0,1\n0,nope\n");
        assert!(e.starts_with("t.csv:3: not a number"), "{e}");
        assert_eq!(
            err("t,x\n0,1\n\n1\n"),
            "t.csv:4: 1 columns where the header has 2"
        );
    }

    /// What the CSV writer writes for each kind of cell.
    #[test]
    fn the_csv_writer_writes_each_cell_kind() {
        let mut csv = CsvWriter::new(Vec::new(), "a,b,c,d,e,f").unwrap();
        csv.time(0.030000000000000002)
            .int(7)
            .num(0.1)
            .opt(None)
            .text("wheels")
            .opt(Some(-1.0));
        csv.end_row().unwrap();
        csv.opt(None).nums([1.0, 2.5]);
        csv.end_row().unwrap();
        assert_eq!(csv.rows(), 2);
        let text = String::from_utf8(csv.into_inner().unwrap()).unwrap();
        assert_eq!(text, "a,b,c,d,e,f\n0.03,7,0.1,,wheels,-1.0\n,1.0,2.5\n");
    }

    #[test]
    fn floats_round_trip() {
        let mut buf = ryu::Buffer::new();
        for v in [0.1, -1.0 / 3.0, 1e-20, 123456.789, 0.0] {
            let mut s = String::new();
            push_f64(&mut s, v, &mut buf);
            assert_eq!(s.parse::<f64>().unwrap(), v);
        }
    }
}
