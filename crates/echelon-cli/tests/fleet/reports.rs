//! What `fleet up` and `fleet bench` report (latency, cost, the bench table),
//! and bad input refused in one line.

use super::*;

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
    let (_dir, fleet_dir, report) = pentagon_up(&[]);
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
            "--hosts",
            "1,3",
            "--out",
        ])
        .arg(dir.path())
        .output()
        .unwrap();
    check(&out, "fleet bench");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("| N | robot procs | startup s |"),
        "{stdout}"
    );
    let bench: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("bench.json")).unwrap())
            .unwrap();
    let row = &bench["rows"][0];
    assert!(row.get("error").is_none(), "{row}");
    assert_eq!(u(row, &["robot_processes"]), 2);
    // The floor (a bare 100 Hz process, 4 s), and the row against it.
    let floor = f(&bench, &["floor_per_min"]);
    assert!(
        floor > 0.0 && u(&bench, &["floor", "wakes"]) > 300,
        "{bench}"
    );
    let over = f(row, &["cpu_over_floor"]);
    assert!((over - f(row, &["cpu_per_robot_per_min"]) / floor).abs() < 1e-9);
    // Hosts of 1 and 3 robots: the slope between them.
    let hosts = bench["hosts"].as_array().unwrap();
    assert_eq!(hosts.len(), 2);
    for h in hosts {
        assert_eq!(u(h, &["converged"]), u(h, &["robots"]), "{h}");
    }
    let slope = (f(&hosts[1], &["cpu_per_min"]) - f(&hosts[0], &["cpu_per_min"])) / 2.0;
    assert!((f(&bench, &["marginal_per_robot_per_min"]) - slope).abs() < 1e-9);
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
