//! `echelon sweep`: Monte Carlo over odometry error models × fix intervals ×
//! seeds, in parallel on all cores, with Theorem 2's bound beside each run.

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use clap::ValueEnum;
use indicatif::{ProgressBar, ProgressStyle};

use echelon::odometry::ZetaModel;
use echelon::scenario::{Overrides, Scenario};
use echelon::sweep::{self, Grid, GridSpec, Row};
use echelon::{ParamError, ScenarioError};

use super::out::outln;
use super::{non_negative, positive};

/// Arguments of `echelon sweep`.
#[derive(Debug, clap::Args)]
pub(crate) struct SweepArgs {
    /// A built-in scenario name or a path to a .toml file.
    scenario: String,
    /// ζ values, m per odometry sample (comma-separated).
    #[arg(long, value_name = "M,…", value_delimiter = ',', default_value = "1e-5", value_parser = non_negative)]
    zeta: Vec<f64>,
    /// How ζ enters: `wheels` (eq. 23) or `worst-case` (eq. 31, Theorem 2's case).
    #[arg(long, value_enum, default_value_t = ZetaArg::Wheels)]
    zeta_model: ZetaArg,
    /// E_d values (wheel diameter ratio; 1 is perfect).
    #[arg(long, value_name = "ED,…", value_delimiter = ',', default_value = "1", value_parser = positive)]
    ed: Vec<f64>,
    /// E_b values (wheelbase ratio; 1 is perfect).
    #[arg(long, value_name = "EB,…", value_delimiter = ',', default_value = "1", value_parser = positive)]
    eb: Vec<f64>,
    /// Slip variances, m²/m.
    #[arg(long, value_name = "V,…", value_delimiter = ',', default_value = "0", value_parser = non_negative)]
    slip: Vec<f64>,
    /// Odometry samples between absolute fixes, N (0: no fixes).
    #[arg(
        long,
        value_name = "N,…",
        value_delimiter = ',',
        default_value = "10,20,50,100,200,500"
    )]
    fix_every: Vec<u64>,
    /// Seeds per combination (runs of each combination, seeds SEED, SEED + 1, …).
    #[arg(long, value_name = "K", default_value_t = 4, value_parser = seed_count)]
    seeds: u64,
    /// First seed.
    #[arg(long, value_name = "N", default_value_t = 0)]
    seed: u64,
    /// Theorem 2's γ ∈ (0, 1) for the bound column.
    #[arg(long, default_value_t = 0.99)]
    gamma: f64,
    /// Statistics are taken after this time, s [default: half the duration].
    #[arg(long, value_name = "S", value_parser = non_negative)]
    transient: Option<f64>,
    /// Simulated time of each run, s (overrides the scenario's).
    #[arg(long, value_name = "S", value_parser = positive)]
    duration: Option<f64>,
    /// RK4 step, s (overrides the scenario's).
    #[arg(long, value_name = "S", value_parser = positive)]
    dt: Option<f64>,
    /// Worker threads [default: all cores].
    #[arg(long, value_name = "K")]
    threads: Option<usize>,
    /// Output directory [default: out/<scenario>-sweep].
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Print nothing but errors.
    #[arg(long, short)]
    quiet: bool,
}

/// A grid value refused, named by its flag as a scenario's value set by a
/// flag is (`command line: --gamma: 2 must be in (0, 1) …`).
fn flag_error(flag: &str, e: &ParamError) -> anyhow::Error {
    ScenarioError::of_flag(flag, GridSpec::refusal(e)).into()
}

/// `--seeds`: how many seeds each combination runs with, at least one
/// (clap value parser).
fn seed_count(s: &str) -> Result<u64, String> {
    match s.parse::<u64>() {
        Ok(n) if n >= 1 => Ok(n),
        Ok(_) => Err(format!(
            "{s} seeds per combination: the number of runs of each combination (seeds SEED, SEED + 1, …) must be ≥ 1"
        )),
        Err(_) => Err(format!("`{s}` is not a whole number of seeds (≥ 1)")),
    }
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum ZetaArg {
    /// Eq. 23: the same ζ on both wheels; the heading stays exact.
    Wheels,
    /// Eq. 31: ζ on both world axes every sample.
    WorstCase,
}

/// Runs `echelon sweep`.
pub(crate) fn sweep(a: &SweepArgs) -> Result<()> {
    let scenario = Scenario::resolve(&a.scenario)?;
    let overrides = Overrides {
        dt: a.dt,
        duration: a.duration,
        ..Overrides::default()
    };
    let last = last_seed(a)?;
    let grid = grid_of(a, &scenario, &overrides, last)?;
    let total = grid.cases().len();
    let pool = thread_pool(a.threads)?;
    let bar = progress_bar(a.quiet, total, scenario.name());
    let started = Instant::now();
    let (rows, curves) = run_grid(&pool, &scenario, &overrides, &grid, &bar)?;
    let sweep::Sweep { rows, diverged } = rows;
    bar.finish_and_clear();
    let out = a
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("out").join(format!("{}-sweep", scenario.name())));
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let path = out.join("sweep.csv");
    write_file(&path, |w| {
        sweep::write_csv(w, &rows, grid.spec().zeta_model)
    })?;
    let drift_path = out.join("drift.csv");
    write_file(&drift_path, |w| sweep::write_drift_csv(w, &curves))?;
    // The figure plots the runs that ended (a diverged run has no maxima to
    // plot); the table and sweep.csv show every run.
    let ended: Vec<Row> = rows.iter().filter(|r| !r.is_diverged()).copied().collect();
    let figure =
        echelon_report::odometry::sweep(scenario.name(), &ended, &curves).save(&out, "sweep")?;
    if !a.quiet {
        print_summary(
            &rows,
            total,
            pool.current_num_threads(),
            started.elapsed().as_secs_f64(),
        )?;
        outln!(
            "wrote {}, {}, {}, {}",
            path.display(),
            drift_path.display(),
            figure.svg.display(),
            figure.png.display()
        )?;
    }
    // A diverged case does not stop the sweep (its row is written above,
    // marked) but fails it: what left its bound goes to diverged.csv and the
    // exit code is 1.
    let diverged_path = out.join("diverged.csv");
    if diverged.is_empty() {
        return remove_stale(&diverged_path);
    }
    write_file(&diverged_path, |w| {
        sweep::write_diverged_csv(w, &diverged, grid.spec().zeta_model)
    })?;
    let first = &diverged[0];
    Err(super::out::Failed(format!(
        "{} of {total} runs diverged, listed in {} (the first: ζ = {}, E_d = {}, E_b = {}, slip = {}, N = {}, seed {}: {}); all {} runs are rows of {}, the diverged ones with their `diverged` time and `inf` statistics",
        diverged.len(),
        diverged_path.display(),
        first.case.zeta,
        first.case.wheel_diameter_ratio,
        first.case.wheelbase_ratio,
        first.case.slip,
        first.case.fix_every,
        first.case.seed,
        first.divergence.message,
        rows.len(),
        path.display(),
    ))
    .into())
}

/// The last seed, SEED + K − 1, refused past `u64::MAX` (the seeds
/// SEED ..= SEED + K − 1 must all exist; K ≥ 1: `seed_count`).
fn last_seed(a: &SweepArgs) -> Result<u64> {
    a.seed.checked_add(a.seeds - 1).ok_or_else(|| {
        ScenarioError::of_flag(
            "--seed",
            format_args!(
                "{} with --seeds {}: the last seed would be past {} (the largest seed)",
                a.seed,
                a.seeds,
                u64::MAX
            ),
        )
        .into()
    })
}

/// The grid of the flags' values with the seeds up to `last` (the
/// transient by default half the run's duration), a value refused named by
/// its flag.
fn grid_of(a: &SweepArgs, scenario: &Scenario, overrides: &Overrides, last: u64) -> Result<Grid> {
    let probe = scenario.build(overrides)?;
    let duration = probe.plan.steps() as f64 * probe.plan.config().dt;
    Grid::new(GridSpec {
        zeta: a.zeta.clone(),
        zeta_model: match a.zeta_model {
            ZetaArg::Wheels => ZetaModel::Wheels,
            ZetaArg::WorstCase => ZetaModel::WorstCase,
        },
        wheel_diameter_ratio: a.ed.clone(),
        wheelbase_ratio: a.eb.clone(),
        slip: a.slip.clone(),
        fix_every: a.fix_every.clone(),
        seeds: (a.seed..=last).collect(),
        gamma: a.gamma,
        transient: a.transient.unwrap_or(0.5 * duration),
    })
    .map_err(|e| match GridSpec::flag(e.field) {
        Some(flag) => flag_error(flag, &e),
        None => e.into(),
    })
}

/// The worker threads: `--threads` of them, else one per core.
fn thread_pool(threads: Option<usize>) -> Result<rayon::ThreadPool> {
    let mut b = rayon::ThreadPoolBuilder::new();
    if let Some(k) = threads {
        anyhow::ensure!(k >= 1, "--threads must be ≥ 1");
        b = b.num_threads(k);
    }
    Ok(b.build()?)
}

/// The progress bar of `total` runs, named `name` (hidden with `--quiet`).
fn progress_bar(quiet: bool, total: usize, name: &str) -> ProgressBar {
    let bar = if quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(total as u64)
    };
    bar.set_style(
        ProgressStyle::with_template("{prefix} [{bar:30}] {pos}/{len} runs, {eta} left")
            .map_or_else(
                |_| ProgressStyle::default_bar(),
                |s| s.progress_chars("=> "),
            ),
    );
    bar.set_prefix(name.to_owned());
    bar
}

/// Every run of `grid` on `pool` (`bar` told of each), then the drift
/// curves; a value refused is named by its flag.
fn run_grid(
    pool: &rayon::ThreadPool,
    scenario: &Scenario,
    overrides: &Overrides,
    grid: &Grid,
    bar: &ProgressBar,
) -> Result<(sweep::Sweep, Vec<sweep::DriftCurve>)> {
    pool.install(|| {
        let rows = sweep::run_all(scenario, overrides, grid, &|| bar.inc(1))?;
        let curves = sweep::drift_curves(scenario, overrides, grid, 300)?;
        Ok::<_, sweep::SweepError>((rows, curves))
    })
    .map_err(|e| match e {
        sweep::SweepError::Param(p) => match GridSpec::flag(p.field) {
            Some(flag) => flag_error(flag, &p),
            None => sweep::SweepError::Param(p).into(),
        },
        e => e.into(),
    })
}

/// Creates `path` and writes it with `write`, either failure naming it.
fn write_file(
    path: &Path,
    write: impl FnOnce(BufWriter<File>) -> std::io::Result<()>,
) -> Result<()> {
    let file = File::create(path).with_context(|| format!("writing {}", path.display()))?;
    write(BufWriter::new(file)).with_context(|| format!("writing {}", path.display()))
}

/// Removes a `diverged.csv` an earlier sweep into the same directory left,
/// which would be read as this one's.
fn remove_stale(diverged_path: &Path) -> Result<()> {
    match std::fs::remove_file(diverged_path) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(e).with_context(|| format!("removing {}", diverged_path.display())),
    }
}

fn print_summary(rows: &[Row], total: usize, threads: usize, seconds: f64) -> anyhow::Result<()> {
    let diverged = rows.iter().filter(|r| r.is_diverged()).count();
    let diverged_note = if diverged == 0 {
        String::new()
    } else {
        format!(", {diverged} diverged (their maxima are inf)")
    };
    outln!(
        "{total} runs on {threads} threads in {seconds:.1} s{diverged_note}; maxima over seeds, after the transient:"
    )?;
    // The ratio column is the theorem's main ratio for the runs' law
    // (echelon::sweep's module docs): ‖e‖/e_bound under the kinematic law.
    let ratio = if rows.iter().all(|r| r.laws == sweep::Laws::Dynamic) {
        "‖z‖/bound"
    } else if rows.iter().all(|r| r.laws == sweep::Laws::Kinematic) {
        "‖e‖/e bound"
    } else {
        "ratio"
    };
    outln!(
        "  {:>8}  {:>6}  {:>6}  {:>8}  {:>6}  {:>10}  {:>10}  {:>9}  {:>10}  {:>10}  {:>8}",
        "ζ (m)",
        "E_d",
        "E_b",
        "slip",
        "N",
        "‖z‖ (m/s)",
        "bound",
        ratio,
        "‖e‖ (m)",
        "drift (m)",
        "diverged"
    )?;
    // Rows come in grid order with seeds varying fastest: group consecutive rows.
    let same =
        |a: &Row, b: &Row| sweep::Case { seed: 0, ..a.case } == sweep::Case { seed: 0, ..b.case };
    let mut start = 0;
    while start < rows.len() {
        let end = (start..rows.len())
            .find(|&k| !same(&rows[start], &rows[k]))
            .unwrap_or(rows.len());
        let group = &rows[start..end];
        let max = |f: fn(&Row) -> f64| group.iter().map(f).fold(0.0, f64::max);
        let opt_max = |f: fn(&Row) -> Option<f64>| group.iter().filter_map(f).reduce(f64::max);
        let c = &group[0].case;
        let n = if c.fix_every == 0 {
            "never".to_owned()
        } else {
            c.fix_every.to_string()
        };
        let shown =
            |v: Option<f64>, p: usize| v.map_or_else(|| "–".to_owned(), |v| format!("{v:.p$e}"));
        outln!(
            "  {:>8.1e}  {:>6}  {:>6}  {:>8.1e}  {:>6}  {:>10.3e}  {:>10}  {:>9}  {:>10.3e}  {:>10.3e}  {:>8}",
            c.zeta,
            c.wheel_diameter_ratio,
            c.wheelbase_ratio,
            c.slip,
            n,
            max(|r| r.z_max),
            shown(opt_max(|r| r.z_bound), 3),
            opt_max(|r| r.z_over_bound).map_or_else(|| "–".to_owned(), |v| format!("{v:.3}")),
            max(|r| r.e_max),
            max(|r| r.drift_max),
            // How many of the group's seeds diverged: a maximum over them
            // is inf, never one over the seeds that ended alone.
            format!(
                "{}/{}",
                group.iter().filter(|r| r.is_diverged()).count(),
                group.len()
            ),
        )?;
        start = end;
    }
    Ok(())
}
