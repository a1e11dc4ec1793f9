//! `echelon fleet excite --ros2`: an identification manoeuvre on one real
//! ROS 2 robot, recorded to a bag that `echelon identify` reads.
//!
//! [`ExciteSignal`] (pure, deterministic, in `echelon::identify::excite`
//! where identification's tests use it too) is the command: a rest, steps
//! of `v` and `ω` on four levels sized from the scenario's base (the prior)
//! so that its acceleration limit never binds and a lower true limit still
//! leaves steps free of it, limit probes when `--limits` asks (reversals at
//! the base's safe speeds), then a chirp of both, then a stop. It stays
//! within the base's safe speeds (`0.8 v_max`, `0.8 ω_max`, at most
//! [`V_CAP`], [`OMEGA_CAP`]) and keeps the robot in a small area: the steps
//! come in retraced pairs, back at the start pose every four steps under an
//! ideal base.
//!
//! [`ExciteTask`] drives the robot's `cmd_vel` with it through a
//! [`Ros2Drive`] (the robot's limits applied; rmw_zenoh keys, attachments
//! and the node's liveliness as `fleet robot --ros2` declares them, on the
//! fleet runtime: [`run`]), and records every command sent and every valid
//! odometry received to an MCAP bag as `ros2 bag record -s mcap` would
//! (ROS 2 channels of [`RosTopic::of_link`]). It commands zero and stops at
//! the end, on SIGINT/SIGTERM, when the odometry is lost (older than
//! `odom_timeout`) and when the odometry says the robot left `radius` of
//! its start; the bag is finished in every case.

use std::path::PathBuf;

use serde::Serialize;

use echelon::agent::Drive;
use echelon::model::State;
use echelon::scenario::{Overrides, Scenario};
use echelon_mcap::McapLog;

use crate::clock::FleetClock;
use crate::net::NetOptions;
use crate::plant::{Command, Plant};
use crate::robot::agent_spec;
use crate::ros2::drive::{CmdSink, Ros2Counters, Ros2Drive};
use crate::ros2::endpoint::{OwnedCmdSink, Ros2Node};
use crate::ros2::record::RosTopic;
use crate::runtime::{self, Flow, Outputs, Sample, Task};
use crate::{FleetError, StopFlag};

pub use echelon::identify::excite::{
    ExciteDesign, ExciteSignal, MARGIN, OMEGA_CAP, SLOWEST_ODOMETRY, V_CAP,
};

/// Options of `fleet excite --ros2`.
#[derive(Debug, Clone)]
pub struct ExciteOptions {
    /// The scenario (the agent's base model and `[fleet.ros2]` link).
    pub scenario: Scenario,
    /// Agent number, from 1.
    pub agent: u32,
    /// Length of the manoeuvre, s.
    pub duration: f64,
    /// Stop when odometry puts the robot farther than this from its start, m.
    pub radius: f64,
    /// Command rate, Hz.
    pub rate: f64,
    /// Add limit probes to the manoeuvre (`--limits`): reversals at the
    /// base's safe speeds, steep enough to reach an acceleration limit.
    pub limits: bool,
    /// How long to wait for the first odometry, s.
    pub wait: f64,
    /// The bag to write.
    pub out: PathBuf,
    /// Network.
    pub net: NetOptions,
}

/// Why the manoeuvre ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ExciteEnd {
    /// It ran to its end.
    Completed,
    /// SIGINT or SIGTERM.
    Signal,
    /// The odometry stopped (older than `odom_timeout`).
    OdometryLost,
    /// The odometry put the robot outside `radius`.
    LeftRadius,
}

/// What `fleet excite` reports when it stops.
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExciteReport {
    /// [`crate::role::Role::Excite`].
    pub role: crate::role::Role,
    /// Agent number.
    pub agent: u32,
    /// Why it ended.
    pub ended: ExciteEnd,
    /// The bag written.
    pub bag: String,
    /// Its `cmd_vel` and `odom` topics.
    pub topics: [String; 2],
    /// Commands recorded.
    pub cmd_recorded: u64,
    /// Odometry messages recorded.
    pub odom_recorded: u64,
    /// The farthest the odometry put the robot from its start, m.
    pub max_distance: f64,
    /// The signal's amplitudes `[v, ω]` and step hold.
    pub amplitudes: [f64; 2],
    /// Seconds per step.
    pub hold: f64,
    /// The drive's counters.
    pub ros2: Ros2Counters,
}

/// A [`CmdSink`] that keeps what it sent for the bag.
#[derive(Debug)]
struct Recording<S> {
    inner: S,
    sent: Vec<(u64, Vec<u8>)>,
}

impl<S: CmdSink> CmdSink for Recording<S> {
    fn now_ns(&self) -> i64 {
        self.inner.now_ns()
    }
    fn send(&mut self, payload: &[u8], attachment: &[u8]) -> Result<(), String> {
        self.inner.send(payload, attachment)?;
        self.record(payload);
        Ok(())
    }
    /// The stop's zero goes out as the inner sink sends stops (reliably,
    /// [`CmdSink::send_stop`]), and is recorded like any command.
    fn send_stop(&mut self, payload: &[u8], attachment: &[u8]) -> Result<(), String> {
        self.inner.send_stop(payload, attachment)?;
        self.record(payload);
        Ok(())
    }
}

impl<S> Recording<S> {
    /// Keeps a sent command for the bag, stamped now.
    fn record(&mut self, payload: &[u8]) {
        self.sent.push((crate::unix_nanos(), payload.to_vec()));
    }
}

/// The bag: one channel per topic.
struct Bag {
    log: McapLog<std::io::BufWriter<std::fs::File>>,
    channels: [u16; 2],
    counts: [u64; 2],
}

impl std::fmt::Debug for Bag {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Bag").field("counts", &self.counts).finish()
    }
}

impl Bag {
    fn write(&mut self, which: usize, log_time: u64, data: &[u8]) -> Result<(), FleetError> {
        self.counts[which] += 1;
        self.log.write(
            self.channels[which],
            self.counts[which] as u32,
            log_time,
            log_time,
            data,
        )?;
        Ok(())
    }
}

/// Where the manoeuvre is.
#[derive(Debug, Clone, Copy)]
enum Phase {
    /// Waiting for the first odometry, which gives the start.
    Waiting,
    /// Commanding the signal from time `t0`, the robot's start `start`;
    /// command `k` is due at `t0 + k / rate`.
    Running { start: State, t0: f64, k: u64 },
    /// Completed, zero commanded: recording the robot settling until `until`.
    Settling { until: f64 },
}

/// The manoeuvre as a [`Task`] of the fleet runtime: the robot's odometry
/// in (recorded when valid), [`ExciteSignal`] out through its drive's
/// `cmd_vel` at `rate` (recorded as sent).
#[derive(Debug)]
pub struct ExciteTask<S: CmdSink> {
    drive: Ros2Drive<Recording<S>>,
    /// The bag, until the task stops.
    bag: Option<Bag>,
    counts: [u64; 2],
    signal: ExciteSignal,
    agent: u32,
    odom_key: String,
    period: f64,
    radius: f64,
    wait: f64,
    phase: Phase,
    next: f64,
    ended: ExciteEnd,
    max_distance: f64,
    out: PathBuf,
}

/// How often a task waiting for odometry or for the robot to settle looks,
/// s.
const LOOK: f64 = 0.01;

impl<S: CmdSink> ExciteTask<S> {
    /// Writes the commands the drive sent since the last call to the bag.
    fn flush(&mut self) -> Result<(), FleetError> {
        let sent = std::mem::take(&mut self.drive.sink_mut().sent);
        for (at, payload) in sent {
            self.write(0, at, &payload)?;
        }
        Ok(())
    }

    fn write(&mut self, which: usize, log_time: u64, data: &[u8]) -> Result<(), FleetError> {
        if let Some(bag) = &mut self.bag {
            bag.write(which, log_time, data)?;
            self.counts = bag.counts;
        }
        Ok(())
    }

    /// The manoeuvre ends (`why`) at `now`: zero commanded; after a
    /// completed one the robot's settling is recorded for a second.
    fn end(&mut self, why: ExciteEnd, now: f64) -> Result<Flow, FleetError> {
        self.ended = why;
        self.drive.stop();
        self.flush()?;
        if why != ExciteEnd::Completed {
            return Ok(Flow::Stop);
        }
        self.phase = Phase::Settling { until: now + 1.0 };
        self.next = now + 1.0;
        Ok(Flow::Continue)
    }
}

impl<S: CmdSink> Task for ExciteTask<S> {
    type Report = ExciteReport;

    fn inputs(&self) -> Vec<String> {
        vec![self.odom_key.clone()]
    }

    fn outputs(&self) -> Vec<String> {
        Vec::new()
    }

    fn on_input(&mut self, _input: usize, sample: &Sample<'_>) -> Result<(), FleetError> {
        // Refused samples are counted by the drive, not recorded.
        if self
            .drive
            .on_odom(sample.key, sample.payload, sample.at)
            .is_ok()
        {
            self.write(1, sample.unix_ns, sample.payload)?;
        }
        Ok(())
    }

    fn next_wake(&self) -> f64 {
        self.next
    }

    fn tick(&mut self, now: f64, _out: &mut dyn Outputs) -> Result<Flow, FleetError> {
        self.drive.advance(now);
        let (start, t0, k) = match self.phase {
            Phase::Settling { until } if now >= until => return Ok(Flow::Stop),
            Phase::Settling { until } => {
                self.next = until;
                return Ok(Flow::Continue);
            }
            Phase::Waiting => match self.drive.state() {
                Some(start) => (start, now, 0),
                None if now > self.wait => {
                    return Err(FleetError::Config(format!(
                        "agent {}: no odometry on {} within {} s; is the robot's base up?",
                        self.agent,
                        self.drive.link().odom,
                        self.wait
                    )));
                }
                None => {
                    self.next = now + LOOK;
                    return Ok(Flow::Continue);
                }
            },
            Phase::Running { start, t0, k } => (start, t0, k),
        };
        let Some(s) = self.drive.state() else {
            return self.end(ExciteEnd::OdometryLost, now);
        };
        let d = (s.x - start.x).hypot(s.y - start.y);
        self.max_distance = self.max_distance.max(d);
        if d > self.radius {
            return self.end(ExciteEnd::LeftRadius, now);
        }
        let t = now - t0;
        if t >= self.signal.duration {
            return self.end(ExciteEnd::Completed, now);
        }
        self.drive.command(Command::Velocity(self.signal.at(t)));
        self.flush()?;
        self.phase = Phase::Running {
            start,
            t0,
            k: k + 1,
        };
        self.next = t0 + (k + 1) as f64 * self.period;
        Ok(Flow::Continue)
    }

    /// Zero commanded (a stop request or an error ends it here) and the bag
    /// finished, in every case.
    fn stop(&mut self, _out: &mut dyn Outputs) -> Result<(), FleetError> {
        if matches!(self.phase, Phase::Waiting | Phase::Running { .. }) {
            self.drive.stop();
        }
        self.flush()?;
        if let Some(bag) = self.bag.take() {
            bag.log.finish()?;
        }
        Ok(())
    }

    fn report(self) -> Result<ExciteReport, FleetError> {
        let link = self.drive.link();
        Ok(ExciteReport {
            role: crate::role::Role::Excite,
            agent: self.agent,
            ended: self.ended,
            bag: self.out.display().to_string(),
            topics: [link.cmd_vel.clone(), link.odom.clone()],
            cmd_recorded: self.counts[0],
            odom_recorded: self.counts[1],
            max_distance: self.max_distance,
            amplitudes: [self.signal.v_amp, self.signal.omega_amp],
            hold: self.signal.hold,
            ros2: *self.drive.counters(),
        })
    }
}

/// Runs the manoeuvre on agent `opts.agent`'s ROS 2 robot: [`ExciteTask`]
/// on the fleet runtime, in real time, declared as the robot's ROS 2 node.
pub fn run(opts: ExciteOptions, stop: &StopFlag) -> Result<ExciteReport, FleetError> {
    let fleet = opts.scenario.fleet()?;
    let plan = opts.scenario.build(&Overrides::default())?.plan;
    let spec = agent_spec(&plan, opts.agent)?;
    let Drive::Velocity(robot) = &spec.drive() else {
        return Err(FleetError::Config(format!(
            "agent {}: fleet excite drives a velocity base (set drive = \"velocity\" on its robot)",
            opts.agent
        )));
    };
    let base = robot.base();
    // The odometry rate is not known before the robot runs: the design
    // assumes the slowest (10 Hz), which only lengthens the steps.
    let signal = ExciteSignal::for_base(
        &base,
        opts.duration,
        ExciteDesign {
            odom_period: SLOWEST_ODOMETRY,
            limits: opts.limits,
        },
    );
    let link = fleet.ros2[opts.agent as usize - 1].clone();
    let topics = RosTopic::of_link(&link).map_err(|e| FleetError::Config(e.to_string()))?;
    let mut log = McapLog::create(&opts.out)?;
    let mut channels = [0; 2];
    for (c, t) in channels.iter_mut().zip(&topics) {
        *c = log.ros2_channel(t.topic(), &t.schema(), t.offered_qos_profiles())?;
    }
    let bag = Bag {
        log,
        channels,
        counts: [0; 2],
    };
    let agent = opts.agent;
    runtime::run_on(
        |session| {
            let node = Ros2Node::declare(session, &link, agent)?;
            let sink = Recording {
                inner: OwnedCmdSink(node.publisher),
                sent: Vec::new(),
            };
            let task = ExciteTask {
                drive: Ros2Drive::new(link, base, node.gid, sink),
                bag: Some(bag),
                counts: [0; 2],
                signal,
                agent,
                odom_key: node.input_keys[0].clone(),
                period: 1.0 / opts.rate,
                radius: opts.radius,
                wait: opts.wait,
                phase: Phase::Waiting,
                next: f64::NEG_INFINITY,
                ended: ExciteEnd::Signal,
                max_distance: 0.0,
                out: opts.out.clone(),
            };
            Ok((task, node.tokens))
        },
        &opts.net,
        FleetClock::new(1.0),
        stop,
    )?
    .report()
}
