//! The watchdogs on the fake clock: a frozen odometry holds the robot
//! within its timeout and a control period, whatever the window, and it
//! follows again when the odometry returns; in a supervised run, robots
//! hold once the operator's heartbeat is older than the deadline, never
//! before, and follow again when heartbeats return; replayed heartbeats
//! keep no robot going.

use proptest::prelude::*;

use super::*;
use crate::heartbeat::{Heartbeat, HeartbeatTask};

/// The fast circle, with `[fleet] operator_heartbeat = deadline` when given.
fn supervised(deadline: Option<f64>) -> Scenario {
    let text = match deadline {
        Some(t) => {
            FAST_CIRCLE.replace("[fleet]\n", &format!("[fleet]\noperator_heartbeat = {t}\n"))
        }
        None => FAST_CIRCLE.to_owned(),
    };
    Scenario::parse(&text, "test", None).unwrap_or_else(|e| panic!("{e}"))
}

/// Whether a state says the robot is held by a watchdog.
fn held(s: &RobotState) -> bool {
    s.link == LinkStatus::Held
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// Agent `k`'s odometry frozen in `[a, a + len)`: from `a + timeout +
    /// period` on to the end of the window its states say `held` and it
    /// commands zero; none is held before `a`; it follows again within
    /// two periods after the window; one trip counted.
    #[test]
    fn a_frozen_odometry_holds_the_robot_until_it_returns(
        k in 1u32..=2, a in 3.0..8.0f64, len in 0.3..3.0f64,
    ) {
        let s = supervised(None);
        let freeze = FaultSpec { freeze_odometry: Some((a, len)), ..FaultSpec::default() };
        let faults: Vec<FaultSpec> = (1..=2).map(|j| if j == k { freeze } else { FaultSpec::default() }).collect();
        let mut fleet = Fleet::of(&s, &faults);
        let end = a + len + 2.0;
        fleet.run_until(end);
        let i = k as usize - 1;
        let r = fleet.robot(i);
        let timeout = r.config().watchdogs.odom_timeout;
        let period = r.config().period;
        let before = fleet.states(i, 1.0, a);
        let none_held = before.iter().all(|s| !held(s));
        prop_assert!(none_held, "held before the freeze");
        let during = fleet.states(i, a + timeout + period + 1e-9, a + len);
        prop_assert!(!during.is_empty());
        prop_assert!(during.iter().all(held), "not held while frozen");
        let after = fleet.states(i, a + len + 2.0 * period, end);
        let none_held = after.iter().all(|s| !held(s));
        prop_assert!(none_held, "still held after the thaw");
        prop_assert_eq!(r.watchdog_counts().odometry, 1);
        prop_assert_eq!(r.watchdog_counts().operator, 0);
        conserved(r);
    }

    /// A supervised run (deadline `t`): heartbeats every `t/4` until
    /// `last`; each robot is held from `last + t + period` on, never
    /// before (once the first heartbeat arrived); each hold counted.
    #[test]
    fn robots_hold_once_the_heartbeat_is_older_than_the_deadline(
        t in 0.2..2.0f64, last in 3.0..8.0f64,
    ) {
        let s = supervised(Some(t));
        let mut fleet = Fleet::of(&s, &[FaultSpec::default(), FaultSpec::default()]);
        let hb = HeartbeatTask::new(fleet.keys.clone(), t, 77, Some(last), None);
        fleet.bus.add(hb, 0.0);
        let end = last + t + 2.0;
        fleet.run_until(end);
        for i in 0..2 {
            let r = fleet.robot(i);
            let period = r.config().period;
            let before = fleet.states(i, 1.0, last);
            let none_held = before.iter().all(|s| !held(s));
            prop_assert!(none_held, "agent {} held too early", i + 1);
            let after = fleet.states(i, last + t + 2.0 * period, end);
            prop_assert!(!after.is_empty());
            prop_assert!(after.iter().all(held), "agent {} not held", i + 1);
            let w = r.watchdog_counts();
            // Once at the end; perhaps once at the very start too, before
            // the first heartbeat reached it.
            prop_assert!((1..=2).contains(&w.operator), "{:?}", w);
            prop_assert!(w.heartbeats > 0);
        }
    }
}

/// Without any heartbeat a supervised robot never moves; heartbeats that
/// return lift the hold; the same heartbeat put again (a replay) is
/// refused and does not keep a robot going.
#[test]
fn heartbeats_returning_lift_the_hold_and_replays_do_not() {
    let t = 0.5;
    let s = supervised(Some(t));
    let mut fleet = Fleet::of(&s, &[FaultSpec::default(), FaultSpec::default()]);
    let key = fleet.keys.heartbeat();
    fleet.run_until(3.0);
    assert!(fleet.states(0, 0.5, 3.0).iter().all(held));
    // Heartbeats from 3 s to 6 s.
    let mut seq = 0;
    let mut now = 3.0;
    while now < 6.0 {
        fleet.bus.put(&key, &Heartbeat { source: 9, seq }.encode());
        seq += 1;
        now += t / 4.0;
        fleet.run_until(now);
    }
    let following = fleet.states(0, 3.1, 6.0);
    assert!(following.iter().all(|s| !held(s)), "{following:?}");
    // Then only the last heartbeat again and again: refused, so held.
    let replay = Heartbeat {
        source: 9,
        seq: seq - 1,
    }
    .encode();
    while now < 8.0 {
        fleet.bus.put(&key, &replay);
        now += t / 4.0;
        fleet.run_until(now);
    }
    let replayed = fleet.states(0, 6.0 + t + 0.05, 8.0);
    assert!(!replayed.is_empty() && replayed.iter().all(held));
    let w = fleet.robot(0).watchdog_counts();
    assert!(w.heartbeats_refused >= 7, "{w:?}");
    assert_eq!(w.operator, 2, "{w:?}");
    // Garbage on the key is refused too.
    fleet.bus.put(&key, b"not a heartbeat");
    fleet.run_until(8.1);
    assert!(fleet.robot(0).watchdog_counts().heartbeats_refused > w.heartbeats_refused);
}

/// A simulated robot whose commands can lose their reader.
#[derive(Debug)]
struct Unread {
    inner: SimulatedDrive,
    lost: bool,
}

impl Plant for Unread {
    fn state(&self) -> Option<State> {
        self.inner.state()
    }
    fn advance(&mut self, t: f64) {
        self.inner.advance(t);
    }
    fn command(&mut self, cmd: Command) -> crate::plant::Actuation {
        self.inner.command(cmd)
    }
    fn stop(&mut self) {
        self.inner.stop();
    }
    fn accelerations(&self) -> (f64, f64) {
        self.inner.accelerations()
    }
    fn set_time(&mut self, t: f64) {
        self.inner.set_time(t);
    }
    fn command_reader_lost(&self) -> bool {
        self.lost
    }
}

/// Robot 1 whose base's `cmd_vel` reader vanishes at 3 s and returns at
/// 5 s, fed the reference by hand: held from its first tick after 3 s to
/// its last before 5 s (link `held`, zero applied), following before and
/// after; one output trip counted.
#[test]
fn a_robot_whose_commands_lose_their_reader_is_held_until_it_returns() {
    let s = supervised(None);
    let config = crate::testing::robot_config(&s, 1, FaultSpec::default());
    let plant = Unread {
        inner: SimulatedDrive::of(&config.spec, 0.0, PLANT_STEP),
        lost: false,
    };
    let period = config.period;
    let mut r = Robot::new(config, plant, 1);
    let reference = reference(&s);
    let mut buf = Vec::new();
    let (mut seq, mut t) = (0, 0.0);
    let mut links = Vec::new();
    while t < 7.0 {
        r.plant_mut().lost = (3.0..5.0).contains(&t);
        reference_message(&mut buf, seq, t, &reference);
        r.on_message(&buf, t);
        seq += 1;
        if r.is_due(t) {
            let tick = r.tick(t);
            if let Some((_, st)) = tick.publish {
                links.push((t, st.link, r.plant().inner.applied()));
            }
        }
        t += period / 2.0;
    }
    for (at, link, _) in &links {
        let lost = (3.0..5.0).contains(at);
        if *at > 1.0 && !lost {
            assert_eq!(*link, LinkStatus::Tracking, "at {at}");
        }
        if lost && *at >= 3.0 + period {
            assert_eq!(*link, LinkStatus::Held, "at {at}");
        }
    }
    let held: Vec<_> = links
        .iter()
        .filter(|(_, l, _)| *l == LinkStatus::Held)
        .collect();
    assert!(
        held.iter()
            .all(|(at, _, a)| (3.0..5.0 + period).contains(at)
                && a.velocity.is_none_or(|(v, _)| v.v == 0.0 && v.omega == 0.0)
                && a.u.u1 == 0.0
                && a.u.u2 == 0.0),
        "{held:?}"
    );
    assert_eq!(r.watchdog_counts().output, 1);
    assert_eq!(r.watchdog_counts().odometry, 0);
}
