//! The robot's behaviour on a fake clock: a [`crate::leader::Leader`] and robots exchanging encoded messages in one deterministic event loop, no network, no sleeps.

use super::*;
use crate::faults::FaultSpec;
use crate::leader::Leader as LeaderTask;
use crate::link::predict;
use crate::plant::SimulatedPlant;
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
                    if up && robot.config().spec.leader() == Leader::Reference {
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
                        if follower.config().spec.leader() == Leader::Agent(i) {
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

/// Robot 1 on a [`Flaky`] plant (never lost) behind the reference.
fn commanded_robot(s: &Scenario) -> Robot<Flaky> {
    let config = crate::testing::robot_config(s, 1, FaultSpec::default());
    let plant = Flaky {
        inner: SimulatedPlant::new(
            *config.spec.torque_robot().unwrap(),
            config.spec.start(),
            0.0,
            PLANT_STEP,
        ),
        lost: false,
        commanded: Input::default(),
    };
    Robot::new(config, plant, 1)
}

mod command;
mod link;
mod messages;
mod plant;
