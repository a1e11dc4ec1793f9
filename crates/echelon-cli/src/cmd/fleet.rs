//! `echelon fleet …`: the scenario as networked processes on Zenoh (leader,
//! robots, collector), `up` to run them all on loopback, `certs` for the
//! secure mode. Each process prints one JSON report line on stdout when it
//! stops; `up` prints a summary.

use std::time::Duration;

use anyhow::{Context, Result, bail};

use echelon::output::TrajectoryRows;
use echelon::scenario::{Overrides, Scenario};
use echelon::stats::Approach;
use echelon_fleet::certs::{self, CertOptions};
use echelon_fleet::collector::{self, ApproachWatch, CollectorOptions};
use echelon_fleet::command::Order;
use echelon_fleet::excite::{self, ExciteOptions};
use echelon_fleet::leader::{self, LeaderOptions};
use echelon_fleet::net::NetOptions;
use echelon_fleet::operator::{self, OperatorOptions};
use echelon_fleet::options::ProcessOptions;
use echelon_fleet::robot::{self, RobotOptions};
use echelon_fleet::role::Member;
use echelon_fleet::ros2::RosTopic;
use echelon_fleet::ros2::base::{self, BaseOptions};
use echelon_fleet::router::{self, RouterOptions};
use echelon_fleet::token::OperatorToken;
use echelon_fleet::{FleetError, StopFlag};
use echelon_mcap::scene::SceneSpec;

use super::out::outln;

mod args;
mod doctor;
mod loopback;
mod operator_args;
mod status;
mod subcommand;
pub(crate) use args::NetArgs;
use loopback::{bench_cmd, faults_cmd, up_cmd};
use operator_args::TopologyArg;
pub(crate) use operator_args::{BenchArgs, FaultsArgs, UpArgs};
pub(crate) use subcommand::FleetCommand;

fn agents_of(s: &Scenario) -> Result<u32> {
    Ok(s.build(&Overrides::default())?.plan.agents().len() as u32)
}

/// The session options of `member` joining by `net`, the access control
/// sized by the scenario's agents when there is one.
fn session(net: &NetArgs, member: Member, scenario: Option<&Scenario>) -> Result<NetOptions> {
    let robots = scenario.map(agents_of).transpose()?;
    net.options(&member.identity(), robots, scenario)
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
    let net = session(net, member, Some(&scenario))?;
    let stop = StopFlag::on_signals()?;
    print_report(&run(scenario, net, &stop)?)
}

/// Agent K's process on the fleet clock (robot, base): [`scenario_process`]
/// as `member(K)`, `run` given its process options and K.
fn agent_process<R, E>(
    a: &args::AgentClockArgs,
    net: &NetArgs,
    member: fn(u32) -> Member,
    run: impl FnOnce(ProcessOptions, u32, &StopFlag) -> Result<R, E>,
) -> Result<()>
where
    R: serde::Serialize,
    E: std::error::Error + Send + Sync + 'static,
{
    let k = a.agent.agent;
    scenario_process(
        &a.agent.scenario,
        net,
        member(k),
        |scenario, options, stop| run(a.clock.process(scenario, options, net), k, stop),
    )
}

/// Every agent's `cmd_vel` and `odom` as `[fleet.ros2]` places them, the
/// ground truth a simulated base publishes and the fixes it takes.
fn ros_topics(s: &Scenario) -> Result<Vec<RosTopic>> {
    let mut topics = Vec::new();
    for link in s.fleet()?.ros2 {
        topics.extend(RosTopic::all_of_link(&link)?);
    }
    Ok(topics)
}

/// `fleet robot`: from its robot.toml (`--config`, the hub given by
/// `--hub` if at all), or from the command line.
fn robot_cmd(a: args::RobotArgs) -> Result<()> {
    let options = match &a.config {
        Some(path) => {
            if a.clock.is_given() || a.faults.spec() != Default::default() || a.net.beyond_hub() {
                bail!(
                    "fleet robot --config {}: the file holds the robot's whole configuration; only --hub may be given with it",
                    path.display()
                );
            }
            robot::RobotFile::load(path)?
                .with_hub(&a.net.hub)
                .options()?
        }
        None => {
            let (Some(scenario), Some(agent)) = (&a.scenario, a.agent) else {
                bail!("give SCENARIO --agent K, or --config robot.toml");
            };
            if a.ros2 && !a.simulated_base && a.clock.time_scale != 1.0 {
                bail!(
                    "fleet robot --ros2 drives a real robot, which runs in real time: \
                     --time-scale {} is refused (give --simulated-base when the robot is \
                     `fleet base`'s simulation, as `fleet up --ros2` does)",
                    a.clock.time_scale
                );
            }
            let scenario = Scenario::resolve(scenario)?;
            let net = session(&a.net, Member::Robot(agent), Some(&scenario))?;
            RobotOptions {
                process: a.clock.process(scenario, net, &a.net),
                agent,
                faults: a.faults.spec(),
                ros2: a.ros2,
                own_router: !a.simulated_base,
                operator_token: OperatorToken::from_env()?,
            }
        }
    };
    let stop = StopFlag::on_signals()?;
    print_report(&robot::run(options, &stop)?)
}

/// `fleet host`: the robots of its robot files (`--config`, the hub given
/// by `--hub` if at all), or the scenario's `--robots`; prints each
/// robot's report (one JSON array) and fails when one of them failed.
fn host_cmd(a: args::HostArgs) -> Result<()> {
    let robots = match (&a.scenario, &a.agents) {
        (Some(scenario), Some(args::AgentList(agents))) => {
            let scenario = Scenario::resolve(scenario)?;
            let first = Member::Robot(agents[0]);
            let net = session(&a.net, first, Some(&scenario))?;
            let token = OperatorToken::from_env()?;
            agents
                .iter()
                .map(|&agent| RobotOptions {
                    process: a.clock.process(scenario.clone(), net.clone(), &a.net),
                    agent,
                    faults: a.faults.spec(),
                    ros2: false,
                    own_router: false,
                    operator_token: token.clone(),
                })
                .collect()
        }
        _ => {
            if a.clock.is_given() || a.faults.spec() != Default::default() || a.net.beyond_hub() {
                bail!(
                    "fleet host --config: the files hold the robots' whole configuration; only --hub may be given with them"
                );
            }
            a.config
                .iter()
                .map(|path| robot::RobotFile::load(path)?.with_hub(&a.net.hub).options())
                .collect::<Result<Vec<_>, _>>()?
        }
    };
    let stop = StopFlag::on_signals()?;
    let report = echelon_fleet::host::run(&echelon_fleet::host::HostOptions { robots }, &stop)?;
    print_report(&report)?;
    let failed: Vec<String> = report
        .iter()
        .filter_map(|r| Some(format!("{}: {}", r.name, r.error.as_ref()?)))
        .collect();
    if !failed.is_empty() {
        return Err(crate::cmd::out::Failed(failed.join("; ")).into());
    }
    Ok(())
}

fn print_report<T: serde::Serialize>(report: &T) -> Result<()> {
    outln!("{}", serde_json::to_string(report)?)?;
    Ok(())
}

/// `fleet stop` / `fleet resume`: puts the command (a resume signed with
/// `token`, and refused before anything is put without one), prints the
/// report, fails (exit 2) when a robot refused the resume, (exit 1) when a
/// robot alive did not acknowledge it.
fn command_cmd(
    a: operator_args::CommandArgs,
    order: Order,
    token: Option<OperatorToken>,
) -> Result<()> {
    if order == Order::Resume && token.is_none() {
        return Err(FleetError::Refused(operator::NEEDS_TOKEN.to_owned()).into());
    }
    let scenario = a.scenario.as_deref().map(Scenario::resolve).transpose()?;
    let fleet = a.net.fleet_name(scenario.as_ref())?;
    let net = session(&a.net, Member::Operator, scenario.as_ref())?;
    let stop = StopFlag::on_signals()?;
    let report = operator::run(
        &OperatorOptions {
            fleet: fleet.clone(),
            order,
            reason: a.reason,
            timeout: Duration::from_secs_f64(a.timeout),
            net,
            token,
        },
        &stop,
    )?;
    print_report(&report)?;
    // A robot that refused the resume (no valid operator token) stays
    // stopped whatever the wait: a refused order, as a hazard's.
    if !report.refused.is_empty() {
        return Err(FleetError::Refused(format!(
            "fleet resume refused: {}; those robots stay stopped (give the fleet's operator token: fleet up's OUT/operator-token, and ECHELON_OPERATOR_TOKEN on robots started by hand)",
            report.refused.join("; ")
        ))
        .into());
    }
    // An order that reached no robot, or fewer than the scenario has, did
    // not do what the operator asked: say so, and fail (a stop typed
    // without the hub's endpoint reached nobody and used to exit 0).
    if report.alive.is_empty() {
        return Err(crate::cmd::out::Failed(format!(
            "fleet {}: no robot of fleet `{fleet}` is reachable from here (give the hub's endpoint with --connect, and --mode as the fleet runs); the {} reached {}",
            order.name(),
            order.name(),
            if report.leader { "only the leader" } else { "no one" }
        ))
        .into());
    }
    if let Some(s) = &scenario {
        let agents = s.file.agents.len();
        let reached: std::collections::BTreeSet<&str> =
            report.alive.iter().map(String::as_str).collect();
        let absent: Vec<String> = (1..=agents as u32)
            .map(|k| Member::Robot(k).liveliness())
            .filter(|r| !reached.contains(r.as_str()))
            .collect();
        if !absent.is_empty() {
            return Err(crate::cmd::out::Failed(format!(
                "fleet {}: {} of the scenario's {agents} robots are not reachable from here: {}",
                order.name(),
                absent.len(),
                absent.join(", ")
            ))
            .into());
        }
    }
    if !report.missing.is_empty() {
        return Err(crate::cmd::out::Failed(format!(
            "fleet {}: {} did not acknowledge within {} s",
            order.name(),
            report.missing.join(", "),
            a.timeout
        ))
        .into());
    }
    Ok(())
}

/// Runs a fleet subcommand.
pub(crate) fn run(cmd: FleetCommand) -> Result<()> {
    size_runtime(&cmd);
    match cmd {
        FleetCommand::Leader(a) => leader_cmd(a),
        FleetCommand::Robot(a) => robot_cmd(a),
        FleetCommand::Host(a) => host_cmd(a),
        FleetCommand::Idle(a) => print_report(&echelon_fleet::cost::idle(
            a.rate,
            a.duration,
            &StopFlag::on_signals()?,
        )?),
        FleetCommand::Bundle(a) => bundle_cmd(a),
        FleetCommand::Base(a) => base_cmd(a),
        FleetCommand::Excite(a) => excite_cmd(a),
        FleetCommand::Collector(a) => collector_cmd(a),
        FleetCommand::Router(a) => router_cmd(a),
        FleetCommand::Heartbeat(a) => heartbeat_cmd(a),
        FleetCommand::Garbage(a) => garbage_cmd(a),
        FleetCommand::Faults(a) => faults_cmd(a),
        // A stop needs no token: stopping is always allowed.
        FleetCommand::Stop(a) => command_cmd(a, Order::Stop, None),
        FleetCommand::Resume(a) => {
            let token = a.operator_token()?;
            command_cmd(a.command, Order::Resume, token)
        }
        FleetCommand::Status(a) => status::status_cmd(a),
        FleetCommand::Doctor(a) => doctor::doctor_cmd(a),
        FleetCommand::Up(a) => up_cmd(a),
        FleetCommand::Bench(a) => bench_cmd(a),
        FleetCommand::Certs(a) => certs_cmd(a),
    }
}

/// A fleet process's Zenoh runtime sized for it (overridable).
fn size_runtime(cmd: &FleetCommand) {
    match cmd {
        FleetCommand::Router(_) => echelon_fleet::net::exec_with_sized_runtime("router"),
        FleetCommand::Leader(_)
        | FleetCommand::Heartbeat(_)
        | FleetCommand::Garbage(_)
        | FleetCommand::Robot(_)
        | FleetCommand::Host(_)
        | FleetCommand::Base(_)
        | FleetCommand::Collector(_) => echelon_fleet::net::exec_with_sized_runtime("client"),
        _ => {}
    }
}

/// `fleet leader`: publishes the scenario's reference.
fn leader_cmd(a: args::LeaderArgs) -> Result<()> {
    scenario_process(
        &a.scenario,
        &a.net,
        Member::Leader,
        |scenario, net, stop| {
            let options = LeaderOptions {
                process: a.clock.process(scenario, net, &a.net),
                rate: a.rate,
                wait_for: a.wait_for,
                wait_timeout: Duration::from_secs_f64(a.wait_timeout),
                rogue: a.rogue,
            };
            leader::run(options, stop)
        },
    )
}

/// `fleet bundle`: writes each on-board robot's directory.
fn bundle_cmd(a: operator_args::BundleArgs) -> Result<()> {
    if let Some(name) = &a.fleet
        && !echelon::scenario::is_valid_fleet_name(name)
    {
        bail!("--fleet `{name}`: letters, digits, '-', '_' and '.' only");
    }
    let token = match &a.token_file {
        Some(path) => Some(OperatorToken::from_file(path).context("--token-file")?),
        None => OperatorToken::from_env()?,
    };
    let report = echelon_fleet::bundle::write(&echelon_fleet::bundle::BundleOptions {
        scenario: a.scenario,
        hub: a.hub,
        out: a.out,
        all: a.all,
        simulated: a.simulated,
        time_scale: a.time_scale,
        duration: a.duration,
        secure: a.secure,
        token,
        fleet: a.fleet,
        install_dir: a.install_dir,
    })?;
    for (k, dir) in &report.robots {
        eprintln!(
            "fleet bundle: robot {k}: {} (on its computer: {}/echelon-robot.sh)",
            dir.display(),
            dir.display()
        );
    }
    print_report(&report)
}

/// `fleet base --ros2`: a simulated ROS 2 base.
fn base_cmd(a: args::BaseArgs) -> Result<()> {
    if !a.ros2 {
        bail!("fleet base simulates a ROS 2 base: give --ros2");
    }
    agent_process(&a.agent, &a.net, Member::Base, |process, agent, stop| {
        let options = BaseOptions {
            process,
            agent,
            clock_offset: a.clock_offset,
            hazards: a.hazard.clone(),
            fault_at: a.fault_at.map(|t| (t, a.fault_window)),
        };
        base::run(options, stop)
    })
}

/// `fleet excite --ros2`: drives one ROS 2 robot and records a bag.
fn excite_cmd(a: args::ExciteArgs) -> Result<()> {
    if !a.ros2 {
        bail!("fleet excite drives a ROS 2 robot: give --ros2");
    }
    let member = Member::Robot(a.agent.agent);
    scenario_process(&a.agent.scenario, &a.net, member, |scenario, net, stop| {
        let options = ExciteOptions {
            scenario,
            agent: a.agent.agent,
            duration: a.duration,
            radius: a.radius,
            rate: a.rate,
            limits: a.limits,
            wait: a.wait,
            out: a.out,
            net,
        };
        excite::run(options, stop)
    })
}

/// `fleet collector`: records the fleet (with the scenario, its 3D scene,
/// ROS 2 channels and closest approach too).
fn collector_cmd(a: args::CollectorArgs) -> Result<()> {
    let scenario = a.scenario.as_deref().map(Scenario::resolve).transpose()?;
    let fleet = a.net.fleet_name(scenario.as_ref())?;
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
    // With the scenario, fleet.mcap also carries the 3D channels.
    let scene = run.as_ref().map(|r| SceneSpec::of(&r.plan));
    // With `[safety]`: the closest approach from the true states.
    let approach = match (&scenario, &run) {
        (Some(s), Some(r)) => Approach::of(&r.plan)
            .map(|a| Ok::<_, anyhow::Error>(ApproachWatch::new(a, 1.0 / s.fleet()?.control_rate)))
            .transpose()?,
        _ => None,
    };
    let report = collector::run_with(
        CollectorOptions {
            out: a.out,
            fleet,
            max_wall: None,
            net,
            die_at: a.die_at,
        },
        collector::Recording {
            ros,
            trajectory,
            scene,
            foxglove: a.live.foxglove,
            dashboard: a.live.dashboard,
            log_rate: a.live.log_rate,
            approach,
        },
        &stop,
    )?;
    print_report(&report)
}

/// `fleet router`: a Zenoh router for every fleet.
fn router_cmd(a: args::RouterArgs) -> Result<()> {
    if a.net.mode.is_some() || a.net.fleet.is_some() {
        bail!("fleet router is always a router, for every fleet: no --mode or --fleet");
    }
    let scenario = a.scenario.as_deref().map(Scenario::resolve).transpose()?;
    let net = session(&a.net, Member::Router, scenario.as_ref())?;
    let stop = StopFlag::on_signals()?;
    let report = router::run(
        &RouterOptions {
            net,
            max_wall: None,
            die_at: a.die_at,
        },
        &stop,
    )?;
    print_report(&report)
}

/// `fleet heartbeat`: the operator's deadman heartbeat.
fn heartbeat_cmd(a: args::HeartbeatArgs) -> Result<()> {
    scenario_process(
        &a.scenario,
        &a.net,
        Member::Operator,
        |scenario, net, stop| {
            echelon_fleet::heartbeat::run(a.clock.process(scenario, net, &a.net), stop)
        },
    )
}

/// `fleet garbage`: hostile input on every key of the fleet.
fn garbage_cmd(a: args::GarbageArgs) -> Result<()> {
    scenario_process(
        &a.scenario,
        &a.net,
        Member::Operator,
        |scenario, net, stop| {
            echelon_fleet::garbage::run(
                a.clock.process(scenario, net, &a.net),
                a.from,
                a.length,
                a.seed,
                stop,
            )
        },
    )
}

/// `fleet certs`: a development CA and certificates.
fn certs_cmd(a: operator_args::CertsArgs) -> Result<()> {
    if a.robots == 0 {
        bail!("--robots must be ≥ 1");
    }
    let options = CertOptions {
        dir: a.dir.clone(),
        robots: a.robots,
        hosts: a.host,
    };
    let files = certs::generate_with(&options, &a.expires)?;
    outln!(
        "wrote {} files to {} (CA, leader, collector, router, operator, robot-1…robot-{n}, base-1…base-{n}); development use only",
        files.len(),
        a.dir.display(),
        n = a.robots
    )?;
    Ok(())
}
