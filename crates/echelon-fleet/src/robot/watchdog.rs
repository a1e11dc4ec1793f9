//! A robot's watchdogs: the odometry's age (every plant, simulated or a
//! ROS 2 base), its commands' reader (a ROS 2 base's `cmd_vel` subscriber,
//! [`Plant::command_reader_lost`]) and, in a supervised run (`[fleet]
//! operator_heartbeat`), the operator's heartbeat ([`crate::heartbeat`]). The leader stream's age is
//! the link-loss policy's ([`crate::link::predict`]).
//!
//! A watchdog that trips holds the robot: the tick is a standstill one,
//! which commands zero ([`Robot::halt`]) and publishes the state with the
//! link status `held`, as a fleet stop does with `stopped` (so neighbours
//! take it as a robot that brakes, [`crate::neighbours`]). The robot
//! follows again at the first tick its watchdogs are satisfied: fresh
//! odometry, a heartbeat within the deadline (the same rule as a leader
//! stream that comes back). Each trip is counted.

use serde::{Deserialize, Serialize};

use crate::heartbeat::Heartbeat;
use crate::plant::Plant;

use super::Robot;

/// What a robot's watchdogs watch, and how long they wait.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WatchdogSettings {
    /// Odometry older than this holds the robot, fleet s (a ROS 2 base's
    /// `odom_timeout`; a simulated robot's, two control periods).
    pub odom_timeout: f64,
    /// No operator heartbeat for this long holds it, fleet s (`None`: the
    /// scenario asks for none).
    pub operator_heartbeat: Option<f64>,
}

/// Which watchdog holds a robot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Watchdog {
    /// Its odometry is stale (older than `odom_timeout`) or lost.
    Odometry,
    /// The operator's heartbeat is older than `operator_heartbeat`.
    Operator,
    /// Its commands have no reader any more (a ROS 2 base's `cmd_vel`
    /// subscriber gone: its driver crashed or was killed).
    Output,
}

impl Watchdog {
    /// Its name in logs.
    pub fn name(self) -> &'static str {
        match self {
            Watchdog::Odometry => "odometry",
            Watchdog::Operator => "operator",
            Watchdog::Output => "output",
        }
    }
}

/// What the watchdogs did.
#[derive(
    Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(deny_unknown_fields)]
pub struct WatchdogCounts {
    /// Times stale or lost odometry held the robot.
    pub odometry: u64,
    /// Times a lost operator heartbeat held it.
    pub operator: u64,
    /// Times its commands lost their reader (the base's `cmd_vel`
    /// subscriber) and that held it.
    #[serde(default)]
    pub output: u64,
    /// Control ticks spent held by a watchdog.
    pub held_ticks: u64,
    /// Operator heartbeats accepted.
    pub heartbeats: u64,
    /// Operator heartbeats refused (malformed, or not newer than the last
    /// of their source).
    pub heartbeats_refused: u64,
}

/// The watchdogs' state in a robot.
#[derive(Debug, Clone, Default)]
pub(super) struct Watchdogs {
    /// The heartbeat source and number last accepted, and when (local s).
    heartbeat: Option<(Heartbeat, f64)>,
    /// The watchdog holding the robot at its last tick.
    holding: Option<Watchdog>,
    pub(super) counts: WatchdogCounts,
}

impl<P: Plant> Robot<P> {
    /// Takes a payload that arrived on the operator heartbeat key at local
    /// time `now`: accepted if it is a heartbeat newer than the last of its
    /// source (a new source starts over), else refused; counted either way.
    pub fn on_heartbeat(&mut self, bytes: &[u8], now: f64) {
        let w = &mut self.watchdogs;
        match Heartbeat::decode(bytes) {
            Some(h) if w.heartbeat.is_none_or(|(last, _)| h.follows(&last)) => {
                w.heartbeat = Some((h, now));
                w.counts.heartbeats += 1;
            }
            _ => w.counts.heartbeats_refused += 1,
        }
    }

    /// What its watchdogs did.
    pub fn watchdog_counts(&self) -> WatchdogCounts {
        self.watchdogs.counts
    }

    /// The watchdog that holds the robot at local time `local` (its plant
    /// brought to its fleet time), if any: the odometry first, then the
    /// operator's heartbeat. Counts a trip when one starts holding.
    pub(super) fn watchdog_holding(&mut self, local: f64) -> Option<Watchdog> {
        let settings = self.config.watchdogs;
        let odometry_stale = match (self.plant.state(), self.plant.odometry_age()) {
            (Some(_), Some(age)) => age > settings.odom_timeout,
            _ => true,
        };
        let operator_lost = settings.operator_heartbeat.is_some_and(|limit| {
            self.watchdogs
                .heartbeat
                .is_none_or(|(_, at)| local - at > limit)
        });
        let output_lost = self.plant.command_reader_lost();
        let holding = if odometry_stale {
            Some(Watchdog::Odometry)
        } else if output_lost {
            Some(Watchdog::Output)
        } else if operator_lost {
            Some(Watchdog::Operator)
        } else {
            None
        };
        let w = &mut self.watchdogs;
        if holding.is_some() && holding != w.holding {
            match holding {
                Some(Watchdog::Odometry) => w.counts.odometry += 1,
                Some(Watchdog::Operator) => w.counts.operator += 1,
                Some(Watchdog::Output) => {
                    w.counts.output += 1;
                    eprintln!(
                        "robot {}: its commands have no reader (the base's cmd_vel subscriber is gone): held",
                        self.config.agent
                    );
                }
                None => {}
            }
        }
        w.holding = holding;
        if holding.is_some() {
            w.counts.held_ticks += 1;
        }
        holding
    }
}
