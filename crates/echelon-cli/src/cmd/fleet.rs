//! `echelon fleet …`: the scenario as networked processes on Zenoh (leader,
//! robots, collector), `up` to run them all on loopback, `certs` for the
//! secure mode. Each process prints one JSON report line on stdout when it
//! stops; `up` prints a summary.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context, Result, bail};
use clap::{Args, Subcommand, ValueEnum};

use echelon::output::TrajectoryRows;
use echelon::scenario::{Overrides, Scenario, is_valid_fleet_name};
use echelon_fleet::bench::{self, BenchOptions, Progress};
use echelon_fleet::certs::{self, CertOptions};
use echelon_fleet::collector::{self, CollectorOptions, MCAP_FILE};
use echelon_fleet::excite::{self, ExciteOptions};
use echelon_fleet::faults::FaultSpec;
use echelon_fleet::latency::LatencyReport;
use echelon_fleet::leader::{self, LeaderOptions};
use echelon_fleet::net::{self, Mode, NetOptions, Secure};
use echelon_fleet::robot::{self, RobotOptions};
use echelon_fleet::role::Member;
use echelon_fleet::ros2::RosTopic;
use echelon_fleet::ros2::base::{self, BaseOptions};
use echelon_fleet::router::{self, RouterOptions};
use echelon_fleet::up::{self, Topology, UP_SUMMARY_FILE, UpOptions};
use echelon_fleet::{StopFlag, collector::SUMMARY_FILE};

use super::out::outln;
use super::{non_negative, parse_number, positive};

/// `echelon fleet` subcommands.
#[derive(Debug, Subcommand)]
pub(crate) enum FleetCommand {
    /// Publish the scenario's reference (the virtual leader).
    Leader(LeaderArgs),
    /// Run one agent of the scenario: control law on a simulated plant paced in real time, or on a ROS 2 robot (--ros2).
    Robot(RobotArgs),
    /// A simulated ROS 2 base (--ros2): cmd_vel in, odom out over rmw_zenoh, as diff_drive_controller on a robot.
    Base(BaseArgs),
    /// Drive one ROS 2 robot's cmd_vel with steps and chirps within its limits (--ros2) and record cmd_vel and odom to a bag for `echelon identify`.
    Excite(ExciteArgs),
    /// Record everything to DIR/fleet.mcap and DIR/trajectory.csv.
    Collector(CollectorArgs),
    /// A Zenoh router (the engine of zenohd) for the fleet's processes to link to; runs until SIGINT/SIGTERM.
    Router(RouterArgs),
    /// Start a router, a leader, one process per robot and a collector on loopback; stop them; summarise.
    #[command(allow_negative_numbers = true)]
    Up(UpArgs),
    /// Make a development CA and certificates for the secure mode.
    Certs(CertsArgs),
    /// Run `fleet up` for several fleet sizes on loopback at time scale 1 and tabulate startup, CPU, messages/s, latency, losses and final error.
    #[command(allow_negative_numbers = true)]
    Bench(BenchArgs),
}

/// Zenoh mode of a fleet process.
#[derive(Debug, Clone, Copy, ValueEnum)]
enum ModeArg {
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
    mode: Option<ModeArg>,
    /// Endpoint to listen on, e.g. tcp/0.0.0.0:7447 (repeatable) [default: tcp/127.0.0.1:0, quic/127.0.0.1:0 in secure mode].
    #[arg(long, value_name = "ENDPOINT")]
    listen: Vec<String>,
    /// Endpoint to connect to, e.g. tcp/192.168.1.10:7447 (repeatable).
    #[arg(long, value_name = "ENDPOINT")]
    connect: Vec<String>,
    /// A Zenoh configuration file (JSON5) to start from instead of the default (peer, no multicast).
    #[arg(long, value_name = "FILE")]
    zenoh_config: Option<PathBuf>,
    /// Fleet name, the second chunk of every key [default: the scenario's].
    #[arg(long, value_name = "NAME")]
    fleet: Option<String>,
    /// Secure mode: mutual TLS and access control with the certificates in DIR (`echelon fleet certs`).
    #[arg(long, value_name = "DIR")]
    secure: Option<PathBuf>,
    /// Certificate identity in secure mode [default: leader, robot-K, base-K, collector or router].
    #[arg(long, value_name = "ID", requires = "secure")]
    identity: Option<String>,
    /// Number of robot identities the access control knows [default: the scenario's agents].
    #[arg(long, value_name = "N", requires = "secure")]
    robots: Option<u32>,
}

impl NetArgs {
    fn options(
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
    loss: f64,
    /// Delay every received message by MS milliseconds of fleet time.
    #[arg(long, value_name = "MS", value_parser = non_negative, default_value_t = 0.0)]
    delay: f64,
    /// Drop everything received in [START, START+LEN) s of fleet time.
    #[arg(long, value_name = "START:LEN", value_parser = outage)]
    outage: Option<(f64, f64)>,
    /// Seed of the drop pattern.
    #[arg(long, value_name = "N", default_value_t = 0)]
    seed: u64,
}

impl FaultArgs {
    fn spec(&self) -> FaultSpec {
        FaultSpec {
            loss: self.loss,
            delay: self.delay * 1e-3,
            outage: self.outage,
            seed: self.seed,
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

/// `echelon fleet leader`.
#[derive(Debug, Args)]
pub(crate) struct LeaderArgs {
    /// A built-in scenario name or a path to a .toml file.
    scenario: String,
    /// Publication rate, Hz [default: the scenario's [fleet] reference_rate, else 50].
    #[arg(long, value_name = "HZ", value_parser = positive)]
    rate: Option<f64>,
    /// Fleet seconds to publish [default: the scenario's sim.duration].
    #[arg(long, value_name = "S", value_parser = positive)]
    duration: Option<f64>,
    /// Run the clock K times faster than real time.
    #[arg(long, value_name = "K", value_parser = positive, default_value_t = 1.0)]
    time_scale: f64,
    /// Wait for this process (collector, robot/K) before starting the clock (repeatable).
    #[arg(long, value_name = "ROLE")]
    wait_for: Vec<String>,
    /// Longest wait for --wait-for, s of real time.
    #[arg(long, value_name = "S", value_parser = positive, default_value_t = 60.0)]
    wait_timeout: f64,
    #[command(flatten)]
    net: NetArgs,
}

/// `echelon fleet robot`.
#[derive(Debug, Args)]
pub(crate) struct RobotArgs {
    /// A built-in scenario name or a path to a .toml file.
    scenario: String,
    /// Which agent of the scenario, from 1.
    #[arg(long, value_name = "K")]
    agent: u32,
    /// Stop at this fleet time, s [default: run until SIGINT/SIGTERM].
    #[arg(long, value_name = "S", value_parser = positive)]
    duration: Option<f64>,
    /// Run the clock K times faster than real time.
    #[arg(long, value_name = "K", value_parser = positive, default_value_t = 1.0)]
    time_scale: f64,
    /// Drive the agent's ROS 2 robot ([fleet.ros2]): odom in, cmd_vel out over rmw_zenoh.
    #[arg(long)]
    ros2: bool,
    /// With --ros2: the robot is `fleet base`'s simulation, so --time-scale
    /// may differ from 1 (a real robot runs in real time).
    #[arg(long, requires = "ros2")]
    simulated_base: bool,
    #[command(flatten)]
    faults: FaultArgs,
    #[command(flatten)]
    net: NetArgs,
}

/// `echelon fleet base`.
#[derive(Debug, Args)]
pub(crate) struct BaseArgs {
    /// A built-in scenario name or a path to a .toml file.
    scenario: String,
    /// Simulate a ROS 2 base (the only kind so far; required).
    #[arg(long)]
    ros2: bool,
    /// Which agent's base, from 1.
    #[arg(long, value_name = "K")]
    agent: u32,
    /// Stop after this many (scaled) seconds [default: run until SIGINT/SIGTERM].
    #[arg(long, value_name = "S", value_parser = positive)]
    duration: Option<f64>,
    /// Run the clock K times faster than real time.
    #[arg(long, value_name = "K", value_parser = positive, default_value_t = 1.0)]
    time_scale: f64,
    #[command(flatten)]
    net: NetArgs,
}

/// `echelon fleet excite`.
#[derive(Debug, Args)]
pub(crate) struct ExciteArgs {
    /// A built-in scenario name or a path to a .toml file (the agent's velocity base and [fleet.ros2] link).
    scenario: String,
    /// Drive a ROS 2 robot (the only kind; required).
    #[arg(long)]
    ros2: bool,
    /// Which agent's robot, from 1.
    #[arg(long, value_name = "K")]
    agent: u32,
    /// The MCAP bag to write (cmd_vel and odom as ROS 2 channels).
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
    /// Length of the manoeuvre, s.
    #[arg(long, value_name = "S", value_parser = positive, default_value_t = 60.0)]
    duration: f64,
    /// Stop with zero when odometry puts the robot farther than this from its start, m.
    #[arg(long, value_name = "M", value_parser = positive, default_value_t = 1.0)]
    radius: f64,
    /// Command rate, Hz.
    #[arg(long, value_name = "HZ", value_parser = positive, default_value_t = 20.0)]
    rate: f64,
    /// Seconds to wait for the first odometry.
    #[arg(long, value_name = "S", value_parser = positive, default_value_t = 10.0)]
    wait: f64,
    #[command(flatten)]
    net: NetArgs,
}

/// `echelon fleet collector`.
#[derive(Debug, Args)]
pub(crate) struct CollectorArgs {
    /// The scenario, for the fleet name and robot count (or give --fleet).
    scenario: Option<String>,
    /// Output directory.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Also record every agent's ROS 2 cmd_vel and odom ([fleet.ros2]) as ROS 2 channels.
    #[arg(long, requires = "scenario")]
    ros2: bool,
    #[command(flatten)]
    net: NetArgs,
}

/// `echelon fleet router`.
#[derive(Debug, Args)]
pub(crate) struct RouterArgs {
    /// The scenario, for the access control's robot count and ROS 2 keys in secure mode (or give --robots).
    scenario: Option<String>,
    /// `--listen` its endpoints, `--connect` other sites' routers (retried until they answer).
    #[command(flatten)]
    net: NetArgs,
}

/// How `fleet up` links its processes.
#[derive(Debug, Clone, Copy, ValueEnum)]
enum TopologyArg {
    /// A router per site; every process a Zenoh client with one link to its site's router.
    Router,
    /// Every process a peer linked to every other (N² links; a handful of robots).
    Mesh,
}

/// `echelon fleet up`.
#[derive(Debug, Args)]
pub(crate) struct UpArgs {
    /// A built-in scenario name or a path to a .toml file.
    scenario: String,
    /// Output directory.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Fleet seconds to run [default: the scenario's sim.duration].
    #[arg(long, value_name = "S", value_parser = positive)]
    duration: Option<f64>,
    /// Run every clock K times faster than real time.
    #[arg(long, value_name = "K", value_parser = positive, default_value_t = 1.0)]
    time_scale: f64,
    #[command(flatten)]
    faults: FaultArgs,
    /// Secure mode with the certificates in DIR (`echelon fleet certs DIR`).
    #[arg(long, value_name = "DIR")]
    secure: Option<PathBuf>,
    /// Robots drive simulated ROS 2 bases (one `fleet base --ros2` each), all robot↔base traffic in ROS 2's format.
    #[arg(long)]
    ros2: bool,
    /// How the processes link.
    #[arg(long, value_enum, default_value = "router")]
    topology: TopologyArg,
    /// Router topology: S routers linked to each other (sites on loopback), robots spread over them.
    #[arg(long, value_name = "S", default_value_t = 1)]
    sites: usize,
    /// Print nothing but errors.
    #[arg(long, short)]
    quiet: bool,
}

/// `echelon fleet bench`.
#[derive(Debug, Args)]
pub(crate) struct BenchArgs {
    /// Output directory: DIR/nNNN/ per size, DIR/bench.json and DIR/bench.md.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Fleet sizes to run, in order (robots behind a circle, generated).
    #[arg(long, value_name = "N,…", value_delimiter = ',', default_values_t = [10, 50, 100, 200])]
    robots: Vec<usize>,
    /// Fleet seconds each size runs (real seconds: time scale 1).
    #[arg(long, value_name = "S", value_parser = positive, default_value_t = 60.0)]
    duration: f64,
    /// Print only the table.
    #[arg(long, short)]
    quiet: bool,
}

/// `echelon fleet certs`.
#[derive(Debug, Args)]
pub(crate) struct CertsArgs {
    /// Output directory.
    dir: PathBuf,
    /// Number of robot identities (robot-1 … robot-N).
    #[arg(long, value_name = "N", default_value_t = 4)]
    robots: u32,
    /// Another host name or IP address the fleet's processes listen on (repeatable).
    #[arg(long, value_name = "HOST")]
    host: Vec<String>,
}

fn agents_of(s: &Scenario) -> Result<u32> {
    Ok(s.build(&Overrides::default())?.plan.agents().len() as u32)
}

/// One process of a scenario (leader, robot, base, excite): sets up what
/// every such process does first (its scenario, its session options as
/// `member`, and the signal flag), runs `run` with them and prints its report.
fn scenario_process<R, E>(
    scenario: &str,
    net: &NetArgs,
    member: Member,
    run: impl FnOnce(Scenario, NetOptions, &StopFlag) -> Result<R, E>,
) -> Result<()>
where
    R: serde::Serialize,
    E: std::error::Error + Send + Sync + 'static,
{
    let scenario = Scenario::resolve(scenario)?;
    let robots = agents_of(&scenario)?;
    let net = net.options(&member.identity(), Some(robots), Some(&scenario))?;
    let stop = StopFlag::on_signals()?;
    print_report(&run(scenario, net, &stop)?)
}

/// Every agent's `cmd_vel` and `odom` as `[fleet.ros2]` places them.
fn ros_topics(s: &Scenario) -> Result<Vec<RosTopic>> {
    let mut topics = Vec::new();
    for link in s.fleet()?.ros2 {
        topics.extend(RosTopic::of_link(&link)?);
    }
    Ok(topics)
}

fn print_report<T: serde::Serialize>(report: &T) -> Result<()> {
    outln!("{}", serde_json::to_string(report)?)?;
    Ok(())
}

/// Runs a fleet subcommand.
pub(crate) fn run(cmd: FleetCommand) -> Result<()> {
    match cmd {
        FleetCommand::Leader(a) => scenario_process(
            &a.scenario,
            &a.net,
            Member::Leader,
            |scenario, net, stop| {
                let options = LeaderOptions {
                    scenario,
                    rate: a.rate,
                    time_scale: a.time_scale,
                    duration: a.duration,
                    wait_for: a.wait_for,
                    wait_timeout: Duration::from_secs_f64(a.wait_timeout),
                    net,
                    fleet: a.net.fleet.clone(),
                };
                leader::run(options, stop)
            },
        ),
        FleetCommand::Robot(a) => {
            if a.ros2 && !a.simulated_base && a.time_scale != 1.0 {
                bail!(
                    "fleet robot --ros2 drives a real robot, which runs in real time: \
                     --time-scale {} is refused (give --simulated-base when the robot is \
                     `fleet base`'s simulation, as `fleet up --ros2` does)",
                    a.time_scale
                );
            }
            let member = Member::Robot(a.agent);
            scenario_process(&a.scenario, &a.net, member, |scenario, net, stop| {
                let options = RobotOptions {
                    scenario,
                    agent: a.agent,
                    time_scale: a.time_scale,
                    duration: a.duration,
                    faults: a.faults.spec(),
                    net,
                    fleet: a.net.fleet.clone(),
                    ros2: a.ros2,
                };
                robot::run(options, stop)
            })
        }
        FleetCommand::Base(a) => {
            if !a.ros2 {
                bail!("fleet base simulates a ROS 2 base: give --ros2");
            }
            let member = Member::Base(a.agent);
            scenario_process(&a.scenario, &a.net, member, |scenario, net, stop| {
                let options = BaseOptions {
                    scenario,
                    agent: a.agent,
                    time_scale: a.time_scale,
                    duration: a.duration,
                    net,
                    fleet: a.net.fleet.clone(),
                };
                base::run(options, stop)
            })
        }
        FleetCommand::Excite(a) => {
            if !a.ros2 {
                bail!("fleet excite drives a ROS 2 robot: give --ros2");
            }
            let member = Member::Robot(a.agent);
            scenario_process(&a.scenario, &a.net, member, |scenario, net, stop| {
                let options = ExciteOptions {
                    scenario,
                    agent: a.agent,
                    duration: a.duration,
                    radius: a.radius,
                    rate: a.rate,
                    wait: a.wait,
                    out: a.out,
                    net,
                };
                excite::run(options, stop)
            })
        }
        FleetCommand::Collector(a) => {
            let scenario = a.scenario.as_deref().map(Scenario::resolve).transpose()?;
            let fleet = match (&a.net.fleet, &scenario) {
                (Some(f), _) => f.clone(),
                (None, Some(s)) => s.fleet()?.name,
                (None, None) => bail!("give the scenario or --fleet NAME"),
            };
            let run = scenario
                .as_ref()
                .map(|s| s.build(&Overrides::default()))
                .transpose()?;
            let robots = run.as_ref().map(|r| r.plan.agents().len() as u32);
            let net = a
                .net
                .options(&Member::Collector.identity(), robots, scenario.as_ref())?;
            let stop = StopFlag::on_signals()?;
            let ros = match (&scenario, a.ros2) {
                (Some(s), true) => ros_topics(s)?,
                _ => Vec::new(),
            };
            // The columns `echelon run` writes for the same scenario.
            let trajectory = run.as_ref().map_or_else(TrajectoryRows::default, |r| {
                TrajectoryRows::for_agents(r.plan.agents())
            });
            let report = collector::run_recording(
                CollectorOptions {
                    out: a.out,
                    fleet,
                    max_wall: None,
                    net,
                },
                ros,
                trajectory,
                &stop,
            )?;
            print_report(&report)
        }
        FleetCommand::Router(a) => {
            if a.net.mode.is_some() || a.net.fleet.is_some() {
                bail!("fleet router is always a router, for every fleet: no --mode or --fleet");
            }
            let scenario = a.scenario.as_deref().map(Scenario::resolve).transpose()?;
            let robots = scenario.as_ref().map(agents_of).transpose()?;
            let net = a
                .net
                .options(&Member::Router.identity(), robots, scenario.as_ref())?;
            let stop = StopFlag::on_signals()?;
            let report = router::run(
                &RouterOptions {
                    net,
                    max_wall: None,
                },
                &stop,
            )?;
            print_report(&report)
        }
        FleetCommand::Up(a) => up_cmd(a),
        FleetCommand::Bench(a) => bench_cmd(a),
        FleetCommand::Certs(a) => {
            if a.robots == 0 {
                bail!("--robots must be ≥ 1");
            }
            let files = certs::generate(&CertOptions {
                dir: a.dir.clone(),
                robots: a.robots,
                hosts: a.host,
            })?;
            outln!(
                "wrote {} files to {} (CA, leader, collector, router, robot-1…robot-{n}, base-1…base-{n}); development use only",
                files.len(),
                a.dir.display(),
                n = a.robots
            )?;
            Ok(())
        }
    }
}

fn bench_cmd(a: BenchArgs) -> Result<()> {
    if a.robots.contains(&0) {
        bail!("--robots: every fleet size must be ≥ 1");
    }
    let stop = StopFlag::on_signals()?;
    let exe = std::env::current_exe().context("locating the echelon binary")?;
    let quiet = a.quiet;
    let duration = a.duration;
    let report = bench::run(
        &BenchOptions {
            robots: a.robots,
            duration,
            out: a.out.clone(),
            exe,
        },
        &stop,
        |p| {
            if quiet {
                return;
            }
            match p {
                Progress::Start { robots, index, of } => eprintln!(
                    "[{index}/{of}] {robots} robots: fleet up for {duration} s of fleet time…"
                ),
                Progress::Done(row) => match &row.error {
                    Some(e) => eprintln!("      failed: {e}"),
                    None => eprintln!(
                        "      done in {:.1} s ({}/{} converged)",
                        row.wall, row.converged, row.robots
                    ),
                },
            }
        },
    )?;
    outln!("{}", bench::markdown(&report).trim_end())?;
    if !quiet {
        outln!(
            "wrote {}, {}",
            a.out.join(bench::BENCH_JSON).display(),
            a.out.join(bench::BENCH_MD).display()
        )?;
    }
    if report.rows.iter().any(|r| r.error.is_some()) {
        bail!("some fleet sizes failed (see the table)");
    }
    Ok(())
}

fn up_cmd(a: UpArgs) -> Result<()> {
    let stop = StopFlag::on_signals()?;
    let exe = std::env::current_exe().context("locating the echelon binary")?;
    let report = up::run(
        &UpOptions {
            scenario: a.scenario,
            out: a.out.clone(),
            duration: a.duration,
            time_scale: a.time_scale,
            faults: a.faults.spec(),
            secure: a.secure,
            exe,
            ros2: a.ros2,
            topology: match a.topology {
                TopologyArg::Router => Topology::Router,
                TopologyArg::Mesh => Topology::Mesh,
            },
            sites: a.sites,
        },
        &stop,
    )?;
    if a.quiet {
        return Ok(());
    }
    outln!(
        "{}: fleet \"{}\", {} robot{}, {} s of fleet time at ×{} in {:.1} s",
        report.scenario,
        report.fleet,
        report.robots.len(),
        if report.robots.len() == 1 { "" } else { "s" },
        report.duration,
        report.time_scale,
        report.wall
    )?;
    if let (Some(startup), Some(run)) = (report.startup, report.run) {
        outln!("  startup (all joined) {startup:.2} s, then run {run:.2} s")?;
    }
    match report.topology {
        Topology::Router => outln!(
            "  through {} router{} at {}",
            report.routers.len(),
            if report.routers.len() == 1 { "" } else { "s" },
            report.router_endpoints.join(", ")
        )?,
        Topology::Mesh => outln!("  peer mesh (every process linked to every other)")?,
    }
    for (s, r) in report.routers.iter().enumerate() {
        outln!(
            "  router {}: {} processes at most at once, {} in all, up {:.1} s",
            s + 1,
            r.members_peak,
            r.members_joined,
            r.uptime
        )?;
    }
    outln!(
        "  leader: {} reference samples published",
        report.leader.published
    )?;
    outln!(
        "  {:<8} {:>11} {:>9} {:>9} {:>9} {:>6} {:>7} {:>9} {:>6} {:>9} {:>6} {:>8} {:>8}",
        "agent",
        "final ‖e‖",
        "received",
        "accepted",
        "loss",
        "outage",
        "malform",
        "wrong-ver",
        "stale",
        "reordered",
        "losses",
        "p50 ms",
        "p99 ms"
    )?;
    for r in &report.robots {
        let c = &r.counters;
        outln!(
            "  {:<8} {:>9.2e} m {:>9} {:>9} {:>9} {:>6} {:>7} {:>9} {:>6} {:>9} {:>6} {:>8.3} {:>8.3}",
            format!("robot {}", r.agent),
            r.final_error,
            c.received,
            c.accepted,
            c.injected_loss,
            c.injected_outage,
            c.malformed,
            c.wrong_version,
            c.stale,
            c.reordered,
            c.link_losses,
            r.latency.p50 * 1e3,
            r.latency.p99 * 1e3,
        )?;
    }
    for (b, r) in report.bases.iter().zip(&report.robots) {
        let c = &b.counters;
        let refused = c.cmd_wrong_type + c.cmd_malformed + c.cmd_non_finite + c.cmd_no_attachment;
        let ros = r.ros2.unwrap_or_default();
        let odom_refused =
            ros.odom_wrong_type + ros.odom_malformed + ros.odom_non_finite + ros.odom_wrong_frames;
        outln!(
            "  ROS 2 base {}: {} cmd_vel received, {} refused, {} odom published; robot: {} odom accepted, {} refused, {} commands saturated",
            b.agent,
            c.cmd_received,
            refused,
            c.odom_published,
            ros.odom_accepted,
            odom_refused,
            ros.cmd_saturated,
        )?;
    }
    if let Some(t) = &report.safety {
        for r in &report.robots {
            let s = r.safety.unwrap_or_default();
            let d = s.min_distance;
            outln!(
                "  safety, robot {}: filter acted {} of {} steps, {} infeasible (braked), {} deadlock breaks, {} stale neighbours ({} steps braked), nearest point {}",
                r.agent,
                s.active,
                s.steps,
                s.infeasible,
                s.deadlock_breaks,
                s.stale_neighbours,
                s.stale_brakes,
                d.map_or("none in range".to_owned(), |d| format!("{d:.4} m")),
            )?;
        }
        outln!(
            "  safety, fleet: acted {} steps, {} infeasible, {} deadlock breaks, {} stale neighbours, nearest points {}",
            t.active,
            t.infeasible,
            t.deadlock_breaks,
            t.stale_neighbours,
            t.min_distance
                .map_or("none in range".to_owned(), |d| format!("{d:.4} m")),
        )?;
        if !report.deadlocked_at_end.is_empty() {
            outln!(
                "  safety: robots {:?} ended away from their slots, held by their filters (deadlocked)",
                report.deadlocked_at_end
            )?;
        }
    }
    let col = &report.collector;
    outln!(
        "  collector: {} messages received, {} logged, {} rejected",
        col.received,
        col.logged,
        col.rejected.values().sum::<u64>()
    )?;
    let lat = |l: &LatencyReport| {
        format!(
            "{} samples, p50 {:.3} ms, p95 {:.3} ms, p99 {:.3} ms, max {:.3} ms",
            l.count,
            l.p50 * 1e3,
            l.p95 * 1e3,
            l.p99 * 1e3,
            l.max * 1e3
        )
    };
    let worst = report
        .latency
        .worst_robot
        .as_ref()
        .map_or(String::new(), |w| {
            format!(
                " (worst: robot {}, p99 {:.3} ms)",
                w.agent,
                w.latency.p99 * 1e3
            )
        });
    outln!(
        "  latency, leader → robot: {}{worst}",
        lat(&report.latency.robots)
    )?;
    outln!("  latency, → collector: {}", lat(&report.latency.collector))?;
    let mb = |b: u64| b as f64 / (1u64 << 20) as f64;
    let c = &report.cost;
    outln!(
        "  CPU: robots {:.2} s ({:.3} s per robot, max {:.3}), leader {:.2} s, collector {:.2} s, total {:.2} s",
        c.robots.cpu,
        c.robots.cpu_mean,
        c.robots.cpu_max,
        c.leader.cpu,
        c.collector.cpu,
        c.total.cpu
    )?;
    outln!(
        "  peak RSS: robot {:.1} MiB (mean; max {:.1}), leader {:.1} MiB, collector {:.1} MiB, sum {:.1} MiB",
        mb(c.robots.max_rss_mean),
        mb(c.robots.max_rss_max),
        mb(c.leader.max_rss_max),
        mb(c.collector.max_rss_max),
        mb(c.total.max_rss_sum)
    )?;
    if let Some(r) = &c.routers {
        outln!(
            "  routers: CPU {:.2} s, peak RSS {:.1} MiB (max)",
            r.cpu,
            mb(r.max_rss_max)
        )?;
    }
    outln!(
        "wrote {}, {}, {}, {}",
        a.out.join(MCAP_FILE).display(),
        a.out.join(echelon::output::TRAJECTORY_FILE).display(),
        a.out.join(SUMMARY_FILE).display(),
        a.out.join(UP_SUMMARY_FILE).display()
    )?;
    Ok(())
}
