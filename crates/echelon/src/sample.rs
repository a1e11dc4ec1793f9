//! One agent at one instant ([`AgentSample`], the kernel's
//! `echelon_core::sample`, re-exported here) and its `trajectory.csv` row.

use std::io::{self, Write};

use crate::csv::CsvWriter;
pub use echelon_core::sim::sample::*;

/// An [`AgentSample`] as a `trajectory.csv` row.
pub trait SampleCsv {
    /// Writes the sample as one `trajectory.csv` row: the [`COLUMNS`], and
    /// the [`VELOCITY_COLUMNS`] when `velocity`. A velocity base's
    /// `u1, u2, tau_r, tau_l` are written `NaN`, a torque-driven robot's
    /// velocity cells too.
    fn write_csv<W: Write>(&self, csv: &mut CsvWriter<W>, velocity: bool) -> io::Result<()>;
}

impl SampleCsv for AgentSample {
    fn write_csv<W: Write>(&self, csv: &mut CsvWriter<W>, velocity: bool) -> io::Result<()> {
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
