//! `echelon bench`: how fast the batch engine steps a large formation.

use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::ValueEnum;

use echelon::engine::{self, BenchFormation, Engine, Topology};

use super::out::{err_line, outln};
use super::positive;

/// Arguments of `echelon bench`.
#[derive(Debug, clap::Args)]
pub(crate) struct BenchArgs {
    /// Number of robots in each run.
    #[arg(long, value_name = "N", default_value_t = 10_000, value_parser = at_least_one)]
    agents: usize,
    /// `star`: every robot follows the virtual leader; `chain`: each follows the one before.
    #[arg(long, value_enum, default_value = "star")]
    topology: TopologyArg,
    /// Simulated time, s.
    #[arg(long, value_name = "S", default_value_t = 10.0, value_parser = positive)]
    duration: f64,
    /// RK4 step, s.
    #[arg(long, value_name = "S", default_value_t = 0.001, value_parser = positive)]
    dt: f64,
    /// Worker threads [default: one per core].
    #[arg(long, value_name = "K", value_parser = at_least_one)]
    threads: Option<usize>,
    /// Independent runs (seeds SEED, SEED + 1, …), spread over the threads.
    #[arg(long, value_name = "R", default_value_t = 1, value_parser = at_least_one)]
    runs: usize,
    /// Seed of the random start poses and offsets.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
pub(crate) enum TopologyArg {
    /// Every robot follows the circular virtual leader.
    Star,
    /// Robot 1 follows the virtual leader, robot i follows robot i − 1.
    Chain,
}

/// The most agents `echelon bench` builds in all (≈ 11 GB of state).
const MAX_AGENTS: u128 = 100_000_000;

/// A whole number ≥ 1 (clap value parser).
fn at_least_one(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(n) if n >= 1 => Ok(n),
        Ok(_) => Err(format!("{s} must be ≥ 1")),
        Err(_) => Err(format!("`{s}` is not a whole number")),
    }
}

/// Builds the formations, times the stepping alone, and reports.
pub(crate) fn bench(args: &BenchArgs) -> Result<()> {
    let topology = match args.topology {
        TopologyArg::Star => Topology::Star,
        TopologyArg::Chain => Topology::Chain,
    };
    let steps = (args.duration / args.dt - 1e-9).ceil().max(1.0);
    if steps > 1e12 {
        bail!(
            "duration {} s at dt {} s is {steps:e} steps: too many",
            args.duration,
            args.dt
        );
    }
    let steps = steps as u64;
    let total = args.agents as u128 * args.runs as u128;
    if total > MAX_AGENTS {
        bail!(
            "{} agents × {} runs is {total} agents (≈ {} GB): at most {MAX_AGENTS} in all",
            args.agents,
            args.runs,
            total * Engine::BLOCK_BYTES_PER_AGENT as u128 / 1_000_000_000
        );
    }
    let threads = args
        .threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .context("starting the worker threads")?;
    let mut engines = (0..args.runs)
        .map(|r| {
            BenchFormation {
                agents: args.agents,
                topology,
                seed: args.seed.wrapping_add(r as u64),
            }
            .engine(args.dt)
        })
        .collect::<Result<Vec<Engine>, _>>()?;

    if !args.json {
        // Before the clock starts: long runs say what they are doing.
        err_line(&format!(
            "stepping {} × {} agents for {steps} steps on {threads} thread{}…",
            args.runs,
            args.agents,
            if threads == 1 { "" } else { "s" }
        ));
    }
    let started = Instant::now();
    let results = pool.install(|| match engines.as_mut_slice() {
        [one] => vec![one.run(steps)],
        many => engine::sweep(many, steps),
    });
    let seconds = started.elapsed().as_secs_f64();
    for r in results {
        r.context("the formation diverged")?;
    }

    let agent_steps = (args.agents * args.runs) as f64 * steps as f64;
    let rate = agent_steps / seconds;
    let errors: Vec<f64> = engines
        .iter()
        .flat_map(|e| e.probes())
        .map(|p| p.e[0].hypot(p.e[1]))
        .collect();
    let max_error = errors.iter().copied().fold(0.0, f64::max);
    let mean_error = errors.iter().sum::<f64>() / errors.len() as f64;
    let bytes = engines[0].bytes_per_agent();
    let name = match topology {
        Topology::Star => "star",
        Topology::Chain => "chain",
    };
    if args.json {
        let out = serde_json::json!({
            "agents": args.agents,
            "steps": steps,
            "seconds": seconds,
            "agent_steps_per_s": rate,
            "topology": name,
            "runs": args.runs,
            "threads": threads,
            "dt": args.dt,
            "seed": args.seed,
            "ns_per_agent_step": 1e9 / rate,
            "bytes_per_agent": bytes,
            "max_error": max_error,
        });
        outln!("{out}")?;
    } else {
        outln!(
            "{name}: {} agents{}, {steps} steps of {} s ({} s), {threads} thread{}",
            args.agents,
            if args.runs > 1 {
                format!(" × {} runs", args.runs)
            } else {
                String::new()
            },
            args.dt,
            steps as f64 * args.dt,
            if threads == 1 { "" } else { "s" },
        )?;
        outln!(
            "  {agent_steps:.3e} agent-steps in {seconds:.3} s: {:.1} M agent-steps/s ({:.1} ns per agent-step)",
            rate / 1e6,
            1e9 / rate
        )?;
        outln!(
            "  memory: {} B per agent of state and constants, {bytes:.0} B with work space",
            Engine::BLOCK_BYTES_PER_AGENT
        )?;
        outln!(
            "  at t = {} s: ‖e‖ max {max_error:.2e} m, mean {mean_error:.2e} m",
            steps as f64 * args.dt
        )?;
    }
    Ok(())
}
