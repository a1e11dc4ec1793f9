//! `echelon fleet up` and `fleet bench`: the whole fleet on loopback, and
//! the summary they print.

use anyhow::{Context, Result, bail};
use echelon_fleet::bench::{self, BenchOptions, Progress};
use echelon_fleet::collector::MCAP_FILE;
use echelon_fleet::latency::LatencyReport;
use echelon_fleet::up::{self, Topology, UP_SUMMARY_FILE, UpCost, UpOptions, UpReport};
use echelon_fleet::{StopFlag, collector::SUMMARY_FILE};

use crate::cmd::out::outln;

use super::{BenchArgs, TopologyArg, UpArgs};

pub(super) fn bench_cmd(a: BenchArgs) -> Result<()> {
    if a.robots.contains(&0) {
        bail!("--robots: every fleet size must be ≥ 1");
    }
    let stop = StopFlag::on_signals()?;
    let exe = std::env::current_exe().context("locating the echelon binary")?;
    let quiet = a.quiet;
    let duration = a.duration;
    let report = bench::run(
        &BenchOptions {
            robots: a.robots,
            duration,
            out: a.out.clone(),
            exe,
            log_rate: a.log_rate,
            robots_per_process: a.robots_per_process,
            hosts: a.hosts,
        },
        &stop,
        |p| {
            if quiet {
                return;
            }
            match p {
                Progress::Start { robots, index, of } => eprintln!(
                    "[{index}/{of}] {robots} robots: fleet up for {duration} s of fleet time…"
                ),
                Progress::Done(row) => match &row.error {
                    Some(e) => eprintln!("      failed: {e}"),
                    None => eprintln!(
                        "      done in {:.1} s ({}/{} converged)",
                        row.wall, row.converged, row.robots
                    ),
                },
                Progress::Floor => eprintln!(
                    "the floor: a bare process waking at the control rate for {duration} s…"
                ),
                Progress::Host(k) => {
                    eprintln!("{k} robots in one host for {duration} s of fleet time…")
                }
            }
        },
    )?;
    outln!("{}", bench::markdown(&report).trim_end())?;
    if !quiet {
        outln!(
            "wrote {}, {}",
            a.out.join(bench::BENCH_JSON).display(),
            a.out.join(bench::BENCH_MD).display()
        )?;
    }
    if report.rows.iter().any(|r| r.error.is_some()) {
        return Err(
            crate::cmd::out::Failed("some fleet sizes failed (see the table)".to_owned()).into(),
        );
    }
    Ok(())
}

/// A run whose leader died mid-run did not do what was asked: exit 1
/// naming it, once the summary (and `fleet-summary.json`) says how the
/// robots held.
fn leader_died(report: &UpReport) -> Result<()> {
    match &report.leader_failure {
        Some(f) => Err(crate::cmd::out::Failed(format!(
            "the leader died mid-run ({f}); the robots held under their link-loss policy"
        ))
        .into()),
        None => Ok(()),
    }
}

/// `fleet up`: the whole fleet on loopback, then its summary (unless `--quiet`).
pub(super) fn up_cmd(a: UpArgs) -> Result<()> {
    let stop = StopFlag::on_signals()?;
    let exe = std::env::current_exe().context("locating the echelon binary")?;
    let (quiet, out) = (a.quiet, a.out.clone());
    let report = up::run(&up_options(a, exe)?, &stop)?;
    if quiet {
        return leader_died(&report);
    }
    print_run(&report)?;
    print_robots(&report)?;
    print_ros2(&report)?;
    print_hazards(&report)?;
    print_safety(&report)?;
    print_collector(&report)?;
    print_latency(&report)?;
    print_cost(&report.cost)?;
    outln!(
        "wrote {}, {}, {}, {}",
        out.join(MCAP_FILE).display(),
        out.join(echelon::output::TRAJECTORY_FILE).display(),
        out.join(SUMMARY_FILE).display(),
        out.join(UP_SUMMARY_FILE).display()
    )?;
    leader_died(&report)
}

/// `fleet up`'s options from its arguments, the processes started from `exe`
/// (reads `--token-file`).
fn up_options(a: UpArgs, exe: std::path::PathBuf) -> Result<UpOptions> {
    Ok(UpOptions {
        scenario: a.scenario,
        out: a.out,
        duration: a.clock.duration,
        time_scale: a.clock.time_scale,
        faults: a.faults.spec(),
        secure: a.secure,
        exe,
        ros2: a.ros2,
        real: a.real,
        topology: match a.topology {
            TopologyArg::Router => Topology::Router,
            TopologyArg::Mesh => Topology::Mesh,
        },
        sites: a.sites,
        foxglove: a.live.foxglove,
        dashboard: a.live.dashboard,
        log_rate: a.live.log_rate,
        hazards: a.hazard,
        chaos: Default::default(),
        hub: a.hub.then_some(echelon_fleet::up::HubOptions {
            listen: a.listen,
            wait: a.wait,
        }),
        token: a
            .token_file
            .as_deref()
            .map(echelon_fleet::token::OperatorToken::from_file)
            .transpose()
            .context("--token-file")?,
        robots_per_process: a.robots_per_process,
    })
}

/// The summary's head: the run, on-board robots, startup, topology,
/// routers and the leader.
fn print_run(report: &UpReport) -> Result<()> {
    outln!(
        "{}: fleet \"{}\", {} robot{}, {} s of fleet time at ×{} in {:.1} s",
        report.scenario,
        report.fleet,
        report.robots.len(),
        if report.robots.len() == 1 { "" } else { "s" },
        report.duration,
        report.time_scale,
        report.wall
    )?;
    if !report.onboard.is_empty() {
        outln!(
            "  on-board (joined from their computers; their reports stay there, their states are in the log): robots {:?}",
            report.onboard
        )?;
    }
    if let (Some(startup), Some(run)) = (report.startup, report.run) {
        outln!("  startup (all joined) {startup:.2} s, then run {run:.2} s")?;
    }
    match report.topology {
        Topology::Router => outln!(
            "  through {} router{} at {}",
            report.routers.len(),
            if report.routers.len() == 1 { "" } else { "s" },
            report.router_endpoints.join(", ")
        )?,
        Topology::Mesh => outln!("  peer mesh (every process linked to every other)")?,
    }
    for (s, r) in report.routers.iter().enumerate() {
        outln!(
            "  router {}: {} processes at most at once, {} in all, up {:.1} s",
            s + 1,
            r.members_peak,
            r.members_joined,
            r.uptime
        )?;
    }
    match (&report.leader, &report.leader_failure) {
        (Some(l), _) => outln!("  leader: {} reference samples published", l.published)?,
        (None, Some(f)) => {
            outln!("  leader: died mid-run ({f}); the robots held under their link-loss policy")?
        }
        (None, None) => outln!("  leader: no report")?,
    }
    Ok(())
}

/// The per-robot table: final error, counters and latency.
fn print_robots(report: &UpReport) -> Result<()> {
    outln!(
        "  {:<8} {:>11} {:>9} {:>9} {:>9} {:>6} {:>7} {:>9} {:>6} {:>9} {:>6} {:>8} {:>8}",
        "agent",
        "final ‖e‖",
        "received",
        "accepted",
        "loss",
        "outage",
        "malform",
        "wrong-ver",
        "stale",
        "reordered",
        "losses",
        "p50 ms",
        "p99 ms"
    )?;
    for r in &report.robots {
        let c = &r.counters;
        outln!(
            "  {:<8} {:>9.2e} m {:>9} {:>9} {:>9} {:>6} {:>7} {:>9} {:>6} {:>9} {:>6} {:>8.3} {:>8.3}",
            format!("robot {}", r.agent),
            r.final_error,
            c.received,
            c.accepted,
            c.injected_loss,
            c.injected_outage,
            c.malformed,
            c.wrong_version,
            c.stale,
            c.reordered,
            c.link_losses,
            r.latency.p50 * 1e3,
            r.latency.p99 * 1e3,
        )?;
    }
    Ok(())
}

/// What the ROS 2 bases (or, with `--real`, the robot processes) saw.
fn print_ros2(report: &UpReport) -> Result<()> {
    for (b, r) in report.bases.iter().zip(&report.robots) {
        let c = &b.counters;
        let refused = c.cmd_wrong_type + c.cmd_malformed + c.cmd_non_finite + c.cmd_no_attachment;
        let ros = r.ros2.unwrap_or_default();
        let odom_refused =
            ros.odom_wrong_type + ros.odom_malformed + ros.odom_non_finite + ros.odom_wrong_frames;
        outln!(
            "  ROS 2 base {}: {} cmd_vel received, {} refused, {} odom published; robot: {} odom accepted, {} refused, {} commands saturated",
            b.agent,
            c.cmd_received,
            refused,
            c.odom_published,
            ros.odom_accepted,
            odom_refused,
            ros.cmd_saturated,
        )?;
    }
    if report.bases.is_empty() {
        // Real robots (--real): what each robot process saw of its robot.
        for r in &report.robots {
            let Some(ros) = r.ros2 else { continue };
            let odom_refused = ros.odom_wrong_type
                + ros.odom_malformed
                + ros.odom_non_finite
                + ros.odom_wrong_frames;
            outln!(
                "  ROS 2 robot {}: {} cmd_vel sent ({} saturated), {} odom accepted, {} refused",
                r.agent,
                ros.cmd_sent,
                ros.cmd_saturated,
                ros.odom_accepted,
                odom_refused,
            )?;
        }
    }
    Ok(())
}

/// Each robot's base-safety counts and the hazard stops it saw.
fn print_hazards(report: &UpReport) -> Result<()> {
    for r in &report.robots {
        let Some(h) = &r.hazards else { continue };
        let c = &h.counts;
        let events: Vec<String> = h
            .events
            .iter()
            .map(|e| match e.cleared {
                Some(end) => format!(
                    "{} at {:.2} s (cleared {:.2} s)",
                    e.hazard.name(),
                    e.at,
                    end
                ),
                None => format!("{} at {:.2} s (still in force)", e.hazard.name(), e.at),
            })
            .collect();
        outln!(
            "  base safety, robot {}: {} hazard vectors ({} refused), {} e-stop samples ({} refused), {} object-proximity, {} backup-limit reports; stops: {}; resumes refused: {}",
            r.agent,
            c.hazard_received,
            c.hazard_refused,
            c.estop_received,
            c.estop_refused,
            c.object_proximity,
            c.backup_limit,
            if events.is_empty() {
                "none".to_owned()
            } else {
                events.join(", ")
            },
            r.commands.refused_resumes,
        )?;
    }
    Ok(())
}

/// The closest approach and the safety filters' work, with `[safety]`.
fn print_safety(report: &UpReport) -> Result<()> {
    if let Some(c) = &report.approach {
        // The closest approach from the true states the collector received.
        let name = |k: usize| {
            report
                .robots
                .iter()
                .find(|r| r.agent as usize == k)
                .map_or_else(|| format!("robot {k}"), |r| r.name.clone())
        };
        crate::cmd::run::print_approach(c, name)?;
    }
    if let Some(t) = &report.safety {
        for r in &report.robots {
            let s = r.safety.unwrap_or_default();
            let d = s.min_distance;
            outln!(
                "  safety, robot {}: filter acted {} of {} steps, {} infeasible (braked), {} deadlock breaks, {} stale neighbours ({} steps braked), nearest point {}",
                r.agent,
                s.active,
                s.steps,
                s.infeasible,
                s.deadlock_breaks,
                s.stale_neighbours,
                s.stale_brakes,
                d.map_or("none in range".to_owned(), |d| format!("{d:.4} m")),
            )?;
        }
        outln!(
            "  safety, fleet: acted {} steps, {} infeasible, {} deadlock breaks, {} stale neighbours, nearest points {}",
            t.active,
            t.infeasible,
            t.deadlock_breaks,
            t.stale_neighbours,
            t.min_distance
                .map_or("none in range".to_owned(), |d| format!("{d:.4} m")),
        )?;
        if !report.deadlocked_at_end.is_empty() {
            outln!(
                "  safety: robots {:?} ended away from their slots, held by their filters (deadlocked)",
                report.deadlocked_at_end
            )?;
        }
    }
    Ok(())
}

/// The collector's counts, a gap in the log, and samples the robots dropped.
fn print_collector(report: &UpReport) -> Result<()> {
    match &report.collector {
        Some(col) => {
            outln!(
                "  collector: {} messages received, {} logged, {} rejected",
                col.received,
                col.logged,
                col.rejected.values().sum::<u64>()
            )?;
            if col.decimated > 0 || col.dropped > 0 {
                outln!(
                    "  collector: {} states decimated (--log-rate), {} samples dropped (queue full)",
                    col.decimated,
                    col.dropped
                )?;
            }
        }
        None => outln!("  collector: killed (no report)")?,
    }
    if let Some(gap) = &report.log_gap {
        outln!(
            "  log gap: the log ends at fleet time {:.2} s; the run went on to {:.2} s",
            gap.from,
            gap.to
        )?;
    }
    let robots_dropped = report.robots_dropped();
    if robots_dropped > 0 {
        outln!(
            "  robots: {robots_dropped} samples dropped (input queue full; each robot's `dropped`)"
        )?;
    }
    Ok(())
}

/// The latencies, leader → robot and → collector.
fn print_latency(report: &UpReport) -> Result<()> {
    let lat = |l: &LatencyReport| {
        format!(
            "{} samples, p50 {:.3} ms, p95 {:.3} ms, p99 {:.3} ms, max {:.3} ms",
            l.count,
            l.p50 * 1e3,
            l.p95 * 1e3,
            l.p99 * 1e3,
            l.max * 1e3
        )
    };
    let worst = report
        .latency
        .worst_robot
        .as_ref()
        .map_or(String::new(), |w| {
            format!(
                " (worst: robot {}, p99 {:.3} ms)",
                w.agent,
                w.latency.p99 * 1e3
            )
        });
    outln!(
        "  latency, leader → robot: {}{worst}",
        lat(&report.latency.robots)
    )?;
    outln!("  latency, → collector: {}", lat(&report.latency.collector))?;
    Ok(())
}

/// The processes' CPU time and peak memory.
fn print_cost(c: &UpCost) -> Result<()> {
    let mb = |b: u64| b as f64 / (1u64 << 20) as f64;
    outln!(
        "  CPU: robots {:.2} s ({:.3} s per robot; {} robots in {} processes, max {:.3} s), leader {:.2} s, collector {:.2} s, total {:.2} s",
        c.robots.cpu,
        c.cpu_per_robot,
        c.robot_count,
        c.robots.processes,
        c.robots.cpu_max,
        c.leader.cpu,
        c.collector.cpu,
        c.total.cpu
    )?;
    outln!(
        "  peak RSS: robot process {:.1} MiB (mean; max {:.1}), leader {:.1} MiB, collector {:.1} MiB, sum {:.1} MiB",
        mb(c.robots.max_rss_mean),
        mb(c.robots.max_rss_max),
        mb(c.leader.max_rss_max),
        mb(c.collector.max_rss_max),
        mb(c.total.max_rss_sum)
    )?;
    if let Some(r) = &c.routers {
        outln!(
            "  routers: CPU {:.2} s, peak RSS {:.1} MiB (max)",
            r.cpu,
            mb(r.max_rss_max)
        )?;
    }
    Ok(())
}

/// `fleet faults`: the fault matrix; exits 1 when a row does not hold.
pub(super) fn faults_cmd(a: super::FaultsArgs) -> Result<()> {
    let stop = StopFlag::on_signals()?;
    let report = echelon_fleet::matrix::run(
        &echelon_fleet::matrix::FaultsOptions {
            out: a.out.clone(),
            exe: std::env::current_exe()?,
            only: a.only,
            time_scale: a.time_scale,
        },
        &stop,
    )?;
    let md = a.out.join(echelon_fleet::matrix::FAULTS_MD);
    outln!("{}", md.display())?;
    if !report.pass() {
        let failed: Vec<String> = report
            .rows
            .iter()
            .filter(|r| !r.pass)
            .map(|r| format!("{}: {}", r.name, r.problems.join("; ")))
            .collect();
        return Err(crate::cmd::out::Failed(format!(
            "fleet faults: {} row(s) did not hold: {}",
            failed.len(),
            failed.join(" | ")
        ))
        .into());
    }
    Ok(())
}
