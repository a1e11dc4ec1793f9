//! Following over a link: a perfect one, the link-loss policies (`stop`,
//! `extrapolate`), a restarted leader and a silent leader robot.

use super::*;

#[test]
fn a_perfect_link_converges_and_the_chain_follows() {
    let s = scenario(EXTRAPOLATE);
    let mut w = Fleet::of(&s, &[FaultSpec::default(); 2]);
    w.run_until(30.0);
    for (i, r) in w.robots().enumerate() {
        let rep = r.report();
        assert!(rep.final_error < 1e-3, "agent {}: {rep:?}", i + 1);
        assert_eq!(rep.link, "tracking");
        // Every message used (the last one may still be on its way).
        assert_eq!(
            rep.counters.accepted + rep.pending,
            rep.counters.received,
            "{rep:?}"
        );
        assert_eq!(rep.counters.link_losses, 0);
        // 100 Hz for 30 s.
        assert!((2990..=3001).contains(&rep.ticks), "{rep:?}");
        conserved(r);
    }
}

/// Velocity bases in the fleet: both robots on a lagged, limited base
/// under the kinematic law converge, and end where the simulator's
/// continuous-time run of the same scenario ends (the fleet samples the
/// law at 100 Hz and sees the reference at 50 Hz).
#[test]
fn velocity_bases_converge_where_the_simulator_does() {
    let src = FAST_CIRCLE
        .replace("robot = \"agent1\"", "robot = \"base\"")
        .replace("robot = \"agent2\"", "robot = \"base\"")
        + "\n[robots.base]\ndrive = \"velocity\"\ntau_v = 0.05\ntau_omega = 0.04\nv_max = 0.5\nomega_max = 2.0\na_max = 1.0\nalpha_max = 4.0\n";
    let s = Scenario::parse(&src, "test", None).unwrap_or_else(|e| panic!("{e}"));
    let mut w = Fleet::of(&s, &[FaultSpec::default(); 2]);
    w.run_until(30.0);
    let mut sim = s
        .build(&Overrides::default())
        .unwrap_or_else(|e| panic!("{e}"))
        .simulation();
    sim.run(&mut |_: &echelon::sim::Frame<'_>| Ok(()))
        .unwrap_or_else(|e| panic!("{e}"));
    for (i, r) in w.robots().enumerate() {
        let rep = r.report();
        assert!(rep.final_error < 1e-3, "agent {}: {rep:?}", i + 1);
        let end = r.plant().true_state();
        let want = sim.states()[i];
        assert!(
            dist(&end, &want) < 5e-3,
            "agent {}: {end:?} vs {want:?}",
            i + 1
        );
        assert!(end.v.abs() <= 0.5 && end.omega.abs() <= 2.0);
        assert!(r.last().u == Input::default() && r.last().tau == Default::default());
    }
}

/// `stop`: the leader is taken at rest where it was last heard; the robot
/// decelerates, converges there and holds; a follower of that robot (its
/// own link fresh all along) comes to rest behind it. Both recover.
#[test]
fn stop_policy_brings_the_robot_and_its_follower_to_rest() {
    let s = scenario(STOP);
    let faults = FaultSpec {
        outage: Some((12.0, 3.0)),
        ..FaultSpec::default()
    };
    let mut w = Fleet::of(&s, &[faults, FaultSpec::default()]);
    w.run_until(12.0);
    let before = w.robot(0).last().e;
    assert!(norm(before) < 5e-3, "{before:?}");
    w.run_until(15.0);
    // The last sample heard was sent at 11.98; the timeout is 0.5 s.
    let ts = 11.98;
    let held = reference(&s).eval(ts, Order::Two).p;
    for st in w.states(0, 12.0, 15.0) {
        if st.t < ts + 0.5 - 1e-6 {
            assert_eq!(st.link, LinkStatus::Tracking, "{st:?}");
        } else if st.t > ts + 0.5 + 1e-6 {
            assert_eq!(st.link, LinkStatus::Stopping, "{st:?}");
            assert!(norm([st.leader.p[0] - held[0], st.leader.p[1] - held[1]]) < 1e-12);
            assert_eq!((st.leader.dp, st.leader.ddp), ([0.0; 2], [0.0; 2]));
        }
    }
    // It slows down: the speed at the timeout, then at rest (< 2 cm/s)
    // and converged to the held position (‖e‖ < 2 cm) over the last 0.5 s,
    // moving less than 5 mm in all of it.
    let lost = w.states(0, ts + 0.5 + 1e-6, ts + 0.52)[0];
    assert!(lost.state.v > 0.1, "{lost:?}");
    let late = w.states(0, 14.5, 15.0);
    assert!(late.len() >= 49, "{}", late.len());
    for st in &late {
        assert!(st.state.v.abs() < 0.02, "{st:?}");
        assert!(norm(st.e) < 0.02, "{st:?}");
    }
    assert!(dist(&late[0].state, &late[late.len() - 1].state) < 5e-3);
    // Robot 2 is still tracking robot 1, and at rest behind it.
    for st in w.states(1, 14.5, 15.0) {
        assert_eq!(st.link, LinkStatus::Tracking);
        assert!(st.state.v.abs() < 0.03, "{st:?}");
    }
    // Both recover.
    w.run_until(30.0);
    let c = *w.robot(0).counters();
    assert_eq!(c.link_losses, 1, "{c:?}");
    assert!(
        c.injected_outage >= 149 && c.injected_outage <= 151,
        "{c:?}"
    );
    for r in w.robots() {
        assert!(r.report().final_error < 1e-3, "{:?}", r.report());
        assert_eq!(r.last().link, LinkStatus::Tracking);
        conserved(r);
    }
}

/// `extrapolate`, hold 4 s: during a 3 s outage the leader motion the robot
/// uses is the true circle (eq. 18 is exact), so the robot keeps tracking
/// the true reference within 1 cm.
#[test]
fn extrapolate_keeps_the_robot_on_the_true_circle_within_the_hold() {
    let s = scenario(EXTRAPOLATE);
    let reference = reference(&s);
    let mut w = Fleet::of(&s, &[FaultSpec::default()]);
    w.cut(12.0, 15.0);
    w.run_until(20.0);
    let spec = w.robot(0).config().spec.clone();
    let during = w.states(0, 12.0, 15.0);
    assert!(during.len() >= 299, "{}", during.len());
    let mut max_e: f64 = 0.0;
    for st in &during {
        let jet = reference.eval(st.t, Order::Two);
        let off = norm([st.leader.p[0] - jet.p[0], st.leader.p[1] - jet.p[1]]);
        if st.t > 11.98 + 0.5 + 1e-6 {
            // Exact along the arc.
            assert_eq!(st.link, LinkStatus::Extrapolating, "{st:?}");
            assert!(off < 1e-9, "{off} {st:?}");
        } else {
            // Fresh: a second-order Taylor step over τ ≤ 0.5 s, error
            // ≤ τ³ V ω² / 6 = 1.7e-4 m.
            assert!(off < 1.7e-4, "{off} {st:?}");
        }
        let truth = follow(&spec, &st.state, LeaderView::Reference(&jet));
        max_e = max_e.max(norm(truth.law.e));
    }
    assert!(max_e < 0.01, "{max_e}");
    assert_eq!(w.robot(0).counters().link_losses, 1);
    assert!(w.robot(0).last().link == LinkStatus::Tracking);
    assert!(norm(w.robot(0).last().e) < 1e-3);
}

/// `extrapolate`, hold 1 s, decel 0.2 m/s²: past the hold the leader motion
/// slows to rest on the circle (`T = π V / 2a`) at `V (hold + T/2)` along
/// it, and the robot comes to rest behind that point.
#[test]
fn extrapolate_past_the_hold_stops_on_the_circle() {
    let s = scenario(r#"{ policy = "extrapolate", hold = 1.0, decel = 0.2 }"#);
    let reference = reference(&s);
    let mut w = Fleet::of(&s, &[FaultSpec::default()]);
    w.cut(12.0, 40.0);
    w.run_until(25.0);
    let ts = 11.98;
    let big_t = std::f64::consts::PI * 0.2 / (2.0 * 0.2);
    let rest = reference.eval(ts + 1.0 + 0.5 * big_t, Order::Two).p;
    for st in w.states(0, 12.0, 25.0) {
        let age = st.t - ts;
        if age > 0.5 + 1e-9 && age <= 1.0 - 1e-9 {
            assert_eq!(st.link, LinkStatus::Extrapolating, "{st:?}");
        } else if age > 1.0 + 1e-9 {
            assert_eq!(st.link, LinkStatus::Stopping, "{st:?}");
        }
        if age > 1.0 + big_t + 1e-9 {
            assert_eq!(st.leader.dp, [0.0, 0.0]);
            assert!(
                norm([st.leader.p[0] - rest[0], st.leader.p[1] - rest[1]]) < 1e-9,
                "{st:?} vs {rest:?}"
            );
        }
    }
    let late = w.states(0, 24.0, 25.0);
    for st in &late {
        assert!(st.state.v.abs() < 0.01 && norm(st.e) < 0.01, "{st:?}");
    }
    assert!(dist(&late[0].state, &late[late.len() - 1].state) < 5e-3);
}

/// A leader restarts (new source, new timeline from 0): the robot resyncs
/// its clock, counts the restart and drops the old leader's sample instead
/// of taking it as fresh on the new clock: with 50 ms of injected delay it
/// waits until the new leader's first sample is delivered.
#[test]
fn a_restarted_leader_resyncs_and_the_old_sample_is_dropped() {
    let s = scenario(EXTRAPOLATE);
    let mut w = Fleet::of(&s, &[delayed(0.05)]);
    w.run_until(10.0);
    assert!(w.robot(0).last().t > 9.9);
    // The new leader process: another source, its clock from 0.
    w.restart_leader(&s, 2, 10.001);
    w.run_until(10.3);
    let after: Vec<Published> = w
        .log(0)
        .into_iter()
        .filter(|p| p.local > 10.0 && p.state.t < 5.0)
        .collect();
    // New timeline: fleet time restarts near 0.
    assert!(after[0].state.t < 0.01, "{:?}", after[0]);
    // Nothing of the new leader delivered before 0.05: waiting, not
    // tracking the old sample (which the new clock would call fresh).
    for p in after.iter().filter(|p| p.state.t < 0.05) {
        assert_eq!(p.state.link, LinkStatus::Waiting, "{p:?}");
    }
    let first = after
        .iter()
        .find(|p| p.state.link == LinkStatus::Tracking)
        .unwrap_or_else(|| panic!("never tracked again"));
    assert!(first.state.t >= 0.05 - 1e-9, "{first:?}");
    let want = reference(&s).eval(first.state.t, Order::Two).p;
    assert!(
        norm([
            first.state.leader.p[0] - want[0],
            first.state.leader.p[1] - want[1]
        ]) < 1e-3
    );
    let c = *w.robot(0).counters();
    assert_eq!(c.restarts, 1, "{c:?}");
    // The old leader's messages still delayed at the restart (50 ms of
    // them) were refused as stale.
    assert!((2..=3).contains(&c.stale), "{c:?}");
    assert!(w.robot(0).is_synced());
    conserved(w.robot(0));
}

/// A chained follower whose leader robot stops publishing (its process
/// died): the follower loses its link and, under `stop`, comes to rest
/// behind the last state it heard.
#[test]
fn a_follower_whose_leader_robot_goes_silent_stops() {
    let s = scenario(STOP);
    let mut w = Fleet::of(&s, &[FaultSpec::default(); 2]);
    w.run_until(12.0);
    assert!(w.robot(1).report().final_error < 5e-3);
    // Robot 1's process dies: it leaves the bus, robot 2 stays.
    let died: Option<RobotTask> = w.bus.take(w.robots[0]);
    assert!(died.is_some());
    let mut last = *w.robot(1).last();
    w.run_until(16.0);
    for p in w.log(1).into_iter().filter(|p| p.local > 12.0) {
        let st = p.state;
        last = st;
        if st.t > 12.0 + 0.5 + 0.011 {
            assert_eq!(st.link, LinkStatus::Stopping, "{st:?}");
            assert_eq!(st.leader.dp, [0.0, 0.0]);
        }
    }
    assert!(last.state.v.abs() < 0.02 && norm(last.e) < 0.02, "{last:?}");
    assert_eq!(w.robot(1).counters().link_losses, 1);
}
