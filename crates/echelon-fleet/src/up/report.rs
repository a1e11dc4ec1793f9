//! What `fleet up` reports ([`UpReport`]): per process, per router, the
//! collector's latency and the fleet's cost.

use serde::Serialize;

use crate::FleetError;
use crate::collector::CollectorReport;
use crate::cost::{ProcessCost, RoleCost};
use crate::latency::FleetLatency;
use crate::leader::LeaderReport;
use crate::robot::RobotReport;
use crate::ros2::base::BaseReport;
use crate::router::RouterReport;

use super::{Proc, Topology};

/// Every process's final report.
#[derive(Debug, Clone, Serialize)]
pub struct UpReport {
    /// Scenario name.
    pub scenario: String,
    /// Fleet name.
    pub fleet: String,
    /// Fleet time run, s.
    pub duration: f64,
    /// Time scale.
    pub time_scale: f64,
    /// Wall-clock time, s.
    pub wall: f64,
    /// Startup: from the first process started until every process had
    /// joined and the leader started the clock, s (absent if the leader did
    /// not say when).
    pub startup: Option<f64>,
    /// The rest of `wall`: the run and the wind-down, s.
    pub run: Option<f64>,
    /// What the processes cost (CPU, peak memory), per process and per role.
    pub cost: UpCost,
    /// Delays measured by the robots (merged, and the worst robot) and the
    /// collector.
    pub latency: FleetLatency,
    /// With `[safety]`: the robots' safety counters summed (the smallest
    /// `min_distance`), each robot's under `robots[k].safety`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub safety: Option<crate::robot::SafetyCounts>,
    /// With `[safety]`: the closest approach between two robots' points
    /// from the true states the collector received (its report's
    /// `approach`: [`crate::collector::ApproachWatch`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub approach: Option<echelon::stats::ClosestApproach>,
    /// Robots (agent numbers) their filter kept from their slot at the end
    /// (each robot's `deadlocked_at_end`).
    pub deadlocked_at_end: Vec<u32>,
    /// The leader's report (`null`: it died without one: `leader_failure`).
    pub leader: Option<LeaderReport>,
    /// How the leader died mid-run, if it did: the robots then held under
    /// their link-loss policy and ran to the end without it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub leader_failure: Option<String>,
    /// The processes killed as asked (`--die-at`, the fault matrix): how
    /// each ended. Their reports are absent.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub deaths: Vec<String>,
    /// Each robot's report, agent 1 first (the robots `fleet up` started:
    /// not the on-board ones, whose reports stay on their computers).
    pub robots: Vec<RobotReport>,
    /// Hub mode: the on-board robots, which joined from their computers.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub onboard: Vec<u32>,
    /// The collector's report (`None`: it was killed as asked, and
    /// `log_gap` says what its log misses).
    pub collector: Option<CollectorReport>,
    /// The second fleet's processes asked for ([`crate::faults::Chaos::intruders`]):
    /// how each ended.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub intruders: Vec<Intrusion>,
    /// Where the log stops short of the run (the collector killed): the
    /// fleet time its `trajectory.csv` ends at, and the run's end.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub log_gap: Option<LogGap>,
    /// With `--ros2`: each simulated base's report.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub bases: Vec<BaseReport>,
    /// How the processes were linked.
    pub topology: Topology,
    /// Router topology: each router's endpoint, site 1 first.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub router_endpoints: Vec<String>,
    /// Router topology: the roles linked to each router, site 1 first.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub sites: Vec<Vec<String>>,
    /// Router topology: each router's report, site 1 first.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub routers: Vec<RouterReport>,
}

impl UpReport {
    /// Samples the robots dropped before taking them, their input queues
    /// full (each robot's `dropped`), summed.
    pub fn robots_dropped(&self) -> u64 {
        self.robots.iter().map(|r| r.dropped).sum()
    }
}

/// A process of a second fleet of the same name that joined the router.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Intrusion {
    /// Its role (`intruder-leader`, `intruder-robot/2`).
    pub role: String,
    /// Its exit code (`None`: still running at the end, then killed).
    pub exit: Option<i32>,
    /// The last line it wrote on stderr.
    pub said: String,
}

/// A stretch of the run the collector's log does not hold.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LogGap {
    /// The last fleet time `trajectory.csv` holds, s (0: none).
    pub from: f64,
    /// The run's end, fleet s.
    pub to: f64,
}

impl LogGap {
    /// The gap in a log whose `trajectory.csv` is at `path` (its last
    /// complete row's time), for a run of `duration` fleet s; `None` when
    /// the log reaches the end.
    pub fn of(path: &std::path::Path, duration: f64) -> Option<LogGap> {
        let text = std::fs::read_to_string(path).unwrap_or_default();
        // The rows a killed writer finished (each ends with its newline).
        let from = text
            .split_inclusive('\n')
            .filter(|l| l.ends_with('\n'))
            .skip(1)
            .filter_map(|l| l.split(',').next()?.trim().parse::<f64>().ok())
            .fold(0.0, f64::max);
        (from < duration - 1e-6).then_some(LogGap { from, to: duration })
    }
}

/// CPU and peak memory of every process of `fleet up` ([`crate::cost`]).
#[derive(Debug, Clone, Default, Serialize)]
pub struct UpCost {
    /// The leader.
    pub leader: RoleCost,
    /// The collector.
    pub collector: RoleCost,
    /// The robots' processes (`cpu_mean`: CPU seconds per process: per
    /// robot when each runs one).
    pub robots: RoleCost,
    /// Robots those processes ran (more than `robots.processes` when hosts
    /// ran several each, `fleet up --robots-per-process`).
    pub robot_count: usize,
    /// CPU seconds per robot: the robots' processes' CPU over
    /// `robot_count`.
    pub cpu_per_robot: f64,
    /// With `--ros2`: the simulated bases.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bases: Option<RoleCost>,
    /// Router topology: the routers.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub routers: Option<RoleCost>,
    /// Every process.
    pub total: RoleCost,
    /// Each process, in start order.
    pub processes: Vec<ProcessCost>,
}

/// The cost of every process, per role and in all.
pub(super) fn up_cost(
    leader: &Proc,
    collector: &Proc,
    (robots, robot_count): (&[Proc], usize),
    bases: &[Proc],
    routers: &[Proc],
) -> UpCost {
    let of = |procs: &[Proc]| procs.iter().map(Proc::cost).collect::<Vec<_>>();
    let (leader, collector) = (vec![leader.cost()], vec![collector.cost()]);
    let (robots, bases, routers) = (of(robots), of(bases), of(routers));
    let processes: Vec<ProcessCost> = routers
        .iter()
        .chain(&collector)
        .chain(&bases)
        .chain(&robots)
        .chain(&leader)
        .cloned()
        .collect();
    let robots = RoleCost::of(&robots);
    UpCost {
        leader: RoleCost::of(&leader),
        collector: RoleCost::of(&collector),
        cpu_per_robot: robots.cpu / robot_count.max(1) as f64,
        robot_count,
        robots,
        bases: (!bases.is_empty()).then(|| RoleCost::of(&bases)),
        routers: (!routers.is_empty()).then(|| RoleCost::of(&routers)),
        total: RoleCost::of(&processes),
        processes,
    }
}

/// A process's report read back as its role's type: an error naming the
/// process when it printed none or one that does not parse (a renamed or
/// missing field is refused, never read as 0).
pub(super) fn report<T: serde::de::DeserializeOwned>(p: &Proc) -> Result<T, FleetError> {
    let value = p.report.clone().ok_or_else(|| {
        FleetError::Child(format!(
            "{} printed no report ({})",
            p.role,
            p.log.display()
        ))
    })?;
    serde_json::from_value(value).map_err(|e| {
        FleetError::Child(format!(
            "{} printed a report that does not parse as its role's: {e} ({})",
            p.role,
            p.log.display()
        ))
    })
}
