//! The collector on the fleet runtime: [`CollectorTask`] and its Zenoh
//! drivers ([`run`], [`run_with_ros2`], [`run_recording`]).

use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

use echelon::output::TrajectoryRows;
use echelon_mcap::scene::SceneSpec;

use super::dashboard::Dashboard;
use super::live::Tee;
use super::{Collector, CollectorReport, FileSink, LiveFeed, SUMMARY_FILE};
use crate::clock::FleetClock;
use crate::keys::Keys;
use crate::net::NetOptions;
use crate::role::Member;
use crate::ros2::record::{self, RosTopic};
use crate::runtime::{self, Flow, Linger, Outputs, Sample, Task};
use crate::{FleetError, StopFlag};

/// Options of the collector.
#[derive(Debug, Clone)]
pub struct CollectorOptions {
    /// Output directory.
    pub out: PathBuf,
    /// Fleet name.
    pub fleet: String,
    /// Stop after this long of real time (absent: run until a signal).
    pub max_wall: Option<Duration>,
    /// Network.
    pub net: NetOptions,
    /// Kill itself with SIGKILL once a reference it records reaches this
    /// fleet time (`--die-at`: the fault matrix's collector failure; it
    /// leaves its files as they were, `fleet.mcap` without its footer).
    pub die_at: Option<f64>,
}

/// [`Collector`] as a [`Task`] of the fleet runtime: every fleet key (and
/// its ROS 2 topics) in, each sample recorded as soon as it arrives (and
/// those that arrived before its inputs closed); files closed and
/// `collector.json` written with its report.
#[derive(Debug)]
pub struct CollectorTask {
    collector: Collector,
    sink: FileSink,
    /// With `--foxglove`: the live feed, fed everything the files get.
    live: Option<LiveFeed>,
    out: PathBuf,
    /// Stop at this time of its clock (real time), s.
    until: f64,
    /// `--die-at`: fleet time, from the references it records.
    die_at: Option<f64>,
}

/// Its input number of the fleet's keys (then one per ROS 2 topic).
const FLEET: usize = 0;

/// Samples that may wait for the collector at once (its input queue); more
/// are dropped and counted (`dropped` in `collector.json`). At 20 000
/// samples/s, a second and a half.
pub const INPUT_QUEUE: usize = 1 << 15;

/// How long the collector lets samples gather before it takes them all
/// (real time, s): one wake-up per batch, not per sample. The delay each
/// sample is recorded with is measured when it arrives, not when taken.
pub const BATCH: f64 = 0.01;

impl CollectorTask {
    /// `collector` recording to `sink`, its summary to `out`, for at most
    /// `max_wall` of real time.
    pub fn new(
        collector: Collector,
        sink: FileSink,
        out: PathBuf,
        max_wall: Option<Duration>,
    ) -> CollectorTask {
        CollectorTask {
            collector,
            sink,
            live: None,
            out,
            until: max_wall.map_or(f64::INFINITY, |m| m.as_secs_f64()),
            die_at: None,
        }
    }

    /// Kills itself once a reference it records reaches fleet time `at`.
    pub fn dying_at(mut self, at: Option<f64>) -> CollectorTask {
        self.die_at = at;
        self
    }

    /// Also feeds everything it records to `live`.
    pub fn with_live(mut self, live: LiveFeed) -> CollectorTask {
        self.live = Some(live);
        self
    }
}

impl Task for CollectorTask {
    type Report = CollectorReport;

    fn inputs(&self) -> Vec<String> {
        std::iter::once(self.collector.keys.everything())
            .chain(self.collector.ros_topics().iter().map(RosTopic::key_expr))
            .collect()
    }

    fn outputs(&self) -> Vec<String> {
        Vec::new()
    }

    fn tokens(&self) -> Vec<String> {
        vec![self.collector.keys.alive(&Member::Collector.liveliness())]
    }

    fn wakes_on_input(&self) -> bool {
        true
    }

    fn batch(&self) -> f64 {
        BATCH
    }

    fn queue(&self) -> usize {
        INPUT_QUEUE
    }

    fn on_dropped(&mut self, total: u64) {
        self.collector.set_dropped(total);
    }

    /// On SIGINT/SIGTERM it records what is still on its way (the others'
    /// last words, flushed to its router before they exited) until nothing
    /// came for a while: `fleet up` stops it after every other process.
    fn linger(&self) -> Option<Linger> {
        Some(Linger::FLEET)
    }

    fn on_input(&mut self, input: usize, s: &Sample<'_>) -> Result<(), FleetError> {
        // Logged at its arrival (UNIX ns), not when its batch is taken
        // (up to BATCH later): the log time is the receipt time.
        let now = s.unix_ns;
        if input == FLEET {
            if self.die_at.is_some()
                && s.key.ends_with("/reference")
                && let Some(t) = crate::clock::ReferenceTime::of(s.payload)
            {
                crate::faults::die_if_due(self.die_at, t, "fleet collector");
            }
            self.collector.record_delay(s.key, s.delay);
            return match self.live.as_mut() {
                Some(live) => {
                    let mut tee = Tee(&mut self.sink, live);
                    self.collector.on_message(s.key, s.payload, now, &mut tee)
                }
                None => self
                    .collector
                    .on_message(s.key, s.payload, now, &mut self.sink),
            };
        }
        // A ROS 2 publisher stamps its attachment, not the sample.
        let delay = s.delay.or_else(|| {
            let sent = record::publish_time(s.attachment, 0);
            (sent > 0).then(|| s.unix_ns as i64 - sent as i64)
        });
        self.collector.record_delay(s.key, delay);
        match self.live.as_mut() {
            Some(live) => {
                let mut tee = Tee(&mut self.sink, live);
                self.collector
                    .on_ros_sample(s.key, s.payload, s.attachment, now, &mut tee)
            }
            None => {
                self.collector
                    .on_ros_sample(s.key, s.payload, s.attachment, now, &mut self.sink)
            }
        }
    }

    fn next_wake(&self) -> f64 {
        self.until
    }

    fn tick(&mut self, now: f64, _: &mut dyn Outputs) -> Result<Flow, FleetError> {
        Ok(if now >= self.until {
            Flow::Stop
        } else {
            Flow::Continue
        })
    }

    fn report(self) -> Result<CollectorReport, FleetError> {
        let mut sink = self.sink;
        let mut report = self.collector.finish();
        report.live = self.live.map(LiveFeed::finish).transpose()?;
        sink.latency_metadata(&report)?;
        sink.finish()?;
        crate::write_json_file(&self.out.join(SUMMARY_FILE), &report)?;
        Ok(report)
    }
}

/// Records until the stop flag (or `max_wall`), then closes the files: the
/// Zenoh driver of [`Collector`] (no ROS 2 topics; see [`run_with_ros2`]).
pub fn run(opts: CollectorOptions, stop: &StopFlag) -> Result<CollectorReport, FleetError> {
    run_with_ros2(opts, Vec::new(), stop)
}

/// [`run`], also recording the ROS 2 topics `ros` (one Zenoh subscription
/// per topic, on [`RosTopic::key_expr`]).
pub fn run_with_ros2(
    opts: CollectorOptions,
    ros: Vec<RosTopic>,
    stop: &StopFlag,
) -> Result<CollectorReport, FleetError> {
    run_recording(opts, ros, TrajectoryRows::default(), stop)
}

/// [`run_with_ros2`], writing `trajectory.csv` with the columns of
/// `trajectory` ([`FileSink::with_trajectory`]): [`CollectorTask`] on the
/// fleet runtime.
pub fn run_recording(
    opts: CollectorOptions,
    ros: Vec<RosTopic>,
    trajectory: TrajectoryRows,
    stop: &StopFlag,
) -> Result<CollectorReport, FleetError> {
    let recording = Recording {
        ros,
        trajectory,
        ..Recording::default()
    };
    run_with(opts, recording, stop)
}

/// What the collector records beyond the fleet's keys, and how.
#[derive(Debug, Clone, Default)]
pub struct Recording {
    /// ROS 2 topics to record ([`run_with_ros2`]).
    pub ros: Vec<RosTopic>,
    /// The columns of `trajectory.csv` ([`FileSink::with_trajectory`]).
    pub trajectory: TrajectoryRows,
    /// The scenario's scene: with it, `fleet.mcap` also carries the 3D
    /// channels ([`echelon_mcap::scene`], [`FileSink::with_scene`]).
    pub scene: Option<SceneSpec>,
    /// Serve the live fleet to Foxglove on this address ([`LiveFeed`];
    /// port 0: any free port, named on stderr and in the report).
    pub foxglove: Option<SocketAddr>,
    /// Serve the live dashboard on this address ([`Dashboard`]; needs the
    /// scene; starts the Foxglove server on a free port if `foxglove` is
    /// not given).
    pub dashboard: Option<SocketAddr>,
    /// Log at most this many states per robot per second
    /// ([`Collector::with_log_rate`]; `None`: every state).
    pub log_rate: Option<f64>,
    /// With the scenario's `[safety]`: measure the closest approach
    /// ([`Collector::with_approach`]).
    pub approach: Option<super::ApproachWatch>,
}

/// The collector recording `recording`: [`CollectorTask`] on the fleet runtime.
pub fn run_with(
    opts: CollectorOptions,
    recording: Recording,
    stop: &StopFlag,
) -> Result<CollectorReport, FleetError> {
    let keys = Keys::new(&opts.fleet);
    let collector = Collector::with_ros2(keys, recording.ros)
        .map_err(|e| FleetError::Config(e.to_string()))?
        .with_log_rate(recording.log_rate)?
        .with_approach(recording.approach);
    let mut sink = FileSink::with_trajectory(&opts.out, recording.trajectory)?;
    if let Some(spec) = &recording.scene {
        sink = sink.with_scene(spec)?;
    }
    let mut task =
        CollectorTask::new(collector, sink, opts.out, opts.max_wall).dying_at(opts.die_at);
    let foxglove = recording
        .foxglove
        .or_else(|| recording.dashboard.map(|d| SocketAddr::new(d.ip(), 0)));
    if let Some(addr) = foxglove {
        let live = LiveFeed::start(addr, recording.scene.as_ref())?;
        eprintln!("foxglove: the live fleet at {}", live.address());
        if let Some(at) = recording.dashboard {
            let scene = recording
                .scene
                .as_ref()
                .ok_or_else(|| FleetError::Config("--dashboard needs the scenario".into()))?;
            // The fleet's operator token (`fleet up` sets it), else one of
            // its own: the page's resumes are signed with it.
            let token = match crate::token::OperatorToken::from_env()? {
                Some(t) => t,
                None => crate::token::OperatorToken::random()?,
            };
            let dashboard =
                Dashboard::start(at, live.address(), scene, &opts.fleet, &opts.net, token)?;
            eprintln!("dashboard (operator): {}", dashboard.operator_url());
        }
        task = task.with_live(live);
    }
    runtime::run(task, &opts.net, FleetClock::new(1.0), stop)
}
