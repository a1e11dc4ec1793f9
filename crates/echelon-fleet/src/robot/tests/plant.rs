//! The robot and its plant: the divergence guard, a lost odometry, a
//! neighbour gone stale (the safety brake), a driven head.

use super::*;

/// The divergence guard: with a gain of 1e12 the plant's state leaves
/// its bounds within a tick; the robot commands zero, stops for good and
/// says which agent, when and what.
#[test]
fn a_diverging_robot_stops_at_zero_and_says_why() {
    let src = FAST_CIRCLE.replace("[sim]", "[control]\nke = 1e12\n\n[sim]");
    let s = Scenario::parse(&src, "test", None).unwrap_or_else(|e| panic!("{e}"));
    let mut w = Fleet::of(&s, &[FaultSpec::default()]);
    w.run_until(2.0);
    let r = &w.robot(0);
    let why = r.diverged().unwrap_or_else(|| panic!("{:?}", r.report()));
    assert!(why.starts_with("agent 1 diverged at t = "), "{why}");
    assert!(
        why.contains("left its bound") || why.contains("not finite"),
        "{why}"
    );
    // Stopped: due never again, zero commanded, nothing published after.
    let applied = r.plant().applied();
    assert!(applied.velocity.is_none(), "a torque robot: {applied:?}");
    assert_eq!(applied.u, Input::default());
    let last = w.log(0).last().map_or(0.0, |p| p.local);
    w.run_until(3.0);
    assert_eq!(w.log(0).last().map_or(0.0, |p| p.local), last);
}

/// `[sim] bounds` reaches the fleet robot: a bound of 0.05 m/s stops a
/// robot that follows a 0.2 m/s circle, naming `|v|`.
#[test]
fn the_scenarios_bounds_stop_the_fleet_robot() {
    let src = FAST_CIRCLE.replace("[sim]\n", "[sim]\nbounds = { speed = 0.05 }\n");
    let s = Scenario::parse(&src, "test", None).unwrap_or_else(|e| panic!("{e}"));
    let r = robot(&s, 1, FaultSpec::default());
    assert_eq!(r.config().bounds.speed, 0.05);
    let mut w = Fleet::new(&s, vec![r]);
    w.run_until(10.0);
    let why = w
        .robot(0)
        .diverged()
        .unwrap_or_else(|| panic!("never stopped"));
    assert!(
        why.contains("|v| = ") && why.contains("left its bound 0.05 m/s"),
        "{why}"
    );
}

/// Odometry lost, or the process stopping: the drive is commanded zero;
/// while the odometry is lost the robot is held by its odometry watchdog
/// and publishes its last known state with the link `held` (so its
/// followers and neighbours see it held where it was last seen, not a
/// stream gone silent); it follows again when the odometry returns.
#[test]
fn losing_the_odometry_or_the_process_commands_zero() {
    let s = scenario(EXTRAPOLATE);
    let mut r = commanded_robot(&s);
    let reference = reference(&s);
    let mut buf = Vec::new();
    reference_message(&mut buf, 0, 0.0, &reference);
    r.on_message(&buf, 0.0);
    let (_, first) = r.tick(0.0).publish.unwrap_or_else(|| panic!("a state"));
    assert_ne!(r.plant().commanded, Input::default());
    r.plant_mut().lost = true;
    let (_, held) = r.tick(0.01).publish.unwrap_or_else(|| panic!("held"));
    assert_eq!(held.link, LinkStatus::Held);
    assert_eq!(held.state, first.state, "its last known state");
    assert_eq!((held.dv, held.domega), (0.0, 0.0));
    assert_eq!(r.plant().commanded, Input::default());
    r.plant_mut().lost = false;
    assert!(r.tick(0.02).publish.is_some());
    assert_ne!(r.plant().commanded, Input::default());
    let stats = r.finish();
    assert_eq!(r.plant().commanded, Input::default());
    assert_eq!((stats.published, stats.counters.accepted), (3, 1));
    assert_eq!(stats.safety, None);
}

/// `crossing`'s agent 1 hears its neighbour (agent 4, 1.2 m away: in
/// range) once, then never again while the reference keeps coming: it
/// moves while the neighbour is fresh and held stopped, then brakes to
/// rest once the hold is over (docs/fleet.md, "Safety filter between
/// robots"), counting one stale episode.
#[test]
fn a_neighbour_stale_past_the_hold_brakes_the_robot() {
    let s = Scenario::resolve("crossing").unwrap_or_else(|e| panic!("{e}"));
    let mut r = robot(&s, 1, FaultSpec::default());
    assert!(r.has_safety());
    let mut buf = Vec::new();
    let b1 = RobotState {
        t: 0.0,
        agent: 4,
        link: LinkStatus::Tracking,
        state: State {
            x: -0.5,
            y: -0.6,
            ..State::default()
        },
        ..RobotState::default()
    };
    wire::encode_state(&mut buf, Header { source: 9, seq: 0 }, &b1);
    r.on_neighbour(wire::decode(&buf), 0.0);
    let timeout = r.config().link_timeout;
    let mut moved = false;
    let mut seq = 0;
    let mut t = 0.0;
    while t < 2.0 {
        if t >= 0.02 * seq as f64 {
            let tr = 0.02 * seq as f64;
            let r0 = wire::Reference {
                t: tr,
                motion: LeaderMotion {
                    p: [0.15 * tr, 0.0],
                    dp: [0.15, 0.0],
                    ddp: [0.0, 0.0],
                },
                speed: 0.15,
                turn_rate: 0.0,
            };
            wire::encode_reference(&mut buf, Header { source: 1, seq }, &r0);
            r.on_message(&buf, t);
            seq += 1;
        }
        if r.is_due(t) {
            let _ = r.tick(t);
            let v = r.last().state.v;
            if t < timeout + STALE_HOLD - 0.05 && v.abs() > 1e-3 {
                moved = true;
            }
        }
        t += 0.001;
    }
    let c = r.safety_counts().unwrap_or_default();
    assert!(moved, "it should move while the neighbour is fresh or held");
    assert_eq!(c.stale_neighbours, 1, "{c:?}");
    assert!(c.stale_brakes > 100, "{c:?}");
    let last = r.last().state;
    assert!(last.v.abs() < 1e-9 && last.omega.abs() < 1e-9, "{last:?}");
    // The stats message carries the same counters.
    assert_eq!(r.finish().safety, Some(c));
}

proptest::proptest! {
    /// The head's derivative filter: a constant speed has no derivative, a
    /// ramp's slope is reached within `e^{−t/τ}` (here after 1 s, 5 τ… 10 τ),
    /// at any sampling step.
    #[test]
    fn the_head_filter_differentiates_ramps(
        v0 in -1.0..1.0f64, a in -2.0..2.0f64, w0 in -1.0..1.0f64, alpha in -2.0..2.0f64,
        h in 0.001..0.05f64,
    ) {
        let mut f = HeadFilter::default();
        let mut t = 0.0;
        let mut last = (0.0, 0.0);
        while t < 1.0 {
            last = f.update(t, v0 + a * t, w0 + alpha * t);
            t += h;
        }
        let tol = 1e-2 * (1.0 + a.abs().max(alpha.abs()));
        proptest::prop_assert!((last.0 - a).abs() < tol, "{} vs {}", last.0, a);
        proptest::prop_assert!((last.1 - alpha).abs() < tol, "{} vs {}", last.1, alpha);
        let mut still = HeadFilter::default();
        for k in 0..50 {
            proptest::prop_assert_eq!(still.update(f64::from(k) * h, v0, w0), (0.0, 0.0));
        }
    }
}

/// A driven head (`ros2 = { driven = true }`): its robot moves by its
/// driver's commands (here the test's, on the simulated plant), never the
/// robot's; it publishes the plant's state with `v̇` from its filter on its
/// own clock, ignores the reference, and stopping commands nothing.
#[test]
fn a_driven_head_publishes_its_robots_motion_and_commands_nothing() {
    let s = scenario(EXTRAPOLATE);
    let config = crate::testing::robot_config(&s, 1, FaultSpec::default());
    let mut head = Robot::simulated(
        RobotConfig {
            driven: true,
            ..config
        },
        7,
    );
    assert!(head.is_synced(), "a head keeps its own time");
    let driver = Command::Torque(Input { u1: 20.0, u2: 1.0 });
    head.plant_mut().command(driver);
    // The reference's messages are not its leader's.
    let mut leader = ReferenceLeader::new(reference(&s), 50.0, 1e9, 1);
    let mut buf = Vec::new();
    let mut published = Vec::new();
    let mut now = 0.0;
    while now < 3.0 {
        if let Some((h, r)) = leader.tick(now + 50.0) {
            wire::encode_reference(&mut buf, h, &r);
            head.on_message(&buf, now);
        }
        if head.is_due(now) {
            let tick = head.tick(now);
            if let Some((_, st)) = tick.publish {
                published.push(st);
            }
        }
        now += 0.001;
    }
    assert!(head.counters().foreign > 100 && head.counters().received == head.counters().foreign);
    assert!(
        (290..=302).contains(&published.len()),
        "{}",
        published.len()
    );
    let last = published[published.len() - 1];
    assert!((last.t - 2.99).abs() < 0.011, "its own clock: {}", last.t);
    let truth = head.plant().state().unwrap_or_else(|| panic!("a state"));
    assert!(last.state.v > 0.05 && (last.state.x - truth.x).abs() < 0.01);
    let (dv, domega) = head.plant().accelerations();
    assert!(
        (last.dv - dv).abs() < 0.05 * dv.abs() + 1e-3
            && (last.domega - domega).abs() < 0.05 * domega.abs() + 1e-3,
        "{last:?} vs ({dv}, {domega})"
    );
    assert_eq!(last.link, LinkStatus::Tracking);
    // Stopping leaves the driver's command alone.
    let _ = head.finish();
    assert_eq!(head.plant().accelerations(), (dv, domega));
}
