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

/// `v` with `places` decimals, or in exponent form when that would show
/// no digit or too many (an `L_Xoff` of 1e-9 m or 1e9 m).
fn shown(v: f64, places: usize) -> String {
    let a = v.abs();
    if a != 0.0 && !(1e-3..1e6).contains(&a) {
        format!("{v:.4e}")
    } else {
        format!("{v:.places$}")
    }
}

fn describe(name: &str, c: &FitCoefficients, gap: &Gap) -> anyhow::Result<()> {
    outln!(
        "  {name:<22} G = {:<9} δ = {:<9} ε = {:<9} largest gap to eq. 5: {} m at |R_C| = {} m (RMS {} m)",
        shown(c.g, 6),
        shown(c.delta, 6),
        shown(c.epsilon, 6),
        shown(gap.gap, 3),
        shown(gap.at, 3),
        shown(gap.rms, 4)
    )?;
    Ok(())
}

/// Prints the largest gaps (and the refit) and writes the figure.
pub(crate) fn lycomp(args: &LycompArgs) -> Result<()> {
    let lambda = args.lxoff;
    let (lo, hi) = FitCoefficients::PAPER_RANGE;
    let in_range = (lo..=hi).contains(&lambda);
    // The output directory first: a refused --out prints nothing else.
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("out").join("lycomp"));
    if out.exists() && !out.is_dir() {
        anyhow::bail!(
            "--out {}: is a file, not a directory (lycomp.svg and lycomp.png go in it)",
            out.display()
        );
    }
    std::fs::create_dir_all(&out).with_context(|| format!("--out: creating {}", out.display()))?;
    let mut fits: Vec<(&str, FitCoefficients)> = Vec::new();
    outln!(
        "L_Ycomp for L_Xoff = {} m, |R_C| ≤ {} m:",
        echelon::error::num(lambda),
        echelon::error::num(lycomp::GAP_SPAN * lambda)
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
    let saved = lycomp::figure(lambda, &fits).save(&out, "lycomp")?;
    outln!("wrote {}, {}", saved.svg.display(), saved.png.display())?;
    Ok(())
}
