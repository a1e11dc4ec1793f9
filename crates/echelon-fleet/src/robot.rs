//! `echelon fleet robot`: one agent of a scenario as its own process.
//!
//! Every tick (the `[fleet] control_rate`): take what arrived from the leader
//! stream (through fault injection, decoding and the sequence/staleness
//! checks), bring the plant to now, predict the leader motion (fresh, or the
//! link-loss policy), run the law (eq. 13, `echelon::control::law`) and
//! publish the state with the leader motion used.

use std::collections::VecDeque;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use serde::Serialize;
use zenoh::Wait;

use echelon::control::{LeaderMotion, law};
use echelon::formation::Leader;
use echelon::model::State;
use echelon::scenario::{FleetSettings, Overrides, Scenario};
use echelon::sim::AgentSpec;

use crate::clock::FleetClock;
use crate::faults::{FaultInjector, FaultSpec, Verdict};
use crate::keys::{Keys, robot_role};
use crate::link::{Counters, LeaderSample, Predicted, StreamTracker, predict};
use crate::net::{self, NetOptions};
use crate::plant::{Plant, SimulatedPlant};
use crate::wire::{self, DecodeError, Header, LinkStatus, Message, RobotState};
use crate::{FleetError, StopFlag};

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
}

/// What a robot reports when it stops (one JSON line on stdout).
#[derive(Debug, Clone, Serialize)]
pub struct RobotReport {
    /// `robot`.
    pub role: &'static str,
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
    pub link: &'static str,
}

/// The stats message published on `echelon/<fleet>/robot/<k>/stats`.
#[derive(Debug, Clone, Serialize)]
struct Stats<'a> {
    agent: u32,
    t: f64,
    link: &'static str,
    counters: &'a Counters,
    published: u64,
    overruns: u64,
}

/// The agent's spec from the scenario, checked for the fleet.
pub fn agent_spec(scenario: &Scenario, agent: u32) -> Result<AgentSpec, FleetError> {
    let run = scenario.build(&Overrides::default())?;
    let agents = run.simulation.agents();
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

/// Runs the robot until `duration` or the stop flag.
pub fn run(opts: RobotOptions, stop: &StopFlag) -> Result<RobotReport, FleetError> {
    let fleet: FleetSettings = opts.scenario.fleet()?;
    let spec = agent_spec(&opts.scenario, opts.agent)?;
    let loss = fleet.link_loss[opts.agent as usize - 1];
    let keys = Keys::new(opts.fleet.as_deref().unwrap_or(&fleet.name));
    let leader_key = match spec.leader {
        Leader::Reference => keys.reference(),
        Leader::Agent(j) => keys.state(j as u32 + 1),
    };

    let session = net::open(&opts.net)?;
    let (tx, rx) = mpsc::channel::<(Instant, Vec<u8>)>();
    let _subscriber = session
        .declare_subscriber(&leader_key)
        .callback(move |sample| {
            let _ = tx.send((Instant::now(), sample.payload().to_bytes().into_owned()));
        })
        .wait()
        .map_err(|e| FleetError::Zenoh(format!("subscribing to {leader_key}: {e}")))?;
    let publisher = session
        .declare_publisher(keys.state(opts.agent))
        .wait()
        .map_err(|e| FleetError::Zenoh(format!("declaring the state publisher: {e}")))?;
    let stats_key = keys.stats(opts.agent);
    let _token = session
        .liveliness()
        .declare_token(keys.alive(&robot_role(opts.agent)))
        .wait()
        .map_err(|e| FleetError::Zenoh(format!("liveliness: {e}")))?;

    let source: u32 = net::rand_source();
    let period = 1.0 / fleet.control_rate;
    let mut clock = FleetClock::new(opts.time_scale);
    let mut synced = false;
    let mut plant = SimulatedPlant::new(spec.robot, spec.start, 0.0, PLANT_STEP);
    let mut tracker = StreamTracker::new(fleet.stale_after);
    let mut injector = FaultInjector::new(opts.faults, u64::from(opts.agent));
    let mut delayed: VecDeque<(f64, Header, LeaderSample)> = VecDeque::new();
    let mut sample: Option<LeaderSample> = None;
    let mut fresh = false;
    let mut next_tick = 0.0;
    let mut next_stats = 0.0;
    let mut seq: u64 = 0;
    let mut ticks: u64 = 0;
    let mut overruns: u64 = 0;
    let mut buf = Vec::with_capacity(wire::STATE_LEN);
    let mut last = RobotState {
        agent: opts.agent,
        state: spec.start,
        ..RobotState::default()
    };
    let nap = Duration::from_millis(20);

    while !stop.is_raised() {
        clock.sleep_until(next_tick, nap);
        let now = clock.now();
        if now < next_tick {
            continue;
        }
        // What arrived: decode, sync, inject faults, queue for delivery.
        while let Ok((arrival, bytes)) = rx.try_recv() {
            tracker.counters.received += 1;
            let msg = match wire::decode(&bytes) {
                Ok(m) => m,
                Err(DecodeError::Malformed(_)) => {
                    tracker.counters.malformed += 1;
                    continue;
                }
                Err(DecodeError::WrongVersion(_)) => {
                    tracker.counters.wrong_version += 1;
                    continue;
                }
            };
            let Some((h, s)) = sample_of(&msg, spec.leader) else {
                tracker.counters.foreign += 1;
                continue;
            };
            let arrived = clock.at(arrival);
            let resync =
                !synced || (tracker.is_new_source(&h) && (arrived - s.t).abs() > fleet.stale_after);
            if resync {
                // Fleet time is the leader's: the first message (or a
                // restarted leader's) sets the clock.
                clock.sync(s.t, arrival);
                plant.set_time(s.t);
                next_tick = s.t;
                next_stats = s.t;
                // The old leader's samples are on the old timeline: at the
                // new clock they would look fresh, even from the future.
                delayed.clear();
                sample = None;
                synced = true;
            }
            match injector.admit(clock.at(arrival)) {
                Verdict::Lost => tracker.counters.injected_loss += 1,
                Verdict::Outage => tracker.counters.injected_outage += 1,
                Verdict::DeliverAt(at) => delayed.push_back((at, h, s)),
            }
        }
        let now = clock.now();
        while let Some(&(at, h, s)) = delayed.front() {
            if at > now {
                break;
            }
            delayed.pop_front();
            if tracker.check(h, s.t, at).is_ok() {
                sample = Some(s);
            }
        }

        let prediction = match (synced, sample) {
            (true, Some(s)) => Some(predict(&s, now, fleet.link_timeout, &loss)),
            _ => None,
        };
        let Some(Predicted {
            motion,
            speed,
            turn_rate,
            status,
        }) = prediction
        else {
            // Waiting for the leader: stand still, say so now and then.
            if synced {
                plant.advance(now);
            }
            last = RobotState {
                t: if synced { now } else { 0.0 },
                agent: opts.agent,
                link: LinkStatus::Waiting,
                state: plant.state(),
                ..RobotState::default()
            };
            publish_state(&publisher, &mut buf, source, &mut seq, &last)?;
            next_tick = now + WAITING_PERIOD.min(period * 10.0);
            continue;
        };
        if status == LinkStatus::Tracking {
            fresh = true;
        } else if fresh {
            fresh = false;
            tracker.counters.link_losses += 1;
        }

        plant.advance(now);
        let state: State = plant.state();
        let offset = spec.placement.offset_for_robot(speed, turn_rate);
        let out = law(
            &spec.robot,
            &state,
            &motion,
            &offset,
            spec.gains,
            spec.variant,
        );
        let act = plant.command(out.u);
        let (dv, domega) = plant.accelerations();
        last = RobotState {
            t: now,
            agent: opts.agent,
            link: status,
            state,
            dv,
            domega,
            e: out.e,
            z: out.z,
            u: act.u,
            tau: act.tau,
            leader: motion,
        };
        publish_state(&publisher, &mut buf, source, &mut seq, &last)?;
        ticks += 1;

        if now >= next_stats {
            next_stats += 1.0;
            publish_stats(
                &session, &stats_key, opts.agent, now, status, &tracker, seq, overruns,
            );
        }
        if opts.duration.is_some_and(|d| now >= d) {
            break;
        }
        next_tick += period;
        if now - next_tick > period {
            // Late by more than a period: the plant keeps moving in real time;
            // the controller resumes on the next tick from now.
            overruns += 1;
            next_tick = now + period;
        }
    }
    publish_stats(
        &session, &stats_key, opts.agent, last.t, last.link, &tracker, seq, overruns,
    );
    drop(publisher);
    let _ = session.close().wait();
    let s = last.state;
    Ok(RobotReport {
        role: "robot",
        agent: opts.agent,
        name: spec.name,
        counters: tracker.counters,
        pending: delayed.len() as u64,
        published: seq,
        ticks,
        overruns,
        t: last.t,
        final_state: [s.x, s.y, s.theta, s.v, s.omega],
        final_error: last.e[0].hypot(last.e[1]),
        link: last.link.name(),
    })
}

/// Publishes `state` under the robot's next sequence number.
fn publish_state(
    publisher: &zenoh::pubsub::Publisher<'_>,
    buf: &mut Vec<u8>,
    source: u32,
    seq: &mut u64,
    state: &RobotState,
) -> Result<(), FleetError> {
    wire::encode_state(buf, Header { source, seq: *seq }, state);
    net::publish(publisher, buf)?;
    *seq += 1;
    Ok(())
}

#[allow(clippy::too_many_arguments)]
fn publish_stats(
    session: &zenoh::Session,
    key: &str,
    agent: u32,
    t: f64,
    link: LinkStatus,
    tracker: &StreamTracker,
    published: u64,
    overruns: u64,
) {
    let stats = Stats {
        agent,
        t,
        link: link.name(),
        counters: &tracker.counters,
        published,
        overruns,
    };
    if let Ok(json) = serde_json::to_vec(&stats) {
        let _ = session.put(key, json).wait();
    }
}
