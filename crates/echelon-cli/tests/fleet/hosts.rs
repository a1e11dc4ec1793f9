//! Robots many to a process (`fleet up --robots-per-process`, `fleet
//! host`): the run reports each robot as its own process would, and what
//! must keep a process per robot is refused before anything starts. That
//! K hosted robots publish what K processes do is shown on the fake clock
//! (`echelon-fleet`'s `host::tests`).

use super::*;

/// circle-pentagon's four robots in two processes (3 + 1): every robot is
/// reported, in agent order, converged as in four processes; the cost
/// counts four robots in two processes; the hosts' logs are named
/// after their robots.
#[test]
fn hosted_robots_report_as_robots() {
    let _fleet = common::one_fleet_at_a_time();
    let (_a, _, alone) = pentagon_up(&[]);
    let (_h, fleet_dir, hosted) = pentagon_up(&["--robots-per-process", "3"]);
    let robots = hosted["robots"].as_array().unwrap();
    assert_eq!(robots.len(), 4);
    for (i, r) in robots.iter().enumerate() {
        assert_eq!(u(r, &["agent"]), i as u64 + 1);
        let (e, e_alone) = (
            f(r, &["final_error"]),
            f(&alone["robots"][i], &["final_error"]),
        );
        // Real time on a shared machine: the same convergence, within a
        // stated margin (a robot that did not run would be metres off).
        assert!(
            e < 2.0 * e_alone + 5e-3,
            "robot {}: {e} vs {e_alone}",
            i + 1
        );
        assert_eq!(u(r, &["counters", "link_losses"]), 0, "{r}");
    }
    assert_eq!(u(&hosted, &["cost", "robot_count"]), 4);
    assert_eq!(u(&hosted, &["cost", "robots", "processes"]), 2);
    assert_eq!(u(&alone, &["cost", "robots", "processes"]), 4);
    let per_robot = f(&hosted, &["cost", "cpu_per_robot"]);
    assert!((per_robot * 4.0 - f(&hosted, &["cost", "robots", "cpu"])).abs() < 1e-9);
    for log in ["robots-1-3.log", "robot-4.log"] {
        assert!(fleet_dir.join("logs").join(log).is_file(), "{log}");
    }
}

/// What keeps a process per robot refuses `--robots-per-process` above 1
/// (exit 2, the reason named, nothing started); `fleet host` refuses a
/// bad list and an agent the scenario lacks.
#[test]
fn robots_that_keep_a_process_each_are_refused_a_host() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("f");
    let cases: [(&[&str], &str); 3] = [
        (&["--topology", "mesh"], "in a mesh"),
        (&["--ros2"], "ROS 2"),
        (&[], "at least one robot"),
    ];
    for (extra, why) in cases {
        let k = if extra.is_empty() { "0" } else { "2" };
        let o = Command::new(EXE)
            .args([
                "fleet",
                "up",
                "circle-pentagon",
                "--robots-per-process",
                k,
                "--out",
            ])
            .arg(&out)
            .args(extra)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{extra:?}: {err}");
        assert!(err.contains(why), "{extra:?}: {err}");
        assert!(!out.join("logs").exists(), "{extra:?}: something started");
    }
    for (robots, why) in [
        ("3-1", "backwards"),
        ("1,1", "twice"),
        ("0", "from 1"),
        ("1-9", "agents 1..=4"),
    ] {
        let o = Command::new(EXE)
            .args(["fleet", "host", "circle-pentagon", "--robots", robots])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{robots}: {err}");
        assert!(err.contains(why), "{robots}: {err}");
    }
}
