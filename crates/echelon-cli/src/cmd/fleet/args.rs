//! The arguments of the fleet's own processes (leader, robot, base, excite,
//! collector, router, heartbeat, garbage) and what they share; an
//! operator's commands' arguments are in [`super::operator_args`], the
//! subcommands that take them in [`super::subcommand`].

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::{Args, ValueEnum};
use echelon::scenario::{Scenario, is_valid_fleet_name};
use echelon_fleet::faults::FaultSpec;
use echelon_fleet::net::{self, Mode, NetOptions, Secure};
use echelon_fleet::options::ProcessOptions;

use crate::cmd::{non_negative, parse_number, positive, seconds, time_scale};

/// Zenoh mode of a fleet process.
#[derive(Debug, Clone, Copy, ValueEnum)]
pub(super) enum ModeArg {
    /// Links to every endpoint it connects to (and, by gossip, to their peers).
    Peer,
    /// Exactly one link, to a router (`fleet router`), which it reconnects to if lost.
    Client,
}

/// How a process joins the fleet.
#[derive(Debug, Args)]
pub(crate) struct NetArgs {
    /// Zenoh mode [default: peer, or the --zenoh-config file's].
    #[arg(long, value_enum)]
    pub(super) mode: Option<ModeArg>,
    /// Endpoint to listen on, e.g. tcp/0.0.0.0:7447 (repeatable) [default: tcp/127.0.0.1:0, quic/127.0.0.1:0 in secure mode].
    #[arg(long, value_name = "ENDPOINT", value_parser = listen_endpoint)]
    pub(super) listen: Vec<String>,
    /// Endpoint to connect to, e.g. tcp/192.168.1.10:7447 (repeatable).
    #[arg(long, value_name = "ENDPOINT", value_parser = connect_endpoint)]
    pub(super) connect: Vec<String>,
    /// The fleet's hub, as `fleet up --hub` printed it (repeatable: tried in order): joins as a client of its router (`--mode client --connect ENDPOINT`).
    #[arg(long, value_name = "ENDPOINT", value_parser = connect_endpoint, conflicts_with_all = ["mode", "connect"])]
    pub(super) hub: Vec<String>,
    /// A Zenoh configuration file (JSON5) to start from instead of the default (peer, no multicast).
    #[arg(long, value_name = "FILE")]
    pub(super) zenoh_config: Option<PathBuf>,
    /// Fleet name, the second chunk of every key [default: the scenario's].
    #[arg(long, value_name = "NAME")]
    pub(super) fleet: Option<String>,
    /// Secure mode: mutual TLS and access control with the certificates in DIR (`echelon fleet certs`).
    #[arg(long, value_name = "DIR")]
    pub(super) secure: Option<PathBuf>,
    /// Certificate identity in secure mode [default: leader, robot-K, base-K, collector, router or operator].
    #[arg(long, value_name = "ID", requires = "secure")]
    pub(super) identity: Option<String>,
    /// Number of robot identities the access control knows [default: the scenario's agents].
    #[arg(long, value_name = "N", requires = "secure")]
    pub(super) robots: Option<u32>,
}

impl NetArgs {
    /// Whether anything but `--hub` was given.
    pub(super) fn beyond_hub(&self) -> bool {
        self.mode.is_some()
            || !self.listen.is_empty()
            || !self.connect.is_empty()
            || self.zenoh_config.is_some()
            || self.fleet.is_some()
            || self.secure.is_some()
            || self.identity.is_some()
            || self.robots.is_some()
    }

    /// The fleet's name: `--fleet`, else the scenario's.
    pub(super) fn fleet_name(&self, scenario: Option<&Scenario>) -> Result<String> {
        match (&self.fleet, scenario) {
            (Some(f), _) => Ok(f.clone()),
            (None, Some(s)) => Ok(s.fleet()?.name),
            (None, None) => bail!("give the scenario or --fleet NAME"),
        }
    }

    pub(super) fn options(
        &self,
        default_identity: &str,
        robots: Option<u32>,
        scenario: Option<&Scenario>,
    ) -> Result<NetOptions> {
        if let Some(name) = &self.fleet
            && !is_valid_fleet_name(name)
        {
            bail!("--fleet `{name}`: letters, digits, '-', '_' and '.' only");
        }
        let secure = match &self.secure {
            None => None,
            Some(dir) => Some(Secure {
                dir: dir.clone(),
                identity: self
                    .identity
                    .clone()
                    .unwrap_or_else(|| default_identity.to_owned()),
                robots: self
                    .robots
                    .or(robots)
                    .context("--secure needs --robots N (or a scenario) for the access control")?,
                ros2: match scenario {
                    Some(s) => net::ros_acl(&s.fleet()?.ros2),
                    None => Vec::new(),
                },
            }),
        };
        if !self.hub.is_empty() {
            return Ok(NetOptions {
                mode: Some(Mode::Client),
                listen: self.listen.clone(),
                connect: self.hub.clone(),
                zenoh_config: self.zenoh_config.clone(),
                secure,
            });
        }
        Ok(NetOptions {
            mode: self.mode.map(|m| match m {
                ModeArg::Peer => Mode::Peer,
                ModeArg::Client => Mode::Client,
            }),
            listen: self.listen.clone(),
            connect: self.connect.clone(),
            zenoh_config: self.zenoh_config.clone(),
            secure,
        })
    }
}

/// Fault injection on what robots receive.
#[derive(Debug, Args)]
pub(crate) struct FaultArgs {
    /// Drop each received message with probability P (0–1).
    #[arg(long, value_name = "P", value_parser = probability, default_value_t = 0.0)]
    pub(super) loss: f64,
    /// Delay every received message by MS milliseconds of fleet time.
    #[arg(long, value_name = "MS", value_parser = non_negative, default_value_t = 0.0)]
    pub(super) delay: f64,
    /// Drop everything received on the leader stream in [START, START+LEN) s of fleet time.
    #[arg(long, value_name = "START:LEN", value_parser = outage)]
    pub(super) outage: Option<(f64, f64)>,
    /// Seed of the drop pattern.
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub(super) seed: u64,
    /// A simulated robot's odometry stops updating in [START, START+LEN) s of fleet time (the robot moves on).
    #[arg(long, value_name = "START:LEN", value_parser = outage)]
    pub(super) freeze_odometry: Option<(f64, f64)>,
    /// Measure what the simulated robot does from fleet time S on (its report's `aftermath`).
    #[arg(long, value_name = "S", value_parser = non_negative)]
    pub(super) fault_at: Option<f64>,
    /// With --fault-at: measure for LEN s only [default: to the end].
    #[arg(long, value_name = "LEN", value_parser = positive, requires = "fault_at")]
    pub(super) fault_window: Option<f64>,
    /// Partition the robot in [START, START+LEN) s of fleet time: nothing of its leader stream or neighbours arrives, its state does not leave (stop, resume and heartbeat still pass).
    #[arg(long, value_name = "START:LEN", value_parser = outage)]
    pub(super) partition: Option<(f64, f64)>,
    /// Step this process's wall clock by STEP s (may be negative) at fleet time AT (a rehearsed NTP step; fleet time is monotonic).
    #[arg(long, value_name = "AT:STEP", value_parser = clock_jump, allow_hyphen_values = true)]
    pub(super) wall_clock_jump: Option<(f64, f64)>,
}

fn clock_jump(s: &str) -> Result<(f64, f64), String> {
    let (a, b) = s
        .split_once(':')
        .ok_or_else(|| format!("`{s}` is not AT:STEP (seconds)"))?;
    Ok((non_negative(a)?, parse_number(b)?))
}

impl FaultArgs {
    pub(super) fn spec(&self) -> FaultSpec {
        FaultSpec {
            loss: self.loss,
            delay: self.delay * 1e-3,
            outage: self.outage,
            seed: self.seed,
            freeze_odometry: self.freeze_odometry,
            fault_at: self.fault_at,
            fault_window: self.fault_window,
            wall_clock_jump: self.wall_clock_jump,
            partition: self.partition,
        }
    }
}

fn probability(s: &str) -> Result<f64, String> {
    let v = parse_number(s)?;
    if (0.0..=1.0).contains(&v) {
        Ok(v)
    } else {
        Err(format!("{s} must be between 0 and 1"))
    }
}

fn outage(s: &str) -> Result<(f64, f64), String> {
    let (a, b) = s
        .split_once(':')
        .ok_or_else(|| format!("`{s}` is not START:LEN (seconds)"))?;
    Ok((non_negative(a)?, positive(b)?))
}

/// A scenario and one of its agents (`robot`, `base`, `excite`).
#[derive(Debug, Args)]
pub(crate) struct AgentArgs {
    /// A built-in scenario name or a path to a .toml file.
    pub(super) scenario: String,
    /// Which agent of the scenario, from 1.
    #[arg(long, value_name = "K")]
    pub(super) agent: u32,
}

/// How long and how fast a fleet process's clock runs (`leader`, `robot`,
/// `base`, `up`).
#[derive(Debug, Args)]
pub(crate) struct ClockArgs {
    /// Stop at this fleet time, s [default: leader and up, the scenario's sim.duration; robot and base, at SIGINT/SIGTERM].
    #[arg(long, value_name = "S", value_parser = seconds)]
    pub(super) duration: Option<f64>,
    /// Run the clock K times faster than real time.
    #[arg(long, value_name = "K", value_parser = time_scale, default_value_t = 1.0)]
    pub(super) time_scale: f64,
    /// Kill this process with SIGKILL at fleet time S (a rehearsed `kill -9`: the fault matrix, docs/faults.md).
    #[arg(long, value_name = "S", value_parser = non_negative)]
    pub(super) die_at: Option<f64>,
}

impl ClockArgs {
    /// Whether any of its flags was given a value of its own.
    pub(super) fn is_given(&self) -> bool {
        self.duration.is_some() || self.time_scale != 1.0 || self.die_at.is_some()
    }

    /// A process of `scenario` on this clock, joining the fleet by `net`
    /// (its session options `options`, its fleet name).
    pub(super) fn process(
        &self,
        scenario: Scenario,
        options: NetOptions,
        net: &NetArgs,
    ) -> ProcessOptions {
        ProcessOptions {
            scenario,
            time_scale: self.time_scale,
            duration: self.duration,
            net: options,
            fleet: net.fleet.clone(),
            die_at: self.die_at,
        }
    }
}

/// One agent's process on the fleet clock (`robot`, `base`).
#[derive(Debug, Args)]
pub(crate) struct AgentClockArgs {
    #[command(flatten)]
    pub(super) agent: AgentArgs,
    #[command(flatten)]
    pub(super) clock: ClockArgs,
}

/// `echelon fleet leader`.
#[derive(Debug, Args)]
pub(crate) struct LeaderArgs {
    /// A built-in scenario name or a path to a .toml file.
    pub(super) scenario: String,
    /// Publication rate, Hz [default: the scenario's [fleet] reference_rate, else 50].
    #[arg(long, value_name = "HZ", value_parser = positive)]
    pub(super) rate: Option<f64>,
    #[command(flatten)]
    pub(super) clock: ClockArgs,
    /// Wait for this process (collector, robot/K) before starting the clock (repeatable).
    #[arg(long, value_name = "ROLE")]
    pub(super) wait_for: Vec<String>,
    /// Longest wait for --wait-for, s of real time.
    #[arg(long, value_name = "S", value_parser = seconds, default_value_t = 60.0)]
    pub(super) wait_timeout: f64,
    /// Rehearse a rogue publisher: join even though the fleet has a leader (only the access control of the secure mode stops it; the secure mode's tests).
    #[arg(long, hide = true)]
    pub(super) rogue: bool,
    #[command(flatten)]
    pub(super) net: NetArgs,
}

/// `echelon fleet heartbeat`.
#[derive(Debug, Args)]
pub(crate) struct HeartbeatArgs {
    /// A built-in scenario name or a path to a .toml file (its [fleet] operator_heartbeat sets the rate).
    pub(super) scenario: String,
    #[command(flatten)]
    pub(super) clock: ClockArgs,
    #[command(flatten)]
    pub(super) net: NetArgs,
}

/// `echelon fleet garbage`.
#[derive(Debug, Args)]
pub(crate) struct GarbageArgs {
    /// A built-in scenario name or a path to a .toml file (its fleet).
    pub(super) scenario: String,
    /// Fleet time to start at, s.
    #[arg(long, value_name = "S", value_parser = non_negative)]
    pub(super) from: f64,
    /// For how long, s.
    #[arg(long = "for", value_name = "S", value_parser = positive)]
    pub(super) length: f64,
    /// Seed of the garbage (mixed with a random one).
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub(super) seed: u64,
    #[command(flatten)]
    pub(super) clock: ClockArgs,
    #[command(flatten)]
    pub(super) net: NetArgs,
}

/// `echelon fleet robot`.
#[derive(Debug, Args)]
pub(crate) struct RobotArgs {
    /// The robot's whole configuration, a robot.toml (`fleet bundle` writes one per on-board robot); only --hub may be given with it.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["scenario", "agent", "ros2", "simulated_base"])]
    pub(super) config: Option<PathBuf>,
    /// A built-in scenario name or a path to a .toml file.
    #[arg(required_unless_present = "config")]
    pub(super) scenario: Option<String>,
    /// Which agent of the scenario, from 1.
    #[arg(long, value_name = "K", required_unless_present = "config")]
    pub(super) agent: Option<u32>,
    #[command(flatten)]
    pub(super) clock: ClockArgs,
    /// Drive the agent's ROS 2 robot ([fleet.ros2]): odom in, cmd_vel out over rmw_zenoh.
    #[arg(long)]
    pub(super) ros2: bool,
    /// With --ros2: the robot is `fleet base`'s simulation, so --time-scale
    /// may differ from 1 (a real robot runs in real time).
    #[arg(long, requires = "ros2")]
    pub(super) simulated_base: bool,
    #[command(flatten)]
    pub(super) faults: FaultArgs,
    #[command(flatten)]
    pub(super) net: NetArgs,
}

/// `echelon fleet idle`.
#[derive(Debug, Args)]
pub(crate) struct IdleArgs {
    /// Wake rate, Hz.
    #[arg(long, value_name = "HZ", value_parser = positive, default_value_t = 100.0)]
    pub(super) rate: f64,
    /// How long, s of real time.
    #[arg(long, value_name = "S", value_parser = positive, default_value_t = 60.0)]
    pub(super) duration: f64,
}

/// `echelon fleet host`. (Its `--robots` lists the agents it runs; the
/// secure mode's robot count, which a host never needs since it refuses
/// the secure mode, is renamed and hidden.)
#[derive(Debug, Args)]
#[command(mut_arg("robots", |a| a.long("acl-robots").hide(true)))]
pub(crate) struct HostArgs {
    /// The robots' files, one per robot (`fleet up --robots-per-process` writes them); only --hub may be given with them.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["scenario", "agents"])]
    pub(super) config: Vec<PathBuf>,
    /// A built-in scenario name or a path to a .toml file.
    #[arg(required_unless_present = "config")]
    pub(super) scenario: Option<String>,
    /// Which agents of the scenario: K, K-L, or a comma-separated list of both (1-250, 1,3,5-9).
    #[arg(id = "agents", long = "robots", value_name = "LIST", value_parser = agent_list, required_unless_present = "config")]
    pub(super) agents: Option<AgentList>,
    #[command(flatten)]
    pub(super) clock: ClockArgs,
    #[command(flatten)]
    pub(super) faults: FaultArgs,
    #[command(flatten)]
    pub(super) net: NetArgs,
}

/// Agents, each from 1, none twice, in the order given ([`agent_list`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct AgentList(pub(crate) Vec<u32>);

/// Agents as `K`, `K-L` or a comma-separated list of both, each from 1,
/// none twice, in the order given.
pub(crate) fn agent_list(s: &str) -> Result<AgentList, String> {
    let mut agents = Vec::new();
    for part in s.split(',') {
        let number = |t: &str| {
            t.trim()
                .parse::<u32>()
                .ok()
                .filter(|&k| k >= 1)
                .ok_or_else(|| format!("`{t}` is not an agent number (from 1)"))
        };
        let (from, to) = match part.split_once('-') {
            Some((a, b)) => (number(a)?, number(b)?),
            None => (number(part)?, number(part)?),
        };
        if to < from {
            return Err(format!("`{part}`: the range runs backwards"));
        }
        for k in from..=to {
            if agents.contains(&k) {
                return Err(format!("agent {k} is given twice"));
            }
            agents.push(k);
        }
    }
    Ok(AgentList(agents))
}

/// `echelon fleet base`.
#[derive(Debug, Args)]
pub(crate) struct BaseArgs {
    #[command(flatten)]
    pub(super) agent: AgentClockArgs,
    /// Simulate a ROS 2 base (the only kind so far; required).
    #[arg(long)]
    pub(super) ros2: bool,
    /// The base's clock minus the wall clock, s (negative: behind): it
    /// drops a stamped cmd_vel older than cmd_vel_timeout by its own clock,
    /// as diff_drive_controller does (a zero stamp is "now").
    #[arg(long, value_name = "S", value_parser = parse_number, default_value_t = 0.0, allow_hyphen_values = true)]
    pub(super) clock_offset: f64,
    /// Report a hazard over a window of its own clock (seconds since it started, scaled), NAME@FROM+DURATION (BUMP@12+3; EMERGENCY_STOP is an e-stop), on the agent's `hazards` (`estop`) topic (repeatable).
    #[arg(long, value_name = "NAME@FROM+S")]
    pub(super) hazard: Vec<echelon_fleet::ros2::hazard::HazardWindow>,
    /// Measure what the simulated base does from fleet time S on (its report's `aftermath`; it learns the fleet's time from the reference).
    #[arg(long, value_name = "S", value_parser = non_negative)]
    pub(super) fault_at: Option<f64>,
    /// With --fault-at: measure for LEN s only [default: to the end].
    #[arg(long, value_name = "LEN", value_parser = positive, requires = "fault_at")]
    pub(super) fault_window: Option<f64>,
    #[command(flatten)]
    pub(super) net: NetArgs,
}

/// `echelon fleet excite`.
#[derive(Debug, Args)]
pub(crate) struct ExciteArgs {
    /// The agent (its velocity base and [fleet.ros2] link).
    #[command(flatten)]
    pub(super) agent: AgentArgs,
    /// Drive a ROS 2 robot (the only kind; required).
    #[arg(long)]
    pub(super) ros2: bool,
    /// The MCAP bag to write (cmd_vel and odom as ROS 2 channels).
    #[arg(long, value_name = "FILE")]
    pub(super) out: PathBuf,
    /// Length of the manoeuvre, s.
    #[arg(long, value_name = "S", value_parser = positive, default_value_t = 60.0)]
    pub(super) duration: f64,
    /// Stop with zero when odometry puts the robot farther than this from its start, m.
    #[arg(long, value_name = "M", value_parser = positive, default_value_t = 1.0)]
    pub(super) radius: f64,
    /// Command rate, Hz.
    #[arg(long, value_name = "HZ", value_parser = positive, default_value_t = 20.0)]
    pub(super) rate: f64,
    /// Add limit probes: reversals at the base's safe speeds (0.8 v_max, 0.8 ω_max, at most 0.3 m/s and 1 rad/s), steep enough to reach an acceleration limit, so that identify can claim it.
    #[arg(long)]
    pub(super) limits: bool,
    /// Seconds to wait for the first odometry.
    #[arg(long, value_name = "S", value_parser = positive, default_value_t = 10.0)]
    pub(super) wait: f64,
    #[command(flatten)]
    pub(super) net: NetArgs,
}

/// `echelon fleet collector`.
#[derive(Debug, Args)]
pub(crate) struct CollectorArgs {
    /// The scenario, for the fleet name and robot count (or give --fleet).
    pub(super) scenario: Option<String>,
    /// Output directory.
    #[arg(long, value_name = "DIR")]
    pub(super) out: PathBuf,
    /// Also record every agent's ROS 2 cmd_vel and odom ([fleet.ros2]) as ROS 2 channels.
    #[arg(long, requires = "scenario")]
    pub(super) ros2: bool,
    /// Kill this process with SIGKILL once a reference it records reaches fleet time S (a rehearsed `kill -9`: the fault matrix, docs/faults.md).
    #[arg(long, value_name = "S", value_parser = non_negative)]
    pub(super) die_at: Option<f64>,
    #[command(flatten)]
    pub(super) live: LiveArgs,
    #[command(flatten)]
    pub(super) net: NetArgs,
}

/// What the collector serves live and how densely it logs (`collector`,
/// and `up` for the collector it starts, with its own wording of the help).
#[derive(Debug, Args)]
pub(crate) struct LiveArgs {
    /// Serve the live fleet to Foxglove (its WebSocket protocol) on ADDR [default: 127.0.0.1:8765; port 0: any free port]: every channel of fleet.mcap, 3D ones with the scenario (docs/foxglove.md).
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = echelon_fleet::collector::DEFAULT_ADDR)]
    pub(super) foxglove: Option<std::net::SocketAddr>,
    /// Serve the live dashboard page on ADDR [default: 127.0.0.1:8766]: the robots moving, per robot link, ‖e‖, safety, saturation, and Stop all / Resume for whoever opens it with the operator token printed at start (docs/foxglove.md).
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = echelon_fleet::collector::DEFAULT_DASHBOARD)]
    pub(super) dashboard: Option<std::net::SocketAddr>,
    /// Log at most HZ states per robot per second (the first of each 1/HZ s of receipt time; the others counted as `decimated` in collector.json) [default: every state].
    #[arg(long, value_name = "HZ", value_parser = positive)]
    pub(super) log_rate: Option<f64>,
}

/// `echelon fleet router`.
#[derive(Debug, Args)]
pub(crate) struct RouterArgs {
    /// The scenario, for the access control's robot count and ROS 2 keys in secure mode (or give --robots).
    pub(super) scenario: Option<String>,
    /// `--listen` its endpoints, `--connect` other sites' routers (retried until they answer).
    #[command(flatten)]
    pub(super) net: NetArgs,
    /// Kill itself with SIGKILL once a reference it forwards reaches fleet time S (a rehearsed router failure: docs/faults.md).
    #[arg(long, value_name = "S", value_parser = non_negative)]
    pub(super) die_at: Option<f64>,
}

/// An endpoint to connect to, `<protocol>/<host>:<port>` (clap value
/// parser): Zenoh's own refusal was a JSON5 dump, and a port beyond 65535
/// waited for a connection that could never open.
pub(super) fn connect_endpoint(s: &str) -> Result<String, String> {
    echelon::scenario::check_endpoint(s).map(|()| s.to_owned())
}

/// An endpoint to listen on: as [`connect_endpoint`], and port 0 (any free
/// port) too.
pub(super) fn listen_endpoint(s: &str) -> Result<String, String> {
    echelon::scenario::check_listen_endpoint(s).map(|()| s.to_owned())
}
