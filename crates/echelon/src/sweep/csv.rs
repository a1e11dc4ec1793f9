//! A sweep's CSV files: `sweep.csv` ([`SWEEP_HEADER`]) and `diverged.csv`
//! ([`DIVERGED_HEADER`]).

use std::io::{self, Write};

use super::{DIVERGED_HEADER, DivergedCase, Row, SWEEP_HEADER};
use crate::csv::CsvWriter;
use crate::odometry::ZetaModel;

/// Writes `diverged.csv` ([`DIVERGED_HEADER`]).
pub fn write_diverged_csv<W: Write>(
    w: W,
    diverged: &[DivergedCase],
    zeta_model: ZetaModel,
) -> io::Result<()> {
    let mut csv = CsvWriter::new(w, DIVERGED_HEADER)?;
    for d in diverged {
        let (c, v) = (&d.case, &d.divergence);
        csv.num(c.zeta)
            .text(zeta_model_name(zeta_model))
            .nums([c.wheel_diameter_ratio, c.wheelbase_ratio, c.slip])
            .int(c.fix_every)
            .int(c.seed)
            .int(v.agent as u64)
            .time(v.t)
            .text(&v.quantity)
            .opt(v.value)
            .opt(v.bound);
        csv.end_row()?;
    }
    csv.flush()
}

/// `zeta_model`'s value in the CSV files, as the CLI spells it.
fn zeta_model_name(zeta_model: ZetaModel) -> &'static str {
    match zeta_model {
        ZetaModel::Wheels => "wheels",
        ZetaModel::WorstCase => "worst-case",
    }
}

/// Writes `sweep.csv`: a row per run, a diverged one's included (its
/// `diverged` column set, see the [module docs](super)).
pub fn write_csv<W: Write>(w: W, rows: &[Row], zeta_model: ZetaModel) -> io::Result<()> {
    let mut csv = CsvWriter::new(w, SWEEP_HEADER)?;
    let model = zeta_model_name(zeta_model);
    for r in rows {
        let c = &r.case;
        csv.num(c.zeta)
            .text(model)
            .nums([c.wheel_diameter_ratio, c.wheelbase_ratio, c.slip])
            .int(c.fix_every)
            .int(c.seed)
            .nums([
                r.omega_max,
                r.z_max,
                r.z_hat_max,
                r.e_max,
                r.final_drift,
                r.drift_max,
            ])
            .opt(r.z_bound)
            .opt(r.z_over_bound)
            .opt(r.e_bound);
        // When it diverged, as diverged.csv writes it; empty for a run
        // that ended.
        match r.diverged {
            Some(t) => csv.time(t),
            None => csv.opt(None),
        };
        csv.end_row()?;
    }
    csv.flush()
}
