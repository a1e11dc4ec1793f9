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

#[path = "../common/mod.rs"]
mod common;
mod converge;
mod faults;
mod hosts;
mod hub;
mod leader_death;
mod recording;
mod reports;
mod routers;
mod secure;
mod status;
mod twice;

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
    common::fleet_up(&[&[scenario], extra].concat(), dir)
}

/// `fleet up circle-pentagon` for 10 fleet s at ×5 (and `extra`) into a
/// new directory: the directory (removed when dropped), the fleet's output
/// in it and its fleet-summary.json.
fn pentagon_up(extra: &[&str]) -> (tempfile::TempDir, PathBuf, Value) {
    let dir = tempfile::tempdir().unwrap();
    let fleet_dir = dir.path().join("fleet");
    let fixed = ["--duration", "10", "--time-scale", "5"];
    let report = up("circle-pentagon", &fleet_dir, &[&fixed[..], extra].concat());
    (dir, fleet_dir, report)
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
/// channels, Foxglove's protobuf schemas, are checked in tests/foxglove/).
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

fn counts_of(v: &Value) -> BTreeMap<String, u64> {
    v.as_object()
        .unwrap()
        .iter()
        .map(|(k, v)| (k.clone(), v.as_u64().unwrap()))
        .collect()
}
