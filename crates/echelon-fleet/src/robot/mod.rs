//! `echelon fleet robot`: one agent of a scenario as its own process.
//!
//! [`Robot`] is the agent as a state machine (sans-IO, after copper-rs tasks
//! and sans-IO protocol crates): it is fed the bytes that arrive on its leader
//! stream ([`Robot::on_message`]) and ticked ([`Robot::tick`]), both with the
//! time read by the caller, and it drives an injected [`Plant`]. It reads no
//! clock, opens no socket and sleeps nowhere, so every behaviour (link loss,
//! restarts, faults) is tested with a fake clock. [`run`] is the thin driver:
//! Zenoh in and out, the [`FleetClock`](crate::clock::FleetClock), and a sleep until the next tick.
//!
//! Every tick (the `[fleet] control_rate`): take what arrived from the leader
//! stream (through fault injection, decoding and the sequence/staleness
//! checks), bring the plant to now, predict the leader motion (fresh, or the
//! link-loss policy), run the law (eq. 13, [`echelon::follow::follow`]) and
//! publish the state with the leader motion used.
//!
//! Whenever the robot has nothing to follow (no leader sample, no odometry,
//! the process stopping) or must not move (a fleet stop, [`crate::command`])
//! it goes through one place, [`Robot::halt`], which commands zero.
//!
//! A fleet stop ([`Robot::on_command`]) commands zero at once, when it is
//! handed over, and again on every tick until a resume; the robot keeps its
//! clock, its leader stream and its plant up to date meanwhile, and
//! publishes its state with the link status `stopped`. On a resume the law
//! runs again from the robot's state at its next tick.
//!
//! When its base reports a stopping hazard (a bump, a cliff, a stall, a
//! wheel drop, an e-stop: [`Plant::hazards`]) the robot commands zero at
//! that tick and pauses the whole fleet: it takes a fleet stop itself and
//! hands it to its driver to put on its own halt key
//! ([`Robot::take_outgoing`]; every robot and the leader obey a stop
//! there, and only a stop), its reason naming the robot and the hazard.
//! While the hazard is reported its latch answer names it (so `fleet
//! resume` refuses, naming it), and a resume that reaches it anyway is
//! refused: it stops the fleet again, numbered above that resume.

use std::collections::VecDeque;

use echelon::base::{Backup, VelocityRobot};
use echelon::control::LeaderMotion;
use echelon::formation::Leader;
use echelon::safety::{SafetyFilter, Tally};

use crate::command::{Change, CommandCounts, FleetCommand, Latch, Latched, Order};
use crate::faults::{FaultInjector, Verdict};
use crate::latency::Latency;
use crate::link::{Counters, LeaderSample, StreamTracker};
use crate::neighbours::{LAG_PERIODS, NeighbourTable, STALE_HOLD};
use crate::plant::{Plant, SimulatedDrive};
use crate::role::{Member, Role};
use crate::ros2::hazard::HazardSet;
use crate::wire::{self, DecodeError, Header, LinkStatus, Message, RobotState};

mod config;
mod driver;
mod file;
mod hazards;
mod head;
mod report;
mod safety;
mod task;
mod tick;
mod watchdog;

pub use config::{RobotConfig, RobotSafety, agent_spec};
pub use driver::{RobotOptions, run};
pub use file::{
    ClockSection, Drive, LoadedRobotFile, NetMode, NetSection, ROBOT_FILE, ROBOT_FILE_VERSION,
    RobotFile, SecureSection, sha256_hex,
};
pub use head::{HEAD_FILTER, HeadFilter};
pub use report::{RobotReport, RobotStats, SafetyCounts};
pub use task::{PlantFeed, RobotTask};
pub use watchdog::{Watchdog, WatchdogCounts, WatchdogSettings};

/// Longest plant integration sub-step, fleet s (the simulator's default `dt`).
pub const PLANT_STEP: f64 = 1e-3;
/// Period of the state messages while waiting for the leader, fleet s.
const WAITING_PERIOD: f64 = 0.1;

/// Why a robot commands zero.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Halt {
    /// No leader sample to follow (not synced yet, or the leader restarted
    /// and nothing of the new timeline is delivered yet).
    NoLeader,
    /// The plant has no valid state (odometry lost).
    NoOdometry,
    /// The process is stopping.
    Shutdown,
    /// The plant's state left the divergence guard's bounds.
    Diverged,
    /// A fleet stop is in force (`fleet stop`, or the leader interrupted).
    Stopped,
    /// The robot's base reports a stopping hazard (bump, cliff, stall,
    /// wheel drop, e-stop).
    Hazard,
    /// A watchdog holds it ([`Watchdog`]: stale odometry, the operator's
    /// heartbeat lost).
    Held(Watchdog),
}

/// What one tick asks the driver to do.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobotTick {
    /// The state message to publish on `robot/<k>/state`, with its header.
    pub publish: Option<(Header, RobotState)>,
    /// The counters to publish on `robot/<k>/stats` (once per fleet second).
    pub stats: Option<RobotStats>,
    /// `duration` reached: the process stops.
    pub done: bool,
}

/// A leader sample from a decoded message of the expected stream, or `None`
/// (counted as foreign) for anything else.
pub fn sample_of(msg: &Message, leader: Leader) -> Option<(Header, LeaderSample)> {
    match (msg, leader) {
        (Message::Reference(h, r), Leader::Reference) => Some((
            *h,
            LeaderSample {
                t: r.t,
                motion: r.motion,
                speed: r.speed,
                turn_rate: r.turn_rate,
            },
        )),
        // A leader robot that waits, or that a watchdog holds (its odometry
        // stale: its pose is not one to follow), is not followed: its
        // follower's link goes stale and its link-loss policy acts.
        (Message::State(h, s), Leader::Agent(j))
            if s.agent as usize == j + 1
                && !matches!(s.link, LinkStatus::Waiting | LinkStatus::Held) =>
        {
            Some((
                *h,
                LeaderSample {
                    t: s.t,
                    motion: LeaderMotion::of_robot(&s.state, s.dv),
                    speed: s.state.v,
                    turn_rate: s.state.omega,
                },
            ))
        }
        _ => None,
    }
}

/// One fleet robot as a state machine over an injected [`Plant`].
///
/// Times passed in are the caller's *local* clock (monotonic, scaled, e.g.
/// [`FleetClock`](crate::clock::FleetClock) never synced); the robot keeps the offset that turns them
/// into fleet time, which is the leader's: the first message of the leader
/// stream (or a restarted leader's) sets it.
#[derive(Debug, Clone)]
pub struct Robot<P: Plant = SimulatedDrive> {
    config: RobotConfig,
    plant: P,
    source: u32,
    /// Fleet time = local time + `offset`.
    offset: f64,
    synced: bool,
    tracker: StreamTracker,
    injector: FaultInjector,
    delayed: VecDeque<(f64, Header, LeaderSample)>,
    sample: Option<LeaderSample>,
    fresh: bool,
    /// The leader's last heading while it moved (`θ_d` of a slot in the
    /// leader's frame: a leader stopped by a link-loss policy, or paused,
    /// keeps it), rad.
    heading: f64,
    next_tick: f64,
    next_stats: f64,
    seq: u64,
    ticks: u64,
    overruns: u64,
    last: RobotState,
    latency: Latency,
    safety: Option<Safety>,
    /// Set when the plant's state left its bounds: the robot has stopped.
    diverged: Option<String>,
    /// A driven head's derivative filter.
    head: HeadFilter,
    /// The fleet command it is under.
    latch: Latch,
    /// The stopping hazards its base reported at its last tick.
    hazards: HazardSet,
    /// Moves whenever `hazards` changes (part of [`Robot::latch_changes`]).
    hazard_changes: u64,
    /// A fleet stop it took and its driver has yet to put on the command key.
    outgoing: Option<FleetCommand>,
    /// Its base's backup budget (a `reverse_limit`), and where it was at
    /// the last tick that measured it.
    backup: Option<(Backup, Option<echelon::model::State>)>,
    /// Its watchdogs ([`watchdog`]).
    watchdogs: watchdog::Watchdogs,
}

impl Robot<SimulatedDrive> {
    /// A robot on its simulated drive (eq. 3, or its velocity base) starting
    /// at its spec's start, under its own faults (`--freeze-odometry`,
    /// `--fault-at`: [`SimulatedDrive::with_faults`]).
    pub fn simulated(config: RobotConfig, source: u32) -> Self {
        let plant = SimulatedDrive::of(&config.spec, 0.0, PLANT_STEP).with_faults(&config.faults);
        Robot::new(config, plant, source)
    }
}

impl<P: Plant> Robot<P> {
    /// A robot driving `plant`, publishing under the random `source`.
    pub fn new(config: RobotConfig, plant: P, source: u32) -> Self {
        let tracker = StreamTracker::new(config.stale_after);
        let injector = FaultInjector::new(config.faults, u64::from(config.agent));
        let last = RobotState {
            agent: config.agent,
            state: config.spec.start(),
            ..RobotState::default()
        };
        let safety = config.safety.as_ref().map(|s| Safety {
            filter: SafetyFilter::new(s.config).with_period(config.period),
            table: NeighbourTable::new(
                config.agent,
                s.l.clone(),
                s.cooperative.clone(),
                config.link_timeout,
                STALE_HOLD,
                LAG_PERIODS * config.period,
            ),
            tally: Tally::default(),
        });
        Robot {
            plant,
            source,
            offset: 0.0,
            tracker,
            injector,
            delayed: VecDeque::with_capacity(64),
            sample: None,
            fresh: false,
            heading: 0.0,
            next_tick: 0.0,
            next_stats: 0.0,
            seq: 0,
            ticks: 0,
            overruns: 0,
            last,
            latency: Latency::new(),
            safety,
            diverged: None,
            latch: Latch::with_token(config.operator_token.clone()),
            hazards: HazardSet::EMPTY,
            hazard_changes: 0,
            outgoing: None,
            backup: config
                .spec
                .velocity_robot()
                .and_then(VelocityRobot::backup)
                .map(|b| (b, None)),
            head: HeadFilter::default(),
            watchdogs: watchdog::Watchdogs::default(),
            // A driven head keeps the fleet's time: its own clock.
            synced: config.driven,
            config,
        }
    }

    /// Takes a payload that arrived on the fleet command key
    /// ([`crate::command`]): refused and counted if malformed; a stop
    /// commands zero at once and on every tick until a resume numbered
    /// after it.
    pub fn on_command(&mut self, bytes: &[u8]) -> Change {
        let mut change = self.latch.on_payload(bytes);
        if change == Change::Resumed && !self.hazards.is_empty() {
            // Its base still reports a hazard: the resume is refused, and
            // the fleet stopped again, numbered above it.
            self.latch.refuse_resume();
            self.pause_fleet("refused a resume");
            change = Change::Unchanged;
        }
        if self.latch.stopped() {
            self.halt(Halt::Stopped);
        }
        change
    }

    /// Takes a payload that arrived on robot `k`'s halt key (its own stop,
    /// its base having reported a hazard: [`Latch::on_halt`]); a stop
    /// commands zero at once.
    pub fn on_halt(&mut self, k: u32, bytes: &[u8]) -> Change {
        let change = self.latch.on_halt(k, bytes);
        if self.latch.stopped() {
            self.halt(Halt::Stopped);
        }
        change
    }

    /// Takes another process's latch answer (at start): it can only stop
    /// the robot ([`Latch::on_hearsay`]).
    pub fn on_latch_answer(&mut self, bytes: &[u8]) -> Change {
        let change = self.latch.on_hearsay(bytes);
        if self.latch.stopped() {
            self.halt(Halt::Stopped);
        }
        change
    }

    /// Whether a fleet stop is in force.
    pub fn is_stopped(&self) -> bool {
        self.latch.stopped()
    }

    /// What it answers on its latch key: the command in force, and the
    /// stopping hazards its base reports.
    pub fn latched(&self) -> Latched {
        Latched {
            hazards: self.hazards,
            ..self.latch.latched()
        }
    }

    /// Moves whenever [`Robot::latched`] changes ([`Latch::changes`], and
    /// its hazards).
    pub fn latch_changes(&self) -> u64 {
        self.latch.changes() + self.hazard_changes
    }

    /// What the fleet commands did.
    pub fn command_counts(&self) -> CommandCounts {
        self.latch.counts()
    }

    /// Why it stopped for good, if its plant's state stopped being finite or
    /// left its bounds ([`echelon::guard::Bounds`]): one line naming the
    /// agent, the fleet time and the quantity.
    pub fn diverged(&self) -> Option<&str> {
        self.diverged.as_deref()
    }

    /// Whether it runs a safety filter (and so listens to every robot's state).
    pub fn has_safety(&self) -> bool {
        self.safety.is_some()
    }

    /// What its safety filter did so far (`None`: it has none).
    pub fn safety_counts(&self) -> Option<SafetyCounts> {
        self.safety.as_ref().map(|s| SafetyCounts {
            steps: s.tally.steps,
            active: s.tally.active,
            infeasible: s.tally.infeasible,
            stale_brakes: s.tally.stale_brakes,
            min_distance: s.tally.closest(),
            refused: s.table.refused(),
            stale_neighbours: s.table.stale_events(),
            lagging: s.table.lagging(),
            deadlock_breaks: s.filter.deadlock_breaks(),
        })
    }

    /// Takes a message that arrived on another robot's state stream at local
    /// time `now` (decoded by the caller) for the safety filter; ignored
    /// without one, and dropped (counted as `injected_outage`) while the
    /// robot is partitioned.
    pub fn on_neighbour(&mut self, msg: Result<Message, DecodeError>, now: f64) {
        if self.synced && self.config.faults.partitioned_at(self.fleet_time(now)) {
            // Partitioned (`--outage`): nothing arrives.
            self.tracker.counters.injected_outage += 1;
            return;
        }
        let Some(s) = self.safety.as_mut() else {
            return;
        };
        match msg {
            Ok(Message::State(h, state)) => s.table.on_state(h, &state, now),
            _ => s.table.refuse(),
        }
    }

    /// Its configuration.
    pub fn config(&self) -> &RobotConfig {
        &self.config
    }

    /// The plant it drives.
    pub fn plant(&self) -> &P {
        &self.plant
    }

    /// The plant it drives, to change (e.g. a test's fault).
    pub fn plant_mut(&mut self) -> &mut P {
        &mut self.plant
    }

    /// The leader stream's counters.
    pub fn counters(&self) -> &Counters {
        &self.tracker.counters
    }

    /// The last state it published (or its start).
    pub fn last(&self) -> &RobotState {
        &self.last
    }

    /// Whether its clock follows a leader.
    pub fn is_synced(&self) -> bool {
        self.synced
    }

    /// Fleet time at local time `now`.
    pub fn fleet_time(&self, now: f64) -> f64 {
        self.offset + now
    }

    /// Local time at which the next tick is due.
    pub fn next_wake(&self) -> f64 {
        self.next_tick - self.offset
    }

    /// Whether a tick is due at local time `now`.
    pub fn is_due(&self, now: f64) -> bool {
        self.fleet_time(now) >= self.next_tick
    }

    /// Messages still delayed by fault injection.
    pub fn pending(&self) -> usize {
        self.delayed.len()
    }

    /// Takes bytes that arrived on the leader stream at local time `now`:
    /// decodes, syncs the clock to the leader, injects faults and queues the
    /// sample for delivery. Counts whatever happens.
    pub fn on_message(&mut self, bytes: &[u8], now: f64) {
        self.tracker.counters.received += 1;
        if self.config.driven {
            // A driven head follows no one (its driver is its leader).
            self.tracker.counters.foreign += 1;
            return;
        }
        let msg = match wire::decode(bytes) {
            Ok(m) => m,
            Err(DecodeError::Malformed(_)) => {
                self.tracker.counters.malformed += 1;
                return;
            }
            Err(DecodeError::WrongVersion(_)) => {
                self.tracker.counters.wrong_version += 1;
                return;
            }
        };
        let Some((h, s)) = sample_of(&msg, self.config.spec.leader()) else {
            self.tracker.counters.foreign += 1;
            return;
        };
        if !s.within(&self.config.bounds) {
            self.tracker.counters.malformed += 1;
            return;
        }
        let arrived = self.fleet_time(now);
        let resync = !self.synced
            || (self.tracker.is_new_source(&h) && (arrived - s.t).abs() > self.config.stale_after);
        if resync {
            // Fleet time is the leader's: the first message (or a restarted
            // leader's) sets the clock.
            self.offset = s.t - now;
            self.plant.set_time(s.t);
            self.next_tick = s.t;
            self.next_stats = s.t + tick::stats_phase(self.config.agent);
            // The old leader's samples are on the old timeline: at the new
            // clock they would look fresh, even from the future. Refused as
            // stale (every message lands in one counter).
            self.tracker.counters.stale += self.delayed.len() as u64;
            self.delayed.clear();
            self.sample = None;
            self.synced = true;
        }
        match self.injector.admit(self.fleet_time(now)) {
            Verdict::Lost => self.tracker.counters.injected_loss += 1,
            Verdict::Outage => self.tracker.counters.injected_outage += 1,
            Verdict::DeliverAt(at) => self.delayed.push_back((at, h, s)),
        }
    }

    /// [`Robot::on_message`] for a sample that arrived `delay` ns after its
    /// sender stamped it ([`crate::latency::delay_ns`]; `None`: not stamped).
    pub fn on_stamped_message(&mut self, bytes: &[u8], now: f64, delay: Option<i64>) {
        self.latency.record(delay);
        self.on_message(bytes, now);
    }

    /// The delays measured on the leader stream.
    pub fn latency(&self) -> &Latency {
        &self.latency
    }

    /// Commands zero: the one place where losing the leader, the odometry,
    /// the process or a fleet stop stops the drive ([`Plant::stop`]: zero
    /// torques, or a zero `cmd_vel` sent at once). The command is held until
    /// the next one. A driven head is never commanded (its driver owns its
    /// `cmd_vel`).
    pub fn halt(&mut self, why: Halt) {
        let _ = why;
        if !self.config.driven {
            self.plant.stop();
        }
    }

    /// The process is stopping: commands zero and returns the final counters.
    pub fn finish(&mut self) -> RobotStats {
        self.halt(Halt::Shutdown);
        self.stats_at(self.last.t, self.last.link)
    }

    /// What the robot reports when it stops.
    pub fn report(&self) -> RobotReport {
        let s = self.last.state;
        RobotReport {
            role: Role::Robot,
            agent: self.config.agent,
            name: self.config.spec.name().to_owned(),
            counters: self.tracker.counters,
            pending: self.delayed.len() as u64,
            published: self.seq,
            ticks: self.ticks,
            overruns: self.overruns,
            t: self.last.t,
            final_state: [s.x, s.y, s.theta, s.v, s.omega],
            final_error: self.last.e[0].hypot(self.last.e[1]),
            deadlocked_at_end: self.deadlocked_at_end(),
            link: self.last.link.name().to_owned(),
            latency: self.latency.report(true),
            ros2: None,
            safety: self.safety_counts(),
            fixes: self.plant.fixes(self.last.t),
            hazards: self.plant.hazard_report(),
            commands: self.latch.counts(),
            watchdogs: self.watchdogs.counts,
            aftermath: self.plant.aftermath(),
            dropped: 0,
        }
    }

    /// Whether its filter kept it from its slot at the end (the
    /// simulator's rule, [`echelon::stats::Summary::SETTLE_TOLERANCE`]).
    fn deadlocked_at_end(&self) -> bool {
        echelon::stats::Summary::deadlocked_at_end(
            self.safety.as_ref().is_some_and(|s| s.filter.deadlocked()),
            self.last.e[0].hypot(self.last.e[1]),
        )
    }

    fn stats_at(&self, t: f64, link: LinkStatus) -> RobotStats {
        RobotStats {
            agent: self.config.agent,
            t,
            link: link.name(),
            counters: self.tracker.counters,
            published: self.seq,
            overruns: self.overruns,
            safety: self.safety_counts(),
            fixes: self.plant.fixes(t),
            hazards: self.plant.hazard_report().map(|r| r.stats()),
            commands: self.latch.counts(),
            watchdogs: self.watchdogs.counts,
            cpu: None,
        }
    }

    /// The next header of its stream, for `state` (which gets the plant's
    /// raw odometry, as does the last state kept).
    fn header_for(&mut self, state: RobotState) -> (Header, RobotState) {
        let state = RobotState {
            odometry: self.plant.odometry(),
            ..state
        };
        self.last.odometry = state.odometry;
        let h = Header {
            source: self.source,
            seq: self.seq,
        };
        self.seq += 1;
        (h, state)
    }
}

use safety::Safety;

#[cfg(test)]
mod tests;
