//! `echelon run`: simulate a scenario into an output directory.

use std::fs::File;
use std::io::BufWriter;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::ValueEnum;

use echelon::formation::Leader;
use echelon::output::{
    self, INTEGRALS_FILE, ODOMETRY_FILE, REFERENCE_FILE, RunSummary, SAFETY_FILE, SCENARIO_FILE,
    SUMMARY_FILE, TRAJECTORY_FILE,
};
use echelon::scenario::{Overrides, Scenario};
use echelon::sim::{Every, Observer};
use echelon::stats::{ClosestApproach, SafetyReport};
use echelon::{Simulation, Variant};
use echelon_mcap::McapObserver;

use super::out::outln;
use super::progress::Progress;
use super::{non_negative, positive};

/// The MCAP file `--mcap` writes next to trajectory.csv.
pub(crate) const MCAP_FILE: &str = "run.mcap";

/// Arguments of `echelon run`.
#[derive(Debug, clap::Args)]
pub(crate) struct RunArgs {
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
    /// Seed of the random models (odometry noise, slip, fixes) [default: the scenario's, else 0].
    #[arg(long, value_name = "N")]
    seed: Option<u64>,
    /// Also draw the figures (paths, errors, signals as SVG and PNG) and report.html.
    #[arg(long)]
    plot: bool,
    /// Also write DIR/run.mcap (JSON channels: /reference, /agent/K/state; Foxglove's 3D channels /tf, /scene, /scene/static), like a fleet run.
    #[arg(long)]
    mcap: bool,
    /// Print nothing but errors.
    #[arg(long, short)]
    quiet: bool,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
pub(crate) enum LawArg {
    /// The paper's eq. 13.
    Paper,
    /// Textbook backstepping: V̇₂ = −K_e‖e‖² − K_z‖z‖².
    Complete,
}

/// Runs the scenario, writes its outputs and prints a summary.
pub(crate) fn run(args: RunArgs) -> Result<()> {
    let scenario = Scenario::resolve(&args.scenario)?;
    let overrides = Overrides {
        dt: args.dt,
        duration: args.duration,
        log_dt: args.log_dt,
        law: args.law.map(|l| match l {
            LawArg::Paper => Variant::Paper,
            LawArg::Complete => Variant::Complete,
        }),
        seed: args.seed,
    };
    let mut run = scenario.build(&overrides)?;
    let out = args
        .out
        .unwrap_or_else(|| PathBuf::from("out").join(&run.name));
    if !args.quiet {
        for w in run.warnings.iter().chain(run.plan.warnings()) {
            super::out::err_line(&format!("warning: {w}"));
        }
    }
    let started = Instant::now();
    let mcap_part = output::part_path(&out.join(MCAP_FILE));
    let mcap = if args.mcap {
        std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
        let file = File::create(&mcap_part)
            .with_context(|| format!("creating {}", mcap_part.display()))?;
        Some(McapObserver::new(BufWriter::with_capacity(1 << 16, file))?)
    } else {
        None
    };
    // The MCAP log keeps the CSV logs' schedule; the bar looks at the clock
    // every so many steps.
    let mut mcap = Every::new(run.log_every, mcap);
    let mut progress = Every::new(
        Progress::CHECK_EVERY,
        Progress::new(run.plan.steps(), args.quiet),
    );
    let result = output::run_to_dir(
        &mut run,
        &out,
        &mut [&mut progress as &mut dyn Observer, &mut mcap],
    );
    drop(progress);
    // The directory now holds this run's logs (even a diverged run's): what
    // an earlier run left that this one does not rewrite is not its own.
    if matches!(result, Ok(_) | Err(echelon::OutputError::Diverged { .. })) {
        if !args.mcap {
            output::remove_if_present(&out.join(MCAP_FILE))?;
        }
        echelon_report::remove_all(&out)?;
    }
    let summary = match result {
        Ok(s) => s,
        Err(e @ echelon::OutputError::Diverged { .. }) => {
            // The MCAP log holds the same frames as the CSV logs: close it
            // (the run did not) and keep it.
            if args.mcap {
                match mcap.finish() {
                    Ok(()) => std::fs::rename(&mcap_part, out.join(MCAP_FILE))
                        .with_context(|| format!("writing {}", out.join(MCAP_FILE).display()))?,
                    Err(_) => {
                        let _ = std::fs::remove_file(&mcap_part);
                    }
                }
            }
            // `--plot` asked for the figures: a diverged run's are the ones
            // that show what went wrong (its report says it diverged).
            // A failure to draw them is said, but the run's failure is the
            // divergence (exit 1).
            if args.plot
                && let Err(draw) = super::plot::draw(&out, args.quiet)
            {
                super::out::err_line(&format!("warning: drawing the diverged run: {draw:#}"));
            }
            return Err(super::out::Failed(format!("{}: {e}", run.name)).into());
        }
        Err(e) => {
            let _ = std::fs::remove_file(&mcap_part);
            return Err(e).with_context(|| format!("running {}", run.name));
        }
    };
    if args.mcap {
        std::fs::rename(&mcap_part, out.join(MCAP_FILE))
            .with_context(|| format!("writing {}", out.join(MCAP_FILE).display()))?;
    }
    let elapsed = started.elapsed().as_secs_f64();
    if !args.quiet {
        print_summary(&run.simulation(), &summary, elapsed)?;
        let mut files = vec![TRAJECTORY_FILE, REFERENCE_FILE, INTEGRALS_FILE];
        if !run.plan.odometers().is_empty() {
            files.push(ODOMETRY_FILE);
        }
        if run.plan.safety().is_some() {
            files.push(SAFETY_FILE);
        }
        files.extend([SUMMARY_FILE, SCENARIO_FILE]);
        if args.mcap {
            files.push(MCAP_FILE);
        }
        let shown: Vec<String> = files
            .iter()
            .map(|f| out.join(f).display().to_string())
            .collect();
        outln!("wrote {}", shown.join(", "))?;
    }
    if args.plot {
        super::plot::draw(&out, args.quiet)?;
    }
    Ok(())
}

fn print_summary(sim: &Simulation, s: &RunSummary, elapsed: f64) -> anyhow::Result<()> {
    let agents = sim.agents();
    outln!(
        "{}: {} agent{}, {} s at dt = {} s ({} steps) in {elapsed:.2} s",
        s.scenario,
        agents.len(),
        if agents.len() == 1 { "" } else { "s" },
        s.duration,
        s.dt,
        s.steps
    )?;
    let leaders: Vec<String> = (0..agents.len())
        .map(|i| match sim.formation().leader(i) {
            Leader::Reference => "reference".to_owned(),
            Leader::Agent(j) => agents[j].name().to_owned(),
        })
        .collect();
    let name_w = agents
        .iter()
        .map(|a| a.name().chars().count())
        .max()
        .unwrap_or(0)
        .max(5);
    let leader_w = leaders
        .iter()
        .map(|l| l.chars().count())
        .max()
        .unwrap_or(0)
        .max(6);
    outln!(
        "  {:<name_w$}  {:<leader_w$}  {:>11}  {:>9}  {:>10}  {:>13}",
        "agent",
        "leader",
        "final ‖e‖",
        "RMS ‖e‖",
        "peak |τ|",
        "‖e‖ < 1 cm at"
    )?;
    for (a, leader) in s.agents.iter().zip(&leaders) {
        let settle = a
            .settle_time
            .map_or_else(|| "never".to_owned(), |t| format!("{t:.2} s"));
        // A velocity base has no wheel torques: its cell says so rather
        // than print a 0 that reads as a measurement.
        let torque = match a.saturated_ticks {
            Some(_) => format!("{:>10}", "—"),
            None => format!("{:>6.2} N·m", a.peak_torque),
        };
        outln!(
            "  {:<name_w$}  {:<leader_w$}  {:>9.2e} m  {:>7.3} m  {torque}  {:>13}",
            a.name,
            leader,
            a.final_error,
            a.rms_error,
            settle
        )?;
    }
    let saturated: Vec<String> = s
        .agents
        .iter()
        .filter_map(|a| a.saturated_ticks.filter(|&n| n > 0).map(|n| (a, n)))
        .map(|(a, n)| format!("{} {n}", a.name))
        .collect();
    if !saturated.is_empty() {
        outln!(
            "  velocity limits cut the command (steps): {}",
            saturated.join(", ")
        )?;
    }
    if let Some(safety) = &s.safety {
        print_safety(s, safety)?;
    }
    Ok(())
}

/// The closest approach between two robots' points against the radius
/// (what the filter promises), names from `name` (1-based agent), and the
/// smallest obstacle clearance: `echelon run`'s and `fleet up`'s lines; a
/// warning on stderr when the robots came more than 1 mm inside the radius.
pub(super) fn print_approach(
    c: &ClosestApproach,
    name: impl Fn(usize) -> String,
) -> anyhow::Result<()> {
    let [a, b] = c.min_distance_agents;
    if c.min_distance.is_finite() {
        outln!(
            "  safety: closest approach {:.4} m ({} and {}, t = {:.2} s), radius {} m",
            c.min_distance,
            name(a),
            name(b),
            c.min_distance_t,
            c.radius
        )?;
        // The filter holds the radius to within a millimetre (docs/safety.md:
        // sampled commands, solver tolerances); deeper is a broken promise.
        if c.min_distance < c.radius - 1e-3 {
            super::out::err_line(&format!(
                "warning: the robots came {:.1} mm inside the safety radius",
                (c.radius - c.min_distance) * 1e3
            ));
        }
    } else {
        outln!("  safety: radius {} m, no pair of robots", c.radius)?;
    }
    if let Some(clearance) = c.min_obstacle_clearance {
        outln!("          smallest obstacle clearance {clearance:.4} m")?;
    }
    Ok(())
}

/// The safety filter's outcome under the table: the closest approach
/// against the radius (what the filter promises), how often it acted, and
/// any robot it left deadlocked (which the ‖e‖ column alone would show as
/// an unexplained "never").
fn print_safety(s: &RunSummary, safety: &SafetyReport) -> anyhow::Result<()> {
    let name = |k: usize| {
        s.agents
            .get(k.wrapping_sub(1))
            .map_or("?", |a| a.name.as_str())
    };
    print_approach(&safety.closest, |k| name(k).to_owned())?;
    outln!(
        "          filter acted on {} agent-steps, braked {} (infeasible), {} deadlock breaks",
        safety.active,
        safety.infeasible,
        safety.deadlock_breaks
    )?;
    if !safety.deadlocked_at_end.is_empty() {
        let names: Vec<&str> = safety.deadlocked_at_end.iter().map(|&k| name(k)).collect();
        super::out::err_line(&format!(
            "warning: deadlocked by the safety filter at the end: {}",
            names.join(", ")
        ));
    }
    Ok(())
}
