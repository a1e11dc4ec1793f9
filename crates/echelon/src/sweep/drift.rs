//! How drift grows without fixes (`drift.csv`): the paper's linear-growth
//! assumption (eqs. 30–31) against what systematic errors do.

use std::io::{self, Write};

use rayon::prelude::*;

use super::{Case, Grid, SweepError, build_case};
use crate::csv::CsvWriter;
use crate::scenario::{Overrides, Scenario};
use crate::sim::{Every, Frame, ObserverError};
use crate::stats::Divergence;

/// How an error model's drift grows without fixes.
#[derive(Debug, Clone, PartialEq)]
pub struct DriftCurve {
    /// The error model (its `fix_every` is 0; the grid's first seed).
    pub case: Case,
    /// Sample times, s.
    pub times: Vec<f64>,
    /// max over dead-reckoning agents of ‖p − p̂‖, m.
    pub drift: Vec<f64>,
    /// The paper's linear growth `√2 N ζ` (eqs. 30–31) after `N` samples, m.
    pub paper: Vec<f64>,
    /// The drift's own first second, extrapolated linearly, m: what a linear
    /// model fitted early would predict.
    pub early_slope: Vec<f64>,
}

/// The header of `drift.csv`.
pub const DRIFT_HEADER: &str =
    "zeta,wheel_diameter_ratio,wheelbase_ratio,slip,seed,t,drift,paper_linear,early_slope";

/// For every distinct error model of `grid`, the drift without fixes over the
/// run (about `points` samples), in parallel. Shows the paper's linear-growth
/// assumption against what systematic errors do.
pub fn drift_curves(
    scenario: &Scenario,
    overrides: &Overrides,
    grid: &Grid,
    points: usize,
) -> Result<Vec<DriftCurve>, SweepError> {
    let mut models: Vec<Case> = Vec::new();
    for c in grid.cases() {
        let model = Case {
            seed: grid.0.seeds[0],
            ..c.error_model()
        };
        if !models.contains(&model) {
            models.push(model);
        }
    }
    models
        .par_iter()
        .map(|case| {
            let run = build_case(scenario, overrides, grid, case)?;
            let sim = &mut run.simulation();
            let every = (sim.steps() / points.max(1) as u64).max(1);
            let mut times = Vec::with_capacity(points + 2);
            let mut drift = Vec::with_capacity(points + 2);
            let mut samples = Vec::with_capacity(points + 2);
            let mut observe = |f: &Frame<'_>| -> Result<(), ObserverError> {
                let mut d: f64 = 0.0;
                let mut n = 0;
                for (i, odometer) in f.odometers.iter().enumerate() {
                    if let Some(o) = odometer {
                        d = d.max(o.drift(&f.states[i]));
                        n = n.max(o.samples());
                    }
                }
                times.push(f.t);
                drift.push(d);
                samples.push(n);
                Ok(())
            };
            // Without fixes an absurd error model can drive the robot out
            // of its bounds: its curve ends where it diverged (the sweep's
            // rows report the divergence).
            match sim.run(&mut Every::new(every, &mut observe)) {
                Ok(()) => {}
                Err(e) if Divergence::of(&e).is_some() => {}
                Err(e) => return Err(e.into()),
            }
            let paper = samples
                .iter()
                .map(|&n| std::f64::consts::SQRT_2 * n as f64 * case.zeta)
                .collect();
            let k1 = times
                .iter()
                .position(|&t| t >= 1.0)
                .unwrap_or(times.len().saturating_sub(1));
            let slope = match times.get(k1) {
                Some(&t) if t > 0.0 => drift[k1] / t,
                _ => 0.0,
            };
            let early_slope = times.iter().map(|t| slope * t).collect();
            Ok(DriftCurve {
                case: *case,
                times,
                drift,
                paper,
                early_slope,
            })
        })
        .collect()
}

/// Writes `drift.csv`: one row per curve per sample.
pub fn write_drift_csv<W: Write>(w: W, curves: &[DriftCurve]) -> io::Result<()> {
    let mut csv = CsvWriter::new(w, DRIFT_HEADER)?;
    for c in curves {
        for k in 0..c.times.len() {
            csv.nums([
                c.case.zeta,
                c.case.wheel_diameter_ratio,
                c.case.wheelbase_ratio,
                c.case.slip,
            ])
            .int(c.case.seed)
            .time(c.times[k])
            .nums([c.drift[k], c.paper[k], c.early_slope[k]]);
            csv.end_row()?;
        }
    }
    csv.flush()
}
