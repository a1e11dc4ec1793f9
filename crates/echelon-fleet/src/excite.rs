//! `echelon fleet excite --ros2`: an identification manoeuvre on one real
//! ROS 2 robot, recorded to a bag that `echelon identify` reads.
//!
//! [`ExciteSignal`] (pure, deterministic) is the command: steps of `v` and
//! `ω`, then a chirp of both, then a stop. It stays within the base's limits
//! and keeps the robot in a small area:
//!
//! - `|v| ≤ 0.8 v_max`, `|ω| ≤ 0.8 ω_max` (and at most [`V_CAP`],
//!   [`OMEGA_CAP`]: identification needs no speed);
//! - every jump of the command is at most `0.8 a_max τ_v` (`0.8 α_max τ_ω`):
//!   a first-order lag's fastest rate after a step `Δ` is `Δ/τ`, so the
//!   acceleration limit never acts and the lag stays identifiable (a
//!   limited rate would bias it); the chirp's rate `A 2π f` obeys the same
//!   bound;
//! - the steps come in pairs `(+A, +Ω)`, `(0, 0)`, `(−A, −Ω)`, `(0, 0)`
//!   (with varied signs and sizes of `A`, `Ω`): the second arc retraces the
//!   first backwards, so under an ideal base the robot is back at its start
//!   pose every four steps; a lag only perturbs that slightly.
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
use echelon::base::{VelocityBase, VelocityCommand};
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

/// Largest linear speed of the manoeuvre, m/s.
pub const V_CAP: f64 = 0.3;
/// Largest angular speed of the manoeuvre, rad/s.
pub const OMEGA_CAP: f64 = 1.0;
/// Fraction of each limit the manoeuvre uses.
pub const MARGIN: f64 = 0.8;
/// Step levels `(v, ω)` over one cycle, in units of the amplitudes: arcs
/// each retraced backwards after a stop.
const CYCLE: [(f64, f64); 12] = [
    (1.0, 1.0),
    (0.0, 0.0),
    (-1.0, -1.0),
    (0.0, 0.0),
    (0.5, -1.0),
    (0.0, 0.0),
    (-0.5, 1.0),
    (0.0, 0.0),
    (1.0, -0.5),
    (0.0, 0.0),
    (-1.0, 0.5),
    (0.0, 0.0),
];

/// The excitation command as a function of time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExciteSignal {
    /// Step (and chirp) amplitude of `v`, m/s.
    pub v_amp: f64,
    /// Step (and chirp) amplitude of `ω`, rad/s.
    pub omega_amp: f64,
    /// Duration of one step, s.
    pub hold: f64,
    /// End of the steps, start of the chirp, s.
    pub steps_end: f64,
    /// End of the chirp, s; zero from here to `duration`.
    pub chirp_end: f64,
    /// Chirp frequency at `steps_end`, Hz.
    pub f0: f64,
    /// Chirp frequency at `chirp_end`, Hz.
    pub f1: f64,
    /// Total duration, s.
    pub duration: f64,
}

impl ExciteSignal {
    /// The manoeuvre for `base` lasting `duration` s: amplitudes and steps
    /// within its limits (module docs), steps held `max(1 s, 8 τ)`, steps
    /// over the first 60 %, a chirp from `1/(4 hold)` up to the lags'
    /// corner frequency (at most 2 Hz) until one hold before the end, zero
    /// after.
    pub fn for_base(base: &VelocityBase, duration: f64) -> ExciteSignal {
        // The largest jump a lag τ turns into a rate within `limit`.
        let jump = |limit: f64, tau: f64| {
            if tau > 0.0 && limit.is_finite() {
                MARGIN * limit * tau
            } else {
                f64::INFINITY
            }
        };
        let v_amp = (MARGIN * base.v_max())
            .min(jump(base.a_max(), base.tau_v()))
            .min(V_CAP);
        let omega_amp = (MARGIN * base.omega_max())
            .min(jump(base.alpha_max(), base.tau_omega()))
            .min(OMEGA_CAP);
        let tau = base.tau_v().max(base.tau_omega());
        let hold = (8.0 * tau).max(1.0);
        // Whole retraced pairs (four steps each).
        let steps_end = (0.6 * duration / (4.0 * hold)).floor().max(1.0) * 4.0 * hold;
        let chirp_end = (duration - hold).max(steps_end);
        // The chirp's rate A 2π f within the acceleration limits.
        let rate_f = |limit: f64, amp: f64| {
            if limit.is_finite() && amp > 0.0 {
                MARGIN * limit / (std::f64::consts::TAU * amp)
            } else {
                f64::INFINITY
            }
        };
        let corner = if tau > 0.0 {
            1.0 / (std::f64::consts::TAU * tau)
        } else {
            2.0
        };
        let f1 = corner
            .min(2.0)
            .min(rate_f(base.a_max(), v_amp))
            .min(rate_f(base.alpha_max(), omega_amp));
        let f0 = (0.25 / hold).min(f1);
        ExciteSignal {
            v_amp,
            omega_amp,
            hold,
            steps_end,
            chirp_end,
            f0,
            f1,
            duration,
        }
    }

    /// The command at `t` s from the start (zero before 0 and from
    /// `chirp_end` on).
    pub fn at(&self, t: f64) -> VelocityCommand {
        if !(0.0..self.chirp_end).contains(&t) {
            return VelocityCommand::default();
        }
        if t < self.steps_end {
            let (v, omega) = CYCLE[(t / self.hold).floor() as usize % CYCLE.len()];
            return VelocityCommand {
                v: self.v_amp * v,
                omega: self.omega_amp * omega,
            };
        }
        // Linear chirp: phase 2π (f0 s + (f1 − f0) s² / (2 T)).
        let s = t - self.steps_end;
        let span = self.chirp_end - self.steps_end;
        let phase =
            std::f64::consts::TAU * (self.f0 * s + (self.f1 - self.f0) * s * s / (2.0 * span));
        VelocityCommand {
            v: self.v_amp * phase.sin(),
            omega: self.omega_amp * phase.sin(),
        }
    }
}

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
    /// How long to wait for the first odometry, s.
    pub wait: f64,
    /// The bag to write.
    pub out: PathBuf,
    /// Network.
    pub net: NetOptions,
}

/// Why the manoeuvre ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
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
#[derive(Debug, Clone, Serialize)]
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
        self.sent.push((crate::unix_nanos(), payload.to_vec()));
        Ok(())
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
    let Drive::Velocity(robot) = &spec.drive else {
        return Err(FleetError::Config(format!(
            "agent {}: fleet excite drives a velocity base (set drive = \"velocity\" on its robot)",
            opts.agent
        )));
    };
    let base = robot.base();
    let signal = ExciteSignal::for_base(&base, opts.duration);
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
                odom_key: node.odom_key,
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

#[cfg(test)]
mod tests {
    use super::*;
    use echelon::identify::{self, Log, Model, simulate_axis};

    fn lab() -> VelocityBase {
        VelocityBase::new(0.1, 0.1, 0.3, 2.0, 1.0, 5.0).expect("the lab base")
    }

    fn bases() -> [VelocityBase; 3] {
        [
            lab(),
            VelocityBase::IDEAL,
            VelocityBase::new(0.25, 0.4, 0.22, 2.84, f64::INFINITY, f64::INFINITY)
                .expect("a slow base"),
        ]
    }

    fn grid(sig: &ExciteSignal, h: f64) -> Vec<f64> {
        let n = ((sig.duration + 2.0) / h) as usize;
        (0..n).map(|i| i as f64 * h - 1.0).collect()
    }

    #[test]
    fn the_command_stays_within_the_limits_and_its_jumps_within_the_lag_rate() {
        for b in bases() {
            for duration in [10.0, 30.0, 90.0] {
                let sig = ExciteSignal::for_base(&b, duration);
                let bound = |limit: f64, tau: f64| {
                    if tau > 0.0 && limit.is_finite() {
                        MARGIN * limit * tau
                    } else {
                        f64::INFINITY
                    }
                };
                let max_jump = [
                    bound(b.a_max(), b.tau_v()),
                    bound(b.alpha_max(), b.tau_omega()),
                ];
                let h = 1e-3;
                let mut last = VelocityCommand::default();
                for t in grid(&sig, h) {
                    let c = sig.at(t);
                    assert!(
                        c.v.abs() <= MARGIN * b.v_max() && c.v.abs() <= V_CAP,
                        "{b:?} {t} {c:?}"
                    );
                    assert!(c.omega.abs() <= MARGIN * b.omega_max() && c.omega.abs() <= OMEGA_CAP);
                    let jump = [(c.v - last.v).abs(), (c.omega - last.omega).abs()];
                    for axis in 0..2 {
                        assert!(jump[axis] <= max_jump[axis] + 1e-12, "{b:?} {t}: {jump:?}");
                    }
                    // In the chirp the rate obeys the acceleration limits.
                    if t > sig.steps_end + h && t < sig.chirp_end {
                        assert!(jump[0] / h <= MARGIN * b.a_max() * 1.001, "{t}");
                        assert!(jump[1] / h <= MARGIN * b.alpha_max() * 1.001, "{t}");
                    }
                    last = c;
                }
                assert_eq!(sig.at(sig.duration), VelocityCommand::default());
                assert_eq!(sig.at(-0.5), VelocityCommand::default());
                assert!(sig.v_amp > 0.0 && sig.omega_amp > 0.0);
            }
        }
    }

    #[test]
    fn under_an_ideal_base_the_robot_stays_within_a_metre_and_comes_back() {
        for b in bases() {
            let sig = ExciteSignal::for_base(&b, 60.0);
            let h = 1e-3;
            let (mut x, mut y, mut th) = (0.0_f64, 0.0_f64, 0.0_f64);
            let mut far: f64 = 0.0;
            for t in grid(&sig, h) {
                let c = sig.at(t);
                x += h * c.v * th.cos();
                y += h * c.v * th.sin();
                th += h * c.omega;
                far = far.max(x.hypot(y));
                // Back at the start pose after every retraced pair.
                let pairs = t / (4.0 * sig.hold);
                if t > 1.0 && t <= sig.steps_end && (pairs - pairs.round()).abs() < 1e-4 {
                    // (to a 1 ms sample at the step edges)
                    assert!(
                        x.hypot(y) < 3e-3 && th.abs() < 3e-3,
                        "{b:?} {t}: ({x}, {y}, {th})"
                    );
                }
            }
            assert!(far <= 1.0, "{b:?}: {far} m");
            assert!(far >= 0.5 * sig.v_amp * sig.hold, "{b:?}: it moved");
        }
    }

    #[test]
    fn a_lagged_base_driven_by_it_is_identified() {
        for b in [lab(), bases()[2]] {
            let sig = ExciteSignal::for_base(&b, 40.0);
            let t: Vec<f64> = (0..2000).map(|i| f64::from(i) * 0.02).collect();
            let cmd: Vec<VelocityCommand> = t.iter().map(|&t| sig.at(t)).collect();
            let vc: Vec<f64> = cmd.iter().map(|c| c.v).collect();
            let wc: Vec<f64> = cmd.iter().map(|c| c.omega).collect();
            let log = Log {
                source: "excite".to_owned(),
                agent: 1,
                v: simulate_axis(&t, &vc, b.tau_v(), 1.0, 0.0),
                omega: simulate_axis(&t, &wc, b.tau_omega(), 1.0, 0.0),
                t,
                cmd: Some([vc, wc]),
                ..Log::default()
            };
            let id = identify::identify(&log, Model::Velocity).unwrap_or_else(|e| panic!("{e}"));
            let tau_v = id.get("tau_v").map(|e| e.value);
            let tau_w = id.get("tau_omega").map(|e| e.value);
            assert!(
                tau_v.is_some_and(|x| (x / b.tau_v() - 1.0).abs() < 1e-3),
                "{tau_v:?}"
            );
            assert!(
                tau_w.is_some_and(|x| (x / b.tau_omega() - 1.0).abs() < 1e-3),
                "{tau_w:?}"
            );
        }
    }
}
