//! Run outputs: `trajectory.csv`, `reference.csv`, `summary.json` and `scenario.toml`.
//!
//! Numbers are written in their shortest round-trip form (the same bits read
//! back), so the same run gives the same bytes.

use std::io::{self, Write};

use serde::Serialize;

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use crate::csv::CsvWriter;
use crate::error::{OutputError, SimError};
use crate::plan::Timing;
use crate::scenario::Run;
use crate::sim::{Every, Frame, Observer, ObserverError, Simulation};
use crate::stats::{AgentSummary, Divergence, SafetyReport, SafetyWatch, Summary};

mod rows;
mod table;
pub use rows::{
    FrameRows, INTEGRALS_HEADER, IntegralRows, ODOMETRY_HEADER, OdometryRows, REFERENCE_HEADER,
    ReferenceRows, SAFETY_HEADER, SafetyRows, TRAJECTORY_HEADER, TRAJECTORY_HEADER_VELOCITY,
    TrajectoryRows,
};
pub use table::Table;

/// An [`Observer`] writing a CSV log of the frames it is shown (attach it
/// with [`crate::sim::Every`] for a logging period): the header when
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

/// Everything `summary.json` holds: written by [`run_to_dir`], read back by
/// the report (`echelon-report`) as the same type.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
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
    #[serde(default)]
    pub controller_period: Option<f64>,
    /// Tolerance on ‖e‖ for `settle_time`, m.
    pub settle_tolerance: f64,
    /// Warnings raised when the scenario was built.
    #[serde(default)]
    pub warnings: Vec<String>,
    /// Per-agent results.
    pub agents: Vec<AgentSummary>,
    /// The safety filter's statistics (absent without `[safety]`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub safety: Option<SafetyReport>,
    /// Present when the run diverged: it stopped there, and `agents` hold
    /// statistics up to the last state within bounds, not results.
    #[serde(default, skip_serializing_if = "Option::is_none")]
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

/// Removes the file `path` if there is one.
pub fn remove_if_present(path: &Path) -> Result<(), OutputError> {
    match std::fs::remove_file(path) {
        Err(e) if e.kind() != io::ErrorKind::NotFound => Err(io_error(path)(e)),
        _ => Ok(()),
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

/// The files a run writes (`odometry.csv` and `safety.csv` only when the
/// simulation has odometers or a safety filter), with the indices of those two.
fn output_names(simulation: &Simulation) -> (Vec<&'static str>, Option<usize>, Option<usize>) {
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
    (names, odometry_at, safety_at)
}

/// The summary of `sim` run to its end (or to its divergence, `diverged`).
fn run_summary(
    run: &Run,
    sim: &Simulation,
    summary: &Summary,
    watch: &SafetyWatch,
    diverged: Option<Divergence>,
) -> RunSummary {
    let config = *sim.config();
    RunSummary {
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
        diverged,
    }
}

/// Writes the summary `report` and the scenario `record` to their parts and
/// renames every part (`parts`, of the files `names`) into `dir`; removes the
/// logs of an earlier run that this one does not write.
fn commit(
    dir: &Path,
    parts: &[PathBuf],
    names: &[&str],
    report: &RunSummary,
    record: &str,
) -> Result<(), OutputError> {
    let (summary_part, scenario_part) = (&parts[2], &parts[3]);
    let mut json = serde_json::to_string_pretty(report).map_err(|e| OutputError::Io {
        path: summary_part.clone(),
        source: e.into(),
    })?;
    json.push('\n');
    std::fs::write(summary_part, json).map_err(io_error(summary_part))?;
    std::fs::write(scenario_part, record).map_err(io_error(scenario_part))?;
    for (from, to) in parts.iter().zip(names) {
        let to = dir.join(to);
        std::fs::rename(from, &to).map_err(io_error(&to))?;
    }
    // A log this run does not write, left by an earlier run into the same
    // directory, would be read as this run's (`echelon plot`, `identify`).
    for stale in [ODOMETRY_FILE, SAFETY_FILE] {
        if !names.contains(&stale) {
            remove_if_present(&dir.join(stale))?;
        }
    }
    Ok(())
}

/// Runs `run` to its end, writing `dir/trajectory.csv`, `dir/reference.csv`,
/// `dir/integrals.csv`, `dir/summary.json` and `dir/scenario.toml`; `extra` sees every frame too
/// (e.g. a progress bar). Files are written under temporary names and renamed
/// only when the run succeeds, so a failed run leaves no half-written output;
/// an `odometry.csv` or `safety.csv` of an earlier run that this one does not
/// write is removed.
pub fn run_to_dir(
    run: &mut Run,
    dir: &Path,
    extra: &mut dyn Observer,
) -> Result<RunSummary, OutputError> {
    std::fs::create_dir_all(dir).map_err(io_error(dir))?;
    let mut simulation = run.simulation();
    let (names, odometry_at, safety_at) = output_names(&simulation);
    let parts: Vec<PathBuf> = names.iter().map(|n| part_path(&dir.join(n))).collect();
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
    let report = run_summary(
        run,
        sim,
        &summary,
        &watch,
        diverged.as_ref().map(|(d, _)| d.clone()),
    );
    commit(dir, &parts, &names, &report, &run.record)?;
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
