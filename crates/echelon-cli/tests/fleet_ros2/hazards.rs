//! `fleet up --ros2 --hazard`: a simulated base reports a BUMP (and another
//! an e-stop) on the scenario's `hazards` (`estop`) topic, as a Create 3
//! would: that robot stops and pauses the whole fleet, which stays paused
//! (nobody resumes) with every base at rest; the reports, the summary's
//! base-safety counts and the robot's stderr say so.

use super::*;

#[test]
fn a_bump_on_a_simulated_base_pauses_the_fleet() {
    let _fleet = common::one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let scenario = dir.path().join("hazards.toml");
    let base = echelon::scenario::Scenario::builtin(SCENARIO).unwrap();
    let toml = format!(
        "{}\n[fleet.ros2]\nhazards = \"hazard_detection\"\nestop = \"platform/emergency_stop\"\n",
        base.source()
    );
    std::fs::write(&scenario, toml).unwrap();
    let out = dir.path().join("fleet");
    let up = common::fleet_up(
        &[
            &[scenario.to_str().unwrap()],
            &UP_ROS2[1..],
            &[
                "--hazard",
                "2:BUMP@10+3",
                "--hazard",
                "1:EMERGENCY_STOP@20+2",
            ],
        ]
        .concat(),
        &out,
    );
    let robots = up["robots"].as_array().unwrap();
    for r in robots {
        // Paused from the bump on, to the end: nobody resumed.
        assert!(f(r, &["commands", "stops"]) >= 1.0, "{r}");
        assert_eq!(r["link"], "stopped", "{r}");
        assert_eq!(f(r, &["hazards", "counts", "hazard_refused"]), 0.0, "{r}");
        assert!(
            f(r, &["hazards", "counts", "hazard_received"]) > 100.0,
            "{r}"
        );
    }
    let events = |k: usize| r_events(&robots[k]);
    let bump = events(1);
    assert_eq!(bump.len(), 1, "{bump:?}");
    let (name, at, cleared) = &bump[0];
    assert_eq!(name, "BUMP");
    // The base's window is on its own clock, which starts with the fleet,
    // a moment (here ×10) before the leader's: the robot's fleet time of
    // the onset is earlier by that moment.
    assert!((4.0..=10.5).contains(at), "{at}");
    assert!(
        cleared.is_some_and(|c| (c - at - 3.0).abs() < 0.3),
        "{cleared:?}"
    );
    let estop = events(0);
    assert_eq!(estop.len(), 1, "{estop:?}");
    assert_eq!(estop[0].0, "EMERGENCY_STOP");
    // Every base at rest at the end, its last command zero.
    for b in up["bases"].as_array().unwrap() {
        assert_eq!(b["last_command"], serde_json::json!([0.0, 0.0]), "{b}");
        let v = b["final_state"][3].as_f64().unwrap();
        assert!(v.abs() < 1e-6, "{b}");
    }
    // The stop robot 2 put names it and the hazard; it said so on stderr.
    let log = std::fs::read_to_string(out.join("logs").join("robot-2.log")).unwrap_or_default();
    assert!(
        log.contains("fleet stop put: agent 2 (robot 2): its base reports BUMP"),
        "{log}"
    );
}

/// A robot report's hazard events: (name, onset, clearing).
fn r_events(r: &Value) -> Vec<(String, f64, Option<f64>)> {
    r["hazards"]["events"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| {
            (
                e["hazard"].as_str().unwrap().to_owned(),
                e["at"].as_f64().unwrap(),
                e["cleared"].as_f64(),
            )
        })
        .collect()
}
