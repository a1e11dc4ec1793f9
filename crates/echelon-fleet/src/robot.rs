//! `echelon fleet robot`: one agent of a scenario as its own process.
//!
//! [`Robot`] is the agent as a state machine (sans-IO, after copper-rs tasks
//! and sans-IO protocol crates): it is fed the bytes that arrive on its leader
//! stream ([`Robot::on_message`]) and ticked ([`Robot::tick`]), both with the
//! time read by the caller, and it drives an injected [`Plant`]. It reads no
//! clock, opens no socket and sleeps nowhere, so every behaviour (link loss,
//! restarts, faults) is tested with a fake clock. [`run`] is the thin driver:
//! Zenoh in and out, the [`FleetClock`], and a sleep until the next tick.
//!
//! Every tick (the `[fleet] control_rate`): take what arrived from the leader
//! stream (through fault injection, decoding and the sequence/staleness
//! checks), bring the plant to now, predict the leader motion (fresh, or the
//! link-loss policy), run the law (eq. 13, [`echelon::follow::follow`]) and
//! publish the state with the leader motion used.
//!
//! Whenever the robot has nothing to follow (no leader sample, no odometry,
//! the process stopping) it goes through one place, [`Robot::halt`], which
//! commands zero.

use std::collections::VecDeque;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};
use zenoh::Wait;

use echelon::agent::{AgentSpec, Command, Guard};
use echelon::control::LeaderMotion;
use echelon::follow::{LeaderView, follow};
use echelon::formation::Leader;
use echelon::guard::Bounds;
use echelon::model::State;
use echelon::plan::Plan;
use echelon::safety::{Obstacle, Outcome, SafetyConfig, SafetyFilter, point};
use echelon::scenario::{FleetSettings, LinkLoss, Overrides, Ros2Link, Scenario};

use crate::clock::FleetClock;
use crate::faults::{FaultInjector, FaultSpec, Verdict};
use crate::keys::{Keys, robot_role};
use crate::latency::{self, Latency, LatencyReport};
use crate::link::{Counters, LeaderSample, StreamTracker, predict};
use crate::neighbours::{NeighbourTable, STALE_HOLD};
use crate::net::{self, NetOptions};
use crate::plant::{Plant, SimulatedDrive};
use crate::role::Role;
use crate::ros2::declare_tokens;
use crate::ros2::drive::{CmdSink, Ros2Counters, Ros2Drive, cmd_vel_type};
use crate::wire::{self, DecodeError, Header, LinkStatus, Message, RobotState};
use crate::{FleetError, StopFlag};
use echelon_ros2::attachment::{Gid, gid_from_token};
use echelon_ros2::keys::{topic_key, topic_key_any_type};
use echelon_ros2::liveliness::{NodeInfo, Qos};
use echelon_ros2::msgs::ODOMETRY;

/// Longest plant integration sub-step, fleet s (the simulator's default `dt`).
pub const PLANT_STEP: f64 = 1e-3;
/// Period of the state messages while waiting for the leader, fleet s.
const WAITING_PERIOD: f64 = 0.1;

/// Options of a robot process.
#[derive(Debug, Clone)]
pub struct RobotOptions {
    /// The scenario.
    pub scenario: Scenario,
    /// Agent number, from 1.
    pub agent: u32,
    /// Clock speed-up `K`.
    pub time_scale: f64,
    /// Stop at this fleet time (absent: run until a signal).
    pub duration: Option<f64>,
    /// Faults injected on what this robot receives.
    pub faults: FaultSpec,
    /// Network.
    pub net: NetOptions,
    /// Fleet name (absent: the scenario's).
    pub fleet: Option<String>,
    /// Drive the agent's ROS 2 robot (`[fleet.ros2]`) instead of a simulated one.
    pub ros2: bool,
}

/// What a robot reports when it stops (one JSON line on stdout; `fleet
/// up` reads it back as this type, so a renamed field is an error, never a 0).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotReport {
    /// [`Role::Robot`].
    pub role: Role,
    /// Agent number, from 1.
    pub agent: u32,
    /// Display name.
    pub name: String,
    /// The leader stream's counters.
    pub counters: Counters,
    /// Messages still delayed by `--delay` when it stopped.
    pub pending: u64,
    /// State messages published.
    pub published: u64,
    /// Controller ticks run.
    pub ticks: u64,
    /// Ticks started more than a period late.
    pub overruns: u64,
    /// Fleet time at the end, s.
    pub t: f64,
    /// Final state.
    pub final_state: [f64; 5],
    /// Final ‖e‖ against the leader motion used, m.
    pub final_error: f64,
    /// Final link status.
    pub link: String,
    /// Delay from the sender's timestamp to receipt of every sample on the
    /// leader stream (reference or leader robot's state), s; `count +
    /// unstamped` equals `counters.received`.
    pub latency: LatencyReport,
    /// With `--ros2`: the drive's odometry and command counters.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ros2: Option<Ros2Counters>,
    /// With `[safety]`: what its safety filter did.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub safety: Option<SafetyCounts>,
}

/// What a robot's safety filter did over its run (`docs/safety.md`, "In the
/// fleet").
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SafetyCounts {
    /// Control steps that went through the filter.
    pub steps: u64,
    /// Steps whose command the filter changed (filtered or braked).
    pub active: u64,
    /// Steps braked because the QP was infeasible (or the solver failed).
    pub infeasible: u64,
    /// Steps braked because a neighbour within range stayed stale past the hold.
    pub stale_brakes: u64,
    /// Deadlocks it started breaking (keep right).
    pub deadlock_breaks: u64,
    /// Neighbours within range whose stream went stale (once per episode).
    pub stale_neighbours: u64,
    /// Neighbour messages refused (unknown agent, reordered, malformed; its
    /// own are ignored).
    pub refused: u64,
    /// Smallest distance from its point to a neighbour's point it saw within
    /// range, m (`null`: none seen).
    pub min_distance: Option<f64>,
}

impl SafetyCounts {
    /// The fleet's total over the robots' counters: summed, the smallest
    /// `min_distance`; `None` when no robot filters.
    pub fn total<'a>(robots: impl IntoIterator<Item = &'a SafetyCounts>) -> Option<SafetyCounts> {
        let mut any = false;
        let mut t = SafetyCounts::default();
        for s in robots {
            any = true;
            t.steps += s.steps;
            t.active += s.active;
            t.infeasible += s.infeasible;
            t.stale_brakes += s.stale_brakes;
            t.deadlock_breaks += s.deadlock_breaks;
            t.stale_neighbours += s.stale_neighbours;
            t.refused += s.refused;
            if let Some(d) = s.min_distance {
                t.min_distance = Some(t.min_distance.map_or(d, |m| m.min(d)));
            }
        }
        any.then_some(t)
    }
}

/// A robot's safety settings, from the scenario's `[safety]`.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotSafety {
    /// Its filter's settings.
    pub config: SafetyConfig,
    /// The known obstacles.
    pub obstacles: Vec<Obstacle>,
    /// `L` of every agent (index agent − 1).
    pub l: Vec<f64>,
    /// Whether every agent filters (a cooperative neighbour).
    pub cooperative: Vec<bool>,
}

/// The stats message published on `echelon/<fleet>/robot/<k>/stats`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RobotStats {
    /// Agent number, from 1.
    pub agent: u32,
    /// Fleet time, s.
    pub t: f64,
    /// Link status.
    pub link: &'static str,
    /// The leader stream's counters.
    pub counters: Counters,
    /// State messages published.
    pub published: u64,
    /// Ticks started more than a period late.
    pub overruns: u64,
    /// With `[safety]`: what its safety filter did so far.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub safety: Option<SafetyCounts>,
}

/// The agent's spec from the scenario, checked for the fleet.
pub fn agent_spec(scenario: &Scenario, agent: u32) -> Result<AgentSpec, FleetError> {
    spec_in(&scenario.build(&Overrides::default())?.plan, agent)
}

/// [`agent_spec`] from the scenario's plan.
fn spec_in(plan: &Plan, agent: u32) -> Result<AgentSpec, FleetError> {
    let agents = plan.agents();
    let n = agents.len();
    let Some(spec) = (agent as usize)
        .checked_sub(1)
        .and_then(|i| agents.get(i))
        .cloned()
    else {
        return Err(FleetError::Config(format!(
            "--agent {agent}: the scenario has agents 1..={n}"
        )));
    };
    if spec.placement.uses_exact_derivatives() {
        return Err(FleetError::Config(format!(
            "agent {agent}: ly_derivatives = \"exact\" needs the reference's 3rd and 4th derivatives, which the fleet does not send; use \"neglect\""
        )));
    }
    Ok(spec)
}

/// Everything a robot's state machine needs to know, fixed for its life.
#[derive(Debug, Clone)]
pub struct RobotConfig {
    /// Agent number, from 1.
    pub agent: u32,
    /// Its body, leader, placement and controller.
    pub spec: AgentSpec,
    /// Controller period `1 / control_rate`, fleet s.
    pub period: f64,
    /// A sample older than this is no longer fresh, fleet s.
    pub link_timeout: f64,
    /// A sample older (or as far in the future) on delivery is refused, fleet s.
    pub stale_after: f64,
    /// What the law sees once the link is lost.
    pub loss: LinkLoss,
    /// Faults injected on what it receives.
    pub faults: FaultSpec,
    /// Stop at this fleet time (absent: never).
    pub duration: Option<f64>,
    /// Its safety filter (absent: none).
    pub safety: Option<RobotSafety>,
    /// The divergence guard's bounds on its plant's state (`[sim] bounds`).
    pub bounds: Bounds,
}

/// Agent `agent`'s safety settings (`None`: it does not filter).
pub fn safety_of(scenario: &Scenario, agent: u32) -> Result<Option<RobotSafety>, FleetError> {
    Ok(safety_in(
        &scenario.build(&Overrides::default())?.plan,
        agent,
    ))
}

/// [`safety_of`] from the scenario's plan.
fn safety_in(plan: &Plan, agent: u32) -> Option<RobotSafety> {
    let config = plan.safety_of(agent as usize - 1)?;
    let n = plan.agents().len();
    Some(RobotSafety {
        config,
        obstacles: plan.obstacles().to_vec(),
        l: plan.agents().iter().map(|a| a.placement.l).collect(),
        cooperative: (0..n).map(|i| plan.safety_of(i).is_some()).collect(),
    })
}

impl RobotConfig {
    /// Agent `agent`'s configuration from a scenario and its `[fleet]` settings.
    pub fn from_scenario(
        scenario: &Scenario,
        fleet: &FleetSettings,
        agent: u32,
        faults: FaultSpec,
        duration: Option<f64>,
    ) -> Result<RobotConfig, FleetError> {
        let plan = scenario.build(&Overrides::default())?.plan;
        let spec = spec_in(&plan, agent)?;
        let loss = fleet.link_loss[agent as usize - 1];
        let safety = safety_in(&plan, agent);
        Ok(RobotConfig {
            agent,
            spec,
            period: 1.0 / fleet.control_rate,
            link_timeout: fleet.link_timeout,
            stale_after: fleet.stale_after,
            loss,
            faults,
            duration,
            safety,
            bounds: plan.config().bounds,
        })
    }
}

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
fn sample_of(msg: &Message, leader: Leader) -> Option<(Header, LeaderSample)> {
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
        (Message::State(h, s), Leader::Agent(j))
            if s.agent as usize == j + 1 && s.link != LinkStatus::Waiting =>
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
/// [`FleetClock`] never synced); the robot keeps the offset that turns them
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
}

/// A robot's safety filter and what it knows of its neighbours.
#[derive(Debug, Clone)]
struct Safety {
    filter: SafetyFilter,
    table: NeighbourTable,
    counts: SafetyCounts,
}

impl Robot<SimulatedDrive> {
    /// A robot on its simulated drive (eq. 3, or its velocity base) starting
    /// at its spec's start.
    pub fn simulated(config: RobotConfig, source: u32) -> Self {
        let plant = SimulatedDrive::of(&config.spec, 0.0, PLANT_STEP);
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
            state: config.spec.start,
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
            ),
            counts: SafetyCounts::default(),
        });
        Robot {
            config,
            plant,
            source,
            offset: 0.0,
            synced: false,
            tracker,
            injector,
            delayed: VecDeque::with_capacity(64),
            sample: None,
            fresh: false,
            next_tick: 0.0,
            next_stats: 0.0,
            seq: 0,
            ticks: 0,
            overruns: 0,
            last,
            latency: Latency::new(),
            safety,
            diverged: None,
        }
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
            refused: s.table.refused(),
            stale_neighbours: s.table.stale_events(),
            deadlock_breaks: s.filter.deadlock_breaks(),
            ..s.counts
        })
    }

    /// Takes a message that arrived on another robot's state stream at local
    /// time `now` (decoded by the caller) for the safety filter; ignored
    /// without one.
    pub fn on_neighbour(&mut self, msg: Result<Message, DecodeError>, now: f64) {
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
        let Some((h, s)) = sample_of(&msg, self.config.spec.leader) else {
            self.tracker.counters.foreign += 1;
            return;
        };
        let arrived = self.fleet_time(now);
        let resync = !self.synced
            || (self.tracker.is_new_source(&h) && (arrived - s.t).abs() > self.config.stale_after);
        if resync {
            // Fleet time is the leader's: the first message (or a restarted
            // leader's) sets the clock.
            self.offset = s.t - now;
            self.plant.set_time(s.t);
            self.next_tick = s.t;
            self.next_stats = s.t;
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
    /// sender stamped it ([`latency::delay_ns`]; `None`: not stamped).
    pub fn on_stamped_message(&mut self, bytes: &[u8], now: f64, delay: Option<i64>) {
        self.latency.record(delay);
        self.on_message(bytes, now);
    }

    /// The delays measured on the leader stream.
    pub fn latency(&self) -> &Latency {
        &self.latency
    }

    /// Runs one controller tick at local time `now` (call when [`is_due`]):
    /// delivers what is due, brings the plant to now, runs the law on the
    /// leader motion (fresh or the link-loss policy's) and commands the plant.
    ///
    /// [`is_due`]: Robot::is_due
    pub fn tick(&mut self, now: f64) -> RobotTick {
        let local = now;
        let now = self.fleet_time(now);
        while let Some(&(at, h, s)) = self.delayed.front() {
            if at > now {
                break;
            }
            self.delayed.pop_front();
            if self.tracker.check(h, s.t, at).is_ok() {
                self.sample = Some(s);
            }
        }
        let prediction = match (self.synced, self.sample) {
            (true, Some(s)) => Some(predict(
                &s,
                now,
                self.config.link_timeout,
                &self.config.loss,
            )),
            _ => None,
        };
        let Some(p) = prediction else {
            // Waiting for the leader: stand still, say so now and then.
            if self.synced {
                self.plant.advance(now);
            }
            self.halt(Halt::NoLeader);
            let t = if self.synced { now } else { 0.0 };
            let publish = self.plant.state().map(|state| {
                self.last = RobotState {
                    t,
                    agent: self.config.agent,
                    link: LinkStatus::Waiting,
                    state,
                    ..RobotState::default()
                };
                self.header_for(self.last)
            });
            self.next_tick = now + WAITING_PERIOD.min(self.config.period * 10.0);
            return RobotTick {
                publish,
                stats: None,
                done: false,
            };
        };
        if p.status == LinkStatus::Tracking {
            self.fresh = true;
        } else if self.fresh {
            self.fresh = false;
            self.tracker.counters.link_losses += 1;
        }

        self.plant.advance(now);
        let state = self.plant.state();
        if let Some(breach) = state.and_then(|s| self.config.bounds.check(&s)) {
            // Diverged: zero first, then say so and stop for good.
            self.halt(Halt::Diverged);
            self.diverged = Some(format!(
                "agent {} diverged at t = {now} s: {breach}",
                self.config.agent
            ));
            self.next_tick = f64::INFINITY;
            return RobotTick {
                publish: None,
                stats: None,
                done: true,
            };
        }
        let publish = match state {
            Some(state) => {
                let out = follow(
                    &self.config.spec,
                    &state,
                    LeaderView::Motion {
                        motion: p.motion,
                        speed: p.speed,
                        turn_rate: p.turn_rate,
                    },
                );
                let nominal = out.command();
                let cmd = match self.safety.as_mut() {
                    Some(s) => s.act(&self.config, local, now, &state, nominal),
                    None => self.config.spec.act(now, &state, nominal, None).command,
                };
                let act = self.plant.command(cmd);
                let (dv, domega) = self.plant.accelerations();
                self.last = RobotState {
                    t: now,
                    agent: self.config.agent,
                    link: p.status,
                    state,
                    dv,
                    domega,
                    e: out.law.e,
                    z: out.law.z,
                    u: act.u,
                    tau: act.tau,
                    leader: out.leader,
                    velocity: act.velocity_sample(cmd),
                };
                self.ticks += 1;
                Some(self.header_for(self.last))
            }
            None => {
                self.halt(Halt::NoOdometry);
                None
            }
        };

        let stats = (now >= self.next_stats).then(|| {
            self.next_stats += 1.0;
            self.stats_at(now, p.status)
        });
        let done = self.config.duration.is_some_and(|d| now >= d);
        if !done {
            let period = self.config.period;
            self.next_tick += period;
            if now - self.next_tick > period {
                // Late by more than a period: the plant keeps moving in real
                // time; the controller resumes on the next tick from now.
                self.overruns += 1;
                self.next_tick = now + period;
            }
        }
        RobotTick {
            publish,
            stats,
            done,
        }
    }

    /// Commands zero: the one place where losing the leader, the odometry or
    /// the process stops the drive ([`Plant::stop`]: zero torques, or a zero
    /// `cmd_vel` sent at once). The command is held until the next one.
    pub fn halt(&mut self, why: Halt) {
        let _ = why;
        self.plant.stop();
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
            name: self.config.spec.name.clone(),
            counters: self.tracker.counters,
            pending: self.delayed.len() as u64,
            published: self.seq,
            ticks: self.ticks,
            overruns: self.overruns,
            t: self.last.t,
            final_state: [s.x, s.y, s.theta, s.v, s.omega],
            final_error: self.last.e[0].hypot(self.last.e[1]),
            link: self.last.link.name().to_owned(),
            latency: self.latency.report(true),
            ros2: None,
            safety: self.safety_counts(),
        }
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
        }
    }

    /// The next header of its stream, for `state`.
    fn header_for(&mut self, state: RobotState) -> (Header, RobotState) {
        let h = Header {
            source: self.source,
            seq: self.seq,
        };
        self.seq += 1;
        (h, state)
    }
}

impl Safety {
    /// The act step ([`AgentSpec::act`]) through this robot's filter at
    /// local time `local` (fleet time `t`) for a robot in state `me`: the
    /// command for its plant, counted (`docs/safety.md`, "In the fleet").
    fn act(
        &mut self,
        config: &RobotConfig,
        local: f64,
        t: f64,
        me: &State,
        nominal: Command,
    ) -> Command {
        let Some(settings) = config.safety.as_ref() else {
            return config.spec.act(t, me, nominal, None).command;
        };
        let l = config.spec.placement.l;
        let sight = self
            .table
            .build(local, t, point(me, l), settings.config.range);
        let guard = Guard {
            filter: &mut self.filter,
            sight,
            obstacles: &settings.obstacles,
        };
        let act = config.spec.act(t, me, nominal, Some(guard));
        let c = &mut self.counts;
        c.steps += 1;
        if let Some(g) = act.safety {
            if g.outcome != Outcome::Nominal {
                c.active += 1;
            }
            if g.stale {
                c.stale_brakes += 1;
            } else if g.outcome == Outcome::Braked {
                c.infeasible += 1;
            }
            if g.min_distance.is_finite() {
                let d = g.min_distance;
                c.min_distance = Some(c.min_distance.map_or(d, |m| m.min(d)));
            }
        }
        act.command
    }
}

/// Runs the robot until `duration` or the stop flag: the Zenoh driver of
/// [`Robot`].
pub fn run(opts: RobotOptions, stop: &StopFlag) -> Result<RobotReport, FleetError> {
    let fleet: FleetSettings = opts.scenario.fleet()?;
    let config = RobotConfig::from_scenario(
        &opts.scenario,
        &fleet,
        opts.agent,
        opts.faults,
        opts.duration,
    )?;
    let keys = Keys::new(opts.fleet.as_deref().unwrap_or(&fleet.name));
    let leader_key = match config.spec.leader {
        Leader::Reference => keys.reference(),
        Leader::Agent(j) => keys.state(j as u32 + 1),
    };

    let session = net::open(&opts.net)?;
    let (tx, rx) = mpsc::channel::<Arrival>();
    let _subscriber = session
        .declare_subscriber(&leader_key)
        .callback(move |sample| {
            let delay = latency::delay_ns(sample.timestamp(), crate::unix_nanos());
            let _ = tx.send((
                Instant::now(),
                delay,
                sample.payload().to_bytes().into_owned(),
            ));
        })
        .wait()
        .map_err(|e| FleetError::Zenoh(format!("subscribing to {leader_key}: {e}")))?;
    // With a safety filter: every robot's state, decoded where it arrives
    // (the bytes are not copied; the table keeps one slot per agent).
    let (ntx, nrx) = mpsc::channel::<NeighbourArrival>();
    let _neighbours = match config.safety {
        Some(_) => {
            let key = keys.states();
            Some(
                session
                    .declare_subscriber(&key)
                    .callback(move |sample| {
                        let msg = wire::decode(&sample.payload().to_bytes());
                        let _ = ntx.send((Instant::now(), msg));
                    })
                    .wait()
                    .map_err(|e| FleetError::Zenoh(format!("subscribing to {key}: {e}")))?,
            )
        }
        None => None,
    };
    let publisher = session
        .declare_publisher(keys.state(opts.agent))
        .wait()
        .map_err(|e| FleetError::Zenoh(format!("declaring the state publisher: {e}")))?;
    let _token = session
        .liveliness()
        .declare_token(keys.alive(&robot_role(opts.agent)))
        .wait()
        .map_err(|e| FleetError::Zenoh(format!("liveliness: {e}")))?;

    let driver = Driver {
        clock: FleetClock::new(opts.time_scale),
        rx,
        neighbours: nrx,
        publisher,
        session: &session,
        stats_key: keys.stats(opts.agent),
    };
    let report = if opts.ros2 {
        let link = fleet.ros2[opts.agent as usize - 1].clone();
        let Some(robot) = config.spec.velocity_robot() else {
            return Err(FleetError::Config(format!(
                "agent {}: a ROS 2 robot takes velocity commands: give it a velocity base (drive = \"velocity\") and the kinematic law",
                opts.agent
            )));
        };
        let ros = Ros2Endpoint::declare(&session, &link, opts.agent)?;
        let drive = Ros2Drive::new(link, robot.base, ros.gid, ZenohCmdSink(&ros.publisher));
        let robot = Robot::new(config, drive, net::rand_source());
        let clock = driver.clock;
        let (robot, result) = driver.run(robot, stop, |robot| {
            while let Ok((arrival, key, bytes)) = ros.odom.try_recv() {
                let t = robot.fleet_time(clock.at(arrival));
                // Refusals are counted in the drive's report.
                let _ = robot.plant_mut().on_odom(&key, &bytes, t);
            }
        });
        result?;
        RobotReport {
            ros2: Some(*robot.plant().counters()),
            ..robot.report()
        }
    } else {
        let (robot, result) =
            driver.run(Robot::simulated(config, net::rand_source()), stop, |_| {});
        result?;
        robot.report()
    };
    let _ = session.close().wait();
    Ok(report)
}

/// A leader-stream sample as the subscription hands it over: when it
/// arrived, its delay since the sender's stamp (ns), its bytes.
type Arrival = (Instant, Option<i64>, Vec<u8>);

/// Another robot's state as the neighbour subscription hands it over.
type NeighbourArrival = (Instant, Result<Message, DecodeError>);

/// The Zenoh side of [`run`] for any plant.
struct Driver<'a> {
    clock: FleetClock,
    rx: mpsc::Receiver<Arrival>,
    neighbours: mpsc::Receiver<NeighbourArrival>,
    publisher: zenoh::pubsub::Publisher<'a>,
    session: &'a zenoh::Session,
    stats_key: String,
}

impl Driver<'_> {
    /// Ticks `robot` until its duration or the stop flag; `feed` hands the
    /// plant what arrived for it before each tick. The robot has been
    /// [finished](Robot::finish) (zero commanded) when this returns.
    fn run<P: Plant>(
        self,
        mut robot: Robot<P>,
        stop: &StopFlag,
        mut feed: impl FnMut(&mut Robot<P>),
    ) -> (Robot<P>, Result<(), FleetError>) {
        let clock = self.clock;
        let mut buf = Vec::with_capacity(wire::STATE_LEN);
        let nap = Duration::from_millis(20);
        let mut failure = None;
        while !stop.is_raised() {
            clock.sleep_until(robot.next_wake(), nap);
            if !robot.is_due(clock.now()) {
                continue;
            }
            while let Ok((arrival, delay, bytes)) = self.rx.try_recv() {
                robot.on_stamped_message(&bytes, clock.at(arrival), delay);
            }
            while let Ok((arrival, msg)) = self.neighbours.try_recv() {
                robot.on_neighbour(msg, clock.at(arrival));
            }
            feed(&mut robot);
            let out = robot.tick(clock.now());
            if let Some((h, state)) = out.publish {
                wire::encode_state(&mut buf, h, &state);
                if let Err(e) = net::publish(self.session, &self.publisher, &buf) {
                    failure = Some(e);
                    break;
                }
            }
            if let Some(stats) = out.stats {
                publish_stats(self.session, &self.stats_key, &stats);
            }
            if out.done {
                break;
            }
        }
        let stats = robot.finish();
        if failure.is_none()
            && let Some(why) = robot.diverged()
        {
            failure = Some(FleetError::Diverged(why.to_owned()));
        }
        if failure.is_none() {
            publish_stats(self.session, &self.stats_key, &stats);
        }
        (robot, failure.map_or(Ok(()), Err))
    }
}

/// Agent `k`'s ROS 2 presence: a node `<namespace>/echelon_robot` with a
/// `cmd_vel` publisher and an `odom` subscription, as rmw_zenoh declares
/// them (liveliness tokens), and the odometry that arrives.
pub(crate) struct Ros2Endpoint<'a> {
    pub(crate) publisher: zenoh::pubsub::Publisher<'a>,
    pub(crate) gid: Gid,
    pub(crate) odom: mpsc::Receiver<(Instant, String, Vec<u8>)>,
    _subscriber: zenoh::pubsub::Subscriber<()>,
    _tokens: Vec<zenoh::liveliness::LivelinessToken>,
}

impl<'a> Ros2Endpoint<'a> {
    pub(crate) fn declare(
        session: &'a zenoh::Session,
        link: &Ros2Link,
        agent: u32,
    ) -> Result<Ros2Endpoint<'a>, FleetError> {
        let zid = session.zid().to_string();
        let node = NodeInfo::new(link.domain_id, &zid, 0, &link.namespace, "echelon_robot")
            .map_err(|e| FleetError::Config(format!("agent {agent}: {e}")))?;
        let cmd_type = cmd_vel_type(link);
        let pub_token = node.publisher_token(1, &link.cmd_vel, &cmd_type, &Qos::default());
        let tokens = declare_tokens(
            session,
            &[
                node.node_token(),
                pub_token.clone(),
                node.subscription_token(2, &link.odom, &ODOMETRY, &Qos::default()),
            ],
        )?;
        let (tx, odom) = mpsc::channel();
        // Any type on the odom topic, so a publisher of the wrong type is
        // seen, counted and refused rather than never heard.
        let odom_key = topic_key_any_type(link.key_scheme, link.domain_id, &link.odom);
        let subscriber = session
            .declare_subscriber(&odom_key)
            .callback(move |s| {
                let _ = tx.send((
                    Instant::now(),
                    s.key_expr().as_str().to_owned(),
                    s.payload().to_bytes().into_owned(),
                ));
            })
            .wait()
            .map_err(|e| FleetError::Zenoh(format!("subscribing to {odom_key}: {e}")))?;
        let cmd_key = topic_key(link.key_scheme, link.domain_id, &link.cmd_vel, &cmd_type);
        let publisher = session
            .declare_publisher(cmd_key.clone())
            .wait()
            .map_err(|e| FleetError::Zenoh(format!("declaring {cmd_key}: {e}")))?;
        Ok(Ros2Endpoint {
            publisher,
            gid: gid_from_token(&pub_token),
            odom,
            _subscriber: subscriber,
            _tokens: tokens,
        })
    }
}

/// `cmd_vel` through a Zenoh publisher, stamped by the system clock.
pub(crate) struct ZenohCmdSink<'a, 'b>(pub(crate) &'a zenoh::pubsub::Publisher<'b>);

impl std::fmt::Debug for ZenohCmdSink<'_, '_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("ZenohCmdSink")
    }
}

impl CmdSink for ZenohCmdSink<'_, '_> {
    fn now_ns(&self) -> i64 {
        crate::unix_nanos() as i64
    }
    fn send(&mut self, payload: &[u8], attachment: &[u8]) -> Result<(), String> {
        self.0
            .put(payload.to_vec())
            .attachment(attachment.to_vec())
            .wait()
            .map_err(|e| e.to_string())
    }
}

fn publish_stats(session: &zenoh::Session, key: &str, stats: &RobotStats) {
    if let Ok(json) = serde_json::to_vec(stats) {
        net::put_stamped(session, key, json);
    }
}

/// The robot's behaviour on a fake clock: a [`crate::leader::Leader`] and
/// robots exchanging encoded messages in one deterministic event loop, no
/// network, no sleeps.
#[cfg(test)]
mod tests {
    use super::*;
    use crate::leader::Leader as LeaderTask;
    use crate::link::predict;
    use crate::plant::SimulatedPlant;
    use echelon::follow::LeaderView;
    use echelon::model::Input;
    use echelon::model::State;
    use echelon::reference::{Order, Reference, Trajectory};

    /// The CLI's process-test fleet (`echelon-cli/tests/fleet/fast-circle.toml`),
    /// whose link-loss policy is [`EXTRAPOLATE`].
    const FAST_CIRCLE: &str = include_str!("../../echelon-cli/tests/fleet/fast-circle.toml");

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
        let fleet = s.fleet().unwrap_or_else(|e| panic!("{e}"));
        let config = RobotConfig::from_scenario(s, &fleet, agent, faults, None)
            .unwrap_or_else(|e| panic!("{e}"));
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
        let mut w = World::new(&s, vec![robot(&s, 1, FaultSpec::default())]);
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
        let mut w = World::new(
            &s,
            vec![
                robot(&s, 1, FaultSpec::default()),
                robot(&s, 2, FaultSpec::default()),
            ],
        );
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
        let mut w = World::new(
            &s,
            vec![
                robot(&s, 1, FaultSpec::default()),
                robot(&s, 2, FaultSpec::default()),
            ],
        );
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
        let mut w = World::new(
            &s,
            vec![robot(&s, 1, faults), robot(&s, 2, FaultSpec::default())],
        );
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
        let mut w = World::new(&s, vec![robot(&s, 1, FaultSpec::default())]);
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
        let mut w = World::new(&s, vec![robot(&s, 1, FaultSpec::default())]);
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
        let mut w = World::new(&s, vec![robot(&s, 1, faults)]);
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
            let mut w = World::new(&s, vec![robot(&s, 1, faults), robot(&s, 2, faults)]);
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
        let mut w = World::new(&s, vec![robot(&s, 1, faults)]);
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
        let mut w = World::new(
            &s,
            vec![
                robot(&s, 1, FaultSpec::default()),
                robot(&s, 2, FaultSpec::default()),
            ],
        );
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
        let fleet = s.fleet().unwrap_or_else(|e| panic!("{e}"));
        let config = RobotConfig::from_scenario(&s, &fleet, 1, FaultSpec::default(), None)
            .unwrap_or_else(|e| panic!("{e}"));
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
}
