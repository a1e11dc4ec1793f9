//! The fleet's child processes: spawned, polled, stopped and reaped
//! ([`Proc`]).

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Instant;

use crate::FleetError;
use crate::cost::{self, ProcessCost};

/// A started child, killed if still running when dropped (a failing test or
/// an error never leaves processes behind).
pub(super) struct Proc {
    pub(super) role: String,
    pub(super) child: Child,
    pub(super) log: PathBuf,
    /// Where its stdout goes; its last JSON line (an object, or a host's
    /// array) is its report.
    pub(super) stdout: PathBuf,
    pub(super) report: Option<serde_json::Value>,
    pub(super) status: Option<std::process::ExitStatus>,
    /// CPU seconds: what reaping it added to this process's children's
    /// usage ([`cost::children_cpu_seconds`]), else `/proc`'s ticks read
    /// when it exited (before it was reaped).
    pub(super) cpu: Option<f64>,
    /// Peak RSS so far, bytes, and when it was last sampled.
    pub(super) max_rss: Option<u64>,
    pub(super) rss_sampled: Option<Instant>,
}

impl Proc {
    pub(super) fn terminate(&self) {
        let pid = rustix::process::Pid::from_child(&self.child);
        let _ = rustix::process::kill_process(pid, rustix::process::Signal::TERM);
    }

    /// Whether it has exited, not reaping it (so that `/proc` still holds
    /// its CPU time); `true` if that cannot be told.
    fn exited(&self) -> bool {
        use rustix::process::{Pid, WaitId, WaitIdOptions, waitid};
        let pid = Pid::from_child(&self.child);
        let options = WaitIdOptions::EXITED | WaitIdOptions::NOWAIT | WaitIdOptions::NOHANG;
        !matches!(waitid(WaitId::Pid(pid), options), Ok(None))
    }

    /// Its cost so far.
    pub(super) fn cost(&self) -> ProcessCost {
        ProcessCost {
            role: self.role.clone(),
            cpu: self.cpu,
            max_rss: self.max_rss,
        }
    }

    /// Polls; samples its peak memory while it runs, reads its CPU time
    /// when it exits, then reaps it and reads the report line from stdout.
    fn poll(&mut self) -> Result<bool, FleetError> {
        if self.status.is_some() {
            return Ok(true);
        }
        if !self.exited() {
            if self
                .rss_sampled
                .is_none_or(|t| t.elapsed() >= cost::MEMORY_PERIOD)
            {
                self.rss_sampled = Some(Instant::now());
                if let Some(m) = cost::peak_rss(self.child.id()) {
                    self.max_rss = Some(self.max_rss.unwrap_or(0).max(m));
                }
            }
            return Ok(false);
        }
        if self.cpu.is_none() {
            self.cpu = cost::cpu_seconds(self.child.id());
        }
        let before = cost::children_cpu_seconds();
        match self.child.try_wait() {
            Ok(Some(status)) => {
                if let (Some(b), Some(a)) = (before, cost::children_cpu_seconds()) {
                    // To the microsecond (`/proc` counts 10 ms ticks).
                    self.cpu = Some((a - b).max(0.0));
                }
                self.status = Some(status);
                let last = std::fs::File::open(&self.stdout).ok().and_then(|out| {
                    BufReader::new(out)
                        .lines()
                        .map_while(Result::ok)
                        .filter(|l| l.trim_start().starts_with(['{', '[']))
                        .last()
                });
                self.report = last.and_then(|l| serde_json::from_str(&l).ok());
                Ok(true)
            }
            Ok(None) => Ok(false),
            Err(e) => Err(FleetError::Child(format!("{}: {e}", self.role))),
        }
    }

    /// The last line it wrote on stderr (its log), `""` if none.
    pub(super) fn last_said(&self) -> String {
        std::fs::read_to_string(&self.log)
            .unwrap_or_default()
            .lines()
            .rev()
            .find(|l| !l.trim().is_empty())
            .unwrap_or("")
            .to_owned()
    }

    pub(super) fn failure(&self) -> Option<String> {
        let status = self.status?;
        if status.success() {
            return None;
        }
        let tail = self.last_said();
        Some(format!(
            "{} exited with {status} ({}: {tail})",
            self.role,
            self.log.display()
        ))
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        if self.status.is_none() && matches!(self.child.try_wait(), Ok(None)) {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// Polls every one of `procs` (none skipped); whether all have exited.
pub(super) fn poll_all<'a>(
    procs: impl IntoIterator<Item = &'a mut Proc>,
) -> Result<bool, FleetError> {
    let mut all = true;
    for p in procs {
        all &= p.poll()?;
    }
    Ok(all)
}

/// Asks each of `procs` to stop (SIGTERM) and waits until all have exited
/// (polling every `nap`, at most 30 s; then the error names `what`). Their
/// exit statuses are left for [`Proc::failure`].
pub(super) fn stop_all(
    procs: &mut [Proc],
    nap: std::time::Duration,
    what: &str,
) -> Result<(), FleetError> {
    for p in procs.iter() {
        p.terminate();
    }
    let wind_down = Instant::now();
    while !poll_all(procs.iter_mut())? {
        if wind_down.elapsed() > std::time::Duration::from_secs(30) {
            return Err(FleetError::Child(format!("{what} did not stop")));
        }
        std::thread::sleep(nap);
    }
    Ok(())
}

/// Starts `exe` with `args` as `role`, with the environment variables `env`
/// on top of this process's, its stderr to `logs/<role>.log`, its stdout to
/// `logs/<role>.out`.
pub(super) fn spawn(
    exe: &Path,
    role: &str,
    args: &[String],
    env: &[(&str, &str)],
    logs: &Path,
) -> Result<Proc, FleetError> {
    let log = logs.join(format!("{}.log", role.replace('/', "-")));
    let file = std::fs::File::create(&log).map_err(FleetError::io(&log))?;
    // Stdout goes to a file, not a pipe: a report longer than the pipe's
    // buffer (the collector's, with a hundred robots) would block the child
    // in its last write while `fleet up` waits for it to exit.
    let stdout = logs.join(format!("{}.out", role.replace('/', "-")));
    let out = std::fs::File::create(&stdout).map_err(FleetError::io(&stdout))?;
    let mut command = Command::new(exe);
    if let Some(runtime) = crate::net::zenoh_runtime(role) {
        command.env(crate::net::ZENOH_RUNTIME_ENV, runtime);
    }
    command.envs(env.iter().copied());
    let child = command
        .args(args)
        .stdin(Stdio::null())
        .stdout(out)
        .stderr(file)
        .spawn()
        .map_err(|e| FleetError::Child(format!("starting {role} ({}): {e}", exe.display())))?;
    Ok(Proc {
        role: role.to_owned(),
        child,
        log,
        stdout,
        report: None,
        status: None,
        cpu: None,
        max_rss: None,
        rss_sampled: None,
    })
}
