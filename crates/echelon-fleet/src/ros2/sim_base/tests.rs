use super::*;
use crate::ros2::drive::encode_cmd_vel;
use echelon::agent::Drive;
use echelon::base::VelocityRobot;
use echelon::odometry::ErrorModel;
use echelon::scenario::Scenario;
use echelon_ros2::KeyScheme;
use echelon_ros2::keys::topic_key;
use echelon_ros2::msgs::{TWIST, TWIST_STAMPED};

fn link() -> Ros2Link {
    let src = "[sim]\nduration = 1.0\ndt = 0.01\n[reference.circle]\nspeed = 0.1\nturn_rate = 0.1\nstart = { x = 0.0, y = 0.0, theta = 0.0 }\n[fleet.ros2]\nodom_rate = 10.0\ncmd_vel_timeout = 0.5\n[[agents]]\nstart = { x = 0.0, y = 0.0, theta = 0.0 }\nleader = \"reference\"\n";
    let s = Scenario::parse(src, "t", None).unwrap_or_else(|e| panic!("{e}"));
    s.fleet().unwrap_or_else(|e| panic!("{e}")).ros2[0].clone()
}

fn base() -> SimBase {
    let model = SimulatedDrive::new(
        Drive::Velocity(VelocityRobot::IDEAL),
        State::at_rest(0.0, 0.0, 0.0),
        0.0,
        1e-3,
    );
    SimBase::new(link(), model, [3; 16])
}

fn cmd(v: f64, omega: f64) -> Vec<u8> {
    let mut buf = Vec::new();
    encode_cmd_vel(&link(), VelocityCommand { v, omega }, 1, &mut buf);
    buf
}

fn attachment() -> [u8; 33] {
    Attachment {
        sequence_number: 1,
        source_timestamp_ns: 1,
        gid: [1; 16],
    }
    .encode()
}

/// Drives `b` at `(v, ω)` for `t` s (commands every 0.1 s) and returns
/// the last odometry it published (odom frame) and its true state.
fn drive(mut b: SimBase, v: f64, omega: f64, t: f64) -> (Odometry, State) {
    let key = topic_key(KeyScheme::RmwZenoh, 0, &link().cmd_vel, &TWIST_STAMPED);
    let mut last = None;
    let steps = (t / 0.1).round() as u32;
    for k in 0..=steps {
        let now = f64::from(k) * 0.1;
        b.on_cmd(&key, &cmd(v, omega), Some(&attachment()), now, 1)
            .expect("a valid command");
        if let Some(out) = b.tick(now, 1) {
            // The truth when this odometry was published.
            last = Some((out, b.base().true_state()));
        }
    }
    let (out, truth) = last.expect("odometry");
    let odom = Odometry::from_cdr_finite(&out.payload).expect("valid");
    (odom, truth)
}

fn odometry(errors: ErrorModel) -> OdometrySpec {
    OdometrySpec::new(0.01, errors, None).expect("valid odometry")
}

/// With perfect encoders the base's odometry is its truth (to the
/// trapezoidal travel's rounding); with Borenstein's unequal wheel
/// diameters `E_d` a base driving straight believes it turned by the
/// closed form `Θ̂ = d r (1/r_R − 1/r_L) / (2 l)` after `d` metres, while
/// its true heading stays 0.
#[test]
fn a_base_publishes_what_its_encoders_measure() {
    let (l, r) = (0.2, 0.05);
    let perfect = base()
        .with_odometry(odometry(ErrorModel::PERFECT), (l, r), 7, 0, 0.0)
        .expect("valid");
    let (odom, truth) = drive(perfect, 0.3, 0.4, 5.0);
    let p = odom.pose.pose.position;
    assert!(
        (p.x - truth.x).abs() < 1e-6 && (p.y - truth.y).abs() < 1e-6,
        "{p:?} vs {truth:?}"
    );
    let ed = ErrorModel::systematic(1.02, 1.0).unwrap();
    let uneven = base()
        .with_odometry(odometry(ed), (l, r), 7, 0, 0.0)
        .expect("valid");
    let (odom, truth) = drive(uneven, 0.3, 0.0, 5.0);
    assert_eq!(truth.theta, 0.0);
    let (rr, rl) = ed.wheel_radii(r);
    // Travel up to the last odometry sample before the last message.
    let d = odom.pose.pose.position.x.hypot(odom.pose.pose.position.y);
    let want = d * r * (1.0 / rr - 1.0 / rl) / (2.0 * l);
    let got = odom.yaw();
    assert!(want.abs() > 1e-3, "{want}");
    assert!(
        (got - want).abs() < 2e-3 * want.abs() + 1e-6,
        "believed heading {got} rad, closed form {want} rad"
    );
}

#[test]
fn it_follows_commands_publishes_odometry_and_stops_on_timeout() {
    let l = link();
    let key = topic_key(KeyScheme::RmwZenoh, 0, &l.cmd_vel, &TWIST_STAMPED);
    let mut b = base();
    assert!(b.tick(0.0, 1).is_some(), "odometry at once");
    b.on_cmd(&key, &cmd(0.2, 0.0), Some(&attachment()), 0.0, 1)
        .expect("a valid command");
    let mut last = None;
    let mut published = 0;
    for k in 1..=40 {
        if let Some(o) = b.tick(f64::from(k) * 0.025, 1) {
            published += 1;
            last = Some(o);
        }
    }
    // 10 Hz for 1 s; the command timed out at 0.5 s: 0.2 m/s × 0.5 s.
    assert_eq!(published, 10);
    let odom = Odometry::from_cdr_finite(&last.expect("odometry").payload).expect("valid");
    assert!((odom.pose.pose.position.x - 0.1).abs() < 1e-9, "{odom:?}");
    assert_eq!(odom.twist.twist.linear.x, 0.0);
    assert_eq!(
        (odom.header.frame_id.as_str(), odom.child_frame_id.as_str()),
        ("odom", "base_link")
    );
    assert_eq!(b.counters().cmd_timeouts, 1);
}

#[test]
fn bad_commands_are_counted_and_refused() {
    let l = link();
    let key = topic_key(KeyScheme::RmwZenoh, 0, &l.cmd_vel, &TWIST_STAMPED);
    let twist_key = topic_key(KeyScheme::RmwZenoh, 0, &l.cmd_vel, &TWIST);
    let mut b = base();
    let att = attachment();
    assert!(b.on_cmd(&key, &cmd(0.2, 0.0), None, 0.0, 1).is_err());
    assert!(
        b.on_cmd(&key, b"\x00\x01\x00\x00junk", Some(&att), 0.0, 1)
            .is_err()
    );
    assert!(
        b.on_cmd(&key, &cmd(f64::INFINITY, 0.0), Some(&att), 0.0, 1)
            .is_err()
    );
    assert!(
        b.on_cmd(&twist_key, &cmd(0.2, 0.0), Some(&att), 0.0, 1)
            .is_err()
    );
    assert_eq!(b.followed(), VelocityCommand::default());
    // Each refusal counted under its reason, none followed, nothing else.
    let counted = BaseCounters {
        cmd_received: 4,
        cmd_no_attachment: 1,
        cmd_malformed: 1,
        cmd_non_finite: 1,
        cmd_wrong_type: 1,
        ..BaseCounters::default()
    };
    assert_eq!(*b.counters(), counted);
}

/// `diff_drive_controller`'s stamp check: a base whose clock is `offset`
/// s ahead of the sender's, commanded every 0.1 s for 2 s at 0.2 m/s with
/// `cmd_vel_stamp = stamp` (stamps from the sender's wall clock): where it
/// ends (x, m) and its counters.
fn stamped_run(stamp: echelon::scenario::schema::CmdVelStamp, offset: f64) -> (f64, BaseCounters) {
    let l = Ros2Link {
        cmd_vel_stamp: stamp,
        ..link()
    };
    let key = topic_key(KeyScheme::RmwZenoh, 0, &l.cmd_vel, &TWIST_STAMPED);
    let model = SimulatedDrive::new(
        Drive::Velocity(VelocityRobot::IDEAL),
        State::at_rest(0.0, 0.0, 0.0),
        0.0,
        1e-3,
    );
    let mut b = SimBase::new(l.clone(), model, [3; 16]).with_clock_offset(offset);
    let wall0: i64 = 1_700_000_000_000_000_000;
    let mut buf = Vec::new();
    for k in 0..=20 {
        let now = f64::from(k) * 0.1;
        let wall = wall0 + (now * 1e9) as i64;
        encode_cmd_vel(&l, VelocityCommand { v: 0.2, omega: 0.0 }, wall, &mut buf);
        // The command reaches the base 2 ms later.
        let _ = b.on_cmd(&key, &buf, Some(&attachment()), now, wall + 2_000_000);
        b.tick(now, wall);
    }
    (b.base().true_state().x, *b.counters())
}

/// With its clock ahead by more than `cmd_vel_timeout` (0.5 s), a base
/// drops every command stamped `now` (counted, it never moves) and takes
/// every command stamped zero ("now" by its own clock: it drives 0.2 m/s
/// × 2 s); with its clock within the timeout, stamped commands drive it too.
#[test]
fn stale_stamps_leave_the_base_stopped_and_zero_stamps_drive_it() {
    use echelon::scenario::schema::CmdVelStamp;
    for offset in [0.6, 3.0, -600.0] {
        let (x, c) = stamped_run(CmdVelStamp::Now, offset);
        if offset > 0.5 {
            assert_eq!(x, 0.0, "offset {offset}");
            assert_eq!((c.cmd_stale, c.cmd_accepted), (21, 0), "offset {offset}");
        } else {
            // A clock behind the sender's: the commands look fresh.
            assert!((x - 0.4).abs() < 1e-9, "offset {offset}: {x}");
            assert_eq!(c.cmd_stale, 0);
        }
        let (x, c) = stamped_run(CmdVelStamp::Zero, offset);
        assert!((x - 0.4).abs() < 1e-9, "offset {offset}: {x}");
        assert_eq!((c.cmd_stale, c.cmd_accepted), (0, 21));
    }
    let (x, c) = stamped_run(CmdVelStamp::Now, 0.4);
    assert!((x - 0.4).abs() < 1e-9, "{x}");
    assert_eq!((c.cmd_stale, c.cmd_accepted), (0, 21));
}
