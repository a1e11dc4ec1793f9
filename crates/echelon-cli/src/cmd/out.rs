//! Standard output that never panics: a closed pipe (`echelon … | head`)
//! ends the command quietly, as ripgrep does; other write errors are errors.

use std::fmt;
use std::io::{self, Write};

/// The reader of our standard output went away.
#[derive(Debug)]
pub(crate) struct Closed;

/// A command that ran but did not get what it was asked for: a run or a
/// sweep that diverged, a `fleet stop` some robot alive did not
/// acknowledge, a `fleet bench` size that failed. Its one-line message;
/// exit code 1, as docs/fleet.md and their help say (a refused input is 2).
#[derive(Debug)]
pub(crate) struct Failed(pub(crate) String);

impl fmt::Display for Failed {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Failed {}

impl fmt::Display for Closed {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("standard output was closed")
    }
}

impl std::error::Error for Closed {}

/// Writes `args` (and a newline if `newline`) to standard output.
pub(crate) fn write(args: fmt::Arguments<'_>, newline: bool) -> anyhow::Result<()> {
    let mut out = io::stdout().lock();
    let result = out.write_fmt(args).and_then(|()| {
        if newline {
            out.write_all(b"\n")
        } else {
            Ok(())
        }
    });
    match result {
        Err(e) if e.kind() == io::ErrorKind::BrokenPipe => Err(Closed.into()),
        r => Ok(r?),
    }
}

/// Prints one line on stderr, even if stderr is gone (never panics).
pub(crate) fn err_line(line: &str) {
    let _ = writeln!(io::stderr(), "{line}");
}

/// `println!` that returns an error instead of panicking.
macro_rules! outln {
    ($($arg:tt)*) => {
        $crate::cmd::out::write(format_args!($($arg)*), true)
    };
}

/// `print!` that returns an error instead of panicking.
macro_rules! out {
    ($($arg:tt)*) => {
        $crate::cmd::out::write(format_args!($($arg)*), false)
    };
}

pub(crate) use {out, outln};
