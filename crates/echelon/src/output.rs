//! Run outputs: `trajectory.csv`, `reference.csv`, `summary.json` and `scenario.toml`.
//!
//! Numbers are written in their shortest round-trip form (the same bits read
//! back), so the same run gives the same bytes.

use std::fmt::Write as _;
use std::io::{self, Write};

use serde::Serialize;

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use crate::error::OutputError;
use crate::model::{State, wrap_angle};
use crate::reference::{Order, Reference, Trajectory};
use crate::scenario::Run;
use crate::sim::{AgentOutput, AgentSummary, Frame, Observer, ObserverError, Summary, Timing};

/// The header of `trajectory.csv`: one row per agent per logged sample, SI units,
/// radians, `e` and `z` in the follower's body frame, agents numbered from 1.
pub const TRAJECTORY_HEADER: &str = "t,agent,x,y,theta,v,omega,ex,ey,zx,zy,u1,u2,tau_r,tau_l";

/// Writes a time to at most nanosecond resolution without float noise
/// (`0.03`, not `0.030000000000000002`).
pub fn push_time(line: &mut String, t: f64) {
    let start = line.len();
    let _ = write!(line, "{t:.9}");
    if line[start..].contains('.') {
        while line.ends_with('0') {
            line.pop();
        }
        if line.ends_with('.') {
            line.pop();
        }
    }
    if &line[start..] == "-0" {
        line.truncate(start);
        line.push('0');
    }
}

/// Writes a float in shortest round-trip form.
#[inline]
pub fn push_f64(line: &mut String, v: f64, buf: &mut ryu::Buffer) {
    if v.is_finite() {
        line.push_str(buf.format_finite(v));
    } else {
        line.push_str(buf.format(v));
    }
}

/// One row of `trajectory.csv`, as [`TrajectoryCsv`] and the fleet's data
/// collector write it.
#[derive(Debug, Clone, Copy)]
pub struct TrajectoryRow<'a> {
    /// Time, s.
    pub t: f64,
    /// Agent number, from 1.
    pub agent: usize,
    /// True state; the heading is written wrapped to `(−π, π]`.
    pub state: &'a State,
    /// `e`, `z` of the true state, the inputs the plant received and the
    /// wheel torques.
    pub output: &'a AgentOutput,
}

impl TrajectoryRow<'_> {
    /// Appends the row, the columns of [`TRAJECTORY_HEADER`] and a newline.
    pub fn push(&self, line: &mut String, buf: &mut ryu::Buffer) {
        let (s, o) = (self.state, self.output);
        push_time(line, self.t);
        let _ = write!(line, ",{}", self.agent);
        for v in [
            s.x,
            s.y,
            wrap_angle(s.theta),
            s.v,
            s.omega,
            o.e[0],
            o.e[1],
            o.z[0],
            o.z[1],
            o.u.u1,
            o.u.u2,
            o.tau.right,
            o.tau.left,
        ] {
            line.push(',');
            push_f64(line, v, buf);
        }
        line.push('\n');
    }
}

/// Streams `trajectory.csv` rows, every `every`-th step and the last one.
#[derive(Debug)]
pub struct TrajectoryCsv<W: Write> {
    out: W,
    every: u64,
    line: String,
    rows: u64,
}

impl<W: Write> TrajectoryCsv<W> {
    /// Writes the header; then logs every `every`-th step (1: every step).
    pub fn new(mut out: W, every: u64) -> io::Result<Self> {
        writeln!(out, "{TRAJECTORY_HEADER}")?;
        Ok(TrajectoryCsv {
            out,
            every,
            line: String::with_capacity(512),
            rows: 0,
        })
    }

    /// Number of data rows written.
    pub fn rows(&self) -> u64 {
        self.rows
    }

    /// Flushes and returns the writer.
    pub fn finish(mut self) -> io::Result<W> {
        self.out.flush()?;
        Ok(self.out)
    }
}

impl<W: Write> Observer for TrajectoryCsv<W> {
    fn observe(&mut self, frame: &Frame<'_>) -> Result<(), ObserverError> {
        if !frame.is_logged(self.every) {
            return Ok(());
        }
        let mut buf = ryu::Buffer::new();
        for (i, (s, o)) in frame.states.iter().zip(frame.outputs).enumerate() {
            self.line.clear();
            let row = TrajectoryRow {
                t: frame.t,
                agent: i + 1,
                state: s,
                output: o,
            };
            row.push(&mut self.line, &mut buf);
            self.out.write_all(self.line.as_bytes())?;
            self.rows += 1;
        }
        Ok(())
    }
}

/// The header of `reference.csv`: the virtual leader `p_d(t)` at the same logged
/// instants as `trajectory.csv`: position, heading `atan2(ẏ_d, ẋ_d)` (0 at
/// standstill), speed `V_d` and turn rate `ω_d`.
pub const REFERENCE_HEADER: &str = "t,x,y,theta,v,omega";

/// Streams `reference.csv` rows at the same steps as [`TrajectoryCsv`].
#[derive(Debug)]
pub struct ReferenceCsv<W: Write> {
    out: W,
    every: u64,
    reference: Reference,
    line: String,
}

impl<W: Write> ReferenceCsv<W> {
    /// Writes the header; then logs every `every`-th step (1: every step) and the last.
    pub fn new(mut out: W, every: u64, reference: Reference) -> io::Result<Self> {
        writeln!(out, "{REFERENCE_HEADER}")?;
        Ok(ReferenceCsv {
            out,
            every,
            reference,
            line: String::with_capacity(128),
        })
    }

    /// Flushes and returns the writer.
    pub fn finish(mut self) -> io::Result<W> {
        self.out.flush()?;
        Ok(self.out)
    }
}

impl<W: Write> Observer for ReferenceCsv<W> {
    fn observe(&mut self, frame: &Frame<'_>) -> Result<(), ObserverError> {
        if !frame.is_logged(self.every) {
            return Ok(());
        }
        let jet = self.reference.eval(frame.t, Order::Two);
        let mut buf = ryu::Buffer::new();
        let line = &mut self.line;
        line.clear();
        push_time(line, frame.t);
        for v in [
            jet.p[0],
            jet.p[1],
            jet.heading(),
            jet.speed(),
            jet.turn_rate(),
        ] {
            line.push(',');
            push_f64(line, v, &mut buf);
        }
        line.push('\n');
        self.out.write_all(line.as_bytes())?;
        Ok(())
    }
}

/// The header of `odometry.csv`: what each dead-reckoning agent's controller
/// believed — its pose estimate and `ê`, `ẑ` (eqs. 33, 35) — and `fix`, the
/// number of absolute fixes applied since the previous row. Only agents with
/// odometry have rows.
pub const ODOMETRY_HEADER: &str = "t,agent,x_hat,y_hat,theta_hat,ex_hat,ey_hat,zx_hat,zy_hat,fix";

/// Streams `odometry.csv` rows on the same schedule as [`TrajectoryCsv`].
#[derive(Debug)]
pub struct OdometryCsv<W: Write> {
    out: W,
    every: u64,
    line: String,
    fixes: Vec<u64>,
}

impl<W: Write> OdometryCsv<W> {
    /// Writes the header; then logs every `every`-th step (1: every step) and the last.
    pub fn new(mut out: W, every: u64) -> io::Result<Self> {
        writeln!(out, "{ODOMETRY_HEADER}")?;
        Ok(OdometryCsv {
            out,
            every,
            line: String::with_capacity(256),
            fixes: Vec::new(),
        })
    }

    /// Flushes and returns the writer.
    pub fn finish(mut self) -> io::Result<W> {
        self.out.flush()?;
        Ok(self.out)
    }
}

impl<W: Write> Observer for OdometryCsv<W> {
    fn observe(&mut self, frame: &Frame<'_>) -> Result<(), ObserverError> {
        if !frame.is_logged(self.every) {
            return Ok(());
        }
        self.fixes.resize(frame.odometers.len(), 0);
        let mut buf = ryu::Buffer::new();
        for (i, (odometer, o)) in frame.odometers.iter().zip(frame.outputs).enumerate() {
            let Some(odometer) = odometer else { continue };
            let est = odometer.believed(&frame.states[i]);
            let line = &mut self.line;
            line.clear();
            push_time(line, frame.t);
            let _ = write!(line, ",{}", i + 1);
            for v in [
                est.x,
                est.y,
                wrap_angle(est.theta),
                o.e_hat[0],
                o.e_hat[1],
                o.z_hat[0],
                o.z_hat[1],
            ] {
                line.push(',');
                push_f64(line, v, &mut buf);
            }
            let applied = odometer.fixes_applied();
            let _ = writeln!(line, ",{}", applied - self.fixes[i]);
            self.fixes[i] = applied;
            self.out.write_all(line.as_bytes())?;
        }
        Ok(())
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

    /// Parses the text of the numeric CSV `path` (named in errors).
    pub fn parse(path: &Path, text: &str) -> Result<Table, OutputError> {
        let parse = |line: usize, message: String| OutputError::Parse {
            path: path.to_path_buf(),
            line,
            message,
        };
        let mut lines = text.lines();
        let header: Vec<String> = lines
            .next()
            .ok_or_else(|| parse(1, "empty file: expected a header".into()))?
            .split(',')
            .map(|h| h.trim().to_owned())
            .collect();
        let mut rows = Vec::new();
        for (k, line) in lines.enumerate() {
            if line.trim().is_empty() {
                continue;
            }
            let row = line
                .split(',')
                .map(|c| c.trim().parse::<f64>())
                .collect::<Result<Vec<f64>, _>>()
                .map_err(|e| parse(k + 2, format!("not a number: {e}")))?;
            if row.len() != header.len() {
                return Err(parse(
                    k + 2,
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
}

/// The files a run writes into its output directory.
pub const TRAJECTORY_FILE: &str = "trajectory.csv";
/// See [`TRAJECTORY_FILE`].
pub const SUMMARY_FILE: &str = "summary.json";
/// See [`TRAJECTORY_FILE`]; header [`REFERENCE_HEADER`].
pub const REFERENCE_FILE: &str = "reference.csv";
/// See [`TRAJECTORY_FILE`]: the scenario source as run ([`Run::record`]).
pub const SCENARIO_FILE: &str = "scenario.toml";
/// Written when any agent dead-reckons; see [`ODOMETRY_HEADER`].
pub const ODOMETRY_FILE: &str = "odometry.csv";

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
/// `dir/summary.json` and `dir/scenario.toml`; `extra` sees every frame too
/// (e.g. a progress bar). Files are written under temporary names and renamed
/// only when the run succeeds, so a failed run leaves no half-written output.
pub fn run_to_dir(
    run: &mut Run,
    dir: &Path,
    extra: &mut dyn Observer,
) -> Result<RunSummary, OutputError> {
    std::fs::create_dir_all(dir).map_err(io_error(dir))?;
    let mut names = vec![TRAJECTORY_FILE, REFERENCE_FILE, SUMMARY_FILE, SCENARIO_FILE];
    if !run.simulation.odometers().is_empty() {
        names.push(ODOMETRY_FILE);
    }
    let parts: Vec<PathBuf> = names.iter().map(|n| part_path(&dir.join(n))).collect();
    let (traj_part, ref_part, summary_part, scenario_part) =
        (&parts[0], &parts[1], &parts[2], &parts[3]);
    let remove_parts = || {
        for p in &parts {
            let _ = std::fs::remove_file(p);
        }
    };
    let create = |path: &Path| -> Result<BufWriter<File>, OutputError> {
        let file = File::create(path).map_err(io_error(path))?;
        Ok(BufWriter::with_capacity(1 << 16, file))
    };
    let mut csv =
        TrajectoryCsv::new(create(traj_part)?, run.log_every).map_err(io_error(traj_part))?;
    let sim = &mut run.simulation;
    let mut reference =
        ReferenceCsv::new(create(ref_part)?, run.log_every, sim.reference().clone())
            .map_err(io_error(ref_part))?;
    let mut odometry = match parts.get(4) {
        Some(p) => Some(OdometryCsv::new(create(p)?, run.log_every).map_err(io_error(p))?),
        None => None,
    };
    let mut summary = Summary::new(sim.agents().len(), Summary::SETTLE_TOLERANCE);
    let result = sim.run(&mut [
        &mut csv as &mut dyn Observer,
        &mut reference,
        &mut odometry,
        &mut summary,
        extra,
    ]);
    if let Err(e) = result {
        remove_parts();
        return Err(e.into());
    }
    csv.finish().map_err(io_error(traj_part))?;
    reference.finish().map_err(io_error(ref_part))?;
    if let (Some(o), Some(p)) = (odometry, parts.get(4)) {
        o.finish().map_err(io_error(p))?;
    }
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
        warnings: sim.warnings().to_vec(),
        agents: summary.agents(sim.agents()),
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
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

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
    fn floats_round_trip() {
        let mut buf = ryu::Buffer::new();
        for v in [0.1, -1.0 / 3.0, 1e-20, 123456.789, 0.0] {
            let mut s = String::new();
            push_f64(&mut s, v, &mut buf);
            assert_eq!(s.parse::<f64>().unwrap(), v);
        }
    }
}
