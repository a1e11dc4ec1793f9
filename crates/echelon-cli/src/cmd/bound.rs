//! `echelon bound`: Theorem 2 both ways — the ultimate bound on ‖z‖ for a fix
//! every N samples, or the largest N (and fix period) for a bound you can accept;
//! for the paper's dynamic law or (`--law kinematic`) the kinematic law a
//! velocity base runs, whose bound a fleet robot taking fixes from ROS 2
//! computes for its `fixes.tolerance` (the same number for the same inputs).

use anyhow::{Result, bail};

use echelon::ParamError;
use echelon::odometry::bound::{BoundReport, KinematicTheorem2, Theorem2};

use super::out::outln;
use super::{non_negative, positive};

/// Arguments of `echelon bound`.
#[derive(Debug, clap::Args)]
#[command(group(clap::ArgGroup::new("target").required(true).args(["steps", "max_z", "max_e"])))]
pub(crate) struct BoundArgs {
    /// K_e > 0.
    #[arg(long, value_name = "KE", default_value_t = 1.5, value_parser = positive)]
    ke: f64,
    /// K_z > 0 (the dynamic law) [default: 10].
    #[arg(long, value_name = "KZ", value_parser = positive)]
    kz: Option<f64>,
    /// ζ: the largest odometry error per axis per sample, m.
    #[arg(long, value_name = "M", value_parser = positive)]
    zeta: f64,
    /// ω_M: the largest angular speed of the robot, rad/s (the dynamic law).
    #[arg(long, value_name = "RAD_S", value_parser = non_negative)]
    omega_max: Option<f64>,
    /// The law: `dynamic` (the paper's eq. 13, Theorem 2 as written) or
    /// `kinematic` (a velocity base: ‖e‖ ≤ √2 N ζ / γ, ‖z‖ ≤ √2 K_e N ζ).
    #[arg(long, value_enum, default_value_t = Law::Dynamic)]
    law: Law,
    /// γ ∈ (0, 1) of the proof; the bound is smallest as γ → 1.
    #[arg(long, value_name = "G", default_value_t = 0.99)]
    gamma: f64,
    /// Forward: samples between fixes N; prints the bound on ‖z‖.
    #[arg(long, value_name = "N")]
    steps: Option<u64>,
    /// Inverse: the largest acceptable ultimate ‖z‖, m/s; prints the largest N.
    #[arg(long, value_name = "M_S", value_parser = positive)]
    max_z: Option<f64>,
    /// Inverse: the largest acceptable ultimate ‖e‖, m (‖e‖ ≤ ‖z‖/K_e); prints the largest N.
    #[arg(long, value_name = "M", value_parser = positive)]
    max_e: Option<f64>,
    /// Sample period T_s, s: also print the fix period N·T_s.
    #[arg(long, value_name = "S", value_parser = positive)]
    ts: Option<f64>,
    /// Print {"z_bound": …, "steps": …, "fix_period_s": …, "e_bound": …}.
    #[arg(long)]
    json: bool,
}

/// `--kz` when not given (the dynamic law).
const DEFAULT_KZ: f64 = 10.0;

/// Which law's Theorem 2.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum Law {
    /// The paper's dynamic law (eq. 13).
    Dynamic,
    /// The kinematic law of a velocity base.
    Kinematic,
}

/// Theorem 2's refusal of a value, at the flag that gave it (`--gamma 1:
/// must be in (0, 1)`), not at the library's parameter (`gamma = 1`).
fn at_flag(e: ParamError) -> anyhow::Error {
    let flag = match e.field {
        "ke" => "--ke",
        "kz" => "--kz",
        "zeta" => "--zeta",
        "omega_max" => "--omega-max",
        "gamma" => "--gamma",
        "max_z" => "--max-z",
        "max_e" => "--max-e",
        _ => return e.into(),
    };
    anyhow::anyhow!("{flag} {}: {}", echelon::error::num(e.value), e.reason)
}

/// The kinematic law's Theorem 2: `N` for `--steps` or `--max-e`, with its
/// bounds.
fn kinematic(a: &BoundArgs) -> Result<()> {
    // Its bound has neither: a flag it would ignore is refused, not dropped.
    for (given, flag) in [
        (a.kz.is_some(), "--kz"),
        (a.omega_max.is_some(), "--omega-max"),
    ] {
        if given {
            bail!(
                "{flag}: the kinematic law's bound does not depend on it (‖e‖ ≤ √2 N ζ / γ); drop it, or use --law dynamic"
            );
        }
    }
    let t = KinematicTheorem2::new(a.ke, a.zeta, a.gamma).map_err(at_flag)?;
    let steps = match (a.steps, a.max_z, a.max_e) {
        (Some(0), ..) => bail!("--steps 0: N counts the samples between fixes and must be ≥ 1"),
        (Some(n), ..) => n,
        (None, Some(_), _) => {
            bail!("--law kinematic takes --max-e (its bound is on ‖e‖), not --max-z")
        }
        (None, None, Some(e)) => match t.max_steps(e).map_err(at_flag)? {
            0 => return Err(no_interval("--max-e", e, "‖e‖", "m", t.e_bound(1))),
            n => n,
        },
        (None, None, None) => bail!("give --steps or --max-e"),
    };
    let report = BoundReport {
        z_bound: t.z_bound(steps),
        steps,
        fix_period_s: a.ts.map(|ts| ts * steps as f64),
    };
    let e_bound = t.e_bound(steps);
    if a.json {
        return print_json(report, e_bound);
    }
    outln!("Theorem 2, kinematic law: ‖e‖ ≤ √2 N ζ / γ, ‖z‖ ≤ √2 K_e N ζ")?;
    outln!("  K_e = {}, ζ = {} m, γ = {}", a.ke, a.zeta, a.gamma)?;
    match a.max_e {
        Some(e) if a.steps.is_none() => {
            outln!("  largest N keeping ‖e‖ ≤ {e} m: N = {steps} samples")?;
        }
        _ => outln!("  N = {steps} samples between fixes")?,
    }
    outln!("  ultimate ‖e‖ ≤ {e_bound:.6} m")?;
    outln!("  ‖z‖ ≤ {:.6} m/s at every instant", report.z_bound)?;
    match (report.fix_period_s, a.ts) {
        (Some(p), Some(ts)) => outln!("  a fix at least every N·T_s = {p} s (T_s = {ts} s)")?,
        _ => outln!("  (give --ts to turn N into a fix period)")?,
    }
    Ok(())
}

/// The answer to an inverse question that has none: even a fix every sample
/// (`N = 1`) allows more than `target` (`flag`'s value) of `what`, up to
/// `at_one`. The command did not get what it asked for: exit 1, in text and
/// JSON alike (a JSON `N = 0` with bounds of 0 read as a bound that holds).
fn no_interval(flag: &str, target: f64, what: &str, unit: &str, at_one: f64) -> anyhow::Error {
    let num = echelon::error::num;
    super::out::Failed(format!(
        "{flag} {}: no fix interval keeps {what} ≤ {} {unit}: a fix every sample (N = 1) already allows {what} up to {at_one:.3e} {unit}",
        num(target),
        num(target),
    ))
    .into()
}

/// Prints `report` with `e_bound` as one JSON line.
fn print_json(report: BoundReport, e_bound: f64) -> Result<()> {
    let mut v = serde_json::to_value(report)?;
    v["e_bound"] = serde_json::json!(e_bound);
    outln!("{v}")?;
    Ok(())
}

/// Runs `echelon bound`.
pub(crate) fn bound(a: &BoundArgs) -> Result<()> {
    if a.law == Law::Kinematic {
        return kinematic(a);
    }
    let Some(omega_max) = a.omega_max else {
        bail!("the dynamic law's bound needs --omega-max (the largest angular speed, rad/s)");
    };
    let kz = a.kz.unwrap_or(DEFAULT_KZ);
    let t = Theorem2::new(a.ke, kz, a.zeta, omega_max, a.gamma).map_err(at_flag)?;
    let report = match (a.steps, a.max_z, a.max_e) {
        (Some(0), ..) => bail!("--steps 0: N counts the samples between fixes and must be ≥ 1"),
        (Some(n), ..) => t.forward(n, a.ts),
        (None, Some(z), _) => t.inverse(z, a.ts).map_err(at_flag)?,
        // ‖e‖ ≤ ‖z‖/K_e: a refusal of the ‖z‖ it asks for is of --max-e.
        (None, None, Some(e)) => t
            .inverse(a.ke * e, a.ts)
            .map_err(|err| at_flag(ParamError::new("max_e", e, err.reason)))?,
        (None, None, None) => bail!("give --steps, --max-z or --max-e"),
    };
    if report.steps == 0 {
        return Err(match (a.max_z, a.max_e) {
            (Some(z), _) => no_interval("--max-z", z, "‖z‖", "m/s", t.z_bound(1)),
            (_, e) => no_interval(
                "--max-e",
                e.unwrap_or_default(),
                "‖e‖",
                "m",
                t.z_bound(1) / a.ke,
            ),
        });
    }
    // ‖e‖ is ultimately within ‖z‖/K_e: V̇₁ = −K_e‖e‖² + eᵀz < 0 beyond it.
    let e_bound = report.z_bound / a.ke;
    if a.json {
        return print_json(report, e_bound);
    }
    outln!("Theorem 2: ‖z‖ ≤ √2 K_e N ζ √(K_z² + ω_M²) / (K_z γ)")?;
    outln!(
        "  K_e = {}, K_z = {}, ζ = {} m, ω_M = {} rad/s, γ = {}",
        a.ke,
        kz,
        a.zeta,
        omega_max,
        a.gamma
    )?;
    if a.steps.is_none() {
        let (what, target) = match (a.max_z, a.max_e) {
            (Some(z), _) => ("‖z‖", format!("{z} m/s")),
            (_, e) => ("‖e‖", format!("{} m", e.unwrap_or_default())),
        };
        outln!(
            "  largest N keeping {what} ≤ {target}: N = {} samples",
            report.steps
        )?;
    } else {
        outln!("  N = {} samples between fixes", report.steps)?;
    }
    outln!("  ultimate ‖z‖ ≤ {:.6} m/s", report.z_bound)?;
    outln!("  ultimate ‖e‖ ≤ ‖z‖/K_e = {:.6} m", e_bound)?;
    match (report.fix_period_s, a.ts) {
        (Some(p), Some(ts)) => outln!("  a fix at least every N·T_s = {p} s (T_s = {ts} s)")?,
        _ => outln!("  (give --ts to turn N into a fix period)")?,
    }
    Ok(())
}
