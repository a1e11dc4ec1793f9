//! What each process of `fleet up` cost: CPU seconds (user + system, every
//! thread) and peak memory (peak resident set, `VmHWM`), read from Linux's
//! `/proc/<pid>/` by the parent.
//!
//! The CPU time is what reaping the child adds to this process's
//! `RUSAGE_CHILDREN` (`getrusage`: user + system of every thread, in
//! microseconds; [`children_cpu_seconds`]), read just before and after the
//! one `wait` that reaps it. `/proc/<pid>/stat`'s `utime + stime`, read
//! once it has exited but before it is reaped (`waitid(WNOWAIT)`), is the
//! fallback: it counts whole clock ticks (10 ms), so a child that used 8 ms
//! read as 0. The peak RSS is gone by then (the
//! kernel frees the memory map on exit), so `VmHWM` (a high-water mark) is
//! sampled while the child runs, at most every [`MEMORY_PERIOD`]: growth in
//! its last period before exit would be missed. Elsewhere than Linux both read
//! as absent.

use std::time::Duration;

use serde::{Deserialize, Serialize};

/// How often a running child's peak RSS is sampled.
pub const MEMORY_PERIOD: Duration = Duration::from_millis(500);

/// `utime + stime` of `/proc/<pid>/stat` text, in clock ticks.
pub fn parse_stat_ticks(stat: &str) -> Option<u64> {
    // The command name (field 2) is in parentheses and may hold anything:
    // fields are counted from the last ')'. Field 3 (state) comes first.
    let rest = &stat[stat.rfind(')')? + 1..];
    let mut fields = rest.split_whitespace();
    let utime: u64 = fields.nth(11)?.parse().ok()?;
    let stime: u64 = fields.next()?.parse().ok()?;
    Some(utime + stime)
}

/// `VmHWM` of `/proc/<pid>/status` text, bytes.
pub fn parse_status_hwm(status: &str) -> Option<u64> {
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let mut it = line["VmHWM:".len()..].split_whitespace();
    let kb: u64 = it.next()?.parse().ok()?;
    (it.next() == Some("kB")).then_some(kb * 1024)
}

/// CPU seconds (user + system) of process `pid` so far (or, for a zombie,
/// in all).
pub fn cpu_seconds(pid: u32) -> Option<f64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let ticks = parse_stat_ticks(&stat)?;
    Some(ticks as f64 / rustix::param::clock_ticks_per_second() as f64)
}

/// CPU seconds (user + system) of this process's children that have been
/// waited for (and of their waited-for descendants), to the microsecond:
/// `getrusage(RUSAGE_CHILDREN)`. The difference across the `wait` that
/// reaps one child is that child's CPU time, as long as no other thread
/// reaps a child meanwhile.
pub fn children_cpu_seconds() -> Option<f64> {
    let usage =
        nix::sys::resource::getrusage(nix::sys::resource::UsageWho::RUSAGE_CHILDREN).ok()?;
    let seconds = |t: nix::sys::time::TimeVal| t.tv_sec() as f64 + t.tv_usec() as f64 * 1e-6;
    Some(seconds(usage.user_time()) + seconds(usage.system_time()))
}

/// Peak resident set of the running process `pid` so far, bytes.
pub fn peak_rss(pid: u32) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    parse_status_hwm(&status)
}

/// A process's own CPU use as it reports it (a robot's `cpu` in its stats,
/// which `fleet status` shows).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CpuUse {
    /// CPU seconds (user + system, every thread) since the process started.
    pub seconds: f64,
    /// Share of one core since its previous reading, real time (0.25: a
    /// quarter of a core; above 1 on several cores); `None` at the first
    /// reading.
    pub share: Option<f64>,
}

/// Reads this process's CPU seconds, each reading with its share of one
/// core since the previous one.
#[derive(Debug, Clone, Default)]
pub struct CpuMeter {
    last: Option<(f64, std::time::Instant)>,
}

impl CpuMeter {
    /// A meter with no reading yet.
    pub fn new() -> CpuMeter {
        CpuMeter::default()
    }

    /// This process's CPU use now (`None` where `/proc` cannot be read).
    pub fn read(&mut self) -> Option<CpuUse> {
        let seconds = cpu_seconds(std::process::id())?;
        Some(self.reading(seconds, std::time::Instant::now()))
    }

    /// The reading of `seconds` CPU seconds at `at`.
    fn reading(&mut self, seconds: f64, at: std::time::Instant) -> CpuUse {
        let share = self.last.and_then(|(before, then)| {
            let wall = at.saturating_duration_since(then).as_secs_f64();
            (wall > 0.0).then(|| ((seconds - before) / wall).max(0.0))
        });
        self.last = Some((seconds, at));
        CpuUse { seconds, share }
    }
}

/// One process's cost.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ProcessCost {
    /// Its role (`leader`, `collector`, `robot/K`, `base/K`).
    pub role: String,
    /// CPU seconds, user + system (absent if it could not be read).
    pub cpu: Option<f64>,
    /// Peak resident set, bytes (absent if never sampled).
    pub max_rss: Option<u64>,
}

/// The cost of a set of processes (one role, or all).
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct RoleCost {
    /// Processes counted.
    pub processes: usize,
    /// CPU seconds, all of them.
    pub cpu: f64,
    /// CPU seconds per process, mean.
    pub cpu_mean: f64,
    /// CPU seconds of the costliest process.
    pub cpu_max: f64,
    /// Peak RSS per process, mean, bytes.
    pub max_rss_mean: u64,
    /// Largest peak RSS, bytes.
    pub max_rss_max: u64,
    /// Peak RSS summed over the processes, bytes (an upper bound on their
    /// memory at any one time).
    pub max_rss_sum: u64,
}

impl RoleCost {
    /// The sums, means and maxima over `costs` (missing readings count as 0).
    pub fn of<'a>(costs: impl IntoIterator<Item = &'a ProcessCost>) -> RoleCost {
        let mut r = RoleCost::default();
        for c in costs {
            let cpu = c.cpu.unwrap_or(0.0);
            let rss = c.max_rss.unwrap_or(0);
            r.processes += 1;
            r.cpu += cpu;
            r.cpu_max = r.cpu_max.max(cpu);
            r.max_rss_sum += rss;
            r.max_rss_max = r.max_rss_max.max(rss);
        }
        if r.processes > 0 {
            r.cpu_mean = r.cpu / r.processes as f64;
            r.max_rss_mean = r.max_rss_sum / r.processes as u64;
        }
        r
    }
}

/// What the machine's floor cost ([`idle`]): a bare process that only
/// wakes at a rate.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct IdleReport {
    /// Its wake rate, Hz.
    pub rate: f64,
    /// How long it ran, s of real time.
    pub duration: f64,
    /// Times it woke.
    pub wakes: u64,
    /// Its CPU seconds (user + system, every thread), whole life, to the
    /// nanosecond.
    pub cpu: f64,
}

/// The floor of a periodic process on this machine: wakes at `rate` Hz
/// (absolute deadlines, as a robot's timer) for `duration` s of real time
/// doing nothing else, then reads its own CPU seconds (`fleet idle`, which
/// `fleet bench` measures robots against).
pub fn idle(
    rate: f64,
    duration: f64,
    stop: &crate::StopFlag,
) -> Result<IdleReport, crate::FleetError> {
    if !(rate.is_finite() && rate > 0.0 && duration.is_finite() && duration > 0.0) {
        return Err(crate::FleetError::Config(format!(
            "fleet idle: rate {rate} Hz and duration {duration} s must be > 0"
        )));
    }
    let period = std::time::Duration::from_secs_f64(1.0 / rate);
    let start = std::time::Instant::now();
    let mut next = start;
    let mut wakes = 0u64;
    while start.elapsed().as_secs_f64() < duration && !stop.is_raised() {
        next += period;
        if let Some(wait) = next.checked_duration_since(std::time::Instant::now()) {
            std::thread::sleep(wait);
        }
        wakes += 1;
    }
    Ok(IdleReport {
        rate,
        duration: start.elapsed().as_secs_f64(),
        wakes,
        cpu: own_cpu_seconds(),
    })
}

/// This process's CPU seconds, every thread, to the nanosecond
/// (`CLOCK_PROCESS_CPUTIME_ID`): `/proc`'s clock ticks (10 ms) would read
/// a few seconds of a bare timer as 0.
fn own_cpu_seconds() -> f64 {
    let t = rustix::time::clock_gettime(rustix::time::ClockId::ProcessCPUTime);
    t.tv_sec as f64 + t.tv_nsec as f64 * 1e-9
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A child that runs for a few milliseconds used CPU: reaping it adds
    /// more than zero to the children's usage, where `/proc`'s 10 ms ticks
    /// may read 0. (No upper bound: another test thread may reap a child
    /// of its own meanwhile.)
    #[test]
    fn a_short_child_costs_more_than_nothing() {
        for _ in 0..3 {
            let before = children_cpu_seconds().expect("getrusage");
            let status = std::process::Command::new("sh")
                .args(["-c", "i=0; while [ $i -lt 3000 ]; do i=$((i+1)); done"])
                .status()
                .expect("sh");
            assert!(status.success());
            let used = children_cpu_seconds().expect("getrusage") - before;
            assert!(used > 0.0, "{used} s of CPU");
        }
    }

    #[test]
    fn stat_and_status_are_parsed() {
        // A command name with spaces and a ')' in it.
        let stat = "4242 (echelon (x) y) S 1 4242 4242 0 -1 4194560 100 0 0 0 \
                    250 31 0 0 20 0 12 0 1000 123456 789 18446744073709551615";
        assert_eq!(parse_stat_ticks(stat), Some(281));
        assert_eq!(parse_stat_ticks("garbage"), None);
        let status = "Name:\techelon\nVmPeak:\t  2000 kB\nVmHWM:\t   1536 kB\nVmRSS:\t 1000 kB\n";
        assert_eq!(parse_status_hwm(status), Some(1536 * 1024));
        assert_eq!(parse_status_hwm("Name: x\n"), None);
    }

    #[test]
    fn this_process_has_a_cost() {
        let pid = std::process::id();
        // Burn a little CPU so that at least one tick is counted.
        let mut x = 0u64;
        let start = std::time::Instant::now();
        while start.elapsed() < Duration::from_millis(30) {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(1);
        }
        std::hint::black_box(x);
        assert!(cpu_seconds(pid).is_some_and(|c| c > 0.0));
        assert!(peak_rss(pid).is_some_and(|m| m > 1 << 20));
    }

    /// A meter's share is the CPU seconds between two readings over the
    /// real time between them; none at the first reading, and none for a
    /// second reading at the same instant.
    #[test]
    fn a_meter_shares_cpu_between_readings() {
        let mut m = CpuMeter::new();
        let t0 = std::time::Instant::now();
        assert_eq!(m.reading(2.0, t0).share, None);
        let r = m.reading(2.5, t0 + Duration::from_secs(2));
        assert_eq!((r.seconds, r.share), (2.5, Some(0.25)));
        assert_eq!(m.reading(2.5, t0 + Duration::from_secs(2)).share, None);
        // The real process: a reading, then one after burning CPU.
        let mut m = CpuMeter::new();
        let first = m.read().unwrap();
        let start = std::time::Instant::now();
        let mut x = 0u64;
        while start.elapsed() < Duration::from_millis(50) {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(1);
        }
        std::hint::black_box(x);
        let second = m.read().unwrap();
        assert!(second.seconds >= first.seconds, "{first:?} {second:?}");
        assert!(second.share.is_some_and(|s| s >= 0.0), "{second:?}");
    }

    #[test]
    fn role_cost_sums_and_means() {
        let p = |cpu, rss| ProcessCost {
            role: "robot/1".into(),
            cpu: Some(cpu),
            max_rss: Some(rss),
        };
        let r = RoleCost::of(&[p(1.0, 100), p(3.0, 300)]);
        assert_eq!(
            (r.processes, r.cpu, r.cpu_mean, r.cpu_max),
            (2, 4.0, 2.0, 3.0)
        );
        assert_eq!(
            (r.max_rss_mean, r.max_rss_max, r.max_rss_sum),
            (200, 300, 400)
        );
        assert_eq!(RoleCost::of(&[]), RoleCost::default());
    }
}
