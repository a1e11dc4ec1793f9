//! `echelon bound`: Theorem 2 both ways — the ultimate bound on ‖z‖ for a fix
//! every N samples, or the largest N (and fix period) for a bound you can accept.

use anyhow::{Result, bail};

use echelon::odometry::bound::Theorem2;

use super::out::outln;
use super::{non_negative, positive};

/// Arguments of `echelon bound`.
#[derive(Debug, clap::Args)]
#[command(group(clap::ArgGroup::new("target").required(true).args(["steps", "max_z", "max_e"])))]
pub(crate) struct BoundArgs {
    /// K_e > 0.
    #[arg(long, value_name = "KE", default_value_t = 1.5, value_parser = positive)]
    ke: f64,
    /// K_z > 0.
    #[arg(long, value_name = "KZ", default_value_t = 10.0, value_parser = positive)]
    kz: f64,
    /// ζ: the largest odometry error per axis per sample, m.
    #[arg(long, value_name = "M", value_parser = positive)]
    zeta: f64,
    /// ω_M: the largest angular speed of the robot, rad/s.
    #[arg(long, value_name = "RAD_S", value_parser = non_negative)]
    omega_max: f64,
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

/// Runs `echelon bound`.
pub(crate) fn bound(a: &BoundArgs) -> Result<()> {
    let t = Theorem2::new(a.ke, a.kz, a.zeta, a.omega_max, a.gamma)?;
    let report = match (a.steps, a.max_z, a.max_e) {
        (Some(0), ..) => bail!("--steps 0: N counts the samples between fixes and must be ≥ 1"),
        (Some(n), ..) => t.forward(n, a.ts),
        (None, Some(z), _) => t.inverse(z, a.ts)?,
        (None, None, Some(e)) => t.inverse(a.ke * e, a.ts)?,
        (None, None, None) => bail!("give --steps, --max-z or --max-e"),
    };
    // ‖e‖ is ultimately within ‖z‖/K_e: V̇₁ = −K_e‖e‖² + eᵀz < 0 beyond it.
    let e_bound = report.z_bound / a.ke;
    if a.json {
        let mut v = serde_json::to_value(report)?;
        v["e_bound"] = serde_json::json!(e_bound);
        outln!("{v}")?;
        return Ok(());
    }
    outln!("Theorem 2: ‖z‖ ≤ √2 K_e N ζ √(K_z² + ω_M²) / (K_z γ)")?;
    outln!(
        "  K_e = {}, K_z = {}, ζ = {} m, ω_M = {} rad/s, γ = {}",
        a.ke,
        a.kz,
        a.zeta,
        a.omega_max,
        a.gamma
    )?;
    if a.steps.is_none() {
        let (what, target) = match (a.max_z, a.max_e) {
            (Some(z), _) => ("‖z‖", format!("{z} m/s")),
            (_, e) => ("‖e‖", format!("{} m", e.unwrap_or_default())),
        };
        if report.steps == 0 {
            outln!(
                "  no fix interval keeps {what} ≤ {target}: one sample of dead reckoning already exceeds it"
            )?;
            return Ok(());
        }
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
