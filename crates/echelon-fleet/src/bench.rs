//! `echelon fleet bench`: how the fleet grows. Runs [`up::run`] (whatever
//! topology `fleet up` uses) for each fleet size N on loopback at time scale
//! 1 and tabulates startup, CPU per robot, message rate, latency, stale
//! samples, link losses and the final error.
//!
//! Each size runs a generated scenario ([`scenario_toml`]): a virtual leader
//! on a circle and N robots that all follow it, their formation offsets on a
//! grid 0.3 m apart, each starting 0.1 m off its slot in x and y. Its
//! directory `DIR/nNNN/` holds the scenario and everything `fleet up` wrote;
//! `DIR/bench.json` and `DIR/bench.md` hold the table.

use std::fmt::Write as _;
use std::path::PathBuf;

use serde::Serialize;

use crate::up::{self, UpOptions, UpReport};
use crate::{FleetError, StopFlag};

/// The table as JSON.
pub const BENCH_JSON: &str = "bench.json";
/// The table as Markdown.
pub const BENCH_MD: &str = "bench.md";
/// Spacing of the formation grid, m.
const SPACING: f64 = 0.3;

/// Options of `fleet bench`.
#[derive(Debug, Clone)]
pub struct BenchOptions {
    /// Fleet sizes, in order.
    pub robots: Vec<usize>,
    /// Fleet seconds each size runs (at time scale 1: real seconds).
    pub duration: f64,
    /// Output directory.
    pub out: PathBuf,
    /// The `echelon` binary `fleet up` starts the processes with.
    pub exe: PathBuf,
    /// The collector's state-log rate (`fleet up --log-rate`; `None`:
    /// every state).
    pub log_rate: Option<f64>,
    /// Robots per robot process (`fleet up --robots-per-process`; `None`:
    /// its default).
    pub robots_per_process: Option<usize>,
    /// Host sizes K whose CPU is measured (a fleet of K robots, all in one
    /// process): the marginal CPU of a robot in a host is the slope between
    /// the first and the last (empty: not measured).
    pub hosts: Vec<usize>,
}

/// One host of K robots (`fleet bench --hosts`).
#[derive(Debug, Clone, Default, Serialize)]
pub struct HostRow {
    /// Robots in the host.
    pub robots: usize,
    /// Why the run failed (the other fields are then empty).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// The host process's CPU seconds per 60 s of fleet time.
    pub cpu_per_min: f64,
    /// The same per robot.
    pub cpu_per_robot_per_min: f64,
    /// Robots whose final ‖e‖ is below 1 cm.
    pub converged: usize,
}

/// One row: one fleet size.
#[derive(Debug, Clone, Default, Serialize)]
pub struct BenchRow {
    /// Robots.
    pub robots: usize,
    /// Why the run failed (the other fields are then empty).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// Startup until every process joined, s.
    pub startup: Option<f64>,
    /// Wall-clock time of the whole `fleet up`, s.
    pub wall: f64,
    /// Robot processes (fewer than robots when hosts ran several each).
    pub robot_processes: usize,
    /// CPU seconds per robot: its processes' CPU (user + system of every
    /// thread, `/proc/<pid>/stat` of the exited child) over the robots.
    pub cpu_per_robot: f64,
    /// The same per minute of fleet time (at time scale 1, real time):
    /// the measure, ≤ 0.12 s aimed for (0.2 % of a core).
    pub cpu_per_robot_per_min: f64,
    /// `cpu_per_robot_per_min` over the floor's (a bare process waking at
    /// the control rate; `None`: the floor not measured).
    pub cpu_over_floor: Option<f64>,
    /// CPU seconds of the costliest robot process.
    pub cpu_robot_max: f64,
    /// CPU seconds of the collector.
    pub cpu_collector: f64,
    /// Collector CPU per sample it received, µs.
    pub collector_us_per_message: f64,
    /// Router CPU per sample delivered (to the collector and the robots), µs.
    pub router_us_per_message: f64,
    /// CPU seconds of every process together.
    pub cpu_total: f64,
    /// CPU seconds of the router(s) (zero in the mesh).
    pub cpu_router: f64,
    /// Peak RSS per robot: its processes' peaks summed over the robots,
    /// bytes.
    pub rss_per_robot: u64,
    /// Samples delivered (collector and robots received) per second of
    /// fleet time.
    pub messages_per_s: f64,
    /// Samples the collector received.
    pub collector_received: u64,
    /// Robot states it received but did not log (`--log-rate`).
    pub collector_decimated: u64,
    /// Samples it dropped, its input queue full.
    pub collector_dropped: u64,
    /// Reference → robot delay over every robot, median, s.
    pub latency_p50: f64,
    /// Reference → robot delay, 99th percentile, s.
    pub latency_p99: f64,
    /// Reference → robot delay, largest, s.
    pub latency_max: f64,
    /// Samples → collector, 99th percentile, s.
    pub collector_p99: f64,
    /// Stale samples refused, all robots.
    pub stale: u64,
    /// Link losses, all robots.
    pub link_losses: u64,
    /// Samples the robots dropped, their input queues full, all robots.
    pub robots_dropped: u64,
    /// Largest final ‖e‖ of the robots, m.
    pub final_max_error: f64,
    /// Robots whose final ‖e‖ is below 1 cm.
    pub converged: usize,
}

/// The machine the bench ran on.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Machine {
    /// CPU model (`/proc/cpuinfo`).
    pub cpu: String,
    /// Logical CPUs available to this process.
    pub cores: usize,
    /// Physical memory, bytes (`/proc/meminfo`).
    pub memory: u64,
    /// Kernel release (`/proc/sys/kernel/osrelease`).
    pub kernel: String,
}

impl Machine {
    /// This machine (empty fields where Linux's `/proc` says nothing).
    pub fn this() -> Machine {
        let read = |p: &str| std::fs::read_to_string(p).unwrap_or_default();
        let cpuinfo = read("/proc/cpuinfo");
        let cpu = cpuinfo
            .lines()
            .find(|l| l.starts_with("model name"))
            .and_then(|l| l.split_once(':'))
            .map_or(String::new(), |(_, v)| v.trim().to_owned());
        let memory = read("/proc/meminfo")
            .lines()
            .find(|l| l.starts_with("MemTotal:"))
            .and_then(|l| l.split_whitespace().nth(1))
            .and_then(|kb| kb.parse::<u64>().ok())
            .map_or(0, |kb| kb * 1024);
        Machine {
            cpu,
            cores: std::thread::available_parallelism().map_or(0, usize::from),
            memory,
            kernel: read("/proc/sys/kernel/osrelease").trim().to_owned(),
        }
    }
}

/// What `fleet bench` writes to `bench.json`.
#[derive(Debug, Clone, Serialize)]
pub struct BenchReport {
    /// Fleet seconds each size ran.
    pub duration: f64,
    /// Time scale (1).
    pub time_scale: f64,
    /// The collector's state-log rate, Hz (`None`: every state).
    pub log_rate: Option<f64>,
    /// The machine.
    pub machine: Machine,
    /// One row per size.
    pub rows: Vec<BenchRow>,
    /// The machine's floor, measured in the same run before the fleets: a
    /// bare process that only wakes at the control rate (`fleet idle`).
    pub floor: Option<crate::cost::IdleReport>,
    /// The floor's CPU seconds per 60 s.
    pub floor_per_min: Option<f64>,
    /// One host per `--hosts` size.
    pub hosts: Vec<HostRow>,
    /// The marginal CPU of one more robot in a host, s per 60 s: the slope
    /// of the host's CPU between the first and last of `hosts`.
    pub marginal_per_robot_per_min: Option<f64>,
}

/// The generated scenario of `n` robots (see the module doc); with a
/// `state_rate` (the bench's `--log-rate`: what the collector keeps), the
/// robots, which no robot reads, publish their states at that rate
/// (`[fleet] state_rate`), not at every tick.
pub fn scenario_toml(n: usize, state_rate: Option<f64>) -> String {
    let cols = (n as f64).sqrt().ceil().max(1.0) as usize;
    let mut s = format!(
        "# Generated by `echelon fleet bench`: {n} robots behind a circular virtual leader.\n\
         name = \"bench-n{n}\"\n\
         description = \"fleet bench: {n} robots on a grid behind a circle\"\n\n\
         [sim]\nduration = 60.0\ndt = 0.001\n\n\
         [control]\nlaw = \"paper\"\nke = 1.5\nkz = 10.0\nl = 0.05\nlycomp = \"fit\"\nly_derivatives = \"neglect\"\n\n\
         [reference.circle]\nspeed = 0.2\nturn_rate = 0.05\nstart = {{ x = 0.0, y = 0.0, theta_deg = 0.0 }}\n"
    );
    if let Some(hz) = state_rate {
        let _ = write!(s, "\n[fleet]\nstate_rate = {hz:?}\n");
    }
    for k in 0..n {
        let (i, j) = (k / cols, k % cols);
        let x_off = 0.5 + SPACING * i as f64;
        let y_off = SPACING * (j as f64 - (cols - 1) as f64 / 2.0);
        // The slot at t = 0 (leader at the origin heading +x) is about
        // (−x_off − l, −y_off); start 0.1 m off it.
        let _ = write!(
            s,
            "\n[[agents]]\nname = \"robot {}\"\nrobot = \"agent1\"\n\
             start = {{ x = {:.3}, y = {:.3}, theta_deg = 0.0 }}\n\
             leader = \"reference\"\noffset = {{ x = {:.3}, y = {:.3} }}\n",
            k + 1,
            -x_off - 0.05 - 0.1,
            -y_off + 0.1,
            x_off,
            y_off
        );
    }
    s
}

/// The row of a finished run.
pub fn row_of(n: usize, up: &UpReport) -> BenchRow {
    let final_errors: Vec<f64> = up.robots.iter().map(|r| r.final_error).collect();
    let robots_received: u64 = up.robots.iter().map(|r| r.counters.received).sum();
    let collector = up.collector.as_ref();
    let collector_received = collector.map_or(0, |c| c.received);
    let delivered = collector_received + robots_received;
    let cpu_router = up.cost.routers.as_ref().map_or(0.0, |r| r.cpu);
    let per = |cpu: f64, n: u64| if n > 0 { cpu / n as f64 * 1e6 } else { 0.0 };
    BenchRow {
        robots: n,
        error: None,
        startup: up.startup,
        wall: up.wall,
        robot_processes: up.cost.robots.processes,
        cpu_per_robot: up.cost.cpu_per_robot,
        cpu_per_robot_per_min: up.cost.cpu_per_robot / up.duration * 60.0,
        cpu_over_floor: None,
        cpu_robot_max: up.cost.robots.cpu_max,
        cpu_collector: up.cost.collector.cpu,
        collector_us_per_message: per(up.cost.collector.cpu, collector_received),
        router_us_per_message: per(cpu_router, delivered),
        cpu_total: up.cost.total.cpu,
        cpu_router,
        rss_per_robot: up.cost.robots.max_rss_sum / up.cost.robot_count.max(1) as u64,
        messages_per_s: delivered as f64 / up.duration,
        collector_received,
        collector_decimated: collector.map_or(0, |c| c.decimated),
        collector_dropped: collector.map_or(0, |c| c.dropped),
        latency_p50: up.latency.robots.p50,
        latency_p99: up.latency.robots.p99,
        latency_max: up.latency.robots.max,
        collector_p99: up.latency.collector.p99,
        stale: up.robots.iter().map(|r| r.counters.stale).sum(),
        link_losses: up.robots.iter().map(|r| r.counters.link_losses).sum(),
        robots_dropped: up.robots_dropped(),
        final_max_error: final_errors.iter().copied().fold(0.0, f64::max),
        converged: final_errors.iter().filter(|&&e| e < 0.01).count(),
    }
}

/// The table in Markdown (one line per size, then the machine).
pub fn markdown(report: &BenchReport) -> String {
    let mut s = String::from(
        "| N | robot procs | startup s | CPU/robot s per 60 s | max proc | router CPU s | µs/msg | collector CPU s | µs/msg | dropped | RSS/robot MiB | msg/s | latency p50 ms | p99 ms | max ms | stale | link losses | robot drops | final max ‖e‖ m | converged |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in &report.rows {
        if let Some(e) = &r.error {
            let _ = writeln!(s, "| {} | failed: {} |||||||||||||||||||", r.robots, e);
            continue;
        }
        let _ = writeln!(
            s,
            "| {} | {} | {} | {:.3} | {:.3} | {:.2} | {:.1} | {:.2} | {:.1} | {} | {:.1} | {:.0} | {:.3} | {:.3} | {:.3} | {} | {} | {} | {:.2e} | {}/{} |",
            r.robots,
            r.robot_processes,
            r.startup.map_or("—".to_owned(), |v| format!("{v:.2}")),
            r.cpu_per_robot_per_min,
            r.cpu_robot_max / report.duration * 60.0,
            r.cpu_router,
            r.router_us_per_message,
            r.cpu_collector,
            r.collector_us_per_message,
            r.collector_dropped,
            r.rss_per_robot as f64 / (1u64 << 20) as f64,
            r.messages_per_s,
            r.latency_p50 * 1e3,
            r.latency_p99 * 1e3,
            r.latency_max * 1e3,
            r.stale,
            r.link_losses,
            r.robots_dropped,
            r.final_max_error,
            r.converged,
            r.robots
        );
    }
    let m = &report.machine;
    let _ = writeln!(
        s,
        "\n{} s of fleet time per size at time scale {}; the collector logged {}; {} ({} logical CPUs, {:.1} GiB), Linux {}.",
        report.duration,
        report.time_scale,
        report
            .log_rate
            .map_or("every state".to_owned(), |hz| format!(
                "{hz} states per robot per second"
            )),
        if m.cpu.is_empty() {
            "unknown CPU"
        } else {
            &m.cpu
        },
        m.cores,
        m.memory as f64 / (1u64 << 30) as f64,
        m.kernel
    );
    hosts_markdown(&mut s, report);
    s
}

/// The floor and the hosts' lines under the table.
fn hosts_markdown(s: &mut String, report: &BenchReport) {
    if let (Some(f), Some(per_min)) = (&report.floor, report.floor_per_min) {
        let _ = writeln!(
            s,
            "\nFloor (a bare process waking at {} Hz, measured first in the same run): {per_min:.3} s CPU per 60 s ({} wakes in {:.1} s); CPU/robot over the floor: {}.",
            f.rate,
            f.wakes,
            f.duration,
            (report.rows.iter())
                .filter_map(|r| Some(format!("{} robots {:.2}×", r.robots, r.cpu_over_floor?)))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    if report.hosts.is_empty() {
        return;
    }
    let _ = writeln!(
        s,
        "\n| robots in one host | host CPU s per 60 s | per robot | converged |\n|---|---|---|---|"
    );
    for h in &report.hosts {
        match &h.error {
            Some(e) => {
                let _ = writeln!(s, "| {} | failed: {e} |||", h.robots);
            }
            None => {
                let _ = writeln!(
                    s,
                    "| {} | {:.3} | {:.4} | {}/{} |",
                    h.robots, h.cpu_per_min, h.cpu_per_robot_per_min, h.converged, h.robots
                );
            }
        }
    }
    if let Some(m) = report.marginal_per_robot_per_min {
        let _ = writeln!(
            s,
            "\nMarginal CPU of one more robot in a host (slope between the first and last host): {m:.4} s per 60 s{}.",
            report
                .floor_per_min
                .map_or(String::new(), |f| format!(", the floor {f:.3} s"))
        );
    }
}

/// What the bench tells as it goes.
#[derive(Debug, Clone)]
pub enum Progress<'a> {
    /// Size `robots` starts (`index` of `of`, from 1).
    Start {
        /// Robots.
        robots: usize,
        /// Which size, from 1.
        index: usize,
        /// Sizes in all.
        of: usize,
    },
    /// A size finished (or failed).
    Done(&'a BenchRow),
    /// The floor is being measured.
    Floor,
    /// A host of this many robots starts.
    Host(usize),
}

/// Runs every size in order (a failed size is a row with its error; the
/// stop flag ends the bench after the current size), writes
/// [`BENCH_JSON`] and [`BENCH_MD`] in `out`.
pub fn run(
    opts: &BenchOptions,
    stop: &StopFlag,
    mut progress: impl FnMut(Progress<'_>),
) -> Result<BenchReport, FleetError> {
    if opts.robots.is_empty() || opts.robots.contains(&0) {
        return Err(FleetError::Config(
            "--robots: give one or more fleet sizes, each ≥ 1".into(),
        ));
    }
    if !(opts.duration.is_finite() && opts.duration > 0.0) {
        return Err(FleetError::Config(format!(
            "--duration {}: must be > 0",
            opts.duration
        )));
    }
    std::fs::create_dir_all(&opts.out).map_err(FleetError::io(&opts.out))?;
    let mut report = BenchReport {
        duration: opts.duration,
        time_scale: 1.0,
        log_rate: opts.log_rate,
        machine: Machine::this(),
        rows: Vec::with_capacity(opts.robots.len()),
        floor: None,
        floor_per_min: None,
        hosts: Vec::new(),
        marginal_per_robot_per_min: None,
    };
    progress(Progress::Floor);
    match floor(opts) {
        // A floor too small to measure is none (no ratio to zero).
        Ok(f) => {
            report.floor_per_min = Some(f.cpu / f.duration * 60.0).filter(|&c| c > 0.0);
            report.floor = Some(f);
        }
        Err(e) => eprintln!("fleet bench: the floor was not measured: {e}"),
    }
    for (i, &n) in opts.robots.iter().enumerate() {
        if stop.is_raised() {
            break;
        }
        progress(Progress::Start {
            robots: n,
            index: i + 1,
            of: opts.robots.len(),
        });
        let mut row = match run_size(opts, n, opts.robots_per_process, stop) {
            Ok(up) => row_of(n, &up),
            Err(e) => BenchRow {
                robots: n,
                error: Some(e.to_string()),
                ..BenchRow::default()
            },
        };
        row.cpu_over_floor = report.floor_per_min.map(|f| row.cpu_per_robot_per_min / f);
        progress(Progress::Done(&row));
        report.rows.push(row);
        crate::write_json_file(&opts.out.join(BENCH_JSON), &report)?;
    }
    for &k in &opts.hosts {
        if stop.is_raised() {
            break;
        }
        progress(Progress::Host(k));
        report.hosts.push(host_row(opts, k, stop));
        crate::write_json_file(&opts.out.join(BENCH_JSON), &report)?;
    }
    report.marginal_per_robot_per_min = marginal(&report.hosts);
    crate::write_json_file(&opts.out.join(BENCH_JSON), &report)?;
    let md = opts.out.join(BENCH_MD);
    std::fs::write(&md, markdown(&report)).map_err(FleetError::io(&md))?;
    Ok(report)
}

/// The machine's floor: `fleet idle` at the generated scenario's control
/// rate for the bench's duration, alone.
fn floor(opts: &BenchOptions) -> Result<crate::cost::IdleReport, FleetError> {
    let text = scenario_toml(1, None);
    let scenario = echelon::scenario::Scenario::parse(&text, "bench", None)?;
    let rate = scenario.fleet()?.control_rate;
    let out = std::process::Command::new(&opts.exe)
        .args(["fleet", "idle", "--rate", &rate.to_string()])
        .args(["--duration", &opts.duration.to_string()])
        .output()
        .map_err(|e| FleetError::Child(format!("fleet idle: {e}")))?;
    let stdout = String::from_utf8_lossy(&out.stdout);
    let line = stdout.lines().last().unwrap_or_default();
    serde_json::from_str(line).map_err(|e| {
        FleetError::Child(format!(
            "fleet idle printed no report ({e}): {}",
            String::from_utf8_lossy(&out.stderr).trim()
        ))
    })
}

/// A fleet of `k` robots all in one host: the host's CPU.
fn host_row(opts: &BenchOptions, k: usize, stop: &StopFlag) -> HostRow {
    match run_size(opts, k, Some(k), stop) {
        Ok(up) => {
            let per_min = up.cost.robots.cpu / up.duration * 60.0;
            HostRow {
                robots: k,
                error: None,
                cpu_per_min: per_min,
                cpu_per_robot_per_min: per_min / k as f64,
                converged: row_of(k, &up).converged,
            }
        }
        Err(e) => HostRow {
            robots: k,
            error: Some(e.to_string()),
            ..HostRow::default()
        },
    }
}

/// The slope of a host's CPU per 60 s between the first and last of
/// `hosts` that ran, per robot (`None`: fewer than two sizes ran).
fn marginal(hosts: &[HostRow]) -> Option<f64> {
    let ran: Vec<&HostRow> = hosts.iter().filter(|h| h.error.is_none()).collect();
    let (first, last) = (ran.first()?, ran.last()?);
    (last.robots != first.robots).then(|| {
        (last.cpu_per_min - first.cpu_per_min) / (last.robots as f64 - first.robots as f64)
    })
}

/// `fleet up` of the generated scenario of `n` robots, `per_process` to
/// a process (`None`: `fleet up`'s default), in `DIR/nNNN` (`DIR/nNNN-kK`
/// given `per_process`).
fn run_size(
    opts: &BenchOptions,
    n: usize,
    per_process: Option<usize>,
    stop: &StopFlag,
) -> Result<UpReport, FleetError> {
    let name = match per_process {
        Some(k) => format!("n{n:03}-k{k}"),
        None => format!("n{n:03}"),
    };
    let dir = opts.out.join(name);
    std::fs::create_dir_all(&dir).map_err(FleetError::io(&dir))?;
    let scenario = dir.join("scenario.toml");
    std::fs::write(&scenario, scenario_toml(n, opts.log_rate))
        .map_err(FleetError::io(&scenario))?;
    up::run(
        &UpOptions {
            duration: Some(opts.duration),
            log_rate: opts.log_rate,
            robots_per_process: per_process,
            ..UpOptions::simulated(
                scenario.display().to_string(),
                dir.clone(),
                opts.exe.clone(),
            )
        },
        stop,
    )
}

#[cfg(test)]
mod tests;
