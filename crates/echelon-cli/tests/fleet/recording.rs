//! What the collector and `echelon run --mcap` write: files valid after a
//! SIGTERM, deterministic MCAP, decimation by `--log-rate`.

use super::*;

/// SIGTERM to a collector in the middle of a run: it exits cleanly and its
/// files read back.
#[test]
fn sigterm_leaves_valid_collector_files() {
    let _fleet = common::one_fleet_at_a_time();
    require_python_mcap();
    let dir = tempfile::tempdir().unwrap();
    let ports: Vec<u16> = (0..2)
        .map(|_| {
            std::net::TcpListener::bind("127.0.0.1:0")
                .unwrap()
                .local_addr()
                .unwrap()
                .port()
        })
        .collect();
    let (c_ep, l_ep) = (
        format!("tcp/127.0.0.1:{}", ports[0]),
        format!("tcp/127.0.0.1:{}", ports[1]),
    );
    let out = dir.path().display().to_string();
    let mut collector = spawn(&[
        "fleet",
        "collector",
        "experiment-circle",
        "--out",
        &out,
        "--listen",
        &c_ep,
    ]);
    let _leader = spawn(&[
        "fleet",
        "leader",
        "experiment-circle",
        "--time-scale",
        "10",
        "--listen",
        &l_ep,
        "--connect",
        &c_ep,
        "--wait-for",
        "collector",
    ]);
    // Let it record for a while, then SIGTERM.
    let mcap_path = dir.path().join("fleet.mcap");
    std::thread::sleep(Duration::from_millis(1500));
    let pid = collector.0.id().to_string();
    let kill = Command::new("kill").args(["-TERM", &pid]).status().unwrap();
    assert!(kill.success());
    let status = collector.0.wait().unwrap();
    assert!(status.success(), "{status}");
    let mut text = String::new();
    std::io::Read::read_to_string(collector.0.stdout.as_mut().unwrap(), &mut text).unwrap();
    let report: Value = serde_json::from_str(text.lines().last().unwrap()).unwrap();
    let received = u(&report, &["received"]);
    assert!(received > 10, "{report}");
    assert_eq!(u(&report, &["logged"]), received);
    let counts = mcap_counts(&mcap_path);
    assert_eq!(counts.values().sum::<u64>(), received);
    assert_eq!(python_mcap_counts(&mcap_path), counts);
}

/// `echelon run --mcap`: the same topics as a fleet, one message per logged
/// step and agent, and the same bytes twice.
#[test]
fn run_mcap_matches_the_csv_and_is_deterministic() {
    let _fleet = common::one_fleet_at_a_time();
    require_python_mcap();
    let dir = tempfile::tempdir().unwrap();
    let mut files = Vec::new();
    for name in ["a", "b"] {
        let out_dir = dir.path().join(name);
        echelon_ok(
            &[
                "run",
                "circle-pentagon",
                "--duration",
                "2",
                "--mcap",
                "--quiet",
                "--out",
            ],
            &out_dir,
        );
        files.push(out_dir);
    }
    let (a, b) = (
        std::fs::read(files[0].join("run.mcap")).unwrap(),
        std::fs::read(files[1].join("run.mcap")).unwrap(),
    );
    assert_eq!(a, b, "run.mcap is not deterministic");
    let csv = rows(&files[0].join("trajectory.csv"));
    let counts = mcap_counts(&files[0].join("run.mcap"));
    let agents = csv.iter().map(|r| r.1).max().unwrap();
    let steps = (csv.len() / agents) as u64;
    assert_eq!(counts["/reference"], steps);
    for k in 1..=agents {
        assert_eq!(counts[&format!("/agent/{k}/state")], steps);
    }
    assert_eq!(python_mcap_counts(&files[0].join("run.mcap")), counts);
}

/// `fleet up --log-rate HZ`: the collector logs at most HZ states per robot
/// per second of receipt time (the 1/HZ s bins it touches), counts the
/// others as decimated, and still logs every reference; the CSV has one row
/// per logged started state; nothing dropped.
#[test]
fn log_rate_decimates_the_collector_s_states() {
    let _fleet = common::one_fleet_at_a_time();
    let (_dir, fleet_dir, report) = pentagon_up(&["--log-rate", "4"]);
    let col = &report["collector"];
    let (received, logged, decimated) = (
        u(col, &["received"]),
        u(col, &["logged"]),
        u(col, &["decimated"]),
    );
    assert_eq!(u(col, &["dropped"]), 0, "{col}");
    assert!(decimated > 0, "{col}");
    assert_eq!(logged + decimated, received, "{col}");
    let by_topic = counts_of(&col["logged_by_topic"]);
    let by_key = counts_of(&col["received_by_key"]);
    // 10 fleet s at ×5: 2 s of receipt time (and the wind-down): at 4 Hz
    // a handful per robot, never the 100 Hz stream.
    let wall = f(&report, &["wall"]);
    for k in 1..=4 {
        let states = by_topic[&format!("/agent/{k}/state")];
        assert!(states >= 2, "{k}: {states}");
        assert!(
            states as f64 <= wall * 4.0 + 2.0,
            "{k}: {states} in {wall} s"
        );
        let sent = by_key[&format!("echelon/circle-pentagon/robot/{k}/state")];
        assert!(sent > 10 * states, "{k}: {sent} vs {states}");
    }
    assert_eq!(
        by_topic["/reference"],
        by_key["echelon/circle-pentagon/reference"]
    );
    let mcap_path = fleet_dir.join("fleet.mcap");
    assert_eq!(mcap_counts(&mcap_path), by_topic);
    let rows: u64 = col["agents"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| u(a, &["rows"]))
        .sum();
    assert_eq!(
        rows as usize,
        self::rows(&fleet_dir.join("trajectory.csv")).len()
    );
}
