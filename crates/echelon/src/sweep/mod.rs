//! Monte Carlo sweeps: a scenario run over a grid of odometry error models ×
//! fix intervals × seeds, in parallel, each run reduced to the numbers that
//! answer "how often does this formation need an absolute fix?".
//!
//! Rows come back in grid order whatever the number of threads, so the same
//! sweep gives the same bytes.
//!
//! # The bound columns, per law
//!
//! `z_bound`, `z_over_bound` and `e_bound` hold Theorem 2 in the form that
//! fits each dead-reckoning agent's law (maxima over the agents when several
//! dead-reckon; a run mixing both laws mixes both forms, see [`Laws`]):
//!
//! | column         | paper / complete law (eq. 13, [`Theorem2`])          | kinematic law ([`KinematicTheorem2`])            |
//! |----------------|------------------------------------------------------|--------------------------------------------------|
//! | `z_bound`      | ultimate bound on ‖z‖: `√2 K_e N ζ √(K_z² + ω_M²)/(K_z γ)` | bound on ‖z‖ at every instant: `√2 K_e N ζ`   |
//! | `e_bound`      | `z_bound / K_e` (V̇₁ < 0 beyond it)                  | ultimate bound on ‖e‖: `√2 N ζ / γ`, the theorem's claim |
//! | `z_over_bound` | ultimate max ‖z‖ / `z_bound`                         | ultimate max ‖e‖ / `e_bound`                     |
//!
//! So `z_over_bound < 1` says, for either law, that the run kept the
//! theorem's main bound. The kinematic form holds for an ideal base
//! (control-law.md, "Theorem 2 for the kinematic law"): a base with a lag, or
//! whose speed limits cut the command after the transient, gets no bound (its
//! own `z` is outside the theorem), like any run outside Assumption 1. So
//! does, for either law, an agent whose safety filter changed its command
//! after the transient (filtered, braked or breaking a deadlock): the
//! filter, not the law, then sets its `z`.
//!
//! # Runs that diverge
//!
//! A run that leaves its bounds ([`SimError::Diverged`]) is a row like any
//! other, in its place in grid order, with `diverged` set to the time it
//! diverged (s; empty for a run that ended) and its statistics `inf` (it
//! has no maximum: it left its bounds), its bound columns empty; a mean or
//! a maximum over seeds that takes it in is `inf`, never a quiet average of
//! the runs that ended. [`run_all`] also lists what left its bound
//! ([`DivergedCase`], `diverged.csv`).
//!
//! This file holds the grid and the runs; `peaks.rs` a run's maxima and
//! their bounds; `drift.rs` the drift curves without fixes (`drift.csv`);
//! `csv.rs` the sweep's other CSV files.
//!
//! [`Theorem2`]: crate::odometry::bound::Theorem2
//! [`KinematicTheorem2`]: crate::odometry::bound::KinematicTheorem2

use rayon::prelude::*;
use serde::Serialize;

use crate::check;
use crate::control::Law;
use crate::error::{ParamError, ScenarioError, SimError};
use crate::odometry::ZetaModel;
use crate::scenario::schema::{FixesSection, Fusion, OdometrySection};
use crate::scenario::{OdometryOverrides, Overrides, Run, Scenario};
use crate::sim::{Frame, ObserverError};
use crate::stats::Divergence;

mod csv;
mod drift;
mod peaks;

use peaks::{Peaks, dead_reckoning, theorem_bounds};

pub use csv::{write_csv, write_diverged_csv};
pub use drift::{DRIFT_HEADER, DriftCurve, drift_curves, write_drift_csv};

/// The grid a sweep is asked for: every combination of the lists, for every
/// seed. [`Grid::new`] checks it.
#[derive(Debug, Clone, PartialEq)]
pub struct GridSpec {
    /// The paper's `ζ`, m per sample.
    pub zeta: Vec<f64>,
    /// How `ζ` enters.
    pub zeta_model: ZetaModel,
    /// `E_d` values.
    pub wheel_diameter_ratio: Vec<f64>,
    /// `E_b` values.
    pub wheelbase_ratio: Vec<f64>,
    /// Slip variances, m²/m.
    pub slip: Vec<f64>,
    /// Odometry samples between fixes (`N`; 0: no fixes).
    pub fix_every: Vec<u64>,
    /// Seeds.
    pub seeds: Vec<u64>,
    /// Theorem 2's `γ ∈ (0, 1)` for the bound column.
    pub gamma: f64,
    /// Statistics are taken after this time, s (the "ultimate" behaviour).
    pub transient: f64,
}

/// A checked [`GridSpec`]: every list has a value and every value is
/// possible, so a sweep over it can run.
#[derive(Debug, Clone, PartialEq)]
pub struct Grid(GridSpec);

/// One run of a sweep.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Case {
    /// `ζ`, m per sample.
    pub zeta: f64,
    /// `E_d`.
    pub wheel_diameter_ratio: f64,
    /// `E_b`.
    pub wheelbase_ratio: f64,
    /// Slip, m²/m.
    pub slip: f64,
    /// Samples between fixes (0: none).
    pub fix_every: u64,
    /// Seed.
    pub seed: u64,
}

impl Case {
    /// The error model alone: this case without its fix interval and seed.
    pub fn error_model(&self) -> Case {
        Case {
            fix_every: 0,
            seed: 0,
            ..*self
        }
    }

    /// Whether the case has errors outside the paper's Assumption 1 (which
    /// keeps the heading exact): unequal wheels, a wrong wheelbase or slip.
    pub fn outside_assumption_1(&self) -> bool {
        self.wheel_diameter_ratio != 1.0 || self.wheelbase_ratio != 1.0 || self.slip != 0.0
    }
}

/// What one run shows. Maxima are over the agents that dead-reckon and over
/// the time after the transient.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Row {
    /// The run's parameters.
    #[serde(flatten)]
    pub case: Case,
    /// Largest |ω|, rad/s (Theorem 2's `ω_M`).
    pub omega_max: f64,
    /// Ultimate max ‖z‖ of the true state, m/s.
    pub z_max: f64,
    /// Ultimate max ‖ẑ‖, what the controller saw, m/s.
    pub z_hat_max: f64,
    /// Ultimate max ‖e‖ of the true state, m.
    pub e_max: f64,
    /// ‖p − p̂‖ at the end, m.
    pub final_drift: f64,
    /// Ultimate max ‖p − p̂‖, m.
    pub drift_max: f64,
    /// Theorem 2's bound on ‖z‖ for this run, m/s (`None` when the run is
    /// outside its assumptions: systematic errors, slip, noisy or late fixes,
    /// no fixes; for the kinematic law also a lagging or saturating base).
    /// See the [module docs](self) for each law's form.
    pub z_bound: Option<f64>,
    /// max over agents of the theorem's main ratio (`None` without a bound):
    /// ‖z‖ / `z_bound` under the paper's law, ‖e‖ / `e_bound` under the
    /// kinematic law.
    pub z_over_bound: Option<f64>,
    /// The bound on ‖e‖, m: `z_bound / K_e` (V̇₁ < 0 beyond it) under the
    /// paper's law, the ultimate `√2 N ζ / γ` under the kinematic law.
    pub e_bound: Option<f64>,
    /// The laws of the agents that dead-reckon: which form of Theorem 2 the
    /// bound columns hold (not written to `sweep.csv`).
    #[serde(skip)]
    pub laws: Laws,
    /// When the run diverged, s (`None`: it ran to its end). A diverged
    /// run's statistics are `inf` and its bounds `None` (see the
    /// [module docs](self)).
    pub diverged: Option<f64>,
}

impl Row {
    /// Whether the run diverged.
    pub fn is_diverged(&self) -> bool {
        self.diverged.is_some()
    }
}

/// The laws of a run's dead-reckoning agents, and so the form of Theorem 2 in
/// a [`Row`]'s bound columns (see the [module docs](self)).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Laws {
    /// The paper's or the complete law (eq. 13) only, or no agent dead-reckons.
    #[default]
    Dynamic,
    /// The kinematic law only.
    Kinematic,
    /// Both: each agent's bound in its own form, maxima over them.
    Mixed,
}

impl Laws {
    /// The laws of the agents `laws` (`Dynamic` for none).
    pub fn of(laws: impl IntoIterator<Item = Law>) -> Laws {
        let (mut dynamic, mut kinematic) = (false, false);
        for law in laws {
            match law {
                Law::Kinematic => kinematic = true,
                Law::Paper | Law::Complete => dynamic = true,
            }
        }
        match (dynamic, kinematic) {
            (true, true) => Laws::Mixed,
            (false, true) => Laws::Kinematic,
            _ => Laws::Dynamic,
        }
    }
}

/// A case whose run diverged ([`SimError::Diverged`]): a sweep goes on
/// past it, reports it apart from the rows (`diverged.csv`) and fails at
/// the end, so one absurd corner of a grid neither hides nor loses the rest.
#[derive(Debug, Clone, PartialEq)]
pub struct DivergedCase {
    /// The case.
    pub case: Case,
    /// Where, when and what left its bound.
    pub divergence: Divergence,
}

/// What a sweep gives: a row per case, in grid order (a diverged run's
/// with [`Row::diverged`] set), and what left its bound in each case that
/// diverged, in grid order.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Sweep {
    /// Every run, diverged or not.
    pub rows: Vec<Row>,
    /// The runs that diverged: what left its bound, where and when.
    pub diverged: Vec<DivergedCase>,
}

/// The header of `diverged.csv`: a diverged case and its divergence
/// (`value`, `bound` empty when not finite / not a bound).
pub const DIVERGED_HEADER: &str = "zeta,zeta_model,wheel_diameter_ratio,wheelbase_ratio,slip,fix_every,seed,agent,t,quantity,value,bound";

/// The header of `sweep.csv`.
pub const SWEEP_HEADER: &str = "zeta,zeta_model,wheel_diameter_ratio,wheelbase_ratio,slip,fix_every,seed,omega_max,z_max,z_hat_max,e_max,final_drift,drift_max,z_bound,z_over_bound,e_bound,diverged";

/// Why a sweep cannot run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SweepError {
    /// A grid value is impossible.
    #[error("sweep: {0}")]
    Param(#[from] ParamError),
    /// A run's scenario does not build.
    #[error(transparent)]
    Scenario(#[from] ScenarioError),
    /// A run failed.
    #[error(transparent)]
    Sim(#[from] SimError),
}

/// Why [`Grid::new`] refuses an empty list (the error's value is then 0, the
/// list's length, not a value given: [`GridSpec::refusal`] words it).
pub const EMPTY_LIST: &str = "needs at least one value";

/// Why [`Grid::new`] refuses a list that holds a value twice (the error's
/// value).
pub const REPEATED: &str = "is given twice: each value of a list is one set of cases, give it once";

/// A value of `values` that another one equals (`0.0 == -0.0`), if any; in
/// O(n log n), for a list of a million seeds.
fn repeated<T: PartialEq + Copy>(
    values: &[T],
    order: fn(&T, &T) -> std::cmp::Ordering,
) -> Option<T> {
    let mut sorted = values.to_vec();
    sorted.sort_unstable_by(order);
    sorted.windows(2).find(|w| w[0] == w[1]).map(|w| w[0])
}

impl GridSpec {
    /// What is wrong with the list or value `e` refuses, after its flag or
    /// key: `an empty list: needs at least one value`, else `VALUE REASON`
    /// (`1 is given twice: …`, `-1 must be a finite number ≥ 0`).
    pub fn refusal(e: &ParamError) -> String {
        if e.reason == EMPTY_LIST {
            format!("an empty list: {EMPTY_LIST}")
        } else {
            format!("{} {}", crate::error::num(e.value), e.reason)
        }
    }

    /// The `echelon sweep` flag that sets `field`, a field of this struct
    /// as a [`ParamError`] from [`Grid::new`] or a sweep names it (`None`
    /// for any other name). Python's keyword is the flag without `--`, `-`
    /// written `_`.
    pub fn flag(field: &str) -> Option<&'static str> {
        const OTHERS: [(&str, &str); 3] = [
            ("seeds", "--seeds"),
            ("gamma", "--gamma"),
            ("transient", "--transient"),
        ];
        OdometryOverrides::FLAGS
            .iter()
            .chain(&OTHERS)
            .find(|(f, _)| *f == field)
            .map(|&(_, flag)| flag)
    }
}

impl Grid {
    /// The grid `spec`, refusing empty lists, impossible values and γ
    /// outside (0, 1).
    pub fn new(spec: GridSpec) -> Result<Grid, ParamError> {
        let lists: [(&'static str, usize); 6] = [
            ("zeta", spec.zeta.len()),
            ("wheel_diameter_ratio", spec.wheel_diameter_ratio.len()),
            ("wheelbase_ratio", spec.wheelbase_ratio.len()),
            ("slip", spec.slip.len()),
            ("fix_every", spec.fix_every.len()),
            ("seeds", spec.seeds.len()),
        ];
        for (field, n) in lists {
            if n == 0 {
                return Err(ParamError::new(field, 0.0, EMPTY_LIST));
            }
        }
        for (field, values) in [("zeta", &spec.zeta), ("slip", &spec.slip)] {
            for &v in values {
                check::non_negative(field, v)?;
            }
        }
        for (field, values) in [
            ("wheel_diameter_ratio", &spec.wheel_diameter_ratio),
            ("wheelbase_ratio", &spec.wheelbase_ratio),
        ] {
            for &v in values {
                check::positive(field, v)?;
            }
        }
        if !(spec.gamma > 0.0 && spec.gamma < 1.0) {
            return Err(ParamError::new(
                "gamma",
                spec.gamma,
                "must be in (0, 1) (Theorem 2's γ)",
            ));
        }
        check::non_negative("transient", spec.transient)?;
        // A value given twice would run its cases twice, into rows a reader
        // takes for different cases (or averages twice as often).
        for (field, values) in [
            ("zeta", &spec.zeta),
            ("wheel_diameter_ratio", &spec.wheel_diameter_ratio),
            ("wheelbase_ratio", &spec.wheelbase_ratio),
            ("slip", &spec.slip),
        ] {
            if let Some(v) = repeated(values, f64::total_cmp) {
                // `+ 0.0`: `-0` and `0` are one value, shown as `0`.
                return Err(ParamError::new(field, v + 0.0, REPEATED));
            }
        }
        for (field, values) in [("fix_every", &spec.fix_every), ("seeds", &spec.seeds)] {
            if let Some(n) = repeated(values, u64::cmp) {
                return Err(ParamError::new(field, n as f64, REPEATED));
            }
        }
        Ok(Grid(spec))
    }

    /// What the grid holds.
    pub fn spec(&self) -> &GridSpec {
        &self.0
    }

    /// Every case, in grid order: ζ, E_d, E_b, slip, N, then seed varies fastest.
    pub fn cases(&self) -> Vec<Case> {
        let mut out = Vec::new();
        for &zeta in &self.0.zeta {
            for &ed in &self.0.wheel_diameter_ratio {
                for &eb in &self.0.wheelbase_ratio {
                    for &slip in &self.0.slip {
                        for &fix_every in &self.0.fix_every {
                            for &seed in &self.0.seeds {
                                out.push(Case {
                                    zeta,
                                    wheel_diameter_ratio: ed,
                                    wheelbase_ratio: eb,
                                    slip,
                                    fix_every,
                                    seed,
                                });
                            }
                        }
                    }
                }
            }
        }
        out
    }
}

/// The scenario with a case's odometry and fixes applied to every agent
/// ([`Scenario::with_odometry`]: the file's other odometry settings — period,
/// ticks, noise, fix noise — are kept; a refused value names its flag).
pub fn apply(scenario: &Scenario, case: &Case, zeta_model: ZetaModel) -> Scenario {
    scenario.with_odometry(&OdometryOverrides {
        zeta: case.zeta,
        zeta_model,
        wheel_diameter_ratio: case.wheel_diameter_ratio,
        wheelbase_ratio: case.wheelbase_ratio,
        slip: case.slip,
        fix_every: case.fix_every,
    })
}

/// The scenario of one case ([`apply`]), built with the case's seed.
fn build_case(
    scenario: &Scenario,
    overrides: &Overrides,
    grid: &Grid,
    case: &Case,
) -> Result<Run, SweepError> {
    let s = apply(scenario, case, grid.0.zeta_model);
    Ok(s.build(&Overrides {
        seed: Some(case.seed),
        ..*overrides
    })?)
}

/// Runs one case and reduces it to a [`Row`]; a run that diverges gives
/// its row too, with [`Row::diverged`] set (see the [module docs](self)).
pub fn run_case(
    scenario: &Scenario,
    overrides: &Overrides,
    grid: &Grid,
    case: &Case,
) -> Result<Row, SweepError> {
    Ok(run_case_with_divergence(scenario, overrides, grid, case)?.0)
}

/// The row of a case whose run diverged at `divergence`.
fn diverged_row(case: &Case, divergence: &Divergence) -> Row {
    Row {
        case: *case,
        omega_max: f64::INFINITY,
        z_max: f64::INFINITY,
        z_hat_max: f64::INFINITY,
        e_max: f64::INFINITY,
        final_drift: f64::INFINITY,
        drift_max: f64::INFINITY,
        z_bound: None,
        z_over_bound: None,
        e_bound: None,
        laws: Laws::default(),
        diverged: Some(divergence.t),
    }
}

/// [`run_case`], with what left its bound when the run diverged.
fn run_case_with_divergence(
    scenario: &Scenario,
    overrides: &Overrides,
    grid: &Grid,
    case: &Case,
) -> Result<(Row, Option<Divergence>), SweepError> {
    let run = build_case(scenario, overrides, grid, case)?;
    let sim = &mut run.simulation();
    let mut peaks = Peaks::new(sim.agents().len());
    let transient = grid.0.transient;
    let mut observe = |f: &Frame<'_>| -> Result<(), ObserverError> {
        peaks.observe(f, transient);
        Ok(())
    };
    if let Err(e) = sim.run(&mut observe) {
        let Some(divergence) = Divergence::of(&e) else {
            return Err(e.into());
        };
        return Ok((diverged_row(case, &divergence), Some(divergence)));
    }
    let [z_bound, ratio, e_bound] = theorem_bounds(scenario, grid, case, sim, &peaks)?;
    let laws = Laws::of(
        sim.agents()
            .iter()
            .enumerate()
            .filter(|&(i, _)| dead_reckoning(sim, i))
            .map(|(_, a)| a.law()),
    );
    let row = Row {
        case: *case,
        omega_max: peaks.omega_max.iter().copied().fold(0.0, f64::max),
        z_max: peaks.z_max.iter().copied().fold(0.0, f64::max),
        z_hat_max: peaks.z_hat_max,
        e_max: peaks.e_max.iter().copied().fold(0.0, f64::max),
        final_drift: peaks.drift,
        drift_max: peaks.drift_max,
        z_bound,
        z_over_bound: ratio,
        e_bound,
        laws,
        diverged: None,
    };
    Ok((row, None))
}

/// Whether the file's other odometry settings keep Theorem 2's assumptions:
/// ideal encoders, exact speeds, exact and immediate fixes.
fn noise_free(s: &Scenario) -> bool {
    let f = &s.file;
    let odometry_ok = |o: &OdometrySection| {
        o.ticks_per_rev.is_none()
            && o.speed_noise.unwrap_or(0.0) == 0.0
            && o.turn_rate_noise.unwrap_or(0.0) == 0.0
    };
    let fixes_ok = |x: &FixesSection| {
        x.position_noise.unwrap_or(0.0) == 0.0
            && x.heading_noise.unwrap_or(0.0) == 0.0
            && x.latency.unwrap_or(0.0) == 0.0
            && x.fusion.is_none_or(|m| m == Fusion::Reset)
    };
    f.odometry.as_ref().is_none_or(odometry_ok)
        && f.fixes.as_ref().is_none_or(fixes_ok)
        && f.agents.iter().all(|a| {
            a.odometry.as_ref().is_none_or(odometry_ok) && a.fixes.as_ref().is_none_or(fixes_ok)
        })
}

/// Runs every case of `grid` in parallel on the current rayon pool; `progress`
/// is called once per finished run. Rows are in grid order, one per case: a
/// run that diverges is recorded in its row ([`Row::diverged`]), not
/// dropped nor averaged in. Fails on the first case (in grid order) that
/// fails otherwise; see [`run_all`] for what left its bound.
pub fn run(
    scenario: &Scenario,
    overrides: &Overrides,
    grid: &Grid,
    progress: &(dyn Fn() + Sync),
) -> Result<Vec<Row>, SweepError> {
    Ok(run_all(scenario, overrides, grid, progress)?.rows)
}

/// As [`run`], with what left its bound in each case that diverged
/// ([`Sweep::diverged`], `echelon sweep`'s `diverged.csv`).
pub fn run_all(
    scenario: &Scenario,
    overrides: &Overrides,
    grid: &Grid,
    progress: &(dyn Fn() + Sync),
) -> Result<Sweep, SweepError> {
    let mut sweep = Sweep::default();
    for (case, outcome) in outcomes(scenario, overrides, grid, progress)? {
        let (row, divergence) = outcome?;
        sweep.rows.push(row);
        if let Some(divergence) = divergence {
            sweep.diverged.push(DivergedCase { case, divergence });
        }
    }
    Ok(sweep)
}

/// A case and what running it gave.
type Outcome = (Case, Result<(Row, Option<Divergence>), SweepError>);

/// Every case with its outcome, in grid order.
fn outcomes(
    scenario: &Scenario,
    overrides: &Overrides,
    grid: &Grid,
    progress: &(dyn Fn() + Sync),
) -> Result<Vec<Outcome>, SweepError> {
    let cases = grid.cases();
    // Build every error model up front (the seed changes no check) so that
    // a broken scenario or a refused grid value fails before any work.
    let seed = grid.0.seeds[0];
    for case in cases.iter().filter(|c| c.seed == seed) {
        build_case(scenario, overrides, grid, case)?;
    }
    Ok(cases
        .into_par_iter()
        .map(|case| {
            let row = run_case_with_divergence(scenario, overrides, grid, &case);
            progress();
            (case, row)
        })
        .collect())
}

#[cfg(test)]
mod tests;
