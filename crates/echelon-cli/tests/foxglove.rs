#![allow(clippy::unwrap_used)]
//! The 3D channels (`/tf`, `/scene`, `/scene/static`: Foxglove's
//! well-known schemas) of `echelon run --mcap` and of the fleet collector's
//! `fleet.mcap`, read back by an independent reader: Python's `mcap` and
//! Foxglove's published protobuf classes (`scripts/foxglove/read_3d.py`;
//! `scripts/test` installs both).

use std::collections::BTreeMap;
use std::f64::consts::{PI, TAU};
use std::path::Path;
use std::process::Command;

use serde_json::Value;

mod common;

use common::{check, echelon_ok};

/// Poses: the CSV and the 3D channels both carry the f64 values themselves
/// (the CSV in shortest round-trip form, protobuf as doubles), so they agree
/// to rounding of the quaternion's half-angle trigonometry only.
const POSITION_TOLERANCE: f64 = 1e-9;
const HEADING_TOLERANCE: f64 = 1e-9;

/// `read_3d.py`'s JSON of `mcap`.
fn read_3d(mcap: &Path) -> Value {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scripts/foxglove/read_3d.py");
    let out = Command::new("python3")
        .arg(&script)
        .arg(mcap)
        .output()
        .unwrap_or_else(|e| panic!("python3: {e}"));
    check(
        &out,
        "read_3d.py (needs `python3 -m pip install -r scripts/requirements-test.txt`)",
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

/// `a − b` wrapped to (−π, π].
fn angle_diff(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(TAU);
    if d > PI { d - TAU } else { d }
}

fn num(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

/// The 3D channels' schemas are Foxglove's well-known ones: protobuf, named
/// as Foxglove names them, and defining the messages exactly as Foxglove's
/// published classes do.
fn check_schemas(read: &Value) {
    let schemas = &read["schemas"];
    for (topic, name) in [
        ("/tf", "foxglove.FrameTransforms"),
        ("/scene", "foxglove.SceneUpdate"),
        ("/scene/static", "foxglove.SceneUpdate"),
    ] {
        assert_eq!(
            schemas[topic],
            serde_json::json!(["protobuf", name, "protobuf", true]),
            "{topic}: {schemas}"
        );
    }
}

/// Every state (t, agent, x, y, θ) has exactly one transform `world` →
/// `robotK/base_link` stamped t with that position and heading, and one
/// body entity at that position; there are no others.
fn check_poses(read: &Value, states: &[(f64, u64, f64, f64, f64)]) {
    let key = |t: f64, k: u64| ((t * 1e9).round() as u64, k);
    let mut tf = BTreeMap::new();
    for e in read["tf"].as_array().unwrap() {
        let frame = e[1].as_str().unwrap();
        assert_eq!(e[2], "world");
        let k: u64 = frame
            .strip_prefix("robot")
            .and_then(|f| f.strip_suffix("/base_link"))
            .unwrap_or_else(|| panic!("child frame {frame}"))
            .parse()
            .unwrap();
        assert_eq!(num(&e[5]), 0.0);
        let old = tf.insert(key(num(&e[0]), k), (num(&e[3]), num(&e[4]), num(&e[6])));
        assert!(old.is_none(), "two transforms of robot {k} at {}", e[0]);
    }
    let mut bodies = BTreeMap::new();
    for e in read["scene"].as_array().unwrap() {
        let id = e[1].as_str().unwrap();
        if let Some(k) = id.strip_prefix("robot").and_then(|k| k.parse::<u64>().ok()) {
            bodies.insert(key(num(&e[0]), k), (num(&e[2]), num(&e[3])));
        }
    }
    assert_eq!(tf.len(), states.len(), "one transform per state");
    assert_eq!(bodies.len(), states.len(), "one body per state");
    for &(t, k, x, y, theta) in states {
        let &(tx, ty, tyaw) = tf
            .get(&key(t, k))
            .unwrap_or_else(|| panic!("no transform of robot {k} at {t}"));
        assert!(
            (tx - x).abs() <= POSITION_TOLERANCE && (ty - y).abs() <= POSITION_TOLERANCE,
            "robot {k} at {t}: transform ({tx}, {ty}), state ({x}, {y})"
        );
        assert!(
            angle_diff(tyaw, theta).abs() <= HEADING_TOLERANCE,
            "robot {k} at {t}: yaw {tyaw}, θ {theta}"
        );
        assert_eq!(bodies[&key(t, k)], (tx, ty));
    }
}

/// `echelon run --mcap`: the 3D channels carry Foxglove's schemas, and each
/// robot's transform and body equal trajectory.csv's pose at every logged
/// step; the fixed scene holds the reference path and each obstacle.
#[test]
fn run_mcap_3d_channels_are_foxglove_and_match_the_csv() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    echelon_ok(
        &[
            "run",
            "obstacle-slalom",
            "--duration",
            "2",
            "--mcap",
            "--quiet",
            "--out",
        ],
        &out,
    );
    let read = read_3d(&out.join("run.mcap"));
    check_schemas(&read);
    let csv = std::fs::read_to_string(out.join("trajectory.csv")).unwrap();
    let states: Vec<(f64, u64, f64, f64, f64)> = csv
        .lines()
        .skip(1)
        .map(|l| {
            let v: Vec<&str> = l.split(',').collect();
            let n = |i: usize| v[i].parse::<f64>().unwrap();
            (n(0), v[1].parse().unwrap(), n(2), n(3), n(4))
        })
        .collect();
    assert!(!states.is_empty());
    check_poses(&read, &states);
    let run = echelon::scenario::Scenario::builtin("obstacle-slalom")
        .unwrap()
        .build(&echelon::scenario::Overrides::default())
        .unwrap();
    let obstacles = run.plan.obstacles().len();
    assert!(obstacles > 0);
    let mut want = vec!["reference".to_owned()];
    want.extend((1..=obstacles).map(|i| format!("obstacle/{i}")));
    assert_eq!(read["static"], serde_json::json!(want));
    // Each leader link starts at its robot.
    for l in read["links"].as_array().unwrap() {
        let k: u64 = l[1].as_str().unwrap()["robot".len()..]
            .trim_end_matches("/link")
            .parse()
            .unwrap();
        let t = num(&l[0]);
        let s = states
            .iter()
            .find(|s| s.1 == k && (s.0 - t).abs() < 1e-9)
            .unwrap();
        assert_eq!((num(&l[2]), num(&l[3])), (s.2, s.3));
    }
}
