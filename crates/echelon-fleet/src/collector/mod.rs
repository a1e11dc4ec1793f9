//! `echelon fleet collector`: records everything published under
//! `echelon/<fleet>/**` (paper section 5's data collector).
//!
//! Every sample that reaches it is logged to `fleet.mcap` exactly once: valid
//! messages on their typed channel (`/reference`, `/agent/K/state`,
//! `/agent/K/stats`, `/fleet/command`), anything else on `/rejected` with the key, the reason and
//! the bytes. Robot states (once started) also go to `trajectory.csv` with the
//! simulator's header. On SIGINT/SIGTERM it records what is still on its way
//! until its inputs are quiet ([`crate::runtime::Linger`]), stops listening,
//! logs what is still queued, and closes valid files.
//!
//! Given ROS 2 topics ([`RosTopic`](crate::ros2::record::RosTopic), e.g. every robot's `cmd_vel` and
//! `odom`), it also records them as `ros2 bag record -s mcap` does: one
//! channel per topic named like it (`/robot1/cmd_vel`), the raw CDR bytes as
//! received, schema `ros2msg` with the full message definition, `log_time`
//! the receipt time and `publish_time` the rmw_zenoh attachment's source
//! timestamp. Whoever published them (echelon or a real robot), a sample of
//! the wrong type (key) or with an invalid CDR payload is refused: counted
//! and logged on `/rejected` instead.

mod approach;
mod dashboard;
mod live;
mod machine;
mod report;
mod schema;
mod sink;
mod task;
#[cfg(test)]
mod tests;

pub use approach::ApproachWatch;
pub use dashboard::Dashboard;
pub use live::{BACKLOG, DEFAULT_ADDR, DEFAULT_DASHBOARD, LiveFeed, LiveReport, QUEUE};
pub use machine::{Collector, state_record};
pub use report::{AgentRecord, CollectorReport};
pub use schema::{COMMAND, REJECTED, STATS};
pub use sink::{Channel, FileSink, RecordSink, Stamp};
pub use task::{
    BATCH, CollectorOptions, CollectorTask, INPUT_QUEUE, Recording, run, run_recording, run_with,
    run_with_ros2,
};

/// The MCAP file the collector writes.
pub const MCAP_FILE: &str = "fleet.mcap";
/// The collector's summary.
pub const SUMMARY_FILE: &str = "collector.json";
/// Name of the MCAP metadata record holding the per-key latency summaries
/// (each key's value: its [`LatencyReport`](crate::latency::LatencyReport) as JSON).
pub const LATENCY_METADATA: &str = "echelon.latency";
/// Topic of the fleet commands ([`crate::command::FleetCommand`]).
pub const COMMAND_TOPIC: &str = "/fleet/command";
/// Topic of everything that was not a valid message of its key.
pub const REJECTED_TOPIC: &str = "/rejected";
