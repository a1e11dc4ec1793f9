//! Where the collector's records go: the [`RecordSink`] trait and its files,
//! [`FileSink`] (`fleet.mcap`, `trajectory.csv` and, for ROS 2 robots,
//! `odometry.csv`).

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::PathBuf;

use echelon::csv::CsvWriter;
use echelon::output::{FrameRows, TRAJECTORY_FILE, TrajectoryRows};
use echelon::sample::AgentSample;
use echelon_mcap::scene::{Scene, SceneChannels, ScenePose, SceneSpec};
use echelon_mcap::{JsonSchema, McapLog};

use super::{CollectorReport, LATENCY_METADATA, MCAP_FILE};
use crate::FleetError;
use crate::ros2::record::RosTopic;
use crate::wire::{OdometryState, RobotState};

/// The collector's table of its ROS 2 robots' own odometry beside their
/// world poses, written once a robot publishes it.
pub(crate) const ODOMETRY_FILE: &str = "odometry.csv";

/// Its columns: fleet time, agent, the world pose the robot published, its
/// raw odometry (odom frame, heading unwrapped), the odometry's age and the
/// last fix's (empty: none).
pub(crate) const ODOMETRY_HEADER: &str = "t,agent,x,y,theta,x_raw,y_raw,theta_raw,age,fix_age";

/// The MCAP channel a record goes on.
#[derive(Debug, Clone, Copy)]
pub enum Channel<'a> {
    /// One of the collector's JSON channels: its topic and schema.
    Json(&'a str, &'a JsonSchema),
    /// A ROS 2 topic's channel: CDR bytes as received.
    Ros(&'a RosTopic),
}

impl Channel<'_> {
    /// Its topic.
    pub fn topic(&self) -> &str {
        match self {
            Channel::Json(topic, _) => topic,
            Channel::Ros(topic) => topic.topic(),
        }
    }
}

/// When a record was received (`log_time`) and sent (`publish_time`),
/// UNIX ns.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stamp {
    /// Received.
    pub log_time: u64,
    /// Sent.
    pub publish_time: u64,
}

/// Where the collector's records go: the files ([`run`](super::run)), or memory in tests.
pub trait RecordSink {
    /// Logs one MCAP message on `channel`.
    fn log(&mut self, channel: Channel<'_>, stamp: Stamp, data: &[u8]) -> Result<(), FleetError>;
    /// Appends one `trajectory.csv` row.
    fn row(&mut self, sample: &AgentSample) -> Result<(), FleetError>;
    /// Appends one `odometry.csv` row: the raw odometry `o` a ROS 2
    /// robot published with its state `s` (nothing in a sink without the
    /// table).
    fn odometry(&mut self, s: &RobotState, o: &OdometryState) -> Result<(), FleetError> {
        let _ = (s, o);
        Ok(())
    }
    /// Shows robot `k` (from 1) at `pose` on the 3D channels
    /// ([`echelon_mcap::scene`]); nothing when the sink has no scene.
    fn pose(&mut self, k: u32, pose: &ScenePose, stamp: Stamp) -> Result<(), FleetError>;
}

/// The collector's files: `fleet.mcap` and `trajectory.csv` in a directory.
#[derive(Debug)]
pub struct FileSink {
    log: McapLog<BufWriter<File>>,
    seq: BTreeMap<u16, u32>,
    csv: CsvWriter<BufWriter<File>>,
    trajectory: TrajectoryRows,
    csv_path: PathBuf,
    /// [`ODOMETRY_FILE`], from its first row.
    odometry: Option<CsvWriter<BufWriter<File>>>,
    /// The 3D channels, when the scenario is known; whether the fixed
    /// scene was written.
    scene: Option<(Scene, SceneChannels, bool)>,
}

impl RecordSink for FileSink {
    fn log(&mut self, channel: Channel<'_>, stamp: Stamp, data: &[u8]) -> Result<(), FleetError> {
        let id = match channel {
            Channel::Json(topic, schema) => self.log.channel(topic, schema)?,
            Channel::Ros(topic) => self.log.ros2_channel(
                topic.topic(),
                &topic.schema(),
                topic.offered_qos_profiles(),
            )?,
        };
        self.write(id, stamp, data)
    }

    fn row(&mut self, sample: &AgentSample) -> Result<(), FleetError> {
        self.trajectory
            .row(sample, &mut self.csv)
            .map_err(FleetError::io(&self.csv_path))
    }

    fn odometry(&mut self, s: &RobotState, o: &OdometryState) -> Result<(), FleetError> {
        let path = self.odometry_path();
        let csv = match self.odometry.as_mut() {
            Some(csv) => csv,
            None => {
                let file = File::create(&path).map_err(FleetError::io(&path))?;
                let csv = CsvWriter::new(BufWriter::with_capacity(1 << 16, file), ODOMETRY_HEADER)
                    .map_err(FleetError::io(&path))?;
                self.odometry.insert(csv)
            }
        };
        let x = &s.state;
        csv.time(s.t)
            .int(u64::from(s.agent))
            .nums([x.x, x.y, x.theta])
            .nums(o.raw)
            .num(o.age)
            .opt(o.fix_age)
            .end_row()
            .map_err(FleetError::io(&path))
    }

    fn pose(&mut self, k: u32, pose: &ScenePose, stamp: Stamp) -> Result<(), FleetError> {
        let Some((scene, channels, fixed_written)) = self.scene.as_mut() else {
            return Ok(());
        };
        if scene.set(k, pose).is_none() {
            // A robot the scenario does not have: its state is on
            // `/agent/K/state` still; the scene has no place for it.
            return Ok(());
        }
        if !*fixed_written {
            *fixed_written = true;
            channels.fixed(&mut self.log, scene, pose.t, stamp.log_time)?;
        }
        channels.robot(&mut self.log, scene, k, stamp.log_time, stamp.publish_time)?;
        Ok(())
    }
}

impl FileSink {
    /// Where [`ODOMETRY_FILE`] goes: beside `trajectory.csv`.
    fn odometry_path(&self) -> PathBuf {
        self.csv_path.with_file_name(ODOMETRY_FILE)
    }

    /// Writes one message on channel `id` with the channel's next sequence number.
    fn write(&mut self, id: u16, stamp: Stamp, data: &[u8]) -> Result<(), FleetError> {
        let seq = self.seq.entry(id).or_insert(0);
        self.log
            .write(id, *seq, stamp.log_time, stamp.publish_time, data)?;
        *seq = seq.wrapping_add(1);
        Ok(())
    }

    /// Creates `out` if needed and the files [`MCAP_FILE`] and
    /// [`TRAJECTORY_FILE`] in it (truncated), the latter with the columns of
    /// a fleet of torque-driven robots ([`FileSink::with_trajectory`]).
    pub fn create(out: &std::path::Path) -> Result<FileSink, FleetError> {
        FileSink::with_trajectory(out, TrajectoryRows::default())
    }

    /// [`FileSink::create`], `trajectory.csv` with the columns of
    /// `trajectory` (those `echelon run` writes for the same scenario:
    /// [`TrajectoryRows::for_agents`]).
    pub fn with_trajectory(
        out: &std::path::Path,
        trajectory: TrajectoryRows,
    ) -> Result<FileSink, FleetError> {
        std::fs::create_dir_all(out).map_err(FleetError::io(out))?;
        let mcap_path = out.join(MCAP_FILE);
        let csv_path = out.join(TRAJECTORY_FILE);
        let log = McapLog::create(&mcap_path)?;
        let file = File::create(&csv_path).map_err(FleetError::io(&csv_path))?;
        let csv = CsvWriter::new(BufWriter::with_capacity(1 << 16, file), trajectory.header())
            .map_err(FleetError::io(&csv_path))?;
        Ok(FileSink {
            log,
            seq: BTreeMap::new(),
            csv,
            trajectory,
            csv_path,
            odometry: None,
            scene: None,
        })
    }

    /// Also writes the 3D channels ([`echelon_mcap::scene`]) of `spec`'s
    /// robots: each robot's transform and scene with each of its states,
    /// the fixed scene once, with the first.
    pub fn with_scene(mut self, spec: &SceneSpec) -> Result<FileSink, FleetError> {
        let channels = SceneChannels::register(&mut self.log)?;
        self.scene = Some((Scene::new(spec), channels, false));
        Ok(self)
    }

    /// Writes the per-key latency summaries of `report` as the MCAP
    /// metadata record [`LATENCY_METADATA`].
    pub fn latency_metadata(&mut self, report: &CollectorReport) -> Result<(), FleetError> {
        let mut map = BTreeMap::new();
        for (key, l) in &report.latency_by_key {
            let json = serde_json::to_string(l).map_err(echelon_mcap::McapLogError::from)?;
            map.insert(key.clone(), json);
        }
        self.log.metadata(LATENCY_METADATA, map)?;
        Ok(())
    }

    /// Closes the files (MCAP summary and footer written).
    pub fn finish(mut self) -> Result<(), FleetError> {
        self.log.finish()?;
        if let Some(csv) = self.odometry.as_mut() {
            let path = self.csv_path.with_file_name(ODOMETRY_FILE);
            csv.flush().map_err(FleetError::io(&path))?;
        }
        self.csv.flush().map_err(FleetError::io(&self.csv_path))
    }
}
