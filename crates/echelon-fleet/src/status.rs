//! `echelon fleet status`: the running fleet as any machine that reaches
//! it sees it, without joining it as a member (no liveliness token, nothing
//! put).
//!
//! The observer subscribes to `echelon/<fleet>/**` and to the fleet's
//! liveliness tokens (`alive/**`, with the tokens already declared), and
//! feeds what arrives to a [`StatusView`], a state machine without I/O.
//! A robot's state goes through [`crate::collector::state_record`], the
//! record the collector logs on `/agent/K/state` and the live dashboard
//! draws its table from (link, ‖e‖, odometry and fix ages): the status
//! shows the dashboard's data, decoded in one place. Its stats message
//! (`robot/<k>/stats`) gives its hazards (the stopping ones in force and
//! the latest onset, [`HazardStats`]) and its process's CPU use
//! ([`CpuUse`]).
//!
//! Each robot is in one of four conditions ([`Condition::of`]): **lost**
//! when its liveliness token is gone or nothing of its state stream arrived
//! for more than [`LOST_AFTER`]; else from the link status of its latest
//! state: **running** (tracking, or extrapolating its leader's motion
//! through a short outage), **holding** (waiting for its leader or its
//! odometry, stopping after a lost link, or held by a watchdog: it commands
//! zero) or **stopped** (a fleet stop in force).

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::{self, Write as _};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use echelon_mcap::AgentStateRecord;
use serde::{Deserialize, Serialize};
use zenoh::Wait;
use zenoh::sample::SampleKind;

use crate::FleetError;
use crate::collector::state_record;
use crate::cost::CpuUse;
use crate::keys::{KeyKind, Keys};
use crate::net::{self, NetOptions};
use crate::role::{Member, Role};
use crate::ros2::hazard::HazardStats;
use crate::wire::{self, LinkStatus, Message};

/// A robot whose latest state arrived longer ago than this (real time) is
/// lost, even if its liveliness token is still there: robots publish at
/// their control rate, and at least every 0.1 fleet s while they wait.
pub const LOST_AFTER: Duration = Duration::from_secs(1);

/// What `fleet status` listens for by default before it answers.
pub const DEFAULT_LISTEN: Duration = Duration::from_millis(1500);

/// A robot's condition, as `fleet status` shows it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Condition {
    /// Following its leader: tracking, or extrapolating through an outage.
    Running,
    /// Alive and commanding zero: waiting for its leader or odometry,
    /// stopping after a lost link, or held by a watchdog.
    Holding,
    /// A fleet stop is in force.
    Stopped,
    /// Its liveliness token is gone, or its state stream went silent.
    Lost,
}

impl Condition {
    /// The condition of a robot whose liveliness token is there or not
    /// (`alive`) and whose latest state had link status `link`, `age` ago
    /// (`None`: no state heard).
    pub fn of(alive: bool, latest: Option<(LinkStatus, Duration)>) -> Condition {
        match latest {
            _ if !alive => Condition::Lost,
            None => Condition::Lost,
            Some((_, age)) if age > LOST_AFTER => Condition::Lost,
            Some((link, _)) => match link {
                LinkStatus::Tracking | LinkStatus::Extrapolating => Condition::Running,
                LinkStatus::Waiting | LinkStatus::Stopping | LinkStatus::Held => Condition::Holding,
                LinkStatus::Stopped => Condition::Stopped,
            },
        }
    }

    /// Its name (`running`, `holding`, `stopped`, `lost`).
    pub fn name(self) -> &'static str {
        match self {
            Condition::Running => "running",
            Condition::Holding => "holding",
            Condition::Stopped => "stopped",
            Condition::Lost => "lost",
        }
    }
}

/// The part of a robot's stats message (`robot/<k>/stats`,
/// [`crate::robot::RobotStats`]) the status shows.
#[derive(Debug, Clone, Copy, Deserialize)]
struct StatsView {
    agent: u32,
    #[serde(default)]
    hazards: Option<HazardStats>,
    #[serde(default)]
    cpu: Option<CpuUse>,
}

/// What was heard of one robot.
#[derive(Debug, Default)]
struct Heard {
    /// Its latest state's record, link status and arrival.
    state: Option<(AgentStateRecord, LinkStatus, Instant)>,
    /// Its latest stats.
    stats: Option<StatsView>,
    /// States heard.
    states: u64,
}

/// The fleet as heard so far: a state machine fed every sample and
/// liveliness change with its arrival time; [`StatusView::status`] says
/// where each robot, the leader and the collector are at an instant.
#[derive(Debug)]
pub struct StatusView {
    keys: Keys,
    /// The scenario's robots (listed even if never heard).
    expected: u32,
    robots: BTreeMap<u32, Heard>,
    /// Liveliness names with a token now.
    alive: BTreeSet<String>,
    /// The latest reference's fleet time and arrival.
    reference: Option<(f64, Instant)>,
    /// Samples under the fleet's keys that were not valid for their key.
    refused: u64,
    /// When it started listening.
    started: Instant,
}

impl StatusView {
    /// A view of fleet `keys`, listing robots 1 to `expected` whether heard
    /// or not (0: only those heard), listening from `started`.
    pub fn new(keys: Keys, expected: u32, started: Instant) -> StatusView {
        StatusView {
            keys,
            expected,
            robots: BTreeMap::new(),
            alive: BTreeSet::new(),
            reference: None,
            refused: 0,
            started,
        }
    }

    /// A sample that arrived on `key` at `at`. Anything that is not a
    /// valid state, stats or reference of its key is counted and ignored.
    pub fn on_sample(&mut self, key: &str, bytes: &[u8], at: Instant) {
        match self.keys.classify(key) {
            KeyKind::State(k) => match wire::decode(bytes) {
                Ok(Message::State(h, s)) if s.agent == k => {
                    let heard = self.robots.entry(k).or_default();
                    heard.state = Some((state_record(h.seq, &s), s.link, at));
                    heard.states += 1;
                }
                _ => self.refused += 1,
            },
            KeyKind::Stats(k) => match serde_json::from_slice::<StatsView>(bytes) {
                Ok(s) if s.agent == k => self.robots.entry(k).or_default().stats = Some(s),
                _ => self.refused += 1,
            },
            KeyKind::Reference => match wire::decode(bytes) {
                Ok(Message::Reference(_, r)) => self.reference = Some((r.t, at)),
                _ => self.refused += 1,
            },
            // The commands, halts and the rest: not shown.
            _ => {}
        }
    }

    /// A liveliness token on `key` appeared (`present`) or went away.
    pub fn on_liveliness(&mut self, key: &str, present: bool) {
        let Some(name) = key.strip_prefix(&self.keys.alive("")) else {
            return;
        };
        if present {
            self.alive.insert(name.to_owned());
        } else {
            self.alive.remove(name);
        }
    }

    /// Robot `k`'s number if `name` is its liveliness name (`robot/<k>`).
    fn robot_of(name: &str) -> Option<u32> {
        let k = name
            .strip_prefix(Role::Robot.name())?
            .strip_prefix('/')?
            .parse()
            .ok()?;
        (Member::Robot(k).liveliness() == name && k >= 1).then_some(k)
    }

    /// The fleet as heard at `now`.
    pub fn status(&self, now: Instant) -> FleetStatus {
        let age = |at: Instant| now.saturating_duration_since(at);
        let mut numbers: BTreeSet<u32> = (1..=self.expected).collect();
        numbers.extend(self.robots.keys());
        numbers.extend(self.alive.iter().filter_map(|n| Self::robot_of(n)));
        let robots = numbers
            .into_iter()
            .map(|k| {
                let alive = self.alive.contains(&Member::Robot(k).liveliness());
                let heard = self.robots.get(&k);
                let state = heard.and_then(|h| h.state.as_ref());
                let stats = heard.and_then(|h| h.stats);
                let record = state.map(|(r, _, _)| r);
                RobotStatus {
                    robot: k,
                    state: Condition::of(alive, state.map(|(_, l, at)| (*l, age(*at)))),
                    alive,
                    link: state.map(|(_, l, _)| l.name().to_owned()),
                    link_age: state.map(|(_, _, at)| age(*at).as_secs_f64()),
                    t: record.map(|r| r.sample.t),
                    error_norm: record.map(|r| r.error_norm),
                    odometry_age: record.and_then(|r| r.odometry).map(|o| o.age),
                    fix_age: record.and_then(|r| r.odometry).and_then(|o| o.fix_age),
                    hazards: stats.and_then(|s| s.hazards),
                    cpu: stats.and_then(|s| s.cpu),
                    states: heard.map_or(0, |h| h.states),
                }
            })
            .collect();
        FleetStatus {
            fleet: self.keys.fleet().to_owned(),
            listened: age(self.started).as_secs_f64(),
            robots,
            leader: LeaderStatus {
                alive: self.alive.contains(&Member::Leader.liveliness()),
                reference_age: self.reference.map(|(_, at)| age(at).as_secs_f64()),
                t: self.reference.map(|(t, _)| t),
            },
            collector: CollectorStatus {
                alive: self.alive.contains(&Member::Collector.liveliness()),
            },
            refused: self.refused,
        }
    }
}

/// One robot as `fleet status` shows it (times in seconds).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RobotStatus {
    /// Its agent number, from 1.
    pub robot: u32,
    /// Its condition.
    pub state: Condition,
    /// Whether its liveliness token is there.
    pub alive: bool,
    /// The link status of its latest state (`None`: none heard).
    pub link: Option<String>,
    /// How long ago its latest state arrived, real s: the link's age.
    pub link_age: Option<f64>,
    /// Its latest state's fleet time.
    pub t: Option<f64>,
    /// ‖e‖ of its latest state, m.
    pub error_norm: Option<f64>,
    /// A ROS 2 robot's: its newest odometry's age when it published the state.
    pub odometry_age: Option<f64>,
    /// A ROS 2 robot's: its newest accepted fix's age then.
    pub fix_age: Option<f64>,
    /// Its base's hazards (a ROS 2 base with safety words): those in
    /// force and the latest onset.
    pub hazards: Option<HazardStats>,
    /// Its process's CPU use, from its latest stats.
    pub cpu: Option<CpuUse>,
    /// States heard while listening.
    pub states: u64,
}

impl RobotStatus {
    /// Whether anything of it was heard (a token, a state, its stats).
    pub fn heard(&self) -> bool {
        self.alive || self.states > 0 || self.cpu.is_some() || self.hazards.is_some()
    }

    /// The hazard cell: the stopping hazards in force, else the latest
    /// onset (and when it cleared), else `—`.
    fn hazard_cell(&self) -> String {
        let Some(h) = &self.hazards else {
            return DASH.to_owned();
        };
        if !h.in_force.is_empty() {
            return format!("{} (in force)", h.in_force.names());
        }
        match h.last {
            Some(e) => match e.cleared {
                Some(c) => format!("{} at {:.1} s, cleared {c:.1} s", e.hazard.name(), e.at),
                None => format!("{} at {:.1} s", e.hazard.name(), e.at),
            },
            None => "none".to_owned(),
        }
    }

    /// The CPU cell: share of a core since its previous stats, and seconds.
    fn cpu_cell(&self) -> String {
        match self.cpu {
            Some(CpuUse {
                seconds,
                share: Some(s),
            }) => format!("{:.1} % ({seconds:.2} s)", 100.0 * s),
            Some(CpuUse { seconds, .. }) => format!("{seconds:.2} s"),
            None => DASH.to_owned(),
        }
    }
}

/// The leader as heard.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LeaderStatus {
    /// Whether its liveliness token is there.
    pub alive: bool,
    /// How long ago its latest reference arrived, real s.
    pub reference_age: Option<f64>,
    /// Its latest reference's fleet time.
    pub t: Option<f64>,
}

/// The collector as heard.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CollectorStatus {
    /// Whether its liveliness token is there.
    pub alive: bool,
}

/// What `fleet status` prints: `--json` as this, else as its table
/// ([`fmt::Display`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FleetStatus {
    /// The fleet's name.
    pub fleet: String,
    /// How long it listened, real s.
    pub listened: f64,
    /// Each robot, by agent number: the scenario's and any other heard.
    pub robots: Vec<RobotStatus>,
    /// The leader.
    pub leader: LeaderStatus,
    /// The collector.
    pub collector: CollectorStatus,
    /// Samples under the fleet's keys that were not valid for their key.
    pub refused: u64,
}

impl FleetStatus {
    /// Whether any robot was heard.
    pub fn heard_a_robot(&self) -> bool {
        self.robots.iter().any(RobotStatus::heard)
    }
}

const DASH: &str = "—";

/// `v` with `digits` decimals, or `—`.
fn fixed(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| DASH.to_owned(), |v| format!("{v:.digits$}"))
}

/// ‖e‖ as the dashboard shows it to the millimetre, smaller ones in
/// scientific notation.
fn error_cell(e: Option<f64>) -> String {
    match e {
        Some(e) if e != 0.0 && e.abs() < 1e-3 => format!("{e:.2e}"),
        e => fixed(e, 4),
    }
}

impl fmt::Display for FleetStatus {
    /// A line on the leader and the collector, then a table, one robot a row.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let leader = if self.leader.alive { "alive" } else { "lost" };
        let reference = match (self.leader.reference_age, self.leader.t) {
            (Some(age), Some(t)) => format!("reference {age:.2} s old (t = {t:.2} s)"),
            _ => "no reference heard".to_owned(),
        };
        let collector = if self.collector.alive {
            "alive"
        } else {
            "lost"
        };
        writeln!(
            f,
            "fleet {}: leader {leader}, {reference}; collector {collector}; listened {:.1} s",
            self.fleet, self.listened
        )?;
        let mut rows = vec![[
            "robot".to_owned(),
            "state".to_owned(),
            "link".to_owned(),
            "link age, s".to_owned(),
            "‖e‖, m".to_owned(),
            "hazard".to_owned(),
            "CPU".to_owned(),
        ]];
        for r in &self.robots {
            rows.push([
                r.robot.to_string(),
                r.state.name().to_owned(),
                r.link.clone().unwrap_or_else(|| DASH.to_owned()),
                fixed(r.link_age, 2),
                error_cell(r.error_norm),
                r.hazard_cell(),
                r.cpu_cell(),
            ]);
        }
        let mut widths = [0usize; 7];
        for row in &rows {
            for (w, cell) in widths.iter_mut().zip(row) {
                *w = (*w).max(cell.chars().count());
            }
        }
        for row in &rows {
            let mut line = String::new();
            for (i, (cell, w)) in row.iter().zip(widths).enumerate() {
                if i + 1 == row.len() {
                    line.push_str(cell);
                } else {
                    let _ = write!(line, "{cell}{}  ", " ".repeat(w - cell.chars().count()));
                }
            }
            writeln!(f, "{}", line.trim_end())?;
        }
        Ok(())
    }
}

/// Where and what `fleet status` listens to.
#[derive(Debug, Clone)]
pub struct StatusOptions {
    /// The fleet's name.
    pub fleet: String,
    /// How it joins (a client of the hub's router, usually).
    pub net: NetOptions,
    /// The scenario's robot count (listed even if never heard), or 0.
    pub robots: u32,
    /// Longest wait for the endpoints to connect to.
    pub connect_timeout: Duration,
}

/// `fleet status` listening: its session, subscriptions and view.
pub struct Listener {
    session: zenoh::Session,
    view: Arc<Mutex<StatusView>>,
    _samples: zenoh::pubsub::Subscriber<()>,
    _tokens: zenoh::pubsub::Subscriber<()>,
}

impl fmt::Debug for Listener {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Listener")
            .field("view", &self.view)
            .finish_non_exhaustive()
    }
}

impl Listener {
    /// Opens a session as `opts` says (waiting at most
    /// `opts.connect_timeout` for its endpoints: an error if they do not
    /// answer), then listens to every sample of the fleet and its
    /// liveliness tokens (those already there included).
    pub fn join(opts: &StatusOptions) -> Result<Listener, FleetError> {
        let keys = Keys::new(&opts.fleet);
        let session = net::open_within(&opts.net, opts.connect_timeout)?;
        let view = Arc::new(Mutex::new(StatusView::new(
            keys.clone(),
            opts.robots,
            Instant::now(),
        )));
        let v = view.clone();
        let samples = session
            .declare_subscriber(keys.everything())
            .callback(move |s| {
                let at = Instant::now();
                let bytes = s.payload().to_bytes();
                if let Ok(mut v) = v.lock() {
                    v.on_sample(s.key_expr().as_str(), &bytes, at);
                }
            })
            .wait()
            .map_err(|e| FleetError::Zenoh(format!("subscribing to {}: {e}", keys.everything())))?;
        let v = view.clone();
        let tokens = session
            .liveliness()
            .declare_subscriber(keys.alive("**"))
            .history(true)
            .callback(move |s| {
                if let Ok(mut v) = v.lock() {
                    v.on_liveliness(s.key_expr().as_str(), s.kind() == SampleKind::Put);
                }
            })
            .wait()
            .map_err(|e| FleetError::Zenoh(format!("liveliness: {e}")))?;
        Ok(Listener {
            session,
            view,
            _samples: samples,
            _tokens: tokens,
        })
    }

    /// The fleet as heard so far.
    pub fn status(&self) -> FleetStatus {
        let now = Instant::now();
        match self.view.lock() {
            Ok(v) => v.status(now),
            Err(poisoned) => poisoned.into_inner().status(now),
        }
    }

    /// Closes the session.
    pub fn close(self) {
        let _ = self.session.close().wait();
    }
}

#[cfg(test)]
mod tests;
