//! A robot process: its options, and [`RobotTask`] on the fleet runtime.

use crate::faults::FaultSpec;
use crate::net;
use crate::options::{ProcessOptions, Resolved};
use crate::ros2::drift::Drift;
use crate::ros2::drive::Ros2Drive;
use crate::ros2::endpoint::{OwnedCmdSink, Ros2Node};
use crate::ros2::{fixes, graph};
use crate::runtime::{self, Task};
use crate::{FleetError, StopFlag};

use super::{Robot, RobotConfig, RobotReport, RobotTask};

/// Options of a robot process.
#[derive(Debug, Clone)]
pub struct RobotOptions {
    /// Scenario, clock, network and fleet name (`duration` absent: run
    /// until a signal).
    pub process: ProcessOptions,
    /// Agent number, from 1.
    pub agent: u32,
    /// Faults injected on what this robot receives.
    pub faults: FaultSpec,
    /// Drive the agent's ROS 2 robot (`[fleet.ros2]`) instead of a simulated one.
    pub ros2: bool,
    /// With `ros2`: reach the robot at its own router (the agent's
    /// `ros2.connect`, when it names one) in a second Zenoh session, apart
    /// from the fleet's; and join the fleet only once its odometry arrives.
    /// `false`: the robot is on the fleet's network (`fleet base`'s
    /// simulation, as `fleet up --ros2` runs it).
    pub own_router: bool,
    /// The operator token: it obeys only the resumes signed with it (none:
    /// it obeys no resume, and says so at its first tick).
    pub operator_token: Option<crate::token::OperatorToken>,
}

/// How long a robot process waits for its robot's first odometry before
/// joining the fleet, real time.
const FIRST_ODOMETRY_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(30);

/// Runs the robot until `duration` or the stop flag: [`RobotTask`] on the
/// fleet runtime, on its simulated drive or, with `ros2`, on its ROS 2
/// robot.
pub fn run(opts: RobotOptions, stop: &StopFlag) -> Result<RobotReport, FleetError> {
    let Resolved {
        plan,
        settings,
        keys,
    } = opts.process.resolve()?;
    let config = RobotConfig::from_plan(
        &plan,
        &settings,
        opts.agent,
        opts.faults,
        opts.process.duration,
    )?;
    // It obeys a resume only with a valid proof of the operator token.
    // (Without one it says so at its first tick: bad input is one line.)
    let config = RobotConfig {
        operator_token: opts.operator_token.clone(),
        ..config
    };
    let net = &opts.process.net;
    let clock = opts.process.clock();
    // Its probe (`fleet doctor`, the hub's join line): who it is, its
    // clock, and the address it reaches the fleet from.
    let member = crate::role::Member::Robot(opts.agent);
    let address = crate::probe::local_address_towards(&net.connect);
    let probe_keys = keys.clone();
    let probe =
        move |s: &zenoh::Session| crate::probe::declare_from(s, &probe_keys, member, address);
    if !opts.ros2 {
        let robot = Robot::simulated(config, net::rand_source());
        let task = RobotTask::new(robot, keys).dying_at(opts.process.die_at);
        return runtime::run_on(|s| Ok((task, probe(s)?)), net, clock, stop)?.report();
    }
    let link = settings.ros2[opts.agent as usize - 1].clone();
    let Some(velocity) = config.spec.velocity_robot() else {
        return Err(FleetError::Config(format!(
            "agent {}: a ROS 2 robot takes velocity commands: give it a velocity base (drive = \"velocity\") and the kinematic law",
            opts.agent
        )));
    };
    let base = velocity.base();
    let agent = opts.agent;
    let config = RobotConfig {
        driven: link.driven,
        watchdogs: super::WatchdogSettings {
            odom_timeout: link.odom_timeout,
            ..config.watchdogs
        },
        ..config
    };
    let fixes = fixes::for_agent(agent, &link, &plan, &config.spec)?;
    // Its σ on odometry alone, from the agent's `[odometry]` error model
    // (none: σ unknown, 0).
    let drift = plan
        .odometer(agent as usize - 1)
        .map(|o| Drift::new(o.spec().errors(), config.spec.drive().wheels()));
    let robot_net = match opts.own_router && !link.connect.is_empty() {
        true => Some(net::robot_router(agent, &link.connect, net)?),
        false => None,
    };
    let device = robot_net.as_ref().map(|net| runtime::Device {
        net,
        name: format!(
            "agent {agent}'s robot ({} at {})",
            link.odom,
            link.connect.join(" or ")
        ),
        first_sample: Some(FIRST_ODOMETRY_TIMEOUT),
    });
    let task = runtime::run_split(
        |fleet, robot| {
            let probe = probe(fleet)?;
            // The robot is the scenario's (its cmd_vel's type, its odom,
            // its namespace) before anything is declared or sent.
            let wait = match opts.own_router {
                true => graph::GRAPH_WAIT,
                false => graph::GRAPH_WAIT_SIMULATED,
            };
            graph::check_robot(robot, &link, agent, wait, stop)?;
            let node = Ros2Node::declare(robot, &link, agent)?;
            let mut drive = Ros2Drive::new(link, base, node.gid, OwnedCmdSink(node.publisher));
            if let Some(f) = fixes {
                drive = drive.with_fixes(f);
            }
            if let Some(d) = drift {
                drive = drive.with_drift(d);
            }
            let robot = Robot::new(config, drive, net::rand_source());
            // Refusals are counted in the drive's report; the inputs are
            // numbered as the drive's (odometry, then fixes, hazards, e-stop).
            let inputs = node.input_keys;
            let task = RobotTask::new(robot, keys)
                .dying_at(opts.process.die_at)
                .with_plant_inputs(inputs.clone(), |d, i, k, b, t| d.on_input(i, k, b, t));
            Ok((task, (node.tokens, probe), inputs))
        },
        net,
        device,
        clock,
        stop,
    )?;
    let ros2 = Some(*task.robot().plant().counters());
    Ok(RobotReport {
        ros2,
        ..task.report()?
    })
}
