//! `trajectory.csv`'s per-agent columns as the report reads them: the
//! [`Column`]s, named by the core's one list of the sample's columns.

/// The per-agent columns of `trajectory.csv` after `t` and `agent`, in order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Column {
    /// x, m.
    X,
    /// y, m.
    Y,
    /// θ, rad, wrapped to (−π, π].
    Theta,
    /// v, m/s.
    V,
    /// ω, rad/s.
    Omega,
    /// e_x, m (eq. 7, body frame).
    Ex,
    /// e_y, m.
    Ey,
    /// z_x, m/s (eq. 10).
    Zx,
    /// z_y, m/s.
    Zy,
    /// u1, N.
    U1,
    /// u2, N·m.
    U2,
    /// τ_r, N·m.
    TauR,
    /// τ_l, N·m.
    TauL,
    /// The kinematic law's commanded `v*`, m/s (velocity runs only; `NaN` for
    /// a torque-driven agent).
    VCmd,
    /// Commanded `ω*`, rad/s.
    OmegaCmd,
    /// `v` after the base's speed limits, m/s.
    VApplied,
    /// `ω` after the base's speed limits, rad/s.
    OmegaApplied,
    /// 1 when the speed limits cut the command at this instant, else 0.
    Sat,
}

/// Number of [`Column`]s: the sample's columns after `t` and `agent`
/// ([`echelon::sample::COLUMNS`], [`echelon::sample::VELOCITY_COLUMNS`]).
pub const COLUMNS: usize =
    echelon::sample::COLUMNS.len() - 2 + echelon::sample::VELOCITY_COLUMNS.len();

/// The columns a run with velocity bases adds after [`Column::TauL`].
pub const VELOCITY_COLUMNS: [Column; 5] = [
    Column::VCmd,
    Column::OmegaCmd,
    Column::VApplied,
    Column::OmegaApplied,
    Column::Sat,
];

impl Column {
    /// Every column, in `trajectory.csv`'s order.
    pub const ALL: [Column; COLUMNS] = [
        Column::X,
        Column::Y,
        Column::Theta,
        Column::V,
        Column::Omega,
        Column::Ex,
        Column::Ey,
        Column::Zx,
        Column::Zy,
        Column::U1,
        Column::U2,
        Column::TauR,
        Column::TauL,
        Column::VCmd,
        Column::OmegaCmd,
        Column::VApplied,
        Column::OmegaApplied,
        Column::Sat,
    ];

    /// Its name in `trajectory.csv`'s header, from the core's one list of the
    /// sample's columns ([`echelon::sample::COLUMNS`] after `t` and `agent`,
    /// then [`echelon::sample::VELOCITY_COLUMNS`]), by position: the position
    /// at which [`RunData::load`](super::RunData::load) reads it.
    pub fn name(self) -> &'static str {
        let torque = &echelon::sample::COLUMNS[2..];
        let i = self as usize;
        torque
            .get(i)
            .copied()
            .unwrap_or_else(|| echelon::sample::VELOCITY_COLUMNS[i - torque.len()])
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use std::path::Path;

    use echelon::csv::CsvWriter;
    use echelon::output::{TRAJECTORY_HEADER_VELOCITY, Table};
    use echelon::sample::{AgentSample, SampleCsv, VelocitySample};

    use super::*;

    /// The core's field that `c` stands for, by meaning (not by position).
    fn field(s: &AgentSample, c: Column) -> f64 {
        let v = s.velocity.unwrap_or_default();
        match c {
            Column::X => s.x,
            Column::Y => s.y,
            Column::Theta => s.theta,
            Column::V => s.v,
            Column::Omega => s.omega,
            Column::Ex => s.ex,
            Column::Ey => s.ey,
            Column::Zx => s.zx,
            Column::Zy => s.zy,
            Column::U1 => s.u1,
            Column::U2 => s.u2,
            Column::TauR => s.tau_r,
            Column::TauL => s.tau_l,
            Column::VCmd => v.v_cmd,
            Column::OmegaCmd => v.omega_cmd,
            Column::VApplied => v.v_applied,
            Column::OmegaApplied => v.omega_applied,
            Column::Sat => f64::from(u8::from(v.sat)),
        }
    }

    /// Each column is read where the core writes the field it stands for, and
    /// is named there: a torque sample and a velocity sample with a distinct
    /// value in every field, written by the core's `trajectory.csv` writer.
    #[test]
    fn columns_are_the_core_samples_fields_in_order() {
        let torque = AgentSample {
            t: 0.5,
            agent: 1,
            x: 1.5,
            y: 2.5,
            theta: 0.25,
            v: 3.5,
            omega: 4.5,
            ex: 5.5,
            ey: 6.5,
            zx: 7.5,
            zy: 8.5,
            u1: 9.5,
            u2: 10.5,
            tau_r: 11.5,
            tau_l: 12.5,
            velocity: None,
        };
        let velocity = AgentSample {
            agent: 2,
            velocity: Some(VelocitySample {
                v_cmd: 13.5,
                omega_cmd: 14.5,
                v_applied: 15.5,
                omega_applied: 16.5,
                sat: true,
            }),
            ..torque
        };
        let mut csv = CsvWriter::new(Vec::new(), TRAJECTORY_HEADER_VELOCITY).unwrap();
        torque.write_csv(&mut csv, true).unwrap();
        velocity.write_csv(&mut csv, true).unwrap();
        let text = String::from_utf8(csv.into_inner().unwrap()).unwrap();
        let path = Path::new("trajectory.csv");
        let table = Table::parse(path, &text).unwrap();
        assert_eq!(table.header.len(), 2 + COLUMNS);
        for c in Column::ALL {
            assert_eq!(
                table.column(c.name(), path).unwrap(),
                2 + c as usize,
                "{c:?}"
            );
            let sample = if VELOCITY_COLUMNS.contains(&c) {
                (&velocity, &table.rows[1])
            } else {
                (&torque, &table.rows[0])
            };
            assert_eq!(sample.1[2 + c as usize], field(sample.0, c), "{c:?}");
        }
    }
}
