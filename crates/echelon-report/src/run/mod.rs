//! An output directory of `echelon run`, read back: `trajectory.csv`,
//! `reference.csv`, `summary.json`, `scenario.toml`, and `odometry.csv`,
//! `safety.csv` when the run wrote them.
//!
//! Only `trajectory.csv` and `summary.json` are required: a directory written
//! before `reference.csv` and `scenario.toml` existed still plots, without the
//! reference path and the leader links.
//!
//! The columns of `trajectory.csv` are in `column` ([`Column`]), the shape of
//! `summary.json` in `summary` ([`RunSummary`]); both are re-exported here.

mod column;
mod summary;

use std::path::{Path, PathBuf};

use echelon::formation::Leader;
use echelon::output::{
    ODOMETRY_FILE, ODOMETRY_HEADER, REFERENCE_FILE, REFERENCE_HEADER, SAFETY_FILE, SAFETY_HEADER,
    SCENARIO_FILE, SUMMARY_FILE, TRAJECTORY_FILE, TRAJECTORY_HEADER, TRAJECTORY_HEADER_VELOCITY,
    Table,
};
use echelon::safety::Obstacle;
use echelon::scenario::schema::{LeaderSpec, ModeName};
use echelon::scenario::{Overrides, Scenario};

use crate::ReportError;

pub use column::{COLUMNS, Column, VELOCITY_COLUMNS};
pub use summary::{AgentSafety, AgentSummary, Divergence, RunSummary, SafetyReport};

/// A velocity base's speed limits (`f64::INFINITY`: unlimited).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpeedLimits {
    /// Largest `|v|`, m/s.
    pub v_max: f64,
    /// Largest `|ω|`, rad/s.
    pub omega_max: f64,
}

/// One agent's logged signals.
#[derive(Debug, Clone, PartialEq)]
pub struct AgentTrack {
    /// Name, as the scenario gives it.
    pub name: String,
    /// Whom it follows (`None`: unknown, no `scenario.toml`).
    pub leader: Option<Leader>,
    /// `(L_Xoff, L_Yoff)`, m (`None`: pure tracking or unknown).
    pub offset: Option<(f64, f64)>,
    /// A velocity base's speed limits (`None`: torque-driven, or unknown
    /// without a `scenario.toml` that builds).
    pub limits: Option<SpeedLimits>,
    columns: [Vec<f64>; COLUMNS],
}

impl AgentTrack {
    /// A column, one value per logged instant (the [`VELOCITY_COLUMNS`] are
    /// empty in a run without velocity bases).
    pub fn get(&self, c: Column) -> &[f64] {
        &self.columns[c as usize]
    }

    /// Whether the agent is on a velocity base: its `sat` column is logged
    /// (a torque-driven agent's is `NaN`, or absent in a torque-only run).
    pub fn is_velocity(&self) -> bool {
        self.get(Column::Sat).first().is_some_and(|s| s.is_finite())
    }

    /// ‖e‖ at every logged instant, m.
    pub fn error_norm(&self) -> Vec<f64> {
        self.norm(Column::Ex, Column::Ey)
    }

    /// The norm of the vector `(x, y)` at every logged instant: `‖e‖` from
    /// `(Ex, Ey)`, `‖z‖` from `(Zx, Zy)`.
    pub(crate) fn norm(&self, x: Column, y: Column) -> Vec<f64> {
        self.get(x)
            .iter()
            .zip(self.get(y))
            .map(|(x, y)| x.hypot(*y))
            .collect()
    }
}

/// The virtual leader, from `reference.csv`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ReferenceTrack {
    /// x, m.
    pub x: Vec<f64>,
    /// y, m.
    pub y: Vec<f64>,
    /// Heading, rad.
    pub theta: Vec<f64>,
}

/// What one dead-reckoning agent believed, from `odometry.csv`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct OdometryTrack {
    /// x̂, m.
    pub x: Vec<f64>,
    /// ŷ, m.
    pub y: Vec<f64>,
    /// θ̂, rad.
    pub theta: Vec<f64>,
    /// ê, m (eq. 35).
    pub ex: Vec<f64>,
    /// ê_y, m.
    pub ey: Vec<f64>,
    /// Fixes applied since the previous instant.
    pub fix: Vec<f64>,
}

/// What one filtering agent's filter did at each logged instant (`safety.csv`).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SafetyTrack {
    /// 0: nominal command, 1: filtered, 2: braked (QP infeasible).
    pub outcome: Vec<u8>,
    /// Whether it was breaking a deadlock.
    pub deadlock: Vec<bool>,
}

/// A run's safety settings and what its filters did.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SafetyData {
    /// Smallest distance between two robots' points, m ([`ClosestApproach::radius`](echelon::stats::ClosestApproach::radius)).
    pub radius: f64,
    /// `L` of each agent: the point kept apart is `L` ahead of the axle, m
    /// (empty when the scenario does not build here).
    pub l: Vec<f64>,
    /// Known obstacles.
    pub obstacles: Vec<Obstacle>,
    /// Per agent, `(gain γ 1/s, range m)` of its filter, `None`: it does not
    /// filter (or `scenario.toml` is missing).
    pub settings: Vec<Option<(f64, f64)>>,
    /// Per agent, from `safety.csv` (`None`: no rows, it does not filter).
    pub tracks: Vec<Option<SafetyTrack>>,
}

impl SafetyData {
    /// Agent `i`'s point `L` ahead at instant `k` of `data`.
    pub fn point(&self, data: &RunData, i: usize, k: usize) -> Option<(f64, f64)> {
        let l = *self.l.get(i)?;
        let a = &data.agents[i];
        let th = a.get(Column::Theta)[k];
        Some((
            a.get(Column::X)[k] + l * th.cos(),
            a.get(Column::Y)[k] + l * th.sin(),
        ))
    }
}

/// A run directory, loaded.
#[derive(Debug, Clone, PartialEq)]
pub struct RunData {
    /// The directory.
    pub dir: PathBuf,
    /// `summary.json`.
    pub summary: RunSummary,
    /// The scenario's description, from `scenario.toml`.
    pub description: Option<String>,
    /// `scenario.toml` as written by the run (header and source).
    pub scenario_text: Option<String>,
    /// Logged instants, s.
    pub times: Vec<f64>,
    /// The agents, numbered from 1 in this order.
    pub agents: Vec<AgentTrack>,
    /// The virtual leader at the same instants (`None`: no `reference.csv`).
    pub reference: Option<ReferenceTrack>,
    /// Per agent, what its odometry believed (empty: no `odometry.csv`).
    pub odometry: Vec<Option<OdometryTrack>>,
    /// The safety filter (`None`: the run had none).
    pub safety: Option<SafetyData>,
}

fn read(path: &Path) -> Result<String, ReportError> {
    std::fs::read_to_string(path).map_err(|source| ReportError::Io {
        path: path.to_path_buf(),
        source,
    })
}

fn read_optional(path: &Path) -> Result<Option<String>, ReportError> {
    match std::fs::read_to_string(path) {
        Ok(s) => Ok(Some(s)),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(source) => Err(ReportError::Io {
            path: path.to_path_buf(),
            source,
        }),
    }
}

/// Parses a CSV of numbers with exactly the given header: one `Vec` per row.
fn numbers(path: &Path, text: &str, header: &str) -> Result<Vec<Vec<f64>>, ReportError> {
    let table = Table::parse(path, text)?;
    table.expect_header(path, header)?;
    Ok(table.rows)
}

/// The rows of a per-agent file (`odometry.csv`, `safety.csv`), grouped by
/// agent: an agent with rows has one at each of the run's logged instants, in order.
fn agent_rows<'a>(
    path: &Path,
    rows: &'a [Vec<f64>],
    times: &[f64],
    n: usize,
) -> Result<Vec<Vec<&'a [f64]>>, ReportError> {
    let mut out: Vec<Vec<&[f64]>> = vec![Vec::new(); n];
    for (i, row) in rows.iter().enumerate() {
        let bad = |message: String| ReportError::Format {
            path: path.to_path_buf(),
            message: format!("line {}: {message}", i + 2),
        };
        let agent = row[1] as usize;
        if row[1] != agent as f64 || agent == 0 || agent > n {
            return Err(bad(format!(
                "agent {} is not one of the {n} agents",
                row[1]
            )));
        }
        let k = out[agent - 1].len();
        if times.get(k) != Some(&row[0]) {
            return Err(bad(format!("time {} is not the run's instant {k}", row[0])));
        }
        out[agent - 1].push(row);
    }
    if let Some(a) = (0..n).find(|&a| !out[a].is_empty() && out[a].len() != times.len()) {
        return Err(ReportError::Format {
            path: path.to_path_buf(),
            message: format!(
                "agent {} has {} rows for the run's {} instants",
                a + 1,
                out[a].len(),
                times.len()
            ),
        });
    }
    Ok(out)
}

/// `odometry.csv`, per agent: every dead-reckoning agent has one row at each
/// of the run's logged instants.
fn odometry_tracks(
    path: &Path,
    text: &str,
    times: &[f64],
    n: usize,
) -> Result<Vec<Option<OdometryTrack>>, ReportError> {
    let rows = numbers(path, text, ODOMETRY_HEADER)?;
    Ok(agent_rows(path, &rows, times, n)?
        .into_iter()
        .map(|rows| {
            (!rows.is_empty()).then(|| {
                let mut t = OdometryTrack::default();
                for row in rows {
                    for (column, v) in [
                        (&mut t.x, row[2]),
                        (&mut t.y, row[3]),
                        (&mut t.theta, row[4]),
                        (&mut t.ex, row[5]),
                        (&mut t.ey, row[6]),
                        (&mut t.fix, row[9]),
                    ] {
                        column.push(v);
                    }
                }
                t
            })
        })
        .collect())
}

/// `safety.csv`, per agent: every filtering agent has one row at each of the
/// run's logged instants.
fn safety_tracks(
    path: &Path,
    text: &str,
    times: &[f64],
    n: usize,
) -> Result<Vec<Option<SafetyTrack>>, ReportError> {
    let rows = numbers(path, text, SAFETY_HEADER)?;
    Ok(agent_rows(path, &rows, times, n)?
        .into_iter()
        .map(|rows| {
            (!rows.is_empty()).then(|| SafetyTrack {
                outcome: rows.iter().map(|r| r[2] as u8).collect(),
                deadlock: rows.iter().map(|r| r[3] != 0.0).collect(),
            })
        })
        .collect())
}

/// Each agent's filter settings from the scenario file: its own `safety`
/// over `[safety]`, defaults `gain = 1`, `range = ∞` (as the scenario builds them).
fn safety_settings(scenario: &Scenario) -> Vec<Option<(f64, f64)>> {
    let f = &scenario.file;
    f.agents
        .iter()
        .map(|a| {
            let get = |field: fn(&echelon::scenario::schema::SafetySection) -> Option<f64>| {
                a.safety
                    .as_ref()
                    .and_then(field)
                    .or_else(|| f.safety.as_ref().and_then(field))
            };
            let enabled = a
                .safety
                .as_ref()
                .and_then(|s| s.enabled)
                .or_else(|| f.safety.as_ref().and_then(|s| s.enabled))
                .unwrap_or(true);
            enabled.then(|| {
                (
                    get(|s| s.gain).unwrap_or(1.0),
                    get(|s| s.range).unwrap_or(f64::INFINITY),
                )
            })
        })
        .collect()
}

/// What the figures take from the scenario built as the run was (its step
/// `dt`; the other overrides do not touch the robots): each agent's speed
/// limits, `L`, and the obstacles. Empty when the scenario does not build here
/// (e.g. a waypoint file next to the original): the figures then draw no
/// limit lines, distances or obstacles.
#[derive(Debug, Default)]
struct Built {
    limits: Vec<Option<SpeedLimits>>,
    l: Vec<f64>,
    obstacles: Vec<Obstacle>,
}

fn built(scenario: &Scenario, dt: f64) -> Built {
    let overrides = Overrides {
        dt: Some(dt),
        ..Overrides::default()
    };
    scenario.build(&overrides).map_or_else(
        |_| Built::default(),
        |run| {
            let agents = run.plan.agents();
            Built {
                limits: agents
                    .iter()
                    .map(|a| {
                        a.velocity_robot().map(|r| SpeedLimits {
                            v_max: r.base().v_max(),
                            omega_max: r.base().omega_max(),
                        })
                    })
                    .collect(),
                l: agents.iter().map(|a| a.placement().l()).collect(),
                obstacles: run.plan.obstacles().to_vec(),
            }
        },
    )
}

/// The agents' tracks and the times of `dir`'s trajectory, checked against
/// the `summary`'s agents (rows go agent 1..n at each instant).
fn trajectory(
    dir: &Path,
    summary: &RunSummary,
) -> Result<(Vec<AgentTrack>, Vec<f64>), ReportError> {
    let n = summary.agents.len();
    let traj_path = dir.join(TRAJECTORY_FILE);
    // A run with velocity bases has five more columns after the torque
    // ones (commands and saturation, [`VELOCITY_COLUMNS`]); the first
    // ones are the same.
    let text = read(&traj_path)?;
    let header = if text.starts_with(&format!("{TRAJECTORY_HEADER_VELOCITY}\n")) {
        TRAJECTORY_HEADER_VELOCITY
    } else {
        TRAJECTORY_HEADER
    };
    let rows = numbers(&traj_path, &text, header)?;
    let mut agents: Vec<AgentTrack> = summary
        .agents
        .iter()
        .map(|a| AgentTrack {
            name: a.name.clone(),
            leader: None,
            offset: None,
            limits: None,
            columns: Default::default(),
        })
        .collect();
    let mut times = Vec::new();
    for (i, row) in rows.iter().enumerate() {
        let bad = |message: String| ReportError::Format {
            path: traj_path.clone(),
            message: format!("line {}: {message}", i + 2),
        };
        let agent = row[1] as usize;
        if row[1] != agent as f64 || agent == 0 || agent > n {
            return Err(bad(format!(
                "agent {} is not one of the {n} agents of {SUMMARY_FILE}",
                row[1]
            )));
        }
        if agent != i % n + 1 {
            return Err(bad(format!(
                "agent {agent} out of order (rows go agent 1..{n} at each instant)"
            )));
        }
        if agent == 1 {
            times.push(row[0]);
        } else if times.last() != Some(&row[0]) {
            return Err(bad(format!("time {} differs from agent 1's", row[0])));
        }
        for (c, v) in agents[agent - 1].columns.iter_mut().zip(&row[2..]) {
            c.push(*v);
        }
    }
    if rows.len() % n.max(1) != 0 || times.is_empty() {
        return Err(ReportError::Format {
            path: traj_path,
            message: format!(
                "{} rows is not a whole number of instants of {n} agents",
                rows.len()
            ),
        });
    }
    Ok((agents, times))
}

/// The reference of `dir`, if it has one, at the trajectory's `times`.
fn reference_track(dir: &Path, times: &[f64]) -> Result<Option<ReferenceTrack>, ReportError> {
    let ref_path = dir.join(REFERENCE_FILE);
    Ok(match read_optional(&ref_path)? {
        None => None,
        Some(text) => {
            let rows = numbers(&ref_path, &text, REFERENCE_HEADER)?;
            if rows.len() != times.len() || rows.iter().zip(times).any(|(r, t)| r[0] != *t) {
                return Err(ReportError::Format {
                    path: ref_path,
                    message: format!("its times are not those of {TRAJECTORY_FILE}"),
                });
            }
            Some(ReferenceTrack {
                x: rows.iter().map(|r| r[1]).collect(),
                y: rows.iter().map(|r| r[2]).collect(),
                theta: rows.iter().map(|r| r[3]).collect(),
            })
        }
    })
}

impl RunData {
    /// Reads `dir`.
    pub fn load(dir: &Path) -> Result<RunData, ReportError> {
        let summary_path = dir.join(SUMMARY_FILE);
        let summary: RunSummary =
            serde_json::from_str(&read(&summary_path)?).map_err(|e| ReportError::Format {
                path: summary_path.clone(),
                message: e.to_string(),
            })?;
        let n = summary.agents.len();
        let (mut agents, times) = trajectory(dir, &summary)?;
        let reference = reference_track(dir, &times)?;
        let odometry_path = dir.join(ODOMETRY_FILE);
        let odometry = match read_optional(&odometry_path)? {
            None => Vec::new(),
            Some(text) => odometry_tracks(&odometry_path, &text, &times, n)?,
        };
        let mut safety = match &summary.safety {
            None => None,
            Some(report) => {
                let path = dir.join(SAFETY_FILE);
                let tracks = match read_optional(&path)? {
                    None => vec![None; n],
                    Some(text) => safety_tracks(&path, &text, &times, n)?,
                };
                Some(SafetyData {
                    radius: report.closest.radius,
                    tracks,
                    ..SafetyData::default()
                })
            }
        };
        let scenario_path = dir.join(SCENARIO_FILE);
        let scenario_text = read_optional(&scenario_path)?;
        let mut description = None;
        if let Some(text) = &scenario_text {
            let scenario = Scenario::parse(text, &scenario_path.display().to_string(), None)
                .map_err(|e| ReportError::Format {
                    path: scenario_path.clone(),
                    message: e.to_string(),
                })?;
            if scenario.file.agents.len() != n {
                return Err(ReportError::Format {
                    path: scenario_path,
                    message: format!(
                        "{} agents, but {SUMMARY_FILE} has {n}",
                        scenario.file.agents.len()
                    ),
                });
            }
            description = scenario.file.description.clone();
            for (track, spec) in agents.iter_mut().zip(&scenario.file.agents) {
                track.leader = match spec.leader {
                    LeaderSpec::Reference => Some(Leader::Reference),
                    LeaderSpec::Agent(k) if k >= 1 && (k as usize) <= n => {
                        Some(Leader::Agent(k as usize - 1))
                    }
                    LeaderSpec::Agent(_) => None,
                };
                track.offset = match (spec.mode, spec.offset) {
                    (Some(ModeName::Tracking), _) | (_, None) => None,
                    (_, Some(o)) => Some((o.x, o.y)),
                };
            }
            if agents.iter().any(AgentTrack::is_velocity) || safety.is_some() {
                let built = built(&scenario, summary.dt);
                for (track, limits) in agents.iter_mut().zip(built.limits) {
                    track.limits = limits;
                }
                if let Some(s) = safety.as_mut() {
                    s.l = built.l;
                    s.obstacles = built.obstacles;
                    s.settings = safety_settings(&scenario);
                }
            }
        }
        Ok(RunData {
            dir: dir.to_path_buf(),
            summary,
            description,
            scenario_text,
            times,
            agents,
            reference,
            odometry,
            safety,
        })
    }

    /// Whether any agent is on a velocity base ([`AgentTrack::is_velocity`]).
    pub fn has_velocity_agents(&self) -> bool {
        self.agents.iter().any(AgentTrack::is_velocity)
    }

    /// Whether any agent follows the virtual leader (or that is unknown).
    pub fn uses_reference(&self) -> bool {
        self.agents
            .iter()
            .any(|a| matches!(a.leader, None | Some(Leader::Reference)))
    }

    /// Position of agent `i`'s leader at instant `k` (the reference point for
    /// the virtual leader), if known.
    pub fn leader_position(&self, i: usize, k: usize) -> Option<(f64, f64)> {
        match self.agents[i].leader? {
            Leader::Reference => {
                let r = self.reference.as_ref()?;
                Some((r.x[k], r.y[k]))
            }
            Leader::Agent(j) => {
                let a = &self.agents[j];
                Some((a.get(Column::X)[k], a.get(Column::Y)[k]))
            }
        }
    }

    /// The leader's display name for agent `i` (`reference`, a name, or `?`).
    pub fn leader_name(&self, i: usize) -> String {
        match self.agents[i].leader {
            Some(Leader::Reference) => "reference".to_owned(),
            Some(Leader::Agent(j)) => self.agents[j].name.clone(),
            None => "?".to_owned(),
        }
    }
}

/// The maximal runs of the first `len` instants of `times` at which `flag`
/// holds, as time spans: instant `k` covers `[t_k, t_{k+1}]` (the last one,
/// `[t_k, t_k]`).
pub fn spans_where(times: &[f64], len: usize, flag: impl Fn(usize) -> bool) -> Vec<(f64, f64)> {
    let n = times.len().min(len);
    let mut spans = Vec::new();
    let mut k = 0;
    while k < n {
        if flag(k) {
            let start = k;
            while k < n && flag(k) {
                k += 1;
            }
            spans.push((times[start], times[k.min(n - 1)]));
        } else {
            k += 1;
        }
    }
    spans
}
