//! The robot's behaviour on a fake clock: the leader and robots as the
//! runtime's tasks on its in-memory bus ([`crate::runtime::bus::Bus`]),
//! exchanging encoded messages in one deterministic event loop, no network,
//! no sleeps; or one robot fed by hand.

use super::*;
use crate::faults::FaultSpec;
use crate::keys::Keys;
use crate::leader::{Leader as ReferenceLeader, LeaderTask};
use crate::link::predict;
use crate::plant::SimulatedDrive;
use crate::runtime::bus::{Bus, TaskId};
use echelon::agent::Command;
use echelon::follow::{LeaderView, follow};
use echelon::model::Input;
use echelon::model::State;
use echelon::reference::{Order, Reference, Trajectory};
use echelon::scenario::{Overrides, Scenario};

/// The CLI's process-test fleet (`echelon-cli/tests/fleet/fast-circle.toml`),
/// whose link-loss policy is [`EXTRAPOLATE`].
const FAST_CIRCLE: &str = include_str!("../../../../echelon-cli/tests/fleet/fast-circle.toml");

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

/// Faults: every leader sample held back `delay` s.
fn delayed(delay: f64) -> FaultSpec {
    FaultSpec {
        delay,
        ..FaultSpec::default()
    }
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

/// A leader and robots as the tasks the fleet runtime runs, on its
/// in-memory [`Bus`] (one fake clock, every task started at 0): the
/// leader's messages reach the robots that follow the reference unless
/// the link is [cut](Fleet::cut); a robot's states reach its followers at
/// once.
struct Fleet {
    bus: Bus,
    keys: Keys,
    leader: TaskId,
    /// Agent `i + 1`'s task.
    robots: Vec<TaskId>,
}

impl Fleet {
    fn new(s: &Scenario, robots: Vec<Robot>) -> Fleet {
        let keys = Keys::new("test");
        let mut bus = Bus::new();
        let leader = bus.add(leader_task(s, 1, &keys), 0.0);
        let robots = robots
            .into_iter()
            .map(|r| bus.add(RobotTask::new(r, keys.clone()), 0.0))
            .collect();
        Fleet {
            bus,
            keys,
            leader,
            robots,
        }
    }

    /// Agents 1, 2, … of `s`, agent `k` with faults `faults[k - 1]`.
    fn of(s: &Scenario, faults: &[FaultSpec]) -> Fleet {
        let robots = (1..).zip(faults).map(|(k, f)| robot(s, k, *f)).collect();
        Fleet::new(s, robots)
    }

    /// Drops the leader's messages sent in `[a, b)` (bus time).
    fn cut(&mut self, a: f64, b: f64) {
        let (leader, key) = (self.leader, self.keys.reference());
        self.bus.link = Box::new(move |from, k, t| {
            (from != leader || k != key || !(a..b).contains(&t)).then_some(0.0)
        });
    }

    /// A new leader process (`source`), its clock reading 0 at bus time
    /// `start`, in place of the old one.
    fn restart_leader(&mut self, s: &Scenario, source: u32, start: f64) {
        let task = leader_task(s, source, &self.keys);
        self.bus.replace(self.leader, task, start);
    }

    /// Runs until bus time `end`.
    fn run_until(&mut self, end: f64) {
        self.bus.run_until(end);
    }

    /// Agent `i + 1`'s robot.
    fn robot(&self, i: usize) -> &Robot {
        self.bus
            .task::<RobotTask>(self.robots[i])
            .unwrap_or_else(|| panic!("agent {} is not on the bus", i + 1))
            .robot()
    }

    /// Every robot, agent 1 first.
    fn robots(&self) -> impl Iterator<Item = &Robot> {
        (0..self.robots.len()).map(|i| self.robot(i))
    }

    /// Runs to bus time `end` in 10 ms steps: the smallest distance two
    /// robots' points `l` ahead came at those instants, m.
    fn closest_until(&mut self, end: f64, l: f64) -> f64 {
        let mut closest = f64::INFINITY;
        let mut t = self.bus.now();
        while t < end {
            t += 0.01;
            self.run_until(t);
            closest = closest.min(self.closest(l));
        }
        closest
    }

    /// The smallest distance between two robots' points `l` ahead, from
    /// their true states now, m.
    fn closest(&self, l: f64) -> f64 {
        let points: Vec<[f64; 2]> = self
            .robots()
            .map(|r| {
                let s = r.plant().true_state();
                [s.x + l * s.theta.cos(), s.y + l * s.theta.sin()]
            })
            .collect();
        let mut closest = f64::INFINITY;
        for (i, a) in points.iter().enumerate() {
            for b in &points[i + 1..] {
                closest = closest.min((a[0] - b[0]).hypot(a[1] - b[1]));
            }
        }
        closest
    }

    /// Agent `i + 1`'s states, in the order it published them.
    fn log(&self, i: usize) -> Vec<Published> {
        let key = self.keys.state(i as u32 + 1);
        self.bus
            .published_by(self.robots[i], &key)
            .map(|p| match wire::decode(&p.payload) {
                Ok(Message::State(_, state)) => Published { local: p.t, state },
                other => panic!("not a state: {other:?}"),
            })
            .collect()
    }

    /// Agent `i + 1`'s states published with fleet time in `[a, b)`.
    fn states(&self, i: usize, a: f64, b: f64) -> Vec<RobotState> {
        self.log(i)
            .into_iter()
            .map(|p| p.state)
            .filter(|s| s.t >= a && s.t < b)
            .collect()
    }
}

/// `s`'s reference published at 50 Hz (for ever) under `source`.
fn leader_task(s: &Scenario, source: u32, keys: &Keys) -> LeaderTask {
    LeaderTask::new(
        ReferenceLeader::new(reference(s), 50.0, 1e9, source),
        keys.clone(),
    )
    .with_operator_token(Some(crate::testing::operator_token()))
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

/// A plant whose odometry can fail, recording what it is commanded.
#[derive(Debug)]
struct Flaky {
    inner: SimulatedDrive,
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

/// Robot 1 on a [`Flaky`] plant (never lost) behind the reference.
fn commanded_robot(s: &Scenario) -> Robot<Flaky> {
    let config = crate::testing::robot_config(s, 1, FaultSpec::default());
    let plant = Flaky {
        inner: SimulatedDrive::of(&config.spec, 0.0, PLANT_STEP),
        lost: false,
        commanded: Input::default(),
    };
    Robot::new(config, plant, 1)
}

mod braking;
mod command;
mod hazard;
mod link;
mod messages;
mod plant;
mod state_rate;
mod stats;
mod swap;
mod watchdog;
