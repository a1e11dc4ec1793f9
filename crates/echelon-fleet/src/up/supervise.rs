//! `fleet up`'s run once every process started ([`Running`]): supervised
//! to its end, the rest stopped in order, every report gathered.

use std::time::{Duration, Instant};

use super::process::{Proc, poll_all, spawn, stop_all};
use super::report::{report, up_cost};
use super::spawn::{Layout, Procs};
use super::{Intrusion, LogGap, UpReport, living, router_role};
use crate::collector::CollectorReport;
use crate::faults::Chaos;
use crate::latency::FleetLatency;
use crate::leader::LeaderReport;
use crate::robot::RobotReport;
use crate::role::{Member, Role};
use crate::{FleetError, StopFlag};

/// How often the processes are polled, real time.
const NAP: Duration = Duration::from_millis(25);

/// The fleet running: its processes, declared in the order they are dropped
/// (each killed if still running), and what has been seen of them so far.
pub(super) struct Running {
    /// A second fleet of the same name reaching the router, when asked.
    intruders: Vec<Proc>,
    /// The leader.
    leader: Proc,
    /// Every other process.
    procs: Procs,
    /// When the leader was started.
    leader_spawned: Instant,
    /// A stop was requested (the leader and robots told to stop).
    interrupted: bool,
    /// When the leader was first seen done.
    leader_done: Option<Instant>,
    /// The robots were told to stop, the leader done for a while.
    robots_told: bool,
    /// The leader died mid-run (killed, crashed): the robots hold under
    /// their link-loss policy and run to the end on their own clocks, as
    /// robots on other machines would; the run is reported, not torn down.
    leader_failure: Option<String>,
    /// Deaths the fault matrix asked for (`--die-at`): who, and how.
    deaths: Vec<(String, String)>,
    /// Site 1's router killed as asked (`router_restart`): when it died.
    router_down: Option<Instant>,
    /// Whether it was started again (its own arguments, on its port).
    router_restarted: bool,
}

impl Running {
    /// The fleet running, `leader` just started (at `leader_spawned`) after
    /// `procs`.
    pub(super) fn new(leader: Proc, leader_spawned: Instant, procs: Procs) -> Running {
        Running {
            intruders: Vec::new(),
            leader,
            procs,
            leader_spawned,
            interrupted: false,
            leader_done: None,
            robots_told: false,
            leader_failure: None,
            deaths: Vec::new(),
            router_down: None,
            router_restarted: false,
        }
    }

    /// Robot process `i`'s member ([`robot_member`]).
    fn robot_of(&self, i: usize) -> Member {
        robot_member(&self.procs, i)
    }

    /// Phase 1: the leader and robots run to the end (or a failure, or a
    /// signal): polled every [`NAP`], faults injected and deaths noted as
    /// asked, the run refused at a failure or at a deadline generous for
    /// the fleet started at `started`.
    pub(super) fn supervise(
        &mut self,
        up: &Layout<'_>,
        stop: &StopFlag,
        started: Instant,
    ) -> Result<(), FleetError> {
        let opts = up.opts;
        // Generous: connection set-up, then the run in real time, then the wind-down.
        let deadline = Duration::from_secs_f64(60.0 + 2.0 * up.plan.duration / opts.time_scale);
        loop {
            self.intrude(up)?;
            poll_all(&mut self.intruders)?;
            let all_done =
                poll_all(std::iter::once(&mut self.leader).chain(&mut self.procs.robots))?;
            let p = &mut self.procs;
            poll_all(
                std::iter::once(&mut p.collector)
                    .chain(&mut p.bases)
                    .chain(p.operator.as_mut())
                    .chain(p.garbage.as_mut())
                    .chain(&mut p.routers),
            )?;
            if let Some(f) = self.procs.garbage.as_ref().and_then(Proc::failure) {
                return Err(FleetError::Child(f));
            }
            self.note_deaths(&opts.chaos);
            if let Some(f) = self.procs.operator.as_ref().and_then(Proc::failure)
                && opts.chaos.death_of(Member::Operator).is_none()
            {
                return Err(FleetError::Child(f));
            }
            if self.leader_failure.is_none()
                && !self.interrupted
                && let Some(f) = self.leader.failure()
            {
                eprintln!(
                    "fleet up: {f}; the robots hold under their link-loss policy and run to --duration without it"
                );
                self.leader_failure = Some(f);
            }
            self.restart_router(up)?;
            self.check_failures(&opts.chaos)?;
            if all_done {
                break;
            }
            if self.procs.collector.status.is_some()
                && opts.chaos.death_of(Member::Collector).is_none()
            {
                return Err(FleetError::Child("the collector stopped early".into()));
            }
            self.wind_down(stop);
            if started.elapsed() > deadline {
                return Err(FleetError::Child(format!(
                    "the fleet did not finish within {:.0} s",
                    deadline.as_secs_f64()
                )));
            }
            std::thread::sleep(NAP);
        }
        Ok(())
    }

    /// A second leader and robot 2 of this fleet, started once when asked
    /// (`intruders`), on the leader's site.
    fn intrude(&mut self, up: &Layout<'_>) -> Result<(), FleetError> {
        let opts = up.opts;
        if let Some(at) = opts.chaos.intruders
            && self.intruders.is_empty()
            && self.leader_spawned.elapsed().as_secs_f64() >= 1.0 + at / opts.time_scale
        {
            for (role, mut args) in [
                ("intruder-leader", up.on_clock(Role::Leader)),
                ("intruder-robot/2", {
                    let mut a = up.on_clock(Role::Robot);
                    a.extend(["--agent".to_owned(), "2".to_owned()]);
                    a
                }),
            ] {
                args.extend(up.common(up.leader_at, &Member::Leader.identity()));
                self.intruders.push(up.spawn(role, &args, &[])?);
            }
            eprintln!("fleet up: a second leader and robot 2 of this fleet joined (as asked)");
        }
        Ok(())
    }

    /// Deaths the fault matrix asked for (`--die-at`): reported, not a
    /// failure of the run; each noted once.
    fn note_deaths(&mut self, chaos: &Chaos) {
        let p = &self.procs;
        for (proc, member) in p
            .robots
            .iter()
            .enumerate()
            .map(|(i, proc)| (proc, robot_member(p, i)))
            .chain(
                p.bases
                    .iter()
                    .enumerate()
                    .map(|(i, proc)| (proc, Member::Base(i as u32 + 1))),
            )
            .chain(p.operator.iter().map(|proc| (proc, Member::Operator)))
            .chain(std::iter::once((&p.collector, Member::Collector)))
        {
            if chaos.death_of(member).is_some()
                && let Some(f) = proc.failure()
                && !self.deaths.iter().any(|(m, _)| *m == member.liveliness())
            {
                eprintln!("fleet up: {f} (as asked: --die-at)");
                self.deaths.push((member.liveliness(), f));
            }
        }
    }

    /// Site 1's router killed as asked: started again, on its port, once it
    /// has been down for the time asked.
    fn restart_router(&mut self, up: &Layout<'_>) -> Result<(), FleetError> {
        let opts = up.opts;
        let routers = &mut self.procs.routers;
        if let Some((_, down)) = opts.chaos.router_restart
            && !self.router_restarted
            && routers[0].status.is_some()
        {
            let deaths = &mut self.deaths;
            let since = *self.router_down.get_or_insert_with(|| {
                if let Some(f) = routers[0].failure() {
                    eprintln!("fleet up: {f} (as asked: --die-at)");
                    deaths.push((router_role(1), f));
                }
                Instant::now()
            });
            if since.elapsed().as_secs_f64() >= down / opts.time_scale {
                let role = format!("{}-restarted", router_role(1));
                routers[0] = spawn(&opts.exe, &role, &self.procs.router_args[0], &[], &up.logs)?;
                self.router_restarted = true;
                eprintln!("fleet up: {} started again", router_role(1));
            }
        }
        Ok(())
    }

    /// Refuses the run when a robot, a base or the collector failed (but
    /// those killed as `chaos` asked; the leader, robots, bases and
    /// collector asked to stop first), or a router stopped (but site 1's
    /// while it is awaited back).
    fn check_failures(&self, chaos: &Chaos) -> Result<(), FleetError> {
        let p = &self.procs;
        let awaited = self.router_down.is_some() && !self.router_restarted;
        let failed = living(&p.robots, chaos, |i| self.robot_of(i))
            .chain(living(&p.bases, chaos, |i| Member::Base(i as u32 + 1)))
            .chain(living(std::slice::from_ref(&p.collector), chaos, |_| {
                Member::Collector
            }))
            .chain(p.routers.iter().skip(usize::from(awaited)))
            .find_map(Proc::failure);
        if let Some(f) = failed {
            for proc in std::iter::once(&self.leader)
                .chain(&p.robots)
                .chain(&p.bases)
            {
                proc.terminate();
            }
            p.collector.terminate();
            return Err(FleetError::Child(f));
        }
        if let Some(r) = p
            .routers
            .iter()
            .skip(usize::from(awaited))
            .find(|r| r.status.is_some())
        {
            return Err(FleetError::Child(format!("{} stopped early", r.role)));
        }
        Ok(())
    }

    /// A stop request: the leader and the robots told to stop. The leader
    /// done: the robots stop by themselves at `--duration`; one that never
    /// heard the leader would not: given a few seconds, then SIGTERM.
    fn wind_down(&mut self, stop: &StopFlag) {
        if stop.is_raised() && !self.interrupted {
            self.interrupted = true;
            self.leader.terminate();
            for r in &self.procs.robots {
                r.terminate();
            }
        }
        if self.leader.status.is_some() && !self.interrupted && self.leader_failure.is_none() {
            let done_at = *self.leader_done.get_or_insert_with(Instant::now);
            if done_at.elapsed() > Duration::from_secs(5) && !self.robots_told {
                self.robots_told = true;
                for r in &self.procs.robots {
                    r.terminate();
                }
            }
        }
    }

    /// Phase 2: the bases, then the collector. No wait is needed here: each
    /// robot and the leader made sure their router held their last words
    /// before they exited (`net::flush`), and on SIGTERM a base follows the
    /// commands still on their way (its robot's final zero), the collector
    /// records what is (the leader's last samples, the robots' and the
    /// bases' last words), each until its inputs are quiet
    /// (`runtime::Linger`, bounded), so the collector goes last. The
    /// routers last, once nothing is linked to them any more.
    pub(super) fn stop_rest(&mut self, chaos: &Chaos) -> Result<(), FleetError> {
        let p = &mut self.procs;
        stop_all(&mut p.bases, NAP, "a ROS 2 base")?;
        if let Some(proc) = p.operator.as_mut().filter(|proc| proc.status.is_none()) {
            stop_all(std::slice::from_mut(proc), NAP, "the operator's heartbeat")?;
        }
        if let Some(proc) = p.garbage.as_mut() {
            stop_all(std::slice::from_mut(proc), NAP, "fleet garbage")?;
        }
        stop_all(std::slice::from_mut(&mut p.collector), NAP, "the collector")?;
        if let Some(f) = living(std::slice::from_ref(&p.collector), chaos, |_| {
            Member::Collector
        })
        .chain(living(&p.bases, chaos, |i| Member::Base(i as u32 + 1)))
        .find_map(Proc::failure)
        {
            return Err(FleetError::Child(f));
        }
        stop_all(&mut p.routers, NAP, "a router")?;
        if let Some(f) = p.routers.iter().find_map(Proc::failure) {
            return Err(FleetError::Child(f));
        }
        Ok(())
    }

    /// The intruders' ends, each still running asked to stop.
    fn intrusions(&mut self) -> Vec<Intrusion> {
        self.intruders
            .iter_mut()
            .map(|p| {
                if p.status.is_none() {
                    p.terminate();
                }
                Intrusion {
                    role: p.role.clone(),
                    exit: p.status.and_then(|s| s.code()),
                    said: p.last_said(),
                }
            })
            .collect()
    }

    /// Phase 3: every process's report, the fleet's started at `started`
    /// (`started_unix_ns`, UNIX ns), its sites' processes `sites`.
    pub(super) fn report(
        &mut self,
        up: &Layout<'_>,
        sites: Vec<Vec<String>>,
        started: Instant,
        started_unix_ns: u64,
    ) -> Result<UpReport, FleetError> {
        let (opts, plan) = (up.opts, &up.plan);
        let chaos = &opts.chaos;
        let intruders = self.intrusions();
        let wall = started.elapsed().as_secs_f64();
        let leader_report: Option<LeaderReport> = match &self.leader_failure {
            Some(_) => None,
            None => Some(report(&self.leader)?),
        };
        let startup = leader_report
            .as_ref()
            .map(|l| l.clock_start_unix_ns)
            .filter(|&t| t > 0)
            .map(|t| t.saturating_sub(started_unix_ns) as f64 * 1e-9);
        let p = &self.procs;
        let robot_reports = robot_reports(p, chaos, |i| self.robot_of(i))?;
        // A collector killed as asked left no report: its log's gap is said.
        let collector_report: Option<CollectorReport> =
            match living(std::slice::from_ref(&p.collector), chaos, |_| {
                Member::Collector
            })
            .next()
            {
                Some(c) => Some(report(c)?),
                None => None,
            };
        let log_gap = match &collector_report {
            Some(_) => None,
            None => LogGap::of(&opts.out.join("trajectory.csv"), plan.duration),
        };
        let no_latency = crate::latency::LatencyReport::default();
        Ok(UpReport {
            scenario: plan.scenario.name().to_owned(),
            fleet: plan.fleet.name.clone(),
            duration: plan.duration,
            time_scale: opts.time_scale,
            wall,
            startup,
            run: startup.map(|s| wall - s),
            cost: up_cost(
                &self.leader,
                &p.collector,
                (&p.robots, p.hosted.iter().map(Vec::len).sum()),
                &p.bases,
                &p.routers,
            ),
            latency: FleetLatency::of(
                robot_reports.iter().map(|r| (r.agent, &r.latency)),
                collector_report
                    .as_ref()
                    .map_or(&no_latency, |c| &c.latency),
            ),
            safety: crate::robot::SafetyCounts::total(
                robot_reports.iter().filter_map(|r| r.safety.as_ref()),
            ),
            approach: collector_report.as_ref().and_then(|c| c.approach.clone()),
            deadlocked_at_end: robot_reports
                .iter()
                .filter(|r| r.deadlocked_at_end)
                .map(|r| r.agent)
                .collect(),
            leader: leader_report,
            leader_failure: self.leader_failure.clone(),
            deaths: self.deaths.iter().map(|(_, f)| f.clone()).collect(),
            robots: robot_reports,
            onboard: (1..=plan.n as u32)
                .filter(|k| !p.on_hub.contains(k))
                .collect(),
            collector: collector_report,
            intruders,
            log_gap,
            bases: living(&p.bases, chaos, |i| Member::Base(i as u32 + 1))
                .map(report)
                .collect::<Result<_, _>>()?,
            topology: opts.topology,
            router_endpoints: up.net.routers.clone(),
            sites,
            routers: p.routers.iter().map(report).collect::<Result<_, _>>()?,
        })
    }
}

/// Robot process `i`'s member: its robot, or a host's first (a host is
/// never asked to die, [`super::hosts`]).
fn robot_member(p: &Procs, i: usize) -> Member {
    Member::Robot(p.hosted[i][0])
}

/// The robots' reports, in agent order: each robot process's, each host's
/// robots' ([`crate::host::HostReport`]; a robot that failed in a host
/// failed its host, which [`Running::check_failures`] refused). A robot
/// killed as asked has no report (its death is in `deaths`).
fn robot_reports(
    p: &Procs,
    chaos: &Chaos,
    member: impl Fn(usize) -> Member,
) -> Result<Vec<RobotReport>, FleetError> {
    let mut reports = Vec::new();
    for (i, proc) in p.robots.iter().enumerate() {
        if !living(std::slice::from_ref(proc), chaos, |_| member(i)).any(|_| true) {
            continue;
        }
        match p.hosted[i].len() {
            1 => reports.push(report(proc)?),
            _ => {
                let hosted: crate::host::HostReport = report(proc)?;
                reports.extend(hosted.into_iter().filter_map(|h| h.report));
            }
        }
    }
    reports.sort_by_key(|r| r.agent);
    Ok(reports)
}
