//! The waypoint CSV reader: `t,x,y` rows from a file next to the scenario
//! (`[reference.waypoints] file = "path.csv"`). Every refusal names the CSV
//! file, its line and the 1-based column of the offending cell.

use std::path::Path;

use crate::error::{Location, ReferenceError, ScenarioError};

/// Why a waypoint file was refused.
#[derive(Debug)]
pub(super) enum ReadError {
    /// The file cannot be read (the caller names the scenario's field).
    Unreadable(String),
    /// A bad header, row or cell, located in the CSV file.
    Csv(ScenarioError),
}

/// The columns of a waypoint file, in the order of a point's coordinates.
const COLUMNS: [&str; 3] = ["t", "x", "y"];

/// The waypoints of a CSV file, with where each came from.
#[derive(Debug)]
pub(super) struct Table {
    /// `[t, x, y]` of each row.
    pub(super) points: Vec<[f64; 3]>,
    /// Each row's line and the columns of its `t`, `x`, `y` cells (1-based).
    places: Vec<(usize, [usize; 3])>,
    /// The header's line.
    header_line: usize,
    /// The file, as shown in errors.
    shown: String,
}

impl Table {
    /// An error at `line:column` of the file.
    fn at(&self, line: usize, column: usize, field: &str, message: String) -> ScenarioError {
        located(&self.shown, line, column, field, message)
    }

    /// The refusal of the spline through these points ([`crate::reference::Waypoints::new`]),
    /// at the row and cell it names.
    pub(super) fn error(&self, e: &ReferenceError) -> ScenarioError {
        let row = |index: usize, coordinate: usize| {
            let (line, columns) = self.places[index - 1];
            self.at(
                line,
                columns[coordinate],
                COLUMNS[coordinate],
                e.to_string(),
            )
        };
        match e {
            ReferenceError::TimesNotIncreasing { index, .. }
            | ReferenceError::WaypointsTooClose { index, .. }
            | ReferenceError::WaypointsTooFast { index, .. }
            | ReferenceError::WaypointsOvershoot { index, .. } => row(*index, 0),
            ReferenceError::NonFiniteWaypoint {
                index, coordinate, ..
            } => row(*index, *coordinate),
            // Too few rows: the last one, or the header.
            ReferenceError::TooFewWaypoints(_) | ReferenceError::Param(_) => {
                let line = self.places.last().map_or(self.header_line, |p| p.0);
                self.at(line, 1, "", e.to_string())
            }
        }
    }
}

fn located(file: &str, line: usize, column: usize, field: &str, message: String) -> ScenarioError {
    ScenarioError {
        location: Location {
            file: file.to_owned(),
            line,
            column,
        },
        field: field.to_owned(),
        message,
    }
}

/// The 1-based column (in characters) where each comma-separated cell of
/// `line` starts, after its leading blanks (the reader trims cells). Commas
/// inside double quotes do not separate.
fn cell_columns(line: &str) -> Vec<usize> {
    let mut starts = vec![0];
    let mut quoted = false;
    for (i, c) in line.char_indices() {
        match c {
            '"' => quoted = !quoted,
            ',' if !quoted => starts.push(i + 1),
            _ => {}
        }
    }
    starts
        .into_iter()
        .map(|s| {
            let rest = &line[s..];
            let start = s + (rest.len() - rest.trim_start_matches([' ', '\t']).len());
            line[..start].chars().count() + 1
        })
        .collect()
}

/// The text of the line starting at byte `offset` of `text` (without its end).
fn line_at(text: &str, offset: usize) -> &str {
    let rest = text.get(offset..).unwrap_or("");
    rest.split(['\n', '\r']).next().unwrap_or("")
}

/// Reads `t,x,y` rows (header required, `#` comments, cells trimmed; other
/// columns are ignored).
pub(super) fn read(full: &Path) -> Result<Table, ReadError> {
    let shown = full.display().to_string();
    let at = |line: usize, column: usize, field: &str, message: String| {
        ReadError::Csv(located(&shown, line, column, field, message))
    };
    let text = std::fs::read_to_string(full)
        .map_err(|e| ReadError::Unreadable(format!("cannot read `{shown}`: {e}")))?;
    let mut reader = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .comment(Some(b'#'))
        .from_reader(text.as_bytes());
    let headers = reader
        .headers()
        .map_err(|e| {
            let line = e.position().map_or(1, |p| p.line() as usize);
            at(line, 1, "", format!("bad CSV header: {e}"))
        })?
        .clone();
    let (header_line, header_text) = headers.position().map_or((1, ""), |p| {
        (p.line() as usize, line_at(&text, p.byte() as usize))
    });
    let header_columns = cell_columns(header_text);
    let mut idx = [0; 3];
    for (k, name) in COLUMNS.into_iter().enumerate() {
        idx[k] = match headers.iter().position(|h| h == name) {
            // Named twice: which one is meant is not for us to guess.
            Some(c) if headers.iter().filter(|h| *h == name).count() > 1 => {
                let again = headers
                    .iter()
                    .skip(c + 1)
                    .position(|h| h == name)
                    .unwrap_or(0)
                    + c
                    + 1;
                return Err(at(
                    header_line,
                    header_columns.get(again).copied().unwrap_or(1),
                    name,
                    format!("the header names column `{name}` twice: name each of t, x and y once"),
                ));
            }
            Some(c) => c,
            None => {
                // The first cell that is none of t, x, y; else just past the last.
                let column = headers
                    .iter()
                    .position(|h| !COLUMNS.contains(&h))
                    .and_then(|c| header_columns.get(c).copied())
                    .unwrap_or(header_text.chars().count() + 1);
                return Err(at(
                    header_line,
                    column,
                    name,
                    format!(
                        "the header has no column `{name}`: it must name columns t, x and y (found: {})",
                        headers.iter().collect::<Vec<_>>().join(",")
                    ),
                ));
            }
        };
    }
    let mut points = Vec::new();
    let mut places = Vec::new();
    for record in reader.records() {
        let record = record.map_err(|e| {
            let line = e.position().map_or(0, |p| p.line() as usize);
            at(line, 1, "", e.to_string())
        })?;
        let (line, columns) = record.position().map_or((0, Vec::new()), |p| {
            (
                p.line() as usize,
                cell_columns(line_at(&text, p.byte() as usize)),
            )
        });
        let column = |c: usize| columns.get(c).copied().unwrap_or(1);
        let mut p = [0.0; 3];
        for (k, (&c, name)) in idx.iter().zip(COLUMNS).enumerate() {
            let cell = record.get(c).unwrap_or("");
            p[k] = cell
                .parse()
                .map_err(|_| at(line, column(c), name, format!("`{cell}` is not a number")))?;
        }
        points.push(p);
        places.push((line, idx.map(column)));
    }
    Ok(Table {
        points,
        places,
        header_line,
        shown,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cells_start_after_commas_and_blanks_outside_quotes() {
        assert_eq!(cell_columns("t,x,y"), [1, 3, 5]);
        assert_eq!(cell_columns("  t , x,\ty"), [3, 7, 10]);
        assert_eq!(cell_columns("\"a,b\",x"), [1, 7]);
        assert_eq!(cell_columns("é,x"), [1, 3]);
        assert_eq!(cell_columns(""), [1]);
    }
}
