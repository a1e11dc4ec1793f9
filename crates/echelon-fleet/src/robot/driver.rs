//! The Zenoh driver of [`Robot`]: the network, the clock, the sleeps.

use std::sync::mpsc;
use std::time::{Duration, Instant};

use zenoh::Wait;

use echelon::formation::Leader;
use echelon::scenario::{FleetSettings, Scenario};

use crate::clock::FleetClock;
use crate::faults::FaultSpec;
use crate::keys::{Keys, robot_role};
use crate::latency::{self};
use crate::net::{self, NetOptions};
use crate::plant::Plant;
use crate::ros2::drive::Ros2Drive;
use crate::wire::{self, DecodeError, Message};
use crate::{FleetError, StopFlag};

use super::{Robot, RobotConfig, RobotReport, RobotStats};
use crate::ros2::endpoint::{Ros2Endpoint, ZenohCmdSink};

/// Options of a robot process.
#[derive(Debug, Clone)]
pub struct RobotOptions {
    /// The scenario.
    pub scenario: Scenario,
    /// Agent number, from 1.
    pub agent: u32,
    /// Clock speed-up `K`.
    pub time_scale: f64,
    /// Stop at this fleet time (absent: run until a signal).
    pub duration: Option<f64>,
    /// Faults injected on what this robot receives.
    pub faults: FaultSpec,
    /// Network.
    pub net: NetOptions,
    /// Fleet name (absent: the scenario's).
    pub fleet: Option<String>,
    /// Drive the agent's ROS 2 robot (`[fleet.ros2]`) instead of a simulated one.
    pub ros2: bool,
}

/// Runs the robot until `duration` or the stop flag: the Zenoh driver of
/// [`Robot`].
pub fn run(opts: RobotOptions, stop: &StopFlag) -> Result<RobotReport, FleetError> {
    let fleet: FleetSettings = opts.scenario.fleet()?;
    let config = RobotConfig::from_scenario(
        &opts.scenario,
        &fleet,
        opts.agent,
        opts.faults,
        opts.duration,
    )?;
    let keys = Keys::new(opts.fleet.as_deref().unwrap_or(&fleet.name));
    let leader_key = match config.spec.leader {
        Leader::Reference => keys.reference(),
        Leader::Agent(j) => keys.state(j as u32 + 1),
    };

    let session = net::open(&opts.net)?;
    let (tx, rx) = mpsc::channel::<Arrival>();
    let _subscriber = session
        .declare_subscriber(&leader_key)
        .callback(move |sample| {
            let delay = latency::delay_ns(sample.timestamp(), crate::unix_nanos());
            let _ = tx.send((
                Instant::now(),
                delay,
                sample.payload().to_bytes().into_owned(),
            ));
        })
        .wait()
        .map_err(|e| FleetError::Zenoh(format!("subscribing to {leader_key}: {e}")))?;
    // With a safety filter: every robot's state, decoded where it arrives
    // (the bytes are not copied; the table keeps one slot per agent).
    let (ntx, nrx) = mpsc::channel::<NeighbourArrival>();
    let _neighbours = match config.safety {
        Some(_) => {
            let key = keys.states();
            Some(
                session
                    .declare_subscriber(&key)
                    .callback(move |sample| {
                        let msg = wire::decode(&sample.payload().to_bytes());
                        let _ = ntx.send((Instant::now(), msg));
                    })
                    .wait()
                    .map_err(|e| FleetError::Zenoh(format!("subscribing to {key}: {e}")))?,
            )
        }
        None => None,
    };
    let publisher = session
        .declare_publisher(keys.state(opts.agent))
        .wait()
        .map_err(|e| FleetError::Zenoh(format!("declaring the state publisher: {e}")))?;
    let _token = session
        .liveliness()
        .declare_token(keys.alive(&robot_role(opts.agent)))
        .wait()
        .map_err(|e| FleetError::Zenoh(format!("liveliness: {e}")))?;

    let driver = Driver {
        clock: FleetClock::new(opts.time_scale),
        rx,
        neighbours: nrx,
        publisher,
        session: &session,
        stats_key: keys.stats(opts.agent),
    };
    let report = if opts.ros2 {
        let link = fleet.ros2[opts.agent as usize - 1].clone();
        let Some(robot) = config.spec.velocity_robot() else {
            return Err(FleetError::Config(format!(
                "agent {}: a ROS 2 robot takes velocity commands: give it a velocity base (drive = \"velocity\") and the kinematic law",
                opts.agent
            )));
        };
        let ros = Ros2Endpoint::declare(&session, &link, opts.agent)?;
        let drive = Ros2Drive::new(link, robot.base(), ros.gid, ZenohCmdSink(&ros.publisher));
        let robot = Robot::new(config, drive, net::rand_source());
        let clock = driver.clock;
        let (robot, result) = driver.run(robot, stop, |robot| {
            while let Ok((arrival, key, bytes)) = ros.odom.try_recv() {
                let t = robot.fleet_time(clock.at(arrival));
                // Refusals are counted in the drive's report.
                let _ = robot.plant_mut().on_odom(&key, &bytes, t);
            }
        });
        result?;
        RobotReport {
            ros2: Some(*robot.plant().counters()),
            ..robot.report()
        }
    } else {
        let (robot, result) =
            driver.run(Robot::simulated(config, net::rand_source()), stop, |_| {});
        result?;
        robot.report()
    };
    let _ = session.close().wait();
    Ok(report)
}

/// A leader-stream sample as the subscription hands it over: when it
/// arrived, its delay since the sender's stamp (ns), its bytes.
type Arrival = (Instant, Option<i64>, Vec<u8>);

/// Another robot's state as the neighbour subscription hands it over.
type NeighbourArrival = (Instant, Result<Message, DecodeError>);

/// The Zenoh side of [`run`] for any plant.
struct Driver<'a> {
    clock: FleetClock,
    rx: mpsc::Receiver<Arrival>,
    neighbours: mpsc::Receiver<NeighbourArrival>,
    publisher: zenoh::pubsub::Publisher<'a>,
    session: &'a zenoh::Session,
    stats_key: String,
}

impl Driver<'_> {
    /// Ticks `robot` until its duration or the stop flag; `feed` hands the
    /// plant what arrived for it before each tick. The robot has been
    /// [finished](Robot::finish) (zero commanded) when this returns.
    fn run<P: Plant>(
        self,
        mut robot: Robot<P>,
        stop: &StopFlag,
        mut feed: impl FnMut(&mut Robot<P>),
    ) -> (Robot<P>, Result<(), FleetError>) {
        let clock = self.clock;
        let mut buf = Vec::with_capacity(wire::STATE_LEN);
        let nap = Duration::from_millis(20);
        let mut failure = None;
        while !stop.is_raised() {
            clock.sleep_until(robot.next_wake(), nap);
            if !robot.is_due(clock.now()) {
                continue;
            }
            while let Ok((arrival, delay, bytes)) = self.rx.try_recv() {
                robot.on_stamped_message(&bytes, clock.at(arrival), delay);
            }
            while let Ok((arrival, msg)) = self.neighbours.try_recv() {
                robot.on_neighbour(msg, clock.at(arrival));
            }
            feed(&mut robot);
            let out = robot.tick(clock.now());
            if let Some((h, state)) = out.publish {
                wire::encode_state(&mut buf, h, &state);
                if let Err(e) = net::publish(self.session, &self.publisher, &buf) {
                    failure = Some(e);
                    break;
                }
            }
            if let Some(stats) = out.stats {
                publish_stats(self.session, &self.stats_key, &stats);
            }
            if out.done {
                break;
            }
        }
        let stats = robot.finish();
        if failure.is_none()
            && let Some(why) = robot.diverged()
        {
            failure = Some(FleetError::Diverged(why.to_owned()));
        }
        if failure.is_none() {
            publish_stats(self.session, &self.stats_key, &stats);
        }
        (robot, failure.map_or(Ok(()), Err))
    }
}

fn publish_stats(session: &zenoh::Session, key: &str, stats: &RobotStats) {
    if let Ok(json) = serde_json::to_vec(stats) {
        net::put_stamped(session, key, json);
    }
}
