//! `echelon`: leader-follower formation control of differential-drive robots,
//! from the command line. A thin layer over the `echelon` library.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand, ValueEnum};

use echelon::formation::Leader;
use echelon::output::{self, RunSummary, SUMMARY_FILE, TRAJECTORY_FILE};
use echelon::scenario::{self, Overrides, Scenario};
use echelon::sim::{Frame, ObserverError};
use echelon::{Simulation, Variant};

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
    Run(RunArgs),
    /// List the built-in scenarios.
    Scenarios,
    /// Print a built-in scenario's TOML, to copy and edit.
    Show {
        /// Built-in scenario name (see `echelon scenarios`).
        name: String,
    },
}

#[derive(Debug, clap::Args)]
struct RunArgs {
    /// A built-in scenario name (see `echelon scenarios`) or a path to a .toml file.
    scenario: String,
    /// Output directory [default: out/<scenario name>].
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// RK4 step, s (overrides the scenario's sim.dt).
    #[arg(long, value_name = "S", value_parser = positive)]
    dt: Option<f64>,
    /// Simulated time, s (overrides the scenario's sim.duration).
    #[arg(long, value_name = "S", value_parser = positive)]
    duration: Option<f64>,
    /// Logging period in s; 0 logs every step [default: the scenario's log.dt, else 0.01].
    #[arg(long, value_name = "S", value_parser = non_negative)]
    log_dt: Option<f64>,
    /// Law for every agent: `paper` (eq. 13) or `complete` (cross term cancelled).
    #[arg(long, value_enum, value_name = "LAW")]
    law: Option<LawArg>,
    /// Print nothing but errors.
    #[arg(long, short)]
    quiet: bool,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum LawArg {
    /// The paper's eq. 13.
    Paper,
    /// Textbook backstepping: V̇₂ = −K_e‖e‖² − K_z‖z‖².
    Complete,
}

fn parse_number(s: &str) -> Result<f64, String> {
    let v: f64 = s.parse().map_err(|_| format!("`{s}` is not a number"))?;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(format!("{s} is not a finite number"))
    }
}

fn positive(s: &str) -> Result<f64, String> {
    let v = parse_number(s)?;
    if v > 0.0 {
        Ok(v)
    } else {
        Err(format!("{s} must be > 0"))
    }
}

fn non_negative(s: &str) -> Result<f64, String> {
    let v = parse_number(s)?;
    if v >= 0.0 {
        Ok(v)
    } else {
        Err(format!("{s} must be ≥ 0"))
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match dispatch(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}

fn dispatch(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Run(args) => run(args),
        Command::Scenarios => {
            list_scenarios();
            Ok(())
        }
        Command::Show { name } => show(&name),
    }
}

fn list_scenarios() {
    for (name, _) in scenario::builtin() {
        let description = Scenario::builtin(name)
            .and_then(|s| s.file.description.clone())
            .unwrap_or_default();
        println!("{name:<24} {description}");
    }
}

fn show(name: &str) -> Result<()> {
    match scenario::builtin().iter().find(|(n, _)| *n == name) {
        Some((_, src)) => {
            print!("{src}");
            Ok(())
        }
        None => {
            let names: Vec<&str> = scenario::builtin().iter().map(|(n, _)| *n).collect();
            bail!(
                "no built-in scenario `{name}` (built-ins: {})",
                names.join(", ")
            )
        }
    }
}

fn run(args: RunArgs) -> Result<()> {
    let scenario = Scenario::resolve(&args.scenario)?;
    let overrides = Overrides {
        dt: args.dt,
        duration: args.duration,
        log_dt: args.log_dt,
        law: args.law.map(|l| match l {
            LawArg::Paper => Variant::Paper,
            LawArg::Complete => Variant::Complete,
        }),
    };
    let mut run = scenario.build(&overrides)?;
    let out = args
        .out
        .unwrap_or_else(|| PathBuf::from("out").join(&run.name));
    if !args.quiet {
        for w in run.simulation.warnings() {
            eprintln!("warning: {w}");
        }
    }
    let mut nothing = |_: &Frame<'_>| -> Result<(), ObserverError> { Ok(()) };
    let started = Instant::now();
    let summary = output::run_to_dir(&mut run, &out, &mut nothing)
        .with_context(|| format!("running {}", run.name))?;
    let elapsed = started.elapsed().as_secs_f64();
    if !args.quiet {
        print_summary(&run.simulation, &summary, elapsed);
        println!(
            "wrote {}, {}",
            out.join(TRAJECTORY_FILE).display(),
            out.join(SUMMARY_FILE).display()
        );
    }
    Ok(())
}

fn print_summary(sim: &Simulation, s: &RunSummary, elapsed: f64) {
    let agents = sim.agents();
    println!(
        "{}: {} agent{}, {} s at dt = {} s ({} steps) in {elapsed:.2} s",
        s.scenario,
        agents.len(),
        if agents.len() == 1 { "" } else { "s" },
        s.duration,
        s.dt,
        s.steps
    );
    let leaders: Vec<String> = (0..agents.len())
        .map(|i| match sim.formation().leader(i) {
            Leader::Reference => "reference".to_owned(),
            Leader::Agent(j) => agents[j].name.clone(),
        })
        .collect();
    let name_w = agents
        .iter()
        .map(|a| a.name.chars().count())
        .max()
        .unwrap_or(0)
        .max(5);
    let leader_w = leaders
        .iter()
        .map(|l| l.chars().count())
        .max()
        .unwrap_or(0)
        .max(6);
    println!(
        "  {:<name_w$}  {:<leader_w$}  {:>11}  {:>9}  {:>10}  {:>13}",
        "agent", "leader", "final ‖e‖", "RMS ‖e‖", "peak |τ|", "‖e‖ < 1 cm at"
    );
    for (a, leader) in s.agents.iter().zip(&leaders) {
        let settle = a
            .settle_time
            .map_or_else(|| "never".to_owned(), |t| format!("{t:.2} s"));
        println!(
            "  {:<name_w$}  {:<leader_w$}  {:>9.2e} m  {:>7.3} m  {:>6.2} N·m  {:>13}",
            a.name, leader, a.final_error, a.rms_error, a.peak_torque, settle
        );
    }
}
