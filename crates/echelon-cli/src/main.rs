//! `echelon`: leader-follower formation control of differential-drive robots,
//! from the command line. A thin layer over the `echelon` library: each
//! command lives in its own module under `cmd/`.

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
    /// Simulate a scenario; write DIR/trajectory.csv and DIR/summary.json.
    #[command(allow_negative_numbers = true)]
    Run(cmd::run::RunArgs),
    /// List the built-in scenarios.
    Scenarios,
    /// Print a built-in scenario's TOML, to copy and edit.
    Show(cmd::scenarios::ShowArgs),
    /// Time the batch engine on a random formation (agent-steps per second).
    #[command(allow_negative_numbers = true)]
    Bench(cmd::bench::BenchArgs),
}

/// Exit code for every refused input or failed run.
const FAILURE: u8 = 2;

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) if matches!(e.kind(), ErrorKind::DisplayHelp | ErrorKind::DisplayVersion) => {
            let _ = e.print();
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
            eprintln!("{} (see --help)", parts.join(" "));
            return ExitCode::from(FAILURE);
        }
    };
    let result = match cli.command {
        Command::Run(args) => cmd::run::run(args),
        Command::Scenarios => cmd::scenarios::list(),
        Command::Show(args) => cmd::scenarios::show(&args),
        Command::Bench(args) => cmd::bench::bench(&args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(FAILURE)
        }
    }
}
