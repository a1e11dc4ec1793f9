//! `echelon identify` as a user runs it: a run of the excitation manoeuvre
//! gives a `[robots.NAME]` block that a scenario accepts, the files, and bad
//! logs are refused in one line with exit code 2.
#![allow(clippy::unwrap_used)] // tests fail loudly by design

use std::path::Path;
use std::process::{Command, Output};

fn echelon(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_echelon"))
        .args(args)
        .output()
        .expect("the echelon binary runs")
}

fn text(b: &[u8]) -> String {
    String::from_utf8(b.to_vec()).unwrap()
}

/// `echelon run identify-excitation --mcap` for `duration` s into `dir`.
fn excitation_run(dir: &Path, duration: &str) {
    let o = echelon(&[
        "run",
        "identify-excitation",
        "--out",
        dir.to_str().unwrap(),
        "--duration",
        duration,
        "--mcap",
        "-q",
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
}

/// A refused input: exit 2, one line on stderr containing every `needle`.
fn refused(o: &Output, needles: &[&str]) {
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
    let err = text(&o.stderr);
    assert_eq!(err.lines().count(), 1, "{err}");
    for n in needles {
        assert!(err.contains(n), "{err} lacks {n}");
    }
    assert!(o.stdout.is_empty());
}

#[test]
fn identify_writes_a_block_a_scenario_accepts_with_its_summary_and_figure() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    excitation_run(&run, "45");
    let out = dir.path().join("id");
    // Agent 2 as `lab2` from `input` (and `more`): what it prints.
    let identify = |input: &Path, more: &[&str]| {
        let input = input.to_str().unwrap();
        let args = ["identify", input, "--agent", "2", "--name", "lab2"];
        let o = echelon(&[&args[..], more].concat());
        assert!(o.status.success(), "{}", text(&o.stderr));
        text(&o.stdout)
    };
    let stdout = identify(&run, &["--out", out.to_str().unwrap()]);
    assert!(stdout.contains("[robots.lab2]"), "{stdout}");
    assert!(stdout.contains("torque model, agent 2"), "{stdout}");
    let block = std::fs::read_to_string(out.join("robot.toml")).unwrap();
    assert!(stdout.contains(block.trim_end()));
    for f in ["identify.json", "identify.svg", "identify.png"] {
        assert!(out.join(f).is_file(), "{f}");
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("identify.json")).unwrap()).unwrap();
    // Noise-free simulated log: agent 2 of Table I to 6 digits.
    let mass = json["params"][0]["estimate"]["value"].as_f64().unwrap();
    assert_eq!(json["params"][0]["field"], "mass");
    assert!((mass - 25.0).abs() < 1e-4, "{mass}");
    let psi = json["params"][3]["estimate"]["value"].as_f64().unwrap();
    assert!((psi - 5.51).abs() < 1e-4, "{psi}");

    // The same run's run.mcap (/agent/2/state JSON records, as in a
    // fleet.mcap) gives the same block but for its source line.
    let from_mcap = identify(&run.join("run.mcap"), &[]);
    let body = |s: &str| -> String {
        s.lines()
            .filter(|l| l.starts_with('[') || l.contains(" = "))
            .collect::<Vec<_>>()
            .join("\n")
    };
    assert_eq!(body(&from_mcap), body(&stdout), "{from_mcap}");

    // The block pasted into a scenario runs.
    pasted_block_runs(dir.path(), "experiment-circle", ("agent2", "lab2"), &block);
}

#[test]
fn bad_logs_exit_2_with_one_line_naming_the_file_and_what_is_missing() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    excitation_run(&run, "0.2");
    let path = run.to_str().unwrap();
    let csv = run.join("trajectory.csv");
    let csv_name = csv.display().to_string();

    // Too short (21 samples per agent).
    refused(
        &echelon(&["identify", path]),
        &[&csv_name, "log too short", "at least 50"],
    );
    // A torque run has no velocity-base columns.
    refused(
        &echelon(&["identify", path, "--model", "velocity"]),
        &[&csv_name, "missing column(s) v_applied, omega_applied"],
    );
    // No such directory.
    let missing = dir.path().join("nowhere");
    refused(
        &echelon(&["identify", missing.to_str().unwrap()]),
        &["nowhere", "cannot read"],
    );
    // A CSV without u1, u2 (cut after the first 11 columns).
    let cut = dir.path().join("cut.csv");
    let body: Vec<String> = std::fs::read_to_string(&csv)
        .unwrap()
        .lines()
        .map(|l| l.split(',').take(11).collect::<Vec<_>>().join(","))
        .collect();
    std::fs::write(&cut, body.join("\n")).unwrap();
    refused(
        &echelon(&["identify", cut.to_str().unwrap()]),
        &["cut.csv", "neither u1, u2"],
    );
    // A non-finite value.
    let nan = dir.path().join("nan.csv");
    let mut long = String::new();
    let src = std::fs::read_to_string(&csv).unwrap();
    let mut lines = src.lines();
    long.push_str(lines.next().unwrap());
    long.push('\n');
    for i in 0..100 {
        let mut cells: Vec<String> = "0,1,0,0,0,0.1,0.2,0,0,0,0,1,2,0,0"
            .split(',')
            .map(str::to_owned)
            .collect();
        cells[0] = format!("{}", f64::from(i) * 0.01);
        if i == 60 {
            cells[5] = "inf".into();
        }
        long.push_str(&cells.join(","));
        long.push('\n');
    }
    std::fs::write(&nan, long).unwrap();
    refused(
        &echelon(&["identify", nan.to_str().unwrap()]),
        &["nan.csv", "non-finite v = inf at t = 0.6 s"],
    );
    // An MCAP without the ROS 2 channels a velocity base needs.
    let mcap = run.join("run.mcap");
    let mcap_name = mcap.display().to_string();
    refused(
        &echelon(&["identify", &mcap_name, "--model", "velocity"]),
        &[
            &mcap_name,
            "missing a command channel of type geometry_msgs/msg/TwistStamped or geometry_msgs/msg/Twist",
            "topics in the file: /reference, /agent/1/state",
        ],
    );
    // Nor the agent asked for.
    refused(
        &echelon(&["identify", &mcap_name, "--agent", "7"]),
        &[
            &mcap_name,
            "missing a ROS 2 cmd_vel channel",
            "/agent/7/state",
        ],
    );
    // Not an MCAP file.
    let fake = dir.path().join("fake.mcap");
    std::fs::write(&fake, "not mcap").unwrap();
    refused(
        &echelon(&["identify", fake.to_str().unwrap()]),
        &["fake.mcap", "not a readable MCAP file"],
    );
}

/// A run directory whose integrals.csv was cut mid-write (a copy
/// interrupted, a disk that filled): `identify` refuses it in one line
/// naming the file and the row where it was cut (exit 2), instead of
/// fitting on the part that is there or quietly without it; the same
/// directory with the file whole identifies.
#[test]
fn a_truncated_integrals_csv_is_refused_naming_the_file_and_the_row() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    excitation_run(&run, "2");
    let path = run.to_str().unwrap();
    let integrals = run.join("integrals.csv");
    let name = integrals.display().to_string();
    let whole = std::fs::read_to_string(&integrals).unwrap();
    let rows = whole.lines().count() - 1;

    // The last line cut inside a number: no newline at its end.
    std::fs::write(&integrals, &whole[..whole.len() - 7]).unwrap();
    refused(
        &echelon(&["identify", path]),
        &[
            &name,
            "truncated",
            &format!("row {rows} (line {})", rows + 1),
        ],
    );
    // Whole rows missing at the end (agent 2's last rows).
    let kept: String = whole
        .lines()
        .take(rows + 1 - 3)
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(&integrals, kept).unwrap();
    refused(
        &echelon(&["identify", path, "--agent", "2"]),
        &[&name, "truncated", "agent 2's rows stop at t ="],
    );
    std::fs::write(&integrals, &whole).unwrap();
    let o = echelon(&["identify", path, "--agent", "2"]);
    assert!(o.status.success(), "{}", text(&o.stderr));
}

/// `python3 scripts/ros2/lagged_base_bag.py OUT args…`: a ROS 2 bag of a
/// lagged velocity base serialized by rclpy (ROS 2 Jazzy wheels, see
/// scripts/requirements-test.txt; `ECHELON_PYTHON` picks the interpreter).
fn lagged_base_bag(out: &Path, args: &[&str]) {
    let python = std::env::var("ECHELON_PYTHON").unwrap_or_else(|_| "python3".to_owned());
    let script =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scripts/ros2/lagged_base_bag.py");
    let o = Command::new(&python)
        .arg(script)
        .arg(out)
        .args(args)
        .output()
        .unwrap_or_else(|e| {
            panic!("cannot run {python}: {e}; run scripts/test to install the ROS 2 wheels")
        });
    assert!(
        o.status.success(),
        "lagged_base_bag.py failed: {}; run scripts/test (it installs scripts/requirements-test.txt)",
        text(&o.stderr)
    );
}

/// `echelon identify BAG --out DIR` and the identified `(τ_v, τ_ω)`.
fn identified_lags(bag: &Path, out: &Path, extra: &[&str]) -> [f64; 2] {
    let mut args = vec![
        "identify",
        bag.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let o = echelon(&args);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let stdout = text(&o.stdout);
    assert!(stdout.contains("velocity model"), "{stdout}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("identify.json")).unwrap()).unwrap();
    let get = |i: usize, field: &str| {
        assert_eq!(json["params"][i]["field"], field, "{json}");
        json["params"][i]["estimate"]["value"].as_f64().unwrap()
    };
    [get(0, "tau_v"), get(1, "tau_omega")]
}

/// A ROS 2 bag written with the ROS 2 serializer (TwistStamped commands at
/// 20 Hz, odometry at 50 Hz offset by 7 ms, noise σ = 0.01 m/s and
/// 0.02 rad/s on the measured twist) of a base with τ_v = 0.1 s,
/// τ_ω = 0.15 s: both lags within 5 %; the same with plain Twist commands
/// (log times instead of stamps) and with other lags.
#[test]
fn a_ros2_bag_of_a_lagged_base_gives_its_lags_within_5_percent() {
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&str, [f64; 2], &[&str]); 3] = [
        ("stamped", [0.1, 0.15], &[]),
        ("twist", [0.1, 0.15], &["--twist", "--seed", "2"]),
        (
            "slow",
            [0.3, 0.2],
            &["--tau-v", "0.3", "--tau-omega", "0.2", "--seed", "3"],
        ),
    ];
    for (name, truth, args) in cases {
        let bag = dir.path().join(format!("{name}.mcap"));
        lagged_base_bag(&bag, args);
        let lags = identified_lags(&bag, &dir.path().join(name), &[]);
        for (got, want) in lags.iter().zip(truth) {
            assert!(
                (got / want - 1.0).abs() < 0.05,
                "{name}: {lags:?} against {truth:?}"
            );
        }
    }
    // Topics named explicitly; a wrong one is refused naming what exists.
    let bag = dir.path().join("stamped.mcap");
    let lags = identified_lags(
        &bag,
        &dir.path().join("named"),
        &["--cmd-vel", "/robot1/cmd_vel", "--odom", "/robot1/odom"],
    );
    assert!((lags[0] / 0.1 - 1.0).abs() < 0.05, "{lags:?}");
    refused(
        &echelon(&["identify", bag.to_str().unwrap(), "--odom", "/robot2/odom"]),
        &[
            "stamped.mcap",
            "odometry topic /robot2/odom (--odom)",
            "odometry channels: /robot1/odom",
        ],
    );
}

/// `identify.json` of `echelon identify BAG --out DIR`.
fn identified_json(bag: &Path, out: &Path) -> serde_json::Value {
    let o = echelon(&[
        "identify",
        bag.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    serde_json::from_str(&std::fs::read_to_string(out.join("identify.json")).unwrap()).unwrap()
}

/// The estimate of parameter or limit `field` in `identify.json`, and
/// whether a limit was `reached`.
fn estimate_of(json: &serde_json::Value, field: &str) -> (Option<f64>, bool) {
    for list in ["params", "limits"] {
        if let Some(p) = json[list]
            .as_array()
            .and_then(|a| a.iter().find(|p| p["field"] == field))
        {
            return (
                p["estimate"]["value"].as_f64(),
                p["reached"].as_bool().unwrap_or(true),
            );
        }
    }
    panic!("no {field} in {json}")
}

/// Bags written with the ROS 2 serializer (rclpy, Fast-CDR) of bases with
/// a transport delay and acceleration limits, the way rosbag2 writes them
/// (TwistStamped commands at 20 Hz, odometry at 50 or 20 Hz, noisy twist):
/// a base with lags 0.2/0.12 s, limits 0.6 m/s² and 2.0 rad/s² and a 40 ms
/// dead time gets all five (lags and limits within 5 %, the dead time
/// within 5 ms); the same base without limits gets its lags and dead time,
/// and both limits "not reached".
#[test]
fn a_ros2_bag_of_a_base_with_dead_time_and_limits_gives_all_of_them() {
    let dir = tempfile::tempdir().unwrap();
    let base = [
        "--tau-v",
        "0.2",
        "--tau-omega",
        "0.12",
        "--dead-time",
        "0.04",
        "--duration",
        "60",
        "--noise-v",
        "0.002",
        "--noise-omega",
        "0.004",
    ];
    for (name, limits, rate) in [("limited", true, "20"), ("free", false, "50")] {
        let bag = dir.path().join(format!("{name}.mcap"));
        let mut args = base.to_vec();
        args.extend(["--odom-rate", rate, "--seed", "5"]);
        if limits {
            args.extend(["--a-max", "0.6", "--alpha-max", "2.0"]);
        }
        lagged_base_bag(&bag, &args);
        let json = identified_json(&bag, &dir.path().join(name));
        for (field, truth) in [("tau_v", 0.2), ("tau_omega", 0.12)] {
            let (e, _) = estimate_of(&json, field);
            let e = e.unwrap_or_else(|| panic!("{name}: {field} withheld: {json}"));
            assert!(
                (e / truth - 1.0).abs() < 0.05,
                "{name}: {field} {e}: {json}"
            );
        }
        let (d, _) = estimate_of(&json, "dead_time");
        let d = d.unwrap_or_else(|| panic!("{name}: dead time withheld: {json}"));
        assert!((d - 0.04).abs() < 0.005, "{name}: dead time {d}: {json}");
        for (field, truth) in [("a_max", 0.6), ("alpha_max", 2.0)] {
            let (e, reached) = estimate_of(&json, field);
            if limits {
                let e = e.unwrap_or_else(|| panic!("{name}: {field} withheld: {json}"));
                assert!(
                    reached && (e / truth - 1.0).abs() < 0.05,
                    "{name}: {field} {e}: {json}"
                );
            } else {
                assert!(!reached && e.is_none(), "{name}: {field} claimed: {json}");
            }
        }
    }
}

/// An ideal base (no lag, no limit, 10 ms dead time) in a bag written with
/// the ROS 2 serializer: both lags are answered — "below one odometry
/// period", a 95 % upper bound under the 20 ms period, written as 0 in the
/// block — not withheld, and no limit is claimed.
#[test]
fn a_ros2_bag_of_an_ideal_base_answers_its_lags_as_below_a_period() {
    let dir = tempfile::tempdir().unwrap();
    let bag = dir.path().join("ideal.mcap");
    lagged_base_bag(
        &bag,
        &[
            "--tau-v",
            "0",
            "--tau-omega",
            "0",
            "--dead-time",
            "0.01",
            "--seed",
            "4",
        ],
    );
    let out = dir.path().join("ideal");
    let json = identified_json(&bag, &out);
    for field in ["tau_v", "tau_omega"] {
        let p = json["params"]
            .as_array()
            .and_then(|a| a.iter().find(|p| p["field"] == field))
            .unwrap_or_else(|| panic!("no {field}: {json}"));
        let bound = p["upper_bound"]
            .as_f64()
            .unwrap_or_else(|| panic!("{field} has no upper bound: {json}"));
        assert!(bound > 0.0 && bound < 0.02, "{field} < {bound}: {json}");
        assert!(p["not_identifiable"].is_null(), "{field} withheld: {json}");
    }
    for field in ["a_max", "alpha_max"] {
        let (e, reached) = estimate_of(&json, field);
        assert!(!reached && e.is_none(), "{field} claimed: {json}");
    }
    let o = echelon(&["identify", bag.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let stdout = text(&o.stdout);
    assert!(
        stdout.contains("\ntau_v = 0.0    # τ_v, s: below what the odometry resolves"),
        "{stdout}"
    );
}

#[test]
fn a_run_whose_acceleration_limit_acted_prints_its_lags_and_limit_and_the_block_runs() {
    // turtlebot-circle: the Burgers' joint acceleration limit (α_max =
    // 3.2 rad/s²) cuts their turns while they catch up from rest. The lags
    // come out with the limit in the loop, and the block carries both.
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let o = echelon(&[
        "run",
        "turtlebot-circle",
        "--out",
        run.to_str().unwrap(),
        "--duration",
        "10",
        "-q",
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let o = echelon(&[
        "identify",
        run.to_str().unwrap(),
        "--agent",
        "1",
        "--name",
        "burger2",
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let stdout = text(&o.stdout);
    for line in [
        "tau_v = 0.1    # τ_v, s: noise-free log",
        "tau_omega = 0.1    # τ_ω, s: noise-free log",
        "alpha_max = 3.2    # α_max, rad/s²: identified with the lag",
        "warning: alpha_max = 3.2000 identified with the lag",
    ] {
        assert!(stdout.contains(line), "{line} not in {stdout}");
    }
    assert!(!stdout.contains("not identifiable"), "{stdout}");
    let block = &stdout[stdout.find("# Identified by").unwrap()..];
    pasted_block_runs(dir.path(), "turtlebot-circle", ("burger", "burger2"), block);
}

/// The identified `block`, pasted into the built-in `scenario` whose robot
/// `robot.0` is renamed `robot.1` (the block's robot), runs.
fn pasted_block_runs(dir: &std::path::Path, scenario: &str, robot: (&str, &str), block: &str) {
    let show = echelon(&["show", scenario]);
    let (from, to) = (
        format!("robot = \"{}\"", robot.0),
        format!("robot = \"{}\"", robot.1),
    );
    let text_with_block = text(&show.stdout).replace(&from, &to) + "\n" + block;
    let file = dir.join(format!("with-{}.toml", robot.1));
    std::fs::write(&file, text_with_block).unwrap();
    let o = echelon(&[
        "run",
        file.to_str().unwrap(),
        "--out",
        dir.join("run2").to_str().unwrap(),
        "--duration",
        "2",
        "-q",
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
}
