//! `echelon fleet base --ros2`: a simulated ROS 2 differential-drive base,
//! what `diff_drive_controller` and the motors do on a robot, for tests and
//! demos without hardware.
//!
//! [`SimBase`] (sans-IO) takes `cmd_vel` samples ([`SimBase::on_cmd`]: the
//! key's type and hash, the rmw_zenoh attachment, CDR and finiteness checked;
//! anything else counted and refused), follows them through the agent's
//! velocity base, simulated ([`SimulatedDrive`]: lags, speed and
//! acceleration limits), stops when no command arrived for `cmd_vel_timeout`,
//! drops a stamped command older than `cmd_vel_timeout` by its own clock
//! (the wall clock shifted by its clock offset; a zero stamp is "now"), as
//! `diff_drive_controller` does, and publishes `nav_msgs/Odometry` (pose in the odom frame, twist in the
//! body frame) at `odom_rate` ([`SimBase::tick`]). Like a real robot's, its
//! odometry starts where it was switched on: its world pose is the agent's
//! `start`, its odom frame lies at the link's `odom_origin` (by default the
//! start pose, so the odometry starts at zero). [`super::base::run`] is
//! its Zenoh driver.

use serde::Serialize;

use echelon::base::VelocityCommand;
use std::collections::VecDeque;

use echelon::model::{Pose, State};
use echelon::odometry::{FixSpec, Odometer, OdometrySpec};
use echelon::rng::SplitMix64;
use echelon::scenario::schema::FixMessage;
use echelon::scenario::{FixSource, Ros2Link};

use super::drive::decode_cmd_vel;
use super::refusal::SampleRefusal;
use crate::FleetError;
use crate::plant::{Plant, SimulatedDrive};

use echelon_ros2::attachment::{Attachment, Gid};
use echelon_ros2::msgs::{Odometry, PoseStamped, PoseWithCovarianceStamped, RosMessage, Time};

/// The world frame's id (REP 105's `map`): the frame of a simulated base's
/// ground truth.
pub const WORLD_FRAME: &str = "map";

/// What a simulated base counted (its report and its stats).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BaseCounters {
    /// `cmd_vel` samples received.
    pub cmd_received: u64,
    /// Followed.
    pub cmd_accepted: u64,
    /// Refused: another type or hash on the key.
    pub cmd_wrong_type: u64,
    /// Refused: not CDR of the `cmd_vel` type.
    pub cmd_malformed: u64,
    /// Refused: a NaN or an infinity.
    pub cmd_non_finite: u64,
    /// Refused: no valid rmw_zenoh attachment (rmw_zenoh drops these).
    pub cmd_no_attachment: u64,
    /// Times the moving base stopped because no command came for `cmd_vel_timeout`.
    pub cmd_timeouts: u64,
    /// Odometry messages published.
    pub odom_published: u64,
    /// Simulated motion-capture fixes published.
    #[serde(default)]
    pub fixes_published: u64,
    /// Refused: stamped longer than `cmd_vel_timeout` ago by the base's
    /// clock (a zero stamp is never stale).
    #[serde(default)]
    pub cmd_stale: u64,
}

/// One odometry message to publish.
#[derive(Debug, Clone, PartialEq)]
pub struct OdomOut {
    /// The CDR payload.
    pub payload: Vec<u8>,
    /// Its rmw_zenoh attachment.
    pub attachment: [u8; 33],
}

impl OdomOut {
    /// `s` as `nav_msgs/Odometry` in `frames` (the pose's, the twist's),
    /// stamped `stamp_ns`, with the attachment of message `(sequence
    /// number, publisher gid)`.
    fn of(s: &State, frames: (&str, &str), stamp_ns: i64, (seq, gid): (i64, Gid)) -> OdomOut {
        let odom = Odometry::planar(
            s.x,
            s.y,
            s.theta,
            s.v,
            s.omega,
            Time::from_nanos(stamp_ns),
            frames.0,
            frames.1,
        );
        OdomOut {
            payload: odom.to_cdr(),
            attachment: Attachment {
                sequence_number: seq,
                source_timestamp_ns: stamp_ns,
                gid,
            }
            .encode(),
        }
    }
}

/// A simulated ROS 2 base on the local clock.
#[derive(Debug, Clone)]
pub struct SimBase {
    link: Ros2Link,
    base: SimulatedDrive,
    gid: Gid,
    seq: i64,
    truth_seq: i64,
    /// Local time it was brought to.
    t: f64,
    last_cmd: Option<f64>,
    timed_out: bool,
    next_odom: f64,
    counters: BaseCounters,
    /// The last command followed (after the base's speed limits).
    followed: VelocityCommand,
    /// Its wheel odometry when the agent has `[odometry]`: what it publishes
    /// instead of the truth.
    encoders: Option<Encoders>,
    /// A simulated motion capture of it, when the agent takes fixes from
    /// ROS 2.
    mocap: Option<Mocap>,
    /// Its clock minus the wall clock, ns (a robot whose clock is not
    /// synchronised, or runs on `use_sim_time`).
    clock_offset_ns: i64,
}

/// A simulated motion-capture system (or any pose source) watching one
/// base: its true pose taken every `period`, with Gaussian noise, sent
/// `latency` later, stamped with the instant it was taken (the fix's
/// `period`, `position_noise`, `heading_noise` and `latency`, as the
/// simulator's fixes), in the source's frame and message type.
#[derive(Debug, Clone)]
struct Mocap {
    source: FixSource,
    position_noise: f64,
    heading_noise: Option<f64>,
    latency: f64,
    period: f64,
    /// Local seconds per wall second (the stamps are wall clock).
    time_scale: f64,
    rng: SplitMix64,
    gid: Gid,
    seq: i64,
    /// Local time of the next take.
    next: f64,
    /// Taken, waiting for their latency: (local time taken, pose in the
    /// source's frame).
    pending: VecDeque<(f64, Pose)>,
}

/// A simulated base's wheel odometry: the simulator's [`Odometer`] (its
/// error models: `ζ`, `E_d`, `E_b`, slip, encoder ticks, speed noise; no
/// fixes: a robot's own odometry has none) sampled every period of the
/// agent's `[odometry]` on the base's true motion.
#[derive(Debug, Clone)]
struct Encoders {
    odometer: Odometer,
    period: f64,
    /// Local time of the next sample.
    next: f64,
    /// `s = ∫v dt` up to `last.0` (trapezoids between the instants the base
    /// was brought to), m.
    distance: f64,
    /// The last instant the base was brought to, and its speed since.
    last: (f64, f64),
}

impl SimBase {
    /// A base for `link` moving as `base` (a velocity base: it is sent
    /// velocity commands), publishing odometry as `gid`.
    pub fn new(link: Ros2Link, base: SimulatedDrive, gid: Gid) -> Self {
        SimBase {
            link,
            base,
            gid,
            seq: 0,
            truth_seq: 0,
            t: 0.0,
            last_cmd: None,
            timed_out: false,
            next_odom: 0.0,
            counters: BaseCounters::default(),
            followed: VelocityCommand::default(),
            encoders: None,
            mocap: None,
            clock_offset_ns: 0,
        }
    }

    /// This base with its clock `offset` s ahead of the wall clock (behind
    /// when negative): what it compares `cmd_vel` stamps with.
    pub fn with_clock_offset(self, offset: f64) -> Self {
        SimBase {
            clock_offset_ns: (offset * 1e9).round() as i64,
            ..self
        }
    }

    /// This base also watched by a simulated motion capture publishing on
    /// `source` as the publisher `gid`: every `period` from the base's time
    /// now, with the noises and latency of `spec`, random numbers from `seed`
    /// (the stamps map local time to the wall clock at `time_scale`).
    pub fn with_mocap(
        self,
        source: FixSource,
        spec: &FixSpec,
        period: f64,
        gid: Gid,
        seed: u64,
        time_scale: f64,
    ) -> Self {
        let t0 = self.t;
        SimBase {
            mocap: Some(Mocap {
                source,
                position_noise: spec.position_noise(),
                heading_noise: spec.heading_noise(),
                latency: spec.latency(),
                period,
                time_scale,
                rng: SplitMix64::new(seed),
                gid,
                seq: 0,
                next: t0 + period,
                pending: VecDeque::with_capacity((spec.latency() / period).ceil() as usize + 2),
            }),
            ..self
        }
    }

    /// This base publishing what wheel odometry of `spec` (sampling period
    /// and error model; its fixes are dropped) measures of its motion,
    /// started at its pose at local time `t0`, rather than the truth:
    /// wheels `(l, r)`, random numbers from `seed` and `stream` (the
    /// simulator's for the same agent).
    pub fn with_odometry(
        self,
        spec: OdometrySpec,
        wheels: (f64, f64),
        seed: u64,
        stream: u64,
        t0: f64,
    ) -> Result<Self, FleetError> {
        let refuse = |e: echelon::error::ParamError| FleetError::Config(format!("odometry: {e}"));
        let spec = OdometrySpec::new(spec.period(), spec.errors(), None).map_err(refuse)?;
        let start = self.base.true_state();
        let odometer = Odometer::with_wheels(spec, wheels.0, wheels.1, &start, seed, stream);
        Ok(SimBase {
            encoders: Some(Encoders {
                odometer,
                period: spec.period(),
                next: t0 + spec.period(),
                distance: 0.0,
                last: (t0, start.v),
            }),
            ..self
        })
    }

    /// Brings the base to local time `t`, its encoders sampled on the way
    /// (never back in time).
    fn advance(&mut self, t: f64) {
        if t < self.t {
            return;
        }
        self.t = t;
        if let Some(e) = self.encoders.as_mut() {
            while e.next <= t {
                self.base.advance(e.next);
                let s = self.base.true_state();
                e.distance += 0.5 * (e.last.1 + s.v) * (e.next - e.last.0);
                e.odometer.sample(e.next, &s, e.distance);
                e.last = (e.next, s.v);
                e.next += e.period;
            }
        }
        self.base.advance(t);
        if let Some(e) = self.encoders.as_mut() {
            let v = self.base.true_state().v;
            e.distance += 0.5 * (e.last.1 + v) * (t - e.last.0);
            e.last = (t, v);
        }
    }

    /// Follows `cmd` from now on (the speed may jump: an ideal base).
    fn follow(&mut self, cmd: VelocityCommand) {
        self.followed = self.base.follow(cmd).0;
        if let Some(e) = self.encoders.as_mut() {
            e.last.1 = self.base.true_state().v;
        }
    }

    /// What its odometry says now, in the world: the truth, or what its
    /// encoders measured.
    pub fn odometry(&self) -> State {
        let truth = self.base.true_state();
        match &self.encoders {
            Some(e) => e.odometer.measure(&truth),
            None => truth,
        }
    }

    /// What it counted.
    pub fn counters(&self) -> &BaseCounters {
        &self.counters
    }

    /// Its link.
    pub fn link(&self) -> &Ros2Link {
        &self.link
    }

    /// The simulated base.
    pub fn base(&self) -> &SimulatedDrive {
        &self.base
    }

    /// Measures its true motion from its clock's `at` on, for `window` s
    /// ([`SimulatedDrive::measure_from`]).
    pub fn measure_from(&mut self, at: f64, window: Option<f64>) {
        self.base.measure_from(at, window);
    }

    /// The last command it followed.
    pub fn followed(&self) -> VelocityCommand {
        self.followed
    }

    /// A `cmd_vel` sample that arrived at local time `now`, wall clock
    /// `wall_ns` (UNIX ns): checked and followed from now on, or counted
    /// and refused.
    pub fn on_cmd(
        &mut self,
        key: &str,
        payload: &[u8],
        attachment: Option<&[u8]>,
        now: f64,
        wall_ns: i64,
    ) -> Result<(), SampleRefusal> {
        self.counters.cmd_received += 1;
        let checked = self.check(key, payload, attachment, wall_ns);
        match checked {
            Ok(cmd) => {
                self.advance(now);
                self.follow(cmd);
                self.last_cmd = Some(now);
                self.timed_out = false;
                self.counters.cmd_accepted += 1;
                Ok(())
            }
            Err(e) => {
                match e {
                    SampleRefusal::WrongType(_) => self.counters.cmd_wrong_type += 1,
                    SampleRefusal::NonFinite(_) => self.counters.cmd_non_finite += 1,
                    SampleRefusal::NoAttachment => self.counters.cmd_no_attachment += 1,
                    SampleRefusal::Stale { .. } => self.counters.cmd_stale += 1,
                    SampleRefusal::Malformed(_)
                    | SampleRefusal::WrongFrames(..)
                    | SampleRefusal::Orientation => {
                        self.counters.cmd_malformed += 1;
                    }
                }
                Err(e)
            }
        }
    }

    fn check(
        &self,
        key: &str,
        payload: &[u8],
        attachment: Option<&[u8]>,
        wall_ns: i64,
    ) -> Result<VelocityCommand, SampleRefusal> {
        if self.link.key_scheme == echelon_ros2::KeyScheme::RmwZenoh
            && attachment.is_none_or(|a| Attachment::decode(a).is_err())
        {
            return Err(SampleRefusal::NoAttachment);
        }
        let (cmd, stamp) = decode_cmd_vel(&self.link, key, payload)?;
        // diff_drive_controller: a zero stamp is "now"; any other is aged
        // by the controller's own clock.
        if let Some(stamp) = stamp.filter(|&s| s != 0) {
            let age = (wall_ns.saturating_add(self.clock_offset_ns) - stamp) as f64 * 1e-9;
            if age > self.link.cmd_vel_timeout {
                return Err(SampleRefusal::Stale {
                    age,
                    timeout: self.link.cmd_vel_timeout,
                });
            }
        }
        Ok(cmd)
    }

    /// Its true state as `nav_msgs/Odometry` in the world frame
    /// ([`WORLD_FRAME`], child its base frame), stamped `stamp_ns`, as
    /// the publisher `gid`: what a simulator's ground-truth plugin
    /// publishes (Gazebo's p3d), for logs and tests.
    pub fn ground_truth(&mut self, stamp_ns: i64, gid: Gid) -> OdomOut {
        self.truth_seq += 1;
        let frames = (WORLD_FRAME, self.link.base_frame.as_str());
        OdomOut::of(
            &self.base.true_state(),
            frames,
            stamp_ns,
            (self.truth_seq, gid),
        )
    }

    /// Local time of the next odometry or motion-capture event.
    pub fn next_wake(&self) -> f64 {
        let mocap = self.mocap.as_ref().map_or(f64::INFINITY, |m| {
            let sent = m
                .pending
                .front()
                .map_or(f64::INFINITY, |&(at, _)| at + m.latency);
            m.next.min(sent)
        });
        self.next_odom.min(mocap)
    }

    /// The next motion-capture fix due at local time `now` (after
    /// [`SimBase::tick`] brought the base there), stamped from `stamp_ns`,
    /// the wall clock now; call until `None`.
    pub fn take_fix(&mut self, now: f64, stamp_ns: i64) -> Option<OdomOut> {
        let m = self.mocap.as_mut()?;
        let &(taken, pose) = m.pending.front()?;
        if taken + m.latency > now {
            return None;
        }
        m.pending.pop_front();
        let stamp = Time::from_nanos(stamp_ns - ((now - taken) / m.time_scale * 1e9) as i64);
        let frame = &m.source.frame;
        let payload = match m.source.message {
            FixMessage::PoseStamped => {
                PoseStamped::planar(pose.x, pose.y, pose.theta, stamp, frame).to_cdr()
            }
            FixMessage::PoseWithCovarianceStamped => {
                let p = m.position_noise * m.position_noise;
                let h = m.heading_noise.map_or(0.0, |s| s * s);
                let cov = [[p, 0.0, 0.0], [0.0, p, 0.0], [0.0, 0.0, h]];
                PoseWithCovarianceStamped::planar(pose.x, pose.y, pose.theta, cov, stamp, frame)
                    .to_cdr()
            }
        };
        m.seq += 1;
        self.counters.fixes_published += 1;
        Some(OdomOut {
            payload,
            attachment: Attachment {
                sequence_number: m.seq,
                source_timestamp_ns: stamp_ns,
                gid: m.gid,
            }
            .encode(),
        })
    }

    /// Takes the motion-capture fixes due up to local time `now`, bringing
    /// the base to each instant.
    fn watch(&mut self, now: f64) {
        while let Some(at) = self.mocap.as_ref().map(|m| m.next).filter(|&at| at <= now) {
            self.advance(at);
            let truth = self.base.true_state().pose();
            let Some(m) = self.mocap.as_mut() else {
                break;
            };
            let mut seen = m.source.frame_origin.between(&truth);
            seen.x += m.rng.normal() * m.position_noise;
            seen.y += m.rng.normal() * m.position_noise;
            if let Some(sd) = m.heading_noise {
                seen.theta += m.rng.normal() * sd;
            }
            m.pending.push_back((at, seen));
            m.next += m.period;
        }
    }

    /// Brings the base to local time `now` (stopping it if its command timed
    /// out) and returns the odometry to publish when it is due, stamped
    /// `stamp_ns` (wall clock).
    pub fn tick(&mut self, now: f64, stamp_ns: i64) -> Option<OdomOut> {
        if let Some(at) = self.last_cmd
            && !self.timed_out
            && now - at > self.link.cmd_vel_timeout
        {
            // diff_drive_controller's cmd_vel_timeout: brake to zero, from
            // the moment the timeout expired.
            self.advance(at + self.link.cmd_vel_timeout);
            self.timed_out = true;
            // A base already commanded to rest is not stopped by a timeout.
            self.counters.cmd_timeouts += u64::from(self.followed != VelocityCommand::default());
            self.follow(VelocityCommand::default());
        }
        self.watch(now);
        self.advance(now);
        if now < self.next_odom {
            return None;
        }
        let period = 1.0 / self.link.odom_rate;
        self.next_odom = (self.next_odom + period).max(now);
        let s = self.odometry().seen_from(&self.link.odom_origin);
        self.seq += 1;
        self.counters.odom_published += 1;
        let frames = (self.link.odom_frame.as_str(), self.link.base_frame.as_str());
        Some(OdomOut::of(&s, frames, stamp_ns, (self.seq, self.gid)))
    }
}

#[cfg(test)]
mod tests;
