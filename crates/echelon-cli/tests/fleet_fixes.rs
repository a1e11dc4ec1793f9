//! Real robots in one world (docs/ros2.md, "Fixes"), as processes:
//! `fleet up --ros2` with bases whose odometry drifts (2 % on one wheel,
//! a longer wheelbase, slip) and a simulated motion capture at 10 Hz with
//! 5 mm noise and 30 ms latency. Every robot's *true* world position (the
//! bases' ground truth in `fleet.mcap`) stays within 2 cm of its slot once
//! settled; without the fixes it does not, and the true error stays under
//! Theorem 2's bound for the drift the run measured (plus what the
//! sampled loop itself leaves, measured). Theorem 2's fix
//! interval is the one `echelon bound --law kinematic` gives for the same
//! inputs, and a robot whose fixes come slower than it requires says so.
//! The crossing on the same odometry with fixes keeps its radius in ten runs.

#![allow(clippy::unwrap_used)]

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

use serde_json::Value;

use echelon_ros2::msgs::{Odometry, RosMessage};

mod common;

use common::EXE;

const SCENARIO: &str = "experiment-circle-velocity";

/// Odometry that drifts as a real robot's does: one wheel 2 % larger
/// (`E_d`), the wheelbase 1 % longer than nominal (`E_b`), random slip.
const DRIFT: &str = "\n[odometry]\nperiod = 0.02\nwheel_diameter_ratio = 1.02\nwheelbase_ratio = 1.01\nslip = 1e-5\n";

/// Fixes from a motion capture: 10 Hz, 5 mm, 0.01 rad, 30 ms late, fused
/// by the EKF; agent 1 asks a tolerance its fixes meet, agent 2 one they
/// do not.
const MOCAP: &str = "\n[fixes]\nsource = \"pose\"\nperiod = 0.1\nposition_noise = 0.005\nheading_noise = 0.01\nlatency = 0.03\nfusion = \"ekf\"\n";

/// The builtin with `extra` appended, and per-agent `fixes` tables.
fn scenario(dir: &Path, name: &str, extra: &str, agents: [&str; 2]) -> String {
    common::scenario_variant(dir, SCENARIO, name, &agents, extra)
}

/// `fleet up --ros2` of `scenario` for `duration` fleet seconds at ×5.
fn fleet_up(scenario: &str, duration: &str, out: &Path) -> Value {
    let args = [
        scenario,
        "--ros2",
        "--time-scale",
        "5",
        "--duration",
        duration,
        "--quiet",
    ];
    common::fleet_up(&args, out)
}

/// A robot's published state: its fleet time, its estimate `(x, y, θ)`,
/// `e` and the leader point `p_d` its law used.
#[derive(Debug, Clone, Copy)]
struct Estimate {
    wall: u64,
    t: f64,
    pose: [f64; 3],
    e: [f64; 2],
    pd: [f64; 2],
    /// The `σ` it published, m.
    sigma: f64,
    /// Its raw odometry's `fix_age`, s (`None`: no fix yet).
    fix_age: Option<f64>,
}

/// From `fleet.mcap`: per agent, its states (by receipt time) and its
/// base's ground truth `(wall stamp ns, x, y, θ)`.
type Logged = BTreeMap<u32, (Vec<Estimate>, Vec<(u64, [f64; 3])>)>;

fn read_log(dir: &Path) -> Logged {
    let bytes = std::fs::read(dir.join("fleet.mcap")).unwrap();
    let mut out: Logged = BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let topic = m.channel.topic.as_str();
        if let Some(k) = common::topic_number(topic, "/agent/", "/state") {
            let v: Value = serde_json::from_slice(&m.data).unwrap();
            let Some(leader) = v.get("leader") else {
                continue;
            };
            let g = |k: &str| v[k].as_f64().unwrap();
            out.entry(k).or_default().0.push(Estimate {
                wall: m.log_time,
                t: g("t"),
                pose: [g("x"), g("y"), g("theta")],
                e: [g("ex"), g("ey")],
                pd: [leader["x"].as_f64().unwrap(), leader["y"].as_f64().unwrap()],
                sigma: g("sigma"),
                fix_age: v["odometry"]["fix_age"].as_f64(),
            });
        } else if let Some(k) = common::topic_number(topic, "/robot", "/ground_truth") {
            let o = Odometry::from_cdr_finite(&m.data).unwrap();
            assert_eq!(o.header.frame_id, "map");
            let p = o.pose.pose.position;
            let stamp = o.header.stamp.to_nanos() as u64;
            out.entry(k)
                .or_default()
                .1
                .push((stamp, [p.x, p.y, o.yaw()]));
        }
    }
    out
}

/// `e = R(θ)ᵀ(p − p_d) + L` (eq. 7) at the true pose, with the `L` the
/// robot used (from its estimate and its `e`).
fn true_error(est: &Estimate, truth: [f64; 3]) -> f64 {
    let body = |pose: [f64; 3]| {
        let (s, c) = pose[2].sin_cos();
        let (dx, dy) = (pose[0] - est.pd[0], pose[1] - est.pd[1]);
        [c * dx + s * dy, -s * dx + c * dy]
    };
    let d = body(est.pose);
    let l = [est.e[0] - d[0], est.e[1] - d[1]];
    let t = body(truth);
    (t[0] + l[0]).hypot(t[1] + l[1])
}

/// Per agent, the largest true ‖e‖ after fleet time `settled`: each ground
/// truth sample against the state the robot published nearest in wall time.
fn worst_true_error(log: &Logged, settled: f64) -> BTreeMap<u32, (f64, usize)> {
    let mut worst = BTreeMap::new();
    for (&k, (states, truth)) in log {
        let mut max = 0.0f64;
        let mut n = 0;
        for &(stamp, pose) in truth {
            let i = states.partition_point(|s| s.wall < stamp);
            let near = [i.checked_sub(1), Some(i)]
                .into_iter()
                .flatten()
                .filter_map(|j| states.get(j))
                .min_by_key(|s| s.wall.abs_diff(stamp));
            let Some(est) = near else { continue };
            // Within 2 ms of wall time (10 ms of fleet time at ×5).
            if est.t < settled || est.wall.abs_diff(stamp) > 2_000_000 {
                continue;
            }
            max = max.max(true_error(est, pose));
            n += 1;
        }
        worst.insert(k, (max, n));
    }
    worst
}

/// Theorem 2 (kinematic law, docs/control-law.md) checked on a run without
/// fixes. `ζ̂` is the odometry error the run measured: the largest per-axis
/// distance between a robot's true and estimated positions, per odometry
/// sample since the start (`N = t / T_s` samples of dead reckoning). The
/// theorem speaks of position errors with the heading exact (its
/// Assumption 1), so it is checked on `e` at the true position and the
/// estimated heading; this odometry's longer wheelbase also drifts the
/// heading, which rotates `p − p_d` and adds `2|sin(θ̃/2)|‖p − p_d‖` to the
/// true ‖e‖ (reported, not bounded by the theorem). The theorem is for an
/// ideal base and a continuous controller, whose `ê` (the error the robot
/// sees) the law keeps at the estimate's own error; a fleet robot is a
/// sampled loop over a network, and what it leaves in `ê` is measured as
/// `r`, the 99th percentile of its `‖ê‖` once the start's transient is over
/// (fleet t ≥ 20 s). Checked: `r` stays under 1 cm (the robot tracks its
/// estimate), that `e` stays under `√2 N ζ̂ / γ + r` in 99 % of the samples
/// (a loaded machine's brief stall is outside what the theorem models, and
/// counted), and the true error did grow.
fn theorem_2_holds_on_measured_drift(log: &Logged) {
    const TS: f64 = 0.02;
    const GAMMA: f64 = 0.99;
    const SETTLED: f64 = 20.0;
    for (k, (states, truth)) in log {
        // (fleet t, true ‖e‖, per-axis position error, ‖e‖ at the true
        // position and the estimated heading, the heading's share), matched
        // in wall time.
        let mut rows = Vec::new();
        for &(stamp, pose) in truth {
            let i = states.partition_point(|s| s.wall < stamp);
            let Some(est) = states.get(i).filter(|s| s.wall - stamp < 2_000_000) else {
                continue;
            };
            let axis = (pose[0] - est.pose[0])
                .abs()
                .max((pose[1] - est.pose[1]).abs());
            let at_estimated_heading = true_error(est, [pose[0], pose[1], est.pose[2]]);
            let heading = (pose[2] - est.pose[2])
                .sin()
                .atan2((pose[2] - est.pose[2]).cos());
            let share = 2.0
                * (heading / 2.0).sin().abs()
                * (pose[0] - est.pd[0]).hypot(pose[1] - est.pd[1]);
            rows.push((
                est.t,
                true_error(est, pose),
                axis,
                at_estimated_heading,
                share,
            ));
        }
        let zeta = rows
            .iter()
            .filter(|r| r.0 > 1.0)
            .map(|&(t, _, axis, ..)| axis / (t / TS))
            .fold(0.0f64, f64::max);
        assert!(zeta > 0.0, "agent {k}: no drift measured");
        let mut seen: Vec<f64> = states
            .iter()
            .filter(|s| s.t >= SETTLED)
            .map(|s| s.e[0].hypot(s.e[1]))
            .collect();
        seen.sort_by(f64::total_cmp);
        assert!(seen.len() > 1000, "agent {k}: {} states", seen.len());
        let r = seen[seen.len() * 99 / 100];
        assert!(r < 0.01, "agent {k}: the robot's own ‖ê‖ p99 {r} m");
        let (mut checked, mut over) = (0usize, Vec::new());
        let (mut ratio, mut heading_share) = (0.0f64, 0.0f64);
        for &(t, _, _, e, share) in rows.iter().filter(|r| r.0 >= SETTLED) {
            heading_share = heading_share.max(share);
            let bound = std::f64::consts::SQRT_2 * (t / TS) * zeta / GAMMA + r;
            ratio = ratio.max(e / bound);
            if e > bound {
                over.push(format!("t = {t:.2} s: {e} m over {bound} m"));
            }
            checked += 1;
        }
        assert!(checked > 1000, "agent {k}: {checked} samples checked");
        assert!(
            over.len() * 100 <= checked,
            "agent {k}: ‖e‖ (true position, estimated heading) over Theorem 2's bound (ζ̂ = {zeta:e} m/sample, r = {r} m) \
             in {} of {checked} samples: {:?}",
            over.len(),
            &over[..over.len().min(10)]
        );
        eprintln!(
            "agent {k}: ζ̂ = {zeta:e} m/sample, r = {r:.4} m, ‖e‖ at most {ratio:.2} of the \
             bound, over it in {} of {checked} samples; the heading's drift added up to \
             {heading_share:.4} m to the true ‖e‖",
            over.len()
        );
        let late = rows.iter().rev().take(50).map(|r| r.1).fold(0.0, f64::max);
        let early = rows
            .iter()
            .filter(|r| (SETTLED..SETTLED + 1.0).contains(&r.0))
            .map(|r| r.1)
            .fold(0.0, f64::max);
        assert!(
            late > early,
            "agent {k}: ‖e‖ {early} m at 20 s, {late} m at the end"
        );
    }
}

fn fixes_of(robot: &Value) -> &Value {
    robot
        .get("fixes")
        .unwrap_or_else(|| panic!("no fixes: {robot}"))
}

#[test]
fn drifting_robots_with_a_motion_capture_keep_their_slots_in_the_world() {
    let _fleet = common::one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let with = scenario(
        dir.path(),
        "mocap",
        &format!("{DRIFT}{MOCAP}"),
        [
            "fixes = { tolerance = 0.05 }\n",
            "fixes = { tolerance = 0.001 }\n",
        ],
    );
    let up = fleet_up(&with, "60", &dir.path().join("with"));
    let log = read_log(&dir.path().join("with"));
    assert_eq!(log.len(), 2, "{:?}", log.keys());
    // Once settled, each state says how old its last fix was (10 Hz fixes)
    // and publishes the EKF's small σ.
    for (k, (states, _)) in &log {
        for s in states.iter().filter(|s| s.t >= 30.0) {
            let age = s
                .fix_age
                .unwrap_or_else(|| panic!("agent {k}: no fix_age at {}", s.t));
            assert!(
                (0.0..0.3).contains(&age),
                "agent {k}: fix_age {age} at {}",
                s.t
            );
            assert!(
                s.sigma > 0.0 && s.sigma < 0.02,
                "agent {k}: σ {} at {}",
                s.sigma,
                s.t
            );
        }
    }
    for (k, (worst, n)) in worst_true_error(&log, 30.0) {
        assert!(n > 500, "agent {k}: {n} ground-truth samples compared");
        assert!(
            worst < 0.02,
            "agent {k}: true ‖e‖ up to {worst} m with fixes"
        );
    }
    let robots = up["robots"].as_array().unwrap();
    for r in robots {
        let f = fixes_of(r);
        let c = &f["counters"];
        // 10 Hz for 60 s, all applied (the first taken as it is).
        assert!(c["applied"].as_u64().unwrap() > 500, "{f}");
        for refused in ["wrong_type", "malformed", "non_finite", "wrong_frame"] {
            assert_eq!(c[refused], 0, "{refused}: {f}");
        }
        assert!(f["interval_max"].as_f64().unwrap() < 0.3, "{f}");
        // Theorem 2's interval is `echelon bound`'s for the same inputs.
        let req = &f["required"];
        let num = |k: &str| req[k].as_f64().unwrap().to_string();
        let bound = Command::new(EXE)
            .args(["bound", "--law", "kinematic", "--json"])
            .args([
                "--ke",
                &num("ke"),
                "--zeta",
                &num("zeta"),
                "--gamma",
                &num("gamma"),
            ])
            .args(["--max-e", &num("tolerance"), "--ts", &num("sample_period")])
            .output()
            .unwrap();
        assert!(
            bound.status.success(),
            "{}",
            String::from_utf8_lossy(&bound.stderr)
        );
        let b: Value = serde_json::from_slice(&bound.stdout).unwrap();
        assert_eq!(b["steps"], req["steps"], "{b} vs {req}");
        assert!(
            (b["fix_period_s"].as_f64().unwrap() - req["interval"].as_f64().unwrap()).abs() < 1e-12
        );
    }
    // Agent 1's fixes come often enough; agent 2's do not, and it said so once.
    let slow: Vec<bool> = robots
        .iter()
        .map(|r| fixes_of(r)["too_slow"].as_bool().unwrap())
        .collect();
    assert_eq!(slow, [false, true], "{up}");
    let logs: String = std::fs::read_dir(dir.path().join("with/logs"))
        .unwrap()
        .map(|e| std::fs::read_to_string(e.unwrap().path()).unwrap_or_default())
        .collect();
    assert_eq!(logs.matches("Theorem 2 requires").count(), 1, "{logs}");
    assert!(
        logs.contains("agent 2: fixes from /robot2/pose came"),
        "{logs}"
    );

    // Without fixes the same odometry drifts away from the slots.
    let without = scenario(dir.path(), "drift", DRIFT, ["", ""]);
    let up = fleet_up(&without, "60", &dir.path().join("without"));
    let log = read_log(&dir.path().join("without"));
    // On odometry alone σ is the dead-reckoning rule's: it never shrinks
    // and ends well above the fixes' (docs/safety.md, "Uncertain positions").
    for (k, (states, _)) in &log {
        let mut by_time = states.clone();
        by_time.sort_by(|a, b| a.t.total_cmp(&b.t).then(a.wall.cmp(&b.wall)));
        for w in by_time.windows(2) {
            assert!(
                w[1].sigma >= w[0].sigma,
                "agent {k}: σ {} then {}",
                w[0].sigma,
                w[1].sigma
            );
        }
        assert!(by_time.iter().all(|s| s.fix_age.is_none()), "agent {k}");
        let last = by_time.last().unwrap().sigma;
        eprintln!("agent {k}: σ on odometry alone after 60 s: {last:.3} m");
        assert!(
            last > 0.05,
            "agent {k}: σ {last} m after 60 s on drifting odometry"
        );
    }
    let worst = worst_true_error(&log, 30.0);
    assert!(
        worst.values().any(|&(w, _)| w > 0.04),
        "odometry alone drifted only {worst:?}"
    );
    theorem_2_holds_on_measured_drift(&log);
    assert!(
        up["robots"]
            .as_array()
            .unwrap()
            .iter()
            .all(|r| r.get("fixes").is_none())
    );
}

/// Per agent, its true point `l` ahead at wall time `w` (ns), interpolated
/// in its base's ground truth.
fn true_point(truth: &[(u64, [f64; 3])], w: u64, l: f64) -> Option<[f64; 2]> {
    let i = truth.partition_point(|&(s, _)| s < w);
    let (&(s0, a), &(s1, b)) = (truth.get(i.checked_sub(1)?)?, truth.get(i)?);
    if s1 - s0 > 100_000_000 {
        return None;
    }
    let f = (w - s0) as f64 / (s1 - s0) as f64;
    let p = |k: usize| a[k] + f * (b[k] - a[k]);
    // The yaw is wrapped to [−π, π]: interpolate along the short way.
    let turn = (b[2] - a[2] + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
        - std::f64::consts::PI;
    let theta = a[2] + f * turn;
    Some([p(0) + l * theta.cos(), p(1) + l * theta.sin()])
}

/// The crossing (two columns swapping sides under the safety filter) on
/// drifting odometry with motion-capture fixes, ten times: the robots'
/// *true* points keep the 0.3 m radius (less 1 cm) in every run.
#[test]
fn the_crossing_on_drifting_odometry_with_fixes_keeps_the_radius_in_ten_runs() {
    let _fleet = common::one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let src = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios/crossing.toml"),
    )
    .unwrap();
    let path = dir.path().join("crossing-drift.toml");
    std::fs::write(&path, format!("{src}{DRIFT}{MOCAP}")).unwrap();
    let scenario = path.to_string_lossy().into_owned();
    let mut closest_all = Vec::new();
    for run in 0..10 {
        let out = dir.path().join(format!("run{run}"));
        let up = fleet_up(&scenario, "40", &out);
        let log = read_log(&out);
        assert_eq!(log.len(), 6);
        let truths: Vec<&Vec<(u64, [f64; 3])>> = log.values().map(|(_, t)| t).collect();
        let start = truths.iter().map(|t| t[0].0).max().unwrap();
        let end = truths.iter().map(|t| t.last().unwrap().0).min().unwrap();
        let mut closest = f64::INFINITY;
        let mut at = (0, 0, 0);
        let mut w = start;
        while w < end {
            let pts: Vec<_> = truths.iter().map(|t| true_point(t, w, 0.05)).collect();
            for i in 0..pts.len() {
                for j in i + 1..pts.len() {
                    if let (Some(a), Some(b)) = (pts[i], pts[j]) {
                        let d = (a[0] - b[0]).hypot(a[1] - b[1]);
                        if d < closest {
                            (closest, at) = (d, (w, i, j));
                        }
                    }
                }
            }
            w += 10_000_000;
        }
        // Where the robots believed they were then (their published
        // estimates nearest in wall time).
        let believed: Vec<String> = [at.1, at.2]
            .iter()
            .map(|&i| {
                let states = &log.values().nth(i).unwrap().0;
                let k = states.partition_point(|s| s.wall < at.0).min(states.len() - 1);
                let s = states[k];
                format!(
                    "agent {} at {} true point {:?} t {:.2}: estimate ({:.3}, {:.3}, {:.3}), e ({:.3}, {:.3}), truth {:?}",
                    i + 1,
                    at.0,
                    true_point(truths[i], at.0, 0.05),
                    s.t,
                    s.pose[0],
                    s.pose[1],
                    s.pose[2],
                    s.e[0],
                    s.e[1],
                    truths[i][truths[i].partition_point(|&(w, _)| w < at.0).min(truths[i].len() - 1)].1
                )
            })
            .collect();
        for r in up["robots"].as_array().unwrap() {
            assert!(
                fixes_of(r)["counters"]["applied"].as_u64().unwrap() > 300,
                "{r}"
            );
        }
        closest_all.push(closest);
        assert!(
            closest >= 0.29,
            "run {run}: true points {closest} m apart (radius 0.3): {believed:#?}"
        );
    }
    eprintln!("closest true distance per run: {closest_all:?}");
}

/// A bad value in the fields this work added (`fixes.source`, `fixes.frame`,
/// `fixes.tolerance`, `ros2.driven`) is refused by the fleet with exit 2 and
/// one line naming file, line, column and field.
#[test]
fn bad_fix_and_head_settings_are_refused_with_their_place() {
    let dir = tempfile::tempdir().unwrap();
    for (own, field) in [
        (
            "fixes = { period = 0.1, source = \"bad topic\" }\n",
            "agents[1].fixes.source",
        ),
        (
            "fixes = { period = 0.1, source = \"pose\", frame = \"a b\" }\n",
            "agents[1].fixes.frame",
        ),
        (
            "fixes = { period = 0.1, source = \"pose\", tolerance = -0.1 }\n",
            "agents[1].fixes.tolerance",
        ),
        ("ros2 = { driven = \"yes\" }\n", "agents[1].ros2.driven"),
    ] {
        let path = scenario(dir.path(), "bad", "", [own, ""]);
        let src = std::fs::read_to_string(&path).unwrap();
        let line = src.lines().position(|l| l == own.trim_end()).unwrap() + 1;
        let out = Command::new(EXE)
            .args(["fleet", "robot", &path, "--agent", "1", "--ros2"])
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(2), "{own}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        let place = format!("{path}:{line}:");
        let rest = err
            .split_once(&place)
            .map(|(_, r)| r)
            .unwrap_or_else(|| panic!("{err}"));
        let (column, after) = rest.split_once(':').unwrap();
        assert!(column.parse::<u32>().unwrap() > 0, "{err}");
        assert!(after.trim_start().starts_with(field), "{field}: {err}");
    }
}
