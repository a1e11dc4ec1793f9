//! [`Robot`] as a [`Task`] of the fleet runtime: its leader stream (and,
//! with a safety filter, every robot's state), its plant's inputs and the
//! fleet command in, its state and counters out; its latch answered on
//! `latch/robot/<k>`.

use echelon::formation::Leader;

use crate::FleetError;
use crate::keys::{KeyKind, Keys};
use crate::plant::{Plant, SimulatedDrive};
use crate::role::Member;
use crate::runtime::{Flow, Latching, Outputs, Sample, Task};
use crate::wire::{self, DecodeError, Message};

use super::{Robot, RobotReport, RobotStats};

/// The input number of the leader stream (then every robot's state, with a
/// safety filter, then the plant's inputs, if any, then the robots' halts,
/// the fleet command and, in a supervised run, the operator heartbeat; the
/// latch answers after them).
const LEADER: usize = 0;
/// The output number of its state.
const STATE: usize = 0;
/// The output number of its counters (`robot/<k>/stats`).
const STATS_OUTPUT: usize = 1;

/// What a plant does with a sample of its own inputs (the input's number
/// among them, key, bytes, fleet time).
pub type PlantFeed<P> = fn(&mut P, usize, &str, &[u8], f64);

/// A robot on the fleet runtime. What arrives waits for its next tick (in
/// order: the leader stream, the neighbours, the plant's input), as its
/// Zenoh driver has always handed it over.
#[derive(Debug)]
pub struct RobotTask<P: Plant = SimulatedDrive> {
    robot: Robot<P>,
    keys: Keys,
    leader: Vec<(f64, Option<i64>, Vec<u8>)>,
    /// The leader samples' buffers, taken back after each tick (no
    /// allocation per sample once warm).
    spare: Vec<Vec<u8>>,
    neighbours: Vec<(f64, Result<Message, DecodeError>)>,
    plant_inputs: Option<(Vec<String>, PlantFeed<P>)>,
    plant: Vec<(f64, usize, String, Vec<u8>)>,
    buf: Vec<u8>,
    failed: bool,
    /// Samples dropped before it took them (the runtime's count).
    dropped: u64,
    /// `--die-at`: the process kills itself at this fleet time.
    die_at: Option<f64>,
    /// Whether it has ticked (it says what it lacks at its first tick).
    started: bool,
    /// Whether its `--wall-clock-jump` happened.
    jumped: bool,
    /// Its process's CPU use, read into each stats message.
    cpu: crate::cost::CpuMeter,
}

impl<P: Plant> RobotTask<P> {
    /// `robot` in the fleet of `keys`.
    pub fn new(robot: Robot<P>, keys: Keys) -> Self {
        RobotTask {
            robot,
            keys,
            leader: Vec::new(),
            spare: Vec::new(),
            neighbours: Vec::new(),
            plant_inputs: None,
            plant: Vec::new(),
            buf: Vec::with_capacity(wire::STATE_LEN),
            failed: false,
            dropped: 0,
            die_at: None,
            started: false,
            jumped: false,
            cpu: crate::cost::CpuMeter::new(),
        }
    }

    /// The same, its process killing itself with SIGKILL at fleet time
    /// `die_at` (`--die-at`, the fault matrix's `kill -9`).
    pub fn dying_at(self, die_at: Option<f64>) -> Self {
        RobotTask { die_at, ..self }
    }

    /// The same, its plant also reading `keys` (e.g. a ROS 2 base's
    /// odometry and fixes) through `feed`.
    pub fn with_plant_inputs(self, keys: Vec<String>, feed: PlantFeed<P>) -> Self {
        RobotTask {
            plant_inputs: Some((keys, feed)),
            ..self
        }
    }

    /// The robot.
    pub fn robot(&self) -> &Robot<P> {
        &self.robot
    }

    /// The robot, to change (e.g. a test's fault).
    pub fn robot_mut(&mut self) -> &mut Robot<P> {
        &mut self.robot
    }

    /// The robot, taken out.
    pub fn into_robot(self) -> Robot<P> {
        self.robot
    }

    /// Its key of the leader stream: the reference, or its leader robot's state.
    pub fn leader_key(&self) -> String {
        match self.robot.config().spec.leader() {
            Leader::Reference => self.keys.reference(),
            Leader::Agent(j) => self.keys.state(j as u32 + 1),
        }
    }

    fn agent(&self) -> u32 {
        self.robot.config().agent
    }

    /// The input number of the fleet command (the robots' halts: the one
    /// before; the latch answers: the next).
    fn command_input(&self) -> usize {
        2 + usize::from(self.robot.has_safety())
            + self.plant_inputs.as_ref().map_or(0, |(keys, _)| keys.len())
    }

    /// Whether the scenario asks for the operator heartbeat.
    fn supervised(&self) -> bool {
        self.robot.config().watchdogs.operator_heartbeat.is_some()
    }

    /// Publishes `stats` with its process's CPU use now.
    fn publish_stats(&mut self, out: &mut dyn Outputs, stats: RobotStats) {
        let stats = RobotStats {
            cpu: self.cpu.read(),
            ..stats
        };
        if let Ok(json) = serde_json::to_vec(&stats) {
            // Best effort, as the counters are: a refusal is not the robot's.
            let _ = out.publish(STATS_OUTPUT, &json);
        }
    }
}

impl<P: Plant + 'static> Task for RobotTask<P> {
    type Report = RobotReport;

    fn inputs(&self) -> Vec<String> {
        let mut keys = vec![self.leader_key()];
        if self.robot.has_safety() {
            keys.push(self.keys.states());
        }
        if let Some((plant, _)) = &self.plant_inputs {
            keys.extend(plant.iter().cloned());
        }
        keys.push(self.keys.halts());
        keys.push(self.keys.command());
        if self.supervised() {
            keys.push(self.keys.heartbeat());
        }
        keys
    }

    fn outputs(&self) -> Vec<String> {
        // The counters through a declared publisher too: its route is
        // resolved once, not at every put (Zenoh matches an undeclared
        // key against every resource it knows, hundreds in a host).
        vec![self.keys.state(self.agent()), self.keys.stats(self.agent())]
    }

    fn tokens(&self) -> Vec<String> {
        vec![self.keys.alive(&Member::Robot(self.agent()).liveliness())]
    }

    fn exclusive(&self) -> bool {
        true
    }

    fn latching(&self) -> Option<Latching> {
        Some(Latching {
            answer_on: vec![self.keys.latch(&Member::Robot(self.agent()).liveliness())],
            ask: self.keys.latches(),
        })
    }

    fn latched(&self, _: usize) -> Option<Vec<u8>> {
        Some(self.robot.latched().encode())
    }

    fn latch_changes(&self) -> Option<u64> {
        Some(self.robot.latch_changes())
    }

    fn on_input(&mut self, input: usize, sample: &Sample<'_>) -> Result<(), FleetError> {
        let neighbours = usize::from(self.robot.has_safety());
        let command = self.command_input();
        if input == command {
            // Obeyed at once: a stop commands zero now, not at the next tick.
            let before = self.robot.command_counts();
            let change = self.robot.on_command(sample.payload);
            let (now, after) = (self.robot.latched(), self.robot.command_counts());
            if let Some(note) = crate::command::resume_note(change, &now, before, after) {
                eprintln!("{note}");
            }
        } else if input == command - 1 {
            // Another robot's own stop (its base's hazard), stop-only.
            if let KeyKind::Halt(k) = self.keys.classify(sample.key) {
                self.robot.on_halt(k, sample.payload);
            }
        } else if self.supervised() && input == command + 1 {
            // Taken at once, with its arrival time: the deadman's clock.
            self.robot.on_heartbeat(sample.payload, sample.at);
        } else if input == command + 1 + usize::from(self.supervised()) {
            self.robot.on_latch_answer(sample.payload);
        } else if input == LEADER {
            let mut bytes = self.spare.pop().unwrap_or_default();
            bytes.clear();
            bytes.extend_from_slice(sample.payload);
            self.leader.push((sample.at, sample.delay, bytes));
        } else if input == neighbours {
            self.neighbours
                .push((sample.at, wire::decode(sample.payload)));
        } else {
            self.plant.push((
                sample.at,
                input - neighbours - 1,
                sample.key.to_owned(),
                sample.payload.to_vec(),
            ));
        }
        Ok(())
    }

    fn on_dropped(&mut self, total: u64) {
        self.dropped = total;
    }

    fn next_wake(&self) -> f64 {
        self.robot.next_wake()
    }

    fn tick(&mut self, now: f64, out: &mut dyn Outputs) -> Result<Flow, FleetError> {
        if !self.robot.is_due(now) {
            return Ok(Flow::Continue);
        }
        if self.robot.is_synced() {
            crate::faults::die_if_due(self.die_at, self.robot.fleet_time(now), "fleet robot");
        }
        if let Some((at, step)) = self.robot.config().faults.wall_clock_jump
            && !self.jumped
            // At 0: at its first tick, before any leader sample (a robot
            // whose clock is off before the run, for `fleet doctor`).
            && (at <= 0.0 || (self.robot.is_synced() && self.robot.fleet_time(now) >= at))
        {
            self.jumped = true;
            eprintln!("fleet robot: --wall-clock-jump: the wall clock steps by {step} s");
            crate::jump_wall_clock((step * 1e9) as i64);
        }
        if !self.started {
            self.started = true;
            if self.robot.config().operator_token.is_none() {
                eprintln!(
                    "robot {}: no operator token ({}): it will refuse every resume",
                    self.agent(),
                    crate::token::TOKEN_ENV
                );
            }
        }
        for (at, delay, bytes) in self.leader.drain(..) {
            self.robot.on_stamped_message(&bytes, at, delay);
            self.spare.push(bytes);
        }
        for (at, msg) in self.neighbours.drain(..) {
            self.robot.on_neighbour(msg, at);
        }
        if let Some((_, feed)) = &self.plant_inputs {
            for (at, input, key, bytes) in self.plant.drain(..) {
                let t = self.robot.fleet_time(at);
                feed(self.robot.plant_mut(), input, &key, &bytes, t);
            }
        }
        let tick = self.robot.tick(now);
        if let Some(stop) = self.robot.take_outgoing() {
            // Its base reported a hazard: the whole fleet pauses.
            eprintln!("fleet stop put: {}", stop.reason);
            out.put(&self.keys.halt(self.agent()), &stop.encode());
        }
        // Partitioned (`--partition`): its state and counters do not leave.
        let cut = self.robot.is_synced()
            && self
                .robot
                .config()
                .faults
                .partitioned_at(self.robot.fleet_time(now));
        if let Some((h, state)) = tick.publish.filter(|_| !cut) {
            wire::encode_state(&mut self.buf, h, &state);
            if let Err(e) = out.publish(STATE, &self.buf) {
                self.failed = true;
                return Err(e);
            }
        }
        if let Some(stats) = tick.stats.filter(|_| !cut) {
            self.publish_stats(out, stats);
        }
        Ok(if tick.done {
            Flow::Stop
        } else {
            Flow::Continue
        })
    }

    /// Commands zero ([`Robot::finish`]); says why if it diverged, else
    /// publishes its final counters (unless publishing had failed).
    fn stop(&mut self, out: &mut dyn Outputs) -> Result<(), FleetError> {
        let stats = self.robot.finish();
        if self.failed {
            return Ok(());
        }
        if let Some(why) = self.robot.diverged() {
            return Err(FleetError::Diverged(why.to_owned()));
        }
        self.publish_stats(out, stats);
        Ok(())
    }

    /// The robot's report, with the samples the runtime dropped.
    fn report(self) -> Result<RobotReport, FleetError> {
        Ok(RobotReport {
            dropped: self.dropped,
            ..self.robot.report()
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::faults::FaultSpec;
    use crate::leader::{Leader as Reference, LeaderTask};
    use crate::runtime::bus::Bus;
    use crate::wire::{LinkStatus, RobotState};

    /// Robot `k` of the fast circle's chain, in the fleet of `keys`.
    fn chain_robot(k: u32, keys: &Keys) -> RobotTask {
        let (s, _, _) = crate::testing::fast_circle();
        let config = crate::testing::robot_config(&s, k, FaultSpec::default());
        RobotTask::new(Robot::simulated(config, 100 + k), keys.clone())
    }

    /// The fast circle's leader (publishing for `duration`) and its chain
    /// of two robots on a bus, fleet `lab`: the bus, the keys and the
    /// tasks' ids (leader, robot 1, robot 2).
    fn chain_on_bus(duration: f64) -> (Bus, Keys, [usize; 3]) {
        let (_, _, reference) = crate::testing::fast_circle();
        let keys = Keys::new("lab");
        let mut bus = Bus::new();
        let leader = Reference::new(reference, 50.0, duration, 1);
        let l = bus.add(
            LeaderTask::new(leader, keys.clone())
                .with_operator_token(Some(crate::testing::operator_token())),
            0.0,
        );
        let r1 = bus.add(chain_robot(1, &keys), 0.0);
        let r2 = bus.add(chain_robot(2, &keys), 0.0);
        (bus, keys, [l, r1, r2])
    }

    fn states(bus: &Bus, id: usize, key: &str) -> Vec<RobotState> {
        bus.published_by(id, key)
            .filter_map(|p| match wire::decode(&p.payload) {
                Ok(Message::State(_, s)) => Some(s),
                _ => None,
            })
            .collect()
    }

    /// Samples the runtime dropped (its queue full) are in the robot's
    /// report, as the runtime's running total says.
    #[test]
    fn the_runtimes_drops_are_in_the_report() {
        let mut task = chain_robot(1, &Keys::new("lab"));
        assert_eq!(task.robot().report().dropped, 0);
        task.on_dropped(3);
        task.on_dropped(7);
        let rep = task.report().unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(rep.dropped, 7);
    }

    /// The leader and a chain of two robots, the tasks the runtime runs,
    /// on the bus: the chain converges; with the reference link cut for
    /// 3 s, robot 1 extrapolates, loses the link once and recovers; robot
    /// 2 (its own link fresh) never loses its link.
    #[test]
    fn the_leader_and_a_chain_run_on_the_bus() {
        let (mut bus, keys, [l, r1, r2]) = chain_on_bus(30.0);
        let reference_key = keys.reference();
        bus.link = Box::new(move |from, key, t| {
            (from != l || key != reference_key || !(12.0..15.0).contains(&t)).then_some(0.0)
        });
        bus.run_until(30.0);
        assert!(!bus.is_running(l), "the leader stops at its duration");
        for (id, k) in [(r1, 1), (r2, 2)] {
            let task: &RobotTask = bus.task(id).unwrap_or_else(|| panic!("a robot"));
            let rep = task.robot().report();
            assert!(rep.final_error < 1e-3, "agent {k}: {rep:?}");
            assert_eq!(rep.link, "tracking");
            assert_eq!(rep.counters.link_losses, u64::from(k == 1), "{rep:?}");
            // 100 Hz for 30 s, every state published and logged.
            assert!((2990..=3001).contains(&rep.ticks), "{rep:?}");
            let published = states(&bus, id, &keys.state(k));
            assert_eq!(published.len() as u64, rep.published);
            assert!(published.windows(2).all(|w| w[0].t <= w[1].t));
            let cut = published.iter().filter(|st| (13.0..15.0).contains(&st.t));
            let expected = if k == 1 {
                LinkStatus::Extrapolating
            } else {
                LinkStatus::Tracking
            };
            assert!(cut.clone().count() > 150);
            assert!(cut.into_iter().all(|st| st.link == expected));
            // Its counters once per fleet second on its stats key.
            let stats = bus.published_by(id, &keys.stats(k)).count();
            assert!((29..=31).contains(&stats), "{stats}");
        }
        // The reference sent during the cut (150 samples) reached no one;
        // the last one may wait for robot 1's next tick.
        let sent = bus.published_by(l, &keys.reference()).count() as u64;
        let task: &RobotTask = bus.task(r1).unwrap_or_else(|| panic!("a robot"));
        let c = task.robot().counters();
        assert_eq!(sent, 1501);
        assert!((sent - 151..=sent - 150).contains(&c.received), "{c:?}");
    }

    /// A fleet stop put on the bus (the operator) halfway: each robot's
    /// states say `stopped` from its next tick on and it commands zero on
    /// every tick; the leader's reference pauses; robot 2 restarted during
    /// the stop learns it from the latches and stays stopped; garbage on the
    /// command key is refused; after the resume both move again and the
    /// chain converges.
    #[test]
    fn a_fleet_stop_on_the_bus_holds_every_robot_until_the_resume() {
        use crate::command::{FleetCommand, Latched, Order};
        let (mut bus, keys, [l, r1, r2]) = chain_on_bus(60.0);
        let period = 0.01;
        bus.run_until(20.0);
        bus.put(&keys.command(), b"{not a command");
        bus.put(
            &keys.command(),
            &FleetCommand::new(Order::Stop, 1, "operator", "test").encode(),
        );
        bus.run_until(25.0);
        // Robot 2 restarts during the stop.
        bus.replace(r2, chain_robot(2, &Keys::new("lab")), 25.0);
        bus.run_until(28.0);
        // A resume without the operator token's proof lifts nothing.
        bus.put(
            &keys.command(),
            &FleetCommand::new(Order::Resume, 2, "operator", "unsigned").encode(),
        );
        bus.run_until(30.0);
        let resume_at = bus.now();
        bus.put(
            &keys.command(),
            &crate::testing::resume(2, "operator", "test").encode(),
        );
        bus.run_until(60.0);
        for (id, k) in [(r1, 1), (r2, 2)] {
            let key = keys.state(k);
            let during: Vec<&crate::runtime::bus::Published> = bus
                .published_by(id, &key)
                .filter(|p| p.t > 20.0 + period && p.t < resume_at)
                .collect();
            assert!(during.len() > 500, "agent {k}: {}", during.len());
            for p in during {
                let Ok(Message::State(_, st)) = wire::decode(&p.payload) else {
                    panic!("a state");
                };
                assert!(
                    matches!(st.link, LinkStatus::Stopped | LinkStatus::Waiting),
                    "agent {k} at {}: {st:?}",
                    p.t
                );
                assert_eq!(st.u, echelon::model::Input::default());
            }
            let task: &RobotTask = bus.task(id).unwrap_or_else(|| panic!("a robot"));
            let rep = task.robot().report();
            assert_eq!(rep.link, "tracking");
            assert!(rep.final_error < 1e-3, "agent {k}: {rep:?}");
            assert_eq!(
                (
                    rep.commands.stops,
                    rep.commands.resumes,
                    rep.commands.unauthorized
                ),
                (1, 1, 1),
                "{rep:?}"
            );
            let answer = Latched::decode(&bus.latched(id).unwrap_or_default());
            assert!(answer.is_some_and(|a| !a.stopped && a.seq() == 2 && a.refused.is_none()));
        }
        let task: &RobotTask = bus.task(r1).unwrap_or_else(|| panic!("a robot"));
        assert_eq!(task.robot().command_counts().refused, 1);
        // The reference stood still during the stop (10 s paused).
        let refs: Vec<crate::wire::Reference> = bus
            .published_by(l, &keys.reference())
            .filter(|p| p.t > 20.1 && p.t < resume_at)
            .filter_map(|p| match wire::decode(&p.payload) {
                Ok(Message::Reference(_, r)) => Some(r),
                _ => None,
            })
            .collect();
        assert!(refs.len() > 400);
        assert!(
            refs.windows(2)
                .all(|w| w[0].motion.p == w[1].motion.p && w[0].t < w[1].t)
        );
        let leader: &LeaderTask = bus.task(l).unwrap_or_else(|| panic!("the leader"));
        assert!((leader.leader().paused(60.0) - 10.0).abs() < 0.05);
    }

    /// The leader interrupted before its end (the runtime stops it on
    /// SIGINT/SIGTERM) puts a fleet stop as its last words: robot 1 (under
    /// `extrapolate`, which would coast on for the hold) and its follower
    /// command zero from their next tick; a leader that reaches its end
    /// puts none.
    #[test]
    fn an_interrupted_leader_stops_the_fleet() {
        let (mut bus, keys, [l, r1, r2]) = chain_on_bus(60.0);
        bus.run_until(10.0);
        bus.stop(l).unwrap_or_else(|e| panic!("{e}"));
        let command_key = keys.command();
        let sent: Vec<_> = bus.published_by(l, &command_key).collect();
        assert_eq!(sent.len(), 1);
        let c = crate::command::FleetCommand::decode(&sent[0].payload)
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            (c.order, c.by.as_str()),
            (crate::command::Order::Stop, "leader")
        );
        bus.run_until(12.0);
        for (id, k) in [(r1, 1), (r2, 2)] {
            let key = keys.state(k);
            let after: Vec<RobotState> = bus
                .published_by(id, &key)
                .filter(|p| p.t > 10.0 + 0.01)
                .filter_map(|p| match wire::decode(&p.payload) {
                    Ok(Message::State(_, st)) => Some(st),
                    _ => None,
                })
                .collect();
            assert!(after.len() > 150, "agent {k}");
            assert!(after.iter().all(|st| st.link == LinkStatus::Stopped));
        }
        let task: LeaderTask = bus.take(l).unwrap_or_else(|| panic!("the leader"));
        let rep = task.report().unwrap_or_else(|e| panic!("{e}"));
        assert!(rep.stopped_the_fleet);

        // A leader at its end stops nothing.
        let mut bus = Bus::new();
        let (_, _, reference) = crate::testing::fast_circle();
        let leader = Reference::new(reference, 50.0, 1.0, 1);
        let l = bus.add(
            LeaderTask::new(leader, keys.clone())
                .with_operator_token(Some(crate::testing::operator_token())),
            0.0,
        );
        bus.run_until(2.0);
        assert!(!bus.is_running(l));
        assert_eq!(bus.published_by(l, &keys.command()).count(), 0);
    }
}
