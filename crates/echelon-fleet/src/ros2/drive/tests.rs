use super::*;
use echelon::base::VelocityBaseSpec;
use echelon::model::wrap_angle;
use echelon::scenario::Scenario;
use echelon_ros2::KeyScheme;
use echelon_ros2::keys::topic_key;
use echelon_ros2::msgs::{POSE_STAMPED, PoseStamped};

/// Records what was sent (and which of it through `send_stop`); time
/// advances 1 ms per read.
#[derive(Debug, Default)]
pub(crate) struct Recorder {
    pub(crate) sent: Vec<(Vec<u8>, Vec<u8>)>,
    pub(crate) now: std::cell::Cell<i64>,
    /// The indices in `sent` of what went through `send_stop`.
    pub(crate) stops: Vec<usize>,
    /// What it says of the commands' reader (`None`: cannot tell).
    pub(crate) reader: Option<bool>,
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
    fn send_stop(&mut self, payload: &[u8], attachment: &[u8]) -> Result<(), String> {
        self.stops.push(self.sent.len());
        self.send(payload, attachment)
    }
    fn reader_present(&self) -> Option<bool> {
        self.reader
    }
}

proptest::proptest! {
    /// The reader present or absent over random spans: the drive says it
    /// is lost only when it has been absent for at least the grace (as
    /// looked for every check), and always once absent for the grace and
    /// one check; a sink that cannot tell is never lost.
    #[test]
    fn a_vanished_reader_is_lost_after_the_grace_and_only_then(
        // Each span longer than two checks: a blip shorter than a check
        // may pass unseen between two looks.
        spans in proptest::collection::vec((proptest::bool::ANY, 0.1..1.0f64), 1..12),
        can_tell in proptest::bool::ANY,
    ) {
        let mut d = drive(VelocityBase::IDEAL);
        let mut t = 0.0;
        let mut absent_since: Option<f64> = None;
        // The last absence: how long it lasted, and when it ended.
        let mut last_absence: Option<(f64, f64)> = None;
        for (present, len) in spans {
            d.sink_mut().reader = can_tell.then_some(present);
            let end = t + len;
            while t < end {
                t += 0.01;
                d.advance(t);
                absent_since = match (can_tell, present, absent_since) {
                    (true, false, since) => Some(since.unwrap_or(t)),
                    (_, _, Some(since)) => {
                        last_absence = Some((t - since, t));
                        None
                    }
                    _ => None,
                };
                let lost = d.command_reader_lost();
                let absent = absent_since.map_or(0.0, |s| t - s);
                if lost {
                    // Absent long enough now, or until a return the
                    // drive has not looked for yet (within a check).
                    let recent = last_absence.is_some_and(|(lasted, ended)| {
                        lasted >= READER_GRACE - READER_CHECK - 0.011
                            && t - ended <= READER_CHECK + 0.011
                    });
                    proptest::prop_assert!(
                        absent >= READER_GRACE - READER_CHECK - 0.011 || recent,
                        "lost after {absent} s absent ({last_absence:?})"
                    );
                }
                if absent >= READER_GRACE + 2.0 * READER_CHECK + 0.02 {
                    proptest::prop_assert!(lost, "not lost after {absent} s absent");
                }
            }
        }
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
    // Each refusal counted under its reason, and nothing else.
    let counted = Ros2Counters {
        odom_received: 6,
        odom_accepted: 1,
        odom_malformed: 2,
        odom_non_finite: 1,
        odom_wrong_type: 1,
        odom_wrong_frames: 1,
        ..Ros2Counters::default()
    };
    assert_eq!(*d.counters(), counted);
}

proptest::proptest! {
    /// One rule for the drive and the fixes: an odometry whose orientation
    /// is a rotation scaled by `s` is the state iff tf2 would take it
    /// (`|s² − 1| < 10e-3`), its heading the rotation's; otherwise (an
    /// all-zero quaternion was yaw 0) it is counted as malformed and
    /// changes nothing: the state, the raw odometry, the heading unwrapper.
    #[test]
    fn odometry_whose_orientation_is_no_rotation_is_refused(
        yaw in -3.1..3.1f64, scale in 0.0..2.0f64, zero in proptest::bool::ANY,
    ) {
        let scale = if zero { 0.0 } else { scale };
        let mut d = drive(VelocityBase::IDEAL);
        let l = link();
        let key = odom_key(&l);
        d.on_odom(&key, &odom(1.0, 3.0, 0.2), 0.0).expect("valid");
        let (state, raw) = (d.state(), Plant::odometry(&d));
        let mut msg = Odometry::from_cdr(&odom(1.5, yaw, 0.2)).expect("valid");
        let q = &mut msg.pose.pose.orientation;
        (q.x, q.y, q.z, q.w) = (scale * q.x, scale * q.y, scale * q.z, scale * q.w);
        let taken = (scale * scale - 1.0).abs() < 0.0099;
        let refused = (scale * scale - 1.0).abs() > 0.0101;
        let r = d.on_odom(&key, &msg.to_cdr(), 0.0);
        if taken {
            proptest::prop_assert!(r.is_ok(), "{scale}: {r:?}");
            let s = d.state().expect("fresh");
            // Unwrapped from 3.0: the same heading modulo 2π, within π of 3.
            proptest::prop_assert!(wrap_angle(s.theta - yaw).abs() < 1e-9, "{s:?}");
            proptest::prop_assert!((s.theta - 3.0).abs() <= std::f64::consts::PI + 1e-9);
            proptest::prop_assert_eq!(s.x, 1.5);
        }
        if refused {
            proptest::prop_assert_eq!(r, Err(SampleRefusal::Orientation));
            proptest::prop_assert_eq!((d.state(), Plant::odometry(&d)), (state, raw));
            let c = d.counters();
            proptest::prop_assert_eq!((c.odom_received, c.odom_accepted, c.odom_malformed), (2, 1, 1));
            // The unwrapper did not see it: a valid heading next follows 3.0.
            d.on_odom(&key, &odom(1.5, -3.0, 0.2), 0.0).expect("valid");
            let s = d.state().expect("fresh");
            proptest::prop_assert!((s.theta - (std::f64::consts::TAU - 3.0)).abs() < 1e-12);
        }
    }
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

/// A lag-free base whose speeds are limited to `v_max`, `omega_max`.
fn limited(v_max: f64, omega_max: f64) -> VelocityBase {
    VelocityBase::new(VelocityBaseSpec {
        v_max,
        omega_max,
        ..VelocityBase::IDEAL.spec()
    })
    .expect("an ideal base with speed limits")
}

#[test]
fn commands_are_limited_finite_stamped_and_attached() {
    let base = limited(0.2, 1.0);
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

proptest::proptest! {
    /// Whatever the robot commands in between (zero included, NaN, beyond
    /// the limits), exactly its stops go through `send_stop` (the reliable
    /// put of the robot's last words) and each of them is zero; every other
    /// command goes through `send` (never blocking the control loop); one
    /// sequence number for both, counted.
    #[test]
    fn exactly_the_stops_go_through_send_stop_as_zeros(
        steps in proptest::collection::vec(
            proptest::option::of((-5.0f64..5.0, -20.0f64..20.0, proptest::bool::ANY)),
            1..60,
        )
    ) {
        let mut d = drive(limited(0.5, 2.0));
        let mut stops = Vec::new();
        for (i, step) in steps.iter().enumerate() {
            match *step {
                None => {
                    stops.push(i);
                    d.stop();
                }
                Some((v, omega, nan)) => {
                    let v = if nan { f64::NAN } else { v };
                    d.command(Command::Velocity(VelocityCommand { v, omega }));
                }
            }
        }
        proptest::prop_assert_eq!(&d.sink().stops, &stops);
        for &i in &stops {
            let (payload, _) = &d.sink().sent[i];
            let msg = TwistStamped::from_cdr_finite(payload).expect("valid TwistStamped");
            proptest::prop_assert_eq!((msg.twist.linear.x, msg.twist.angular.z), (0.0, 0.0));
        }
        for (i, (_, att)) in d.sink().sent.iter().enumerate() {
            let att = Attachment::decode(att).expect("valid attachment");
            proptest::prop_assert_eq!(att.sequence_number, i as i64 + 1);
        }
        let c = d.counters();
        proptest::prop_assert_eq!(c.cmd_sent, steps.len() as u64);
        proptest::prop_assert_eq!(c.cmd_zero, stops.len() as u64);
    }
}
