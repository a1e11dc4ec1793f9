//! `echelon lycomp`: eq. 5 against eq. 6 (the paper's Fig. 5), and refitting
//! eq. 6 for any `L_Xoff`.

use std::path::PathBuf;

use anyhow::{Context, Result};

use echelon::lycomp::FitCoefficients;
use echelon_report::lycomp::{self, Gap};

use super::out::outln;
use super::positive;

/// Arguments of `echelon lycomp`.
#[derive(Debug, clap::Args)]
pub(crate) struct LycompArgs {
    /// L_Xoff = λ, m (the paper's polynomials for G, δ, ε hold for 0.1–0.9).
    #[arg(long, value_name = "M", value_parser = positive)]
    lxoff: f64,
    /// Also refit G, δ, ε of eq. 6 by least squares for this L_Xoff.
    #[arg(long)]
    fit: bool,
    /// Where to write lycomp.svg and lycomp.png [default: out/lycomp].
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
}

fn describe(name: &str, c: &FitCoefficients, gap: &Gap) -> anyhow::Result<()> {
    outln!(
        "  {name:<22} G = {:<9.6} δ = {:<9.6} ε = {:<9.6} largest gap to eq. 5: {:.3} m at |R_C| = {:.3} m (RMS {:.4} m)",
        c.g,
        c.delta,
        c.epsilon,
        gap.gap,
        gap.at,
        gap.rms
    )?;
    Ok(())
}

/// Prints the largest gaps (and the refit) and writes the figure.
pub(crate) fn lycomp(args: &LycompArgs) -> Result<()> {
    let lambda = args.lxoff;
    let (lo, hi) = FitCoefficients::PAPER_RANGE;
    let in_range = (lo..=hi).contains(&lambda);
    let mut fits: Vec<(&str, FitCoefficients)> = Vec::new();
    outln!(
        "L_Ycomp for L_Xoff = {lambda} m, |R_C| ≤ {} m:",
        lycomp::GAP_SPAN * lambda
    )?;
    if in_range {
        let paper = FitCoefficients::paper(lambda);
        describe(
            "eq. 6, paper (§4.1)",
            &paper,
            &lycomp::largest_gap(&paper, lambda),
        )?;
        fits.push(("eq. 6, paper's G, δ, ε", paper));
    } else {
        super::out::err_line(&format!(
            "warning: the paper's polynomials for G, δ, ε hold only for L_Xoff in {lo}–{hi} m: showing the least-squares refit"
        ));
    }
    if args.fit || !in_range {
        let refit = lycomp::refit(lambda)?;
        let c = refit.coefficients;
        describe("eq. 6, least squares", &c, &lycomp::largest_gap(&c, lambda))?;
        outln!(
            "  (weighted least squares on 0 < R_C ≤ {}λ, weight {} beyond R_C = λ; {} Levenberg–Marquardt iterations)",
            lycomp::FIT_SPAN,
            lycomp::TAIL_WEIGHT,
            refit.iterations
        )?;
        fits.push(("eq. 6, least-squares refit", c));
    }
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("out").join("lycomp"));
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let saved = lycomp::figure(lambda, &fits).save(&out, "lycomp")?;
    outln!("wrote {}, {}", saved.svg.display(), saved.png.display())?;
    Ok(())
}
