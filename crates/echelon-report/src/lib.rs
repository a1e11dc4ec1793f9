//! Seeing an echelon run: the paper's figures as SVG and PNG, a self-contained
//! HTML report with an animated replay, and the `L_Ycomp` fit (paper eqs. 5–6).
//!
//! Kept out of the core `echelon` crate so that it builds in seconds.
//!
//! - [`figure`]: a small figure builder (panels of lines, segments, robot
//!   markers; one style; SVG + PNG with an embedded font) for any crate's figures;
//! - [`run`]: an output directory of `echelon run`, read back;
//! - [`plots`]: the run figures `paths`, `errors`, `signals` (paper Figs. 8–17;
//!   for velocity bases, commanded against actual `v`, `ω` and saturation);
//! - [`safety`]: the `safety` figure of a run with a safety filter (closest
//!   pair, obstacle clearance, when the filters acted);
//! - [`html`]: `report.html`, with the replay;
//! - [`replay`]: the replay's drawing, shared with the fleet's live dashboard;
//! - [`lycomp`]: eq. 5 against eq. 6 (Fig. 5), and refitting eq. 6 for any `L_Xoff`.

#![cfg_attr(not(test), warn(clippy::too_many_lines))]

pub mod figure;
pub mod html;
pub mod lycomp;
pub mod odometry;
pub mod plots;
pub mod replay;
pub mod run;
pub mod safety;

use std::path::{Path, PathBuf};

pub use run::RunData;

/// Everything that can go wrong here.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A run directory's file is not what `echelon run` writes.
    #[error("{path}: {message}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong, and where (line).
        message: String,
    },
    /// A run file does not parse (the core's reader names file and line).
    #[error(transparent)]
    Output(#[from] echelon::OutputError),
    /// Drawing a figure failed.
    #[error("drawing a figure: {0}")]
    Draw(String),
    /// A refused argument (e.g. `L_Xoff ≤ 0`).
    #[error("{0}")]
    Invalid(String),
}

/// Writes `bytes` to `path` through a temporary file and a rename, so a reader
/// never sees half a file.
pub(crate) fn write_file(path: &Path, bytes: &[u8]) -> Result<(), ReportError> {
    let io = |source| ReportError::Io {
        path: path.to_path_buf(),
        source,
    };
    let part = echelon::output::part_path(path);
    std::fs::write(&part, bytes).map_err(io)?;
    std::fs::rename(&part, path).map_err(io)
}

/// Removes the figure `stem` (`.svg` and `.png`) from `dir`, if there.
fn remove_figure(dir: &Path, stem: &str) -> Result<(), ReportError> {
    for ext in ["svg", "png"] {
        echelon::output::remove_if_present(&dir.join(format!("{stem}.{ext}")))?;
    }
    Ok(())
}

/// Removes what [`write_all`] writes (every run figure and `report.html`)
/// from `dir`, if there: `echelon run` calls it, as what an earlier run
/// drew there is not the new run's.
pub fn remove_all(dir: &Path) -> Result<(), ReportError> {
    for stem in plots::RUN_FIGURES {
        remove_figure(dir, stem)?;
    }
    echelon::output::remove_if_present(&dir.join(html::REPORT_FILE))?;
    Ok(())
}

/// What [`write_all`] wrote.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Written {
    /// The figures, SVG and PNG each.
    pub figures: Vec<figure::Saved>,
    /// `DIR/report.html`.
    pub report: PathBuf,
    /// The run diverged (`summary.json`'s `diverged`): its one-line message.
    /// The figures and the report then stop at its last state within
    /// bounds, and the report says so.
    pub diverged: Option<String>,
}

impl Written {
    /// The figure `name` (`drift` for `drift.svg` and `drift.png`), if written.
    pub fn figure(&self, name: &str) -> Option<&figure::Saved> {
        let svg = format!("{name}.svg");
        self.figures.iter().find(|f| f.svg.ends_with(&svg))
    }
}

/// Reads the run in `dir` and writes its figures (`paths`, `errors`,
/// `signals`, as SVG and PNG) and `report.html` next to `trajectory.csv`.
pub fn write_all(dir: &Path) -> Result<Written, ReportError> {
    let data = RunData::load(dir)?;
    let figures = plots::run_figures(&data);
    let mut saved = Vec::new();
    let mut svgs = Vec::new();
    for (stem, fig) in &figures {
        let svg = fig.svg()?;
        saved.push(fig.save_with_svg(dir, stem, &svg)?);
        svgs.push((*stem, svg));
    }
    let report = dir.join(html::REPORT_FILE);
    write_file(&report, html::report(&data, &svgs).as_bytes())?;
    // A figure this run does not have (`drift`, `safety`), drawn for an
    // earlier run into the same directory, is not this run's.
    for stem in plots::RUN_FIGURES {
        if !figures.iter().any(|(s, _)| *s == stem) {
            remove_figure(dir, stem)?;
        }
    }
    Ok(Written {
        figures: saved,
        report,
        diverged: data.summary.diverged.as_ref().map(|d| d.message.clone()),
    })
}
