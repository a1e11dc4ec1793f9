//! The one CSV writer of echelon and its number formats (times without float
//! noise, other numbers in shortest round-trip form). Below everything that
//! writes CSV: the run logs (`output.rs`), a sample's row (`sample.rs`),
//! sweeps, the fleet collector.

use std::fmt::Write as _;
use std::io::{self, Write};

/// Writes a time to at most nanosecond resolution without float noise
/// (`0.03`, not `0.030000000000000002`).
pub fn push_time(line: &mut String, t: f64) {
    let start = line.len();
    let _ = write!(line, "{t:.9}");
    if line[start..].contains('.') {
        while line.ends_with('0') {
            line.pop();
        }
        if line.ends_with('.') {
            line.pop();
        }
    }
    if &line[start..] == "-0" {
        line.truncate(start);
        line.push('0');
    }
}

/// Writes a float in shortest round-trip form.
#[inline]
pub fn push_f64(line: &mut String, v: f64, buf: &mut ryu::Buffer) {
    if v.is_finite() {
        line.push_str(buf.format_finite(v));
    } else {
        line.push_str(buf.format(v));
    }
}

/// The one CSV writer: a header line, then rows of cells in echelon's number
/// formats (times without float noise, other numbers in shortest round-trip
/// form, an empty cell for a missing value). Every CSV echelon writes goes
/// through it: the run logs ([`crate::output::CsvLog`]), the fleet collector's
/// `trajectory.csv`, `sweep.csv` and `drift.csv`.
pub struct CsvWriter<W: Write> {
    out: W,
    line: String,
    cells: usize,
    buf: ryu::Buffer,
    rows: u64,
}

impl<W: Write> std::fmt::Debug for CsvWriter<W> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CsvWriter")
            .field("rows", &self.rows)
            .finish_non_exhaustive()
    }
}

impl<W: Write> CsvWriter<W> {
    /// Writes `header` (comma-separated column names) as the first line.
    pub fn new(mut out: W, header: &str) -> io::Result<Self> {
        writeln!(out, "{header}")?;
        Ok(CsvWriter {
            out,
            line: String::with_capacity(512),
            cells: 0,
            buf: ryu::Buffer::new(),
            rows: 0,
        })
    }

    fn cell(&mut self) -> &mut String {
        if self.cells > 0 {
            self.line.push(',');
        }
        self.cells += 1;
        &mut self.line
    }

    /// A time, s, to at most nanosecond resolution ([`push_time`]).
    pub fn time(&mut self, t: f64) -> &mut Self {
        push_time(self.cell(), t);
        self
    }

    /// A number in shortest round-trip form ([`push_f64`]).
    pub fn num(&mut self, v: f64) -> &mut Self {
        self.cell();
        push_f64(&mut self.line, v, &mut self.buf);
        self
    }

    /// Numbers, one cell each.
    pub fn nums(&mut self, values: impl IntoIterator<Item = f64>) -> &mut Self {
        for v in values {
            self.num(v);
        }
        self
    }

    /// A number, or an empty cell for `None`.
    pub fn opt(&mut self, v: Option<f64>) -> &mut Self {
        match v {
            Some(v) => self.num(v),
            None => {
                self.cell();
                self
            }
        }
    }

    /// An integer (agent numbers, counts, seeds).
    pub fn int(&mut self, v: u64) -> &mut Self {
        let _ = write!(self.cell(), "{v}");
        self
    }

    /// A text cell: as given, or quoted (RFC 4180, `"` doubled) when it
    /// holds a comma, a quote or a line break (a breach's `‖(x, y)‖`).
    pub fn text(&mut self, s: &str) -> &mut Self {
        let cell = self.cell();
        if s.contains([',', '"', '\n', '\r']) {
            cell.push('"');
            cell.push_str(&s.replace('"', "\"\""));
            cell.push('"');
        } else {
            cell.push_str(s);
        }
        self
    }

    /// Ends the row: writes it and a newline.
    pub fn end_row(&mut self) -> io::Result<()> {
        self.line.push('\n');
        let written = self.out.write_all(self.line.as_bytes());
        self.line.clear();
        self.cells = 0;
        written?;
        self.rows += 1;
        Ok(())
    }

    /// Number of data rows written.
    pub fn rows(&self) -> u64 {
        self.rows
    }

    /// Flushes the writer.
    pub fn flush(&mut self) -> io::Result<()> {
        self.out.flush()
    }

    /// Flushes and returns the writer.
    pub fn into_inner(mut self) -> io::Result<W> {
        self.out.flush()?;
        Ok(self.out)
    }
}
