//! The waypoint CSV reader: `t,x,y` rows from a file next to the scenario
//! (`[reference.waypoints] file = "path.csv"`).

use std::path::Path;

use crate::error::{Location, ScenarioError};

/// Why a waypoint file was refused.
#[derive(Debug)]
pub(super) enum ReadError {
    /// The file cannot be read (the caller names the scenario's field).
    Unreadable(String),
    /// A bad header, row or cell, located in the CSV file.
    Csv(ScenarioError),
}

/// Reads `t,x,y` rows (header required, `#` comments, cells trimmed).
pub(super) fn read(full: &Path) -> Result<Vec<[f64; 3]>, ReadError> {
    let shown = full.display().to_string();
    let at = |line: usize, field: &str, message: String| {
        ReadError::Csv(ScenarioError {
            location: Location {
                file: shown.clone(),
                line,
                column: 0,
            },
            field: field.to_owned(),
            message,
        })
    };
    let text = std::fs::read_to_string(full)
        .map_err(|e| ReadError::Unreadable(format!("cannot read `{shown}`: {e}")))?;
    let mut reader = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .comment(Some(b'#'))
        .from_reader(text.as_bytes());
    let headers = reader
        .headers()
        .map_err(|e| at(1, "", format!("bad CSV header: {e}")))?
        .clone();
    let col = |name: &str| {
        headers.iter().position(|h| h == name).ok_or_else(|| {
            at(
                1,
                name,
                format!(
                    "the header must name columns t, x and y (found: {})",
                    headers.iter().collect::<Vec<_>>().join(",")
                ),
            )
        })
    };
    let idx = [col("t")?, col("x")?, col("y")?];
    let mut points = Vec::new();
    for record in reader.records() {
        let record = record.map_err(|e| {
            let line = e.position().map_or(0, |p| p.line() as usize);
            at(line, "", e.to_string())
        })?;
        let line = record.position().map_or(0, |p| p.line() as usize);
        let mut p = [0.0; 3];
        for (k, (&c, name)) in idx.iter().zip(["t", "x", "y"]).enumerate() {
            let cell = record.get(c).unwrap_or("");
            p[k] = cell
                .parse()
                .map_err(|_| at(line, name, format!("`{cell}` is not a number")))?;
        }
        points.push(p);
    }
    Ok(points)
}
