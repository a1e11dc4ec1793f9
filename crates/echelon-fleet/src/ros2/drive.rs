//! A ROS 2 robot as a fleet [`Plant`]: the robot's odometry in, `cmd_vel`
//! out, over rmw_zenoh (or zenoh-bridge-ros2dds's keys).
//!
//! [`Ros2Drive`] is sans-IO like the robot it serves: the driver hands it the
//! odometry samples that arrived ([`Ros2Drive::on_odom`], with the fleet time
//! of arrival) and it sends its commands through an injected [`CmdSink`] (a
//! Zenoh publisher in the process, a `Vec` in tests). What it guarantees:
//!
//! - the state is the last valid odometry mapped into the world (REP 105:
//!   the pose in the odom frame, yaw unwrapped, carried by the link's
//!   `odom_origin`, the odom frame's pose in the world; the twist stays in
//!   the body frame, REP 103), and there is none once it is older than
//!   `odom_timeout`, so the robot commands zero; the raw odometry is
//!   published beside it ([`Plant::odometry`]: the pose in the odom frame,
//!   its age and the last fix's);
//! - its position uncertainty `σ` is its EKF's when its fixes keep a
//!   covariance, else the dead-reckoning rule of [`Drift`] on its error
//!   model;
//! - odometry that is not CDR of `nav_msgs/msg/Odometry`, carries the wrong
//!   type or hash on its key, holds a NaN or an infinity, is in other
//!   frames than configured, or whose orientation is not a rotation (all
//!   zero, or a squared norm beyond tf2's tolerance of 1, as the fixes:
//!   [`echelon_ros2::msgs::Quaternion::checked_yaw`]) is counted and
//!   refused, never a crash, and never becomes the robot's state;
//! - no command it sends is non-finite or beyond the base's speed limits
//!   (scaled together, keeping the curvature, [`VelocityBase::limit`]);
//! - its base's safety words (a Create 3's hazards, an e-stop:
//!   [`BaseSafety`]) are read when the link names their topics, and
//!   answered by [`Plant::hazards`], upon which the robot stops and pauses
//!   the fleet;
//! - [`Plant::stop`] sends a zero command at once (leader or odometry lost,
//!   the process stopping), through [`CmdSink::send_stop`] (on Zenoh,
//!   congestion control `Block` for the process's last words:
//!   `endpoint.rs`).

use serde::Serialize;

use echelon::base::{VelocityBase, VelocityCommand};
use echelon::model::{Pose, State};
use echelon::scenario::Ros2Link;
use echelon::scenario::schema::{CmdVelStamp, CmdVelType};

use super::drift::Drift;
use super::fixes::{FixInput, FixReport};
use super::hazard::{BaseSafety, HazardReport, HazardSet};
use super::refusal::SampleRefusal;
use crate::plant::{Actuation, Command, Plant};
use crate::wire::OdometryState;
use echelon_ros2::attachment::{Attachment, Gid};
use echelon_ros2::keys::check_topic_key;
use echelon_ros2::msgs::{
    BOOL, HAZARD_DETECTION_VECTOR, MessageType, ODOMETRY, Odometry, RosMessage, TWIST,
    TWIST_STAMPED, Time, Twist, TwistStamped, YawUnwrapper,
};

/// The input number of a drive's odometry.
pub const ODOM_INPUT: usize = 0;
/// The input number of a drive's fixes, when it takes any.
pub const FIX_INPUT: usize = 1;

/// What one of a drive's inputs carries. The inputs are numbered in this
/// order, each present or not by the link ([`DriveInput::of_link`]):
/// odometry always, then fixes, hazards and the e-stop when configured.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DriveInput {
    /// `nav_msgs/msg/Odometry`.
    Odometry,
    /// Absolute fixes ([`FixInput`]).
    Fixes,
    /// A Create 3's `HazardDetectionVector` ([`BaseSafety`]).
    Hazards,
    /// An e-stop `Bool` ([`BaseSafety`]).
    EStop,
}

impl DriveInput {
    /// The message type it carries on `link`.
    pub fn message_type(self, link: &Ros2Link) -> &'static MessageType {
        match (self, &link.fixes) {
            (DriveInput::Odometry, _) => &ODOMETRY,
            (DriveInput::Fixes, Some(f)) => super::fixes::fix_type(f.message),
            (DriveInput::Fixes, None) => &ODOMETRY,
            (DriveInput::Hazards, _) => &HAZARD_DETECTION_VECTOR,
            (DriveInput::EStop, _) => &BOOL,
        }
    }

    /// Its name in messages (`odom`, `fixes`, `hazards`, `estop`: the
    /// scenario's field).
    pub fn role(self) -> &'static str {
        match self {
            DriveInput::Odometry => "odom",
            DriveInput::Fixes => "fixes",
            DriveInput::Hazards => "hazards",
            DriveInput::EStop => "estop",
        }
    }

    /// The inputs of a drive for `link`, in their numbering, with their
    /// fully qualified topics.
    pub fn of_link(link: &Ros2Link) -> Vec<(DriveInput, &str)> {
        let mut inputs = vec![(DriveInput::Odometry, link.odom.as_str())];
        inputs.extend(
            link.fixes
                .as_ref()
                .map(|f| (DriveInput::Fixes, f.topic.as_str())),
        );
        inputs.extend(link.hazards.as_deref().map(|t| (DriveInput::Hazards, t)));
        inputs.extend(link.estop.as_deref().map(|t| (DriveInput::EStop, t)));
        inputs
    }
}

/// The message type a link's `cmd_vel` carries.
pub fn cmd_vel_type(link: &Ros2Link) -> &'static MessageType {
    match link.cmd_vel_type {
        CmdVelType::TwistStamped => &TWIST_STAMPED,
        CmdVelType::Twist => &TWIST,
    }
}

/// Encodes a velocity command as `link`'s `cmd_vel` type into `buf`.
pub fn encode_cmd_vel(link: &Ros2Link, cmd: VelocityCommand, stamp_ns: i64, buf: &mut Vec<u8>) {
    let stamp = match link.cmd_vel_stamp {
        CmdVelStamp::Zero => Time::default(),
        CmdVelStamp::Now => Time::from_nanos(stamp_ns),
    };
    match link.cmd_vel_type {
        CmdVelType::TwistStamped => {
            TwistStamped::planar(cmd.v, cmd.omega, stamp, &link.base_frame).encode_into(buf)
        }
        CmdVelType::Twist => Twist::planar(cmd.v, cmd.omega).encode_into(buf),
    }
}

/// A `cmd_vel` payload decoded to a velocity command and its stamp, ns
/// (`None`: a plain `Twist`; `Some(0)`: a zero stamp), refusing the wrong
/// type on the key, bad CDR and non-finite values.
pub fn decode_cmd_vel(
    link: &Ros2Link,
    key: &str,
    payload: &[u8],
) -> Result<(VelocityCommand, Option<i64>), SampleRefusal> {
    check_topic_key(link.key_scheme, key, cmd_vel_type(link))
        .map_err(|e| SampleRefusal::WrongType(e.to_string()))?;
    let (twist, stamp) = match link.cmd_vel_type {
        CmdVelType::TwistStamped => TwistStamped::from_cdr_finite(payload)
            .map(|t| (t.twist, Some(t.header.stamp.to_nanos()))),
        CmdVelType::Twist => Twist::from_cdr_finite(payload).map(|t| (t, None)),
    }
    .map_err(SampleRefusal::from)?;
    let cmd = VelocityCommand {
        v: twist.linear.x,
        omega: twist.angular.z,
    };
    Ok((cmd, stamp))
}

/// Where a drive's commands go: the `cmd_vel` publisher, and the wall clock
/// that stamps them (injected, so tests are deterministic).
pub trait CmdSink {
    /// Wall-clock time, ns since the UNIX epoch (header stamps, attachments).
    fn now_ns(&self) -> i64;
    /// Publishes one `cmd_vel` payload with its rmw_zenoh attachment.
    fn send(&mut self, payload: &[u8], attachment: &[u8]) -> Result<(), String>;
    /// Publishes a stop's zero ([`Plant::stop`]), reliably where the sink
    /// can: it may be the robot's last command, never superseded by another
    /// (the default: as [`CmdSink::send`]).
    fn send_stop(&mut self, payload: &[u8], attachment: &[u8]) -> Result<(), String> {
        self.send(payload, attachment)
    }
    /// Whether a reader of the commands is there now (Zenoh's matching
    /// status of the `cmd_vel` publisher: the base's subscriber, through
    /// the routers); `None` (the default): the sink cannot tell.
    fn reader_present(&self) -> Option<bool> {
        None
    }
}

/// How long a `cmd_vel` without a reader is tolerated before the drive
/// says so ([`Plant::command_reader_lost`]): a base that restarts, or a
/// router's routes being rebuilt, is not lost at once. Fleet s.
pub const READER_GRACE: f64 = 0.25;
/// How often the reader is looked for, fleet s.
pub const READER_CHECK: f64 = 0.05;

/// What a ROS 2 drive counted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Ros2Counters {
    /// Odometry samples received.
    pub odom_received: u64,
    /// Accepted as the robot's state.
    pub odom_accepted: u64,
    /// Refused: another type or hash on the key.
    pub odom_wrong_type: u64,
    /// Refused: not CDR of `nav_msgs/msg/Odometry`, or its orientation not
    /// a rotation (a zero quaternion, or not normalised within tf2's
    /// tolerance).
    pub odom_malformed: u64,
    /// Refused: a NaN or an infinity.
    pub odom_non_finite: u64,
    /// Refused: frames other than the configured odom → base frames.
    pub odom_wrong_frames: u64,
    /// `cmd_vel` messages sent.
    pub cmd_sent: u64,
    /// Zero commands sent by [`Plant::stop`].
    pub cmd_zero: u64,
    /// Commands cut by the speed limits.
    pub cmd_saturated: u64,
    /// Non-finite commands from the law, replaced by zero.
    pub cmd_non_finite: u64,
    /// Sends that failed.
    pub send_errors: u64,
}

/// A ROS 2 robot driven through its `cmd_vel`, its state read from `odom`.
#[derive(Debug)]
pub struct Ros2Drive<S: CmdSink> {
    link: Ros2Link,
    base: VelocityBase,
    sink: S,
    gid: Gid,
    seq: i64,
    buf: Vec<u8>,
    yaw: YawUnwrapper,
    /// The last valid odometry (odom frame) still on the fleet clock's
    /// timeline, and its fleet time of arrival.
    odom: Option<(State, f64)>,
    /// Its absolute fixes, when it has a source.
    fixes: Option<FixInput>,
    /// Its dead-reckoning uncertainty, when its error model is known.
    drift: Option<Drift>,
    /// What its inputs carry, in their numbering.
    inputs: Vec<DriveInput>,
    /// Its base's safety words, when it listens to any.
    safety: Option<BaseSafety>,
    t: f64,
    last_sent: VelocityCommand,
    counters: Ros2Counters,
    /// When the reader was last looked for, and since when it is missing.
    reader: (f64, Option<f64>),
}

impl<S: CmdSink> Ros2Drive<S> {
    /// A drive for the robot at `link`, within the limits of `base`,
    /// publishing as the publisher `gid` through `sink`.
    pub fn new(link: Ros2Link, base: VelocityBase, gid: Gid, sink: S) -> Self {
        let inputs: Vec<DriveInput> = DriveInput::of_link(&link)
            .into_iter()
            .map(|(i, _)| i)
            .collect();
        let safety = inputs
            .iter()
            .any(|i| matches!(i, DriveInput::Hazards | DriveInput::EStop))
            .then(|| BaseSafety::new(link.key_scheme));
        Ros2Drive {
            inputs,
            safety,
            link,
            base,
            sink,
            gid,
            seq: 0,
            buf: Vec::with_capacity(128),
            yaw: YawUnwrapper::new(),
            odom: None,
            fixes: None,
            drift: None,
            t: 0.0,
            last_sent: VelocityCommand::default(),
            counters: Ros2Counters::default(),
            reader: (f64::NEG_INFINITY, None),
        }
    }

    /// The same drive fusing absolute fixes from `fixes` (its
    /// `odom_origin` becomes the fixes' starting correction).
    pub fn with_fixes(mut self, fixes: FixInput) -> Self {
        if !self.inputs.contains(&DriveInput::Fixes) {
            self.inputs.insert(1, DriveInput::Fixes);
        }
        Ros2Drive {
            fixes: Some(fixes),
            ..self
        }
    }

    /// The same drive knowing how its odometry errs: its `σ` without an
    /// EKF covariance is `drift`'s ([`Drift`]).
    pub fn with_drift(self, drift: Drift) -> Self {
        Ros2Drive {
            drift: Some(drift),
            ..self
        }
    }

    /// Its fixes, if it takes any.
    pub fn fixes(&self) -> Option<&FixInput> {
        self.fixes.as_ref()
    }

    /// The pose of the robot's odom frame in the world: as its fixes say,
    /// else the link's `odom_origin`.
    pub fn odom_origin(&self) -> Pose {
        self.fixes
            .as_ref()
            .map_or(self.link.odom_origin, FixInput::correction)
    }

    /// A sample of input `input` (numbered as [`DriveInput::of_link`]) on
    /// `key` that arrived at fleet time `t`; refusals are counted.
    pub fn on_input(&mut self, input: usize, key: &str, payload: &[u8], t: f64) {
        match self.inputs.get(input) {
            Some(DriveInput::Odometry) => {
                let _ = self.on_odom(key, payload, t);
            }
            Some(DriveInput::Fixes) => {
                if let Some(f) = self.fixes.as_mut()
                    && f.on_fix(key, payload, t).is_ok()
                    && let (Some(d), Some((_, noise))) = (self.drift.as_mut(), f.last_fix())
                {
                    d.reset(noise.position, noise.heading);
                }
            }
            Some(DriveInput::Hazards) => {
                if let Some(s) = self.safety.as_mut() {
                    let _ = s.on_hazards(key, payload, t);
                }
            }
            Some(DriveInput::EStop) => {
                if let Some(s) = self.safety.as_mut() {
                    let _ = s.on_estop(key, payload, t);
                }
            }
            None => {}
        }
    }

    /// Its base's safety words, when it listens to any.
    pub fn base_safety(&self) -> Option<&BaseSafety> {
        self.safety.as_ref()
    }

    /// Its robot's link.
    pub fn link(&self) -> &Ros2Link {
        &self.link
    }

    /// What it counted.
    pub fn counters(&self) -> &Ros2Counters {
        &self.counters
    }

    /// The sink (a test reads what was sent).
    pub fn sink(&self) -> &S {
        &self.sink
    }

    /// The sink, mutably (`fleet excite` drains what it recorded).
    pub fn sink_mut(&mut self) -> &mut S {
        &mut self.sink
    }

    /// The last command sent.
    pub fn last_sent(&self) -> VelocityCommand {
        self.last_sent
    }

    /// An odometry sample on `key` that arrived at fleet time `t`: checked,
    /// decoded and kept as the state, or counted and refused.
    pub fn on_odom(&mut self, key: &str, payload: &[u8], t: f64) -> Result<(), SampleRefusal> {
        self.counters.odom_received += 1;
        let checked = self.check_odom(key, payload);
        match &checked {
            Ok((odom, yaw)) => {
                let p = odom.pose.pose.position;
                let raw = State {
                    x: p.x,
                    y: p.y,
                    theta: self.yaw.unwrap(*yaw),
                    v: odom.twist.twist.linear.x,
                    omega: odom.twist.twist.angular.z,
                };
                if let Some(f) = self.fixes.as_mut() {
                    f.on_odom(odom.header.stamp.to_nanos(), raw.pose(), t);
                }
                if let Some(d) = self.drift.as_mut() {
                    d.on_odom(raw.pose());
                }
                self.odom = Some((raw, t));
                self.counters.odom_accepted += 1;
            }
            Err(SampleRefusal::WrongType(_)) => self.counters.odom_wrong_type += 1,
            Err(SampleRefusal::NonFinite(_)) => self.counters.odom_non_finite += 1,
            Err(SampleRefusal::WrongFrames(..)) => self.counters.odom_wrong_frames += 1,
            Err(
                SampleRefusal::Malformed(_)
                | SampleRefusal::Orientation
                | SampleRefusal::NoAttachment
                | SampleRefusal::Stale { .. },
            ) => {
                self.counters.odom_malformed += 1;
            }
        }
        checked.map(|_| ())
    }

    /// The odometry and its yaw (rad, `[-π, π]`), or why it is refused.
    fn check_odom(&self, key: &str, payload: &[u8]) -> Result<(Odometry, f64), SampleRefusal> {
        check_topic_key(self.link.key_scheme, key, &ODOMETRY)
            .map_err(|e| SampleRefusal::WrongType(e.to_string()))?;
        let odom = Odometry::from_cdr_finite(payload).map_err(SampleRefusal::from)?;
        if odom.header.frame_id != self.link.odom_frame
            || odom.child_frame_id != self.link.base_frame
        {
            return Err(SampleRefusal::WrongFrames(
                odom.header.frame_id,
                odom.child_frame_id,
            ));
        }
        let yaw = odom
            .pose
            .pose
            .orientation
            .checked_yaw()
            .ok_or(SampleRefusal::Orientation)?;
        Ok((odom, yaw))
    }

    /// Sends `cmd` (already finite and within the limits); a stop's zero
    /// through [`CmdSink::send_stop`].
    fn send(&mut self, cmd: VelocityCommand, stop: bool) {
        let now = self.sink.now_ns();
        encode_cmd_vel(&self.link, cmd, now, &mut self.buf);
        self.seq += 1;
        let attachment = Attachment {
            sequence_number: self.seq,
            source_timestamp_ns: now,
            gid: self.gid,
        }
        .encode();
        let sent = match stop {
            true => self.sink.send_stop(&self.buf, &attachment),
            false => self.sink.send(&self.buf, &attachment),
        };
        match sent {
            Ok(()) => self.counters.cmd_sent += 1,
            Err(_) => self.counters.send_errors += 1,
        }
        self.last_sent = cmd;
    }
}

impl<S: CmdSink> Plant for Ros2Drive<S> {
    fn state(&self) -> Option<State> {
        self.odom
            .filter(|&(_, at)| self.t - at <= self.link.odom_timeout)
            .map(|(raw, _)| raw.carried_by(&self.odom_origin()))
    }

    fn odometry_age(&self) -> Option<f64> {
        self.odom.map(|(_, at)| (self.t - at).max(0.0))
    }

    /// Whether its `cmd_vel` has had no reader for [`READER_GRACE`] s
    /// (the base's driver gone), as last looked for.
    fn command_reader_lost(&self) -> bool {
        self.reader
            .1
            .is_some_and(|since| self.t - since >= READER_GRACE)
    }

    fn advance(&mut self, t: f64) {
        self.t = self.t.max(t);
        if self.t - self.reader.0 >= READER_CHECK {
            self.reader.0 = self.t;
            self.reader.1 = match self.sink.reader_present() {
                Some(false) => Some(self.reader.1.unwrap_or(self.t)),
                _ => None,
            };
        }
        if let Some(f) = self.fixes.as_mut() {
            f.tick(self.t);
        }
    }

    fn position_sigma(&self) -> f64 {
        match self.fixes.as_ref().and_then(FixInput::covariance) {
            Some(p) => position_sigma(&p),
            None => self.drift.as_ref().map_or(0.0, Drift::sigma),
        }
    }

    fn odometry(&self) -> Option<OdometryState> {
        let (raw, at) = self.odom?;
        let fix_age = self
            .fixes
            .as_ref()
            .and_then(FixInput::last_fix)
            .map(|(fixed, _)| (self.t - fixed).max(0.0));
        Some(OdometryState {
            raw: [raw.x, raw.y, raw.theta],
            age: (self.t - at).max(0.0),
            fix_age,
        })
    }

    fn fixes(&self, t: f64) -> Option<FixReport> {
        self.fixes.as_ref().map(|f| f.report(t))
    }

    fn hazards(&mut self, t: f64) -> HazardSet {
        self.safety
            .as_mut()
            .map_or(HazardSet::EMPTY, |s| s.update(t))
    }

    fn hazard_report(&self) -> Option<HazardReport> {
        self.safety.as_ref().map(BaseSafety::report)
    }

    fn command(&mut self, cmd: Command) -> Actuation {
        let wanted = match cmd {
            Command::Velocity(c) => c,
            // The robot's law follows its drive: a ROS 2 robot is a velocity
            // base, never sent torques.
            Command::Torque(_) => VelocityCommand::default(),
        };
        let (cmd, saturated) = if wanted.v.is_finite() && wanted.omega.is_finite() {
            self.base.limit(wanted)
        } else {
            self.counters.cmd_non_finite += 1;
            (VelocityCommand::default(), false)
        };
        self.counters.cmd_saturated += u64::from(saturated);
        self.send(cmd, false);
        Actuation {
            velocity: Some((cmd, saturated)),
            ..Actuation::default()
        }
    }

    fn stop(&mut self) {
        self.counters.cmd_zero += 1;
        self.send(VelocityCommand::default(), true);
    }

    fn accelerations(&self) -> (f64, f64) {
        // The base model's prediction for the command it follows (a real
        // base's own loops are not observed directly).
        self.state()
            .map_or((0.0, 0.0), |s| self.base.accelerations(&s, self.last_sent))
    }

    fn set_time(&mut self, t: f64) {
        // The fleet clock jumped (a leader's timeline began or restarted):
        // odometry received before is on the old timeline; wait for the next.
        self.t = t;
        self.odom = None;
        if let Some(s) = self.safety.as_mut() {
            s.set_time(t);
        }
    }
}

/// The standard deviation along the most uncertain axis of the position
/// block of a pose covariance `p` (the square root of its largest
/// eigenvalue).
pub fn position_sigma(p: &[[f64; 3]; 3]) -> f64 {
    let (a, b, d) = (p[0][0], p[0][1], p[1][1]);
    let mean = 0.5 * (a + d);
    let spread = (0.5 * (a - d)).hypot(b);
    (mean + spread).max(0.0).sqrt()
}

#[cfg(test)]
mod tests;
