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

use std::path::PathBuf;
use std::time::{Duration, Instant};

use serde::Serialize;

use echelon::scenario::{Overrides, Placement, Scenario};

use crate::collector::CollectorReport;
use crate::faults::{Chaos, FaultSpec};
use crate::latency::FleetLatency;
use crate::leader::LeaderReport;
use crate::robot::RobotReport;
use crate::role::{Member, Role};
use crate::token::{OperatorToken, TOKEN_ENV, TOKEN_FILE};

use crate::{FleetError, StopFlag};

mod join;
mod ports;
mod process;
mod report;
mod robots;
use ports::Links;
pub use ports::{free_ports, free_ports_for};
use process::{Proc, poll_all, spawn, stop_all};
pub use report::{Intrusion, LogGap, UpCost, UpReport};
use report::{report, up_cost};
pub use robots::ROBOTS_DIR;

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

/// Runs the fleet and returns every process's report.
pub fn run(opts: &UpOptions, stop: &StopFlag) -> Result<UpReport, FleetError> {
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
    let logs = opts.out.join("logs");
    std::fs::create_dir_all(&logs).map_err(FleetError::io(&logs))?;
    // The operator token: the caller's, else a new one; on file for `fleet
    // resume`, and handed to the processes that obey or sign a resume.
    let token_file = opts.out.join(TOKEN_FILE);
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
    token.write_file(&token_file)?;
    let token_hex = token.to_hex();
    let token_env = [(TOKEN_ENV, token_hex.as_str())];

    let proto = crate::net::link_protocol(opts.secure.is_some());
    // Start order: the routers (router topology), the collector, the ROS 2
    // bases (with --ros2), the robots, the leader; in a mesh also the order
    // of their ports.
    let robot_at = |k: usize| bases + k;
    let leader_at = bases + n + 1;
    // The operator's heartbeat last, when the scenario asks for one.
    let net = Links::new(opts, proto, leader_at + 2)?;
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
        i if i >= leader_at => 0,
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
            if let Some(hub) = &opts.hub {
                for (i, e) in hub.listen.iter().enumerate() {
                    let name = match i {
                        0 => "hub".to_owned(),
                        i => format!("hub/{}", i + 1),
                    };
                    endpoints.insert(name, e.clone().into());
                    eprintln!(
                        "fleet up: the hub listens on {e} (robots, fleet status/stop/resume: --hub {})",
                        e.replacen("/0.0.0.0:", "/<this machine's address>:", 1)
                    );
                }
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
    if let Some(addr) = opts.foxglove {
        endpoints.insert("foxglove".into(), format!("ws://{addr}").into());
    }
    if let Some(addr) = opts.dashboard {
        endpoints.insert("dashboard".into(), format!("http://{addr}/").into());
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
    let mut router_args = Vec::with_capacity(net.routers.len());
    for s in 0..net.routers.len() {
        let mut args = vec!["fleet".to_owned(), Role::Router.name().to_owned()];
        if opts.ros2 {
            args.push(opts.scenario.clone());
        }
        for l in &net.listen[s] {
            args.extend(["--listen".to_owned(), l.clone()]);
        }
        for other in &net.routers[..s] {
            args.extend(["--connect".to_owned(), other.clone()]);
        }
        args.extend(secure_args(&Member::Router.identity()));
        let mut first = args.clone();
        if s == 0
            && let Some((at, _)) = opts.chaos.router_restart
        {
            first.extend(["--die-at".to_owned(), at.to_string()]);
        }
        routers.push(spawn(&opts.exe, &router_role(s + 1), &first, &[], &logs)?);
        router_args.push(args);
    }
    // Site 1's router killed as asked (`router_restart`): when it died,
    // and whether it was started again (its own arguments, on its port).
    let mut router_down: Option<Instant> = None;
    let mut router_restarted = false;
    let scale = opts.time_scale.to_string();
    let dur = duration.to_string();
    // `fleet ROLE SCENARIO` on the fleet's clock, to its end.
    let on_clock = |role: Role| {
        vec![
            "fleet".to_owned(),
            role.name().to_owned(),
            opts.scenario.clone(),
            "--duration".to_owned(),
            dur.clone(),
            "--time-scale".to_owned(),
            scale.clone(),
        ]
    };
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
    // Real robots' ROS topics stay on their own routers, out of its reach.
    if opts.ros2 && !opts.real {
        args.push("--ros2".to_owned());
    }
    if let Some(addr) = opts.foxglove {
        args.extend(["--foxglove".to_owned(), addr.to_string()]);
    }
    if let Some(addr) = opts.dashboard {
        args.extend(["--dashboard".to_owned(), addr.to_string()]);
    }
    if let Some(hz) = opts.log_rate {
        args.extend(["--log-rate".to_owned(), hz.to_string()]);
    }
    args.extend(chaos_args(&opts.chaos, Member::Collector));
    args.extend(common(0, &Member::Collector.identity()));
    let mut collector = spawn(&opts.exe, Role::Collector.name(), &args, &token_env, &logs)?;

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
        for (_, w) in opts.hazards.iter().filter(|(j, _)| *j as usize == k) {
            args.extend(["--hazard".to_owned(), w.to_string()]);
        }
        args.extend(chaos_args(&opts.chaos, Member::Base(k as u32)));
        args.extend(common(k, &Member::Base(k as u32).identity()));
        base_procs.push(spawn(
            &opts.exe,
            &Member::Base(k as u32).liveliness(),
            &args,
            &[],
            &logs,
        )?);
    }

    // A supervised run: the operator's heartbeat, on the hub (its death,
    // or its machine asleep, holds the fleet within the deadline).
    let operator_at = leader_at + 1;
    let mut operator = match fleet.operator_heartbeat {
        Some(_) => {
            let mut args = vec![
                "fleet".to_owned(),
                "heartbeat".to_owned(),
                opts.scenario.clone(),
                "--time-scale".to_owned(),
                scale.clone(),
            ];
            args.extend(chaos_args(&opts.chaos, Member::Operator));
            args.extend(common(operator_at, &Member::Operator.identity()));
            Some(spawn(&opts.exe, Role::Operator.name(), &args, &[], &logs)?)
        }
        None => None,
    };

    // Hostile input on every key (`fleet garbage`), when asked.
    let mut garbage = match opts.chaos.garbage {
        Some((from, len)) => {
            let mut args = vec![
                "fleet".to_owned(),
                "garbage".to_owned(),
                opts.scenario.clone(),
                "--from".to_owned(),
                from.to_string(),
                "--for".to_owned(),
                len.to_string(),
                "--time-scale".to_owned(),
                scale.clone(),
            ];
            // A peer of the operator's site, as anyone reaching the router.
            args.extend(common(operator_at, &Member::Operator.identity()));
            Some(spawn(&opts.exe, "garbage", &args, &[], &logs)?)
        }
        None => None,
    };

    // The robots on the hub, each from its robot file (the type an
    // on-board robot's bundle holds); the on-board ones join by themselves.
    let on_hub: Vec<u32> = (1..=n as u32)
        .filter(|&k| fleet.placement[k as usize - 1] == Placement::Hub || opts.hub.is_none())
        .collect();
    let mut robots = Vec::with_capacity(on_hub.len());
    for &k in &on_hub {
        let i = robot_at(k as usize);
        let file = robots::write_robot_file(
            opts,
            &scenario,
            k,
            n as u32,
            duration,
            net.net_section(i, site_of(i)),
            &token_file,
        )?;
        let args = vec![
            "fleet".to_owned(),
            Role::Robot.name().to_owned(),
            "--config".to_owned(),
            file.display().to_string(),
        ];
        robots.push(spawn(
            &opts.exe,
            &Member::Robot(k).liveliness(),
            &args,
            &[],
            &logs,
        )?);
    }
    let robot_of = |i: usize| Member::Robot(on_hub[i]);

    // Hub mode: the reference starts once every robot has joined.
    if let Some(hub) = &opts.hub {
        let awaited: join::Awaited = (1..=n as u32)
            .map(|k| (k, fleet.placement[k as usize - 1]))
            .collect();
        let session = crate::net::NetOptions {
            mode: Some(crate::net::Mode::Client),
            connect: vec![net.routers[0].clone()],
            secure: opts.secure.as_ref().map(|dir| crate::net::Secure {
                dir: dir.clone(),
                identity: Member::Leader.identity(),
                robots: n as u32,
                ros2: crate::net::ros_acl(&fleet.ros2),
            }),
            ..crate::net::NetOptions::default()
        };
        let keys = crate::keys::Keys::new(&fleet.name);
        let waited = join::wait_for_robots(
            &session,
            &keys,
            &awaited,
            Duration::from_secs_f64(hub.wait),
            stop,
            &mut || {
                poll_all(
                    std::iter::once(&mut collector)
                        .chain(&mut robots)
                        .chain(&mut base_procs)
                        .chain(operator.as_mut())
                        .chain(&mut routers),
                )?;
                match std::iter::once(&collector)
                    .chain(&robots)
                    .chain(&base_procs)
                    .chain(&routers)
                    .find(|p| p.status.is_some())
                {
                    Some(p) => Err(FleetError::Child(
                        p.failure()
                            .unwrap_or_else(|| format!("{} stopped early", p.role)),
                    )),
                    None => Ok(()),
                }
            },
        );
        if let Err(e) = waited {
            for p in std::iter::once(&collector)
                .chain(&robots)
                .chain(&base_procs)
                .chain(operator.iter())
                .chain(&routers)
            {
                p.terminate();
            }
            return Err(e);
        }
    }

    let mut args = on_clock(Role::Leader);
    args.extend(chaos_args(&opts.chaos, Member::Leader));
    args.extend(["--wait-for".to_owned(), Role::Collector.name().to_owned()]);
    if operator.is_some() {
        args.extend(["--wait-for".to_owned(), Member::Operator.liveliness()]);
    }
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
    let mut leader = spawn(&opts.exe, Role::Leader.name(), &args, &token_env, &logs)?;
    let leader_spawned = Instant::now();
    // A second fleet of the same name reaching the router, when asked.
    let mut intruders: Vec<Proc> = Vec::new();

    // Generous: connection set-up, then the run in real time, then the wind-down.
    let deadline = Duration::from_secs_f64(60.0 + 2.0 * duration / opts.time_scale);
    let nap = Duration::from_millis(25);
    let mut interrupted = false;
    let mut leader_done: Option<Instant> = None;
    let mut robots_told = false;
    // The leader died mid-run (killed, crashed): the robots hold under
    // their link-loss policy and run to the end on their own clocks, as
    // robots on other machines would; the run is reported, not torn down.
    let mut leader_failure: Option<String> = None;
    let mut deaths: Vec<(String, String)> = Vec::new();
    // 1. Leader and robots run to the end (or a failure, or a signal).
    loop {
        if let Some(at) = opts.chaos.intruders
            && intruders.is_empty()
            && leader_spawned.elapsed().as_secs_f64() >= 1.0 + at / opts.time_scale
        {
            for (role, mut args) in [
                ("intruder-leader", on_clock(Role::Leader)),
                ("intruder-robot/2", {
                    let mut a = on_clock(Role::Robot);
                    a.extend(["--agent".to_owned(), "2".to_owned()]);
                    a
                }),
            ] {
                args.extend(common(leader_at, &Member::Leader.identity()));
                intruders.push(spawn(&opts.exe, role, &args, &[], &logs)?);
            }
            eprintln!("fleet up: a second leader and robot 2 of this fleet joined (as asked)");
        }
        poll_all(&mut intruders)?;
        let all_done = poll_all(std::iter::once(&mut leader).chain(&mut robots))?;
        poll_all(
            std::iter::once(&mut collector)
                .chain(&mut base_procs)
                .chain(operator.as_mut())
                .chain(garbage.as_mut())
                .chain(&mut routers),
        )?;
        if let Some(f) = garbage.as_ref().and_then(Proc::failure) {
            return Err(FleetError::Child(f));
        }
        // Deaths the fault matrix asked for (`--die-at`): reported, not
        // a failure of the run.
        for (p, member) in robots
            .iter()
            .enumerate()
            .map(|(i, p)| (p, robot_of(i)))
            .chain(
                base_procs
                    .iter()
                    .enumerate()
                    .map(|(i, p)| (p, Member::Base(i as u32 + 1))),
            )
            .chain(operator.iter().map(|p| (p, Member::Operator)))
            .chain(std::iter::once((&collector, Member::Collector)))
        {
            if opts.chaos.death_of(member).is_some()
                && let Some(f) = p.failure()
                && !deaths.iter().any(|(m, _)| *m == member.liveliness())
            {
                eprintln!("fleet up: {f} (as asked: --die-at)");
                deaths.push((member.liveliness(), f));
            }
        }
        if let Some(f) = operator.as_ref().and_then(Proc::failure)
            && opts.chaos.death_of(Member::Operator).is_none()
        {
            return Err(FleetError::Child(f));
        }
        if leader_failure.is_none()
            && !interrupted
            && let Some(f) = leader.failure()
        {
            eprintln!(
                "fleet up: {f}; the robots hold under their link-loss policy and run to --duration without it"
            );
            leader_failure = Some(f);
        }
        // Site 1's router killed as asked: started again, on its port,
        // once it has been down for the time asked.
        if let Some((_, down)) = opts.chaos.router_restart
            && !router_restarted
            && routers[0].status.is_some()
        {
            let since = *router_down.get_or_insert_with(|| {
                if let Some(f) = routers[0].failure() {
                    eprintln!("fleet up: {f} (as asked: --die-at)");
                    deaths.push((router_role(1), f));
                }
                Instant::now()
            });
            if since.elapsed().as_secs_f64() >= down / opts.time_scale {
                let role = format!("{}-restarted", router_role(1));
                routers[0] = spawn(&opts.exe, &role, &router_args[0], &[], &logs)?;
                router_restarted = true;
                eprintln!("fleet up: {} started again", router_role(1));
            }
        }
        let awaited = router_down.is_some() && !router_restarted;
        let failed = living(&robots, &opts.chaos, robot_of)
            .chain(living(&base_procs, &opts.chaos, |i| {
                Member::Base(i as u32 + 1)
            }))
            .chain(living(
                std::slice::from_ref(&collector),
                &opts.chaos,
                |_| Member::Collector,
            ))
            .chain(routers.iter().skip(usize::from(awaited)))
            .find_map(Proc::failure);
        if let Some(f) = failed {
            for p in std::iter::once(&leader).chain(&robots).chain(&base_procs) {
                p.terminate();
            }
            collector.terminate();
            return Err(FleetError::Child(f));
        }
        if let Some(r) = routers
            .iter()
            .skip(usize::from(awaited))
            .find(|r| r.status.is_some())
        {
            return Err(FleetError::Child(format!("{} stopped early", r.role)));
        }
        if all_done {
            break;
        }
        if collector.status.is_some() && opts.chaos.death_of(Member::Collector).is_none() {
            return Err(FleetError::Child("the collector stopped early".into()));
        }
        if stop.is_raised() && !interrupted {
            interrupted = true;
            leader.terminate();
            for r in &robots {
                r.terminate();
            }
        }
        if leader.status.is_some() && !interrupted && leader_failure.is_none() {
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
    // 2. The bases, then the collector. No wait is needed here: each robot
    // and the leader made sure their router held their last words before
    // they exited (`net::flush`), and on SIGTERM a base follows the
    // commands still on their way (its robot's final zero), the collector
    // records what is (the leader's last samples, the robots' and the
    // bases' last words), each until its inputs are quiet
    // (`runtime::Linger`, bounded), so the collector goes last.
    stop_all(&mut base_procs, nap, "a ROS 2 base")?;
    if let Some(p) = operator.as_mut().filter(|p| p.status.is_none()) {
        stop_all(std::slice::from_mut(p), nap, "the operator's heartbeat")?;
    }
    if let Some(p) = garbage.as_mut() {
        stop_all(std::slice::from_mut(p), nap, "fleet garbage")?;
    }
    stop_all(std::slice::from_mut(&mut collector), nap, "the collector")?;
    if let Some(f) = living(std::slice::from_ref(&collector), &opts.chaos, |_| {
        Member::Collector
    })
    .chain(living(&base_procs, &opts.chaos, |i| {
        Member::Base(i as u32 + 1)
    }))
    .find_map(Proc::failure)
    {
        return Err(FleetError::Child(f));
    }
    // The routers last, once nothing is linked to them any more.
    stop_all(&mut routers, nap, "a router")?;
    if let Some(f) = routers.iter().find_map(Proc::failure) {
        return Err(FleetError::Child(f));
    }
    let intruders = intruders
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
        .collect();
    let wall = started.elapsed().as_secs_f64();
    let leader_report: Option<LeaderReport> = match &leader_failure {
        Some(_) => None,
        None => Some(report(&leader)?),
    };
    let startup = leader_report
        .as_ref()
        .map(|l| l.clock_start_unix_ns)
        .filter(|&t| t > 0)
        .map(|t| t.saturating_sub(started_unix_ns) as f64 * 1e-9);
    // A robot killed as asked has no report (its death is in `deaths`).
    let robot_reports: Vec<RobotReport> = living(&robots, &opts.chaos, robot_of)
        .map(report)
        .collect::<Result<_, _>>()?;
    // A collector killed as asked left no report: its log's gap is said.
    let collector_report: Option<CollectorReport> =
        match living(std::slice::from_ref(&collector), &opts.chaos, |_| {
            Member::Collector
        })
        .next()
        {
            Some(c) => Some(report(c)?),
            None => None,
        };
    let log_gap = match &collector_report {
        Some(_) => None,
        None => LogGap::of(&opts.out.join("trajectory.csv"), duration),
    };
    let no_latency = crate::latency::LatencyReport::default();
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
        leader_failure,
        deaths: deaths.into_iter().map(|(_, f)| f).collect(),
        robots: robot_reports,
        onboard: (1..=n as u32).filter(|k| !on_hub.contains(k)).collect(),
        collector: collector_report,
        intruders,
        log_gap,
        bases: living(&base_procs, &opts.chaos, |i| Member::Base(i as u32 + 1))
            .map(report)
            .collect::<Result<_, _>>()?,
        topology: opts.topology,
        router_endpoints: net.routers.clone(),
        sites,
        routers: routers.iter().map(report).collect::<Result<_, _>>()?,
    };
    crate::write_json_file(&opts.out.join(UP_SUMMARY_FILE), &up)?;
    Ok(up)
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
