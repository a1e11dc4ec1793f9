//! A host on the fake clock: K robots in one [`Host`] do what K robot
//! tasks do alone (every state they publish, their reports), over random
//! formations, chains, safety filters, latencies and link cuts; one
//! robot's failure leaves the others running.

use proptest::prelude::*;

use super::*;
use crate::faults::FaultSpec;
use crate::keys::Keys;
use crate::leader::{Leader, LeaderTask};
use crate::runtime::bus::{Bus, Link, TaskId};
use crate::wire::{self, Message};
use echelon::scenario::Scenario;

/// `n` robots behind a circle, robot `i` at `offsets[i]` behind its leader:
/// the reference, or (`chain[i]`) the robot before it; with `safety`, each
/// filters against the others.
/// Robot `i` starts at `(-0.6 i, 0)`, heading along the circle's start.
fn scenario(offsets: &[(f64, f64)], chain: &[bool], safety: bool) -> Scenario {
    let mut text = crate::testing::tb4_kinematic("hosted", 0.05);
    text += r#"[reference.circle]
speed = 0.15
turn_rate = 0.1
start = { x = 0.0, y = 0.0, theta = 0.0 }
[fleet]
control_rate = 50.0
link_timeout = 0.2
link_loss = { policy = "extrapolate", hold = 1.0, decel = 0.2 }
"#;
    if safety {
        text += "[safety]\nradius = 0.25\ngain = 1.0\nrange = 1.5\n";
    }
    for (i, (x, y)) in offsets.iter().enumerate() {
        let leader = match i > 0 && chain[i] {
            true => i.to_string(),
            false => "\"reference\"".to_owned(),
        };
        text += &format!(
            "[[agents]]\nname = \"r{i}\"\nrobot = \"tb4\"\nstart = {{ x = {}, y = {}, theta = 0.0 }}\nleader = {leader}\noffset = {{ x = {x}, y = {y} }}\n",
            -0.6 * i as f64,
            0.0
        );
    }
    Scenario::parse(&text, "hosted", None).unwrap_or_else(|e| panic!("{e}\n{text}"))
}

/// Robot `k` of `s`, seeded by its number.
fn robot_task(s: &Scenario, k: u32, keys: &Keys) -> RobotTask {
    let config = crate::testing::robot_config(s, k, FaultSpec::default());
    RobotTask::new(Robot::simulated(config, 100 + k), keys.clone())
}

/// A link whose latency and losses depend only on the key and the time
/// (never on the sender, which a host changes): latency 1–5 ms from a hash
/// of both; the reference lost in `[cut, cut + 0.6)`.
fn link(keys: &Keys, seed: u64, cut: f64) -> Link {
    let reference = keys.reference();
    Box::new(move |_, key: &str, t: f64| {
        if key == reference && (cut..cut + 0.6).contains(&t) {
            return None;
        }
        let mut h = seed ^ (t * 1e6) as u64;
        for b in key.bytes() {
            h = (h ^ u64::from(b)).wrapping_mul(0x100_0000_01b3);
        }
        Some(0.001 + 0.004 * ((h >> 11) as f64 / (1u64 << 53) as f64))
    })
}

/// The leader of `s` for `duration` on a bus with `link`.
fn bus_with_leader(s: &Scenario, keys: &Keys, duration: f64, link: Link) -> Bus {
    let reference = crate::testing::reference_of(s);
    let mut bus = Bus::new();
    bus.link = link;
    let leader = LeaderTask::new(Leader::new(reference, 50.0, duration, 1), keys.clone())
        .with_operator_token(Some(crate::testing::operator_token()));
    bus.add(leader, 0.0);
    bus
}

/// Every state robot `k` published (time and payload), by whichever task.
fn states(bus: &Bus, ids: &[TaskId], keys: &Keys, k: u32) -> Vec<(f64, Vec<u8>)> {
    let key = keys.state(k);
    ids.iter()
        .flat_map(|&id| bus.published_by(id, &key))
        .map(|p| (p.t, p.payload.clone()))
        .collect()
}

/// A report with what differs between processes and one host removed:
/// nothing but the CPU time, which is not in the report.
fn comparable(r: &RobotReport) -> serde_json::Value {
    serde_json::to_value(r).unwrap_or_else(|e| panic!("{e}"))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(12))]

    /// The same fleet, K robot tasks alone vs one host of them, on the same
    /// link: every robot publishes the same states at the same times, and
    /// reports the same.
    #[test]
    fn a_host_of_k_robots_is_k_robots(
        offsets in proptest::collection::vec((0.3..0.9f64, -0.6..0.6f64), 2..=6),
        chain in proptest::collection::vec(any::<bool>(), 6),
        safety in any::<bool>(),
        seed in any::<u64>(),
        cut in 1.0..4.0f64,
    ) {
        let n = offsets.len() as u32;
        let s = scenario(&offsets, &chain, safety);
        let keys = Keys::new("hosted");
        let duration = 6.0;
        let mut alone = bus_with_leader(&s, &keys, duration, link(&keys, seed, cut));
        let ids: Vec<TaskId> =
            (1..=n).map(|k| alone.add(robot_task(&s, k, &keys), 0.0)).collect();
        alone.run_until(duration + 0.5);
        let mut hosted = bus_with_leader(&s, &keys, duration, link(&keys, seed, cut));
        let members = (1..=n)
            .map(|k| (format!("robot/{k}"), robot_task(&s, k, &keys)))
            .collect();
        let host = hosted.add(Host::new(members).unwrap_or_else(|e| panic!("{e}")), 0.0);
        hosted.run_until(duration + 0.5);
        for (i, &id) in ids.iter().enumerate() {
            let k = i as u32 + 1;
            let a = states(&alone, &[id], &keys, k);
            let h = states(&hosted, &[host], &keys, k);
            prop_assert!(a.len() > 200, "robot {k} published {}", a.len());
            let first = a.iter().zip(&h).position(|(x, y)| x != y);
            prop_assert!(
                a.len() == h.len() && first.is_none(),
                "robot {k}'s states: {} alone, {} hosted, first differing: {:?}",
                a.len(),
                h.len(),
                first.map(|i| (a[i].0, h[i].0))
            );
            let task: &RobotTask = alone.task(id).unwrap_or_else(|| panic!("a robot"));
            let host_task: &Host<RobotTask> = hosted.task(host).unwrap_or_else(|| panic!("a host"));
            let member = host_task.tasks().nth(i).unwrap_or_else(|| panic!("a member"));
            prop_assert_eq!(
                comparable(&task.robot().report()),
                comparable(&member.robot().report())
            );
            // Decoded, its states are its own.
            for (_, p) in h.iter().take(3) {
                prop_assert!(matches!(wire::decode(p), Ok(Message::State(..))));
            }
        }
    }
}

/// One robot of a host diverges (a gain of 1e12: its state leaves the
/// guard's bounds within a tick): it stops (its report entry says why),
/// the others run to the end and converge.
#[test]
fn a_robot_that_diverges_in_a_host_stops_alone() {
    let third = "[[agents]]\nname = \"robot 3\"\nrobot = \"agent1\"\nstart = { x = -0.8, y = 0.0, theta_deg = 0.0 }\nleader = \"reference\"\noffset = { x = 0.6, y = -0.4 }\n";
    let text = crate::testing::FAST_CIRCLE
        .replace("leader = 1\n", "leader = 1\ncontrol = { ke = 1e12 }\n");
    assert!(text.contains("1e12"), "the fixture's second agent moved");
    let s = Scenario::parse(&(text + third), "test", None).unwrap_or_else(|e| panic!("{e}"));
    let keys = Keys::new("hosted");
    let duration = 20.0;
    let mut bus = bus_with_leader(&s, &keys, duration, Box::new(|_, _, _| Some(0.001)));
    let members = (1..=3)
        .map(|k| (format!("robot/{k}"), robot_task(&s, k, &keys)))
        .collect();
    let host = bus.add(Host::new(members).unwrap_or_else(|e| panic!("{e}")), 0.0);
    bus.run_until(duration / 2.0);
    let h: &Host<RobotTask> = bus.task(host).unwrap_or_else(|| panic!("a host"));
    assert!(bus.is_running(host), "the host runs on");
    assert!(!h.is_running(1), "robot 2 diverged and stopped");
    assert!(h.is_running(0) && h.is_running(2));
    assert_eq!(h.running(), 2);
    // Robot 2 publishes nothing more; the others go on.
    let last = |bus: &Bus, k: u32| states(bus, &[host], &keys, k).last().map_or(0.0, |p| p.0);
    assert!(
        last(&bus, 2) < 2.0,
        "robot 2 still published at {}",
        last(&bus, 2)
    );
    bus.run_until(duration + 0.5);
    assert!(last(&bus, 1) > duration - 0.5 && last(&bus, 3) > duration - 0.5);
    let h: Host<RobotTask> = bus.take(host).unwrap_or_else(|| panic!("a host"));
    let reports = h.report().unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(reports.len(), 3);
    let error = reports[1].error.as_deref().unwrap_or_default();
    assert!(error.contains("agent 2 diverged"), "{error}");
    for r in [&reports[0], &reports[2]] {
        assert_eq!(r.error, None, "{r:?}");
        let rep = r.report.as_ref().unwrap_or_else(|| panic!("a report"));
        assert!(rep.final_error < 0.02, "{}: {rep:?}", r.name);
    }
}

/// A host's inputs are each key once, however many members listen; its
/// outputs and tokens every member's; its latch every member's key.
#[test]
fn a_host_subscribes_once_per_key() {
    let offsets = [(0.4, 0.3), (0.4, -0.3), (0.8, 0.0), (1.2, 0.0)];
    let s = scenario(&offsets, &[false, false, true, true], true);
    let keys = Keys::new("hosted");
    let tasks: Vec<RobotTask> = (1..=4).map(|k| robot_task(&s, k, &keys)).collect();
    let all: Vec<String> = tasks.iter().flat_map(Task::inputs).collect();
    let members = tasks
        .into_iter()
        .enumerate()
        .map(|(i, t)| (format!("robot/{}", i + 1), t))
        .collect();
    let host = Host::new(members).unwrap_or_else(|e| panic!("{e}"));
    let inputs = host.inputs();
    let mut distinct = all.clone();
    distinct.sort();
    distinct.dedup();
    assert_eq!(inputs.len(), distinct.len(), "{inputs:?}");
    assert!(distinct.iter().all(|k| inputs.contains(k)));
    assert!(inputs.len() < all.len());
    assert_eq!(
        host.outputs(),
        (1..=4)
            .flat_map(|k| [keys.state(k), keys.stats(k)])
            .collect::<Vec<_>>()
    );
    assert_eq!(host.tokens().len(), 4);
    let latching = host.latching().unwrap_or_else(|| panic!("a latch"));
    assert_eq!(latching.answer_on.len(), 4);
    assert!((0..4).all(|i| host.latched(i).is_some()));
    assert!(host.latched(4).is_none());
}

/// Members of two fleets cannot share a host; nor can nobody.
#[test]
fn a_host_refuses_members_of_two_fleets() {
    let s = scenario(&[(0.4, 0.3), (0.4, -0.3)], &[false, false], false);
    let a = robot_task(&s, 1, &Keys::new("one"));
    let b = robot_task(&s, 2, &Keys::new("two"));
    let e = Host::new(vec![("robot/1".into(), a), ("robot/2".into(), b)])
        .err()
        .unwrap_or_else(|| panic!("refused"));
    assert!(e.to_string().contains("one fleet"), "{e}");
    assert!(Host::<RobotTask>::new(Vec::new()).is_err());
}
