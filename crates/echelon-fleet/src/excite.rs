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
//! [`run`] drives the robot's `cmd_vel` with it through a [`Ros2Drive`]
//! (the robot's limits applied, rmw_zenoh keys, attachments and liveliness
//! as `fleet robot --ros2`), and records every command sent and every valid
//! odometry received to an MCAP bag as `ros2 bag record -s mcap` would
//! (ROS 2 channels of [`RosTopic::of_link`]). It commands zero and stops at
//! the end, on SIGINT/SIGTERM, when the odometry is lost (older than
//! `odom_timeout`) and when the odometry says the robot left `radius` of
//! its start; the bag is finished in every case.

use std::path::PathBuf;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use serde::Serialize;
use zenoh::Wait;

use echelon::agent::Drive;
use echelon::base::{VelocityBase, VelocityCommand};
use echelon::scenario::{Overrides, Scenario};
use echelon_mcap::McapLog;

use crate::clock::FleetClock;
use crate::net::{self, NetOptions};
use crate::plant::{Command, Plant};
use crate::robot::agent_spec;
use crate::ros2::drive::{CmdSink, Ros2Counters, Ros2Drive};
use crate::ros2::endpoint::{Ros2Endpoint, ZenohCmdSink};
use crate::ros2::record::RosTopic;
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

/// Runs the manoeuvre on agent `opts.agent`'s ROS 2 robot.
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
    let mut bag = Bag {
        log,
        channels,
        counts: [0; 2],
    };

    let session = net::open(&opts.net)?;
    let ros = Ros2Endpoint::declare(&session, &link, opts.agent)?;
    let sink = Recording {
        inner: ZenohCmdSink(&ros.publisher),
        sent: Vec::new(),
    };
    let mut drive = Ros2Drive::new(link.clone(), base, ros.gid, sink);
    let clock = FleetClock::new(1.0);
    // Instants to UNIX nanoseconds (log times of received odometry).
    let (unix0, instant0) = (crate::unix_nanos(), Instant::now());
    let unix_at = |i: Instant| unix0 + i.saturating_duration_since(instant0).as_nanos() as u64;
    let feed = |drive: &mut Ros2Drive<Recording<ZenohCmdSink<'_, '_>>>,
                bag: &mut Bag,
                rx: &mpsc::Receiver<(Instant, String, Vec<u8>)>|
     -> Result<(), FleetError> {
        while let Ok((arrival, key, bytes)) = rx.try_recv() {
            // Refused samples are counted by the drive, not recorded.
            if drive.on_odom(&key, &bytes, clock.at(arrival)).is_ok() {
                bag.write(1, unix_at(arrival), &bytes)?;
            }
        }
        Ok(())
    };
    let flush = |drive: &mut Ros2Drive<Recording<ZenohCmdSink<'_, '_>>>,
                 bag: &mut Bag|
     -> Result<(), FleetError> {
        for (at, payload) in std::mem::take(&mut drive.sink_mut().sent) {
            bag.write(0, at, &payload)?;
        }
        Ok(())
    };

    // The first odometry gives the start.
    let nap = Duration::from_millis(10);
    let start = loop {
        feed(&mut drive, &mut bag, &ros.odom)?;
        drive.advance(clock.now());
        if let Some(s) = drive.state() {
            break Some(s);
        }
        if stop.is_raised() {
            break None;
        }
        if clock.now() > opts.wait {
            let _ = bag.log.finish();
            let _ = session.close().wait();
            return Err(FleetError::Config(format!(
                "agent {}: no odometry on {} within {} s; is the robot's base up?",
                opts.agent, link.odom, opts.wait
            )));
        }
        std::thread::sleep(nap);
    };
    let mut ended = ExciteEnd::Signal;
    let mut max_distance: f64 = 0.0;
    if let Some(start) = start {
        let t0 = clock.now();
        let period = 1.0 / opts.rate;
        let mut k = 0_u64;
        ended = loop {
            let due = t0 + k as f64 * period;
            clock.sleep_until(due, nap);
            if clock.now() < due {
                continue;
            }
            feed(&mut drive, &mut bag, &ros.odom)?;
            let now = clock.now();
            drive.advance(now);
            if stop.is_raised() {
                break ExciteEnd::Signal;
            }
            let Some(s) = drive.state() else {
                break ExciteEnd::OdometryLost;
            };
            let d = (s.x - start.x).hypot(s.y - start.y);
            max_distance = max_distance.max(d);
            if d > opts.radius {
                break ExciteEnd::LeftRadius;
            }
            let t = now - t0;
            if t >= signal.duration {
                break ExciteEnd::Completed;
            }
            drive.command(Command::Velocity(signal.at(t)));
            flush(&mut drive, &mut bag)?;
            k += 1;
        };
    }
    drive.stop();
    flush(&mut drive, &mut bag)?;
    if ended == ExciteEnd::Completed {
        // The robot settles under the zero command: recorded too.
        let until = clock.now() + 1.0;
        while clock.now() < until && !stop.is_raised() {
            std::thread::sleep(nap);
            feed(&mut drive, &mut bag, &ros.odom)?;
        }
    }
    let counts = bag.counts;
    bag.log.finish()?;
    let _ = session.close().wait();
    Ok(ExciteReport {
        role: crate::role::Role::Excite,
        agent: opts.agent,
        ended,
        bag: opts.out.display().to_string(),
        topics: [link.cmd_vel, link.odom],
        cmd_recorded: counts[0],
        odom_recorded: counts[1],
        max_distance,
        amplitudes: [signal.v_amp, signal.omega_amp],
        hold: signal.hold,
        ros2: *drive.counters(),
    })
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
