//! `echelon plot`: a run directory's figures and report.html.

use std::path::{Path, PathBuf};
use std::time::Instant;

use super::out::outln;
use anyhow::{Context, Result};

/// Arguments of `echelon plot`.
#[derive(Debug, clap::Args)]
pub(crate) struct PlotArgs {
    /// An output directory of `echelon run` (with trajectory.csv and summary.json).
    dir: PathBuf,
    /// Print nothing but errors.
    #[arg(long, short)]
    quiet: bool,
}

/// Draws the figures of `dir` and writes its report. A diverged run's
/// figures are drawn too (up to its last state within bounds), and the
/// command then fails as `echelon run` did: exit 1, naming the divergence.
pub(crate) fn plot(args: &PlotArgs) -> Result<()> {
    if let Some(message) = draw(&args.dir, args.quiet)?.diverged {
        return Err(super::out::Failed(format!(
            "{}: the run diverged: {message} (figures and report.html show it up to then)",
            args.dir.display()
        ))
        .into());
    }
    Ok(())
}

/// Writes `dir`'s figures and `report.html`; lists them unless `quiet`.
pub(crate) fn draw(dir: &Path, quiet: bool) -> Result<echelon_report::Written> {
    let started = Instant::now();
    let written =
        echelon_report::write_all(dir).with_context(|| format!("plotting {}", dir.display()))?;
    if !quiet {
        let mut files: Vec<String> = written
            .figures
            .iter()
            .flat_map(|f| [f.svg.display().to_string(), f.png.display().to_string()])
            .collect();
        files.push(written.report.display().to_string());
        outln!(
            "wrote {} in {:.2} s",
            files.join(", "),
            started.elapsed().as_secs_f64()
        )?;
    }
    Ok(written)
}
