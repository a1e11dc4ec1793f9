use super::*;
use crate::ros2::hazard::{Hazard, HazardEvent, HazardSet};
use crate::wire::{Header, OdometryState, Reference, RobotState};

fn state(k: u32, link: LinkStatus, t: f64, e: [f64; 2]) -> Vec<u8> {
    let mut s = RobotState {
        t,
        agent: k,
        link,
        ..RobotState::default()
    };
    s.e = e;
    let mut buf = Vec::new();
    wire::encode_state(&mut buf, Header { source: 9, seq: 3 }, &s);
    buf
}

/// The conditions from the link status, the token and the age.
#[test]
fn conditions_follow_link_token_and_age() {
    let fresh = Duration::from_millis(10);
    let cases = [
        (LinkStatus::Tracking, Condition::Running),
        (LinkStatus::Extrapolating, Condition::Running),
        (LinkStatus::Waiting, Condition::Holding),
        (LinkStatus::Stopping, Condition::Holding),
        (LinkStatus::Held, Condition::Holding),
        (LinkStatus::Stopped, Condition::Stopped),
    ];
    for (link, c) in cases {
        assert_eq!(Condition::of(true, Some((link, fresh))), c, "{link:?}");
        assert_eq!(Condition::of(false, Some((link, fresh))), Condition::Lost);
        let old = LOST_AFTER + Duration::from_millis(1);
        assert_eq!(Condition::of(true, Some((link, old))), Condition::Lost);
    }
    assert_eq!(Condition::of(true, None), Condition::Lost);
}

/// States, stats, the reference and tokens make the status; another
/// agent's state or stats on a robot's key, garbage and other fleets'
/// keys change nothing but the refused count.
#[test]
fn the_view_shows_what_arrived() {
    let keys = Keys::new("lab");
    let t0 = Instant::now();
    let mut v = StatusView::new(keys.clone(), 3, t0);
    v.on_liveliness(&keys.alive("robot/1"), true);
    v.on_liveliness(&keys.alive("robot/2"), true);
    v.on_liveliness(&keys.alive("leader"), true);
    v.on_liveliness(&keys.alive("robot/2"), false);
    v.on_liveliness(&Keys::new("other").alive("collector"), true);
    v.on_sample(
        &keys.state(1),
        &state(1, LinkStatus::Tracking, 4.0, [0.03, 0.04]),
        t0,
    );
    v.on_sample(
        &keys.state(2),
        &state(2, LinkStatus::Stopped, 4.0, [0.0, 0.0]),
        t0,
    );
    let stats = serde_json::json!({
        "agent": 1, "t": 4.0, "link": "tracking", "published": 3,
        "cpu": {"seconds": 1.5, "share": 0.25},
        "hazards": {"in_force": [], "counts": {"hazard_received": 1, "hazard_refused": 0,
            "estop_received": 0, "estop_refused": 0, "object_proximity": 0,
            "backup_limit": 0, "onsets": 1},
            "last": {"hazard": "BUMP", "at": 2.0, "cleared": 3.0}},
    });
    v.on_sample(&keys.stats(1), stats.to_string().as_bytes(), t0);
    // Refused: robot 2's state on robot 3's key, robot 1's stats on
    // robot 3's, garbage as a reference.
    v.on_sample(
        &keys.state(3),
        &state(2, LinkStatus::Tracking, 4.0, [0.0, 0.0]),
        t0,
    );
    v.on_sample(&keys.stats(3), stats.to_string().as_bytes(), t0);
    v.on_sample(&keys.reference(), b"\xec\x03garbage", t0);
    let mut r = Vec::new();
    wire::encode_reference(
        &mut r,
        Header { source: 1, seq: 0 },
        &Reference {
            t: 4.5,
            motion: Default::default(),
            speed: 0.0,
            turn_rate: 0.0,
        },
    );
    v.on_sample(&keys.reference(), &r, t0);
    let s = v.status(t0 + Duration::from_millis(200));
    assert_eq!(s.refused, 3);
    assert_eq!(s.robots.len(), 3);
    let r1 = &s.robots[0];
    assert_eq!(
        (r1.robot, r1.state, r1.alive),
        (1, Condition::Running, true)
    );
    assert_eq!(r1.link.as_deref(), Some("tracking"));
    assert!((r1.error_norm.unwrap() - 0.05).abs() < 1e-15);
    assert!((r1.link_age.unwrap() - 0.2).abs() < 1e-9);
    assert_eq!(r1.cpu.unwrap().share, Some(0.25));
    assert_eq!(r1.hazard_cell(), "BUMP at 2.0 s, cleared 3.0 s");
    assert_eq!(r1.cpu_cell(), "25.0 % (1.50 s)");
    // Robot 2's token went: lost, whatever its last state said.
    assert_eq!(
        (s.robots[1].state, s.robots[1].alive),
        (Condition::Lost, false)
    );
    assert_eq!(s.robots[1].link.as_deref(), Some("stopped"));
    // Robot 3: the scenario's, never heard.
    assert!(!s.robots[2].heard() && s.robots[2].state == Condition::Lost);
    assert!(s.heard_a_robot());
    assert!(s.leader.alive && !s.collector.alive);
    assert_eq!(s.leader.t, Some(4.5));
    // Silent for longer than LOST_AFTER: lost though alive.
    let later = v.status(t0 + LOST_AFTER + Duration::from_millis(1));
    assert_eq!(later.robots[0].state, Condition::Lost);
    assert!(later.robots[0].alive);
    let table = s.to_string();
    let lines: Vec<&str> = table.lines().collect();
    assert_eq!(lines.len(), 5, "{table}");
    assert!(
        lines[0].starts_with(
            "fleet lab: leader alive, reference 0.20 s old (t = 4.50 s); collector lost"
        ),
        "{table}"
    );
    assert!(
        lines[1].starts_with("robot  state    link      link age, s  ‖e‖, m"),
        "{table}"
    );
    assert!(
        lines[2].starts_with("1      running  tracking  0.20         0.0500"),
        "{table}"
    );
    assert!(lines[2].ends_with("25.0 % (1.50 s)"), "{table}");
    assert!(
        lines[4].starts_with("3      lost     —         —            —"),
        "{table}"
    );
    // The JSON round-trips.
    let json = serde_json::to_string(&s).unwrap();
    assert_eq!(serde_json::from_str::<FleetStatus>(&json).unwrap(), s);
}

/// A hazard in force, a ROS 2 robot's odometry ages, and nothing heard.
#[test]
fn hazards_in_force_odometry_and_silence() {
    let keys = Keys::new("lab");
    let t0 = Instant::now();
    let mut v = StatusView::new(keys.clone(), 0, t0);
    assert!(!v.status(t0).heard_a_robot());
    assert!(v.status(t0).robots.is_empty());
    let mut s = RobotState {
        t: 1.0,
        agent: 2,
        link: LinkStatus::Held,
        odometry: Some(OdometryState {
            raw: [0.0; 3],
            age: 0.05,
            fix_age: Some(0.5),
        }),
        ..RobotState::default()
    };
    s.e = [0.0, 0.0];
    let mut buf = Vec::new();
    wire::encode_state(&mut buf, Header { source: 1, seq: 0 }, &s);
    v.on_liveliness(&keys.alive("robot/2"), true);
    v.on_sample(&keys.state(2), &buf, t0);
    let hazards = HazardStats {
        in_force: HazardSet::EMPTY.with(Hazard::Bump).with(Hazard::Cliff),
        counts: Default::default(),
        last: Some(HazardEvent {
            hazard: Hazard::Cliff,
            at: 0.5,
            cleared: None,
        }),
    };
    let stats = serde_json::json!({"agent": 2, "hazards": hazards});
    v.on_sample(&keys.stats(2), stats.to_string().as_bytes(), t0);
    let st = v.status(t0);
    let r = &st.robots[0];
    assert_eq!((r.robot, r.state), (2, Condition::Holding));
    assert_eq!((r.odometry_age, r.fix_age), (Some(0.05), Some(0.5)));
    assert_eq!(r.hazard_cell(), "BUMP+CLIFF (in force)");
    assert_eq!(r.cpu_cell(), "—");
    assert_eq!(r.error_norm, Some(0.0));
    assert_eq!(error_cell(Some(1.234e-4)), "1.23e-4");
    assert_eq!(error_cell(Some(0.0)), "0.0000");
}
