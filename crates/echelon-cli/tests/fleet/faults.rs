//! The fault matrix (`echelon fleet faults`, docs/faults.md), one test per
//! row: each fault injected into a simulated fleet over real Zenoh; every
//! affected robot's farthest travel from where the fault found it within
//! the bound its policy implies, the expected outcome (stop, hold then
//! follow, continue), and no robot left moving without a reference or
//! odometry. The rows' numbers are read back from `faults.json` and
//! checked here too, not only by the command's exit status.

use super::*;

/// Runs the row `name` at ×2 and checks what `faults.json` says of it.
fn row(name: &str) {
    let _fleet = common::one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("faults");
    let o = Command::new(EXE)
        .args([
            "fleet",
            "faults",
            "--only",
            name,
            "--time-scale",
            "2",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{}: {err}", o.status);
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("faults.json")).unwrap()).unwrap();
    let rows = report["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 1, "{report}");
    let r = &rows[0];
    assert_eq!(r["name"], name);
    assert_eq!(r["pass"], true, "{r}");
    let robots = r["robots"].as_array().unwrap();
    assert!(!robots.is_empty(), "{r}");
    for robot in robots {
        let a = &robot["aftermath"];
        let v = a["speed_at_fault"].as_f64().unwrap();
        // The robots cruised at the reference's 0.15 m/s when it hit.
        assert!((v - 0.15).abs() < 0.01, "{robot}");
        let farthest = a["farthest"].as_f64().unwrap();
        if let Some(bound) = robot["bound"].as_f64() {
            assert!(farthest <= bound, "{robot}");
            // A bound is not vacuous: within a few times what it measured.
            assert!(bound < 4.0 * farthest + 0.05, "{robot}");
        }
        match r["outcome"].as_str().unwrap() {
            "unaffected" => {
                assert_eq!(robot["link"], "tracking", "{robot}");
                if name == "garbage" {
                    assert!(robot["refused"].as_u64().unwrap() > 0, "{robot}");
                }
                assert!(robot["bound"].is_null(), "{robot}");
            }
            "continue" => assert_eq!(robot["link"], "tracking", "{robot}"),
            "hold" => assert_eq!(robot["link"], "tracking", "{robot}: follows again"),
            _ => assert_eq!(a["moving_at_end"], false, "{robot}"),
        }
    }
    let md = std::fs::read_to_string(out.join("faults.md")).unwrap();
    assert!(md.contains(&format!("| `{name}` |")), "{md}");
}

#[test]
fn leader_killed_under_stop() {
    row("leader-kill-stop");
}

#[test]
fn leader_killed_under_extrapolate() {
    row("leader-kill-extrapolate");
}

#[test]
fn robot_killed() {
    row("robot-kill");
}

#[test]
fn robot_killed_over_a_ros2_base() {
    row("robot-kill-ros2");
}

#[test]
fn base_killed_under_its_robot() {
    row("base-kill-ros2");
}

#[test]
fn robot_partitioned_for_a_third_of_a_second() {
    row("partition-0.3s");
}

#[test]
fn robot_partitioned_for_3_s() {
    row("partition-3s");
}

#[test]
fn robot_partitioned_for_30_s() {
    row("partition-30s");
}

#[test]
fn router_killed_and_restarted() {
    row("router-restart");
}

#[test]
fn wall_clock_stepped_forward() {
    row("clock-jump-forward");
}

#[test]
fn wall_clock_stepped_back() {
    row("clock-jump-back");
}

#[test]
fn garbage_and_replays_on_every_key() {
    row("garbage");
}

#[test]
fn odometry_frozen() {
    row("odometry-freeze");
}

#[test]
fn operator_heartbeat_lost() {
    row("heartbeat-lost");
}

/// An unknown row is refused with the list of rows (exit 2), nothing run.
#[test]
fn an_unknown_row_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let o = Command::new(EXE)
        .args(["fleet", "faults", "--only", "no-such-row", "--out"])
        .arg(dir.path().join("f"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{o:?}");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("leader-kill-stop") && err.contains("heartbeat-lost"),
        "{err}"
    );
    assert!(!dir.path().join("f").exists());
}

#[test]
fn collector_killed() {
    row("collector-kill");
}

#[test]
fn a_second_fleet_of_the_same_name() {
    row("second-fleet");
}
