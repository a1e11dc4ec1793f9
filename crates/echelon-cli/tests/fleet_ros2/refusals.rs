//! ROS 2 settings and flags refused before anything starts.

use super::*;

/// A bad `[fleet.ros2]` value stops `fleet robot --ros2` and `fleet up
/// --ros2` before anything starts: one line naming file, line, column and
/// field, exit 2.
#[test]
fn a_bad_ros2_setting_is_refused_with_its_place() {
    let dir = tempfile::tempdir().unwrap();
    let src = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../scenarios/experiment-circle-velocity.toml"),
    )
    .unwrap();
    let line = src.lines().count() + 3;
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, format!("{src}\n[fleet.ros2]\ndomain_id = 300\n")).unwrap();
    let bad = bad.to_str().unwrap();
    let out_dir = dir.path().join("out");
    for args in [
        vec!["fleet", "robot", bad, "--agent", "1", "--ros2"],
        vec![
            "fleet",
            "up",
            bad,
            "--ros2",
            "--out",
            out_dir.to_str().unwrap(),
        ],
    ] {
        let out = Command::new(EXE).args(&args).output().unwrap();
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(
            err.contains(&format!(
                "{bad}:{line}:13: fleet.ros2.domain_id: 300 is not a ROS domain id"
            )),
            "{err}"
        );
    }
}

/// A robot driving a real ROS 2 base runs in real time: `--time-scale` is
/// refused (exit 2, one line) unless its base is `fleet base`'s simulation.
#[test]
fn a_real_robot_refuses_a_time_scale() {
    let out = Command::new(EXE)
        .args([
            "fleet",
            "robot",
            SCENARIO,
            "--agent",
            "1",
            "--ros2",
            "--time-scale",
            "10",
        ])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(
        err.contains("real time") && err.contains("--time-scale 10"),
        "{err}"
    );
}
