//! Every scenario under `examples/` (any depth) parses, builds without a
//! warning, resolves its `[fleet]` section (ROS 2 links included) and
//! round-trips, so the examples the docs point to cannot rot. The real-robot
//! examples (`examples/real-robots/`, docs/real-robots.md) also say how
//! each robot is reached: a `[fleet.ros2]` section, a per-agent `ros2`, and
//! velocity bases under the kinematic law.
#![allow(clippy::unwrap_used)] // tests fail loudly by design

mod common;

use std::path::{Path, PathBuf};

use echelon::scenario::{Overrides, Scenario};

fn examples_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples")
}

/// Every `.toml` under `dir`, sorted.
fn tomls(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap_or_else(|e| panic!("{}: {e}", d.display())) {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|e| e == "toml") {
                out.push(path);
            }
        }
    }
    out.sort();
    out
}

#[test]
fn every_example_parses_builds_resolves_its_fleet_and_round_trips() {
    let files = tomls(&examples_dir());
    assert!(files.len() >= 3, "examples found: {files:?}");
    for path in &files {
        let s = common::load_clean_scenario(path);
        let fleet = s.fleet().unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(fleet.ros2.len(), s.file.agents.len(), "{}", path.display());
    }
}

#[test]
fn the_real_robot_examples_say_how_each_robot_is_reached() {
    let files = tomls(&examples_dir().join("real-robots"));
    assert!(files.len() >= 3, "real-robot examples: {files:?}");
    for path in &files {
        let s = Scenario::load(path).unwrap_or_else(|e| panic!("{e}"));
        let at = path.display();
        assert!(s.file.fleet.ros2.is_some(), "{at}: no [fleet.ros2]");
        assert!(
            s.file.agents.iter().any(|a| a.ros2.is_some()),
            "{at}: no agent's own ros2"
        );
        // Every robot's own router is named: `fleet up --ros2 --real` runs them.
        for (k, link) in s.fleet().unwrap().ros2.iter().enumerate() {
            assert!(
                !link.connect.is_empty(),
                "{at}: agent {} has no connect",
                k + 1
            );
        }
        let run = s.build(&Overrides::default()).unwrap();
        for (k, agent) in run.plan.agents().iter().enumerate() {
            assert!(
                agent.velocity_robot().is_some(),
                "{at}: agent {} is not a velocity base (a ROS 2 robot takes velocities)",
                k + 1
            );
        }
    }
}
