//! Convergence against the simulator: experiment-circle in a peer mesh, velocity
//! bases' trajectory columns, an outage under each link-loss policy, the
//! crossing kept apart by the safety filter.

use super::*;

/// Every message a robot received is counted in exactly one outcome; nothing
/// but injected faults and (under a loaded machine at high time scales) a few
/// stale messages is refused.
fn check_conservation(c: &Value) {
    let outcomes = [
        "accepted",
        "malformed",
        "wrong_version",
        "foreign",
        "injected_loss",
        "injected_outage",
        "stale",
        "reordered",
    ];
    let sum: u64 = outcomes.iter().map(|k| u(c, &[k])).sum::<u64>() + u(c, &["pending"]);
    assert_eq!(sum, u(c, &["received"]), "{c}");
    for k in ["malformed", "wrong_version", "reordered"] {
        assert_eq!(u(c, &[k]), 0, "{k}: {c}");
    }
    // Stale: late under load at a high time scale; foreign: a leader robot's states while it waited.
    for k in ["stale", "foreign"] {
        assert!(
            u(c, &[k]) * 20 <= u(c, &["received"]),
            "more than 5 % {k}: {c}"
        );
    }
}

/// experiment-circle (Fig. 16) with two robot processes in a peer mesh
/// converges like the simulator; the collector logged every message it received, and two
/// readers (the mcap crate and Python's mcap) agree with its counts.
#[test]
fn experiment_circle_converges_like_the_simulator() {
    let _fleet = common::one_fleet_at_a_time();
    require_python_mcap();
    let dir = tempfile::tempdir().unwrap();
    let sim_dir = dir.path().join("sim");
    echelon_ok(&["run", "experiment-circle", "--quiet", "--out"], &sim_dir);
    let sim: Value =
        serde_json::from_str(&std::fs::read_to_string(sim_dir.join("summary.json")).unwrap())
            .unwrap();
    let fleet_dir = dir.path().join("fleet");
    // The peer mesh (the other tests go through the default router).
    let report = up(
        "experiment-circle",
        &fleet_dir,
        &["--time-scale", "20", "--topology", "mesh"],
    );
    assert_eq!(report["topology"], "mesh");
    let sim_rows = rows(&sim_dir.join("trajectory.csv"));
    let fleet_trajectory = rows(&fleet_dir.join("trajectory.csv"));
    for k in 1..=2usize {
        let robot = &report["robots"][k - 1];
        let (fleet_e, sim_e) = (
            f(robot, &["final_error"]),
            f(&sim["agents"][k - 1], &["final_error"]),
        );
        // Stated tolerance: the final ‖e‖ of both is within 1 mm (the simulator
        // reaches 1e-15 m, the 100 Hz sampled fleet ~1e-8 m).
        assert!(
            (fleet_e - sim_e).abs() < 1e-3,
            "agent {k}: fleet {fleet_e} vs sim {sim_e}"
        );
        // And the robot is where the simulated one is at the same time (5 mm):
        // its last logged state within the simulated span. (Its final state
        // may come after the scenario's end: a late last tick under load at
        // time scale 20 ended at 157.196 s, the simulator at 157.08 s, 4.6 mm
        // further along the circle at 0.04 m/s.)
        let sim_end = sim_rows
            .iter()
            .filter(|(_, a, _)| *a == k)
            .map(|r| r.0)
            .fold(f64::NEG_INFINITY, f64::max);
        let (t, _, pos) = fleet_trajectory
            .iter()
            .filter(|(t, a, _)| *a == k && *t <= sim_end)
            .max_by(|a, b| a.0.total_cmp(&b.0))
            .unwrap();
        let t = *t;
        let (_, _, near) = sim_rows
            .iter()
            .filter(|(_, a, _)| *a == k)
            .min_by(|a, b| (a.0 - t).abs().total_cmp(&(b.0 - t).abs()))
            .unwrap();
        let (x, y) = (pos[0], pos[1]);
        assert!(
            (x - near[0]).hypot(y - near[1]) < 5e-3,
            "agent {k} at t = {t}: fleet ({x}, {y}) vs sim ({}, {})",
            near[0],
            near[1]
        );
        // The whole transient: RMS ‖e‖ over time within 10 % of the
        // simulator's. Over time, not per row: a robot starved of CPU (tests
        // run fleets in parallel) skips ticks, and fewer rows of a transient
        // would bias a per-row RMS (the collector's `rms_error`) low.
        let rms_sim = f(&sim["agents"][k - 1], &["rms_error"]);
        let fleet_rows: Vec<(f64, f64)> = fleet_trajectory
            .iter()
            .filter(|(_, a, _)| *a == k)
            .map(|(t, _, v)| (*t, v[5].hypot(v[6])))
            .collect();
        let (sum, span) = fleet_rows.windows(2).fold((0.0, 0.0), |(s, d), w| {
            let dt = w[1].0 - w[0].0;
            (s + w[0].1 * w[0].1 * dt, d + dt)
        });
        let rms_fleet = (sum / span).sqrt();
        assert!(
            (rms_fleet - rms_sim).abs() < 0.1 * rms_sim,
            "agent {k}: RMS fleet {rms_fleet} vs sim {rms_sim}"
        );
        let mut c = robot["counters"].clone();
        c["pending"] = robot["pending"].clone();
        check_conservation(&c);
    }
    // Every reference sample reached both robots and the collector.
    let published = u(&report["leader"], &["published"]);
    assert!(published > 7800, "{published}");
    let col = &report["collector"];
    assert_eq!(
        u(
            col,
            &["received_by_key", "echelon/experiment-circle/reference"]
        ),
        published
    );
    // Logged = received, and the file says so to two independent readers.
    assert_eq!(u(col, &["logged"]), u(col, &["received"]));
    let logged = counts_of(&col["logged_by_topic"]);
    let mcap_path = fleet_dir.join("fleet.mcap");
    assert_eq!(mcap_counts(&mcap_path), logged);
    assert_eq!(python_mcap_counts(&mcap_path), logged);
}

/// Issue 21: the fleet's `trajectory.csv` for a scenario of velocity bases
/// has exactly the header `echelon run` writes for it, velocity-base
/// columns included, and the robots' rows fill them (their commands, what
/// the base followed, whether its limits cut it; `u1…tau_l` `NaN` as in the
/// simulator's).
#[test]
fn the_fleet_trajectory_of_velocity_bases_has_the_simulator_s_header() {
    let _fleet = common::one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let scenario = "experiment-circle-velocity";
    let sim_dir = dir.path().join("sim");
    echelon_ok(&["run", scenario, "--quiet", "--out"], &sim_dir);
    let fleet_dir = dir.path().join("fleet");
    up(
        scenario,
        &fleet_dir,
        &["--time-scale", "20", "--duration", "10"],
    );
    let header = |dir: &Path| {
        let text = std::fs::read_to_string(dir.join("trajectory.csv")).unwrap();
        text.lines().next().unwrap().to_owned()
    };
    assert_eq!(header(&fleet_dir), header(&sim_dir));
    assert_eq!(
        header(&fleet_dir),
        echelon::output::TRAJECTORY_HEADER_VELOCITY
    );
    let text = std::fs::read_to_string(fleet_dir.join("trajectory.csv")).unwrap();
    let rows: Vec<Vec<f64>> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
        .collect();
    assert!(rows.len() > 100, "{} rows", rows.len());
    for r in &rows {
        assert_eq!(r.len(), 20);
        assert!(r[11..15].iter().all(|x| x.is_nan()), "{r:?}");
        assert!(r[15..19].iter().all(|x| x.is_finite()), "{r:?}");
        assert!(r[19] == 0.0 || r[19] == 1.0, "{r:?}");
    }
    // The robots move under their commands: some are not zero.
    assert!(rows.iter().any(|r| r[15] != 0.0 && r[17] != 0.0));
}

/// A 3 s outage of everything the robots receive: under `stop` they come to
/// rest near the last reference; under `extrapolate` (hold 4 s) the true
/// tracking error stays small; both recover.
#[test]
fn outage_stop_rests_and_extrapolate_keeps_tracking() {
    let _fleet = common::one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let (start, len) = (12.0, 3.0);
    let outage = format!("{start}:{len}");
    let common = ["--time-scale", "10", "--outage", &outage, "--seed", "1"];
    let runs: Vec<(String, PathBuf)> = ["fast-circle-stop.toml", "fast-circle.toml"]
        .iter()
        .map(|s| (fixture(s), dir.path().join(s)))
        .collect();
    let reports: Vec<Value> = std::thread::scope(|scope| {
        let handles: Vec<_> = runs
            .iter()
            .map(|(s, d)| scope.spawn(|| up(s, d, &common)))
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    for (((scenario, out), report), policy) in
        runs.iter().zip(&reports).zip(["stop", "extrapolate"])
    {
        let csv = out.join("trajectory.csv");
        let all = rows(&csv);
        for k in 1..=2usize {
            let c = &report["robots"][k - 1]["counters"];
            assert!(u(c, &["injected_outage"]) > 0);
            assert!(u(c, &["link_losses"]) >= 1, "{policy}: {c}");
            // Both recover: at the end ‖e‖ < 1 mm.
            let final_e = f(&report["robots"][k - 1], &["final_error"]);
            assert!(final_e < 1e-3, "{policy} agent {k}: final ‖e‖ = {final_e}");
            // The last 0.5 s of the outage.
            let late: Vec<&(f64, usize, Vec<f64>)> = all
                .iter()
                .filter(|(t, a, _)| *a == k && *t > start + len - 0.5 && *t < start + len - 0.02)
                .collect();
            assert!(late.len() > 20, "{policy}: {} rows", late.len());
            if policy == "stop" {
                for (t, _, v) in &late {
                    // At rest (v < 2 cm/s) near the last reference (‖e‖ < 2 cm
                    // against the held position).
                    assert!(v[3].abs() < 0.02, "stop agent {k} at {t}: v = {}", v[3]);
                    assert!(
                        v[5].hypot(v[6]) < 0.02,
                        "stop agent {k} at {t}: e = {:?}",
                        &v[5..7]
                    );
                }
            }
        }
        // Against the true reference (agent 1 follows it directly).
        let errs = true_errors(scenario, &csv, 1);
        let during = errs
            .iter()
            .filter(|(t, _)| *t >= start && *t < start + len)
            .map(|(_, e)| *e)
            .fold(0.0, f64::max);
        let before = errs
            .iter()
            .filter(|(t, _)| *t > start - 2.0 && *t < start)
            .map(|(_, e)| *e)
            .fold(0.0, f64::max);
        assert!(
            before < 5e-3,
            "{policy}: converged before the outage ({before})"
        );
        if policy == "extrapolate" {
            // Stated bound: 1 cm (exact on a circle; the rest is sampling).
            assert!(during < 0.01, "extrapolate: max true ‖e‖ {during}");
        } else {
            // The reference moves 0.2 m/s × 3 s on while the robot rests.
            assert!(during > 0.3, "stop: max true ‖e‖ {during}");
        }
    }
}

/// `(t, agent, point L ahead)` of every row of a trajectory CSV (the
/// collector's or the simulator's: `t, agent, x, y, θ, …`).
fn points(csv: &Path, l: &[f64]) -> Vec<(f64, usize, [f64; 2])> {
    let text = std::fs::read_to_string(csv).unwrap();
    text.lines()
        .skip(1)
        .map(|line| {
            let v: Vec<f64> = line
                .split(',')
                .take(5)
                .map(|x| x.parse().unwrap())
                .collect();
            let k = v[1] as usize;
            let (x, y, th) = (v[2], v[3], v[4]);
            let lk = l[k - 1];
            (v[0], k, [x + lk * th.cos(), y + lk * th.sin()])
        })
        .collect()
}

/// The smallest distance between two robots' points over every row of
/// `csv`: each row of robot i against robot j's point at the same time
/// (linear between j's rows around it, at most `gap` s apart). Also how many
/// pairs were compared.
fn min_pair_distance(csv: &Path, l: &[f64], gap: f64) -> (f64, usize) {
    let all = points(csv, l);
    let n = l.len();
    let per: Vec<Vec<(f64, [f64; 2])>> = (1..=n)
        .map(|k| {
            let mut v: Vec<(f64, [f64; 2])> = all
                .iter()
                .filter(|r| r.1 == k)
                .map(|r| (r.0, r.2))
                .collect();
            v.sort_by(|a, b| a.0.total_cmp(&b.0));
            v
        })
        .collect();
    let (mut min, mut pairs) = (f64::INFINITY, 0);
    for i in 0..n {
        for j in (0..n).filter(|&j| j != i) {
            for &(t, p) in &per[i] {
                let k = per[j].partition_point(|r| r.0 < t);
                let q = match (k.checked_sub(1).map(|k| per[j][k]), per[j].get(k)) {
                    (_, Some(b)) if b.0 == t => b.1,
                    (Some(a), Some(b)) if b.0 - a.0 <= gap => {
                        let w = (t - a.0) / (b.0 - a.0);
                        [
                            a.1[0] + w * (b.1[0] - a.1[0]),
                            a.1[1] + w * (b.1[1] - a.1[1]),
                        ]
                    }
                    _ => continue,
                };
                pairs += 1;
                min = min.min((p[0] - q[0]).hypot(p[1] - q[1]));
            }
        }
    }
    (min, pairs)
}

/// Issue 15 in the fleet: `crossing` (two columns of velocity-base robots
/// swapping sides) with every robot filtering its command against its
/// neighbours' state streams. The true points L ahead (the collector's
/// trajectory, every published state: 100 Hz per robot, fleet time) stay at
/// least `radius` − 1 mm apart, and the formation converges: final ‖e‖ of
/// every robot < 5 cm after 120 s of fleet time (12 s of wall time), against
/// ~1 m for a robot still on the wrong side. The scenario's 40 s is not
/// enough in the fleet: the robots' unsynchronised ticks break the crossing's
/// symmetry differently from the simulator and from run to run; in half the
/// runs one follower slides alongside the other column for a while before it
/// passes (measured on the idle machine: converged to ≤ 1e-5 m by 80 s in ten
/// runs of ten; once, with another fleet test on the same cores, still 1.2 m
/// off at 80 s). Without `[safety]` the simulator drives them within 0.1 m of
/// each other (its log, every 0.05 s).
#[test]
fn crossing_keeps_robots_apart_in_the_fleet() {
    let _fleet = common::one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let scenario = Scenario::resolve("crossing").unwrap();
    let run = scenario.build(&Overrides::default()).unwrap();
    let l: Vec<f64> = run
        .plan
        .agents()
        .iter()
        .map(|a| a.placement().l())
        .collect();
    let radius = run.plan.safety_radius().unwrap();
    let fleet_dir = dir.path().join("fleet");
    // ×5, not ×10: at ×10 six robots at 100 Hz and the collector ask
    // 6000 ticks/s of two cores, ticks overrun (~120 per robot) and
    // neighbour states arrive a whole control period old, outside what
    // the decentralised split assumes (docs/fleet.md).
    let args = [
        "fleet",
        "up",
        "crossing",
        "--time-scale",
        "5",
        "--duration",
        "120",
        "--out",
    ];
    let out = Command::new(EXE)
        .args(args)
        .arg(&fleet_dir)
        .output()
        .unwrap();
    check(&out, &args.join(" "));
    let report = common::fleet_summary(&fleet_dir);
    // The closest approach from the true states the collector received,
    // printed as `echelon run` prints it: the summary's figures, names and
    // time, and not below the radius − 1 mm (no warning on stderr).
    let approach = &report["approach"];
    let [a, b] = [0, 1].map(|i| approach["min_distance_agents"][i].as_u64().unwrap());
    let name = |k: u64| {
        report["robots"][k as usize - 1]["name"]
            .as_str()
            .unwrap()
            .to_owned()
    };
    let d = f(approach, &["min_distance"]);
    let line = format!(
        "  safety: closest approach {d:.4} m ({} and {}, t = {:.2} s), radius {} m",
        name(a),
        name(b),
        f(approach, &["min_distance_t"]),
        f(approach, &["radius"]),
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.lines().any(|l| l == line),
        "{line:?} not in:\n{stdout}"
    );
    assert!(a < b && b as usize <= l.len(), "{approach}");
    assert_eq!(f(approach, &["radius"]), radius);
    assert!(
        d >= radius - 1e-3,
        "closest approach {d} m < radius {radius} m − 1 mm"
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("inside the safety radius"), "{stderr}");
    let (min, pairs) = min_pair_distance(&fleet_dir.join("trajectory.csv"), &l, 0.05);
    // 6 robots × 5 others × ~8000 states.
    assert!(pairs > 200_000, "{pairs} pairs compared");
    let safety = &report["safety"];
    assert!(
        min >= radius - 1e-3,
        "nearest points {min} m < radius {radius} m − 1 mm (filters: {safety}; per robot: {:?})",
        report["robots"].as_array().map(|rs| rs
            .iter()
            .map(|r| (r["safety"].clone(), r["overruns"].clone()))
            .collect::<Vec<_>>())
    );
    assert!(u(safety, &["active"]) > 0, "{safety}");
    // A neighbour's state older than the filter allows brakes the robot
    // (the safe answer; its logic is tested on the fake clock,
    // echelon-fleet's robot::tests::plant). How often that happens here is
    // the machine's timing, not the logic: none on an idle 2-core machine,
    // 139 of 71 508 filter steps (0.2 %) with `stress-ng --cpu 2` beside
    // the fleet. The bound, 2 % of the steps, is the stated margin: a fleet
    // braking that often for stale states has fallen behind its clock.
    let (stale, steps) = (u(safety, &["stale_brakes"]), u(safety, &["steps"]));
    assert!(
        50 * stale <= steps,
        "stale brakes {stale} of {steps} steps: {safety}"
    );
    assert!(
        stale == 0 || u(safety, &["stale_neighbours"]) > 0,
        "{safety}"
    );
    // The simulator's liveness property (docs/safety.md, "Deadlock"): every
    // robot reached its slot, or its filter held it and it says so.
    let deadlocked: Vec<u64> = report["deadlocked_at_end"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a.as_u64().unwrap())
        .collect();
    for r in report["robots"].as_array().unwrap() {
        let e = f(r, &["final_error"]);
        let held = r["deadlocked_at_end"].as_bool().unwrap();
        assert_eq!(held, deadlocked.contains(&r["agent"].as_u64().unwrap()));
        assert!(
            e < 1e-2 || held,
            "robot {}: final ‖e‖ = {e} m, not reported deadlocked",
            r["agent"]
        );
        assert!(u(r, &["safety", "steps"]) > 6000, "{r}");
    }
    eprintln!(
        "fleet crossing: nearest points {min:.4} m over {pairs} pairs, deadlocked {deadlocked:?}, final ‖e‖ max {:.2e} m, {safety}",
        report["robots"]
            .as_array()
            .unwrap()
            .iter()
            .map(|r| f(r, &["final_error"]))
            .fold(0.0, f64::max)
    );

    // Without the filter (the simulator, the scenario minus [safety]).
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios/crossing.toml"),
    )
    .unwrap();
    let mut unsafe_text = String::new();
    let mut skip = false;
    for line in text.lines() {
        if line.starts_with('[') {
            skip = line.trim() == "[safety]";
        }
        if !skip {
            unsafe_text.push_str(line);
            unsafe_text.push('\n');
        }
    }
    assert!(!unsafe_text.lines().any(|l| l.starts_with("[safety]")));
    assert!(unsafe_text.contains("[[agents]]"));
    let unsafe_path = dir.path().join("crossing-unsafe.toml");
    std::fs::write(&unsafe_path, unsafe_text).unwrap();
    let sim_dir = dir.path().join("sim");
    echelon_ok(
        &["run", unsafe_path.to_str().unwrap(), "--quiet", "--out"],
        &sim_dir,
    );
    let (min, _) = min_pair_distance(&sim_dir.join("trajectory.csv"), &l, 0.1);
    assert!(
        min < 0.1,
        "without the filter the nearest points are {min} m"
    );
}
