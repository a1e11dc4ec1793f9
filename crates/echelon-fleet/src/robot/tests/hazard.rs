//! A base's hazard stops its robot within one control period and pauses
//! the whole fleet; a resume is refused while the base still reports it,
//! and obeyed once it cleared.

use super::*;
use crate::command::{FleetCommand, Latched, Order};
use crate::ros2::hazard::{Hazard, HazardSet};
use proptest::prelude::*;

/// A simulated robot whose base reports a BUMP during `[from, to)` (fleet
/// time), recording every command it is given with the time it was given.
#[derive(Debug)]
struct Bumped {
    inner: SimulatedDrive,
    window: (f64, f64),
    t: f64,
    /// (fleet time, whether the command was zero).
    commands: Vec<(f64, bool)>,
}

impl Plant for Bumped {
    fn state(&self) -> Option<State> {
        Some(self.inner.true_state())
    }
    fn advance(&mut self, t: f64) {
        self.t = self.t.max(t);
        self.inner.advance(t);
    }
    fn command(&mut self, cmd: Command) -> crate::plant::Actuation {
        let zero = torque(cmd) == Input::default();
        self.commands.push((self.t, zero));
        self.inner.command(cmd)
    }
    fn stop(&mut self) {
        self.commands.push((self.t, true));
        self.inner.stop();
    }
    fn accelerations(&self) -> (f64, f64) {
        self.inner.accelerations()
    }
    fn set_time(&mut self, t: f64) {
        self.t = t;
        self.inner.set_time(t);
    }
    fn hazards(&mut self, t: f64) -> HazardSet {
        let (a, b) = self.window;
        match (a..b).contains(&t) {
            true => HazardSet::EMPTY.with(Hazard::Bump),
            false => HazardSet::EMPTY,
        }
    }
}

fn bumped(s: &Scenario, agent: u32, window: (f64, f64)) -> Robot<Bumped> {
    let config = crate::testing::robot_config(s, agent, FaultSpec::default());
    let plant = Bumped {
        inner: SimulatedDrive::of(&config.spec, 0.0, PLANT_STEP),
        window,
        t: 0.0,
        commands: Vec::new(),
    };
    Robot::new(config, plant, 100 + agent)
}

/// States of `id` on `key` published at bus time in `[a, b)`.
fn links(bus: &Bus, id: TaskId, key: &str, a: f64, b: f64) -> Vec<LinkStatus> {
    bus.published_by(id, key)
        .filter(|p| p.t >= a && p.t < b)
        .map(|p| match wire::decode(&p.payload) {
            Ok(Message::State(_, s)) => s.link,
            other => panic!("not a state: {other:?}"),
        })
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    /// Robot `k` of the fast circle's chain is bumped at a random time for
    /// a random while; an operator tries to resume during the bump and
    /// again after it cleared.
    #[test]
    fn a_bump_stops_the_robot_within_a_period_and_pauses_the_fleet(
        k in 1u32..=2,
        onset in 1.0f64..8.0,
        length in 0.05f64..3.0,
    ) {
        let s = scenario(EXTRAPOLATE);
        let keys = Keys::new("test");
        let mut bus = Bus::new();
        bus.add(leader_task(&s, 1, &keys), 0.0);
        let clear = onset + length;
        let mut ids = [0; 2];
        for agent in 1..=2u32 {
            ids[agent as usize - 1] = if agent == k {
                bus.add(RobotTask::new(bumped(&s, agent, (onset, clear)), keys.clone()), 0.0)
            } else {
                bus.add(RobotTask::new(robot(&s, agent, FaultSpec::default()), keys.clone()), 0.0)
            };
        }
        let me = ids[k as usize - 1];
        let period = 0.01;
        // The first tick at or after the onset commands zero; the fleet
        // pauses when the stop is delivered (at once on the bus).
        bus.run_until(onset + length / 2.0);
        let resume_during = crate::testing::resume(100, "operator", "try");
        bus.put(&keys.command(), &resume_during.encode());
        let answer = bus.latched(me).and_then(|b| Latched::decode(&b));
        prop_assert!(answer.as_ref().is_some_and(|a| a.stopped && a.hazards.names() == "BUMP"), "{answer:?}");
        let answers = vec![(keys.latch(&Member::Robot(k).liveliness()), bus.latched(me).unwrap_or_default())];
        let why = crate::operator::hazards_in_force(&keys, &answers).unwrap_or_default();
        prop_assert_eq!(why, format!("robot/{k} reports BUMP"));
        bus.run_until(clear + 1.0);
        let resume_after = crate::testing::resume(1000, "operator", "clear");
        bus.put(&keys.command(), &resume_after.encode());
        let resumed_at = bus.now();
        bus.run_until(resumed_at + 1.0);

        let task: &RobotTask<Bumped> = bus.task(me).unwrap_or_else(|| panic!("the bumped robot"));
        // Zero from the first tick at the onset until the resume after it cleared.
        let cmds = &task.robot().plant().commands;
        let first = cmds.iter().position(|&(t, _)| t >= onset).unwrap_or(cmds.len());
        prop_assert!(cmds.get(first).is_some_and(|&(t, _)| t < onset + period + 1e-9), "{:?}", cmds.get(first));
        for &(t, zero) in &cmds[first..] {
            if t < resumed_at {
                prop_assert!(zero, "a non-zero command at {t} (bump {onset}..{clear})");
            }
        }
        prop_assert!(cmds.iter().any(|&(t, zero)| t > resumed_at + 0.5 && !zero), "it moves again after the resume");
        // It put a fleet stop naming the robot and the hazard on its halt
        // key, then one refusing the resume.
        let stops: Vec<FleetCommand> = bus
            .published_by(me, &keys.halt(k))
            .filter_map(|p| FleetCommand::decode(&p.payload).ok())
            .collect();
        prop_assert_eq!(stops.len(), 2, "{:?}", stops);
        let by = format!("robot-{k}");
        prop_assert!(stops.iter().all(|c| c.order == Order::Stop && c.by == by && c.reason.contains("BUMP")), "{:?}", stops);
        prop_assert!(stops[1].seq > resume_during.seq);
        let counts = task.robot().command_counts();
        prop_assert_eq!((counts.refused_resumes, counts.resumes), (1, 2));
        // Every robot publishes `stopped` from one period after the onset
        // until the resume after the clearing (the refused resume lasted
        // at most one of the other robot's periods).
        for (i, &id) in ids.iter().enumerate() {
            let key = keys.state(i as u32 + 1);
            let during = links(&bus, id, &key, onset + 2.0 * period, resumed_at);
            prop_assert!(during.len() > 4);
            let moving = during.iter().filter(|l| **l != LinkStatus::Stopped).count();
            prop_assert!(moving <= usize::from(id != me), "agent {}: {moving} states not stopped", i + 1);
            let after = links(&bus, id, &key, resumed_at + 2.0 * period, resumed_at + 1.0);
            prop_assert!(after.iter().all(|l| *l != LinkStatus::Stopped), "agent {} resumed", i + 1);
        }
    }
}
