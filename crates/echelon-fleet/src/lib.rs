//! # echelon-fleet
//!
//! The paper's experiment (section 5) as networked processes on Zenoh: a
//! leader publishing the virtual leader's reference, one process per robot
//! running the control law (eq. 13) on a plant, and a collector recording
//! everything to MCAP and `trajectory.csv`. `up` starts the whole fleet on
//! loopback. See `docs/fleet.md` for key expressions, the wire format,
//! counters and the link-loss policies.

#![cfg_attr(not(test), warn(clippy::too_many_lines))]

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

pub mod bench;
pub mod bundle;
pub mod certs;
pub mod clock;
pub mod collector;
pub mod command;
pub mod cost;
pub mod doctor;
pub mod excite;
pub mod faults;
pub mod garbage;
pub mod heartbeat;
pub mod host;
pub mod keys;
pub mod latency;
pub mod leader;
pub mod link;
pub mod matrix;
pub mod neighbours;
pub mod net;
pub mod operator;
pub mod options;
pub mod plant;
pub mod probe;
pub mod robot;
pub mod role;
pub mod ros2;
pub mod router;
pub mod runtime;
pub mod status;
pub mod token;
pub mod up;
pub mod wire;

#[cfg(test)]
mod testing;

/// Everything that can stop a fleet process.
#[derive(Debug, thiserror::Error)]
pub enum FleetError {
    /// The scenario is invalid or does not fit the fleet.
    #[error(transparent)]
    Scenario(#[from] echelon::ScenarioError),
    /// A setting is invalid.
    #[error("{0}")]
    Config(String),
    /// Zenoh refused (configuration, connection, declaration).
    #[error("zenoh: {0}")]
    Zenoh(String),
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: std::path::PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The MCAP log failed.
    #[error(transparent)]
    Mcap(#[from] echelon_mcap::McapLogError),
    /// A child process of `fleet up` failed.
    #[error("{0}")]
    Child(String),
    /// A robot's ROS 2 graph is not what the scenario says (its `cmd_vel`
    /// takes another type, nothing under its namespace, no `odom`): one
    /// line naming the robot and what was found.
    #[error("{0}")]
    Graph(String),
    /// An order the fleet refuses (a resume while a robot's base reports a
    /// hazard): nothing was sent.
    #[error("{0}")]
    Refused(String),
    /// A bounded wait ended without what it waited for (robots that never
    /// joined the hub): one line naming what is missing.
    #[error("{0}")]
    TimedOut(String),
    /// A robot's state stopped being finite or left its bounds
    /// ([`echelon::guard::Bounds`]): it commanded zero and stopped.
    #[error("{0}")]
    Diverged(String),
}

impl FleetError {
    pub(crate) fn io(path: &std::path::Path) -> impl FnOnce(std::io::Error) -> FleetError + '_ {
        move |source| FleetError::Io {
            path: path.to_path_buf(),
            source,
        }
    }
}

/// Writes `value` to `path` as pretty JSON with a final newline.
pub(crate) fn write_json_file<T: serde::Serialize>(
    path: &std::path::Path,
    value: &T,
) -> Result<(), FleetError> {
    let mut json = serde_json::to_string_pretty(value).map_err(echelon_mcap::McapLogError::from)?;
    json.push('\n');
    std::fs::write(path, json).map_err(FleetError::io(path))
}

/// A flag raised by SIGINT or SIGTERM (and SIGHUP): processes finish their
/// loop, flush and exit cleanly.
#[derive(Debug, Clone, Default)]
pub struct StopFlag(Arc<AtomicBool>);

impl StopFlag {
    /// A flag no signal raises (for tests and embedding).
    pub fn new() -> StopFlag {
        StopFlag::default()
    }

    /// A flag raised by SIGINT/SIGTERM/SIGHUP. Only one per process.
    pub fn on_signals() -> Result<StopFlag, FleetError> {
        let flag = StopFlag::new();
        let raised = flag.clone();
        ctrlc::set_handler(move || raised.raise())
            .map_err(|e| FleetError::Config(format!("cannot handle signals: {e}")))?;
        Ok(flag)
    }

    /// Raises the flag.
    pub fn raise(&self) {
        self.0.store(true, Ordering::SeqCst);
    }

    /// Whether it was raised.
    pub fn is_raised(&self) -> bool {
        self.0.load(Ordering::SeqCst)
    }
}

/// The wall-clock time now in UNIX nanoseconds (MCAP `log_time` of the collector).
pub(crate) fn unix_nanos() -> u64 {
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64);
    now.saturating_add_signed(WALL_CLOCK_JUMP.load(std::sync::atomic::Ordering::Relaxed))
}

/// What the process's wall clock was stepped by, ns (`--wall-clock-jump`:
/// a rehearsed NTP step; fleet time is monotonic and does not see it).
static WALL_CLOCK_JUMP: std::sync::atomic::AtomicI64 = std::sync::atomic::AtomicI64::new(0);

/// Steps this process's wall clock (every stamp it writes and reads) by
/// `ns`: the fault matrix's clock jump.
pub(crate) fn jump_wall_clock(ns: i64) {
    WALL_CLOCK_JUMP.fetch_add(ns, std::sync::atomic::Ordering::Relaxed);
}
