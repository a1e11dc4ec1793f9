//! `echelon fleet faults`: the fault matrix. Each row is one fault injected
//! into a simulated fleet over real Zenoh ([`up::run`]: one OS process per
//! role, a router, the collector): three TurtleBot 4s (velocity bases:
//! lag 0.1 s, 0.9 m/s², 0.306 m/s) in a column behind a virtual leader on a
//! circle at 0.15 m/s, started on their slots, the fault at fleet time
//! [`FAULT_AT`]. Every simulated robot measures its own true motion from the
//! fault on ([`crate::faults::Aftermath`]); the row compares the farthest
//! any affected robot got from where the fault found it with the bound the
//! policy implies,
//!
//! `d ≤ v·(t_detect + depth·(T + 10 ms)) + v·τ_v + d_brake`,
//!
//! `v` the robot's speed at the fault, `t_detect` the time the robot needs
//! to notice (the link timeout, the odometry timeout, the heartbeat
//! deadline, plus one control period `T`, or the longest interval between
//! its ticks up to its first zero command when a loaded machine made that
//! longer: measured, never assumed), `depth` the robots ahead of it
//! in its chain that notice first (each adds a period and a state's
//! delivery), `τ_v` the base's lag (a first-order
//! lag delays any braking by at most `τ_v`) and `d_brake` the braking
//! distance of the action taken: `v²/2a` for a zero command on a base that
//! decelerates at `a`, and for `extrapolate` its hold and smooth stop,
//! `v·hold + π v²/(4·decel)`.
//!
//! Rows: the leader killed (`kill -9`) under `stop` and under
//! `extrapolate`; a robot killed (its followers lose their leader); a
//! robot killed while it drives a simulated ROS 2 base (the base's own
//! `cmd_vel` timeout stops it, measured by the base, which learns the
//! fleet's time from the reference); the router killed and started again
//! 2 s later; a robot's wall clock stepped ±1 s; garbage and replays on
//! every key; a robot's base killed (the robot's
//! output watchdog holds it, its followers stop); a robot partitioned (nothing in or out) for
//! 0.3 s, 3 s and 30 s; a robot's odometry frozen; the operator's
//! heartbeat killed in a supervised run. Each row's
//! directory `DIR/<row>/` holds its scenario and everything `fleet up`
//! wrote; `DIR/faults.json` and `DIR/faults.md` hold the table.

use std::fmt::Write as _;
use std::path::PathBuf;

use serde::Serialize;

use crate::bench::Machine;
use crate::faults::{AftermathReport, Chaos};
use crate::robot::Watchdog;
use crate::up::{self, UpOptions, UpReport};
use crate::{FleetError, StopFlag};

/// The table as JSON.
pub const FAULTS_JSON: &str = "faults.json";
/// The table as Markdown.
pub const FAULTS_MD: &str = "faults.md";
/// Fleet time of every fault, s (the robots cruise on their slots by then).
pub const FAULT_AT: f64 = 6.0;
/// Fleet seconds every row runs after its fault's measurement window.
const TAIL: f64 = 2.0;
/// The measurement window of a fault that lasts (a stop is over by then:
/// the law settles a robot onto a point at rest within a few seconds).
const WINDOW: f64 = 8.0;
/// A window at least this long ends with the robots at rest, s; a shorter
/// one (a fault that ends sooner) is judged on its bound alone.
const SETTLE: f64 = 6.0;
/// The operator heartbeat deadline of the supervised row, s.
const HEARTBEAT: f64 = 1.0;
/// The control rate of the matrix's fleet, Hz.
const CONTROL_RATE: f64 = 50.0;
/// The reference rate, Hz.
const REFERENCE_RATE: f64 = 50.0;
/// `[fleet] link_timeout`, s.
const LINK_TIMEOUT: f64 = 0.2;
/// `extrapolate`'s hold, s, and peak deceleration, m/s².
const HOLD: f64 = 1.0;
const DECEL: f64 = 0.1;
/// What a follower adds per robot ahead of it in its chain to the time it
/// needs to notice, besides one control period: its leader robot's state
/// on its way, s.
const HOP_DELIVERY: f64 = 0.01;
/// A simulated ROS 2 base's `cmd_vel` timeout and odometry rate (the
/// defaults of `[fleet.ros2]`), s and Hz.
const CMD_VEL_TIMEOUT: f64 = echelon::scenario::DEFAULT_CMD_VEL_TIMEOUT;
const ODOM_RATE: f64 = echelon::scenario::DEFAULT_ODOM_RATE;
/// How far apart the column's slots are, m.
const SPACING: f64 = 0.4;
/// The TurtleBot 4's base: lag τ_v, s, and linear acceleration limit, m/s².
const TAU_V: f64 = 0.1;
const A_MAX: f64 = 0.9;

mod rows;
pub use rows::{Outcome, Row, rows};

/// One affected robot's measurement.
#[derive(Debug, Clone, Serialize)]
pub struct RobotOutcome {
    /// Agent number.
    pub agent: u32,
    /// Robots ahead of it in its chain that notice the fault first.
    pub depth: u32,
    /// What it measured.
    pub aftermath: AftermathReport,
    /// The row's bound at its speed, m (`None`: the row bounds no travel).
    pub bound: Option<f64>,
    /// Messages from the network it refused (malformed, another version,
    /// foreign, stale, reordered).
    pub refused: u64,
    /// Its link status at the end.
    pub link: String,
}

/// One row's result.
#[derive(Debug, Clone, Serialize)]
pub struct RowResult {
    /// The row's name.
    pub name: String,
    /// The fault.
    pub fault: String,
    /// What the robots do.
    pub action: String,
    /// What it expects.
    pub outcome: Outcome,
    /// Detection time used in the bound, s.
    pub t_detect: f64,
    /// The affected robots.
    pub robots: Vec<RobotOutcome>,
    /// The farthest any affected robot got, m.
    pub farthest: f64,
    /// The bound for that robot, m (`None`: the row bounds no travel).
    pub bound: Option<f64>,
    /// Messages the affected robots refused.
    pub refused: u64,
    /// The longest time from the fault to a zero command, s (`None`: no
    /// affected robot was commanded zero in the window).
    pub time_to_zero: Option<f64>,
    /// The longest an affected robot kept moving after the fault, s.
    pub moving_for: f64,
    /// Whether the outcome is the expected one and every travel within its bound.
    pub pass: bool,
    /// Why not, if not.
    pub problems: Vec<String>,
    /// Processes killed as asked.
    pub deaths: Vec<String>,
    /// Samples the collector logged.
    pub logged: u64,
}

/// What `fleet faults` writes to `faults.json`.
#[derive(Debug, Clone, Serialize)]
pub struct FaultsReport {
    /// The machine.
    pub machine: Machine,
    /// Time scale of every row.
    pub time_scale: f64,
    /// The rows.
    pub rows: Vec<RowResult>,
}

impl FaultsReport {
    /// Whether every row passed.
    pub fn pass(&self) -> bool {
        self.rows.iter().all(|r| r.pass)
    }
}

/// Options of `fleet faults`.
#[derive(Debug, Clone)]
pub struct FaultsOptions {
    /// Output directory.
    pub out: PathBuf,
    /// The `echelon` binary `fleet up` starts the processes with.
    pub exe: PathBuf,
    /// Only the rows of these names (empty: all).
    pub only: Vec<String>,
    /// Clock speed-up of every row.
    pub time_scale: f64,
}

/// Judges a row from `fleet up`'s report.
pub fn judge(row: &Row, up: &UpReport) -> RowResult {
    let mut problems = Vec::new();
    let robots: Vec<RobotOutcome> = row
        .affected
        .iter()
        .filter_map(|&(k, depth)| judge_robot(row, up, k, depth, &mut problems))
        .collect();
    let mut notes: Vec<String> = Vec::new();
    judge_collector(row, up, &mut problems, &mut notes);
    judge_partitions(row, up, &mut problems);
    judge_intruders(row, up, &mut problems, &mut notes);
    judge_watchdogs(row, up, &mut problems);
    let refused: u64 = robots.iter().map(|r| r.refused).sum();
    if row.outcome == Outcome::Unaffected && refused > 0 {
        notes.push(format!("{refused} messages refused"));
    }
    let worst = robots
        .iter()
        .max_by(|a, b| a.aftermath.farthest.total_cmp(&b.aftermath.farthest));
    RowResult {
        name: row.name.to_owned(),
        fault: row.fault.to_owned(),
        action: match notes.is_empty() {
            true => row.action.to_owned(),
            false => format!("{} (here: {})", row.action, notes.join("; ")),
        },
        outcome: row.outcome,
        t_detect: row.t_detect(),
        farthest: worst.map_or(0.0, |w| w.aftermath.farthest),
        bound: worst.and_then(|w| w.bound),
        refused,
        time_to_zero: robots
            .iter()
            .filter_map(|r| r.aftermath.time_to_zero)
            .max_by(f64::total_cmp),
        moving_for: robots
            .iter()
            .map(|r| r.aftermath.moving_for)
            .fold(0.0, f64::max),
        pass: problems.is_empty(),
        problems,
        deaths: up.deaths.clone(),
        logged: up.collector.as_ref().map_or(0, |c| c.logged),
        robots,
    }
}

/// Affected robot `k`'s measurement (`depth` robots ahead of it in its
/// chain), its problems pushed on `problems`; none when it measured nothing.
fn judge_robot(
    row: &Row,
    up: &UpReport,
    k: u32,
    depth: u32,
    problems: &mut Vec<String>,
) -> Option<RobotOutcome> {
    // A simulated robot measures itself; a ROS 2 robot's base
    // measures it (and outlives a robot killed).
    let robot = up.robots.iter().find(|r| r.agent == k);
    let base = up.bases.iter().find(|b| b.agent == k);
    let Some(a) = robot
        .and_then(|r| r.aftermath)
        .or_else(|| base.and_then(|b| b.aftermath))
    else {
        problems.push(format!("robot {k} measured nothing"));
        return None;
    };
    let link = robot.map_or("killed", |r| r.link.as_str());
    let v = a.speed_at_fault.unwrap_or(0.0);
    let bound = (row.outcome != Outcome::Unaffected).then(|| row.bound(v, depth, a.slowest_tick));
    if let Some(bound) = bound
        && a.farthest > bound
    {
        problems.push(format!(
            "robot {k} got {:.4} m from where the fault found it, above its bound {bound:.4} m",
            a.farthest
        ));
    }
    let at_rest = !a.moving_at_end;
    match row.outcome {
        Outcome::Stop | Outcome::Hold if !at_rest && row.window >= SETTLE => problems.push(
            format!("robot {k} still moved {:.1} s after the fault", row.window),
        ),
        Outcome::Continue | Outcome::Unaffected if at_rest => {
            problems.push(format!("robot {k} stopped; it should have carried on"))
        }
        _ => {}
    }
    if row.outcome == Outcome::Unaffected
        && let Some(r) = robot
    {
        let c = r.counters;
        if row.chaos.garbage.is_some() && (c.malformed == 0 || c.reordered == 0) {
            problems.push(format!(
                "robot {k} refused no garbage or no replay ({c:?}): did it hear any?"
            ));
        }
        if r.final_error > 0.01 || c.link_losses > 0 {
            problems.push(format!(
                "robot {k} was disturbed: final error {:.4} m, {} link losses",
                r.final_error, c.link_losses
            ));
        }
    }
    if matches!(
        row.outcome,
        Outcome::Hold | Outcome::Continue | Outcome::Unaffected
    ) && link != "tracking"
    {
        problems.push(format!(
            "robot {k} did not follow again: its link is {link} at the end"
        ));
    }
    Some(RobotOutcome {
        agent: k,
        depth,
        aftermath: a,
        bound,
        refused: robot.map_or(0, |r| {
            let c = r.counters;
            c.malformed + c.wrong_version + c.foreign + c.stale + c.reordered
        }),
        link: link.to_owned(),
    })
}

/// The collector killed: the gap in its log is reported, from about the
/// fault on (a note), or a problem.
fn judge_collector(row: &Row, up: &UpReport, problems: &mut Vec<String>, notes: &mut Vec<String>) {
    if row.chaos.death_of(crate::role::Member::Collector).is_some() {
        match up.log_gap {
            Some(g) if (g.from - FAULT_AT).abs() <= 1.0 => {
                notes.push(format!("the log ends at {:.2} s of {:.0}", g.from, g.to));
            }
            g => problems.push(format!(
                "the collector's log gap was not reported from the fault on ({g:?})"
            )),
        }
    }
}

/// A partition cuts both ways: robot 2, which follows robot 1, lost it
/// (its state stopped leaving) when the partition outlasted its link
/// timeout; a problem for each follower that never did.
fn judge_partitions(row: &Row, up: &UpReport, problems: &mut Vec<String>) {
    for &(k, (_, len)) in &row.chaos.partitions {
        if len > LINK_TIMEOUT + 1.0 / CONTROL_RATE {
            let follower = up.robots.iter().find(|r| r.agent == k + 1);
            if follower.is_none_or(|r| r.counters.link_losses == 0) {
                problems.push(format!(
                    "robot {}, robot {k}'s follower, never lost it: did robot {k}'s state keep leaving?",
                    k + 1
                ));
            }
        }
    }
}

/// A second fleet's processes: each refused, exit 2, naming why (the
/// first's reason a note).
fn judge_intruders(row: &Row, up: &UpReport, problems: &mut Vec<String>, notes: &mut Vec<String>) {
    if row.chaos.intruders.is_some() {
        if up.intruders.len() != 2 {
            problems.push(format!("{} intruders ran, not 2", up.intruders.len()));
        }
        for i in &up.intruders {
            if i.exit != Some(2) || !i.said.contains("already running") {
                problems.push(format!(
                    "{} was not refused (exit {:?}: {})",
                    i.role, i.exit, i.said
                ));
            }
        }
        if let Some(i) = up.intruders.first() {
            let said = i.said.trim_start_matches("error: ");
            notes.push(said.split(": a second").next().unwrap_or(said).to_owned());
        }
    }
}

/// The robots a watchdog should have held: a problem for each it never did.
fn judge_watchdogs(row: &Row, up: &UpReport, problems: &mut Vec<String>) {
    for &(k, w) in &row.held_by {
        let counts = up.robots.iter().find(|r| r.agent == k).map(|r| r.watchdogs);
        let trips = counts.map_or(0, |c| match w {
            Watchdog::Odometry => c.odometry,
            Watchdog::Operator => c.operator,
            Watchdog::Output => c.output,
        });
        if trips == 0 {
            problems.push(format!(
                "robot {k}'s {} watchdog never held it ({counts:?})",
                w.name()
            ));
        }
    }
}

/// Runs the matrix (the rows `opts.only` names), writes `faults.json` and
/// `faults.md`, and returns the report (its [`FaultsReport::pass`] says
/// whether every row held).
pub fn run(opts: &FaultsOptions, stop: &StopFlag) -> Result<FaultsReport, FleetError> {
    let selected: Vec<Row> = rows()
        .into_iter()
        .filter(|r| opts.only.is_empty() || opts.only.iter().any(|o| o == r.name))
        .collect();
    if let Some(bad) = opts
        .only
        .iter()
        .find(|o| !rows().iter().any(|r| r.name == o.as_str()))
    {
        let names: Vec<&str> = rows().iter().map(|r| r.name).collect();
        return Err(FleetError::Config(format!(
            "--only {bad}: no such row (rows: {})",
            names.join(", ")
        )));
    }
    std::fs::create_dir_all(&opts.out).map_err(FleetError::io(&opts.out))?;
    let mut results = Vec::with_capacity(selected.len());
    for (i, row) in selected.iter().enumerate() {
        let dir = opts.out.join(row.name);
        std::fs::create_dir_all(&dir).map_err(FleetError::io(&dir))?;
        let scenario = dir.join("scenario.toml");
        std::fs::write(&scenario, row.scenario_toml()).map_err(FleetError::io(&scenario))?;
        eprintln!(
            "fleet faults: [{}/{}] {} ({:.0} s of fleet time)",
            i + 1,
            selected.len(),
            row.name,
            row.duration()
        );
        let chaos = Chaos {
            fault_at: Some(FAULT_AT),
            window: Some(row.window),
            ..row.chaos.clone()
        };
        let report = up::run(
            &UpOptions {
                time_scale: opts.time_scale,
                ros2: row.ros2,
                chaos,
                ..UpOptions::simulated(
                    scenario.display().to_string(),
                    dir.clone(),
                    opts.exe.clone(),
                )
            },
            stop,
        )?;
        let result = judge(row, &report);
        let measured = match result.bound {
            Some(b) => format!("farthest {:.3} m (bound {b:.3} m)", result.farthest),
            None => format!("{} messages refused", result.refused),
        };
        eprintln!(
            "fleet faults: {}: {measured}, {}",
            row.name,
            if result.pass {
                "ok".to_owned()
            } else {
                result.problems.join("; ")
            }
        );
        results.push(result);
    }
    let report = FaultsReport {
        machine: Machine::this(),
        time_scale: opts.time_scale,
        rows: results,
    };
    crate::write_json_file(&opts.out.join(FAULTS_JSON), &report)?;
    let md = opts.out.join(FAULTS_MD);
    std::fs::write(&md, markdown(&report)).map_err(FleetError::io(&md))?;
    Ok(report)
}

/// What the rows measured through the real zenoh-bridge-ros2dds show
/// (`scripts/interop/ros2dds/run`, by hand), as the table's text says it.
const INTEROP: &str = "Through the real bridge, by hand (`scripts/interop/ros2dds/run`, phases `robot-kill` and `base-kill`: a real zenoh-bridge-ros2dds 1.10.2 in front of a Fast DDS base with the Create 3's timing; not in CI, the bridge takes minutes to build): with robot 1 killed, the base's own 0.5 s timeout stopped its wheels 0.45 s after the kill and it travelled 48.7–48.9 mm (bound 58.9 mm at 0.0975 m/s); with the base killed, robot 1's odometry watchdog held it 0.30–0.31 s after the kill (limit 0.36 s) and the fleet saw it `held`, while the bridge kept its `cmd_vel` subscriber until the dead participant's DDS lease expired 20 s later (so the output watchdog cannot see a SIGKILLed DDS base: the odometry watchdog is what holds it). scripts/interop/README.md has the numbers.";

/// The table as Markdown, with how it was made.
pub fn markdown(r: &FaultsReport) -> String {
    let mut s = String::new();
    let m = &r.machine;
    let _ = writeln!(s, "# Fault matrix\n");
    let _ = writeln!(
        s,
        "What a fleet does when something fails mid-run, each row measured on a simulated fleet over real Zenoh: one process per role (router, collector, leader, a robot each, the operator's heartbeat in a supervised run), three TurtleBot 4s (velocity bases: lag {TAU_V} s, {A_MAX} m/s², 0.306 m/s) in a column behind a virtual leader on a circle at 0.15 m/s, control at {CONTROL_RATE} Hz, link timeout {LINK_TIMEOUT} s, the fault at fleet time {FAULT_AT} s. Every simulated robot measures its own true motion from the fault on. This file is written by `echelon fleet faults --out DIR` (as `DIR/faults.md`, with `DIR/faults.json` and each row's fleet in `DIR/<row>/`): rerun it on your machine, or with `--only ROW` for one row. CI runs every row (`crates/echelon-cli/tests/fleet/faults.rs`).\n"
    );
    let _ = writeln!(
        s,
        "Measured by `echelon fleet faults --time-scale {}` on {} ({} logical CPUs, Linux {}).\n",
        r.time_scale,
        if m.cpu.is_empty() {
            "an unnamed CPU"
        } else {
            &m.cpu
        },
        m.cores,
        m.kernel
    );
    let _ = writeln!(
        s,
        "| row | fault | outcome | t_detect (s) | farthest (m) | bound (m) | time to zero (s) | moving after (s) | held |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|");
    for row in &r.rows {
        let _ = writeln!(
            s,
            "| `{}` | {} | {} | {} | {} | {} | {} | {:.2} | {} |",
            row.name,
            row.fault,
            match row.outcome {
                Outcome::Stop => "stop",
                Outcome::Hold => "hold, then follow",
                Outcome::Continue => "continue",
                Outcome::Unaffected => "unaffected",
            },
            match row.outcome {
                Outcome::Unaffected => "—".to_owned(),
                _ => format!("{:.3}", row.t_detect),
            },
            match row.bound {
                Some(_) => format!("{:.4}", row.farthest),
                None => "—".to_owned(),
            },
            row.bound.map_or("—".to_owned(), |b| format!("{b:.4}")),
            row.time_to_zero
                .map_or("—".to_owned(), |t| format!("{t:.3}")),
            row.moving_for,
            if row.pass {
                "yes".to_owned()
            } else {
                format!("**no**: {}", row.problems.join("; "))
            }
        );
    }
    let _ = writeln!(
        s,
        "\n`farthest` is the largest distance any affected robot got from where the fault found it (its true pose, integrated at 1 ms); `bound` is that robot's `v·(t_detect + depth·(T + 10 ms)) + v·τ_v + d_brake` (T the control period, which `t_detect` holds once: the robot's slowest tick up to its first zero command instead when that was longer, τ_v the base's lag, `depth` the robots ahead of it in its chain that notice first, d_brake = v²/2a for a zero command or the law settling onto a point at rest, v·hold + πv²/4·decel for `extrapolate`); `time to zero` the longest time from the fault to a zero command (— where the robots settle under the law instead: `stop` converges onto the last reference); `moving after` the longest time an affected robot kept moving faster than {} m/s after the fault, within the row's window.",
        crate::faults::AT_REST
    );
    let _ = writeln!(s, "\n{INTEROP}");
    let _ = writeln!(s, "\nWhat the robots do, row by row:\n");
    for row in &r.rows {
        let _ = writeln!(s, "- `{}`: {}.", row.name, row.action);
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every row's scenario loads and runs as a fleet (its `[fleet]`
    /// settings valid), and its bound grows with the speed.
    #[test]
    fn every_rows_scenario_is_valid_and_bounds_grow_with_speed() {
        for row in rows() {
            let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
            let p = dir.path().join("s.toml");
            std::fs::write(&p, row.scenario_toml()).unwrap_or_else(|e| panic!("{e}"));
            let s = echelon::scenario::Scenario::resolve(&p.display().to_string())
                .unwrap_or_else(|e| panic!("{}: {e}", row.name));
            let f = s.fleet().unwrap_or_else(|e| panic!("{}: {e}", row.name));
            assert_eq!(f.operator_heartbeat.is_some(), row.supervised);
            assert!(row.bound(0.0, 2, 0.0) == 0.0);
            assert!(
                row.bound(0.15, 0, 0.0) < row.bound(0.3, 0, 0.0),
                "{}",
                row.name
            );
            assert!(
                row.bound(0.15, 0, 0.0) < row.bound(0.15, 1, 0.0),
                "{}",
                row.name
            );
            // A tick no later than a control period changes nothing; a
            // later one widens the bound by v times what it exceeds.
            let period = 1.0 / CONTROL_RATE;
            assert_eq!(row.bound(0.15, 0, period), row.bound(0.15, 0, 0.0));
            let late = row.bound(0.15, 0, period + 0.02) - row.bound(0.15, 0, period);
            assert!((late - 0.15 * 0.02).abs() < 1e-12, "{}: {late}", row.name);
        }
    }
}
