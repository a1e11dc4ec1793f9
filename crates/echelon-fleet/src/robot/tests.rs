//! The robot's behaviour on a fake clock: a [`crate::leader::Leader`] and robots exchanging encoded messages in one deterministic event loop, no network, no sleeps.

use super::*;
use crate::faults::FaultSpec;
use crate::leader::Leader as LeaderTask;
use crate::link::predict;
use crate::plant::SimulatedPlant;
use echelon::agent::Command;
use echelon::follow::LeaderView;
use echelon::model::Input;
use echelon::model::State;
use echelon::reference::{Order, Reference, Trajectory};
use echelon::scenario::{Overrides, Scenario};

/// The CLI's process-test fleet (`echelon-cli/tests/fleet/fast-circle.toml`),
/// whose link-loss policy is [`EXTRAPOLATE`].
const FAST_CIRCLE: &str = include_str!("../../../echelon-cli/tests/fleet/fast-circle.toml");

const STOP: &str = r#"{ policy = "stop" }"#;
const EXTRAPOLATE: &str = r#"{ policy = "extrapolate", hold = 4.0, decel = 0.2 }"#;

fn scenario(link_loss: &str) -> Scenario {
    assert!(
        FAST_CIRCLE.contains(EXTRAPOLATE),
        "the fixture's policy moved"
    );
    Scenario::parse(&FAST_CIRCLE.replace(EXTRAPOLATE, link_loss), "test", None)
        .unwrap_or_else(|e| panic!("{e}"))
}

fn robot(s: &Scenario, agent: u32, faults: FaultSpec) -> Robot {
    let config = crate::testing::robot_config(s, agent, faults);
    Robot::simulated(config, 100 + agent)
}

fn reference(s: &Scenario) -> Reference {
    s.build(&Overrides::default())
        .unwrap_or_else(|e| panic!("{e}"))
        .plan
        .reference()
        .clone()
}

/// One published state.
#[derive(Debug, Clone, Copy)]
struct Published {
    /// Local (fake clock) time.
    local: f64,
    state: RobotState,
}

/// A leader and robots on one fake clock. The leader's messages reach
/// the robots that follow the reference `latency` later unless the link
/// is `cut`; a robot's states reach its followers at once.
struct World {
    leader: LeaderTask,
    /// Local time at which the leader's clock read 0.
    leader_start: f64,
    robots: Vec<Robot>,
    latency: f64,
    cut: Option<(f64, f64)>,
    now: f64,
    buf: Vec<u8>,
    log: Vec<Vec<Published>>,
}

impl World {
    fn new(s: &Scenario, robots: Vec<Robot>) -> World {
        let n = robots.len();
        World {
            leader: LeaderTask::new(reference(s), 50.0, 1e9, 1),
            leader_start: 0.0,
            robots,
            latency: 0.0,
            cut: None,
            now: 0.0,
            buf: Vec::new(),
            log: vec![Vec::new(); n],
        }
    }

    /// Agents 1, 2, … of `s`, agent `k` with faults `faults[k - 1]`.
    fn of(s: &Scenario, faults: &[FaultSpec]) -> World {
        let robots = (1..).zip(faults).map(|(k, f)| robot(s, k, *f)).collect();
        World::new(s, robots)
    }

    /// Runs until local time `end`.
    fn run_until(&mut self, end: f64) {
        loop {
            let leader_due = self
                .leader
                .next_due()
                .map_or(f64::INFINITY, |t| t + self.leader_start);
            let mut t = self
                .robots
                .iter()
                .map(Robot::next_wake)
                .fold(leader_due, f64::min)
                .max(self.now);
            if t > end {
                self.now = end;
                return;
            }
            let due = leader_due <= t || self.robots.iter().any(|r| r.is_due(t));
            if !due {
                // next_wake − offset + offset rounded below the tick time.
                t += 1e-12 * t.abs().max(1.0);
            }
            self.now = t;
            // The leader's own time, not below its due time (rounding).
            let leader_now = self.leader.next_due().map(|d| d.max(t - self.leader_start));
            if leader_due <= t
                && let Some((h, r)) = leader_now.and_then(|lt| self.leader.tick(lt))
            {
                let up = self.cut.is_none_or(|(a, b)| t < a || t >= b);
                wire::encode_reference(&mut self.buf, h, &r);
                for robot in &mut self.robots {
                    if up && robot.config().spec.leader == Leader::Reference {
                        robot.on_message(&self.buf, t + self.latency);
                    }
                }
            }
            for i in 0..self.robots.len() {
                if !self.robots[i].is_due(t) {
                    continue;
                }
                let out = self.robots[i].tick(t);
                if let Some((h, state)) = out.publish {
                    self.log[i].push(Published { local: t, state });
                    wire::encode_state(&mut self.buf, h, &state);
                    for follower in &mut self.robots {
                        if follower.config().spec.leader == Leader::Agent(i) {
                            follower.on_message(&self.buf, t);
                        }
                    }
                }
            }
        }
    }

    /// Agent `i`'s (from 0) states published with fleet time in `[a, b)`.
    fn states(&self, i: usize, a: f64, b: f64) -> Vec<RobotState> {
        self.log[i]
            .iter()
            .map(|p| p.state)
            .filter(|s| s.t >= a && s.t < b)
            .collect()
    }
}

fn norm(v: [f64; 2]) -> f64 {
    v[0].hypot(v[1])
}

fn dist(a: &State, b: &State) -> f64 {
    (a.x - b.x).hypot(a.y - b.y)
}

/// Every message received is counted in exactly one outcome.
fn conserved(r: &Robot) {
    let c = r.counters();
    assert_eq!(
        c.received,
        c.accepted
            + c.malformed
            + c.wrong_version
            + c.foreign
            + c.injected_loss
            + c.injected_outage
            + c.stale
            + c.reordered
            + r.pending() as u64,
        "{c:?}"
    );
}

/// The divergence guard: with a gain of 1e12 the plant's state leaves
/// its bounds within a tick; the robot commands zero, stops for good and
/// says which agent, when and what.
#[test]
fn a_diverging_robot_stops_at_zero_and_says_why() {
    let src = FAST_CIRCLE.replace("[sim]", "[control]\nke = 1e12\n\n[sim]");
    let s = Scenario::parse(&src, "test", None).unwrap_or_else(|e| panic!("{e}"));
    let mut w = World::of(&s, &[FaultSpec::default()]);
    w.run_until(2.0);
    let r = &w.robots[0];
    let why = r.diverged().unwrap_or_else(|| panic!("{:?}", r.report()));
    assert!(why.starts_with("agent 1 diverged at t = "), "{why}");
    assert!(
        why.contains("left its bound") || why.contains("not finite"),
        "{why}"
    );
    // Stopped: due never again, zero commanded, nothing published after.
    let SimulatedDrive::Torque(p) = r.plant() else {
        panic!("a torque robot")
    };
    assert_eq!(p.applied_input(), Input::default());
    let last = w.log[0].last().map_or(0.0, |p| p.local);
    w.run_until(3.0);
    assert_eq!(w.log[0].last().map_or(0.0, |p| p.local), last);
}

/// `[sim] bounds` reaches the fleet robot: a bound of 0.05 m/s stops a
/// robot that follows a 0.2 m/s circle, naming `|v|`.
#[test]
fn the_scenarios_bounds_stop_the_fleet_robot() {
    let src = FAST_CIRCLE.replace("[sim]\n", "[sim]\nbounds = { speed = 0.05 }\n");
    let s = Scenario::parse(&src, "test", None).unwrap_or_else(|e| panic!("{e}"));
    let r = robot(&s, 1, FaultSpec::default());
    assert_eq!(r.config().bounds.speed, 0.05);
    let mut w = World::new(&s, vec![r]);
    w.run_until(10.0);
    let why = w.robots[0]
        .diverged()
        .unwrap_or_else(|| panic!("never stopped"));
    assert!(
        why.contains("|v| = ") && why.contains("left its bound 0.05 m/s"),
        "{why}"
    );
}

#[test]
fn a_perfect_link_converges_and_the_chain_follows() {
    let s = scenario(EXTRAPOLATE);
    let mut w = World::of(&s, &[FaultSpec::default(); 2]);
    w.run_until(30.0);
    for (i, r) in w.robots.iter().enumerate() {
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
    let mut w = World::of(&s, &[FaultSpec::default(); 2]);
    w.run_until(30.0);
    let mut sim = s
        .build(&Overrides::default())
        .unwrap_or_else(|e| panic!("{e}"))
        .simulation();
    sim.run(&mut |_: &echelon::sim::Frame<'_>| Ok(()))
        .unwrap_or_else(|e| panic!("{e}"));
    for (i, r) in w.robots.iter().enumerate() {
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
    let mut w = World::of(&s, &[faults, FaultSpec::default()]);
    w.run_until(12.0);
    let before = w.robots[0].last().e;
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
    let c = *w.robots[0].counters();
    assert_eq!(c.link_losses, 1, "{c:?}");
    assert!(
        c.injected_outage >= 149 && c.injected_outage <= 151,
        "{c:?}"
    );
    for r in &w.robots {
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
    let mut w = World::of(&s, &[FaultSpec::default()]);
    w.cut = Some((12.0, 15.0));
    w.run_until(20.0);
    let spec = w.robots[0].config().spec.clone();
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
    assert_eq!(w.robots[0].counters().link_losses, 1);
    assert!(w.robots[0].last().link == LinkStatus::Tracking);
    assert!(norm(w.robots[0].last().e) < 1e-3);
}

/// `extrapolate`, hold 1 s, decel 0.2 m/s²: past the hold the leader motion
/// slows to rest on the circle (`T = π V / 2a`) at `V (hold + T/2)` along
/// it, and the robot comes to rest behind that point.
#[test]
fn extrapolate_past_the_hold_stops_on_the_circle() {
    let s = scenario(r#"{ policy = "extrapolate", hold = 1.0, decel = 0.2 }"#);
    let reference = reference(&s);
    let mut w = World::of(&s, &[FaultSpec::default()]);
    w.cut = Some((12.0, 40.0));
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
    let faults = FaultSpec {
        delay: 0.05,
        ..FaultSpec::default()
    };
    let mut w = World::of(&s, &[faults]);
    w.run_until(10.0);
    assert!(w.robots[0].last().t > 9.9);
    // The new leader process: another source, its clock from 0.
    w.leader = LeaderTask::new(reference(&s), 50.0, 1e9, 2);
    w.leader_start = 10.001;
    w.run_until(10.3);
    let after: Vec<Published> = w.log[0]
        .iter()
        .copied()
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
    let c = *w.robots[0].counters();
    assert_eq!(c.restarts, 1, "{c:?}");
    // The old leader's messages still delayed at the restart (50 ms of
    // them) were refused as stale.
    assert!((2..=3).contains(&c.stale), "{c:?}");
    assert!(w.robots[0].is_synced());
    conserved(&w.robots[0]);
}

fn reference_message(buf: &mut Vec<u8>, seq: u64, t: f64, reference: &Reference) {
    let jet = reference.eval(t, Order::Two);
    let r = wire::Reference {
        t,
        motion: LeaderMotion::of_jet(&jet),
        speed: jet.speed(),
        turn_rate: jet.turn_rate(),
    };
    wire::encode_reference(buf, Header { source: 5, seq }, &r);
}

/// Every message taken in has its delay recorded (garbage too: the
/// delay is the transport's), unstamped ones counted apart, and the
/// report's latency counts add up to `counters.received`.
#[test]
fn every_received_message_has_its_delay_recorded() {
    let s = scenario(EXTRAPOLATE);
    let reference = reference(&s);
    let mut r = robot(&s, 1, FaultSpec::default());
    let mut buf = Vec::new();
    for (k, delay) in [Some(200_000), Some(400_000), None, Some(-3)]
        .into_iter()
        .enumerate()
    {
        reference_message(&mut buf, k as u64, 0.02 * k as f64, &reference);
        r.on_stamped_message(&buf, 0.02 * k as f64, delay);
    }
    r.on_stamped_message(&[0xEC], 0.1, Some(1_000_000));
    let rep = r.report();
    assert_eq!(rep.counters.received, 5);
    let l = &rep.latency;
    assert_eq!((l.count, l.unstamped, l.early), (4, 1, 1));
    assert_eq!(l.count + l.unstamped, rep.counters.received);
    assert!((l.max - 1e-3).abs() < 1e-15);
    assert!((l.p50 - 2e-4).abs() <= 2e-4 * crate::latency::RELATIVE_ERROR);
    assert_eq!(l.buckets.iter().map(|b| b.1).sum::<u64>(), 4);
}

/// Out-of-order, duplicate, stale (old or from the future) and garbage
/// messages are counted and refused; the law keeps the newest accepted
/// sample, advanced by its age.
#[test]
fn stale_reordered_and_garbage_messages_are_counted_and_refused() {
    let s = scenario(EXTRAPOLATE);
    let reference = reference(&s);
    let mut r = robot(&s, 1, FaultSpec::default());
    let mut buf = Vec::new();
    reference_message(&mut buf, 0, 0.0, &reference);
    r.on_message(&buf, 0.0);
    assert!(r.is_due(0.0));
    assert_eq!(
        r.tick(0.0).publish.map(|p| p.1.link),
        Some(LinkStatus::Tracking)
    );
    reference_message(&mut buf, 5, 0.1, &reference);
    r.on_message(&buf, 0.1);
    reference_message(&mut buf, 3, 0.06, &reference); // reordered
    r.on_message(&buf, 0.101);
    reference_message(&mut buf, 5, 0.1, &reference); // duplicate
    r.on_message(&buf, 0.102);
    reference_message(&mut buf, 6, -1.5, &reference); // stale: 1.6 s old
    r.on_message(&buf, 0.103);
    reference_message(&mut buf, 7, 2.0, &reference); // stale: from the future
    r.on_message(&buf, 0.104);
    r.on_message(&[0xEC, 1, 1], 0.105); // malformed
    let mut wrong = buf.clone();
    wrong[1] = 9;
    r.on_message(&wrong, 0.106); // wrong version
    let mut state = Vec::new();
    wire::encode_state(
        &mut state,
        Header { source: 9, seq: 0 },
        &RobotState {
            agent: 2,
            link: LinkStatus::Tracking,
            ..RobotState::default()
        },
    );
    r.on_message(&state, 0.107); // a state on the reference key: foreign
    let out = r.tick(0.13);
    let c = *r.counters();
    assert_eq!(
        (
            c.received,
            c.accepted,
            c.reordered,
            c.stale,
            c.malformed,
            c.wrong_version,
            c.foreign
        ),
        (9, 2, 2, 2, 1, 1, 1),
        "{c:?}"
    );
    conserved(&r);
    // The sample of seq 5 (t = 0.1), advanced by 0.03 s.
    let jet = reference.eval(0.1, Order::Two);
    let sample = LeaderSample {
        t: 0.1,
        motion: LeaderMotion::of_jet(&jet),
        speed: jet.speed(),
        turn_rate: jet.turn_rate(),
    };
    let want = predict(&sample, 0.13, 0.5, &r.config().loss);
    let (_, st) = out.publish.unwrap_or_else(|| panic!("published"));
    assert_eq!(st.leader, want.motion);
    assert_eq!(st.link, LinkStatus::Tracking);
}

/// `--loss 0.2`: about a fifth of the messages are dropped, the same ones
/// for the same seed (the same run, bit for bit), and the formation still
/// converges.
#[test]
fn injected_loss_is_seeded_and_the_formation_still_converges() {
    let s = scenario(EXTRAPOLATE);
    let faults = FaultSpec {
        loss: 0.2,
        seed: 7,
        ..FaultSpec::default()
    };
    let run = || {
        let mut w = World::of(&s, &[faults; 2]);
        w.run_until(30.0);
        w.robots.iter().map(Robot::report).collect::<Vec<_>>()
    };
    let (a, b) = (run(), run());
    for (ra, rb) in a.iter().zip(&b) {
        assert_eq!(ra.final_state, rb.final_state);
        assert_eq!(ra.counters, rb.counters);
        let c = ra.counters;
        let rate = c.injected_loss as f64 / c.received as f64;
        // Binomial(~1500 or ~3000, 0.2): σ ≤ 0.011; 3σ.
        assert!((rate - 0.2).abs() < 0.033, "{rate} {c:?}");
        assert_eq!(c.accepted + c.injected_loss, c.received, "{c:?}");
        assert!(ra.final_error < 1e-3, "{ra:?}");
    }
}

/// `--delay 50 ms`: a sample is used only once delivered, 50 ms after it
/// arrived; the robot waits until the first one and then converges on
/// samples advanced by their age.
#[test]
fn injected_delay_holds_samples_back() {
    let s = scenario(EXTRAPOLATE);
    let faults = FaultSpec {
        delay: 0.05,
        ..FaultSpec::default()
    };
    let mut w = World::of(&s, &[faults]);
    w.run_until(0.2);
    let first = w.log[0]
        .iter()
        .find(|p| p.state.link == LinkStatus::Tracking)
        .unwrap_or_else(|| panic!("never tracked"));
    // Synced at 0 on the first arrival; waiting ticks come every 0.1 s,
    // so the first sample (delivered at 0.05) is first used at 0.1.
    assert!((first.state.t - 0.1).abs() < 1e-9, "{first:?}");
    let waiting = w.log[0]
        .iter()
        .take_while(|p| p.state.link == LinkStatus::Waiting)
        .count();
    assert_eq!(waiting, 1);
    // Messages of the last 50 ms are in flight.
    assert!(
        (2..=3).contains(&w.robots[0].pending()),
        "{}",
        w.robots[0].pending()
    );
    w.run_until(30.0);
    let r = &w.robots[0];
    assert!(r.report().final_error < 1e-3, "{:?}", r.report());
    assert_eq!(r.counters().link_losses, 0);
    conserved(r);
}

/// A chained follower whose leader robot stops publishing (its process
/// died): the follower loses its link and, under `stop`, comes to rest
/// behind the last state it heard.
#[test]
fn a_follower_whose_leader_robot_goes_silent_stops() {
    let s = scenario(STOP);
    let mut w = World::of(&s, &[FaultSpec::default(); 2]);
    w.run_until(12.0);
    // Robot 1's process dies: drop it, robot 2 stays (now index 0).
    let mut follower = w.robots.remove(1);
    assert!(follower.report().final_error < 5e-3);
    let mut t = w.now;
    let mut last = *follower.last();
    while t < 16.0 {
        t = follower.next_wake();
        if !follower.is_due(t) {
            t += 1e-9;
        }
        if let Some((_, st)) = follower.tick(t).publish {
            last = st;
            if st.t > 12.0 + 0.5 + 0.011 {
                assert_eq!(st.link, LinkStatus::Stopping, "{st:?}");
                assert_eq!(st.leader.dp, [0.0, 0.0]);
            }
        }
    }
    assert!(last.state.v.abs() < 0.02 && norm(last.e) < 0.02, "{last:?}");
    assert_eq!(follower.counters().link_losses, 1);
}

/// A plant whose odometry can fail, recording what it is commanded.
#[derive(Debug)]
struct Flaky {
    inner: SimulatedPlant,
    lost: bool,
    commanded: Input,
}

fn torque(cmd: Command) -> Input {
    match cmd {
        Command::Torque(u) => u,
        Command::Velocity(_) => panic!("a torque-driven robot got a velocity command"),
    }
}

impl Plant for Flaky {
    fn state(&self) -> Option<State> {
        (!self.lost).then(|| self.inner.true_state())
    }
    fn advance(&mut self, t: f64) {
        self.inner.advance(t);
    }
    fn command(&mut self, cmd: Command) -> crate::plant::Actuation {
        self.commanded = torque(cmd);
        self.inner.command(cmd)
    }
    fn stop(&mut self) {
        self.commanded = Input::default();
        self.inner.stop();
    }
    fn accelerations(&self) -> (f64, f64) {
        self.inner.accelerations()
    }
    fn set_time(&mut self, t: f64) {
        self.inner.set_time(t);
    }
}

/// Odometry lost, or the process stopping: the drive is commanded zero
/// and nothing is published for a state it does not have.
#[test]
fn losing_the_odometry_or_the_process_commands_zero() {
    let s = scenario(EXTRAPOLATE);
    let config = crate::testing::robot_config(&s, 1, FaultSpec::default());
    let plant = Flaky {
        inner: SimulatedPlant::new(
            *config.spec.torque_robot().unwrap(),
            config.spec.start,
            0.0,
            PLANT_STEP,
        ),
        lost: false,
        commanded: Input::default(),
    };
    let mut r = Robot::new(config, plant, 1);
    let reference = reference(&s);
    let mut buf = Vec::new();
    reference_message(&mut buf, 0, 0.0, &reference);
    r.on_message(&buf, 0.0);
    assert!(r.tick(0.0).publish.is_some());
    assert_ne!(r.plant().commanded, Input::default());
    r.plant_mut().lost = true;
    let out = r.tick(0.01);
    assert!(out.publish.is_none());
    assert_eq!(r.plant().commanded, Input::default());
    r.plant_mut().lost = false;
    assert!(r.tick(0.02).publish.is_some());
    assert_ne!(r.plant().commanded, Input::default());
    let stats = r.finish();
    assert_eq!(r.plant().commanded, Input::default());
    assert_eq!((stats.published, stats.counters.accepted), (2, 1));
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
    let mut leader = LeaderTask::new(reference(&s), 50.0, 1e9, 1);
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

/// Robot 1 on a [`Flaky`] plant (never lost) behind the reference.
fn commanded_robot(s: &Scenario) -> Robot<Flaky> {
    let config = crate::testing::robot_config(s, 1, FaultSpec::default());
    let plant = Flaky {
        inner: SimulatedPlant::new(
            *config.spec.torque_robot().unwrap(),
            config.spec.start,
            0.0,
            PLANT_STEP,
        ),
        lost: false,
        commanded: Input::default(),
    };
    Robot::new(config, plant, 1)
}

fn command(order: crate::command::Order, seq: u64) -> Vec<u8> {
    crate::command::FleetCommand::new(order, seq, "operator", "test").encode()
}

/// Drives `r` from local time `from` to `to`: the reference every 20 ms,
/// a tick whenever one is due; the states published and, after each tick,
/// the command its plant holds.
fn drive(
    r: &mut Robot<Flaky>,
    reference: &Reference,
    from: f64,
    to: f64,
) -> Vec<(RobotState, Input)> {
    let mut buf = Vec::new();
    let mut out = Vec::new();
    let mut t = from;
    while t < to {
        let k = (t / 0.02).round();
        if (t - k * 0.02).abs() < 1e-9 {
            reference_message(&mut buf, k as u64, t, reference);
            r.on_message(&buf, t);
        }
        if r.is_due(t)
            && let Some((_, st)) = r.tick(t).publish
        {
            out.push((st, r.plant().commanded));
        }
        t = ((t + 0.005) * 1e6).round() / 1e6;
    }
    out
}

/// A fleet stop commands zero the moment it is handed over (before the
/// next tick), and on every tick after; the states say `stopped`; a
/// resume numbered at or below the stop is ignored, a later one lets the
/// law run again from where the robot is (no jump in its state); garbage
/// on the command key is counted and refused.
#[test]
fn a_fleet_stop_is_obeyed_at_once_and_held_until_a_later_resume() {
    use crate::command::Order;
    let s = scenario(EXTRAPOLATE);
    let reference = reference(&s);
    let mut r = commanded_robot(&s);
    let period = r.config().period;
    let running = drive(&mut r, &reference, 0.0, 5.0);
    assert!(
        running
            .iter()
            .all(|(st, _)| st.link == LinkStatus::Tracking)
    );
    assert_ne!(r.plant().commanded, Input::default());
    assert_eq!(r.on_command(b"garbage"), crate::command::Change::Unchanged);
    assert!(!r.is_stopped());

    let stop_at = r.last().t;
    r.on_command(&command(Order::Stop, 1));
    assert!(r.is_stopped());
    assert_eq!(r.plant().commanded, Input::default(), "zero at once");
    let stopped = drive(&mut r, &reference, 5.0, 7.0);
    // Every control period a state, `stopped`, and zero held.
    assert!(
        stopped.len() as f64 >= 2.0 / period - 2.0,
        "{}",
        stopped.len()
    );
    for (st, cmd) in &stopped {
        assert_eq!(st.link, LinkStatus::Stopped, "{st:?}");
        assert_eq!(*cmd, Input::default());
        assert_eq!(st.u, Input::default());
    }
    assert!(stopped[0].0.t - stop_at <= period + 1e-9);
    r.on_command(&command(Order::Resume, 1));
    assert!(r.is_stopped(), "a resume not after the stop is ignored");
    let before = *r.last();
    r.on_command(&command(Order::Resume, 2));
    assert!(!r.is_stopped());
    let resumed = drive(&mut r, &reference, 7.0, 7.2);
    let (first, cmd) = resumed[0];
    assert_eq!(first.link, LinkStatus::Tracking);
    assert_ne!(cmd, Input::default());
    assert!(dist(&first.state, &before.state) < 0.01, "no jump");
    let c = r.command_counts();
    assert_eq!(
        (c.received, c.stops, c.resumes, c.ignored, c.refused),
        (4, 1, 1, 1, 1)
    );
    assert_eq!(r.report().commands, c);
}

/// A stop learnt from another process's latch answer before the robot
/// heard its leader latches: it stands still (waiting, then `stopped` once
/// its clock follows the leader) until a resume numbered after that stop.
#[test]
fn a_stop_heard_before_start_latches() {
    use crate::command::{FleetCommand, Latched, Order};
    let s = scenario(EXTRAPOLATE);
    let reference = reference(&s);
    let mut r = commanded_robot(&s);
    let answer = Latched {
        stopped: true,
        command: Some(FleetCommand::new(Order::Stop, 4, "operator", "")),
    };
    r.on_latch_answer(&answer.encode());
    assert!(r.is_stopped());
    let stopped = drive(&mut r, &reference, 0.0, 2.0);
    assert!(stopped.len() > 100);
    assert!(
        stopped
            .iter()
            .all(|(st, cmd)| st.link == LinkStatus::Stopped && *cmd == Input::default())
    );
    assert_eq!(r.last().state, r.config().spec.start);
    r.on_command(&command(Order::Resume, 4));
    assert!(r.is_stopped());
    r.on_command(&command(Order::Resume, 5));
    let moving = drive(&mut r, &reference, 2.0, 3.0);
    assert!(moving.iter().all(|(st, _)| st.link == LinkStatus::Tracking));
    assert!(dist(&r.last().state, &r.config().spec.start) > 0.01);
}
