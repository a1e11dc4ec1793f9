//! One agent at one instant: the one sample type that `trajectory.csv`, the
//! MCAP `/agent/K/state` channel, the fleet's wire state and the report all
//! carry, whoever produced it (the simulator's frames, `sim/outputs.rs`, or a
//! fleet robot).
//!
//! Its fields are `trajectory.csv`'s columns, in order ([`COLUMNS`],
//! [`VELOCITY_COLUMNS`]); serialised (serde, JSON Schema through schemars)
//! they are the MCAP record's fields. SI units, radians.

use std::io::{self, Write};

use serde::{Deserialize, Serialize};

use crate::base::VelocityCommand;
use crate::csv::CsvWriter;
use crate::model::State;

/// One agent at one instant: true state, tracking error `e` (eq. 7) and
/// backstepping error `z` (eq. 10) of the true state in the robot's body
/// frame, the generalised input the plant received and the wheel torques,
/// and for a velocity base its command ([`VelocitySample`]).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize, schemars::JsonSchema)]
pub struct AgentSample {
    /// Time, s.
    pub t: f64,
    /// Agent number, from 1.
    pub agent: u32,
    /// Position x, m.
    pub x: f64,
    /// Position y, m.
    pub y: f64,
    /// Heading, rad, wrapped to (−π, π].
    pub theta: f64,
    /// Linear speed, m/s.
    pub v: f64,
    /// Angular speed, rad/s.
    pub omega: f64,
    /// Tracking error `e_x`, m.
    pub ex: f64,
    /// Tracking error `e_y`, m.
    pub ey: f64,
    /// Backstepping error `z_x`, m/s.
    pub zx: f64,
    /// Backstepping error `z_y`, m/s.
    pub zy: f64,
    /// Force `u1` the plant received, N (0 on a velocity base).
    pub u1: f64,
    /// Torque `u2` the plant received, N m (0 on a velocity base).
    pub u2: f64,
    /// Right wheel torque, N m (0 on a velocity base).
    pub tau_r: f64,
    /// Left wheel torque, N m (0 on a velocity base).
    pub tau_l: f64,
    /// A velocity base's command; absent for a torque-driven robot.
    #[serde(flatten, default, skip_serializing_if = "Option::is_none")]
    pub velocity: Option<VelocitySample>,
}

/// What a velocity base was commanded and what it followed.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize, schemars::JsonSchema)]
pub struct VelocitySample {
    /// The kinematic law's `v*`, m/s.
    pub v_cmd: f64,
    /// The kinematic law's `ω*`, rad/s.
    pub omega_cmd: f64,
    /// `v` after the base's speed limits, m/s.
    pub v_applied: f64,
    /// `ω` after the base's speed limits, rad/s.
    pub omega_applied: f64,
    /// Whether the speed limits cut the command.
    pub sat: bool,
}

/// The columns of `trajectory.csv`: [`AgentSample`]'s fields before its
/// velocity-base ones, in order.
pub const COLUMNS: [&str; 15] = [
    "t", "agent", "x", "y", "theta", "v", "omega", "ex", "ey", "zx", "zy", "u1", "u2", "tau_r",
    "tau_l",
];

/// The columns `trajectory.csv` adds after [`COLUMNS`] when some agent is on
/// a velocity base: [`VelocitySample`]'s fields, in order (`sat` written 0 or 1).
pub const VELOCITY_COLUMNS: [&str; 5] = ["v_cmd", "omega_cmd", "v_applied", "omega_applied", "sat"];

impl VelocitySample {
    /// The law's command `command`, what the base follows (`applied`) and
    /// whether its limits cut it.
    pub fn new(command: VelocityCommand, applied: VelocityCommand, saturated: bool) -> Self {
        VelocitySample {
            v_cmd: command.v,
            omega_cmd: command.omega,
            v_applied: applied.v,
            omega_applied: applied.omega,
            sat: saturated,
        }
    }
}

impl AgentSample {
    /// ‖e‖, m.
    pub fn error_norm(&self) -> f64 {
        self.ex.hypot(self.ey)
    }

    /// The larger wheel torque magnitude, N m.
    pub fn peak_torque(&self) -> f64 {
        self.tau_r.abs().max(self.tau_l.abs())
    }

    /// The state `(x, y, θ, v, ω)` (θ wrapped).
    pub fn state(&self) -> State {
        State {
            x: self.x,
            y: self.y,
            theta: self.theta,
            v: self.v,
            omega: self.omega,
        }
    }

    /// Writes the sample as one `trajectory.csv` row: the [`COLUMNS`], and
    /// the [`VELOCITY_COLUMNS`] when `velocity`. A velocity base's
    /// `u1, u2, tau_r, tau_l` are written `NaN`, a torque-driven robot's
    /// velocity cells too.
    pub fn write_csv<W: Write>(&self, csv: &mut CsvWriter<W>, velocity: bool) -> io::Result<()> {
        let torque = |x: f64| if self.velocity.is_some() { f64::NAN } else { x };
        csv.time(self.t).int(u64::from(self.agent)).nums([
            self.x,
            self.y,
            self.theta,
            self.v,
            self.omega,
            self.ex,
            self.ey,
            self.zx,
            self.zy,
            torque(self.u1),
            torque(self.u2),
            torque(self.tau_r),
            torque(self.tau_l),
        ]);
        if velocity {
            match self.velocity {
                Some(v) => csv.nums([
                    v.v_cmd,
                    v.omega_cmd,
                    v.v_applied,
                    v.omega_applied,
                    f64::from(u8::from(v.sat)),
                ]),
                None => csv.nums([f64::NAN; 5]),
            };
        }
        csv.end_row()
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use std::fmt;

    use serde::de::{Deserializer as _, IgnoredAny, MapAccess, Visitor};

    use super::*;
    use crate::output::{TRAJECTORY_HEADER, TRAJECTORY_HEADER_VELOCITY};

    /// The keys of a JSON object, in the order written.
    fn keys(json: &str) -> Vec<String> {
        struct Keys;
        impl<'de> Visitor<'de> for Keys {
            type Value = Vec<String>;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("an object")
            }
            fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Vec<String>, A::Error> {
                let mut keys = Vec::new();
                while let Some(k) = map.next_key::<String>()? {
                    map.next_value::<IgnoredAny>()?;
                    keys.push(k);
                }
                Ok(keys)
            }
        }
        serde_json::Deserializer::from_str(json)
            .deserialize_map(Keys)
            .unwrap()
    }

    fn velocity_sample() -> AgentSample {
        AgentSample {
            velocity: Some(VelocitySample::default()),
            ..AgentSample::default()
        }
    }

    /// `trajectory.csv`'s header is the sample's serialised fields, in
    /// order: without the velocity-base ones, and with them.
    #[test]
    fn the_csv_header_is_the_sample_s_fields() {
        let torque = keys(&serde_json::to_string(&AgentSample::default()).unwrap());
        let velocity = keys(&serde_json::to_string(&velocity_sample()).unwrap());
        assert_eq!(torque, COLUMNS);
        assert_eq!(velocity, [&COLUMNS[..], &VELOCITY_COLUMNS[..]].concat());
        assert_eq!(TRAJECTORY_HEADER, torque.join(","));
        assert_eq!(TRAJECTORY_HEADER_VELOCITY, velocity.join(","));
    }

    /// A row has as many cells as its header, and reads back as the sample.
    #[test]
    fn a_row_has_one_cell_per_column_and_reads_back() {
        let s = AgentSample {
            t: 0.03,
            agent: 2,
            x: 1.5,
            theta: -0.25,
            ex: 1e-3,
            velocity: Some(VelocitySample {
                v_cmd: 0.5,
                v_applied: 0.4,
                sat: true,
                ..VelocitySample::default()
            }),
            ..AgentSample::default()
        };
        let mut csv = CsvWriter::new(Vec::new(), TRAJECTORY_HEADER_VELOCITY).unwrap();
        s.write_csv(&mut csv, true).unwrap();
        AgentSample {
            velocity: None,
            ..s
        }
        .write_csv(&mut csv, true)
        .unwrap();
        let text = String::from_utf8(csv.into_inner().unwrap()).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(
            lines[1],
            "0.03,2,1.5,0.0,-0.25,0.0,0.0,0.001,0.0,0.0,0.0,NaN,NaN,NaN,NaN,0.5,0.0,0.4,0.0,1.0"
        );
        assert!(lines[2].ends_with(",0.0,0.0,0.0,0.0,NaN,NaN,NaN,NaN,NaN"));
        for line in &lines[1..] {
            assert_eq!(
                line.split(',').count(),
                VELOCITY_COLUMNS.len() + COLUMNS.len()
            );
        }
        let back: AgentSample = serde_json::from_str(&serde_json::to_string(&s).unwrap()).unwrap();
        assert_eq!(back, s);
        let torque = AgentSample {
            velocity: None,
            ..s
        };
        let back: AgentSample =
            serde_json::from_str(&serde_json::to_string(&torque).unwrap()).unwrap();
        assert_eq!(back, torque);
    }
}
