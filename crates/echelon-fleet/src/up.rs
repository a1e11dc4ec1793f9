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
//! and leader stop at `--duration`; the bases, then the collector, are then
//! sent SIGTERM: each takes what is still on its way until its inputs are
//! quiet, and the collector closes its files. Each child's stderr goes to
//! `DIR/logs/<role>.log`; its last stdout line (kept in
//! `DIR/logs/<role>.out`) is its JSON report.
//!
//! The fleet's operator token ([`crate::token`]: `ECHELON_OPERATOR_TOKEN`
//! if set, else a new random one) is written to `DIR/operator-token` (mode
//! 0600) and given to the robots, the leader and the collector in that
//! variable: they obey only the resumes signed with it (`fleet resume
//! --token-file DIR/operator-token`), and the dashboard's URL carries it.
//!
//! With `ros2`, one simulated ROS 2 base per robot (`fleet base --ros2`)
//! starts before the robots, on the fleet's network. With `ros2` and `real`
//! there are none: each robot process reaches its real robot at the agent's
//! `ros2.connect` in a session of its own (docs/ros2.md, "Two networks"),
//! and joins the fleet once the robot's odometry arrives; real time only.

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::Serialize;

use echelon::scenario::{Overrides, Placement, Scenario};

use crate::faults::{Chaos, FaultSpec};
use crate::role::{Member, Role};
use crate::token::{OperatorToken, TOKEN_ENV, TOKEN_FILE};

use crate::{FleetError, StopFlag};

mod hosts;
mod join;
mod ports;
mod process;
mod report;
mod robots;
mod spawn;
mod supervise;
pub use hosts::{ONE_EACH_UP_TO, PROCESSES_PER_CORE};
pub use ports::{free_ports, free_ports_for};
use process::Proc;
pub use report::{Intrusion, LogGap, UpCost, UpReport};
pub use robots::ROBOTS_DIR;
use spawn::{Layout, Planned, Procs};
use supervise::Running;

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
    /// With `ros2`: the bases are real robots, each behind its own router
    /// (its agent's `ros2.connect`): no simulated bases, time scale 1, and
    /// each robot process reaches its robot in a session of its own.
    pub real: bool,
    /// Through routers (default) or a peer mesh.
    pub topology: Topology,
    /// Router topology: the number of sites (routers), ≥ 1.
    pub sites: usize,
    /// Serve the live fleet to Foxglove on this address: the collector's
    /// `--foxglove` ([`crate::collector::LiveFeed`]).
    pub foxglove: Option<std::net::SocketAddr>,
    /// Serve the live dashboard on this address: the collector's
    /// `--dashboard` ([`crate::collector::Dashboard`]).
    pub dashboard: Option<std::net::SocketAddr>,
    /// The collector's state-log rate, states per robot per second
    /// (`--log-rate`; `None`: every state).
    pub log_rate: Option<f64>,
    /// With `ros2` (simulated bases): hazards base `k` reports, `(k,
    /// window)` (`fleet base --hazard`).
    pub hazards: Vec<(u32, crate::ros2::hazard::HazardWindow)>,
    /// Faults injected into its own processes (the fault matrix's rows:
    /// `--die-at`, `--freeze-odometry`, a robot's `--outage`,
    /// `--fault-at`).
    pub chaos: crate::faults::Chaos,
    /// Hub mode: the router listens where told, the on-board robots join
    /// by themselves, and the reference starts once every robot joined.
    pub hub: Option<HubOptions>,
    /// The operator token (`None`: `ECHELON_OPERATOR_TOKEN`, else a new one).
    pub token: Option<OperatorToken>,
    /// How many simulated robots each robot process runs (`fleet host`;
    /// `None`: one each up to [`ONE_EACH_UP_TO`] robots, else a few
    /// processes per core; always one each on ROS 2 bases, in the secure
    /// mode, in a mesh, or with a robot's rehearsed kill or clock step).
    pub robots_per_process: Option<usize>,
}

/// `fleet up --hub`: where the hub's router listens and how long it waits
/// for the robots.
#[derive(Debug, Clone, PartialEq)]
pub struct HubOptions {
    /// The router's endpoints (`--listen`), each with a port of its own.
    pub listen: Vec<String>,
    /// The longest wait for every robot to join, real s (`--wait`).
    pub wait: f64,
}

impl UpOptions {
    /// A simulated fleet of `scenario` on loopback through one router, in
    /// plain mode, at time scale 1 for the scenario's duration, no faults,
    /// no live view, every state logged: the base of `fleet bench` and
    /// `fleet faults`, each changing what it needs.
    pub fn simulated(scenario: String, out: PathBuf, exe: PathBuf) -> UpOptions {
        UpOptions {
            scenario,
            out,
            duration: None,
            time_scale: 1.0,
            faults: FaultSpec::default(),
            secure: None,
            exe,
            ros2: false,
            real: false,
            topology: Topology::Router,
            sites: 1,
            foxglove: None,
            dashboard: None,
            log_rate: None,
            hazards: Vec::new(),
            chaos: Chaos::default(),
            hub: None,
            token: None,
            robots_per_process: None,
        }
    }
}

/// `fleet up --ros2 --real`'s refusals, before anything starts: real robots
/// run in real time, and each agent names its robot's router, reachable
/// with the fleet's mode (plain, or secure with certificates).
fn check_real(
    opts: &UpOptions,
    links: &[echelon::scenario::Ros2Link],
    placement: &[Placement],
    n: usize,
) -> Result<(), FleetError> {
    if !opts.ros2 {
        return Err(FleetError::Config(
            "--real drives ROS 2 robots: give --ros2 too".into(),
        ));
    }
    if opts.time_scale != 1.0 {
        return Err(FleetError::Config(format!(
            "--time-scale {}: real robots run in real time, so `fleet up --real` runs at 1 (rehearse faster on simulated bases: `fleet up --ros2` without --real)",
            opts.time_scale
        )));
    }
    for (i, link) in links.iter().enumerate() {
        let k = i as u32 + 1;
        // An on-board robot reaches its robot from its own computer.
        if placement[i] == Placement::Onboard {
            continue;
        }
        if link.connect.is_empty() {
            return Err(FleetError::Config(format!(
                "agent {k} has no ros2.connect: `fleet up --real` reaches each robot at its own router; give agents[{k}].ros2.connect, or [fleet.ros2] connect for all (e.g. \"tcp/192.168.1.2{{k}}:7447\")"
            )));
        }
        let fleet_net = crate::net::NetOptions {
            secure: opts.secure.as_ref().map(|dir| crate::net::Secure {
                dir: dir.clone(),
                identity: Member::Robot(k).identity(),
                robots: n as u32,
                ros2: Vec::new(),
            }),
            ..crate::net::NetOptions::default()
        };
        crate::net::robot_router(k, &link.connect, &fleet_net)?;
    }
    Ok(())
}

/// `fleet up --hub`'s refusals, before anything starts: one router
/// listening on known ports; on-board robots only in hub mode, and not on
/// simulated bases (those rehearse the hub's own robots; an on-board
/// rehearsal is `fleet bundle --simulated`).
fn check_hub(opts: &UpOptions, placement: &[Placement]) -> Result<(), FleetError> {
    let onboard: Vec<String> = placement
        .iter()
        .enumerate()
        .filter(|(_, p)| **p == Placement::Onboard)
        .map(|(i, _)| (i + 1).to_string())
        .collect();
    let Some(hub) = &opts.hub else {
        if !onboard.is_empty() {
            return Err(FleetError::Config(format!(
                "agents {} are on-board (placement = \"onboard\"): run the hub with `fleet up --hub --listen ENDPOINT` and start each on its computer (`fleet bundle`)",
                onboard.join(", ")
            )));
        }
        return Ok(());
    };
    if opts.topology != Topology::Router || opts.sites != 1 {
        return Err(FleetError::Config(
            "--hub runs one router (the hub's): no --topology mesh, no --sites".into(),
        ));
    }
    if hub.listen.is_empty() {
        return Err(FleetError::Config(
            "--hub needs where its router listens: --listen tcp/0.0.0.0:7447 (quic/… in secure mode)".into(),
        ));
    }
    for e in &hub.listen {
        echelon::scenario::check_listen_endpoint(e).map_err(FleetError::Config)?;
        if echelon::scenario::endpoint_port(e) == Some("0") {
            return Err(FleetError::Config(format!(
                "--listen {e}: the hub's robots need a known port (e.g. 7447), not 0"
            )));
        }
        if let Some(why) = ports::taken(e) {
            return Err(FleetError::Refused(format!(
                "--listen {e}: {why}: another hub (a second `fleet up --hub`?) or router already listens there; see it with `echelon fleet status --hub {e}`, or stop it first"
            )));
        }
    }
    if !(hub.wait.is_finite() && hub.wait > 0.0) {
        return Err(FleetError::Config(format!(
            "--wait {}: must be > 0",
            hub.wait
        )));
    }
    if opts.ros2 && !opts.real && !onboard.is_empty() {
        return Err(FleetError::Config(format!(
            "agents {} are on-board: simulated bases (--ros2 without --real) rehearse the hub's own robots; rehearse on-board ones with `fleet bundle --simulated`",
            onboard.join(", ")
        )));
    }
    Ok(())
}

/// Checks `opts` against the scenario before anything is written or
/// starts: the agents, the sites, the hub, real robots, the hazards, every
/// process's certificates (secure mode).
fn plan(opts: &UpOptions) -> Result<Planned, FleetError> {
    let scenario = Scenario::resolve(&opts.scenario)?;
    let fleet = scenario.fleet()?;
    let built = scenario.build(&Overrides::default())?;
    let n = built.plan.agents().len();
    for k in 1..=n as u32 {
        crate::robot::agent_spec(&built.plan, k)?;
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
    check_hub(opts, &fleet.placement)?;
    if opts.real {
        check_real(opts, &fleet.ros2, &fleet.placement, n)?;
    }
    let bases = if opts.ros2 && !opts.real { n } else { 0 };
    if let Some((k, w)) = opts.hazards.iter().find(|(k, _)| *k as usize > bases) {
        return Err(FleetError::Config(match bases {
            0 => format!(
                "--hazard {k}:{w}: hazards are reported by simulated bases: give --ros2 (without --real)"
            ),
            _ => format!("--hazard {k}:{w}: the fleet has {bases} robots"),
        }));
    }
    if let Some(dir) = &opts.secure {
        // Every process's certificates, before anything is written or starts.
        let routers = (opts.topology == Topology::Router).then_some(Member::Router);
        let operator = fleet.operator_heartbeat.map(|_| Member::Operator);
        let robots = (1..=n as u32).map(Member::Robot);
        let simulated = (1..=bases as u32).map(Member::Base);
        for m in [Member::Collector, Member::Leader]
            .into_iter()
            .chain(routers)
            .chain(operator)
            .chain(robots)
            .chain(simulated)
        {
            crate::net::secure_files(dir, &m.identity())?;
        }
    }
    let duration = opts.duration.unwrap_or(built.plan.config().duration);
    let per_process = hosts::per_process(opts, n)?;
    Ok(Planned {
        scenario,
        fleet,
        n,
        bases,
        duration,
        per_process,
    })
}

/// The operator token: the caller's, else a new one; on file at
/// `token_file` for `fleet resume`, and returned in hex for the processes
/// that obey or sign a resume.
fn operator_token(opts: &UpOptions, token_file: &Path) -> Result<String, FleetError> {
    let token = match opts
        .token
        .clone()
        .map_or_else(OperatorToken::from_env, |t| Ok(Some(t)))?
    {
        Some(t) => {
            eprintln!(
                "fleet up: operator token from --token-file or {TOKEN_ENV} (also in {})",
                token_file.display()
            );
            t
        }
        None => {
            let t = OperatorToken::random()?;
            eprintln!(
                "fleet up: operator token {} (fleet resume --token-file {}, or {TOKEN_ENV})",
                t.to_hex(),
                token_file.display()
            );
            t
        }
    };
    token.write_file(token_file)?;
    Ok(token.to_hex())
}

/// Runs the fleet and returns every process's report: planned, started in
/// order (the hub waiting for its robots), supervised to the end, stopped
/// in order, reported.
pub fn run(opts: &UpOptions, stop: &StopFlag) -> Result<UpReport, FleetError> {
    let planned = plan(opts)?;
    let logs = opts.out.join("logs");
    std::fs::create_dir_all(&logs).map_err(FleetError::io(&logs))?;
    let token_file = opts.out.join(TOKEN_FILE);
    let token_hex = operator_token(opts, &token_file)?;
    let token_env = [(TOKEN_ENV, token_hex.as_str())];
    let up = Layout::new(opts, planned, logs)?;
    up.write_endpoints()?;
    let sites = up.sites();
    let (routers, router_args) = up.spawn_routers()?;
    let started = Instant::now();
    let started_unix_ns = crate::unix_nanos();
    let collector = up.spawn_collector(&token_env)?;
    let bases = up.spawn_bases()?;
    let operator = up.spawn_operator()?;
    let garbage = up.spawn_garbage()?;
    let (robots, on_hub, hosted) = up.spawn_robots(&token_file)?;
    let mut procs = Procs {
        robots,
        hosted,
        garbage,
        operator,
        bases,
        collector,
        routers,
        router_args,
        on_hub,
    };
    // Hub mode: the reference starts once every robot has joined.
    if let Some(hub) = &opts.hub {
        up.wait_for_joins(hub, &mut procs, stop)?;
    }
    let leader = up.spawn_leader(procs.operator.is_some(), &token_env)?;
    let mut running = Running::new(leader, Instant::now(), procs);
    running.supervise(&up, stop, started)?;
    running.stop_rest(&opts.chaos)?;
    let report = running.report(&up, sites, started, started_unix_ns)?;
    crate::write_json_file(&opts.out.join(UP_SUMMARY_FILE), &report)?;
    Ok(report)
}

/// The fault arguments `member`'s process takes from `chaos` (its
/// `--die-at`; a simulated base's `--fault-at` and `--fault-window`; a
/// robot's are in its robot file).
fn chaos_args(chaos: &Chaos, member: Member) -> Vec<String> {
    let mut a = Vec::new();
    if let Some(t) = chaos.death_of(member) {
        a.extend(["--die-at".to_owned(), t.to_string()]);
    }
    if matches!(member, Member::Base(_))
        && let Some(t) = chaos.fault_at
    {
        a.extend(["--fault-at".to_owned(), t.to_string()]);
        if let Some(w) = chaos.window {
            a.extend(["--fault-window".to_owned(), w.to_string()]);
        }
    }
    a
}

/// The processes (the one at `i` of `member(i)`: robots, bases) but
/// those killed as `chaos` asked (`--die-at`), whose ends are
/// in the report's `deaths`.
fn living<'a>(
    procs: &'a [Proc],
    chaos: &'a Chaos,
    member: impl Fn(usize) -> Member + 'a,
) -> impl Iterator<Item = &'a Proc> + 'a {
    procs.iter().enumerate().filter_map(move |(i, p)| {
        let asked = chaos.death_of(member(i)).is_some();
        (!asked || p.failure().is_none()).then_some(p)
    })
}
