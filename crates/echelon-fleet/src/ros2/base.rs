//! `echelon fleet base --ros2` as a process: [`SimBase`] (the simulated
//! base, sans-IO) as a [`BaseTask`] on the fleet runtime, declared as the
//! ROS 2 node `/robotK/echelon_base` with rmw_zenoh keys, attachments and
//! liveliness tokens.

use serde::Serialize;

use echelon::agent::Drive;
use echelon::scenario::{FixSource, Ros2Link};

use super::drive::cmd_vel_type;
use super::endpoint::declare_node;
use super::fixes::fix_type;
use super::ground_truth_topic;
use super::sim_base::{BaseCounters, SimBase};
use crate::options::{ProcessOptions, Resolved};
use crate::plant::{Plant, SimulatedDrive};
use crate::robot::{PLANT_STEP, agent_spec};
use crate::role::Member;
use crate::runtime::{self, Flow, Linger, Outputs, Sample, Task};
use crate::{FleetError, StopFlag};
use echelon_ros2::attachment::Gid;
use echelon_ros2::keys::{topic_key, topic_key_any_type};
use echelon_ros2::msgs::{
    BOOL, Bool, HAZARD_DETECTION_VECTOR, HazardDetection, HazardDetectionVector, Header,
    MessageType, ODOMETRY, RosMessage, Time,
};

use super::hazard::{Hazard, HazardWindow};

/// Options of `fleet base --ros2`.
#[derive(Debug, Clone)]
pub struct BaseOptions {
    /// The scenario (the agent's start pose, its base model and `ros2`
    /// link), clock, network and fleet name (for its echelon liveliness
    /// token); `duration` absent: run until a signal.
    pub process: ProcessOptions,
    /// Agent number, from 1.
    pub agent: u32,
    /// Its clock minus the wall clock, s: what it ages stamped `cmd_vel`
    /// by (`diff_drive_controller`'s `cmd_vel_timeout`).
    pub clock_offset: f64,
    /// Hazards it reports, on its link's `hazards` topic (an e-stop on
    /// its `estop` topic), each over its window; with those topics set it
    /// publishes them at its odometry rate, empty (or `false`) otherwise.
    pub hazards: Vec<HazardWindow>,
    /// `--fault-at S [--fault-window LEN]`: it measures its true motion
    /// from fleet time `S` on ([`crate::faults::Aftermath`]; its clock is
    /// its own, so it learns the fleet's from the leader's reference).
    pub fault_at: Option<(f64, Option<f64>)>,
}

/// What a base reports when it stops.
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BaseReport {
    /// [`crate::role::Role::Base`].
    pub role: crate::role::Role,
    /// Agent number.
    pub agent: u32,
    /// Its `cmd_vel` and `odom` topics.
    pub topics: [String; 2],
    /// What it counted.
    pub counters: BaseCounters,
    /// Final pose (world) and speeds `[x, y, θ, v, ω]`.
    pub final_state: [f64; 5],
    /// The last command it followed `[v, ω]`.
    pub last_command: [f64; 2],
    /// With `--fault-at`: what it did from the fault on (its `fault_at`
    /// in fleet time).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub aftermath: Option<crate::faults::AftermathReport>,
}

/// [`SimBase`] as a [`Task`] of the fleet runtime: `cmd_vel` in, odometry
/// out, until `duration`.
#[derive(Debug)]
pub struct BaseTask {
    base: SimBase,
    agent: u32,
    cmd_key: String,
    odom_key: String,
    /// The simulated motion capture's key, when it has one.
    fix_key: Option<String>,
    /// Its ground truth's key and publisher gid.
    truth: (String, Gid),
    alive: String,
    duration: Option<f64>,
    /// The wall clock (UNIX ns), for the stamps.
    wall: fn() -> u64,
    /// Its hazard and e-stop keys, when its link names them, and the
    /// hazards it reports.
    safety: BaseWords,
    /// With `--fault-at` or `--die-at`: the fleet's time, from its reference.
    fault: Option<FaultWatch>,
}

/// A base that acts at fleet times (its clock is its own): it measures
/// what it does after a fault (`--fault-at`), or kills itself
/// (`--die-at`).
#[derive(Debug)]
struct FaultWatch {
    /// `--fault-at`: the fault's fleet time and the measurement's window.
    at: Option<(f64, Option<f64>)>,
    /// `--die-at`, fleet time.
    die_at: Option<f64>,
    /// The fleet's reference key.
    reference: String,
    /// The fleet's time, from the first reference heard.
    fleet: crate::clock::ReferenceTime,
}

impl FaultWatch {
    /// The watch `opts` ask for (`--fault-at`, `--die-at`; none without
    /// either), on the fleet's reference from `keys`.
    fn of(opts: &BaseOptions, keys: &crate::keys::Keys) -> Option<FaultWatch> {
        (opts.fault_at.is_some() || opts.process.die_at.is_some()).then(|| FaultWatch {
            at: opts.fault_at,
            die_at: opts.process.die_at,
            reference: keys.reference(),
            fleet: crate::clock::ReferenceTime::default(),
        })
    }
}

/// What a simulated base says of its own safety (a Create 3's hazards, an
/// e-stop), at its odometry rate.
#[derive(Debug, Default)]
struct BaseWords {
    hazard_key: Option<String>,
    estop_key: Option<String>,
    windows: Vec<HazardWindow>,
    buf: Vec<u8>,
}

/// Its outputs: odometry, ground truth, then the simulated motion
/// capture's fixes.
const ODOM: usize = 0;
const TRUTH: usize = 1;
const FIXES: usize = 2;

impl Task for BaseTask {
    type Report = BaseReport;

    /// Its `cmd_vel`; with `--fault-at` or `--die-at`, also the fleet's
    /// reference.
    fn inputs(&self) -> Vec<String> {
        let mut keys = vec![self.cmd_key.clone()];
        keys.extend(self.fault.as_ref().map(|f| f.reference.clone()));
        keys
    }

    fn outputs(&self) -> Vec<String> {
        let mut keys = vec![self.odom_key.clone(), self.truth.0.clone()];
        keys.extend(self.fix_key.clone());
        keys.extend(self.safety.hazard_key.clone());
        keys.extend(self.safety.estop_key.clone());
        keys
    }

    fn tokens(&self) -> Vec<String> {
        vec![self.alive.clone()]
    }

    fn exclusive(&self) -> bool {
        true
    }

    fn on_input(&mut self, input: usize, s: &Sample<'_>) -> Result<(), FleetError> {
        if input == 1 {
            // The reference, for the fleet's time: the first sample arms
            // the measurement at the fault's time on its own clock.
            if let Some(f) = self.fault.as_mut()
                && f.fleet.offset().is_none()
                && f.fleet.hear(s.payload, s.at)
                && let (Some((at, window)), Some(offset)) = (f.at, f.fleet.offset())
            {
                self.base.measure_from(at - offset, window);
            }
            return Ok(());
        }
        // Refusals are counted in the report.
        let wall = (self.wall)() as i64;
        let _ = self.base.on_cmd(s.key, s.payload, s.attachment, s.at, wall);
        Ok(())
    }

    fn next_wake(&self) -> f64 {
        self.base.next_wake()
    }

    /// On SIGINT/SIGTERM it still follows the `cmd_vel` on its way (its
    /// robot's last, zero, command: flushed to the router before the robot
    /// exited) until none came for a while.
    fn linger(&self) -> Option<Linger> {
        Some(Linger::FLEET)
    }

    fn tick(&mut self, now: f64, out: &mut dyn Outputs) -> Result<Flow, FleetError> {
        if let Some(f) = &self.fault
            && let Some(t) = f.fleet.at(now)
        {
            crate::faults::die_if_due(f.die_at, t, "fleet base");
        }
        if self.duration.is_some_and(|d| now >= d) {
            return Ok(Flow::Stop);
        }
        let wall = (self.wall)() as i64;
        if let Some(odom) = self.base.tick(now, wall) {
            out.publish_attached(ODOM, &odom.payload, &odom.attachment)
                .map_err(|e| FleetError::Zenoh(format!("publishing odometry: {e}")))?;
            let truth = self.base.ground_truth(wall, self.truth.1);
            out.publish_attached(TRUTH, &truth.payload, &truth.attachment)
                .map_err(|e| FleetError::Zenoh(format!("publishing ground truth: {e}")))?;
            let next = FIXES + usize::from(self.fix_key.is_some());
            self.safety.publish(now, wall, next, out)?;
        }
        while let Some(fix) = self.base.take_fix(now, wall) {
            out.publish_attached(FIXES, &fix.payload, &fix.attachment)
                .map_err(|e| FleetError::Zenoh(format!("publishing a fix: {e}")))?;
        }
        Ok(Flow::Continue)
    }

    fn report(self) -> Result<BaseReport, FleetError> {
        let base = self.base;
        let s = base.base().true_state();
        let link = base.link();
        Ok(BaseReport {
            role: crate::role::Role::Base,
            agent: self.agent,
            topics: [link.cmd_vel.clone(), link.odom.clone()],
            counters: *base.counters(),
            final_state: [s.x, s.y, s.theta, s.v, s.omega],
            last_command: [base.followed().v, base.followed().omega],
            aftermath: self.fault.as_ref().and_then(|f| {
                let a = base.base().aftermath()?;
                Some(crate::faults::AftermathReport {
                    fault_at: f.at?.0,
                    ..a
                })
            }),
        })
    }
}

impl BaseWords {
    /// The hazards and e-stop `link` names topics for, reporting `windows`.
    fn of(link: &Ros2Link, windows: &[HazardWindow]) -> BaseWords {
        BaseWords {
            hazard_key: link
                .hazards
                .as_ref()
                .map(|t| topic_key(link.key_scheme, link.domain_id, t, &HAZARD_DETECTION_VECTOR)),
            estop_key: link
                .estop
                .as_ref()
                .map(|t| topic_key(link.key_scheme, link.domain_id, t, &BOOL)),
            windows: windows.to_vec(),
            buf: Vec::with_capacity(128),
        }
    }

    /// Publishes its hazard vector (the windows covering `now`) and e-stop
    /// on outputs from `first` on.
    fn publish(
        &mut self,
        now: f64,
        wall: i64,
        first: usize,
        out: &mut dyn Outputs,
    ) -> Result<(), FleetError> {
        let stamp = Time::from_nanos(wall);
        let header = |frame: &str| Header {
            stamp,
            frame_id: frame.to_owned(),
        };
        let mut output = first;
        if self.hazard_key.is_some() {
            let detections = self
                .windows
                .iter()
                .filter(|w| w.covers(now) && w.hazard != Hazard::EmergencyStop)
                .filter_map(|w| {
                    let ty = (0..=5u8).find(|&t| Hazard::of_create3(t) == Some(w.hazard))?;
                    Some(HazardDetection {
                        header: header("bump_front_center"),
                        r#type: ty,
                    })
                })
                .collect();
            HazardDetectionVector {
                header: header("base_link"),
                detections,
            }
            .encode_into(&mut self.buf);
            out.publish(output, &self.buf)
                .map_err(|e| FleetError::Zenoh(format!("publishing hazards: {e}")))?;
            output += 1;
        }
        if self.estop_key.is_some() {
            let data = self
                .windows
                .iter()
                .any(|w| w.covers(now) && w.hazard == Hazard::EmergencyStop);
            Bool { data }.encode_into(&mut self.buf);
            out.publish(output, &self.buf)
                .map_err(|e| FleetError::Zenoh(format!("publishing the e-stop: {e}")))?;
        }
        Ok(())
    }
}

/// Runs a simulated ROS 2 base until `duration` or the stop flag:
/// [`BaseTask`] on the fleet runtime, declared as a ROS 2 node.
pub fn run(opts: BaseOptions, stop: &StopFlag) -> Result<BaseReport, FleetError> {
    let Resolved {
        plan,
        settings,
        keys,
    } = opts.process.resolve()?;
    let spec = agent_spec(&plan, opts.agent)?;
    let Drive::Velocity(_) = spec.drive() else {
        return Err(FleetError::Config(format!(
            "agent {}: a ROS 2 base is a velocity base (set drive = \"velocity\" on its robot)",
            opts.agent
        )));
    };
    let link = settings.ros2[opts.agent as usize - 1].clone();
    // The agent's `[odometry]`: its wheel odometry lies as the simulator's.
    let odometry = plan.odometer(opts.agent as usize - 1).cloned();
    let seed = plan.seed();
    // A simulated motion capture when the agent takes fixes from ROS 2.
    let mocap = match (
        &link.fixes,
        odometry.as_ref().and_then(|o| o.spec().fixes()),
    ) {
        (Some(source), Some(spec)) => {
            let period = spec.interval(odometry.as_ref().map_or(0.0, |o| o.spec().period()));
            Some((source.clone(), spec, period))
        }
        _ => None,
    };
    let alive = keys.alive(&Member::Base(opts.agent).liveliness());
    runtime::run_on(
        |session| {
            let truth_topic = ground_truth_topic(&link);
            let publishes = publishes(
                &link,
                &truth_topic,
                mocap.as_ref().map(|(source, ..)| source),
            );
            let (tokens, gids) = declare_node(
                session,
                &link,
                "echelon_base",
                &publishes,
                &[(&link.cmd_vel, cmd_vel_type(&link))],
                |e| FleetError::Config(e.to_string()),
            )?;
            let model = SimulatedDrive::of(&spec, 0.0, PLANT_STEP);
            let mut base =
                SimBase::new(link.clone(), model, gids[0]).with_clock_offset(opts.clock_offset);
            if let Some((source, spec, period)) = &mocap {
                // Its own random stream: the odometry's are the agents'.
                let stream = seed ^ (0x6d6f_6361_7000_0000 | u64::from(opts.agent));
                base = base.with_mocap(
                    source.clone(),
                    spec,
                    *period,
                    gids[2],
                    stream,
                    opts.process.time_scale,
                );
            }
            if let Some(odometry) = &odometry {
                base = base.with_odometry(
                    odometry.spec(),
                    spec.drive().wheels(),
                    seed,
                    u64::from(opts.agent - 1),
                    0.0,
                )?;
            }
            let task = BaseTask {
                base,
                agent: opts.agent,
                cmd_key: topic_key_any_type(link.key_scheme, link.domain_id, &link.cmd_vel),
                odom_key: topic_key(link.key_scheme, link.domain_id, &link.odom, &ODOMETRY),
                truth: (
                    topic_key(link.key_scheme, link.domain_id, &truth_topic, &ODOMETRY),
                    gids[1],
                ),
                fix_key: mocap.as_ref().map(|(source, ..)| {
                    topic_key(
                        link.key_scheme,
                        link.domain_id,
                        &source.topic,
                        fix_type(source.message),
                    )
                }),
                alive,
                duration: opts.process.duration,
                wall: crate::unix_nanos,
                safety: BaseWords::of(&link, &opts.hazards),
                fault: FaultWatch::of(&opts, &keys),
            };
            Ok((task, tokens))
        },
        &opts.process.net,
        opts.process.clock(),
        stop,
    )?
    .report()
}

/// The topics the base publishes, each with its type: its odometry, its
/// ground truth (on `truth_topic`), its motion capture's fixes (`mocap`),
/// hazards and e-stop, as `link` names them.
fn publishes<'a>(
    link: &'a Ros2Link,
    truth_topic: &'a str,
    mocap: Option<&'a FixSource>,
) -> Vec<(&'a str, &'static MessageType)> {
    let mut publishes = vec![(link.odom.as_str(), &ODOMETRY), (truth_topic, &ODOMETRY)];
    if let Some(source) = mocap {
        publishes.push((source.topic.as_str(), fix_type(source.message)));
    }
    if let Some(t) = &link.hazards {
        publishes.push((t.as_str(), &HAZARD_DETECTION_VECTOR));
    }
    if let Some(t) = &link.estop {
        publishes.push((t.as_str(), &BOOL));
    }
    publishes
}
