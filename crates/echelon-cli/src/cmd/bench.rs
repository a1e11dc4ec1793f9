//! `echelon bench`: how fast the batch engine steps a large formation.

use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::ValueEnum;

use rayon::prelude::*;

use echelon::engine::{self, BenchFormation, Engine, Topology, VelocityEngine};

use super::out::{err_line, outln};
use super::positive;
use super::progress::Progress;

/// Arguments of `echelon bench`.
#[derive(Debug, clap::Args)]
pub(crate) struct BenchArgs {
    /// Number of robots in each run.
    #[arg(long, value_name = "N", default_value_t = 10_000, value_parser = at_least_one)]
    agents: usize,
    /// `star`: every robot follows the virtual leader; `chain`: each follows the one before.
    #[arg(long, value_enum, default_value = "star")]
    topology: TopologyArg,
    /// `torque`: the paper's robots under the dynamic law; `velocity`:
    /// velocity-controlled bases (a Clearpath Jackal's lags and limits) under
    /// the kinematic law.
    #[arg(long, value_enum, default_value = "torque")]
    drive: DriveArg,
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

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub(crate) enum DriveArg {
    /// Wheel torques, the paper's plant (Table I, agent 1) and law.
    Torque,
    /// Velocity commands to a base with lags and limits, the kinematic law.
    Velocity,
}

/// The engines of the runs, of one drive.
enum Runs {
    Torque(Vec<Engine>),
    Velocity(Vec<VelocityEngine>),
}

impl Runs {
    /// Steps every run, spread over the current rayon pool.
    fn run(&mut self, steps: u64) -> Vec<Result<(), echelon::SimError>> {
        match self {
            Runs::Torque(e) => match e.as_mut_slice() {
                [one] => vec![one.run(steps)],
                many => engine::sweep(many, steps),
            },
            Runs::Velocity(e) => match e.as_mut_slice() {
                [one] => vec![one.run(steps)],
                many => many.par_iter_mut().map(|e| e.run(steps)).collect(),
            },
        }
    }

    /// `steps` steps as [`Runs::run`], in calls of at most `chunk` steps
    /// (the same bits: the engines step the same either way), `progress`
    /// told after each (time = steps × `dt`); the first call in which a
    /// run diverged is the last (its error is not overwritten by a later
    /// call's answer).
    fn run_showing(
        &mut self,
        steps: u64,
        chunk: u64,
        progress: &mut Progress,
        dt: f64,
    ) -> Vec<Result<(), echelon::SimError>> {
        let mut done = 0;
        let mut results = Vec::new();
        while done < steps {
            let n = chunk.max(1).min(steps - done);
            results = self.run(n);
            done += n;
            progress.at(done, done as f64 * dt);
            if results.iter().any(Result::is_err) {
                break;
            }
        }
        results
    }

    /// Every agent's `‖e‖` at the current state.
    fn errors(&self) -> Vec<f64> {
        let norm = |e: [f64; 2]| e[0].hypot(e[1]);
        match self {
            Runs::Torque(e) => e
                .iter()
                .flat_map(|e| e.probes())
                .map(|p| norm(p.e))
                .collect(),
            Runs::Velocity(e) => e
                .iter()
                .flat_map(|e| e.probes())
                .map(|p| norm(p.e))
                .collect(),
        }
    }

    /// Heap bytes per agent of the first run.
    fn bytes_per_agent(&self) -> f64 {
        match self {
            Runs::Torque(e) => e[0].bytes_per_agent(),
            Runs::Velocity(e) => e[0].bytes_per_agent(),
        }
    }

    /// Saturated ticks of every agent of every run (velocity bases).
    fn saturated_ticks(&self) -> Option<u64> {
        match self {
            Runs::Torque(_) => None,
            Runs::Velocity(e) => Some(
                e.iter()
                    .map(|e| (0..e.len()).map(|i| e.saturated_ticks(i)).sum::<u64>())
                    .sum(),
            ),
        }
    }
}

/// Agent-steps between two looks at the clock for the progress bar (well
/// under a second at any speed the engines reach; a call's overhead is
/// microseconds).
const CHUNK_AGENT_STEPS: usize = 1 << 22;

/// Steps per call for `agents` agents in all: [`CHUNK_AGENT_STEPS`] of
/// them, in whole tiles of 64 steps (a star's engine steps its blocks 64 at
/// a time).
fn chunk_steps(agents: usize) -> u64 {
    ((CHUNK_AGENT_STEPS / agents.max(1)) as u64 / 64).max(1) * 64
}

/// The most agents `echelon bench` builds in all (≈ 11 GB of state).
const MAX_AGENTS: u128 = BenchFormation::MAX_AGENTS as u128;

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
    let steps = step_count(args)?;
    check_total(args)?;
    let threads = args
        .threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .context("starting the worker threads")?;
    check_velocity_step(args)?;
    let mut engines = build_runs(args, topology)?;

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
    let results = pool.install(|| {
        engines.run_showing(
            steps,
            chunk_steps(args.agents * args.runs),
            &mut Progress::new(steps, false),
            args.dt,
        )
    });
    let seconds = started.elapsed().as_secs_f64();
    // A diverged formation ran without giving what was asked: exit 1, as
    // `echelon run` and `sweep` do for a divergence (2 is for refused input).
    for r in results {
        if let Err(e) = r {
            return Err(super::out::Failed(format!("the formation diverged: {e}")).into());
        }
    }

    let summary = Summary::of(args, topology, &engines, steps, seconds, threads);
    if args.json {
        summary.print_json(args)
    } else {
        summary.print_text(args)
    }
}

/// The number of RK4 steps of `--duration` at `--dt`, refused beyond 10¹².
fn step_count(args: &BenchArgs) -> Result<u64> {
    let steps = (args.duration / args.dt - 1e-9).ceil().max(1.0);
    if steps > 1e12 {
        bail!(
            "duration {} s at dt {} s is {steps:e} steps: too many",
            args.duration,
            args.dt
        );
    }
    Ok(steps as u64)
}

/// Refuses more than [`MAX_AGENTS`] agents over all the runs.
fn check_total(args: &BenchArgs) -> Result<()> {
    let total = args.agents as u128 * args.runs as u128;
    if total > MAX_AGENTS {
        bail!(
            "{} agents × {} runs is {total} agents (≈ {} GB): at most {MAX_AGENTS} in all",
            args.agents,
            args.runs,
            total
                * Engine::BLOCK_BYTES_PER_AGENT.max(VelocityEngine::BLOCK_BYTES_PER_AGENT) as u128
                / 1_000_000_000
        );
    }
    Ok(())
}

/// With `--drive velocity`: refuses a `--dt` longer than the base's lags.
fn check_velocity_step(args: &BenchArgs) -> Result<()> {
    if args.drive == DriveArg::Velocity
        && let Err(e) = BenchFormation::BASE.check_step(args.dt)
    {
        let axis = if e.field == "tau_omega" {
            "turn-rate"
        } else {
            "speed"
        };
        bail!(
            "--dt: {} s is longer than the velocity base's {axis} lag ({} = {} s, a Clearpath \
             Jackal's, which `--drive velocity` simulates): a lag cannot be integrated with a \
             step longer than itself; use --dt ≤ {} (or --drive torque)",
            args.dt,
            e.field,
            e.value,
            e.value
        );
    }
    Ok(())
}

/// The engines of the `--runs` runs (seeds SEED, SEED + 1, …) of the drive.
fn build_runs(args: &BenchArgs, topology: Topology) -> Result<Runs> {
    let formation = |r: usize| BenchFormation {
        agents: args.agents,
        topology,
        seed: args.seed.wrapping_add(r as u64),
    };
    Ok(match args.drive {
        DriveArg::Torque => Runs::Torque(
            (0..args.runs)
                .map(|r| formation(r).engine(args.dt))
                .collect::<Result<_, _>>()?,
        ),
        DriveArg::Velocity => Runs::Velocity(
            (0..args.runs)
                .map(|r| formation(r).velocity_engine(BenchFormation::BASE, args.dt))
                .collect::<Result<_, _>>()?,
        ),
    })
}

/// What a bench measured, as its report gives it.
struct Summary {
    name: &'static str,
    drive: &'static str,
    steps: u64,
    seconds: f64,
    threads: usize,
    agent_steps: f64,
    rate: f64,
    max_error: f64,
    mean_error: f64,
    bytes: f64,
    saturated: Option<u64>,
    block_bytes: usize,
}

impl Summary {
    /// The summary of `engines` having stepped `steps` steps in `seconds`.
    fn of(
        args: &BenchArgs,
        topology: Topology,
        engines: &Runs,
        steps: u64,
        seconds: f64,
        threads: usize,
    ) -> Summary {
        let agent_steps = (args.agents * args.runs) as f64 * steps as f64;
        let errors = engines.errors();
        Summary {
            name: match topology {
                Topology::Star => "star",
                Topology::Chain => "chain",
            },
            drive: match args.drive {
                DriveArg::Torque => "torque",
                DriveArg::Velocity => "velocity",
            },
            steps,
            seconds,
            threads,
            agent_steps,
            rate: agent_steps / seconds,
            max_error: errors.iter().copied().fold(0.0, f64::max),
            mean_error: errors.iter().sum::<f64>() / errors.len() as f64,
            bytes: engines.bytes_per_agent(),
            saturated: engines.saturated_ticks(),
            block_bytes: match args.drive {
                DriveArg::Torque => Engine::BLOCK_BYTES_PER_AGENT,
                DriveArg::Velocity => VelocityEngine::BLOCK_BYTES_PER_AGENT,
            },
        }
    }

    /// The summary as one JSON object (`--json`).
    fn print_json(&self, args: &BenchArgs) -> Result<()> {
        let mut out = serde_json::json!({
            "agents": args.agents,
            "steps": self.steps,
            "seconds": self.seconds,
            "agent_steps_per_s": self.rate,
            "topology": self.name,
            "drive": self.drive,
            "runs": args.runs,
            "threads": self.threads,
            "dt": args.dt,
            "seed": args.seed,
            "ns_per_agent_step": 1e9 / self.rate,
            "bytes_per_agent": self.bytes,
            "max_error": self.max_error,
        });
        if let (Some(n), Some(map)) = (self.saturated, out.as_object_mut()) {
            map.insert("saturated_ticks".into(), n.into());
        }
        outln!("{out}")?;
        Ok(())
    }

    /// The summary as text.
    fn print_text(&self, args: &BenchArgs) -> Result<()> {
        let Summary {
            name,
            drive,
            steps,
            seconds,
            threads,
            agent_steps,
            rate,
            max_error,
            mean_error,
            bytes,
            saturated,
            block_bytes,
        } = *self;
        outln!(
            "{name} ({drive} drive): {} agents{}, {steps} steps of {} s ({} s), {threads} thread{}",
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
            "  memory: {block_bytes} B per agent of state and constants, {bytes:.0} B with work space"
        )?;
        outln!(
            "  at t = {} s: ‖e‖ max {max_error:.2e} m, mean {mean_error:.2e} m",
            steps as f64 * args.dt
        )?;
        if let Some(n) = saturated {
            outln!("  saturated ticks (command beyond a speed limit): {n} of {agent_steps:.3e}")?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn runs(drive: DriveArg, topology: Topology, agents: usize, dt: f64) -> Runs {
        let f = |r: u64| BenchFormation {
            agents,
            topology,
            seed: 7 + r,
        };
        match drive {
            DriveArg::Torque => Runs::Torque((0..2).map(|r| f(r).engine(dt).unwrap()).collect()),
            DriveArg::Velocity => Runs::Velocity(
                (0..2)
                    .map(|r| f(r).velocity_engine(BenchFormation::BASE, dt).unwrap())
                    .collect(),
            ),
        }
    }

    /// Stepping in chunks (for the progress bar) is the same computation
    /// as one call: the same errors, bit for bit, for chunks of any size,
    /// tile-aligned or not, on either drive and topology.
    #[test]
    fn chunked_stepping_is_the_same_bits_as_one_call() {
        let mut lcg = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = |m: u64| {
            lcg = lcg
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (lcg >> 33) % m
        };
        for drive in [DriveArg::Torque, DriveArg::Velocity] {
            for topology in [Topology::Star, Topology::Chain] {
                for _ in 0..3 {
                    let agents = 1 + next(40) as usize;
                    let steps = 1 + next(700);
                    let chunk = 1 + next(steps + 100);
                    let mut one = runs(drive, topology, agents, 0.004);
                    let mut chunked = runs(drive, topology, agents, 0.004);
                    one.run(steps);
                    let mut progress = Progress::new(steps, true);
                    let r = chunked.run_showing(steps, chunk, &mut progress, 0.004);
                    assert_eq!(r.len(), 2);
                    assert!(r.iter().all(Result::is_ok));
                    let bits = |e: Vec<f64>| e.into_iter().map(f64::to_bits).collect::<Vec<_>>();
                    assert_eq!(
                        bits(one.errors()),
                        bits(chunked.errors()),
                        "{agents} agents, {steps} steps in chunks of {chunk}"
                    );
                }
            }
        }
    }

    #[test]
    fn chunks_are_whole_tiles_and_bounded() {
        for agents in [1, 2, 63, 64, 1000, 65_536, 1 << 22, 100_000_000] {
            let c = chunk_steps(agents);
            assert!(c >= 64 && c.is_multiple_of(64), "{agents}: {c}");
            assert!(
                c as usize * agents <= CHUNK_AGENT_STEPS.max(64 * agents),
                "{agents}: {c}"
            );
        }
    }
}
