//! Many fleet members in one process: a [`Host`] is one [`Task`] made of K
//! tasks (K robots' [`RobotTask`]s, the same sans-IO state machine a robot
//! process runs alone), so the runtime gives them one Zenoh session, one
//! timer and one input queue, and each keeps its own keys, tokens, latch,
//! link-loss policy, neighbours, faults and counters: nothing outside can
//! tell K hosted robots from K processes.
//!
//! - **Inputs** are subscribed once per key expression (the reference, the
//!   fleet command, the halts, every robot's state with a safety filter are
//!   the same for all): a sample is handed to each member that listens to
//!   it, under that member's own input number.
//! - **Outputs** are the members' in turn; a member publishes through its
//!   own numbers, shifted to its place.
//! - **Ticks**: the host wakes at its earliest member's wake and ticks
//!   the members whose wake has come.
//! - **Failure stops that member only**: a member that errs (diverged, a
//!   refused input) or is done is stopped at once (its last words: a
//!   robot commands zero) and its error kept for its report; the others go
//!   on. The host stops when none runs.
//!
//! `echelon fleet host` runs simulated robots this way ([`run`]); `fleet
//! up --robots-per-process K` starts its robots as hosts. A ROS 2 robot
//! keeps a process of its own (its second session is its robot's network).

use serde::Serialize;

use crate::FleetError;
use crate::robot::{Robot, RobotConfig, RobotOptions, RobotReport, RobotTask};
use crate::runtime::{self, Flow, Latching, Linger, Outgoing, Outputs, Sample, Task, WaitFor};

/// How many samples may wait for a host per member, on top of the most
/// any member asks for alone ([`Task::queue`]).
pub const QUEUE_PER_MEMBER: usize = 64;

/// One member of a host: its task, whether it runs, and how it ended.
#[derive(Debug)]
struct Member<T> {
    /// Its name in reports and messages (`robot/3`).
    name: String,
    task: T,
    running: bool,
    /// Its own inputs' count (the number of its latch answers' input).
    inputs: usize,
    /// Whether it holds a latch (asked once: a task builds its keys).
    latches: bool,
    /// Its first output's number among the host's.
    first_output: usize,
    /// Its failure, if it failed; kept for its report.
    error: Option<FleetError>,
    /// It failed taking an input: stop it at the next tick.
    failed_input: bool,
}

/// K tasks as one ([module docs](self)).
#[derive(Debug)]
pub struct Host<T> {
    members: Vec<Member<T>>,
    /// The distinct key expressions the members subscribe to.
    inputs: Vec<String>,
    /// For each of `inputs`: the members that listen, with their own input
    /// number.
    routes: Vec<Vec<(usize, usize)>>,
    outputs: Vec<String>,
    /// Which member answers each latch key (in the order of
    /// [`Latching::answer_on`]), with its own number for it.
    latch_owners: Vec<(usize, usize)>,
    latching: Option<Latching>,
}

/// What a host reports: one entry per member, in order.
#[derive(Debug, Clone, Serialize, serde::Deserialize, PartialEq)]
pub struct Hosted<R> {
    /// The member's name (`robot/3`).
    pub name: String,
    /// Its report (absent when even that failed: the error says why).
    pub report: Option<R>,
    /// Why it stopped before the host did, or failed to stop (absent: it
    /// ran to its end, or to the host's stop).
    pub error: Option<String>,
}

impl<T: Task> Host<T> {
    /// The host of `members` (name, task), in order. Refused: no member,
    /// or members that ask different latch keys (of different fleets).
    pub fn new(members: Vec<(String, T)>) -> Result<Host<T>, FleetError> {
        if members.is_empty() {
            return Err(FleetError::Config(
                "a host needs at least one member".into(),
            ));
        }
        let mut host = Host {
            members: Vec::with_capacity(members.len()),
            inputs: Vec::new(),
            routes: Vec::new(),
            outputs: Vec::new(),
            latch_owners: Vec::new(),
            latching: None,
        };
        for (m, (name, task)) in members.into_iter().enumerate() {
            let keys = task.inputs();
            for (own, key) in keys.iter().enumerate() {
                let at = match host.inputs.iter().position(|k| k == key) {
                    Some(at) => at,
                    None => {
                        host.inputs.push(key.clone());
                        host.routes.push(Vec::new());
                        host.inputs.len() - 1
                    }
                };
                host.routes[at].push((m, own));
            }
            let latching = task.latching();
            let latches = latching.is_some();
            host.add_latching(m, &name, latching)?;
            let first_output = host.outputs.len();
            host.outputs.extend(task.outputs());
            host.members.push(Member {
                name,
                task,
                running: true,
                inputs: keys.len(),
                latches,
                first_output,
                error: None,
                failed_input: false,
            });
        }
        Ok(host)
    }

    /// Adds member `m`'s latch (if any) to the host's: its keys answered by
    /// it, the query the same for all.
    fn add_latching(
        &mut self,
        m: usize,
        name: &str,
        latching: Option<Latching>,
    ) -> Result<(), FleetError> {
        let Some(l) = latching else {
            return Ok(());
        };
        let host = self.latching.get_or_insert_with(|| Latching {
            answer_on: Vec::new(),
            ask: l.ask.clone(),
        });
        if host.ask != l.ask {
            return Err(FleetError::Config(format!(
                "{name} asks the latches of {}, the host's first member those of {}: one host serves one fleet",
                l.ask, host.ask
            )));
        }
        for (own, key) in l.answer_on.into_iter().enumerate() {
            host.answer_on.push(key);
            self.latch_owners.push((m, own));
        }
        Ok(())
    }

    /// The members' tasks, in order.
    pub fn tasks(&self) -> impl Iterator<Item = &T> {
        self.members.iter().map(|m| &m.task)
    }

    /// Member `i`'s task, to change (e.g. a test's fault).
    pub fn task_mut(&mut self, i: usize) -> Option<&mut T> {
        self.members.get_mut(i).map(|m| &mut m.task)
    }

    /// Whether member `i` still runs.
    pub fn is_running(&self, i: usize) -> bool {
        self.members.get(i).is_some_and(|m| m.running)
    }

    /// How many members still run.
    pub fn running(&self) -> usize {
        self.members.iter().filter(|m| m.running).count()
    }
}

impl<T> Member<T>
where
    T: Task,
{
    /// Stops it (its last words through `out`, shifted to its outputs),
    /// keeping the first error it met.
    fn stop(&mut self, out: &mut dyn Outputs) {
        self.running = false;
        let mut shifted = Shifted {
            out,
            by: self.first_output,
        };
        if let Err(e) = self.task.stop(&mut shifted)
            && self.error.is_none()
        {
            self.error = Some(e);
        }
        if let Some(e) = &self.error {
            eprintln!(
                "{}: stopped: {e} (the host's other members go on)",
                self.name
            );
        }
    }

    /// Ticks it at `now`; stops it when it is done or fails.
    fn tick(&mut self, now: f64, out: &mut dyn Outputs) {
        if self.failed_input {
            return self.stop(out);
        }
        let mut shifted = Shifted {
            out: &mut *out,
            by: self.first_output,
        };
        match self.task.tick(now, &mut shifted) {
            Ok(Flow::Continue) => {}
            Ok(Flow::Stop) => self.stop(out),
            Err(e) => {
                self.error = Some(e);
                self.stop(out);
            }
        }
    }
}

/// A member's outputs among the host's: its output `o` is the host's
/// `o + by`.
struct Shifted<'a> {
    out: &'a mut dyn Outputs,
    by: usize,
}

impl Outputs for Shifted<'_> {
    fn send(&mut self, message: Outgoing<'_>) -> Result<(), FleetError> {
        self.out.send(Outgoing {
            output: message.output + self.by,
            ..message
        })
    }

    fn put(&mut self, key: &str, payload: &[u8]) {
        self.out.put(key, payload);
    }
}

impl<T: Task> Task for Host<T> {
    type Report = Vec<Hosted<T::Report>>;

    fn inputs(&self) -> Vec<String> {
        self.inputs.clone()
    }

    fn outputs(&self) -> Vec<String> {
        self.outputs.clone()
    }

    fn tokens(&self) -> Vec<String> {
        self.members.iter().flat_map(|m| m.task.tokens()).collect()
    }

    fn exclusive(&self) -> bool {
        self.members.iter().any(|m| m.task.exclusive())
    }

    fn latching(&self) -> Option<Latching> {
        self.latching.clone()
    }

    fn latched(&self, i: usize) -> Option<Vec<u8>> {
        let &(m, own) = self.latch_owners.get(i)?;
        self.members[m].task.latched(own)
    }

    /// Moves whenever a member's moves (the sum of theirs); unknown when
    /// one member's is.
    fn latch_changes(&self) -> Option<u64> {
        let mut sum = 0u64;
        for m in self.members.iter().filter(|m| m.latches) {
            sum = sum.wrapping_add(m.task.latch_changes()?);
        }
        Some(sum)
    }

    /// Every member's awaited names, under the first one's fleet and
    /// longest timeout.
    fn wait_for(&self) -> Option<WaitFor> {
        let mut all: Option<WaitFor> = None;
        for w in self.members.iter().filter_map(|m| m.task.wait_for()) {
            match &mut all {
                None => all = Some(w),
                Some(a) => {
                    a.timeout = a.timeout.max(w.timeout);
                    for n in w.names {
                        if !a.names.contains(&n) {
                            a.names.push(n);
                        }
                    }
                }
            }
        }
        all
    }

    fn wakes_on_input(&self) -> bool {
        self.members.iter().any(|m| m.task.wakes_on_input())
    }

    fn queue(&self) -> usize {
        let most = self.members.iter().map(|m| m.task.queue()).max();
        most.unwrap_or(runtime::DEFAULT_QUEUE) + QUEUE_PER_MEMBER * self.members.len()
    }

    /// Told to every member: the drops are the host's (its one queue), so
    /// each member's report counts the host's total.
    fn on_dropped(&mut self, total: u64) {
        for m in &mut self.members {
            m.task.on_dropped(total);
        }
    }

    fn batch(&self) -> f64 {
        let batches = self.members.iter().map(|m| m.task.batch());
        batches.fold(f64::INFINITY, f64::min).max(0.0)
    }

    fn linger(&self) -> Option<Linger> {
        self.members.iter().find_map(|m| m.task.linger())
    }

    fn started(&mut self, unix_ns: u64) {
        for m in &mut self.members {
            m.task.started(unix_ns);
        }
    }

    /// Hands the sample to every running member that listens to its key
    /// (the latch answers: to every member that holds a latch).
    fn on_input(&mut self, input: usize, sample: &Sample<'_>) -> Result<(), FleetError> {
        let latch = input == self.inputs.len();
        let routes: &[(usize, usize)] = match self.routes.get(input) {
            Some(r) => r,
            None if latch => &[],
            None => return Err(FleetError::Config(format!("a host has no input {input}"))),
        };
        let hand = |m: &mut Member<T>, own: usize| {
            if m.running
                && !m.failed_input
                && let Err(e) = m.task.on_input(own, sample)
            {
                m.error = Some(e);
                m.failed_input = true;
            }
        };
        if latch {
            for m in self
                .members
                .iter_mut()
                .filter(|m| m.task.latching().is_some())
            {
                let own = m.inputs;
                hand(m, own);
            }
        } else {
            for &(m, own) in routes {
                hand(&mut self.members[m], own);
            }
        }
        Ok(())
    }

    /// The earliest wake of a running member (at once: one to stop).
    fn next_wake(&self) -> f64 {
        let running = self.members.iter().filter(|m| m.running);
        running
            .map(|m| match m.failed_input {
                true => f64::NEG_INFINITY,
                false => m.task.next_wake(),
            })
            .fold(f64::INFINITY, f64::min)
    }

    /// Ticks every running member whose wake has come (as the runtime
    /// ticks a task alone: not before its wake, so a member's ticks fall
    /// when they would in a process of its own).
    fn tick(&mut self, now: f64, out: &mut dyn Outputs) -> Result<Flow, FleetError> {
        for m in self.members.iter_mut().filter(|m| m.running) {
            if m.failed_input || m.task.next_wake() <= now {
                m.tick(now, out);
            }
        }
        Ok(match self.members.iter().any(|m| m.running) {
            true => Flow::Continue,
            false => Flow::Stop,
        })
    }

    /// Stops every member still running (each commands zero first).
    fn stop(&mut self, out: &mut dyn Outputs) -> Result<(), FleetError> {
        for m in self.members.iter_mut().filter(|m| m.running) {
            m.stop(out);
        }
        Ok(())
    }

    fn report(self) -> Result<Self::Report, FleetError> {
        Ok(self
            .members
            .into_iter()
            .map(|m| {
                let (report, failed) = match m.task.report() {
                    Ok(r) => (Some(r), None),
                    Err(e) => (None, Some(e)),
                };
                Hosted {
                    name: m.name,
                    report,
                    error: m.error.or(failed).map(|e| e.to_string()),
                }
            })
            .collect())
    }
}

/// Options of `fleet host`: the robots, each as `fleet robot` would run it
/// alone; they must share one process's scenario, clock and network.
#[derive(Debug, Clone)]
pub struct HostOptions {
    /// The robots, in order.
    pub robots: Vec<RobotOptions>,
}

/// What `fleet host` reports: each robot's report, or why it has none.
pub type HostReport = Vec<Hosted<RobotReport>>;

/// Checks that `robots` can share one process: simulated, of one scenario,
/// fleet, clock and network, not in the secure mode (each robot's
/// certificate names it alone), no agent twice.
fn check_shared(robots: &[RobotOptions]) -> Result<(), FleetError> {
    let Some(first) = robots.first() else {
        return Err(FleetError::Config("fleet host: no robot to host".into()));
    };
    let p = &first.process;
    let mut seen = std::collections::BTreeSet::new();
    for r in robots {
        let q = &r.process;
        let why = if r.ros2 {
            Some("it drives a ROS 2 robot, which keeps a process of its own (fleet robot --ros2)")
        } else if q.net.secure.is_some() {
            Some("the secure mode gives each robot its own certificate, so its own process")
        } else if q.scenario.source() != p.scenario.source() || q.fleet != p.fleet {
            Some("its scenario or fleet differs from the first robot's")
        } else if q.time_scale != p.time_scale || q.duration != p.duration || q.die_at != p.die_at {
            Some("its clock (time scale, duration, die-at) differs from the first robot's")
        } else if q.net != p.net {
            Some("its network differs from the first robot's")
        } else if !seen.insert(r.agent) {
            Some("it is given twice")
        } else {
            None
        };
        if let Some(why) = why {
            return Err(FleetError::Config(format!(
                "fleet host: robot {} cannot share the host: {why}",
                r.agent
            )));
        }
    }
    Ok(())
}

/// Runs the simulated robots of `opts` in this process until their
/// duration or the stop flag: a [`Host`] of [`RobotTask`]s on the fleet
/// runtime. Each robot's report, in order; a robot that failed has its
/// error in its entry, and the others ran on.
pub fn run(opts: &HostOptions, stop: &crate::StopFlag) -> Result<HostReport, FleetError> {
    check_shared(&opts.robots)?;
    let first = &opts.robots[0];
    let resolved = first.process.resolve()?;
    let mut members = Vec::with_capacity(opts.robots.len());
    for r in &opts.robots {
        let config = RobotConfig::from_plan(
            &resolved.plan,
            &resolved.settings,
            r.agent,
            r.faults,
            r.process.duration,
        )?;
        let config = RobotConfig {
            operator_token: r.operator_token.clone(),
            ..config
        };
        let robot = Robot::simulated(config, crate::net::rand_source());
        let task = RobotTask::new(robot, resolved.keys.clone()).dying_at(r.process.die_at);
        let name = crate::role::Member::Robot(r.agent).liveliness();
        members.push((name, task));
    }
    let host = Host::new(members)?;
    let net = &first.process.net;
    let address = crate::probe::local_address_towards(&net.connect);
    let keys = resolved.keys.clone();
    let agents: Vec<u32> = opts.robots.iter().map(|r| r.agent).collect();
    // Each robot answers its own probe (`fleet doctor`, the hub's join line).
    let probes = move |s: &zenoh::Session| {
        (agents.iter())
            .map(|&k| {
                let member = crate::role::Member::Robot(k);
                crate::probe::declare_from(s, &keys, member, address.clone())
            })
            .collect::<Result<Vec<_>, _>>()
    };
    let clock = first.process.clock();
    runtime::run_on(|s| Ok((host, probes(s)?)), net, clock, stop)?.report()
}

#[cfg(test)]
mod tests;
