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

#[path = "../common/mod.rs"]
mod common;
mod dashboard;
mod live;
mod run;

use common::{check, echelon_ok, one_fleet_at_a_time};

/// Poses: the CSV and the 3D channels both carry the f64 values themselves
/// (the CSV in shortest round-trip form, protobuf as doubles), so they agree
/// to rounding of the quaternion's half-angle trigonometry only.
const POSITION_TOLERANCE: f64 = 1e-9;

const HEADING_TOLERANCE: f64 = 1e-9;

fn script(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../scripts/foxglove")
        .join(name)
}

/// `read_3d.py`'s JSON of `mcap`.
fn read_3d(mcap: &Path) -> Value {
    let out = Command::new("python3")
        .arg(script("read_3d.py"))
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
/// published classes do (`schemas`: topic → [message encoding, schema name,
/// schema encoding, same definition]).
fn check_schemas(schemas: &Value) {
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

/// Robot `k` of an entity id or child frame `robotK…`.
fn robot_of(id: &str) -> Option<u64> {
    let rest = id.strip_prefix("robot")?;
    let digits = rest.split('/').next()?;
    digits.parse().ok()
}

/// Every state (t, agent, x, y, θ), in order per robot, has its transform
/// `world` → `robotK/base_link` stamped t with that position and heading
/// and its body at that position, in the same order; there are no others.
fn check_poses(read: &Value, states: &[(f64, u64, f64, f64, f64)]) {
    let mut tf: BTreeMap<u64, Vec<(f64, f64, f64, f64)>> = BTreeMap::new();
    for e in read["tf"].as_array().unwrap() {
        let frame = e[1].as_str().unwrap();
        assert_eq!(e[2], "world");
        assert!(frame.ends_with("/base_link"), "{frame}");
        let k = robot_of(frame).unwrap_or_else(|| panic!("child frame {frame}"));
        assert_eq!(num(&e[5]), 0.0);
        tf.entry(k)
            .or_default()
            .push((num(&e[0]), num(&e[3]), num(&e[4]), num(&e[6])));
    }
    let mut bodies: BTreeMap<u64, Vec<(f64, f64)>> = BTreeMap::new();
    for e in read["scene"].as_array().unwrap() {
        let id = e[1].as_str().unwrap();
        if let Some(k) = id.strip_prefix("robot").and_then(|k| k.parse::<u64>().ok()) {
            bodies.entry(k).or_default().push((num(&e[2]), num(&e[3])));
        }
    }
    let mut by_robot: BTreeMap<u64, Vec<(f64, f64, f64, f64)>> = BTreeMap::new();
    for &(t, k, x, y, theta) in states {
        by_robot.entry(k).or_default().push((t, x, y, theta));
    }
    assert_eq!(
        tf.keys().collect::<Vec<_>>(),
        by_robot.keys().collect::<Vec<_>>()
    );
    for (k, want) in &by_robot {
        let (got, body) = (&tf[k], &bodies[k]);
        assert_eq!(got.len(), want.len(), "robot {k}: one transform per state");
        assert_eq!(body.len(), want.len(), "robot {k}: one body per state");
        for ((&(tt, tx, ty, tyaw), &(t, x, y, theta)), &b) in got.iter().zip(want).zip(body) {
            assert!(
                (tt - t).abs() < 1e-9,
                "robot {k}: transform at {tt}, state at {t}"
            );
            assert!(
                (tx - x).abs() <= POSITION_TOLERANCE && (ty - y).abs() <= POSITION_TOLERANCE,
                "robot {k} at {t}: transform ({tx}, {ty}), state ({x}, {y})"
            );
            assert!(
                angle_diff(tyaw, theta).abs() <= HEADING_TOLERANCE,
                "robot {k} at {t}: yaw {tyaw}, θ {theta}"
            );
            assert_eq!(b, (tx, ty), "robot {k} at {t}: body");
        }
    }
}

/// A free loopback address, `127.0.0.1:PORT`.
fn free_addr() -> String {
    let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    l.local_addr().unwrap().to_string()
}

/// `fleet up` into `dir` with `extra` arguments; fleet-summary.json.
fn up(dir: &Path, extra: &[&str]) -> Value {
    let fixed = [
        "experiment-circle",
        "--duration",
        "20",
        "--time-scale",
        "5",
        "--quiet",
    ];
    common::fleet_up(&[&fixed[..], extra].concat(), dir)
}
