//! A base's own safety words, which the fleet obeys: an iRobot Create 3's
//! `hazard_detection` (`irobot_create_msgs/msg/HazardDetectionVector`) and
//! an e-stop `std_msgs/msg/Bool` (a Jackal's `platform/emergency_stop`,
//! `true` = stop).
//!
//! [`BaseSafety`] is sans-IO: it is handed the samples that arrived with
//! their fleet time and answers which stopping hazards are in force
//! ([`BaseSafety::in_force`]). The rules:
//!
//! - a Create 3 reports every hazard it detects *now*, as one vector, over
//!   and over while it lasts; BUMP, CLIFF, STALL and WHEEL_DROP stop the
//!   robot (and, through the robot, the fleet: `robot/mod.rs`);
//!   OBJECT_PROXIMITY and BACKUP_LIMIT are counted and logged, never a stop
//!   (the base already refuses to back up further; echelon's
//!   `reverse_limit` keeps the law from asking it to);
//! - a stopping hazard is in force from the first vector that reports it
//!   until a vector without it arrives, or until no vector has reported it
//!   for [`HAZARD_CLEAR_AFTER`] (a base that only publishes while hazards
//!   last);
//! - an e-stop is in force from a `true` until a `false`: it is latched by
//!   the base, never by silence;
//! - a sample that is not the type on the key, not CDR of it, or holds an
//!   unknown hazard type is counted and refused; it changes nothing (a
//!   refused vector clears nothing).
//!
//! Every onset is an event with its fleet time, and its clearing time once
//! it cleared ([`HazardEvent`]): in the robot's report, its stats (and so
//! the collector's MCAP) and the fleet stop it puts, whose reason names it.

use serde::{Deserialize, Serialize};

use echelon_ros2::keys::check_topic_key;
use echelon_ros2::msgs::{
    BOOL, Bool, HAZARD_DETECTION_VECTOR, HazardDetection, HazardDetectionVector, RosMessage,
};
use echelon_ros2::names::KeyScheme;

use super::refusal::SampleRefusal;

/// How long a stopping hazard stays in force after the last vector that
/// reported it, when no vector without it arrives, s.
pub const HAZARD_CLEAR_AFTER: f64 = 1.0;
/// The most events a report keeps (the first ones; later onsets are
/// counted only).
pub const MAX_EVENTS: usize = 256;

/// One safety word of a base.
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    PartialOrd,
    Ord,
    Hash,
    Serialize,
    Deserialize,
    schemars::JsonSchema,
)]
#[serde(rename_all = "SCREAMING_SNAKE_CASE")]
pub enum Hazard {
    /// The base backed up as far as it will without its safety override
    /// (Create 3 `BACKUP_LIMIT`, 0): logged.
    BackupLimit,
    /// A bumper pressed (`BUMP`, 1): stops.
    Bump,
    /// A cliff below a sensor (`CLIFF`, 2): stops.
    Cliff,
    /// The wheels stalled (`STALL`, 3): stops.
    Stall,
    /// The wheels dropped: the robot is lifted (`WHEEL_DROP`, 4): stops.
    WheelDrop,
    /// An obstacle close to the IR sensors (`OBJECT_PROXIMITY`, 5): logged.
    ObjectProximity,
    /// The base's e-stop is pressed (a `true` on its e-stop topic): stops.
    EmergencyStop,
}

impl Hazard {
    /// Every hazard, in bit order.
    pub const ALL: [Hazard; 7] = [
        Hazard::BackupLimit,
        Hazard::Bump,
        Hazard::Cliff,
        Hazard::Stall,
        Hazard::WheelDrop,
        Hazard::ObjectProximity,
        Hazard::EmergencyStop,
    ];

    /// The hazard of a Create 3 `HazardDetection.type` (`None`: a type the
    /// message does not define).
    pub fn of_create3(ty: u8) -> Option<Hazard> {
        Some(match ty {
            HazardDetection::BACKUP_LIMIT => Hazard::BackupLimit,
            HazardDetection::BUMP => Hazard::Bump,
            HazardDetection::CLIFF => Hazard::Cliff,
            HazardDetection::STALL => Hazard::Stall,
            HazardDetection::WHEEL_DROP => Hazard::WheelDrop,
            HazardDetection::OBJECT_PROXIMITY => Hazard::ObjectProximity,
            _ => return None,
        })
    }

    /// Its name, as the message's constant (`BUMP`; `EMERGENCY_STOP`).
    pub fn name(self) -> &'static str {
        match self {
            Hazard::BackupLimit => "BACKUP_LIMIT",
            Hazard::Bump => "BUMP",
            Hazard::Cliff => "CLIFF",
            Hazard::Stall => "STALL",
            Hazard::WheelDrop => "WHEEL_DROP",
            Hazard::ObjectProximity => "OBJECT_PROXIMITY",
            Hazard::EmergencyStop => "EMERGENCY_STOP",
        }
    }

    /// The hazard of a name ([`Hazard::name`]).
    pub fn from_name(name: &str) -> Option<Hazard> {
        Hazard::ALL.into_iter().find(|h| h.name() == name)
    }

    /// Whether it stops the robot and pauses the fleet.
    pub fn stops(self) -> bool {
        matches!(
            self,
            Hazard::Bump
                | Hazard::Cliff
                | Hazard::Stall
                | Hazard::WheelDrop
                | Hazard::EmergencyStop
        )
    }

    fn bit(self) -> u8 {
        1 << (self as u8)
    }
}

/// A set of hazards.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct HazardSet(u8);

impl HazardSet {
    /// No hazard.
    pub const EMPTY: HazardSet = HazardSet(0);

    /// Whether it holds none.
    pub fn is_empty(&self) -> bool {
        self.0 == 0
    }

    /// Whether it holds `h`.
    pub fn contains(self, h: Hazard) -> bool {
        self.0 & h.bit() != 0
    }

    /// It with `h`.
    pub fn with(self, h: Hazard) -> HazardSet {
        HazardSet(self.0 | h.bit())
    }

    /// Its hazards that stop ([`Hazard::stops`]).
    pub fn stopping(self) -> HazardSet {
        HazardSet(
            Hazard::ALL
                .iter()
                .filter(|h| h.stops())
                .fold(0, |m, h| m | h.bit())
                & self.0,
        )
    }

    /// Its hazards, in bit order.
    pub fn iter(self) -> impl Iterator<Item = Hazard> {
        Hazard::ALL.into_iter().filter(move |h| self.contains(*h))
    }

    /// Its names joined by `+` (`BUMP+CLIFF`; empty: none).
    pub fn names(self) -> String {
        self.iter().map(Hazard::name).collect::<Vec<_>>().join("+")
    }
}

impl FromIterator<Hazard> for HazardSet {
    fn from_iter<I: IntoIterator<Item = Hazard>>(iter: I) -> HazardSet {
        iter.into_iter().fold(HazardSet::EMPTY, HazardSet::with)
    }
}

impl Serialize for HazardSet {
    /// As the list of its names.
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq(self.iter())
    }
}

impl<'de> Deserialize<'de> for HazardSet {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<HazardSet, D::Error> {
        let names = Vec::<Hazard>::deserialize(d)?;
        Ok(names.into_iter().collect())
    }
}

impl schemars::JsonSchema for HazardSet {
    fn schema_name() -> std::borrow::Cow<'static, str> {
        "HazardSet".into()
    }
    fn json_schema(g: &mut schemars::SchemaGenerator) -> schemars::Schema {
        <Vec<Hazard>>::json_schema(g)
    }
}

/// One stopping hazard's episode: from the sample that reported it to the
/// one that cleared it, fleet time.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct HazardEvent {
    /// What.
    pub hazard: Hazard,
    /// Its onset, fleet s.
    pub at: f64,
    /// When it cleared, fleet s (`None`: still in force at the end).
    pub cleared: Option<f64>,
}

/// What a base's safety words did.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(deny_unknown_fields)]
pub struct HazardCounts {
    /// Hazard vectors received.
    pub hazard_received: u64,
    /// Refused: the wrong type on the key, not CDR of it, or an unknown
    /// hazard type.
    pub hazard_refused: u64,
    /// E-stop samples received.
    pub estop_received: u64,
    /// Refused: the wrong type on the key, or not CDR of a `Bool`.
    pub estop_refused: u64,
    /// Vectors reporting an obstacle close by (logged, not a stop).
    pub object_proximity: u64,
    /// Vectors reporting the backup limit (logged, not a stop).
    pub backup_limit: u64,
    /// Onsets of stopping hazards (each one an event while fewer than
    /// [`MAX_EVENTS`]).
    pub onsets: u64,
}

/// What [`BaseSafety`] says in a robot's stats, once per fleet second.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct HazardStats {
    /// The stopping hazards in force.
    pub in_force: HazardSet,
    /// Counters.
    pub counts: HazardCounts,
    /// The latest onset, with its clearing time once it cleared (`None`:
    /// none yet).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub last: Option<HazardEvent>,
}

/// What [`BaseSafety`] reports (the robot's report).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct HazardReport {
    /// The stopping hazards in force at the end.
    pub in_force: HazardSet,
    /// Counters.
    pub counts: HazardCounts,
    /// The episodes, in order of onset (at most [`MAX_EVENTS`]).
    pub events: Vec<HazardEvent>,
    /// The latest onset, with its clearing time once it cleared (kept
    /// past [`MAX_EVENTS`]; `None`: none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub last: Option<HazardEvent>,
}

impl HazardReport {
    /// Its stats part.
    pub fn stats(&self) -> HazardStats {
        HazardStats {
            in_force: self.in_force,
            counts: self.counts,
            last: self.last,
        }
    }
}

/// A hazard a simulated base reports over `[from, from + duration)` of its
/// own clock, s (scaled; it starts with the fleet, a moment before the
/// leader) (`fleet base --hazard BUMP@12+3`, `fleet up --ros2 --hazard
/// 2:BUMP@12+3`; `EMERGENCY_STOP` is an e-stop): the rehearsal of a bump
/// before a real robot meets one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HazardWindow {
    /// What.
    pub hazard: Hazard,
    /// From, fleet s.
    pub from: f64,
    /// For how long, s.
    pub duration: f64,
}

impl HazardWindow {
    /// Whether it is reported at time `t` of the base's clock.
    pub fn covers(&self, t: f64) -> bool {
        t >= self.from && t < self.from + self.duration
    }
}

impl std::fmt::Display for HazardWindow {
    /// As it is parsed: `BUMP@12+3`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}@{}+{}", self.hazard.name(), self.from, self.duration)
    }
}

impl std::str::FromStr for HazardWindow {
    type Err = String;

    /// `NAME@FROM+DURATION` (`BUMP@12+3`, names as [`Hazard::name`], any
    /// case), times in seconds of the base's clock, finite, `FROM ≥ 0`, `DURATION > 0`.
    fn from_str(s: &str) -> Result<HazardWindow, String> {
        let usage = || {
            format!(
                "`{s}`: give NAME@FROM+DURATION, e.g. BUMP@12+3 (names: {})",
                Hazard::ALL.map(Hazard::name).join(", ")
            )
        };
        let (name, times) = s.split_once('@').ok_or_else(usage)?;
        let (from, duration) = times.split_once('+').ok_or_else(usage)?;
        let hazard = Hazard::from_name(&name.to_ascii_uppercase()).ok_or_else(usage)?;
        let number = |x: &str| x.trim().parse::<f64>().ok().filter(|v| v.is_finite());
        match (number(from), number(duration)) {
            (Some(from), Some(duration)) if from >= 0.0 && duration > 0.0 => Ok(HazardWindow {
                hazard,
                from,
                duration,
            }),
            _ => Err(usage()),
        }
    }
}

/// A base's safety words as they arrive (see the module's rules).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct BaseSafety {
    scheme: KeyScheme,
    /// The stopping hazards the last valid vector reported, and its time.
    reported: HazardSet,
    reported_at: f64,
    estop: bool,
    /// The stopping hazards in force as last updated.
    in_force: HazardSet,
    events: Vec<HazardEvent>,
    /// The latest onset (kept past [`MAX_EVENTS`]).
    last: Option<HazardEvent>,
    counts: HazardCounts,
}

impl BaseSafety {
    /// Nothing heard, on keys of `scheme`.
    pub fn new(scheme: KeyScheme) -> BaseSafety {
        BaseSafety {
            scheme,
            ..BaseSafety::default()
        }
    }

    /// A hazard vector on `key` that arrived at fleet time `t`.
    pub fn on_hazards(
        &mut self,
        key: &str,
        payload: &[u8],
        t: f64,
    ) -> Result<HazardSet, SampleRefusal> {
        self.counts.hazard_received += 1;
        let decoded = check_topic_key(self.scheme, key, &HAZARD_DETECTION_VECTOR)
            .map_err(|e| SampleRefusal::WrongType(e.to_string()))
            .and_then(|()| HazardDetectionVector::from_cdr(payload).map_err(SampleRefusal::from))
            .and_then(|v| {
                v.detections
                    .iter()
                    .map(|d| Hazard::of_create3(d.r#type))
                    .collect::<Option<HazardSet>>()
                    .ok_or_else(|| SampleRefusal::WrongType("an unknown hazard type".to_owned()))
            });
        let all = match decoded {
            Ok(all) => all,
            Err(e) => {
                self.counts.hazard_refused += 1;
                return Err(e);
            }
        };
        self.counts.object_proximity += u64::from(all.contains(Hazard::ObjectProximity));
        self.counts.backup_limit += u64::from(all.contains(Hazard::BackupLimit));
        self.reported = all.stopping();
        self.reported_at = t;
        self.update(t);
        Ok(all)
    }

    /// An e-stop sample on `key` that arrived at fleet time `t`.
    pub fn on_estop(&mut self, key: &str, payload: &[u8], t: f64) -> Result<bool, SampleRefusal> {
        self.counts.estop_received += 1;
        let decoded = check_topic_key(self.scheme, key, &BOOL)
            .map_err(|e| SampleRefusal::WrongType(e.to_string()))
            .and_then(|()| Bool::from_cdr(payload).map_err(SampleRefusal::from));
        match decoded {
            Ok(b) => {
                self.estop = b.data;
                self.update(t);
                Ok(b.data)
            }
            Err(e) => {
                self.counts.estop_refused += 1;
                Err(e)
            }
        }
    }

    /// The stopping hazards in force at fleet time `t` (see the module's
    /// rules).
    pub fn in_force(&self, t: f64) -> HazardSet {
        let mut set = if t - self.reported_at <= HAZARD_CLEAR_AFTER {
            self.reported
        } else {
            HazardSet::EMPTY
        };
        if self.estop {
            set = set.with(Hazard::EmergencyStop);
        }
        set
    }

    /// Brings the events to fleet time `t` (an onset opens one, a clearing
    /// closes it); returns the hazards in force.
    pub fn update(&mut self, t: f64) -> HazardSet {
        let now = self.in_force(t);
        for h in now.iter().filter(|h| !self.in_force.contains(*h)) {
            self.counts.onsets += 1;
            let event = HazardEvent {
                hazard: h,
                at: t,
                cleared: None,
            };
            if self.events.len() < MAX_EVENTS {
                self.events.push(event);
            }
            self.last = Some(event);
        }
        for e in self
            .events
            .iter_mut()
            .chain(self.last.as_mut())
            .filter(|e| e.cleared.is_none() && !now.contains(e.hazard))
        {
            e.cleared = Some(t);
        }
        self.in_force = now;
        now
    }

    /// Its counters.
    pub fn counts(&self) -> HazardCounts {
        self.counts
    }

    /// Its report.
    pub fn report(&self) -> HazardReport {
        HazardReport {
            in_force: self.in_force,
            counts: self.counts,
            events: self.events.clone(),
            last: self.last,
        }
    }

    /// The fleet clock jumped to `t` (a leader restarted): what was heard
    /// stays in force (a hazard is the base's, not the leader's), now timed
    /// from `t`.
    pub fn set_time(&mut self, t: f64) {
        self.reported_at = t;
    }
}

#[cfg(test)]
mod tests;
