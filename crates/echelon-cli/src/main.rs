//! `echelon`: leader-follower formation control of differential-drive robots,
//! from the command line. A thin layer over the `echelon` library: each
//! command lives in its own module under `cmd/`.

#![cfg_attr(not(test), warn(clippy::too_many_lines))]

mod cmd;

use std::process::ExitCode;

use clap::error::ErrorKind;
use clap::{Parser, Subcommand};

#[derive(Debug, Parser)]
#[command(
    name = "echelon",
    version,
    about = "Leader-follower formation control of differential-drive robots",
    long_about = "Leader-follower formation control of differential-drive robots.\n\n\
        Simulates the backstepping law of 'Leader-Follower Control with Odometry Error \
        Analysis' on the paper's dynamic unicycle model. Units are SI, angles radians.\n\n\
        Start with `echelon scenarios`, then `echelon run circle-pentagon`."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Simulate a scenario; write DIR/trajectory.csv, summary.json, reference.csv, scenario.toml.
    #[command(allow_negative_numbers = true)]
    Run(cmd::run::RunArgs),
    /// Draw a run's figures (SVG + PNG) and DIR/report.html from its output directory.
    Plot(cmd::plot::PlotArgs),
    /// L_Ycomp exact (eq. 5) against the smooth fit (eq. 6), or refit eq. 6 for any L_Xoff.
    #[command(allow_negative_numbers = true)]
    Lycomp(cmd::lycomp::LycompArgs),
    /// List the built-in scenarios.
    Scenarios,
    /// Print a built-in scenario's TOML, to copy and edit.
    Show(cmd::scenarios::ShowArgs),
    /// Theorem 2: the bound on ‖z‖ for a fix every N samples, or the largest N.
    #[command(allow_negative_numbers = true)]
    Bound(cmd::bound::BoundArgs),
    /// Monte Carlo over odometry errors × fix intervals × seeds, on all cores.
    #[command(allow_negative_numbers = true)]
    Sweep(cmd::sweep::SweepArgs),
    /// Borenstein's UMBmark: estimate E_d and E_b from a bidirectional square test.
    #[command(allow_negative_numbers = true)]
    Umbmark(cmd::umbmark::UmbmarkArgs),
    /// Identify a robot from a logged run: eq. 3's m, η, J, ψ or a velocity base's lags and limits.
    Identify(cmd::identify::IdentifyArgs),
    /// Run a scenario as networked processes on Zenoh (leader, robots, collector).
    #[command(subcommand)]
    Fleet(cmd::fleet::FleetCommand),
    /// Time the batch engine on a random formation (agent-steps per second).
    #[command(allow_negative_numbers = true)]
    Bench(cmd::bench::BenchArgs),
}

/// Exit code for every refused input or failed run.
const FAILURE: u8 = 2;

/// Exit code of a run that diverged (`echelon run`), or of a command that
/// ran without getting what it asked for (`fleet stop` not acknowledged).
const DIVERGED: u8 = 1;

/// Hidden: with this environment variable set the command line is only
/// parsed (the docs test checks every `echelon …` line written in README.md
/// and docs/ against the CLI): exit 0, printing nothing, when it parses
/// (`--help` too), else 2 with one line on stderr, clap's error kind first
/// (`UnknownArgument: error: unexpected argument …`).
const PARSE_ONLY: &str = "ECHELON_PARSE_ONLY";

fn main() -> ExitCode {
    let parse_only = std::env::var_os(PARSE_ONLY).is_some();
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) if matches!(e.kind(), ErrorKind::DisplayHelp | ErrorKind::DisplayVersion) => {
            if !parse_only {
                let _ = e.print();
            }
            return ExitCode::SUCCESS;
        }
        Err(e) => {
            // One line, like every other error: clap's informative lines joined
            // (the usage block is what --help is for).
            let text = e.to_string();
            let parts: Vec<&str> = text
                .lines()
                .map(str::trim)
                .take_while(|l| !l.starts_with("Usage:") && !l.starts_with("For more information"))
                .filter(|l| !l.is_empty())
                .collect();
            let kind = if parse_only {
                format!("{:?}: ", e.kind())
            } else {
                String::new()
            };
            cmd::out::err_line(&format!("{kind}{} (see --help)", parts.join(" ")));
            return ExitCode::from(FAILURE);
        }
    };
    if parse_only {
        return ExitCode::SUCCESS;
    }
    let result = match cli.command {
        Command::Run(args) => cmd::run::run(args),
        Command::Plot(args) => cmd::plot::plot(&args),
        Command::Lycomp(args) => cmd::lycomp::lycomp(&args),
        Command::Scenarios => cmd::scenarios::list(),
        Command::Show(args) => cmd::scenarios::show(&args),
        Command::Bound(args) => cmd::bound::bound(&args),
        Command::Sweep(args) => cmd::sweep::sweep(&args),
        Command::Umbmark(args) => cmd::umbmark::umbmark(&args),
        Command::Identify(args) => cmd::identify::identify(&args),
        Command::Fleet(c) => cmd::fleet::run(c),
        Command::Bench(args) => cmd::bench::bench(&args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            let code = exit_code(&e);
            match code {
                // `echelon … | head`: the reader has what it wanted.
                0 => {}
                DIVERGED => cmd::out::err_line(&format!("error: {e}")),
                _ => cmd::out::err_line(&format!("error: {}", chain(&e))),
            }
            ExitCode::from(code)
        }
    }
}

/// The exit code of a command that returned `e`: 0 when standard output
/// was closed (the reader has what it wanted), [`DIVERGED`] for a run that
/// diverged or a command that ran without getting what it asked for
/// ([`cmd::out::Failed`]), else [`FAILURE`].
fn exit_code(e: &anyhow::Error) -> u8 {
    if e.downcast_ref::<cmd::out::Closed>().is_some() {
        0
    } else if e.downcast_ref::<cmd::out::Failed>().is_some()
        || matches!(
            e.downcast_ref::<echelon_fleet::FleetError>(),
            Some(echelon_fleet::FleetError::Diverged(_) | echelon_fleet::FleetError::TimedOut(_))
        )
    {
        DIVERGED
    } else {
        FAILURE
    }
}

/// `e` and its causes joined by `: ` (as `{e:#}`), a cause left out when
/// the text so far already ends with it: the libraries' I/O errors name
/// their source in their own message and also return it as their source,
/// which printed `File exists (os error 17): File exists (os error 17)`.
fn chain(e: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in e.chain() {
        let cause = cause.to_string();
        if text.ends_with(&cause) {
            continue;
        }
        if !text.is_empty() {
            text.push_str(": ");
        }
        text.push_str(&cause);
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    /// docs/fleet.md and `fleet stop --help` say an unacknowledged stop
    /// (and a failed `fleet bench` size) exits 1; it exited 2, as a refused
    /// input does.
    #[test]
    fn each_outcome_has_its_exit_code() {
        let cases: [(anyhow::Error, u8); 6] = [
            (
                echelon_fleet::FleetError::TimedOut("robot/2 never joined".into()).into(),
                1,
            ),
            (cmd::out::Failed("fleet stop: robot/2 …".into()).into(), 1),
            (cmd::out::Failed("run: diverged".into()).into(), 1),
            (cmd::out::Closed.into(), 0),
            (anyhow::anyhow!("bad input"), 2),
            (
                anyhow::Error::from(cmd::out::Failed("x".into())).context("more"),
                1,
            ),
        ];
        for (e, code) in cases {
            assert_eq!(exit_code(&e), code, "{e:#}");
        }
    }
}
