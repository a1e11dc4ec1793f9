#![allow(clippy::unwrap_used)]
//! The fleet as real processes on loopback (`echelon fleet …`), each test on
//! its own free ports, sped up with `--time-scale` so that minutes of
//! experiment take seconds. Child processes are killed if a test fails.
//!
//! Only the end-to-end lives here (convergence against the simulator, an
//! outage, the secure mode, SIGTERM, bad input). What a robot does with what
//! it receives (loss and delay injection, stale, reordered and garbage
//! messages, restarts, link-loss policies, chained followers) and what the
//! collector logs are tested on a fake clock in `echelon-fleet`'s unit tests
//! (`robot::tests`, `collector::tests`).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use serde_json::Value;

use echelon::control::law;
use echelon::model::State;
use echelon::reference::{Order, Trajectory};
use echelon::scenario::{Overrides, Scenario};

mod common;

use common::{EXE, Guard, check, echelon_ok, endpoints_of, f, spawn};

fn fixture(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fleet")
        .join(name)
        .display()
        .to_string()
}

/// `echelon fleet up` into `dir`; returns fleet-summary.json.
fn up(scenario: &str, dir: &Path, extra: &[&str]) -> Value {
    echelon_ok(
        &[&["fleet", "up", scenario], extra, &["--out"]].concat(),
        dir,
    );
    serde_json::from_str(&std::fs::read_to_string(dir.join("fleet-summary.json")).unwrap()).unwrap()
}

fn u(v: &Value, path: &[&str]) -> u64 {
    path.iter()
        .fold(v, |v, k| &v[*k])
        .as_u64()
        .unwrap_or_else(|| panic!("{path:?} in {v}"))
}

/// trajectory.csv rows: (t, agent, the 13 numbers).
fn rows(path: &Path) -> Vec<(f64, usize, Vec<f64>)> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some(echelon::output::TRAJECTORY_HEADER));
    lines
        .map(|l| {
            let v: Vec<&str> = l.split(',').collect();
            assert_eq!(v.len(), 15, "{l}");
            (
                v[0].parse().unwrap(),
                v[1].parse().unwrap(),
                v[2..].iter().map(|x| x.parse().unwrap()).collect(),
            )
        })
        .collect()
}

/// ‖e‖ (eq. 7) of agent `k` (from 1) following the reference, at each CSV row,
/// against the true reference: what the robot would see with a perfect link.
fn true_errors(scenario: &str, csv: &Path, k: usize) -> Vec<(f64, f64)> {
    let run = Scenario::resolve(scenario)
        .unwrap()
        .build(&Overrides::default())
        .unwrap();
    let spec = &run.plan.agents()[k - 1];
    let reference = run.plan.reference();
    rows(csv)
        .into_iter()
        .filter(|(_, a, _)| *a == k)
        .map(|(t, _, v)| {
            let s = State {
                x: v[0],
                y: v[1],
                theta: v[2],
                v: v[3],
                omega: v[4],
            };
            let jet = reference.eval(t, Order::Two);
            let motion = echelon::control::LeaderMotion {
                p: jet.p,
                dp: jet.dp,
                ddp: jet.ddp,
            };
            let off = spec.placement().offset_for_reference(&jet);
            let out = law(
                spec.torque_robot().expect("a torque-driven fleet agent"),
                &s,
                &motion,
                &off,
                spec.gains(),
                spec.variant().expect("a torque-driven fleet agent"),
            );
            (t, out.e[0].hypot(out.e[1]))
        })
        .collect()
}

/// Message counts per JSON topic, read with the mcap crate (the 3D
/// channels, Foxglove's protobuf schemas, are checked in tests/foxglove.rs).
fn mcap_counts(path: &Path) -> BTreeMap<String, u64> {
    let bytes = std::fs::read(path).unwrap();
    let mut counts = BTreeMap::new();
    let mut scene = 0;
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        if m.channel.message_encoding == "protobuf" {
            scene += 1;
            continue;
        }
        assert_eq!(m.channel.message_encoding, "json");
        let schema = m.channel.schema.as_ref().unwrap();
        assert_eq!(schema.encoding, "jsonschema");
        let _: Value = serde_json::from_slice(&m.data).unwrap();
        *counts.entry(m.channel.topic.clone()).or_insert(0) += 1;
    }
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    assert_eq!(
        summary.stats.unwrap().message_count,
        counts.values().sum::<u64>() + scene
    );
    counts
}

/// Fails the test at once, saying what to install, when `python3` cannot
/// import Python's `mcap` package (the independent MCAP reader).
fn require_python_mcap() {
    let found = Command::new("python3")
        .args(["-c", "import mcap.reader"])
        .output();
    match found {
        Ok(out) if out.status.success() => {}
        Ok(out) => panic!(
            "Python's `mcap` package is missing ({}): run `scripts/test`, which installs \
             it, or `python3 -m pip install -r scripts/requirements-test.txt`",
            String::from_utf8_lossy(&out.stderr)
                .lines()
                .last()
                .unwrap_or("")
        ),
        Err(e) => panic!(
            "python3 is missing ({e}): install Python 3, then run `scripts/test`, which \
             installs Python's `mcap` package"
        ),
    }
}

/// Message counts per topic, read by Python's `mcap` package (an independent
/// reader; `scripts/test` installs it).
fn python_mcap_counts(path: &Path) -> BTreeMap<String, u64> {
    require_python_mcap();
    let script = "import json, sys\n\
        from mcap.reader import make_reader\n\
        counts = {}\n\
        with open(sys.argv[1], 'rb') as f:\n\
        \x20   for schema, channel, message in make_reader(f).iter_messages():\n\
        \x20       if channel.message_encoding != 'json': continue\n\
        \x20       json.loads(message.data)\n\
        \x20       counts[channel.topic] = counts.get(channel.topic, 0) + 1\n\
        print(json.dumps(counts))\n";
    let out = Command::new("python3")
        .args(["-c", script, &path.display().to_string()])
        .output()
        .expect("python3 ran before");
    check(&out, "Python mcap reader");
    serde_json::from_slice(&out.stdout).unwrap()
}

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

fn counts_of(v: &Value) -> BTreeMap<String, u64> {
    v.as_object()
        .unwrap()
        .iter()
        .map(|(k, v)| (k.clone(), v.as_u64().unwrap()))
        .collect()
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
        // And the robot is where the simulated one is at the same time (5 mm).
        let t = f(robot, &["t"]);
        let (_, _, near) = sim_rows
            .iter()
            .filter(|(_, a, _)| *a == k)
            .min_by(|a, b| (a.0 - t).abs().total_cmp(&(b.0 - t).abs()))
            .unwrap();
        let pos = &robot["final_state"];
        let (x, y) = (pos[0].as_f64().unwrap(), pos[1].as_f64().unwrap());
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
        let fleet_rows: Vec<(f64, f64)> = rows(&fleet_dir.join("trajectory.csv"))
            .into_iter()
            .filter(|(_, a, _)| *a == k)
            .map(|(t, _, v)| (t, v[5].hypot(v[6])))
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

/// A rogue's scenario: `fast-circle.toml` with its reference swapped for a
/// line heading off at 1 m/s far away, written into `dir`.
fn fake_reference(dir: &Path) -> PathBuf {
    let fake = dir.join("fake.toml");
    std::fs::write(
        &fake,
        std::fs::read_to_string(fixture("fast-circle.toml"))
            .unwrap()
            .replace(
                "[reference.circle]\nspeed = 0.2\nturn_rate = 0.2\nstart = { x = 0.0, y = 0.0, theta_deg = 0.0 }",
                "[reference.line]\nspeed = 1.0\nstart = { x = 5.0, y = 5.0, theta_deg = 90.0 }",
            ),
    )
    .unwrap();
    fake
}

/// A rogue leader publishing `fake` on the `fast-circle` fleet through the
/// Zenoh configuration `config`.
fn rogue_leader(fake: &Path, config: &Path) -> Guard {
    let (fake, config) = (fake.display().to_string(), config.display().to_string());
    spawn(&[
        "fleet",
        "leader",
        &fake,
        "--fleet",
        "fast-circle",
        "--time-scale",
        "10",
        "--duration",
        "25",
        "--zenoh-config",
        &config,
    ])
}

/// Robot 1's largest true ‖e‖ after t = 10 s of a `fast-circle.toml` fleet
/// run into `fleet_dir`, m.
fn late_error_of_robot_1(fleet_dir: &Path) -> f64 {
    true_errors(
        &fixture("fast-circle.toml"),
        &fleet_dir.join("trajectory.csv"),
        1,
    )
    .iter()
    .filter(|(t, _)| *t > 10.0)
    .map(|(_, e)| *e)
    .fold(0.0, f64::max)
}

/// Secure mode: with mutual TLS and access control, a rogue that holds a
/// valid robot certificate publishes a fake reference and no robot takes it;
/// a rogue without credentials cannot even join.
#[test]
fn secure_mode_rogue_moves_no_robot() {
    let _fleet = common::one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let certs = common::certs(dir.path(), 2);
    let fleet_dir = dir.path().join("fleet");
    let scenario = fixture("fast-circle.toml");
    let fleet = std::thread::spawn({
        let (fleet_dir, certs) = (fleet_dir.clone(), certs.clone());
        move || {
            up(
                &scenario,
                &fleet_dir,
                &[
                    "--time-scale",
                    "10",
                    "--secure",
                    &certs.display().to_string(),
                ],
            )
        }
    });
    let endpoints = endpoints_of(&fleet_dir);
    // Through the router (the default): it is the only process listening.
    assert_eq!(endpoints.keys().collect::<Vec<_>>(), ["router/1"]);
    assert!(endpoints.values().all(|e| e.starts_with("quic/")));
    // A fake reference far away: a line heading off at 1 m/s.
    let fake = fake_reference(dir.path());
    assert!(
        std::fs::read_to_string(&fake)
            .unwrap()
            .contains("reference.line")
    );
    let connect: Vec<String> = endpoints.values().cloned().collect();
    let config = |tls: Value| common::outsider_config(&connect, tls, 5000, true).to_string();
    // Rogue 1: robot 2's certificate, no access control of its own.
    let stolen = dir.path().join("stolen.json5");
    std::fs::write(&stolen, config(common::tls_as(&certs, "robot-2"))).unwrap();
    // Rogue 2: trusts the CA but has no certificate of its own.
    let anonymous = dir.path().join("anonymous.json5");
    let ca = certs.join("ca.pem").display().to_string();
    std::fs::write(
        &anonymous,
        config(serde_json::json!({ "root_ca_certificate": ca })),
    )
    .unwrap();
    let mut stolen_rogue = rogue_leader(&fake, &stolen);
    let mut anonymous_rogue = rogue_leader(&fake, &anonymous);
    let report = fleet.join().unwrap();
    // The rogue with a stolen robot certificate joined and published…
    let status = stolen_rogue.0.wait().unwrap();
    let mut text = String::new();
    std::io::Read::read_to_string(stolen_rogue.0.stdout.as_mut().unwrap(), &mut text).unwrap();
    let _ = status;
    let rogue_report: Option<Value> = text
        .lines()
        .last()
        .and_then(|l| serde_json::from_str(l).ok());
    // …the anonymous one could not connect at all.
    let anon_status = anonymous_rogue.0.wait().unwrap();
    assert!(
        !anon_status.success(),
        "a rogue without a certificate joined"
    );
    let published = u(&report["leader"], &["published"]);
    let rogue_report = rogue_report.expect("the rogue with a robot certificate did not run");
    assert!(u(&rogue_report, &["published"]) > 1000, "{rogue_report}");
    // No robot took a fake sample: one source, nothing foreign, no more
    // samples than the leader's. (Over QUIC, through the router, the robot
    // heard 1499 to 1501 of the 1501, also with two CPU hogs running: the
    // last one or two may come after it stopped.)
    let c = &report["robots"][0]["counters"];
    assert_eq!(u(c, &["restarts"]), 0, "{c}");
    assert_eq!(u(c, &["foreign"]), 0, "{c}");
    let received = u(c, &["received"]);
    assert!(
        received <= published && received * 100 >= published * 99,
        "{c} vs {published}"
    );
    assert_eq!(
        u(
            &report["collector"],
            &["received_by_key", "echelon/fast-circle/reference"]
        ),
        published,
        "the collector's reference samples against the leader's"
    );
    for k in 0..2 {
        let r = &report["robots"][k];
        assert!(f(r, &["final_error"]) < 1e-3, "{r}");
    }
    // And robot 1 really tracked the true circle.
    let late = late_error_of_robot_1(&fleet_dir);
    assert!(late < 5e-3, "{late}");
}

/// The control for `secure_mode_rogue_moves_no_robot`: the same rogue against
/// a fleet without security does reach the robots, so it is the secure mode
/// (certificates and access control) that stops it there.
#[test]
fn without_security_the_same_rogue_does_move_robots() {
    let _fleet = common::one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let fleet_dir = dir.path().join("fleet");
    let scenario = fixture("fast-circle.toml");
    // The rogue's reference jumps 5 m at 1 m/s: robot 1, between two
    // leaders, may spin past the divergence guard's 100 rad/s, command zero
    // and exit 1 (then `fleet up` fails naming it): that is moving it too.
    let fleet = std::thread::spawn({
        let fleet_dir = fleet_dir.clone();
        move || {
            Command::new(EXE)
                .args(["fleet", "up", &scenario, "--time-scale", "10", "--out"])
                .arg(&fleet_dir)
                .output()
                .unwrap()
        }
    });
    let endpoints = endpoints_of(&fleet_dir);
    assert!(endpoints.values().all(|e| e.starts_with("tcp/")));
    let fake = fake_reference(dir.path());
    let connect: Vec<String> = endpoints.values().cloned().collect();
    let plain = dir.path().join("plain.json5");
    std::fs::write(
        &plain,
        serde_json::json!({
            "mode": "peer",
            "scouting": {"multicast": {"enabled": false}},
            "listen": {"endpoints": ["tcp/127.0.0.1:0"]},
            "connect": {"endpoints": connect, "timeout_ms": 5000, "exit_on_failure": true},
        })
        .to_string(),
    )
    .unwrap();
    let mut rogue = rogue_leader(&fake, &plain);
    let out = fleet.join().unwrap();
    let _ = rogue.0.wait();
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        // Whichever robot the rogue's jump spins past the guard's bound
        // first (robot 1 behind the reference, or robot 2 behind it).
        let diverged = (1..=3).any(|k| {
            err.contains(&format!("robot/{k} exited"))
                && err.contains(&format!("agent {k} diverged at t = "))
        });
        assert!(diverged, "fleet up failed otherwise: {err}");
        return;
    }
    let report: Value = serde_json::from_str(
        &std::fs::read_to_string(fleet_dir.join("fleet-summary.json")).unwrap(),
    )
    .unwrap();
    let published = u(&report["leader"], &["published"]);
    let c = &report["robots"][0]["counters"];
    // A second sender on the reference key: the robot saw its samples.
    assert!(
        u(c, &["restarts"]) > 0 || u(c, &["received"]) > published + 2,
        "the rogue never reached robot 1: {c} (leader published {published})"
    );
    // And it pulled robot 1 off the true circle.
    let late = late_error_of_robot_1(&fleet_dir);
    assert!(
        late > 0.05,
        "robot 1 stayed on the circle ({late} m): the control shows nothing"
    );
}

/// A free loopback TCP endpoint.
fn free_endpoint() -> String {
    let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    format!("tcp/127.0.0.1:{}", l.local_addr().unwrap().port())
}

/// Router topology, started by hand as on a site: killing the router
/// (SIGKILL) mid-run cuts every link, so each robot loses its leader and
/// applies its link-loss policy (`stop`); a router started again on the same
/// endpoint is found by every client, which re-declares itself, and the
/// robots resume and converge; the collector records again.
#[test]
fn robots_lose_the_link_when_the_router_dies_and_resume_when_it_returns() {
    let _fleet = common::one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let ep = free_endpoint();
    let scenario = fixture("fast-circle-stop.toml");
    let out = dir.path().display().to_string();
    let router = || spawn(&["fleet", "router", "--listen", &ep]);
    let client = ["--mode", "client", "--connect", &ep];
    let run = ["--time-scale", "5", "--duration", "60"];
    let mut first_router = router();
    let collector = spawn(
        &[
            &["fleet", "collector", &scenario, "--out", &out][..],
            &client,
        ]
        .concat(),
    );
    let robots: Vec<Guard> = ["1", "2"]
        .iter()
        .map(|k| {
            spawn(
                &[
                    &["fleet", "robot", &scenario, "--agent", k][..],
                    &run,
                    &client,
                ]
                .concat(),
            )
        })
        .collect();
    let wait = [
        "--wait-for",
        "collector",
        "--wait-for",
        "robot/1",
        "--wait-for",
        "robot/2",
    ];
    let leader = spawn(&[&["fleet", "leader", &scenario][..], &run, &wait, &client].concat());
    // The leader starts its clock about a second after it is spawned; at ×5
    // the router dies near t = 10 s of fleet time and is back after about
    // 0.6 s of real time (3 s of fleet time, plus the clients' reconnection).
    std::thread::sleep(Duration::from_millis(3000));
    first_router.0.kill().unwrap();
    first_router.0.wait().unwrap();
    std::thread::sleep(Duration::from_millis(600));
    let second_router = router();
    let leader = leader.report();
    let robots: Vec<Value> = robots.into_iter().map(Guard::report).collect();
    std::thread::sleep(Duration::from_millis(300));
    collector.terminate();
    let collector = collector.report();
    second_router.terminate();
    let router_report = second_router.report();
    // Robot 1 follows the reference, robot 2 robot 1's state.
    let streams = [u(&leader, &["published"]), u(&robots[0], &["published"])];
    for (r, published) in robots.iter().zip(streams) {
        let c = &r["counters"];
        // The outage: the link was lost, and many samples never came.
        assert!(u(c, &["link_losses"]) >= 1, "{r}");
        assert!(u(c, &["received"]) + 50 < published, "{c} vs {published}");
        // Same leader all along, and it tracks again: converged at the end.
        assert_eq!(u(c, &["restarts"]), 0, "{c}");
        assert!(f(r, &["final_error"]) < 0.01, "{r}");
    }
    // The collector heard the robots again after the new router came up.
    assert!(u(&collector, &["received"]) > 0);
    let last = rows(&dir.path().join("trajectory.csv"))
        .iter()
        .map(|(t, _, _)| *t)
        .fold(0.0, f64::max);
    assert!(last > 55.0, "the collector's last row is at t = {last}");
    // Everyone came back through the second router.
    assert_eq!(u(&router_report, &["members_peak"]), 4, "{router_report}");
}

/// Two sites on loopback (`fleet up --sites 2`): two routers linked to each
/// other, robot 1 and the leader and collector on site 1, robot 2 on site 2.
/// Robot 2 follows robot 1 across the routers, and the collector on site 1
/// records robot 2: both converge.
#[test]
fn two_sites_two_routers_converge() {
    let _fleet = common::one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let report = up(
        &fixture("fast-circle.toml"),
        dir.path(),
        &["--time-scale", "10", "--sites", "2"],
    );
    assert_eq!(report["topology"], "router");
    assert_eq!(report["routers"].as_array().unwrap().len(), 2);
    assert_eq!(
        report["sites"][0],
        serde_json::json!(["collector", "robot/1", "leader"])
    );
    assert_eq!(report["sites"][1], serde_json::json!(["robot/2"]));
    for r in report["routers"].as_array().unwrap() {
        // Every process's liveliness token reached both routers.
        assert_eq!(u(r, &["members_peak"]), 4, "{r}");
    }
    for k in 0..2 {
        let r = &report["robots"][k];
        assert!(f(r, &["final_error"]) < 1e-3, "{r}");
        assert_eq!(u(&r["counters"], &["link_losses"]), 0, "{r}");
    }
    assert!(
        u(
            &report["collector"],
            &["received_by_key", "echelon/fast-circle/robot/2/state"]
        ) > 1000
    );
}

/// SIGTERM to a collector in the middle of a run: it exits cleanly and its
/// files read back.
#[test]
fn sigterm_leaves_valid_collector_files() {
    let _fleet = common::one_fleet_at_a_time();
    require_python_mcap();
    let dir = tempfile::tempdir().unwrap();
    let ports: Vec<u16> = (0..2)
        .map(|_| {
            std::net::TcpListener::bind("127.0.0.1:0")
                .unwrap()
                .local_addr()
                .unwrap()
                .port()
        })
        .collect();
    let (c_ep, l_ep) = (
        format!("tcp/127.0.0.1:{}", ports[0]),
        format!("tcp/127.0.0.1:{}", ports[1]),
    );
    let out = dir.path().display().to_string();
    let mut collector = spawn(&[
        "fleet",
        "collector",
        "experiment-circle",
        "--out",
        &out,
        "--listen",
        &c_ep,
    ]);
    let _leader = spawn(&[
        "fleet",
        "leader",
        "experiment-circle",
        "--time-scale",
        "10",
        "--listen",
        &l_ep,
        "--connect",
        &c_ep,
        "--wait-for",
        "collector",
    ]);
    // Let it record for a while, then SIGTERM.
    let mcap_path = dir.path().join("fleet.mcap");
    std::thread::sleep(Duration::from_millis(1500));
    let pid = collector.0.id().to_string();
    let kill = Command::new("kill").args(["-TERM", &pid]).status().unwrap();
    assert!(kill.success());
    let status = collector.0.wait().unwrap();
    assert!(status.success(), "{status}");
    let mut text = String::new();
    std::io::Read::read_to_string(collector.0.stdout.as_mut().unwrap(), &mut text).unwrap();
    let report: Value = serde_json::from_str(text.lines().last().unwrap()).unwrap();
    let received = u(&report, &["received"]);
    assert!(received > 10, "{report}");
    assert_eq!(u(&report, &["logged"]), received);
    let counts = mcap_counts(&mcap_path);
    assert_eq!(counts.values().sum::<u64>(), received);
    assert_eq!(python_mcap_counts(&mcap_path), counts);
}

/// `echelon run --mcap`: the same topics as a fleet, one message per logged
/// step and agent, and the same bytes twice.
#[test]
fn run_mcap_matches_the_csv_and_is_deterministic() {
    let _fleet = common::one_fleet_at_a_time();
    require_python_mcap();
    let dir = tempfile::tempdir().unwrap();
    let mut files = Vec::new();
    for name in ["a", "b"] {
        let out_dir = dir.path().join(name);
        echelon_ok(
            &[
                "run",
                "circle-pentagon",
                "--duration",
                "2",
                "--mcap",
                "--quiet",
                "--out",
            ],
            &out_dir,
        );
        files.push(out_dir);
    }
    let (a, b) = (
        std::fs::read(files[0].join("run.mcap")).unwrap(),
        std::fs::read(files[1].join("run.mcap")).unwrap(),
    );
    assert_eq!(a, b, "run.mcap is not deterministic");
    let csv = rows(&files[0].join("trajectory.csv"));
    let counts = mcap_counts(&files[0].join("run.mcap"));
    let agents = csv.iter().map(|r| r.1).max().unwrap();
    let steps = (csv.len() / agents) as u64;
    assert_eq!(counts["/reference"], steps);
    for k in 1..=agents {
        assert_eq!(counts[&format!("/agent/{k}/state")], steps);
    }
    assert_eq!(python_mcap_counts(&files[0].join("run.mcap")), counts);
}

/// Bad fleet input: one `error:` line, exit code 2, nothing started.
#[test]
fn bad_fleet_input_is_one_line_and_exit_2() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().display().to_string();
    let up = ["fleet", "up", "experiment-circle", "--out", &out];
    for args in [
        vec!["fleet", "robot", "experiment-circle", "--agent", "9"],
        [&up[..], &["--loss", "1.5"]].concat(),
        [&up[..], &["--outage", "3"]].concat(),
        [&up[..], &["--time-scale", "0"]].concat(),
        [&up[..], &["--sites", "3"]].concat(),
        [&up[..], &["--sites", "2", "--topology", "mesh"]].concat(),
        [&up[..], &["--topology", "star"]].concat(),
        vec!["fleet", "router", "--mode", "client"],
        vec!["fleet", "router", "--secure", &out],
        vec!["fleet", "collector", "--out", &out],
        vec!["fleet", "leader", "experiment-circle", "--fleet", "a/b"],
        vec!["fleet", "bench", "--robots", "10,0", "--out", &out],
        vec!["fleet", "bench", "--duration", "-1", "--out", &out],
        vec![
            "fleet",
            "robot",
            "experiment-circle",
            "--agent",
            "1",
            "--secure",
            &out,
        ],
    ] {
        let o = Command::new(EXE).args(&args).output().unwrap();
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{err}");
    }
    // Nothing written.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

/// A latency report's quantiles are ordered, in seconds, and count every
/// sample taken in (`count + unstamped`); fleet publishers all stamp.
fn check_latency(l: &Value, samples: u64, what: &str) {
    assert_eq!(
        u(l, &["count"]) + u(l, &["unstamped"]),
        samples,
        "{what}: {l}"
    );
    assert_eq!(u(l, &["unstamped"]), 0, "{what}: {l}");
    assert!(u(l, &["count"]) > 0, "{what}: {l}");
    let q = ["p50", "p95", "p99", "max"].map(|k| f(l, &[k]));
    assert!(
        q[0] > 0.0 && q.windows(2).all(|w| w[0] <= w[1]),
        "{what}: {q:?}"
    );
    // Loopback delays are well under a second (a stated, generous bound:
    // a wrong clock or unit would be off by orders of magnitude).
    assert!(q[3] < 1.0, "{what}: {q:?}");
}

/// `fleet up` measures every sample's delay (each robot's leader stream, the
/// collector in total and per key, the MCAP metadata record) and each
/// process's CPU seconds and peak memory, and tells startup from run.
#[test]
fn latency_and_cost_are_reported() {
    let _fleet = common::one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let fleet_dir = dir.path().join("fleet");
    let report = up(
        "circle-pentagon",
        &fleet_dir,
        &["--duration", "10", "--time-scale", "5"],
    );
    let mut robots_count = 0;
    for r in report["robots"].as_array().unwrap() {
        let received = u(r, &["counters", "received"]);
        check_latency(&r["latency"], received, "robot");
        robots_count += u(r, &["latency", "count"]);
    }
    assert_eq!(u(&report, &["latency", "robots", "count"]), robots_count);
    let worst = &report["latency"]["worst_robot"];
    let worst_p99 = f(worst, &["latency", "p99"]);
    for r in report["robots"].as_array().unwrap() {
        assert!(f(r, &["latency", "p99"]) <= worst_p99);
    }
    let col = &report["collector"];
    check_latency(&col["latency"], u(col, &["received"]), "collector");
    let by_key = counts_of(&col["received_by_key"]);
    let lat_keys = col["latency_by_key"].as_object().unwrap();
    assert_eq!(lat_keys.len(), by_key.len());
    for (key, n) in &by_key {
        check_latency(&lat_keys[key], *n, key);
    }
    assert_eq!(report["latency"]["collector"], col["latency"]);
    // The same per-key summaries in the MCAP file's metadata record.
    let bytes = std::fs::read(fleet_dir.join("fleet.mcap")).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    let index = summary
        .metadata_indexes
        .iter()
        .find(|m| m.name == "echelon.latency")
        .unwrap();
    let meta = mcap::read::metadata(&bytes, index).unwrap();
    assert_eq!(meta.metadata.len(), by_key.len());
    for (key, json) in &meta.metadata {
        let l: Value = serde_json::from_str(json).unwrap();
        assert_eq!(&l, &lat_keys[key]);
    }
    // Cost: every process used CPU and memory; startup ends before the run.
    let procs = report["cost"]["processes"].as_array().unwrap();
    // 4 robots, leader, collector and the router.
    assert_eq!(procs.len(), 4 + 2 + 1);
    assert_eq!(u(&report["cost"]["routers"], &["processes"]), 1);
    for p in procs {
        assert!(f(p, &["cpu"]) > 0.0, "{p}");
        assert!(u(p, &["max_rss"]) > 1 << 20, "{p}");
    }
    let robots = &report["cost"]["robots"];
    assert_eq!(u(robots, &["processes"]), 4);
    let mean = f(robots, &["cpu_mean"]);
    assert!((mean * 4.0 - f(robots, &["cpu"])).abs() < 1e-9 && mean <= f(robots, &["cpu_max"]));
    assert!(f(&report, &["cost", "total", "cpu"]) >= f(robots, &["cpu"]));
    let (startup, run, wall) = (
        f(&report, &["startup"]),
        f(&report, &["run"]),
        f(&report, &["wall"]),
    );
    assert!(startup > 0.0 && run > 0.0 && (startup + run - wall).abs() < 1e-6);
}

/// `fleet bench` with one small size: a row with no error, every robot
/// converged, ordered latencies, and the table in bench.json and bench.md.
#[test]
fn bench_smoke() {
    let _fleet = common::one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(EXE)
        .args([
            "fleet",
            "bench",
            "--robots",
            "2",
            "--duration",
            "4",
            "--out",
        ])
        .arg(dir.path())
        .output()
        .unwrap();
    check(&out, "fleet bench");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("| N | startup s |"), "{stdout}");
    let bench: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("bench.json")).unwrap())
            .unwrap();
    let row = &bench["rows"][0];
    assert!(row.get("error").is_none(), "{row}");
    assert_eq!(u(row, &["robots"]), 2);
    assert_eq!(u(row, &["converged"]), 2);
    assert_eq!(u(row, &["stale"]) + u(row, &["link_losses"]), 0);
    assert!(f(row, &["latency_p50"]) <= f(row, &["latency_p99"]));
    assert!(f(row, &["cpu_per_robot"]) > 0.0 && f(row, &["messages_per_s"]) > 0.0);
    // CPU per robot per minute of fleet time, and per message.
    let per_min = f(row, &["cpu_per_robot"]) / 4.0 * 60.0;
    assert!(
        (f(row, &["cpu_per_robot_per_min"]) - per_min).abs() < 1e-9,
        "{row}"
    );
    assert!(
        f(row, &["cpu_robot_max"]) >= f(row, &["cpu_per_robot"]),
        "{row}"
    );
    let us = f(row, &["cpu_collector"]) / u(row, &["collector_received"]) as f64 * 1e6;
    assert!(
        (f(row, &["collector_us_per_message"]) - us).abs() < 1e-6,
        "{row}"
    );
    assert!(f(row, &["router_us_per_message"]) > 0.0, "{row}");
    assert_eq!(
        u(row, &["collector_dropped"]) + u(row, &["collector_decimated"]),
        0
    );
    let md = std::fs::read_to_string(dir.path().join("bench.md")).unwrap();
    assert!(md.lines().any(|l| l.starts_with("| 2 |")), "{md}");
    assert!(dir.path().join("n002/fleet-summary.json").is_file());
}

/// `fleet up --log-rate HZ`: the collector logs at most HZ states per robot
/// per second of receipt time (the 1/HZ s bins it touches), counts the
/// others as decimated, and still logs every reference; the CSV has one row
/// per logged started state; nothing dropped.
#[test]
fn log_rate_decimates_the_collector_s_states() {
    let _fleet = common::one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let fleet_dir = dir.path().join("fleet");
    let report = up(
        "circle-pentagon",
        &fleet_dir,
        &["--duration", "10", "--time-scale", "5", "--log-rate", "4"],
    );
    let col = &report["collector"];
    let (received, logged, decimated) = (
        u(col, &["received"]),
        u(col, &["logged"]),
        u(col, &["decimated"]),
    );
    assert_eq!(u(col, &["dropped"]), 0, "{col}");
    assert!(decimated > 0, "{col}");
    assert_eq!(logged + decimated, received, "{col}");
    let by_topic = counts_of(&col["logged_by_topic"]);
    let by_key = counts_of(&col["received_by_key"]);
    // 10 fleet s at ×5: 2 s of receipt time (and the wind-down): at 4 Hz
    // a handful per robot, never the 100 Hz stream.
    let wall = f(&report, &["wall"]);
    for k in 1..=4 {
        let states = by_topic[&format!("/agent/{k}/state")];
        assert!(states >= 2, "{k}: {states}");
        assert!(
            states as f64 <= wall * 4.0 + 2.0,
            "{k}: {states} in {wall} s"
        );
        let sent = by_key[&format!("echelon/circle-pentagon/robot/{k}/state")];
        assert!(sent > 10 * states, "{k}: {sent} vs {states}");
    }
    assert_eq!(
        by_topic["/reference"],
        by_key["echelon/circle-pentagon/reference"]
    );
    let mcap_path = fleet_dir.join("fleet.mcap");
    assert_eq!(mcap_counts(&mcap_path), by_topic);
    let rows: u64 = col["agents"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| u(a, &["rows"]))
        .sum();
    assert_eq!(
        rows as usize,
        self::rows(&fleet_dir.join("trajectory.csv")).len()
    );
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
    let report = up(
        "crossing",
        &fleet_dir,
        // ×5, not ×10: at ×10 six robots at 100 Hz and the collector ask
        // 6000 ticks/s of two cores, ticks overrun (~120 per robot) and
        // neighbour states arrive a whole control period old, outside what
        // the decentralised split assumes (docs/fleet.md).
        &["--time-scale", "5", "--duration", "120"],
    );
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
    assert_eq!(u(safety, &["stale_brakes"]), 0, "{safety}");
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
