//! MCAP logs as identification input ([`echelon::identify::Log`]) for
//! `echelon identify`.
//!
//! Two kinds of MCAP are read:
//!
//! - **ROS 2 channels** (a rosbag2 MCAP bag, `fleet excite`'s bag or the ROS
//!   2 channels of a `fleet.mcap` recorded with `--ros2`): a command channel
//!   of `geometry_msgs/msg/TwistStamped` or `geometry_msgs/msg/Twist` and an
//!   odometry channel of `nav_msgs/msg/Odometry`, both CDR. They give a
//!   velocity-base log: the command `(twist.linear.x, twist.angular.z)`
//!   against the measured body twist of the odometry.
//! - **echelon's JSON channels** (`echelon run --mcap`'s `run.mcap`, the
//!   fleet collector's `fleet.mcap`): `/agent/K/state` records carry `t, v,
//!   ω, u1, u2, τr, τl`, a torque-model log exactly like the run's
//!   `trajectory.csv` rows.
//!
//! ## Times and resampling (ROS 2 channels)
//!
//! Both series are put on one clock: the header stamps when the command is
//! a `TwistStamped` (a stamp of zero falls back to the log time), the
//! recorder's log times when it is a plain `Twist` (it has no stamp, and a
//! command's log time and an odometry's stamp may come from different
//! clocks). The sample grid is the odometry's times (the measurements are
//! kept as measured, so their noise stays white); the command is a
//! zero-order hold of the command messages (each holds until the next), and
//! the input of grid interval `[t_i, t_{i+1})` — which [`identify`] holds over
//! it — is that hold's *time average* over the interval. A command that
//! arrives inside an interval then counts for the part of the interval it
//! acted, instead of being moved to either end (half an odometry period of
//! timing error, a bias of that size on the lags). The command messages
//! themselves are kept too ([`echelon::identify::Log::hold`]): the
//! output-error fit integrates the lag exactly through each command change,
//! so the average only serves the first guess. The log keeps the odometry
//! from the first command on, up to the last command, or to the end when the
//! last command is a stop (a zero command holds however long it lasts; any
//! other would run into the base's `cmd_vel_timeout`).
//!
//! [`identify`]: echelon::identify::identify

use std::collections::BTreeMap;
use std::path::Path;

use echelon::identify::{IdentifyError, Log, Model};

use crate::{CDR, agent_topic};
use echelon_ros2::msgs::{
    ODOMETRY, Odometry, RosMessage, TWIST, TWIST_STAMPED, Twist, TwistStamped,
};

/// Which series to read from an MCAP.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct BagOptions {
    /// The agent, from 1 (its `/agent/K/state` channel for the torque model).
    pub agent: usize,
    /// The model asked for (`None`: velocity if the file has a command and
    /// an odometry channel, else torque from `/agent/K/state`).
    pub model: Option<Model>,
    /// The command topic (needed when the file has several).
    pub cmd_vel: Option<String>,
    /// The odometry topic (needed when the file has several).
    pub odom: Option<String>,
}

/// One timed planar velocity: `(ns, v, ω)`.
type Sample = (u64, f64, f64);

/// The ROS 2 series of one channel.
#[derive(Debug, Default)]
struct Series {
    /// Header stamps (0 if none).
    stamped: Vec<Sample>,
    /// Log times.
    logged: Vec<Sample>,
    /// The message type.
    ty: &'static str,
}

/// What an MCAP file holds that identification can use.
#[derive(Debug, Default)]
struct Contents {
    cmd: BTreeMap<String, Series>,
    odom: BTreeMap<String, Series>,
    /// `/agent/K/state` records of the chosen agent.
    states: Vec<serde_json::Value>,
    topics: Vec<String>,
}

/// Reads `path` (an MCAP file) into a [`Log`] of `opts.agent`.
///
/// Errors (each naming the file): unreadable, not MCAP, a message that does
/// not decode, or missing channels: no command or odometry channel for the
/// velocity model, no `/agent/K/state` for the torque model, several
/// candidates and no `--cmd-vel` / `--odom` to choose.
pub fn read_log(path: &Path, opts: &BagOptions) -> Result<Log, IdentifyError> {
    let origin = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|e| IdentifyError::Read {
        file: origin.clone(),
        reason: format!("cannot read: {e}"),
    })?;
    parse_log(&bytes, &origin, opts)
}

/// [`read_log`] of the bytes of an MCAP file named `origin`.
pub fn parse_log(bytes: &[u8], origin: &str, opts: &BagOptions) -> Result<Log, IdentifyError> {
    let read_err = |reason: String| IdentifyError::Read {
        file: origin.to_owned(),
        reason,
    };
    let contents = scan(bytes, opts.agent).map_err(read_err)?;
    let missing = |what: String| IdentifyError::MissingTopics {
        file: origin.to_owned(),
        what,
        present: if contents.topics.is_empty() {
            "none".to_owned()
        } else {
            contents.topics.join(", ")
        },
    };
    let has_ros = !contents.cmd.is_empty() || !contents.odom.is_empty();
    let model = match opts.model {
        Some(m) => m,
        None if has_ros => Model::Velocity,
        None if !contents.states.is_empty() => Model::Torque,
        None => {
            return Err(missing(format!(
                "a ROS 2 cmd_vel channel ({} or {}) with a {} channel (velocity base), or /agent/{}/state (torque model)",
                TWIST_STAMPED.name, TWIST.name, ODOMETRY.name, opts.agent
            )));
        }
    };
    match model {
        Model::Velocity => {
            let cmd =
                pick(&contents.cmd, opts.cmd_vel.as_deref(), Kind::Command).map_err(&missing)?;
            let odom =
                pick(&contents.odom, opts.odom.as_deref(), Kind::Odometry).map_err(&missing)?;
            let stamped = cmd.ty == TWIST_STAMPED.name;
            let series = |s: &Series| {
                if stamped {
                    s.stamped.clone()
                } else {
                    s.logged.clone()
                }
            };
            velocity_log(&series(cmd), &series(odom), origin, opts.agent).map_err(read_err)
        }
        Model::Torque => {
            if contents.states.is_empty() {
                return Err(missing(format!(
                    "/agent/{}/state (the torque model reads u1, u2 from echelon's agent states)",
                    opts.agent
                )));
            }
            Ok(torque_log(&contents.states, origin, opts.agent))
        }
    }
}

/// A channel [`pick`] chooses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Command,
    Odometry,
}

/// The channel of `map` named `wanted`, or its only one.
fn pick<'a>(
    map: &'a BTreeMap<String, Series>,
    wanted: Option<&str>,
    kind: Kind,
) -> Result<&'a Series, String> {
    let names = || map.keys().cloned().collect::<Vec<_>>().join(", ");
    let (what, a, flag, types) = match kind {
        Kind::Command => (
            "command",
            "a",
            "--cmd-vel",
            format!("{} or {}", TWIST_STAMPED.name, TWIST.name),
        ),
        Kind::Odometry => ("odometry", "an", "--odom", ODOMETRY.name.to_owned()),
    };
    match wanted {
        Some(topic) => map.get(topic).ok_or_else(|| {
            format!(
                "{what} topic {topic} ({flag}) of type {types}; {what} channels: {}",
                if map.is_empty() {
                    "none".to_owned()
                } else {
                    names()
                }
            )
        }),
        None => match map.len() {
            0 => Err(format!("{a} {what} channel of type {types}")),
            1 => map.values().next().ok_or_else(String::new),
            _ => Err(format!(
                "a choice between {what} channels {}: name one with {flag}",
                names()
            )),
        },
    }
}

/// Reads every message: ROS 2 command and odometry channels decoded, the
/// agent's JSON states kept.
fn scan(bytes: &[u8], agent: usize) -> Result<Contents, String> {
    let mut c = Contents::default();
    let state_topic = agent_topic(agent);
    let stream =
        mcap::MessageStream::new(bytes).map_err(|e| format!("not a readable MCAP file: {e}"))?;
    for m in stream {
        let m = m.map_err(|e| format!("not a readable MCAP file: {e}"))?;
        let ch = &m.channel;
        if !c.topics.contains(&ch.topic) {
            c.topics.push(ch.topic.clone());
        }
        let schema = ch.schema.as_ref().map(|s| s.name.as_str()).unwrap_or("");
        let bad = |ty: &str, e: &dyn std::fmt::Display| {
            format!(
                "{}: message at log time {} ns is not a valid {ty}: {e}",
                ch.topic, m.log_time
            )
        };
        if ch.message_encoding == CDR {
            let (map, sample, ty) = if schema == TWIST_STAMPED.name {
                let msg = TwistStamped::from_cdr(&m.data).map_err(|e| bad(schema, &e))?;
                let t = &msg.twist;
                (
                    &mut c.cmd,
                    (msg.header.stamp.to_nanos(), t.linear.x, t.angular.z),
                    TWIST_STAMPED.name,
                )
            } else if schema == TWIST.name {
                let t = Twist::from_cdr(&m.data).map_err(|e| bad(schema, &e))?;
                (&mut c.cmd, (0, t.linear.x, t.angular.z), TWIST.name)
            } else if schema == ODOMETRY.name {
                let msg = Odometry::from_cdr(&m.data).map_err(|e| bad(schema, &e))?;
                let t = &msg.twist.twist;
                (
                    &mut c.odom,
                    (msg.header.stamp.to_nanos(), t.linear.x, t.angular.z),
                    ODOMETRY.name,
                )
            } else {
                continue;
            };
            let s = map.entry(ch.topic.clone()).or_default();
            s.ty = ty;
            let stamp = u64::try_from(sample.0).unwrap_or(0);
            let stamp = if stamp == 0 { m.log_time } else { stamp };
            s.stamped.push((stamp, sample.1, sample.2));
            s.logged.push((m.log_time, sample.1, sample.2));
        } else if ch.message_encoding == "json" && ch.topic == state_topic {
            let v: serde_json::Value =
                serde_json::from_slice(&m.data).map_err(|e| bad("JSON agent state", &e))?;
            c.states.push(v);
        }
    }
    Ok(c)
}

/// Sorts by time and keeps the last of equal times.
fn sorted(mut s: Vec<Sample>) -> Vec<Sample> {
    s.sort_by_key(|x| x.0);
    let mut out: Vec<Sample> = Vec::with_capacity(s.len());
    for x in s {
        match out.last_mut() {
            Some(last) if last.0 == x.0 => *last = x,
            _ => out.push(x),
        }
    }
    out
}

/// The velocity-base log: odometry times as the grid, the command's
/// zero-order hold averaged over each grid interval (module docs).
fn velocity_log(
    cmd: &[Sample],
    odom: &[Sample],
    origin: &str,
    agent: usize,
) -> Result<Log, String> {
    let cmd = sorted(cmd.to_vec());
    let odom = sorted(odom.to_vec());
    let (Some(first), Some(last)) = (cmd.first(), cmd.last()) else {
        return Err("the command channel has no messages".to_owned());
    };
    let stop_last = last.1 == 0.0 && last.2 == 0.0;
    let grid: Vec<Sample> = odom
        .into_iter()
        .filter(|o| o.0 >= first.0 && (stop_last || o.0 <= last.0))
        .collect();
    let Some(t0) = grid.first().map(|o| o.0) else {
        return Err(format!(
            "no odometry between the first and the last command ({} commands)",
            cmd.len()
        ));
    };
    let sec = |ns: u64| (ns - t0) as f64 * 1e-9;
    let mut log = Log {
        source: origin.to_owned(),
        agent,
        ..Log::default()
    };
    let mut u: [Vec<f64>; 2] = Default::default();
    for (i, o) in grid.iter().enumerate() {
        log.t.push(sec(o.0));
        log.v.push(o.1);
        log.omega.push(o.2);
        let held = match grid.get(i + 1) {
            Some(next) => hold_average(&cmd, o.0, next.0),
            None => held_at(&cmd, o.0),
        };
        u[0].push(held[0]);
        u[1].push(held[1]);
    }
    log.cmd = Some(u);
    // The hold itself, from the command in force at the first sample on:
    // the fit integrates the lag exactly through each command change.
    let from = last_at(&cmd, t0);
    let mut hold = echelon::identify::Hold::default();
    for c in &cmd[from..] {
        hold.t
            .push((i128::from(c.0) - i128::from(t0)) as f64 * 1e-9);
        hold.u[0].push(c.1);
        hold.u[1].push(c.2);
    }
    log.hold = Some(hold);
    Ok(log)
}

/// The index of the last command at or before `t` (commands start at or
/// before every grid time).
fn last_at(cmd: &[Sample], t: u64) -> usize {
    cmd.partition_point(|c| c.0 <= t).saturating_sub(1)
}

/// The held command at `t`.
fn held_at(cmd: &[Sample], t: u64) -> [f64; 2] {
    let c = cmd[last_at(cmd, t)];
    [c.1, c.2]
}

/// The time average over `[a, b)` of the command held from each message to
/// the next.
fn hold_average(cmd: &[Sample], a: u64, b: u64) -> [f64; 2] {
    let mut j = last_at(cmd, a);
    let mut from = a;
    let mut acc = [0.0; 2];
    while from < b {
        let to = cmd.get(j + 1).map_or(b, |n| n.0.min(b));
        let w = (to - from) as f64;
        acc[0] += w * cmd[j].1;
        acc[1] += w * cmd[j].2;
        from = to;
        j += 1;
    }
    let span = (b - a) as f64;
    [acc[0] / span, acc[1] / span]
}

/// The torque-model log from `/agent/K/state` records (null fields, as NaN
/// is written in JSON, read back as NaN).
fn torque_log(states: &[serde_json::Value], origin: &str, agent: usize) -> Log {
    let mut rows: Vec<[f64; 7]> = states
        .iter()
        // A fleet robot waiting for its leader publishes its state at t = 0
        // with its clock stopped, over and over (`"link": "waiting"`): not
        // samples of a run (the collector's trajectory.csv leaves them out
        // too), and their repeated time refused the whole log.
        .filter(|s| s.get("link").and_then(serde_json::Value::as_str) != Some("waiting"))
        .map(|s| {
            let f = |k: &str| {
                s.get(k)
                    .and_then(serde_json::Value::as_f64)
                    .unwrap_or(f64::NAN)
            };
            [
                f("t"),
                f("v"),
                f("omega"),
                f("u1"),
                f("u2"),
                f("tau_r"),
                f("tau_l"),
            ]
        })
        .collect();
    rows.sort_by(|a, b| a[0].total_cmp(&b[0]));
    let col = |i: usize| rows.iter().map(|r| r[i]).collect::<Vec<f64>>();
    let present = |c: &[f64]| !c.iter().all(|x| x.is_nan());
    let (u1, u2, tr, tl) = (col(3), col(4), col(5), col(6));
    Log {
        source: origin.to_owned(),
        agent,
        t: col(0),
        v: col(1),
        omega: col(2),
        u: present(&u1).then_some([u1, u2]),
        tau: present(&tr).then_some([tr, tl]),
        ..Log::default()
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use crate::{McapLog, Ros2Schema, nanos};
    use echelon_ros2::definitions::definition;
    use echelon_ros2::msgs::{MessageType, Time};

    fn schema(ty: &MessageType) -> Ros2Schema {
        Ros2Schema {
            name: ty.name,
            definition: definition(ty).unwrap(),
            type_hash: ty.hash,
        }
    }

    /// A bag: TwistStamped commands at `cmds` (s, v, ω), odometry at `odom`.
    fn bag(cmds: &[(f64, f64, f64)], odom: &[(f64, f64, f64)]) -> Vec<u8> {
        let mut log = McapLog::new(std::io::Cursor::new(Vec::new())).unwrap();
        let c = log
            .ros2_channel("/r/cmd_vel", &schema(&TWIST_STAMPED), "[]")
            .unwrap();
        let o = log
            .ros2_channel("/r/odom", &schema(&ODOMETRY), "[]")
            .unwrap();
        let ns = |t: f64| (t * 1e9).round() as i64;
        for &(t, v, w) in cmds {
            let m = TwistStamped::planar(v, w, Time::from_nanos(ns(t) + 1_000_000_000), "b");
            log.write(c, 7, ns(t) as u64, ns(t) as u64, &m.to_cdr())
                .unwrap();
        }
        for &(t, v, w) in odom {
            let m = Odometry::planar(
                0.0,
                0.0,
                0.0,
                v,
                w,
                Time::from_nanos(ns(t) + 1_000_000_000),
                "odom",
                "base_link",
            );
            log.write(o, 7, ns(t) as u64, ns(t) as u64, &m.to_cdr())
                .unwrap();
        }
        log.finish().unwrap().into_inner()
    }

    #[test]
    fn commands_are_held_and_averaged_over_each_odometry_interval() {
        // Odometry every 0.1 s; the command steps to 1 at 0.05 s (half of
        // the first interval) and to 0 at 0.3 s (on a grid time).
        let odom: Vec<_> = (0..6).map(|k| (0.1 * f64::from(k), 0.5, -0.5)).collect();
        let cmds = [(0.0, 0.0, 0.0), (0.05, 1.0, 2.0), (0.3, 0.0, 0.0)];
        let log = parse_log(&bag(&cmds, &odom), "b.mcap", &BagOptions::default()).unwrap();
        assert_eq!(log.detect(), Some(Model::Velocity));
        assert_eq!(log.t.len(), 6, "the last command is a stop: odometry kept");
        for (t, want) in log.t.iter().zip([0.0, 0.1, 0.2, 0.3, 0.4, 0.5]) {
            assert!((t - want).abs() < 1e-9, "{t}");
        }
        let cmd = log.cmd.unwrap();
        let want_v = [0.5, 1.0, 1.0, 0.0, 0.0, 0.0];
        for (got, want) in cmd[0].iter().zip(want_v) {
            assert!((got - want).abs() < 1e-9, "{:?}", cmd[0]);
        }
        assert!((cmd[1][0] - 1.0).abs() < 1e-9);
        assert_eq!(log.omega, vec![-0.5; 6]);
    }

    #[test]
    fn odometry_after_a_last_moving_command_is_dropped() {
        let odom: Vec<_> = (0..6).map(|k| (0.1 * f64::from(k), 0.0, 0.0)).collect();
        let log = parse_log(
            &bag(&[(0.1, 1.0, 0.0), (0.3, 0.5, 0.0)], &odom),
            "b.mcap",
            &BagOptions::default(),
        )
        .unwrap();
        assert_eq!(log.t.len(), 3, "odometry from 0.1 to 0.3 s");
        assert_eq!(log.cmd.unwrap()[0], vec![1.0, 1.0, 0.5]);
    }

    /// A fleet.mcap's `/agent/K/state`: a robot waiting for its leader
    /// repeats its state at t = 0 before its clock runs (`fleet up` of
    /// identify-excitation gave `time does not increase at t = 0 s`). Those
    /// records are left out, whatever their number; the running ones are
    /// the log.
    #[test]
    fn a_fleet_robots_waiting_states_are_not_samples() {
        for waiting in [0_u32, 1, 2, 7, 40] {
            let mut log = McapLog::new(std::io::Cursor::new(Vec::new())).unwrap();
            let ch = log.channel("/agent/1/state", &crate::AGENT_STATE).unwrap();
            let state = |t: f64, link: &str| {
                serde_json::json!({"t": t, "agent": 1, "v": 0.1 * t, "omega": 0.0, "u1": 1.0, "u2": 0.5,
                    "tau_r": 0.1, "tau_l": 0.1, "link": link})
            };
            let mut seq = 0;
            for _ in 0..waiting {
                seq += 1;
                log.write_json(ch, seq, 0, 0, &state(0.0, "waiting"))
                    .unwrap();
            }
            for k in 0..50 {
                seq += 1;
                let t = 0.12 + 0.01 * f64::from(k);
                log.write_json(ch, seq, nanos(t), nanos(t), &state(t, "ok"))
                    .unwrap();
            }
            let bytes = log.finish().unwrap().into_inner();
            let opts = BagOptions {
                model: Some(Model::Torque),
                agent: 1,
                ..BagOptions::default()
            };
            let l = parse_log(&bytes, "fleet.mcap", &opts).unwrap();
            assert_eq!(l.t.len(), 50, "{waiting} waiting");
            assert!(l.t.windows(2).all(|w| w[1] > w[0]) && l.t[0] == 0.12);
        }
    }

    #[test]
    fn missing_and_ambiguous_channels_are_named() {
        let only_cmd = bag(&[(0.0, 1.0, 0.0)], &[]);
        let e = parse_log(&only_cmd, "b.mcap", &BagOptions::default()).unwrap_err();
        let msg = e.to_string();
        assert!(
            msg.starts_with("b.mcap: missing an odometry channel"),
            "{msg}"
        );
        assert!(msg.contains("nav_msgs/msg/Odometry"), "{msg}");
        assert!(msg.contains("/r/cmd_vel"), "{msg}");
        let opts = BagOptions {
            cmd_vel: Some("/x/cmd_vel".to_owned()),
            ..BagOptions::default()
        };
        let e = parse_log(
            &bag(&[(0.0, 1.0, 0.0)], &[(0.0, 0.0, 0.0)]),
            "b.mcap",
            &opts,
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("/x/cmd_vel (--cmd-vel)") && e.contains("channels: /r/cmd_vel"),
            "{e}"
        );
        let opts = BagOptions {
            model: Some(Model::Torque),
            agent: 3,
            ..BagOptions::default()
        };
        let e = parse_log(&only_cmd, "b.mcap", &opts)
            .unwrap_err()
            .to_string();
        assert!(e.contains("missing /agent/3/state"), "{e}");
        let e = parse_log(b"not mcap", "b.mcap", &BagOptions::default())
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("b.mcap: not a readable MCAP file"), "{e}");
    }
}
