//! `echelon fleet base --ros2`: a simulated ROS 2 differential-drive base,
//! what `diff_drive_controller` and the motors do on a robot, for tests and
//! demos without hardware.
//!
//! [`SimBase`] (sans-IO) takes `cmd_vel` samples ([`SimBase::on_cmd`]: the
//! key's type and hash, the rmw_zenoh attachment, CDR and finiteness checked;
//! anything else counted and refused), follows them through the agent's
//! velocity-base model ([`SimulatedVelocityBase`]: lags, speed and
//! acceleration limits), stops when no command arrived for `cmd_vel_timeout`,
//! and publishes `nav_msgs/Odometry` (pose in the odom frame, twist in the
//! body frame) at `odom_rate` ([`SimBase::tick`]). Like a real robot's, its
//! odometry starts where it was switched on: its world pose is the agent's
//! `start`, its odom frame lies at the link's `odom_origin` (by default the
//! start pose, so the odometry starts at zero). [`run`] is its Zenoh
//! driver: rmw_zenoh keys, attachments and liveliness tokens, as a ROS 2 node
//! `/robotK/echelon_base` would show.

use serde::Serialize;

use echelon::agent::Drive;
use echelon::base::VelocityCommand;
use std::collections::VecDeque;

use echelon::model::{Pose, State};
use echelon::odometry::{FixSpec, Odometer, OdometrySpec};
use echelon::rng::SplitMix64;
use echelon::scenario::schema::FixMessage;
use echelon::scenario::{FixSource, Ros2Link};

use super::drive::{cmd_vel_type, decode_cmd_vel};
use super::endpoint::declare_node;
use super::fixes::fix_type;
use super::ground_truth_topic;
use super::refusal::SampleRefusal;
use crate::options::{ProcessOptions, Resolved};
use crate::plant::{Plant, SimulatedVelocityBase};
use crate::robot::{PLANT_STEP, agent_spec};
use crate::role::Member;
use crate::runtime::{self, Flow, Outputs, Sample, Task};
use crate::{FleetError, StopFlag};
use echelon_ros2::attachment::{Attachment, Gid};
use echelon_ros2::keys::{topic_key, topic_key_any_type};
use echelon_ros2::msgs::{
    ODOMETRY, Odometry, PoseStamped, PoseWithCovarianceStamped, RosMessage, Time,
};

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
    base: SimulatedVelocityBase,
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
    /// A base for `link` moving as `base`, publishing odometry as `gid`.
    pub fn new(link: Ros2Link, base: SimulatedVelocityBase, gid: Gid) -> Self {
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
                position_noise: spec.position_noise,
                heading_noise: spec.heading_noise,
                latency: spec.latency,
                period,
                time_scale,
                rng: SplitMix64::new(seed),
                gid,
                seq: 0,
                next: t0 + period,
                pending: VecDeque::with_capacity((spec.latency / period).ceil() as usize + 2),
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
        let odometer = Odometer::with_wheels(spec, wheels.0, wheels.1, &start, seed, stream)
            .map_err(refuse)?;
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

    /// The simulated base.
    pub fn base(&self) -> &SimulatedVelocityBase {
        &self.base
    }

    /// The last command it followed.
    pub fn followed(&self) -> VelocityCommand {
        self.followed
    }

    /// A `cmd_vel` sample that arrived at local time `now`: checked and
    /// followed from now on, or counted and refused.
    pub fn on_cmd(
        &mut self,
        key: &str,
        payload: &[u8],
        attachment: Option<&[u8]>,
        now: f64,
    ) -> Result<(), SampleRefusal> {
        self.counters.cmd_received += 1;
        let checked = self.check(key, payload, attachment);
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
                    SampleRefusal::Malformed(_) | SampleRefusal::WrongFrames(..) => {
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
    ) -> Result<VelocityCommand, SampleRefusal> {
        if self.link.key_scheme == echelon_ros2::KeyScheme::RmwZenoh
            && attachment.is_none_or(|a| Attachment::decode(a).is_err())
        {
            return Err(SampleRefusal::NoAttachment);
        }
        decode_cmd_vel(&self.link, key, payload)
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

/// Options of `fleet base --ros2`.
#[derive(Debug, Clone)]
pub struct BaseOptions {
    /// The scenario (the agent's start pose, its base model and `ros2`
    /// link), clock, network and fleet name (for its echelon liveliness
    /// token); `duration` absent: run until a signal.
    pub process: ProcessOptions,
    /// Agent number, from 1.
    pub agent: u32,
}

/// What a base reports when it stops.
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BaseReport {
    /// [`crate::role::Role::Base`].
    pub role: crate::role::Role,
    /// Agent number.
    pub agent: u32,
    /// Its `cmd_vel` and `odom` topics.
    pub topics: [String; 2],
    /// What it counted.
    pub counters: BaseCounters,
    /// Final pose (world) and speeds `[x, y, θ, v, ω]`.
    pub final_state: [f64; 5],
    /// The last command it followed `[v, ω]`.
    pub last_command: [f64; 2],
}

/// [`SimBase`] as a [`Task`] of the fleet runtime: `cmd_vel` in, odometry
/// out, until `duration`.
#[derive(Debug)]
pub struct BaseTask {
    base: SimBase,
    agent: u32,
    cmd_key: String,
    odom_key: String,
    /// The simulated motion capture's key, when it has one.
    fix_key: Option<String>,
    /// Its ground truth's key and publisher gid.
    truth: (String, Gid),
    alive: String,
    duration: Option<f64>,
    /// The wall clock (UNIX ns), for the stamps.
    wall: fn() -> u64,
}

/// Its outputs: odometry, ground truth, then the simulated motion
/// capture's fixes.
const ODOM: usize = 0;
const TRUTH: usize = 1;
const FIXES: usize = 2;

impl Task for BaseTask {
    type Report = BaseReport;

    fn inputs(&self) -> Vec<String> {
        vec![self.cmd_key.clone()]
    }

    fn outputs(&self) -> Vec<String> {
        let mut keys = vec![self.odom_key.clone(), self.truth.0.clone()];
        keys.extend(self.fix_key.clone());
        keys
    }

    fn tokens(&self) -> Vec<String> {
        vec![self.alive.clone()]
    }

    fn on_input(&mut self, _: usize, s: &Sample<'_>) -> Result<(), FleetError> {
        // Refusals are counted in the report.
        let _ = self.base.on_cmd(s.key, s.payload, s.attachment, s.at);
        Ok(())
    }

    fn next_wake(&self) -> f64 {
        self.base.next_wake()
    }

    fn tick(&mut self, now: f64, out: &mut dyn Outputs) -> Result<Flow, FleetError> {
        if self.duration.is_some_and(|d| now >= d) {
            return Ok(Flow::Stop);
        }
        let wall = (self.wall)() as i64;
        if let Some(odom) = self.base.tick(now, wall) {
            out.publish_attached(ODOM, &odom.payload, &odom.attachment)
                .map_err(|e| FleetError::Zenoh(format!("publishing odometry: {e}")))?;
            let truth = self.base.ground_truth(wall, self.truth.1);
            out.publish_attached(TRUTH, &truth.payload, &truth.attachment)
                .map_err(|e| FleetError::Zenoh(format!("publishing ground truth: {e}")))?;
        }
        while let Some(fix) = self.base.take_fix(now, wall) {
            out.publish_attached(FIXES, &fix.payload, &fix.attachment)
                .map_err(|e| FleetError::Zenoh(format!("publishing a fix: {e}")))?;
        }
        Ok(Flow::Continue)
    }

    fn report(self) -> Result<BaseReport, FleetError> {
        let base = self.base;
        let s = base.base().true_state();
        let link = &base.link;
        Ok(BaseReport {
            role: crate::role::Role::Base,
            agent: self.agent,
            topics: [link.cmd_vel.clone(), link.odom.clone()],
            counters: *base.counters(),
            final_state: [s.x, s.y, s.theta, s.v, s.omega],
            last_command: [base.followed().v, base.followed().omega],
        })
    }
}

/// Runs a simulated ROS 2 base until `duration` or the stop flag:
/// [`BaseTask`] on the fleet runtime, declared as a ROS 2 node.
pub fn run(opts: BaseOptions, stop: &StopFlag) -> Result<BaseReport, FleetError> {
    let Resolved {
        plan,
        settings,
        keys,
    } = opts.process.resolve()?;
    let spec = agent_spec(&plan, opts.agent)?;
    let Drive::Velocity(robot) = &spec.drive else {
        return Err(FleetError::Config(format!(
            "agent {}: a ROS 2 base is a velocity base (set drive = \"velocity\" on its robot)",
            opts.agent
        )));
    };
    let link = settings.ros2[opts.agent as usize - 1].clone();
    // The agent's `[odometry]`: its wheel odometry lies as the simulator's.
    let odometry = plan.odometer(opts.agent as usize - 1).cloned();
    let seed = plan.seed();
    // A simulated motion capture when the agent takes fixes from ROS 2.
    let mocap = match (
        &link.fixes,
        odometry.as_ref().and_then(|o| o.spec().fixes()),
    ) {
        (Some(source), Some(spec)) => {
            let period = spec.interval(odometry.as_ref().map_or(0.0, |o| o.spec().period()));
            Some((source.clone(), spec, period))
        }
        _ => None,
    };
    let alive = keys.alive(&Member::Base(opts.agent).liveliness());
    runtime::run_on(
        |session| {
            let truth_topic = ground_truth_topic(&link);
            let mut publishes = vec![
                (link.odom.as_str(), &ODOMETRY),
                (truth_topic.as_str(), &ODOMETRY),
            ];
            if let Some((source, ..)) = &mocap {
                publishes.push((source.topic.as_str(), fix_type(source.message)));
            }
            let (tokens, gids) = declare_node(
                session,
                &link,
                "echelon_base",
                &publishes,
                &[(&link.cmd_vel, &cmd_vel_type(&link))],
                |e| FleetError::Config(e.to_string()),
            )?;
            let model = SimulatedVelocityBase::new(robot.base(), spec.start, 0.0, PLANT_STEP);
            let mut base = SimBase::new(link.clone(), model, gids[0]);
            if let Some((source, spec, period)) = &mocap {
                // Its own random stream: the odometry's are the agents'.
                let stream = seed ^ (0x6d6f_6361_7000_0000 | u64::from(opts.agent));
                base = base.with_mocap(
                    source.clone(),
                    spec,
                    *period,
                    gids[2],
                    stream,
                    opts.process.time_scale,
                );
            }
            if let Some(odometry) = &odometry {
                base = base.with_odometry(
                    odometry.spec(),
                    spec.drive.wheels(),
                    seed,
                    u64::from(opts.agent - 1),
                    0.0,
                )?;
            }
            let task = BaseTask {
                base,
                agent: opts.agent,
                cmd_key: topic_key_any_type(link.key_scheme, link.domain_id, &link.cmd_vel),
                odom_key: topic_key(link.key_scheme, link.domain_id, &link.odom, &ODOMETRY),
                truth: (
                    topic_key(link.key_scheme, link.domain_id, &truth_topic, &ODOMETRY),
                    gids[1],
                ),
                fix_key: mocap.as_ref().map(|(source, ..)| {
                    topic_key(
                        link.key_scheme,
                        link.domain_id,
                        &source.topic,
                        fix_type(source.message),
                    )
                }),
                alive,
                duration: opts.process.duration,
                wall: crate::unix_nanos,
            };
            Ok((task, tokens))
        },
        &opts.process.net,
        opts.process.clock(),
        stop,
    )?
    .report()
}

#[cfg(test)]
mod tests;
