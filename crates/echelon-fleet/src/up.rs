//! `echelon fleet up`: the whole fleet on loopback, one OS process per role,
//! started in order, stopped cleanly, summarised.
//!
//! With the router topology (the default) a router (`fleet router`) starts
//! first on a free loopback port (with `--sites S`, S routers, each linked to
//! the ones before it, robots spread over them round-robin, the collector and
//! the leader on site 1's); every other process is a Zenoh client with
//! exactly one link, to its site's router. With the mesh topology every
//! process is a peer that listens on its own free loopback port and connects
//! to every process started before it (N² links: a handful of robots only).
//! The collector starts first, then robot 1 … N, then the leader; the
//! leader waits for every liveliness token before starting the clock. Robots
//! and leader stop at `--duration`; the collector is then sent SIGTERM and
//! closes its files. Each child's stderr goes to `DIR/logs/<role>.log`; its
//! last stdout line (kept in `DIR/logs/<role>.out`) is its JSON report.

use std::io::{BufRead, BufReader};
use std::net::{TcpListener, UdpSocket};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use serde::Serialize;

use echelon::scenario::{Overrides, Scenario};

use crate::collector::CollectorReport;
use crate::cost::{self, ProcessCost, RoleCost};
use crate::faults::FaultSpec;
use crate::latency::FleetLatency;
use crate::leader::LeaderReport;
use crate::robot::RobotReport;
use crate::role::{Member, Role};
use crate::ros2::base::BaseReport;

use crate::router::RouterReport;
use crate::{FleetError, StopFlag};

/// The summary `fleet up` writes.
pub const UP_SUMMARY_FILE: &str = "fleet-summary.json";
/// Each process's listening endpoint, written when `fleet up` starts them.
pub const ENDPOINTS_FILE: &str = "endpoints.json";

/// How `fleet up` links its processes.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Topology {
    /// One router per site; every process a client with one link to it.
    #[default]
    Router,
    /// Every process a peer linked to every other (N² links).
    Mesh,
}

/// The role name of site `s`'s router (from 1) in logs, reports and
/// `endpoints.json`: `router/<s>`.
pub fn router_role(site: usize) -> String {
    format!("{}/{site}", Role::Router)
}

/// Options of `fleet up`.
#[derive(Debug, Clone)]
pub struct UpOptions {
    /// Scenario name or path, as the children will resolve it.
    pub scenario: String,
    /// Output directory.
    pub out: PathBuf,
    /// Fleet time to run, s (absent: the scenario's `sim.duration`).
    pub duration: Option<f64>,
    /// Clock speed-up `K`.
    pub time_scale: f64,
    /// Faults injected on what robots receive.
    pub faults: FaultSpec,
    /// Certificates directory: run in secure mode (mutual TLS + access control).
    pub secure: Option<PathBuf>,
    /// The `echelon` binary to start the children with.
    pub exe: PathBuf,
    /// Robots drive ROS 2 bases: one simulated base per robot
    /// (`fleet base --ros2`), all robot↔base traffic in ROS 2's format.
    pub ros2: bool,
    /// Through routers (default) or a peer mesh.
    pub topology: Topology,
    /// Router topology: the number of sites (routers), ≥ 1.
    pub sites: usize,
}

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
    /// Robots (agent numbers) their filter kept from their slot at the end
    /// (each robot's `deadlocked_at_end`).
    pub deadlocked_at_end: Vec<u32>,
    /// The leader's report.
    pub leader: LeaderReport,
    /// Each robot's report, agent 1 first.
    pub robots: Vec<RobotReport>,
    /// The collector's report.
    pub collector: CollectorReport,
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

/// CPU and peak memory of every process of `fleet up` ([`crate::cost`]).
#[derive(Debug, Clone, Default, Serialize)]
pub struct UpCost {
    /// The leader.
    pub leader: RoleCost,
    /// The collector.
    pub collector: RoleCost,
    /// The robots (`cpu_mean`: CPU seconds per robot).
    pub robots: RoleCost,
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

/// A started child, killed if still running when dropped (a failing test or
/// an error never leaves processes behind).
struct Proc {
    role: String,
    child: Child,
    log: PathBuf,
    /// Where its stdout goes; its last JSON line is its report.
    stdout: PathBuf,
    report: Option<serde_json::Value>,
    status: Option<std::process::ExitStatus>,
    /// CPU seconds, read when it exited (before it was reaped).
    cpu: Option<f64>,
    /// Peak RSS so far, bytes, and when it was last sampled.
    max_rss: Option<u64>,
    rss_sampled: Option<Instant>,
}

impl Proc {
    fn terminate(&self) {
        let pid = rustix::process::Pid::from_child(&self.child);
        let _ = rustix::process::kill_process(pid, rustix::process::Signal::TERM);
    }

    /// Whether it has exited, not reaping it (so that `/proc` still holds
    /// its CPU time); `true` if that cannot be told.
    fn exited(&self) -> bool {
        use rustix::process::{Pid, WaitId, WaitIdOptions, waitid};
        let pid = Pid::from_child(&self.child);
        let options = WaitIdOptions::EXITED | WaitIdOptions::NOWAIT | WaitIdOptions::NOHANG;
        !matches!(waitid(WaitId::Pid(pid), options), Ok(None))
    }

    /// Its cost so far.
    fn cost(&self) -> ProcessCost {
        ProcessCost {
            role: self.role.clone(),
            cpu: self.cpu,
            max_rss: self.max_rss,
        }
    }

    /// Polls; samples its peak memory while it runs, reads its CPU time
    /// when it exits, then reaps it and reads the report line from stdout.
    fn poll(&mut self) -> Result<bool, FleetError> {
        if self.status.is_some() {
            return Ok(true);
        }
        if !self.exited() {
            if self
                .rss_sampled
                .is_none_or(|t| t.elapsed() >= cost::MEMORY_PERIOD)
            {
                self.rss_sampled = Some(Instant::now());
                if let Some(m) = cost::peak_rss(self.child.id()) {
                    self.max_rss = Some(self.max_rss.unwrap_or(0).max(m));
                }
            }
            return Ok(false);
        }
        if self.cpu.is_none() {
            self.cpu = cost::cpu_seconds(self.child.id());
        }
        match self.child.try_wait() {
            Ok(Some(status)) => {
                self.status = Some(status);
                let last = std::fs::File::open(&self.stdout).ok().and_then(|out| {
                    BufReader::new(out)
                        .lines()
                        .map_while(Result::ok)
                        .filter(|l| l.trim_start().starts_with('{'))
                        .last()
                });
                self.report = last.and_then(|l| serde_json::from_str(&l).ok());
                Ok(true)
            }
            Ok(None) => Ok(false),
            Err(e) => Err(FleetError::Child(format!("{}: {e}", self.role))),
        }
    }

    fn failure(&self) -> Option<String> {
        let status = self.status?;
        if status.success() {
            return None;
        }
        let tail = std::fs::read_to_string(&self.log)
            .unwrap_or_default()
            .lines()
            .rev()
            .find(|l| !l.trim().is_empty())
            .unwrap_or("")
            .to_owned();
        Some(format!(
            "{} exited with {status} ({}: {tail})",
            self.role,
            self.log.display()
        ))
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        if self.status.is_none() && matches!(self.child.try_wait(), Ok(None)) {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// The cost of every process, per role and in all.
fn up_cost(
    leader: &Proc,
    collector: &Proc,
    robots: &[Proc],
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
    UpCost {
        leader: RoleCost::of(&leader),
        collector: RoleCost::of(&collector),
        robots: RoleCost::of(&robots),
        bases: (!bases.is_empty()).then(|| RoleCost::of(&bases)),
        routers: (!routers.is_empty()).then(|| RoleCost::of(&routers)),
        total: RoleCost::of(&processes),
        processes,
    }
}

/// Polls every one of `procs` (none skipped); whether all have exited.
fn poll_all<'a>(procs: impl IntoIterator<Item = &'a mut Proc>) -> Result<bool, FleetError> {
    let mut all = true;
    for p in procs {
        all &= p.poll()?;
    }
    Ok(all)
}

/// Free loopback ports for a Zenoh link protocol: UDP ports for QUIC, else
/// TCP ports.
pub fn free_ports_for(proto: &str, n: usize) -> Result<Vec<u16>, FleetError> {
    match proto {
        "quic" => held_ports(n, "UDP", || {
            let socket = UdpSocket::bind("127.0.0.1:0")?;
            Ok((socket.local_addr()?.port(), socket))
        }),
        _ => free_ports(n),
    }
}

/// Free loopback TCP ports (bound then released: each is free right now).
pub fn free_ports(n: usize) -> Result<Vec<u16>, FleetError> {
    held_ports(n, "TCP", || {
        let listener = TcpListener::bind("127.0.0.1:0")?;
        Ok((listener.local_addr()?.port(), listener))
    })
}

/// `n` ports from `bind`, all bound at once (so they differ), released on
/// return.
fn held_ports<S>(
    n: usize,
    kind: &str,
    bind: impl Fn() -> std::io::Result<(u16, S)>,
) -> Result<Vec<u16>, FleetError> {
    let held = (0..n)
        .map(|_| bind())
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| FleetError::Config(format!("no free loopback {kind} port: {e}")))?;
    Ok(held.into_iter().map(|(port, _)| port).collect())
}

/// How `fleet up`'s processes link: the routers' endpoints (router topology)
/// or every process's own port (mesh).
struct Links {
    topology: Topology,
    proto: &'static str,
    /// Router topology: site `s`'s router endpoint at `s`.
    routers: Vec<String>,
    /// Mesh: process `i`'s port at `i`.
    ports: Vec<u16>,
}

impl Links {
    fn new(opts: &UpOptions, proto: &'static str, processes: usize) -> Result<Links, FleetError> {
        let (routers, ports) = match opts.topology {
            Topology::Router => {
                let ports = free_ports_for(proto, opts.sites)?;
                let routers = ports
                    .iter()
                    .map(|p| format!("{proto}/127.0.0.1:{p}"))
                    .collect();
                (routers, Vec::new())
            }
            Topology::Mesh => (Vec::new(), free_ports_for(proto, processes)?),
        };
        Ok(Links {
            topology: opts.topology,
            proto,
            routers,
            ports,
        })
    }

    /// Mesh: process `i`'s endpoint.
    fn peer(&self, i: usize) -> String {
        format!("{}/127.0.0.1:{}", self.proto, self.ports[i])
    }

    /// The Zenoh arguments of process `i` (of site `site`, from 0).
    fn args(&self, i: usize, site: usize) -> Vec<String> {
        match self.topology {
            Topology::Router => vec![
                "--mode".to_owned(),
                "client".to_owned(),
                "--connect".to_owned(),
                self.routers[site].clone(),
            ],
            Topology::Mesh => {
                let mut a = vec!["--listen".to_owned(), self.peer(i)];
                for j in 0..i {
                    a.extend(["--connect".to_owned(), self.peer(j)]);
                }
                a
            }
        }
    }
}

fn spawn(exe: &Path, role: &str, args: &[String], logs: &Path) -> Result<Proc, FleetError> {
    let log = logs.join(format!("{}.log", role.replace('/', "-")));
    let file = std::fs::File::create(&log).map_err(FleetError::io(&log))?;
    // Stdout goes to a file, not a pipe: a report longer than the pipe's
    // buffer (the collector's, with a hundred robots) would block the child
    // in its last write while `fleet up` waits for it to exit.
    let stdout = logs.join(format!("{}.out", role.replace('/', "-")));
    let out = std::fs::File::create(&stdout).map_err(FleetError::io(&stdout))?;
    let child = Command::new(exe)
        .args(args)
        .stdin(Stdio::null())
        .stdout(out)
        .stderr(file)
        .spawn()
        .map_err(|e| FleetError::Child(format!("starting {role} ({}): {e}", exe.display())))?;
    Ok(Proc {
        role: role.to_owned(),
        child,
        log,
        stdout,
        report: None,
        status: None,
        cpu: None,
        max_rss: None,
        rss_sampled: None,
    })
}

/// Runs the fleet and returns every process's report.
pub fn run(opts: &UpOptions, stop: &StopFlag) -> Result<UpReport, FleetError> {
    let scenario = Scenario::resolve(&opts.scenario)?;
    let fleet = scenario.fleet()?;
    let built = scenario.build(&Overrides::default())?;
    let n = built.plan.agents().len();
    for k in 1..=n as u32 {
        crate::robot::agent_spec(&scenario, k)?;
    }
    match opts.topology {
        Topology::Router if opts.sites == 0 || opts.sites > n.max(1) => {
            return Err(FleetError::Config(format!(
                "--sites {}: between 1 and the number of robots ({n})",
                opts.sites
            )));
        }
        Topology::Mesh if opts.sites != 1 => {
            return Err(FleetError::Config(
                "--sites needs the router topology".into(),
            ));
        }
        _ => {}
    }
    let duration = opts.duration.unwrap_or(built.plan.config().duration);
    let logs = opts.out.join("logs");
    std::fs::create_dir_all(&logs).map_err(FleetError::io(&logs))?;

    let proto = crate::net::link_protocol(opts.secure.is_some());
    // Start order: the routers (router topology), the collector, the ROS 2
    // bases (with --ros2), the robots, the leader; in a mesh also the order
    // of their ports.
    let bases = if opts.ros2 { n } else { 0 };
    let robot_at = |k: usize| bases + k;
    let leader_at = bases + n + 1;
    let net = Links::new(opts, proto, leader_at + 1)?;
    let secure_args = |identity: &str| -> Vec<String> {
        match &opts.secure {
            Some(dir) => vec![
                "--secure".to_owned(),
                dir.display().to_string(),
                "--identity".to_owned(),
                identity.to_owned(),
                "--robots".to_owned(),
                n.to_string(),
            ],
            None => Vec::new(),
        }
    };
    // Process `i`'s site (router topology): robots and their bases round-robin,
    // the collector and the leader on site 1.
    let site_of = |i: usize| match i {
        0 => 0,
        i if i == leader_at => 0,
        i => ((i - 1) % n) % net.routers.len().max(1),
    };
    let common = |i: usize, identity: &str| -> Vec<String> {
        let mut a = vec!["--fleet".to_owned(), fleet.name.clone()];
        a.extend(net.args(i, site_of(i)));
        a.extend(secure_args(identity));
        a
    };
    // Where each process listens, for tools (or tests) that want to join.
    let mut endpoints = serde_json::Map::new();
    endpoints.insert(
        "topology".into(),
        serde_json::to_value(opts.topology).map_err(echelon_mcap::McapLogError::from)?,
    );
    match opts.topology {
        Topology::Router => {
            for (s, e) in net.routers.iter().enumerate() {
                endpoints.insert(router_role(s + 1), e.clone().into());
            }
        }
        Topology::Mesh => {
            endpoints.insert(Role::Collector.name().into(), net.peer(0).into());
            for k in 1..=n {
                endpoints.insert(
                    Member::Robot(k as u32).liveliness(),
                    net.peer(robot_at(k)).into(),
                );
            }
            for k in 1..=bases {
                endpoints.insert(Member::Base(k as u32).liveliness(), net.peer(k).into());
            }
            endpoints.insert(Role::Leader.name().into(), net.peer(leader_at).into());
        }
    }
    crate::write_json_file(&opts.out.join(ENDPOINTS_FILE), &endpoints)?;
    let mut sites = vec![Vec::new(); net.routers.len()];
    for i in 0..=leader_at {
        let role = match i {
            0 => Role::Collector.name().to_owned(),
            i if i == leader_at => Role::Leader.name().to_owned(),
            i if i <= bases => Member::Base(i as u32).liveliness(),
            i => Member::Robot((i - bases) as u32).liveliness(),
        };
        if let Some(site) = sites.get_mut(site_of(i)) {
            site.push(role);
        }
    }
    let mut routers = Vec::with_capacity(net.routers.len());
    for (s, e) in net.routers.iter().enumerate() {
        let mut args = vec!["fleet".to_owned(), Role::Router.name().to_owned()];
        if opts.ros2 {
            args.push(opts.scenario.clone());
        }
        args.extend(["--listen".to_owned(), e.clone()]);
        for other in &net.routers[..s] {
            args.extend(["--connect".to_owned(), other.clone()]);
        }
        args.extend(secure_args(&Member::Router.identity()));
        routers.push(spawn(&opts.exe, &router_role(s + 1), &args, &logs)?);
    }
    let scale = opts.time_scale.to_string();
    let dur = duration.to_string();
    let started = Instant::now();
    let started_unix_ns = crate::unix_nanos();

    let mut args = vec![
        "fleet".to_owned(),
        Role::Collector.name().to_owned(),
        "--out".to_owned(),
        opts.out.display().to_string(),
        // For its trajectory.csv's columns (and, with --ros2, its topics).
        opts.scenario.clone(),
    ];
    if opts.ros2 {
        args.push("--ros2".to_owned());
    }
    args.extend(common(0, &Member::Collector.identity()));
    let mut collector = spawn(&opts.exe, Role::Collector.name(), &args, &logs)?;

    let mut base_procs = Vec::with_capacity(bases);
    for k in 1..=bases {
        let mut args = vec![
            "fleet".to_owned(),
            Role::Base.name().to_owned(),
            opts.scenario.clone(),
            "--ros2".to_owned(),
            "--agent".to_owned(),
            k.to_string(),
            "--time-scale".to_owned(),
            scale.clone(),
        ];
        args.extend(common(k, &Member::Base(k as u32).identity()));
        base_procs.push(spawn(
            &opts.exe,
            &Member::Base(k as u32).liveliness(),
            &args,
            &logs,
        )?);
    }

    let mut robots = Vec::with_capacity(n);
    for k in 1..=n {
        let mut args = vec![
            "fleet".to_owned(),
            Role::Robot.name().to_owned(),
            opts.scenario.clone(),
            "--agent".to_owned(),
            k.to_string(),
            "--duration".to_owned(),
            dur.clone(),
            "--time-scale".to_owned(),
            scale.clone(),
            "--seed".to_owned(),
            opts.faults.seed.to_string(),
        ];
        if opts.faults.loss > 0.0 {
            args.extend(["--loss".to_owned(), opts.faults.loss.to_string()]);
        }
        if opts.faults.delay > 0.0 {
            args.extend(["--delay".to_owned(), (opts.faults.delay * 1e3).to_string()]);
        }
        if let Some((s, l)) = opts.faults.outage {
            args.extend(["--outage".to_owned(), format!("{s}:{l}")]);
        }
        if opts.ros2 {
            // Its robot is the simulated base started above, on this clock.
            args.extend(["--ros2".to_owned(), "--simulated-base".to_owned()]);
        }
        args.extend(common(robot_at(k), &Member::Robot(k as u32).identity()));
        robots.push(spawn(
            &opts.exe,
            &Member::Robot(k as u32).liveliness(),
            &args,
            &logs,
        )?);
    }

    let mut args = vec![
        "fleet".to_owned(),
        Role::Leader.name().to_owned(),
        opts.scenario.clone(),
        "--duration".to_owned(),
        dur.clone(),
        "--time-scale".to_owned(),
        scale.clone(),
        "--wait-for".to_owned(),
        Role::Collector.name().to_owned(),
    ];
    for k in 1..=n {
        args.extend([
            "--wait-for".to_owned(),
            Member::Robot(k as u32).liveliness(),
        ]);
    }
    for k in 1..=bases {
        args.extend(["--wait-for".to_owned(), Member::Base(k as u32).liveliness()]);
    }
    args.extend(common(leader_at, &Member::Leader.identity()));
    let mut leader = spawn(&opts.exe, Role::Leader.name(), &args, &logs)?;

    // Generous: connection set-up, then the run in real time, then the wind-down.
    let deadline = Duration::from_secs_f64(60.0 + 2.0 * duration / opts.time_scale);
    let nap = Duration::from_millis(25);
    let mut interrupted = false;
    let mut leader_done: Option<Instant> = None;
    let mut robots_told = false;
    // 1. Leader and robots run to the end (or a failure, or a signal).
    loop {
        let all_done = poll_all(std::iter::once(&mut leader).chain(&mut robots))?;
        poll_all(
            std::iter::once(&mut collector)
                .chain(&mut base_procs)
                .chain(&mut routers),
        )?;
        let failed = std::iter::once(&leader)
            .chain(&robots)
            .chain(&base_procs)
            .chain(std::iter::once(&collector))
            .chain(&routers)
            .find_map(Proc::failure);
        if let Some(f) = failed {
            for p in std::iter::once(&leader).chain(&robots).chain(&base_procs) {
                p.terminate();
            }
            collector.terminate();
            return Err(FleetError::Child(f));
        }
        if let Some(r) = routers.iter().find(|r| r.status.is_some()) {
            return Err(FleetError::Child(format!("{} stopped early", r.role)));
        }
        if all_done {
            break;
        }
        if collector.status.is_some() {
            return Err(FleetError::Child("the collector stopped early".into()));
        }
        if stop.is_raised() && !interrupted {
            interrupted = true;
            leader.terminate();
            for r in &robots {
                r.terminate();
            }
        }
        if leader.status.is_some() && !interrupted {
            // Robots stop by themselves at --duration; one that never heard
            // the leader would not: give them a few seconds, then SIGTERM.
            let done_at = *leader_done.get_or_insert_with(Instant::now);
            if done_at.elapsed() > Duration::from_secs(5) && !robots_told {
                robots_told = true;
                for r in &robots {
                    r.terminate();
                }
            }
        }
        if started.elapsed() > deadline {
            return Err(FleetError::Child(format!(
                "the fleet did not finish within {:.0} s",
                deadline.as_secs_f64()
            )));
        }
        std::thread::sleep(nap);
    }
    // 2. Let the last messages reach the collector, then stop it and the
    // bases (after the robots' last, zero, command).
    std::thread::sleep(Duration::from_millis(300));
    collector.terminate();
    for b in &base_procs {
        b.terminate();
    }
    let wind_down = Instant::now();
    while !poll_all(std::iter::once(&mut collector).chain(&mut base_procs))? {
        if wind_down.elapsed() > Duration::from_secs(30) {
            return Err(FleetError::Child(
                "the collector or a ROS 2 base did not stop".into(),
            ));
        }
        std::thread::sleep(nap);
    }
    if let Some(f) = std::iter::once(&collector)
        .chain(&base_procs)
        .find_map(Proc::failure)
    {
        return Err(FleetError::Child(f));
    }
    // The routers last, once nothing is linked to them any more.
    for r in &routers {
        r.terminate();
    }
    let wind_down = Instant::now();
    while !poll_all(&mut routers)? {
        if wind_down.elapsed() > Duration::from_secs(30) {
            return Err(FleetError::Child("a router did not stop".into()));
        }
        std::thread::sleep(nap);
    }
    if let Some(f) = routers.iter().find_map(Proc::failure) {
        return Err(FleetError::Child(f));
    }
    let wall = started.elapsed().as_secs_f64();
    let leader_report: LeaderReport = report(&leader)?;
    let startup = Some(leader_report.clock_start_unix_ns)
        .filter(|&t| t > 0)
        .map(|t| t.saturating_sub(started_unix_ns) as f64 * 1e-9);
    let robot_reports: Vec<RobotReport> = robots.iter().map(report).collect::<Result<_, _>>()?;
    let collector_report: CollectorReport = report(&collector)?;
    let up = UpReport {
        scenario: scenario.name().to_owned(),
        fleet: fleet.name.clone(),
        duration,
        time_scale: opts.time_scale,
        wall,
        startup,
        run: startup.map(|s| wall - s),
        cost: up_cost(&leader, &collector, &robots, &base_procs, &routers),
        latency: FleetLatency::of(
            robot_reports.iter().map(|r| (r.agent, &r.latency)),
            &collector_report.latency,
        ),
        safety: crate::robot::SafetyCounts::total(
            robot_reports.iter().filter_map(|r| r.safety.as_ref()),
        ),
        deadlocked_at_end: robot_reports
            .iter()
            .filter(|r| r.deadlocked_at_end)
            .map(|r| r.agent)
            .collect(),
        leader: leader_report,
        robots: robot_reports,
        collector: collector_report,
        bases: base_procs.iter().map(report).collect::<Result<_, _>>()?,
        topology: opts.topology,
        router_endpoints: net.routers.clone(),
        sites,
        routers: routers.iter().map(report).collect::<Result<_, _>>()?,
    };
    crate::write_json_file(&opts.out.join(UP_SUMMARY_FILE), &up)?;
    Ok(up)
}

/// A process's report read back as its role's type: an error naming the
/// process when it printed none or one that does not parse (a renamed or
/// missing field is refused, never read as 0).
fn report<T: serde::de::DeserializeOwned>(p: &Proc) -> Result<T, FleetError> {
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
