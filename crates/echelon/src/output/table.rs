//! The run summary's table of per-agent numbers ([`Table`]).

use std::path::Path;

use crate::error::OutputError;

use super::io_error;

/// A CSV of numbers with a header line, as echelon writes them.
#[derive(Debug, Clone, PartialEq)]
pub struct Table {
    /// Column names.
    pub header: Vec<String>,
    /// Rows of numbers, one per line after the header.
    pub rows: Vec<Vec<f64>>,
}

impl Table {
    /// Reads a numeric CSV; every error names the file and line.
    pub fn read(path: &Path) -> Result<Table, OutputError> {
        let text = std::fs::read_to_string(path).map_err(io_error(path))?;
        Table::parse(path, &text)
    }

    /// Parses the text of the numeric CSV `path` (named in errors): a header
    /// line, then rows of numbers with as many cells; blank lines are skipped
    /// and cells trimmed.
    pub fn parse(path: &Path, text: &str) -> Result<Table, OutputError> {
        let parse = |line: usize, message: String| OutputError::Parse {
            path: path.to_path_buf(),
            line,
            message,
        };
        // The line of a record from its byte offset: the reader's own line
        // count leaves out the empty lines it skips, and its offset is where
        // they begin.
        let line_at = |pos: Option<&csv::Position>| {
            pos.map_or(0, |p| {
                let bytes = text.as_bytes();
                let mut end = (p.byte() as usize).min(bytes.len());
                while end < bytes.len() && matches!(bytes[end], b'\n' | b'\r') {
                    end += 1;
                }
                1 + bytes[..end].iter().filter(|&&b| b == b'\n').count()
            })
        };
        let line_of = |e: &csv::Error| line_at(e.position());
        let mut reader = csv::ReaderBuilder::new()
            .trim(csv::Trim::All)
            .flexible(true)
            .from_reader(text.as_bytes());
        let header: Vec<String> = reader
            .headers()
            .map_err(|e| parse(line_of(&e), e.to_string()))?
            .iter()
            .map(str::to_owned)
            .collect();
        if header.is_empty() {
            return Err(parse(1, "empty file: expected a header".into()));
        }
        let mut rows = Vec::new();
        for record in reader.records() {
            let record = record.map_err(|e| parse(line_of(&e), e.to_string()))?;
            if record.iter().all(str::is_empty) {
                continue;
            }
            let line = || line_at(record.position());
            let row = record
                .iter()
                .map(str::parse::<f64>)
                .collect::<Result<Vec<f64>, _>>()
                .map_err(|e| parse(line(), format!("not a number: {e}")))?;
            if row.len() != header.len() {
                return Err(parse(
                    line(),
                    format!(
                        "{} columns where the header has {}",
                        row.len(),
                        header.len()
                    ),
                ));
            }
            rows.push(row);
        }
        Ok(Table { header, rows })
    }

    /// Checks that the header is exactly `expected` (a file echelon wrote).
    pub fn expect_header(&self, path: &Path, expected: &str) -> Result<(), OutputError> {
        let found = self.header.join(",");
        if found == expected {
            Ok(())
        } else {
            Err(OutputError::Parse {
                path: path.to_path_buf(),
                line: 1,
                message: format!("expected the header `{expected}`, found `{found}`"),
            })
        }
    }

    /// The index of column `name`, or an error naming the file.
    pub fn column(&self, name: &str, path: &Path) -> Result<usize, OutputError> {
        self.header
            .iter()
            .position(|h| h == name)
            .ok_or_else(|| OutputError::Parse {
                path: path.to_path_buf(),
                line: 1,
                message: format!("no column `{name}` (found: {})", self.header.join(",")),
            })
    }
}
