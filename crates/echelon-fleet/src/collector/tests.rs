//! Tests of the collector's state machine, with records kept in memory.

use echelon::control::LeaderMotion;
use echelon::csv::CsvWriter;
use echelon::output::TrajectoryRows;
use echelon::sample::AgentSample;
use echelon::stats::Summary;
use echelon_mcap::scene::ScenePose;
use echelon_mcap::{REFERENCE_TOPIC, nanos};

use super::{Channel, Collector, CollectorReport, REJECTED_TOPIC, RecordSink, Stamp};
use crate::FleetError;
use crate::keys::Keys;
use crate::ros2::record::RosTopic;
use crate::wire::{self, Header, LinkStatus, Reference, RobotState};

/// Records in memory.
#[derive(Debug, Default)]
struct Memory {
    logged: Vec<(String, u64, u64, Vec<u8>)>,
    rows: Vec<String>,
    trajectory: TrajectoryRows,
    poses: Vec<(u32, ScenePose)>,
}

impl RecordSink for Memory {
    fn log(&mut self, channel: Channel<'_>, stamp: Stamp, data: &[u8]) -> Result<(), FleetError> {
        self.logged.push((
            channel.topic().to_owned(),
            stamp.log_time,
            stamp.publish_time,
            data.to_vec(),
        ));
        Ok(())
    }

    fn row(&mut self, sample: &AgentSample) -> Result<(), FleetError> {
        // One row on its own, without the header line.
        let mut csv =
            CsvWriter::new(Vec::new(), "").map_err(FleetError::io(std::path::Path::new("row")))?;
        self.trajectory
            .row(sample, &mut csv)
            .map_err(FleetError::io(std::path::Path::new("row")))?;
        let bytes = csv
            .into_inner()
            .map_err(FleetError::io(std::path::Path::new("row")))?;
        let text = String::from_utf8_lossy(&bytes);
        self.rows.push(text.trim_start_matches('\n').to_owned());
        Ok(())
    }

    fn pose(&mut self, k: u32, pose: &ScenePose, _: Stamp) -> Result<(), FleetError> {
        self.poses.push((k, *pose));
        Ok(())
    }
}

/// Valid messages go to their typed topic, a started robot's state also to
/// the CSV; garbage, wrong versions, unknown keys and messages of the
/// wrong kind go to `/rejected` with their reason: every sample is logged
/// exactly once.
#[test]
fn every_sample_is_logged_once_and_garbage_is_rejected_with_its_reason() {
    let keys = Keys::new("f");
    let mut c = Collector::new(keys.clone());
    let mut sink = Memory::default();
    let mut reference = Vec::new();
    wire::encode_reference(
        &mut reference,
        Header { source: 1, seq: 4 },
        &Reference {
            t: 2.0,
            motion: LeaderMotion::default(),
            speed: 0.2,
            turn_rate: 0.2,
        },
    );
    let state = |link| {
        let mut b = Vec::new();
        let s = RobotState {
            t: 2.5,
            agent: 1,
            link,
            e: [3e-3, 4e-3],
            ..RobotState::default()
        };
        wire::encode_state(&mut b, Header { source: 2, seq: 0 }, &s);
        b
    };
    let (tracking, waiting) = (state(LinkStatus::Tracking), state(LinkStatus::Waiting));
    let mut wrong_version = reference.clone();
    wrong_version[1] = 9;
    let stats = br#"{"agent":1,"t":3.0}"#;
    let command =
        crate::command::FleetCommand::new(crate::command::Order::Stop, 1, "operator", "").encode();
    let k = |s: &str| s.to_owned();
    let inputs: Vec<(String, &[u8])> = vec![
        (keys.reference(), &reference),
        (keys.state(1), &tracking),
        (keys.state(1), &waiting),
        (keys.stats(1), stats),
        (keys.stats(2), stats),
        (keys.stats(1), b"{"),
        (keys.reference(), &[1, 2, 3]),
        (keys.state(1), &wrong_version),
        (keys.state(2), &tracking),
        (keys.state(1), &reference),
        (k("echelon/f/alive/junk"), &reference),
        (keys.command(), &command),
        (keys.command(), b"{\"order\":\"stop\"}"),
    ];
    for (i, (key, bytes)) in inputs.iter().enumerate() {
        c.on_message(key, bytes, 1000 + i as u64, &mut sink)
            .unwrap_or_else(|e| panic!("{e}"));
    }
    let report = c.finish();
    assert_eq!(report.received, inputs.len() as u64);
    assert_eq!(report.logged, report.received);
    assert_eq!(sink.logged.len() as u64, report.logged);
    assert_eq!(
        rejected(&report),
        [
            ("malformed", 1),
            ("malformed command", 1),
            ("malformed stats JSON", 1),
            ("message of the wrong kind for its key", 2),
            ("stats of another agent", 1),
            ("unknown key", 1),
            ("wrong version", 1),
        ]
    );
    assert_eq!(report.logged_by_topic[REFERENCE_TOPIC], 1);
    assert_eq!(report.logged_by_topic["/agent/1/state"], 2);
    assert_eq!(report.logged_by_topic["/agent/1/stats"], 1);
    assert_eq!(report.logged_by_topic[super::COMMAND_TOPIC], 1);
    assert_eq!(report.logged_by_topic[REJECTED_TOPIC], 8);
    // log_time is the arrival time given, publish_time the sender's.
    assert_eq!((sink.logged[0].1, sink.logged[0].2), (1000, nanos(2.0)));
    // One CSV row: the tracking state, not the waiting one.
    assert_eq!(sink.rows.len(), 1);
    assert!(sink.rows[0].starts_with("2.5,1,"), "{}", sink.rows[0]);
    let a = &report.agents[0];
    assert_eq!((a.agent, a.messages, a.rows), (1, 2, 1));
    assert!((a.final_error - 5e-3).abs() < 1e-15);
    assert_eq!(a.link, "waiting");
}

/// The states of a simulated run of velocity bases, sent as robots send
/// them, give the collector the simulator's statistics (the same
/// accumulator, the same samples) and the simulator's rows, velocity
/// columns included.
#[test]
fn the_collector_s_statistics_and_rows_are_the_simulator_s() {
    use echelon::output::{FrameRows, TRAJECTORY_HEADER_VELOCITY};
    use echelon::scenario::{Overrides, Scenario};
    use echelon::sim::{Frame, Observer, ObserverError};

    let run = Scenario::builtin("experiment-circle-velocity")
        .unwrap_or_else(|| panic!("a built-in"))
        .build(&Overrides {
            duration: Some(2.0),
            ..Overrides::default()
        })
        .unwrap_or_else(|e| panic!("{e}"));
    let mut simulation = run.simulation();
    let trajectory = TrajectoryRows::for_agents(run.plan.agents());
    assert_eq!(trajectory.header(), TRAJECTORY_HEADER_VELOCITY);
    let keys = Keys::new("f");
    let mut c = Collector::new(keys.clone());
    let mut sink = Memory {
        trajectory,
        ..Memory::default()
    };
    let mut sim_rows = Memory {
        trajectory,
        ..Memory::default()
    };
    let mut summary = Summary::new(run.plan.agents().len(), Summary::SETTLE_TOLERANCE);
    let mut send = |frame: &Frame<'_>| -> Result<(), ObserverError> {
        for (i, (state, o)) in frame.states.iter().zip(frame.outputs).enumerate() {
            let s = RobotState {
                t: frame.t,
                agent: i as u32 + 1,
                link: LinkStatus::Tracking,
                state: *state,
                e: o.e,
                z: o.z,
                u: o.u,
                tau: o.tau,
                velocity: o.velocity.as_ref().map(Into::into),
                ..RobotState::default()
            };
            let mut b = Vec::new();
            wire::encode_state(
                &mut b,
                Header {
                    source: 1,
                    seq: frame.step,
                },
                &s,
            );
            c.on_message(&keys.state(s.agent), &b, 0, &mut sink)?;
        }
        for sample in AgentSample::all(frame) {
            sim_rows.row(&sample)?;
        }
        Ok(())
    };
    simulation
        .run(&mut [&mut send as &mut dyn Observer, &mut summary])
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(sink.rows, sim_rows.rows);
    assert!(sink.rows[0].split(',').count() == 20, "{}", sink.rows[0]);
    let report = c.finish();
    let agents = summary.agents(run.plan.agents());
    assert_eq!(report.agents.len(), agents.len());
    for (a, s) in report.agents.iter().zip(&agents) {
        assert_eq!(a.rows, run.plan.steps() + 1);
        assert_eq!(
            (a.final_error, a.rms_error, a.peak_torque),
            (s.final_error, s.rms_error, s.peak_torque)
        );
        assert_eq!(
            [a.final_state[0], a.final_state[1], a.final_state[2]],
            [s.final_pose.x, s.final_pose.y, s.final_pose.theta]
        );
    }
}

/// Delays are recorded per key and in total, unstamped samples counted
/// apart, and the quantiles come out in seconds.
#[test]
fn delays_are_summarised_per_key_and_in_total() {
    let keys = Keys::new("f");
    let mut c = Collector::new(keys.clone());
    for d in [1_000_000, 2_000_000, 3_000_000] {
        c.record_delay(&keys.reference(), Some(d));
    }
    c.record_delay(&keys.state(1), Some(5_000_000));
    c.record_delay(&keys.state(1), None);
    let r = c.finish();
    assert_eq!((r.latency.count, r.latency.unstamped), (4, 1));
    assert!((r.latency.max - 5e-3).abs() < 1e-12);
    let reference = &r.latency_by_key[&keys.reference()];
    assert_eq!(reference.count, 3);
    assert!((reference.p50 - 2e-3).abs() <= 2e-3 * crate::latency::RELATIVE_ERROR);
    assert!((reference.max - 3e-3).abs() < 1e-12);
    assert_eq!(r.latency_by_key[&keys.state(1)].unstamped, 1);
    assert!(reference.buckets.is_empty());
}

/// ROS samples of the recorded topics are logged as received on their
/// topic's channel; a wrong type, a wrong hash, bad CDR or a foreign key
/// goes to `/rejected`, counted as refused; every sample once.
#[test]
fn ros_samples_are_recorded_as_received_or_refused_with_their_reason() {
    use echelon_ros2::KeyScheme;
    use echelon_ros2::attachment::Attachment;
    use echelon_ros2::keys::topic_key;
    use echelon_ros2::msgs::{ODOMETRY, TWIST, TWIST_STAMPED, Time, TwistStamped};
    use echelon_ros2::{Odometry, RosMessage};

    let scheme = KeyScheme::RmwZenoh;
    let mut topics = RosTopic::robot(scheme, 0, "/robot1", TWIST_STAMPED)
        .unwrap_or_else(|e| panic!("{e}"))
        .to_vec();
    let mut c =
        Collector::with_ros2(Keys::new("f"), topics.clone()).unwrap_or_else(|e| panic!("{e}"));
    let mut sink = Memory::default();
    let cmd_key = topic_key(scheme, 0, "/robot1/cmd_vel", &TWIST_STAMPED);
    let odom_key = topic_key(scheme, 0, "/robot1/odom", &ODOMETRY);
    let cmd = TwistStamped::planar(0.3, 0.1, Time::from_nanos(5), "base_link").to_cdr();
    let odom = Odometry::planar(
        1.0,
        2.0,
        0.5,
        0.3,
        0.1,
        Time::default(),
        "odom",
        "base_link",
    )
    .to_cdr();
    let attachment = Attachment {
        sequence_number: 1,
        source_timestamp_ns: 777,
        gid: [0; 16],
    }
    .encode();
    let wrong_type = topic_key(scheme, 0, "/robot1/cmd_vel", &TWIST);
    let wrong_hash = format!("0/robot1/odom/{}/RIHS01_00", ODOMETRY.dds_name());
    // (key, payload, attachment)
    type Sample<'a> = (String, &'a [u8], Option<&'a [u8]>);
    let inputs: Vec<Sample<'_>> = vec![
        (cmd_key.clone(), &cmd, Some(&attachment)),
        (odom_key.clone(), &odom, None),
        (odom_key.clone(), &odom[..odom.len() - 3], None),
        (wrong_type, &cmd, None),
        (wrong_hash, &odom, None),
        (cmd_key.clone(), &[0xff; 8], None),
        ("0/robot2/odom/x/y".to_owned(), &odom, None),
    ];
    for (i, (key, bytes, att)) in inputs.iter().enumerate() {
        c.on_ros_sample(key, bytes, *att, 100 + i as u64, &mut sink)
            .unwrap_or_else(|e| panic!("{e}"));
    }
    let report = c.finish();
    assert_eq!(report.received, inputs.len() as u64);
    assert_eq!(report.logged, report.received);
    assert_eq!((report.ros_recorded, report.ros_refused), (2, 5));
    assert_eq!(
        sink.logged[0],
        ("/robot1/cmd_vel".to_owned(), 100, 777, cmd.clone())
    );
    assert_eq!(sink.logged[1], ("/robot1/odom".to_owned(), 101, 101, odom));
    assert_eq!(
        rejected(&report),
        [
            ("ROS: key of no recorded topic", 1),
            ("ROS: malformed CDR for the topic's type", 1),
            ("ROS: not CDR little-endian", 1),
            ("ROS: wrong message type on the key", 1),
            ("ROS: wrong type hash on the key", 1),
        ]
    );
    assert_eq!(report.logged_by_topic[REJECTED_TOPIC], 5);
    // A topic twice is refused.
    topics.push(topics[0].clone());
    assert!(Collector::with_ros2(Keys::new("f"), topics).is_err());
}

/// The report's rejection counts, by reason.
fn rejected(report: &CollectorReport) -> Vec<(&str, u64)> {
    report
        .rejected
        .iter()
        .map(|(r, n)| (r.as_str(), *n))
        .collect()
}

/// Each valid robot state, started or waiting, is shown on the 3D channels
/// once: at its position and heading, with its `e`, linked to the leader
/// point its law used; states that are rejected are not shown.
#[test]
fn each_valid_state_is_shown_at_its_pose_linked_to_its_leader_point() {
    let keys = Keys::new("f");
    let mut c = Collector::new(keys.clone());
    let mut sink = Memory::default();
    let state = |agent, link, x: f64| {
        let mut b = Vec::new();
        let s = RobotState {
            t: 1.5,
            agent,
            link,
            state: echelon::State {
                x,
                y: -2.0,
                theta: 0.7,
                v: 0.1,
                omega: 0.0,
            },
            e: [0.1, -0.2],
            leader: LeaderMotion {
                p: [3.0, 4.0],
                ..LeaderMotion::default()
            },
            ..RobotState::default()
        };
        wire::encode_state(&mut b, Header { source: 2, seq: 0 }, &s);
        b
    };
    let inputs = [
        (keys.state(1), state(1, LinkStatus::Tracking, 1.0)),
        (keys.state(2), state(2, LinkStatus::Waiting, 2.0)),
        (keys.state(2), state(1, LinkStatus::Tracking, 9.0)),
    ];
    for (key, bytes) in &inputs {
        c.on_message(key, bytes, 5, &mut sink).unwrap();
    }
    let want = |x| ScenePose {
        t: 1.5,
        p: [x, -2.0],
        theta: 0.7,
        e: [0.1, -0.2],
        leader: [3.0, 4.0],
    };
    assert_eq!(sink.poses, [(1, want(1.0)), (2, want(2.0))]);
}

/// Agent `agent`'s started state at fleet time `t`, encoded.
fn moving(agent: u32, seq: u64, t: f64, state: echelon::State) -> Vec<u8> {
    let mut b = Vec::new();
    let s = RobotState {
        t,
        agent,
        link: LinkStatus::Tracking,
        state,
        ..RobotState::default()
    };
    wire::encode_state(&mut b, Header { source: agent, seq }, &s);
    b
}

/// Two robots pass head-on at lateral offset `d` (points `L` ahead, speed
/// `v` each: closest `d` at `t* = 1 s`), publishing every `T` but out of
/// step (robot 2 half a period later), with a third robot parked far away:
/// the report names robots 1 and 2, `t*` within
/// half a period, and `d` within the matching error (0 on straight lines).
#[test]
fn two_robots_passing_give_the_closest_approach_named_and_timed() {
    use echelon::stats::Approach;

    use super::ApproachWatch;

    let keys = Keys::new("f");
    let (l, v, d, period) = (0.1, 1.0, 0.25, 0.1);
    let approach = Approach::new(vec![l; 4], 0.2, Vec::new());
    let mut c =
        Collector::new(keys.clone()).with_approach(Some(ApproachWatch::new(approach, period)));
    let mut sink = Memory::default();
    let st = |x: f64, y: f64, theta: f64, v: f64| echelon::State {
        x,
        y,
        theta,
        v,
        omega: 0.0,
    };
    // Robot 1's point: (−1 + v t, 0), heading 0; robot 2's: (1 − v t, d),
    // heading π; robot 3 parked 10 m away.
    for k in 0..=20u64 {
        let t1 = k as f64 * period;
        let t2 = t1 + period / 2.0;
        let sends = [
            (1, t1, st(-1.0 + v * t1 - l, 0.0, 0.0, v)),
            (3, t1, st(10.0, 10.0, 0.0, 0.0)),
            (2, t2, st(1.0 - v * t2 + l, d, std::f64::consts::PI, v)),
        ];
        for (agent, t, s) in sends {
            let bytes = moving(agent, k, t, s);
            c.on_message(&keys.state(agent), &bytes, k, &mut sink)
                .unwrap();
        }
    }
    let report = c.finish();
    let a = report
        .approach
        .clone()
        .expect("an approach with two robots in step");
    assert_eq!(a.min_distance_agents, [1, 2]);
    assert!(
        (a.min_distance_t - 1.0).abs() <= period / 2.0 + 1e-9,
        "t {}",
        a.min_distance_t
    );
    // On straight lines at constant speed the extrapolation is exact and
    // robot 1 publishes at t* itself: the true minimum, to rounding
    // (matching without extrapolation would give hypot(d, v·T/2) − d more,
    // 5 mm here).
    assert!(
        (a.min_distance - d).abs() <= 1e-9,
        "{} vs {d}",
        a.min_distance
    );
    assert_eq!(a.radius, 0.2);
    assert_eq!(a.min_obstacle_clearance, None);
    // The report round-trips (collector.json is read back typed).
    let json = serde_json::to_string(&report).unwrap();
    let back: CollectorReport = serde_json::from_str(&json).unwrap();
    assert_eq!(back.approach, Some(a));
}

/// A robot whose latest state is older than one period is not matched:
/// two robots that never publish within a period of each other give no
/// approach, and without `[safety]` there is none either.
#[test]
fn states_more_than_a_period_apart_are_not_matched() {
    use echelon::stats::Approach;

    use super::ApproachWatch;

    let keys = Keys::new("f");
    let approach = Approach::new(vec![0.0; 2], 0.2, Vec::new());
    let mut with =
        Collector::new(keys.clone()).with_approach(Some(ApproachWatch::new(approach, 0.1)));
    let mut without = Collector::new(keys.clone());
    let mut sink = Memory::default();
    let s = echelon::State::default();
    for k in 0..5u64 {
        let (t1, t2) = (k as f64, k as f64 + 0.5);
        for (agent, t) in [(1, t1), (2, t2)] {
            let bytes = moving(agent, k, t, s);
            with.on_message(&keys.state(agent), &bytes, k, &mut sink)
                .unwrap();
            without
                .on_message(&keys.state(agent), &bytes, k, &mut sink)
                .unwrap();
        }
    }
    assert_eq!(with.finish().approach, None);
    assert_eq!(without.finish().approach, None);
}
