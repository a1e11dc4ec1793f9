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
//!   type or hash on its key, holds a NaN or an infinity, or is in other
//!   frames than configured is counted and refused, never a crash;
//! - no command it sends is non-finite or beyond the base's speed limits
//!   (scaled together, keeping the curvature, [`VelocityBase::limit`]);
//! - [`Plant::stop`] sends a zero command at once (leader or odometry lost,
//!   the process stopping).

use serde::Serialize;

use echelon::base::{VelocityBase, VelocityCommand};
use echelon::model::{Pose, State};
use echelon::scenario::Ros2Link;
use echelon::scenario::schema::{CmdVelStamp, CmdVelType};

use super::drift::Drift;
use super::fixes::{FixInput, FixReport};
use super::refusal::SampleRefusal;
use crate::plant::{Actuation, Command, Plant};
use crate::wire::OdometryState;
use echelon_ros2::attachment::{Attachment, Gid};
use echelon_ros2::keys::check_topic_key;
use echelon_ros2::msgs::{
    MessageType, ODOMETRY, Odometry, RosMessage, TWIST, TWIST_STAMPED, Time, Twist, TwistStamped,
    YawUnwrapper,
};

/// The input number of a drive's odometry.
pub const ODOM_INPUT: usize = 0;
/// The input number of a drive's fixes.
pub const FIX_INPUT: usize = 1;

/// The message type a link's `cmd_vel` carries.
pub fn cmd_vel_type(link: &Ros2Link) -> MessageType {
    match link.cmd_vel_type {
        CmdVelType::TwistStamped => TWIST_STAMPED,
        CmdVelType::Twist => TWIST,
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
    check_topic_key(link.key_scheme, key, &cmd_vel_type(link))
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
}

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
    /// Refused: not CDR of `nav_msgs/msg/Odometry`.
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
    t: f64,
    last_sent: VelocityCommand,
    counters: Ros2Counters,
}

impl<S: CmdSink> Ros2Drive<S> {
    /// A drive for the robot at `link`, within the limits of `base`,
    /// publishing as the publisher `gid` through `sink`.
    pub fn new(link: Ros2Link, base: VelocityBase, gid: Gid, sink: S) -> Self {
        Ros2Drive {
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
        }
    }

    /// The same drive fusing absolute fixes from `fixes` (its
    /// `odom_origin` becomes the fixes' starting correction).
    pub fn with_fixes(self, fixes: FixInput) -> Self {
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

    /// A sample of input `input` ([`ODOM_INPUT`] or [`FIX_INPUT`]) on `key`
    /// that arrived at fleet time `t`; refusals are counted.
    pub fn on_input(&mut self, input: usize, key: &str, payload: &[u8], t: f64) {
        match (input, self.fixes.as_mut()) {
            (ODOM_INPUT, _) => {
                let _ = self.on_odom(key, payload, t);
            }
            (_, Some(f)) => {
                if f.on_fix(key, payload, t).is_ok()
                    && let (Some(d), Some((_, noise))) = (self.drift.as_mut(), f.last_fix())
                {
                    d.reset(noise.position, noise.heading);
                }
            }
            (_, None) => {}
        }
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
            Ok(odom) => {
                let p = odom.pose.pose.position;
                let raw = State {
                    x: p.x,
                    y: p.y,
                    theta: self.yaw.unwrap(odom.yaw()),
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
                | SampleRefusal::NoAttachment
                | SampleRefusal::Stale { .. },
            ) => {
                self.counters.odom_malformed += 1;
            }
        }
        checked.map(|_| ())
    }

    fn check_odom(&self, key: &str, payload: &[u8]) -> Result<Odometry, SampleRefusal> {
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
        Ok(odom)
    }

    /// Sends `cmd` (already finite and within the limits).
    fn send(&mut self, cmd: VelocityCommand) {
        let now = self.sink.now_ns();
        encode_cmd_vel(&self.link, cmd, now, &mut self.buf);
        self.seq += 1;
        let attachment = Attachment {
            sequence_number: self.seq,
            source_timestamp_ns: now,
            gid: self.gid,
        }
        .encode();
        match self.sink.send(&self.buf, &attachment) {
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

    fn advance(&mut self, t: f64) {
        self.t = self.t.max(t);
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
        self.send(cmd);
        Actuation {
            velocity: Some((cmd, saturated)),
            ..Actuation::default()
        }
    }

    fn stop(&mut self) {
        self.counters.cmd_zero += 1;
        self.send(VelocityCommand::default());
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
mod tests {
    use super::*;
    use echelon::scenario::Scenario;
    use echelon_ros2::KeyScheme;
    use echelon_ros2::keys::topic_key;
    use echelon_ros2::msgs::{POSE_STAMPED, PoseStamped};

    /// Records what was sent; time advances 1 ms per read.
    #[derive(Debug, Default)]
    pub(crate) struct Recorder {
        pub(crate) sent: Vec<(Vec<u8>, Vec<u8>)>,
        pub(crate) now: std::cell::Cell<i64>,
    }

    impl CmdSink for Recorder {
        fn now_ns(&self) -> i64 {
            self.now.set(self.now.get() + 1_000_000);
            self.now.get()
        }
        fn send(&mut self, payload: &[u8], attachment: &[u8]) -> Result<(), String> {
            self.sent.push((payload.to_vec(), attachment.to_vec()));
            Ok(())
        }
    }

    fn link() -> Ros2Link {
        let src = "[sim]\nduration = 1.0\ndt = 0.01\n[reference.circle]\nspeed = 0.1\nturn_rate = 0.1\nstart = { x = 0.0, y = 0.0, theta = 0.0 }\n[[agents]]\nstart = { x = 0.0, y = 0.0, theta = 0.0 }\nleader = \"reference\"\n";
        let s = Scenario::parse(src, "t", None).unwrap_or_else(|e| panic!("{e}"));
        s.fleet().unwrap_or_else(|e| panic!("{e}")).ros2[0].clone()
    }

    fn drive(base: VelocityBase) -> Ros2Drive<Recorder> {
        Ros2Drive::new(link(), base, [7; 16], Recorder::default())
    }

    fn odom_key(l: &Ros2Link) -> String {
        topic_key(KeyScheme::RmwZenoh, l.domain_id, &l.odom, &ODOMETRY)
    }

    fn odom(x: f64, yaw: f64, v: f64) -> Vec<u8> {
        Odometry::planar(
            x,
            0.0,
            yaw,
            v,
            0.1,
            Time::from_nanos(5),
            "odom",
            "base_link",
        )
        .to_cdr()
    }

    fn last_cmd(d: &Ros2Drive<Recorder>) -> (TwistStamped, Attachment) {
        let (payload, attachment) = d.sink().sent.last().expect("a command sent");
        (
            TwistStamped::from_cdr_finite(payload).expect("valid TwistStamped"),
            Attachment::decode(attachment).expect("valid attachment"),
        )
    }

    proptest::proptest! {
        /// `position_sigma` is the square root of the position block's
        /// largest eigenvalue, for any covariance: `det(P − σ² I) = 0` and
        /// `σ²` at least either variance.
        #[test]
        fn position_sigma_is_the_largest_axis(
            a in -1.0..1.0f64, b in -1.0..1.0f64, c in -1.0..1.0f64, h in 0.0..1.0f64
        ) {
            // P = L Lᵀ with L lower triangular: any 2×2 covariance.
            let (pxx, pxy, pyy) = (a * a, a * b, b * b + c * c);
            let p = [[pxx, pxy, 0.0], [pxy, pyy, 0.0], [0.0, 0.0, h]];
            let l = position_sigma(&p).powi(2);
            let det = (pxx - l) * (pyy - l) - pxy * pxy;
            proptest::prop_assert!(det.abs() < 1e-9, "{det}");
            proptest::prop_assert!(l >= pxx - 1e-12 && l >= pyy - 1e-12);
        }
    }

    #[test]
    fn odometry_is_the_state_until_it_goes_stale() {
        let mut d = drive(VelocityBase::IDEAL);
        let l = link();
        assert_eq!(
            (l.namespace.as_str(), l.odom.as_str()),
            ("/robot1", "/robot1/odom")
        );
        assert_eq!(d.state(), None);
        d.on_odom(&odom_key(&l), &odom(1.0, 3.0, 0.2), 0.0)
            .expect("valid odometry");
        // Across ±π the heading keeps counting.
        d.on_odom(&odom_key(&l), &odom(1.1, -3.0, 0.2), 0.02)
            .expect("valid odometry");
        d.advance(0.02);
        let s = d.state().expect("fresh");
        assert_eq!((s.x, s.v, s.omega), (1.1, 0.2, 0.1));
        assert!((s.theta - (2.0 * std::f64::consts::PI - 3.0)).abs() < 1e-12);
        d.advance(0.02 + l.odom_timeout);
        assert!(d.state().is_some());
        d.advance(0.03 + l.odom_timeout);
        assert_eq!(d.state(), None, "stale odometry is no state");
        assert_eq!(d.counters().odom_accepted, 2);
    }

    #[test]
    fn bad_odometry_is_counted_and_refused() {
        let mut d = drive(VelocityBase::IDEAL);
        let l = link();
        let key = odom_key(&l);
        d.on_odom(&key, &odom(1.0, 0.0, 0.0), 0.0).expect("valid");
        let before = d.state();
        let mut truncated = odom(2.0, 0.0, 0.0);
        truncated.truncate(40);
        assert!(d.on_odom(&key, &truncated, 0.01).is_err());
        assert!(d.on_odom(&key, b"garbage", 0.01).is_err());
        assert!(d.on_odom(&key, &odom(f64::NAN, 0.0, 0.0), 0.01).is_err());
        let twist_key = topic_key(KeyScheme::RmwZenoh, 0, &l.odom, &TWIST);
        assert!(d.on_odom(&twist_key, &odom(2.0, 0.0, 0.0), 0.01).is_err());
        let other_frames =
            Odometry::planar(2.0, 0.0, 0.0, 0.0, 0.0, Time::default(), "map", "base_link").to_cdr();
        assert!(d.on_odom(&key, &other_frames, 0.01).is_err());
        assert_eq!(d.state(), before, "refused samples change nothing");
        let c = d.counters();
        assert_eq!(
            (
                c.odom_received,
                c.odom_accepted,
                c.odom_malformed,
                c.odom_non_finite
            ),
            (6, 1, 2, 1)
        );
        assert_eq!((c.odom_wrong_type, c.odom_wrong_frames), (1, 1));
    }

    /// A drive whose odom frame is at a world pose `origin` (returned with
    /// it and its fixes' key), with fixes from `/mocap/robot1/pose`
    /// (`PoseStamped` in `map`, 5 mm noise, `reset`, gated with `gate`) on
    /// slipping odometry.
    fn drive_with_fixes(gate: bool) -> (Ros2Drive<Recorder>, String, Pose) {
        use crate::ros2::fixes::{FixInput, OdometryModel};
        use echelon::odometry::{ErrorModel, FixSchedule, FixSpec, Fusion};
        use echelon::scenario::FixSource;
        use echelon::scenario::schema::FixMessage;
        let errors = ErrorModel::PERFECT.with_slip(1e-4).expect("valid slip");
        let model = OdometryModel {
            errors,
            wheels: (0.15, 0.05),
            sample_period: 0.02,
            top_speed: 0.5,
        };
        let source = FixSource {
            topic: "/mocap/robot1/pose".to_owned(),
            message: FixMessage::PoseStamped,
            frame: "map".to_owned(),
            frame_origin: Pose::default(),
            timeout: None,
            tolerance: None,
            gate,
        };
        let spec = FixSpec::new(FixSchedule::Period(0.1), Fusion::Reset)
            .and_then(|f| f.with_noise(0.005, None))
            .expect("valid fix spec");
        let origin = Pose {
            x: 1.0,
            y: -2.0,
            theta: 0.7,
        };
        let l = Ros2Link {
            odom_origin: origin,
            ..link()
        };
        let fixes = FixInput::new(1, source, KeyScheme::RmwZenoh, &spec, model, origin, 1.0)
            .expect("valid fixes");
        let key = topic_key(KeyScheme::RmwZenoh, 0, "/mocap/robot1/pose", &POSE_STAMPED);
        let d = Ros2Drive::new(l, VelocityBase::IDEAL, [7; 16], Recorder::default())
            .with_fixes(fixes)
            .with_drift(Drift::new(errors, (0.15, 0.05)));
        (d, key, origin)
    }

    /// Odometry sample `k` of a straight run at 0.5 m/s (every 20 ms,
    /// stamped) fed to `d` at fleet time `0.02 k`, and `d` brought there:
    /// the raw state sent.
    fn straight(d: &mut Ros2Drive<Recorder>, k: u32) -> State {
        let l = link();
        let t = f64::from(k) * 0.02;
        let msg = Odometry::planar(
            0.5 * t,
            0.0,
            0.0,
            0.5,
            0.0,
            Time::from_nanos(1_000_000_000 + (t * 1e9) as i64),
            "odom",
            "base_link",
        );
        d.on_input(ODOM_INPUT, &odom_key(&l), &msg.to_cdr(), t);
        d.advance(t);
        State {
            x: 0.5 * t,
            v: 0.5,
            ..State::default()
        }
    }

    /// Issue 22: a wrong type, another frame, a NaN pose and a fix 5 m away
    /// are counted and refused, and the robot keeps driving on its
    /// odometry: its state stays `odom_origin ⊕ raw`, its published
    /// odometry block is the raw pose with its age and the last good fix's.
    #[test]
    fn bad_fixes_leave_the_robot_on_its_odometry() {
        let (mut d, key, origin) = drive_with_fixes(true);
        let at = |p: &Pose| PoseStamped::planar(p.x, p.y, p.theta, Time::default(), "map");
        for k in 0..10 {
            straight(&mut d, k);
        }
        // A good fix at the truth: taken, the world unchanged.
        let truth = origin.compose(&Pose {
            x: 0.5 * 0.18,
            ..Pose::default()
        });
        d.on_input(FIX_INPUT, &key, &at(&truth).to_cdr(), 0.18);
        let wrong_type = topic_key(
            KeyScheme::RmwZenoh,
            0,
            "/mocap/robot1/pose",
            &echelon_ros2::msgs::POSE_WITH_COVARIANCE_STAMPED,
        );
        let far = Pose {
            x: truth.x + 5.0,
            ..truth
        };
        let nan = Pose {
            x: f64::NAN,
            ..truth
        };
        let mut other_frame = at(&truth);
        other_frame.header.frame_id = "odom".to_owned();
        for k in 10..100 {
            let raw = straight(&mut d, k);
            let t = f64::from(k) * 0.02;
            match k % 4 {
                0 => d.on_input(FIX_INPUT, &wrong_type, &at(&truth).to_cdr(), t),
                1 => d.on_input(FIX_INPUT, &key, &other_frame.to_cdr(), t),
                2 => d.on_input(FIX_INPUT, &key, &at(&nan).to_cdr(), t),
                _ if k < 40 => d.on_input(FIX_INPUT, &key, &at(&far).to_cdr(), t),
                _ => {}
            }
            let s = d.state().expect("driving on odometry");
            let want = raw.carried_by(&origin);
            assert!(
                (s.x - want.x).abs() < 1e-9 && (s.y - want.y).abs() < 1e-9,
                "{s:?} vs {want:?}"
            );
            let o = Plant::odometry(&d).expect("the raw odometry");
            assert_eq!(o.raw, [raw.x, 0.0, 0.0]);
            assert_eq!(o.age, 0.0);
            let fix_age = o.fix_age.expect("a fix was taken");
            assert!((fix_age - (t - 0.18)).abs() < 1e-12, "{fix_age}");
        }
        let c = d.fixes().expect("fixes").counters();
        assert_eq!(
            (
                c.applied,
                c.wrong_type,
                c.wrong_frame,
                c.non_finite,
                c.gated
            ),
            (1, 22, 22, 23, 8),
            "{c:?}"
        );
        assert_eq!(c.relocalized, 0);
    }

    /// σ without an EKF covariance (`reset` fixes, no gate): the
    /// dead-reckoning rule, growing with the distance driven, the fix's
    /// noise right after a fix; without fixes the same rule from the start.
    #[test]
    fn sigma_grows_on_odometry_and_is_the_fixs_after_one() {
        let (mut d, key, origin) = drive_with_fixes(false);
        let at = |p: &Pose| PoseStamped::planar(p.x, p.y, p.theta, Time::default(), "map");
        assert_eq!(d.position_sigma(), 0.0);
        let mut last = 0.0;
        for k in 0..50 {
            straight(&mut d, k);
            let sigma = d.position_sigma();
            assert!(sigma >= last);
            last = sigma;
        }
        // Slip alone on a straight line: √(slip d / 2) along the track,
        // plus the heading's share.
        let along = (1e-4 * 0.49 / 2.0f64).sqrt();
        assert!(last > along, "{last} vs {along}");
        let truth = origin.compose(&Pose {
            x: 0.49 * 0.5,
            ..Pose::default()
        });
        d.on_input(FIX_INPUT, &key, &at(&truth).to_cdr(), 0.98);
        assert_eq!(d.position_sigma(), 0.005);
        straight(&mut d, 50);
        assert!(d.position_sigma() > 0.005);
    }

    #[test]
    fn commands_are_limited_finite_stamped_and_attached() {
        let base = VelocityBase::new(0.0, 0.0, 0.2, 1.0, f64::INFINITY, f64::INFINITY)
            .expect("an ideal base with speed limits");
        let mut d = drive(base);
        let act = d.command(Command::Velocity(VelocityCommand { v: 0.4, omega: 0.5 }));
        let (applied, saturated) = act.velocity.expect("velocity");
        assert!(saturated);
        let (msg, att) = last_cmd(&d);
        assert_eq!(msg.twist.linear.x, 0.2);
        assert!((msg.twist.angular.z - 0.25).abs() < 1e-15);
        assert_eq!(msg.twist.angular.z, applied.omega);
        assert_eq!(msg.header.frame_id, "base_link");
        assert_eq!(att.sequence_number, 1);
        assert_eq!(att.gid, [7; 16]);
        // By default the stamp is zero (diff_drive_controller: "now" on its
        // own clock); the attachment keeps the send time.
        assert_eq!(msg.header.stamp, Time::default());
        assert!(att.source_timestamp_ns > 0);
        let mut stamped = Ros2Drive::new(
            Ros2Link {
                cmd_vel_stamp: CmdVelStamp::Now,
                ..link()
            },
            base,
            [7; 16],
            Recorder::default(),
        );
        stamped.command(Command::Velocity(VelocityCommand { v: 0.1, omega: 0.0 }));
        let (msg, att) = last_cmd(&stamped);
        assert_eq!(att.source_timestamp_ns, msg.header.stamp.to_nanos());
        d.command(Command::Velocity(VelocityCommand {
            v: f64::NAN,
            omega: 0.1,
        }));
        let (msg, att) = last_cmd(&d);
        assert_eq!((msg.twist.linear.x, msg.twist.angular.z), (0.0, 0.0));
        assert_eq!(att.sequence_number, 2);
        d.stop();
        let (msg, _) = last_cmd(&d);
        assert_eq!((msg.twist.linear.x, msg.twist.angular.z), (0.0, 0.0));
        let c = d.counters();
        assert_eq!(
            (c.cmd_sent, c.cmd_saturated, c.cmd_non_finite, c.cmd_zero),
            (3, 1, 1, 1)
        );
    }
}
