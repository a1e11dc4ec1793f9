//! The leader killed (SIGKILL) mid-run under `fleet up`: the fleet is not
//! torn down; each robot holds under its link-loss policy (here
//! `extrapolate`, 4 s then 0.2 m/s²), comes to rest and runs to
//! `--duration` on its own clock; `fleet up` then reports the leader's
//! death (exit 1, `leader_failure` in `fleet-summary.json`) with every
//! robot's report.

use super::*;

/// The pid of the process whose command line holds `needle` (Linux: `/proc`).
fn pid_with(needle: &str) -> Option<u32> {
    std::fs::read_dir("/proc").ok()?.find_map(|e| {
        let e = e.ok()?;
        let pid: u32 = e.file_name().to_str()?.parse().ok()?;
        let cmd = std::fs::read(e.path().join("cmdline")).ok()?;
        let cmd = String::from_utf8_lossy(&cmd).replace('\0', " ");
        cmd.contains(needle).then_some(pid)
    })
}

#[test]
fn the_fleet_outlives_its_leader() {
    let _fleet = common::one_fleet_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let scenario = dir.path().join("circle.toml");
    std::fs::write(&scenario, include_str!("fast-circle.toml")).unwrap();
    let scenario = scenario.to_str().unwrap().to_owned();
    let out = dir.path().join("fleet");
    let up = common::fleet_up_in_background(
        &[
            &scenario,
            "--time-scale",
            "10",
            "--duration",
            "40",
            "--quiet",
        ],
        &out,
    );
    // The leader, once the robots follow it (about 10 fleet seconds in).
    let needle = format!("fleet leader {scenario}");
    let started = std::time::Instant::now();
    let pid = loop {
        if let Some(pid) = pid_with(&needle) {
            break pid;
        }
        assert!(
            started.elapsed() < Duration::from_secs(20),
            "no leader process"
        );
        std::thread::sleep(Duration::from_millis(50));
    };
    std::thread::sleep(Duration::from_millis(2500));
    let killed = Command::new("kill")
        .args(["-9", &pid.to_string()])
        .status()
        .unwrap();
    assert!(killed.success());
    let o = up.join().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("the leader died mid-run"), "{err}");
    let s = common::fleet_summary(&out);
    assert!(s["leader"].is_null(), "{}", s["leader"]);
    assert!(
        s["leader_failure"]
            .as_str()
            .is_some_and(|f| f.contains("leader")),
        "{s}"
    );
    let robots = s["robots"].as_array().unwrap();
    assert_eq!(robots.len(), 2);
    // Robot 1 lost its leader stream (the reference) and held; robot 2
    // follows robot 1, whose stream never stopped.
    assert!(
        f(&robots[0], &["counters", "link_losses"]) >= 1.0,
        "{}",
        robots[0]
    );
    for r in robots {
        // Both came to rest.
        let v = r["final_state"][3].as_f64().unwrap();
        assert!(v.abs() < 1e-3, "still moving at the end: {r}");
        // It ran to the end on its own clock.
        assert!(f(r, &["t"]) >= 39.0, "{r}");
    }
}
