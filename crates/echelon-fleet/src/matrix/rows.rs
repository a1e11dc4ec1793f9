//! The matrix's rows: each fault, what the robots do about it, the bound
//! its policy implies ([`Row::bound`]) and the fleet it runs on
//! ([`Row::scenario_toml`]).

use serde::Serialize;

use crate::faults::Chaos;
use crate::robot::Watchdog;
use crate::role::Member;

use super::{
    A_MAX, CMD_VEL_TIMEOUT, CONTROL_RATE, DECEL, FAULT_AT, HEARTBEAT, HOLD, HOP_DELIVERY,
    LINK_TIMEOUT, ODOM_RATE, REFERENCE_RATE, SPACING, TAIL, TAU_V, WINDOW,
};

/// What a row expects its affected robots to do.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Outcome {
    /// Come to rest and stay there (until the run ends).
    Stop,
    /// Come to rest while the fault lasts, then follow again.
    Hold,
    /// Keep following (the fault is shorter than its detection).
    Continue,
    /// Follow on as if nothing happened: what arrives is counted and
    /// refused (no travel bound: the robots never stop).
    Unaffected,
}

/// How a row's robots brake once they notice.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Brake {
    /// A zero command (or the law toward a point at rest) on the base:
    /// `v²/2a`.
    Zero,
    /// `extrapolate`: the last speed for `hold`, then the smooth stop.
    Extrapolate,
}

/// One row of the matrix.
#[derive(Debug, Clone)]
pub struct Row {
    /// Its name (its directory).
    pub name: &'static str,
    /// The fault, in words.
    pub fault: &'static str,
    /// What the robots do about it, in words.
    pub action: &'static str,
    /// What it expects.
    pub outcome: Outcome,
    /// The agents the bound applies to, each with its depth: how many
    /// robots of its chain notice the fault before it does (0: it notices
    /// it itself).
    pub affected: Vec<(u32, u32)>,
    /// `[fleet] link_loss.policy`.
    pub(super) policy: &'static str,
    /// A supervised run (`[fleet] operator_heartbeat`).
    pub(super) supervised: bool,
    /// The robots drive simulated ROS 2 bases (`fleet up --ros2`): what a
    /// robot did is measured by its base.
    pub(super) ros2: bool,
    /// Robots a watchdog must have held, and which (its report's count).
    pub(super) held_by: Vec<(u32, Watchdog)>,
    /// Detection time, s (before one control period is added).
    pub(super) detect: f64,
    pub(super) brake: Brake,
    pub(super) chaos: Chaos,
    /// Fleet seconds measured after the fault.
    pub(super) window: f64,
    /// Fleet seconds it runs after the window (to follow again).
    pub(super) tail: f64,
}

/// A row under policy `stop` on simulated robots, unsupervised, braking
/// with a zero command, measured for `window` s after the fault and run
/// [`TAIL`] s more; each row states what differs.
#[allow(clippy::too_many_arguments)]
fn row(
    name: &'static str,
    fault: &'static str,
    action: &'static str,
    outcome: Outcome,
    affected: Vec<(u32, u32)>,
    detect: f64,
    chaos: Chaos,
    window: f64,
) -> Row {
    Row {
        name,
        fault,
        action,
        outcome,
        affected,
        policy: "stop",
        supervised: false,
        ros2: false,
        held_by: Vec::new(),
        detect,
        brake: Brake::Zero,
        chaos,
        window,
        tail: TAIL,
    }
}

/// The matrix's rows, in order.
pub fn rows() -> Vec<Row> {
    let mut rows = kill_rows();
    rows.extend(unaffected_rows());
    rows.extend(clock_rows());
    rows.extend(partition_rows());
    rows.extend(watchdog_rows());
    rows
}

/// Chaos killing `m`'s process (`kill -9`) at the fault.
fn kill(m: Member) -> Chaos {
    Chaos {
        kills: vec![(m, FAULT_AT)],
        ..Chaos::default()
    }
}

/// The column's robots affected down their chain: robot 1 notices first.
fn chain() -> Vec<(u32, u32)> {
    vec![(1, 0), (2, 1), (3, 2)]
}

/// The column's robots affected each by itself: each notices by itself.
fn each() -> Vec<(u32, u32)> {
    vec![(1, 0), (2, 0), (3, 0)]
}

/// The time a robot needs to notice its leader's stream went stale, s.
fn link_lost() -> f64 {
    LINK_TIMEOUT + 1.0 / REFERENCE_RATE
}

/// The rows that kill a process (the leader, a robot, a base, the router)
/// and expect the robots affected to stop, or hold until it is back.
fn kill_rows() -> Vec<Row> {
    vec![
        row(
            "leader-kill-stop",
            "the leader killed (`kill -9`), link_loss `stop`",
            "the link times out; each robot converges to its slot behind the last reference received, at rest",
            Outcome::Stop,
            chain(),
            link_lost(),
            kill(Member::Leader),
            WINDOW,
        ),
        Row {
            policy: "extrapolate",
            brake: Brake::Extrapolate,
            ..row(
                "leader-kill-extrapolate",
                "the leader killed (`kill -9`), link_loss `extrapolate` (hold 1 s, decel 0.1 m/s²)",
                "the reference is carried on its arc for the hold, then slowed to rest",
                Outcome::Stop,
                chain(),
                1.0 / REFERENCE_RATE,
                kill(Member::Leader),
                WINDOW,
            )
        },
        row(
            "robot-kill",
            "robot 1's process killed (`kill -9`); its simulated base dies with it",
            "robots 2 and 3 lose their leader (robot 1's state): link-loss policy `stop`",
            Outcome::Stop,
            vec![(2, 0), (3, 1)],
            LINK_TIMEOUT + 1.0 / CONTROL_RATE,
            kill(Member::Robot(1)),
            WINDOW,
        ),
        Row {
            ros2: true,
            ..row(
                "robot-kill-ros2",
                "robot 1's process killed (`kill -9`) while it drives a simulated ROS 2 base (`cmd_vel_timeout` 0.5 s, as a Create 3)",
                "robot 1's base stops on its own `cmd_vel` timeout, 0.5 s after the last command (robots 2 and 3 lose their leader, as in `robot-kill`)",
                Outcome::Stop,
                vec![(1, 0)],
                // The base checks its timeout at its odometry rate.
                CMD_VEL_TIMEOUT + 1.0 / ODOM_RATE,
                kill(Member::Robot(1)),
                WINDOW,
            )
        },
        Row {
            ros2: true,
            held_by: vec![(1, Watchdog::Odometry)],
            ..row(
                "base-kill-ros2",
                "robot 1's simulated ROS 2 base killed (`kill -9`): no odometry, no `cmd_vel` reader",
                "robot 1's odometry watchdog holds it (zero command, link `held`, reported) once its odometry is `odom_timeout` old (its output watchdog cannot tell here: the collector, recording `cmd_vel`, is a reader too); robots 2 and 3 do not follow a held leader: link-loss policy `stop`",
                Outcome::Stop,
                vec![(2, 0), (3, 1)],
                echelon::scenario::DEFAULT_ODOM_TIMEOUT
                    + 1.0 / ODOM_RATE
                    + 1.0 / CONTROL_RATE
                    + LINK_TIMEOUT,
                kill(Member::Base(1)),
                WINDOW,
            )
        },
        Row {
            // Zenoh clients retry their router with a growing back-off.
            tail: 10.0,
            ..row(
                "router-restart",
                "the router killed (`kill -9`) and started again on its port 2 s later",
                "every process loses its link at once: each robot's leader stream goes stale (link-loss policy `stop`); the clients reconnect to the router when it is back and the robots follow again",
                Outcome::Hold,
                each(),
                link_lost(),
                Chaos {
                    router_restart: Some((FAULT_AT, 2.0)),
                    ..Chaos::default()
                },
                2.0,
            )
        },
    ]
}

/// The rows whose fault the robots must shrug off: garbage, the collector
/// killed, a second fleet.
fn unaffected_rows() -> Vec<Row> {
    vec![
        row(
            "garbage",
            "garbage, duplicated and replayed (1 s old) messages on every key of the fleet, 20 times a second for 5 s",
            "every robot counts and refuses what is not a newer sample of its streams (malformed, reordered) and follows on",
            Outcome::Unaffected,
            each(),
            0.0,
            Chaos {
                garbage: Some((FAULT_AT, 5.0)),
                ..Chaos::default()
            },
            5.0,
        ),
        row(
            "collector-kill",
            "the collector killed (`kill -9`)",
            "the robots do not depend on it and follow on; its log ends at the fault (`trajectory.csv` up to there, `fleet.mcap` without its footer) and `fleet up` reports the gap (`log_gap`)",
            Outcome::Unaffected,
            each(),
            0.0,
            kill(Member::Collector),
            5.0,
        ),
        row(
            "second-fleet",
            "a second leader and a second robot 2 of the same fleet name join the router mid-run (what a second `fleet up` reaching this router would start)",
            "each is refused before it publishes anything (the fleet's leader and robot 2 already hold their liveliness tokens: exit 2, naming them); the running fleet is undisturbed",
            Outcome::Unaffected,
            each(),
            0.0,
            Chaos {
                intruders: Some(FAULT_AT),
                ..Chaos::default()
            },
            5.0,
        ),
    ]
}

/// The rows stepping robot 2's wall clock, forward and back.
fn clock_rows() -> Vec<Row> {
    let mut rows = Vec::new();
    for (name, fault, step) in [
        (
            "clock-jump-forward",
            "robot 2's wall clock stepped forward by 1 s (an NTP step)",
            1.0,
        ),
        (
            "clock-jump-back",
            "robot 2's wall clock stepped back by 1 s (an NTP step)",
            -1.0,
        ),
    ] {
        rows.push(row(
            name,
            fault,
            "fleet time is the leader's on a monotonic clock: control never reads the wall clock; only robot 2's latency statistics (delays against its wall clock) see the step",
            Outcome::Unaffected,
            each(),
            0.0,
            Chaos {
                wall_clock_jumps: vec![(2, (FAULT_AT, step))],
                ..Chaos::default()
            },
            5.0,
        ));
    }
    rows
}

/// The rows partitioning robot 1 from the fleet, shorter and longer than
/// its link timeout.
fn partition_rows() -> Vec<Row> {
    let mut rows = Vec::new();
    for (name, fault, len, outcome) in [
        (
            "partition-0.3s",
            "robot 1 partitioned from the fleet for 0.3 s (nothing in or out but the fleet's stop and heartbeat keys)",
            0.3,
            Outcome::Continue,
        ),
        (
            "partition-3s",
            "robot 1 partitioned from the fleet for 3 s",
            3.0,
            Outcome::Hold,
        ),
        (
            "partition-30s",
            "robot 1 partitioned from the fleet for 30 s",
            30.0,
            Outcome::Hold,
        ),
    ] {
        rows.push(row(
            name,
            fault,
            "after the link timeout robot 1 converges to the last reference and robot 2, which hears no more of robot 1, to its slot behind robot 1's last state (policy `stop`); robot 3 follows robot 2; all follow again when the partition ends",
            outcome,
            vec![(1, 0), (2, 0), (3, 1)],
            link_lost(),
            Chaos {
                partitions: vec![(1, (FAULT_AT, len))],
                ..Chaos::default()
            },
            len,
        ));
    }
    rows
}

/// The rows a watchdog must hold: odometry frozen, the operator's
/// heartbeat lost.
fn watchdog_rows() -> Vec<Row> {
    vec![
        Row {
            held_by: vec![(2, Watchdog::Odometry)],
            ..row(
                "odometry-freeze",
                "robot 2's odometry frozen for 3 s (the robot moves on)",
                "robot 2's odometry watchdog holds it (zero command, link `held`) after two control periods; robot 3 stops following a held leader (its link-loss policy)",
                Outcome::Hold,
                vec![(2, 0)],
                2.0 / CONTROL_RATE,
                Chaos {
                    freeze_odometry: vec![(2, (FAULT_AT, 3.0))],
                    ..Chaos::default()
                },
                3.0,
            )
        },
        Row {
            supervised: true,
            held_by: vec![
                (1, Watchdog::Operator),
                (2, Watchdog::Operator),
                (3, Watchdog::Operator),
            ],
            ..row(
                "heartbeat-lost",
                "supervised run (operator_heartbeat = 1 s): the operator's heartbeat process killed (`kill -9`)",
                "every robot's operator watchdog holds it (zero command, link `held`) once the last heartbeat is 1 s old",
                Outcome::Stop,
                each(),
                HEARTBEAT,
                kill(Member::Operator),
                WINDOW,
            )
        },
    ]
}

impl Row {
    /// The bound on the farthest a robot moving at `v`, `depth` robots
    /// down its chain from the first to notice, gets from where the fault
    /// found it, m: its detection comes at its first tick after the fault's
    /// timeout, one control period on, or `slowest_tick` s on when its
    /// ticks came further apart than that (a loaded machine; measured,
    /// [`crate::faults::AftermathReport::slowest_tick`]); each robot ahead
    /// adds a control period and a state's delivery.
    pub fn bound(&self, v: f64, depth: u32, slowest_tick: f64) -> f64 {
        let detect = self.detect
            + slowest_tick.max(1.0 / CONTROL_RATE)
            + f64::from(depth) * (1.0 / CONTROL_RATE + HOP_DELIVERY);
        let brake = match self.brake {
            Brake::Zero => v * v / (2.0 * A_MAX),
            Brake::Extrapolate => v * HOLD + std::f64::consts::PI * v * v / (4.0 * DECEL),
        };
        v * detect + v * TAU_V + brake
    }

    /// Its detection time, s (with the control period).
    pub fn t_detect(&self) -> f64 {
        self.detect + 1.0 / CONTROL_RATE
    }

    /// Fleet seconds it runs.
    pub(super) fn duration(&self) -> f64 {
        FAULT_AT + self.window.max(1.0) + self.tail
    }

    /// Its scenario.
    pub fn scenario_toml(&self) -> String {
        let heartbeat = match self.supervised {
            true => format!("operator_heartbeat = {HEARTBEAT}\n"),
            false => String::new(),
        };
        format!(
            r#"# The fault matrix's fleet (`echelon fleet faults`, row {name}).
name = "faults-{name}"
description = "Three TurtleBot 4s in a column at 0.15 m/s: {name}"

[sim]
duration = {duration}
dt = 0.001

[log]
dt = 0.01

[control]
law = "kinematic"
ke = 1.0
l = 0.05
ly_derivatives = "neglect"

[robots.tb4]
preset = "turtlebot4"

[reference.circle]
speed = 0.15
turn_rate = 0.05
start = {{ x = 0.0, y = 0.0, theta_deg = 0.0 }}

[fleet]
name = "faults-{name}"
reference_rate = {REFERENCE_RATE}
control_rate = {CONTROL_RATE}
link_timeout = {LINK_TIMEOUT}
{heartbeat}
[fleet.link_loss]
policy = "{policy}"
hold = {HOLD}
decel = {DECEL}
{agents}"#,
            name = self.name,
            duration = self.duration(),
            policy = self.policy,
            agents = column(),
        )
    }
}

/// The column's agents: robot 1 [`SPACING`] behind the reference, each
/// next one `SPACING` behind the one before, every one on its slot.
fn column() -> String {
    (1..=3u32)
        .map(|k| {
            let leader = match k {
                1 => "\"reference\"".to_owned(),
                k => (k - 1).to_string(),
            };
            format!(
                "\n[[agents]]\nname = \"tb4 {k}\"\nrobot = \"tb4\"\nstart = {{ x = {:.1}, y = 0.0, theta_deg = 0.0 }}\nleader = {leader}\noffset = {{ x = {SPACING}, y = 0.0 }}\n",
                -SPACING * f64::from(k)
            )
        })
        .collect()
}
