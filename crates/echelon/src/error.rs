//! Typed errors. Every message says what is wrong and why it is refused.
//!
//! The kernel's errors (parameters, references, formations, runs) are
//! `echelon_core::error`'s, re-exported here; a scenario file's and a run's
//! outputs' errors are this crate's.

use std::borrow::Cow;
use std::fmt;

pub use echelon_core::error::*;

/// Where in a scenario file a problem is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Location {
    /// File name as given by the user (or `<builtin NAME>`).
    pub file: String,
    /// 1-based line (0 if unknown).
    pub line: usize,
    /// 1-based column (0 if unknown).
    pub column: usize,
}

impl Location {
    /// The `file` of a value a command-line flag set (its `field` is then
    /// the flag, `--dt`; line and column are 0).
    pub const COMMAND_LINE: &'static str = "command line";
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let file = one_line(&self.file);
        if self.line == 0 {
            write!(f, "{file}")
        } else {
            write!(f, "{file}:{}:{}", self.line, self.column)
        }
    }
}

/// `s` with its control characters escaped (`\n`, `\t`, `\u{1b}`), so that
/// a value quoted in a message (`robot = "a\nb"`) cannot break it over lines
/// or drive the terminal.
fn one_line(s: &str) -> Cow<'_, str> {
    if s.chars().any(char::is_control) {
        let mut out = String::with_capacity(s.len() + 8);
        for c in s.chars() {
            if c.is_control() {
                out.extend(c.escape_default());
            } else {
                out.push(c);
            }
        }
        Cow::Owned(out)
    } else {
        Cow::Borrowed(s)
    }
}

/// A scenario that cannot be loaded: always names the file, line, column and
/// field. Shown on one line: control characters of a quoted value are escaped.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub struct ScenarioError {
    /// File, line and column.
    pub location: Location,
    /// Dotted path of the field, e.g. `agents[3].offset.x` (agents count from 1).
    pub field: String,
    /// What is wrong.
    pub message: String,
}

impl ScenarioError {
    /// A value the command-line flag `flag` (`--dt`) set, refused:
    /// `command line: --dt: message`.
    pub fn of_flag(flag: &str, message: impl fmt::Display) -> ScenarioError {
        ScenarioError {
            location: Location {
                file: Location::COMMAND_LINE.into(),
                line: 0,
                column: 0,
            },
            field: flag.to_owned(),
            message: message.to_string(),
        }
    }
}

impl fmt::Display for ScenarioError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let message = one_line(&self.message);
        if self.field.is_empty() {
            write!(f, "{}: {message}", self.location)
        } else {
            let field = one_line(&self.field);
            write!(f, "{}: {field}: {message}", self.location)
        }
    }
}

/// Errors while running a scenario and writing its outputs.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// Writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: std::path::PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The simulation failed.
    #[error(transparent)]
    Sim(#[from] SimError),
    /// The run diverged ([`SimError::Diverged`]); its outputs up to the last
    /// state within bounds are written, `summary.json` says so.
    #[error("{error} (outputs up to t = {until} s in {})", dir.display())]
    Diverged {
        /// What diverged.
        error: SimError,
        /// The last time written, s.
        until: f64,
        /// The output directory.
        dir: std::path::PathBuf,
    },
    /// A file that should hold a run's output does not parse.
    #[error("{}:{line}: {message}", path.display())]
    Parse {
        /// The file.
        path: std::path::PathBuf,
        /// 1-based line (0: the whole file).
        line: usize,
        /// What is wrong.
        message: String,
    },
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_scenario_error_is_one_line() {
        let e = ScenarioError {
            location: Location {
                file: "s.toml".into(),
                line: 3,
                column: 9,
            },
            field: "robots.a\nb.preset".into(),
            message: "unknown robot `two\nlines\t\u{1b}[31m` (known: ω)".into(),
        };
        assert_eq!(
            e.to_string(),
            "s.toml:3:9: robots.a\\nb.preset: unknown robot `two\\nlines\\t\\u{1b}[31m` (known: ω)"
        );
    }
}
