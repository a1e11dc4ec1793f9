//! The scenario format: built-ins, round trips, errors that say where, golden
//! outputs and determinism.
#![allow(clippy::unwrap_used)] // tests fail loudly by design

mod common;

use std::path::Path;

use echelon::output::{
    self, REFERENCE_FILE, SCENARIO_FILE, SUMMARY_FILE, TRAJECTORY_FILE, TRAJECTORY_HEADER,
};
use echelon::scenario::{self, Overrides, Scenario};
use echelon::sim::{Frame, ObserverError};

const NAMES: [&str; 12] = [
    "circle-pentagon-velocity",
    "circle-pentagon",
    "crossing",
    "experiment-circle-velocity",
    "experiment-circle",
    "experiment-lemniscate",
    "fix-study",
    "identify-excitation",
    "lemniscate-wedge",
    "nonfeasible",
    "obstacle-slalom",
    "turtlebot-circle",
];

#[test]
fn the_papers_setups_and_the_fix_study_are_built_in() {
    let names: Vec<&str> = scenario::builtin().iter().map(|(n, _)| *n).collect();
    assert_eq!(names, NAMES);
}

#[test]
fn every_scenario_file_parses_builds_and_round_trips() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios");
    let mut seen = 0;
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "toml") {
            continue;
        }
        seen += 1;
        let s = common::load_clean_scenario(&path);
        // The file is the built-in of the same name.
        let stem = path.file_stem().unwrap().to_str().unwrap();
        assert_eq!(Scenario::builtin(stem).unwrap().source(), s.source());
    }
    assert_eq!(seen, NAMES.len());
}

const BASE: &str = include_str!("fixtures/base.toml");

use common::{build, expect_error, expect_errors_in};

#[test]
fn the_base_scenario_is_valid() {
    let run = build(BASE).unwrap();
    assert_eq!(run.plan.agents().len(), 2);
    assert_eq!(run.plan.agents()[1].name(), "agent 2");
    assert_eq!(run.log_every, 1);
}

#[test]
fn syntax_and_type_errors_name_line_column_and_field() {
    expect_errors_in(
        BASE,
        &[
            ("[sim]", "[sim", 2, "", ""),
            (
                "speed = 0.5",
                "speed = \"fast\"",
                7,
                "reference.circle.speed",
                "invalid type",
            ),
            (
                "offset = { x = 0.5, y = 0.8 }",
                "ofset = { x = 0.5, y = 0.8 }",
                14,
                "agents[1].ofset",
                "unknown field",
            ),
            ("dt = 0.01\n", "", 2, "sim.dt", "missing field"),
            (
                "[reference.circle]",
                "[reference.square]",
                6,
                "reference.square",
                "unknown variant",
            ),
            (
                "leader = 1",
                "leader = \"agent 1\"",
                18,
                "agents[2].leader",
                "\"reference\" or the number",
            ),
            (
                "offset = { x = 0.5, y = 0.8 }",
                "offset = { x = 0.5, y = 0.8, frame = \"leaders\" }",
                14,
                "agents[1].offset.frame",
                "unknown variant",
            ),
        ],
    );
}

#[test]
fn impossible_values_are_refused_with_the_reason() {
    expect_errors_in(
        BASE,
        &[
            // L_X = L_Xoff + L ≤ 0
            (
                "x = 0.5, y = 0.8",
                "x = -0.2, y = 0.8",
                14,
                "agents[1].offset.x",
                "L_X = L_Xoff + L",
            ),
            // a cycle in the leader graph
            (
                "leader = \"reference\"",
                "leader = 2",
                13,
                "agents[1].leader",
                "agents 1 → 2 → 1 form a cycle",
            ),
            // a dangling leader, and agent numbers from 1
            (
                "leader = 1",
                "leader = 7",
                18,
                "agents[2].leader",
                "does not exist",
            ),
            (
                "leader = 1",
                "leader = 0",
                18,
                "agents[2].leader",
                "numbered 1..=2",
            ),
            // an agent following itself
            (
                "leader = 1",
                "leader = 2",
                18,
                "agents[2].leader",
                "follows itself",
            ),
            // negative speed for the virtual leader
            (
                "speed = 0.5",
                "speed = -0.5",
                7,
                "reference.circle.speed",
                "≥ 0",
            ),
        ],
    );
    // L ≤ 0
    expect_error(
        &format!("{BASE}\n[control]\nl = 0.0\n"),
        22,
        "control.l",
        "must be a finite number > 0",
    );
    // negative mass
    let robot = BASE.replacen("[[agents]]\n", "[[agents]]\nrobot = \"heavy\"\n", 1)
        + "\n[robots.heavy]\npreset = \"agent1\"\nmass = -27.0\n";
    expect_error(&robot, 24, "robots.heavy.mass", "must be > 0");
    // NaN
    expect_error(
        &format!("{BASE}\n[control]\nke = nan\n"),
        22,
        "control.ke",
        "finite",
    );
    // an agent's own control table is named, not the file's
    expect_error(
        &BASE.replacen("[[agents]]\n", "[[agents]]\ncontrol = { kz = -1.0 }\n", 1),
        12,
        "agents[1].control.kz",
        "must be a finite number > 0",
    );
    // non-positive gains
    expect_error(
        &format!("{BASE}\n[control]\nkz = -10.0\n"),
        22,
        "control.kz",
        "> 0",
    );
}

#[test]
fn ambiguous_or_inconsistent_settings_are_refused() {
    expect_errors_in(
        BASE,
        &[
            (
                "theta_deg = 0.0 }\nleader = \"reference\"",
                "theta_deg = 0.0, theta = 0.0 }\nleader = \"reference\"",
                12,
                "agents[1].start.theta_deg",
                "not both",
            ),
            (
                "dt = 0.01\n",
                "dt = 0.01\ncontroller_period = 0.025\n",
                5,
                "sim.controller_period",
                "whole multiple",
            ),
            (
                "offset = { x = 0.5, y = -0.4 }",
                "mode = \"tracking\"\noffset = { x = 0.5, y = -0.4 }",
                20,
                "agents[2].offset",
                "takes no offset",
            ),
            (
                "offset = { x = 0.5, y = -0.4 }\n",
                "",
                16,
                "agents[2]",
                "missing field `offset`",
            ),
        ],
    );
    expect_error(
        &BASE.replacen("[[agents]]\n", "[[agents]]\nrobot = \"agent9\"\n", 1),
        12,
        "agents[1].robot",
        "unknown robot `agent9`",
    );
    expect_error(
        &format!("{BASE}\n[log]\ndt = 0.015\n"),
        22,
        "log.dt",
        "whole multiple of dt",
    );
    expect_error(
        &format!("{BASE}\n[control]\nlycomp = \"exact\"\nly_derivatives = \"exact\"\n"),
        23,
        "control.ly_derivatives",
        "analytic reference",
    );
    expect_error(
        &BASE.replace(
            "start = { x = 0.0, y = 0.0, theta_deg = 0.0 }",
            "start = { x = 0.0, y = 0.0, theta_deg = 0.0, v = 1.0 }",
        ),
        9,
        "reference.circle.start.v",
        "takes no speed",
    );
}

#[test]
fn waypoint_errors_point_at_the_waypoint() {
    let wp = BASE.replace(
        "[reference.circle]\nspeed = 0.5\nturn_rate = 0.1\nstart = { x = 0.0, y = 0.0, theta_deg = 0.0 }",
        "[reference.waypoints]\npoints = [\n  [0.0, 0.0, 0.0],\n  [2.0, 1.0, 0.0],\n  [1.0, 2.0, 1.0],\n]",
    );
    expect_error(
        &wp,
        10,
        "reference.waypoints.points[3]",
        "not after the previous one",
    );
}

#[test]
fn waypoints_load_from_a_csv_file_next_to_the_scenario() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("path.csv"), "t,x,y\n0,0,0\n5,2,1\n10,4,0\n").unwrap();
    let src = BASE.replace(
        "[reference.circle]\nspeed = 0.5\nturn_rate = 0.1\nstart = { x = 0.0, y = 0.0, theta_deg = 0.0 }",
        "[reference.waypoints]\nfile = \"path.csv\"",
    );
    let file = dir.path().join("s.toml");
    std::fs::write(&file, &src).unwrap();
    let run = Scenario::load(&file)
        .unwrap()
        .build(&Overrides::default())
        .unwrap();
    assert!(
        matches!(run.plan.reference(), echelon::reference::Reference::Waypoints(w) if w.points().len() == 3)
    );
    // A bad cell names the CSV file, its line and the column.
    std::fs::write(dir.path().join("path.csv"), "t,x,y\n0,0,0\n5,two,1\n").unwrap();
    let err = Scenario::load(&file)
        .unwrap()
        .build(&Overrides::default())
        .unwrap_err();
    assert!(err.location.file.ends_with("path.csv"), "{err}");
    assert_eq!((err.location.line, err.field.as_str()), (3, "x"), "{err}");
}

#[test]
fn overrides_replace_the_files_timing_and_law() {
    let s = Scenario::builtin("nonfeasible").unwrap();
    let run = s
        .build(&Overrides {
            dt: Some(0.002),
            duration: Some(3.0),
            log_dt: Some(0.0),
            law: Some(echelon::Variant::Complete),
            seed: Some(9),
        })
        .unwrap();
    assert_eq!(run.plan.steps(), 1500);
    assert_eq!(run.seed, 9);
    assert_eq!(run.log_every, 1);
    assert_eq!(
        run.plan.agents()[0].variant(),
        Some(echelon::Variant::Complete)
    );
    let bad = s.build(&Overrides {
        dt: Some(-1.0),
        ..Overrides::default()
    });
    let err = bad.unwrap_err();
    assert_eq!(err.field, "--dt");
    assert_eq!(
        err.to_string(),
        "command line: --dt: -1 must be a finite number > 0"
    );
    // The law flag wins over an agent's own law, as over the file's.
    let own = BASE.replacen(
        "[[agents]]\n",
        "[[agents]]\ncontrol = { law = \"paper\" }\n",
        1,
    );
    let run = Scenario::parse(&own, "test.toml", None)
        .unwrap()
        .build(&Overrides {
            law: Some(echelon::Variant::Complete),
            ..Overrides::default()
        })
        .unwrap();
    assert!(
        run.plan
            .agents()
            .iter()
            .all(|a| a.variant() == Some(echelon::Variant::Complete))
    );
    // A value from the file is still located in the file.
    let err = build(&BASE.replace("dt = 0.01\n", "dt = -0.01\n")).unwrap_err();
    assert_eq!(
        (err.location.line, err.field.as_str()),
        (4, "sim.dt"),
        "{err}"
    );
}

fn run_into(dir: &Path, name: &str) -> output::RunSummary {
    common::run_to_dir(
        &Scenario::builtin(name).unwrap(),
        &Overrides::default(),
        dir,
    )
}

#[test]
fn same_scenario_gives_the_same_bytes() {
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    run_into(a.path(), "circle-pentagon");
    run_into(b.path(), "circle-pentagon");
    for f in [
        TRAJECTORY_FILE,
        SUMMARY_FILE,
        REFERENCE_FILE,
        SCENARIO_FILE,
        output::INTEGRALS_FILE,
    ] {
        let (x, y) = (
            std::fs::read(a.path().join(f)).unwrap(),
            std::fs::read(b.path().join(f)).unwrap(),
        );
        assert!(x == y, "{f} differs between two runs");
    }
    let csv = std::fs::read_to_string(a.path().join(TRAJECTORY_FILE)).unwrap();
    assert_eq!(csv.lines().next(), Some(TRAJECTORY_HEADER));
    // 0.00 … 62.83 every 10 ms, plus the final step at 62.832, for 4 agents.
    assert_eq!(csv.lines().count() - 1, (6284 + 1) * 4);
    let leftovers: Vec<_> = std::fs::read_dir(a.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(
        leftovers.len(),
        5,
        "only the five outputs (with integrals.csv) remain: {leftovers:?}"
    );
}

#[test]
fn the_run_records_its_scenario_and_reference() {
    let dir = tempfile::tempdir().unwrap();
    let scenario = Scenario::builtin("circle-pentagon").unwrap();
    let overrides = Overrides {
        duration: Some(2.0),
        law: Some(echelon::Variant::Complete),
        ..Overrides::default()
    };
    common::run_to_dir(&scenario, &overrides, dir.path());
    // scenario.toml: a header naming origin and overrides, then the exact source,
    // which parses back to the same scenario.
    let text = std::fs::read_to_string(dir.path().join(SCENARIO_FILE)).unwrap();
    let mut lines = text.lines();
    assert!(lines.next().unwrap().starts_with("# Written by echelon"));
    assert_eq!(lines.next(), Some("# origin: builtin:circle-pentagon"));
    assert_eq!(
        lines.next(),
        Some("# overrides: --duration 2 --law complete")
    );
    assert!(text.ends_with(scenario.source()));
    let back = Scenario::parse(&text, "scenario.toml", None).unwrap();
    assert_eq!(back.file, scenario.file);
    // reference.csv: the virtual leader at the logged instants (eq. 18: a circle
    // of radius V_d/ω_d = 5 m through the origin, heading ω_d t).
    let reference = std::fs::read_to_string(dir.path().join(REFERENCE_FILE)).unwrap();
    let traj = std::fs::read_to_string(dir.path().join(TRAJECTORY_FILE)).unwrap();
    let mut rows = reference.lines();
    assert_eq!(rows.next(), Some(output::REFERENCE_HEADER));
    let times: Vec<&str> = traj
        .lines()
        .skip(1)
        .filter(|l| l.split(',').nth(1) == Some("1"))
        .map(|l| l.split(',').next().unwrap())
        .collect();
    let rows: Vec<Vec<f64>> = rows
        .map(|l| l.split(',').map(|c| c.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), times.len());
    for (row, t) in rows.iter().zip(&times) {
        assert_eq!(row[0], t.parse::<f64>().unwrap());
        let (x, y, th) = (
            5.0 * (0.1 * row[0]).sin(),
            5.0 - 5.0 * (0.1 * row[0]).cos(),
            0.1 * row[0],
        );
        assert!(
            (row[1] - x).abs() < 1e-12 && (row[2] - y).abs() < 1e-12,
            "{row:?}"
        );
        assert!((row[3] - th).abs() < 1e-12 && (row[4] - 0.5).abs() < 1e-12);
        assert!((row[5] - 0.1).abs() < 1e-12);
    }
}

/// Golden summaries of every built-in scenario, compared with a relative
/// tolerance of 1e-9 (plus 1e-11 absolute for quantities that converge to 0).
/// Regenerate with `ECHELON_BLESS=1 cargo test --test scenarios golden`.
#[test]
fn golden_summaries() {
    let golden_dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/golden");
    let bless = std::env::var_os("ECHELON_BLESS").is_some();
    for name in NAMES {
        let dir = tempfile::tempdir().unwrap();
        run_into(dir.path(), name);
        let got: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.path().join(SUMMARY_FILE)).unwrap()).unwrap();
        let file = golden_dir.join(format!("{name}.json"));
        if bless {
            std::fs::create_dir_all(&golden_dir).unwrap();
            std::fs::write(&file, serde_json::to_string_pretty(&got).unwrap() + "\n").unwrap();
            continue;
        }
        let want: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(&file)
                .unwrap_or_else(|_| panic!("missing {}", file.display())),
        )
        .unwrap();
        compare(&got, &want, name);
    }
}

fn compare(got: &serde_json::Value, want: &serde_json::Value, path: &str) {
    use serde_json::Value::*;
    match (got, want) {
        (Number(a), Number(b)) => {
            let (a, b) = (a.as_f64().unwrap(), b.as_f64().unwrap());
            assert!(
                (a - b).abs() <= 1e-9 * a.abs().max(b.abs()) + 1e-11,
                "{path}: {a} vs golden {b}"
            );
        }
        (Object(a), Object(b)) => {
            assert_eq!(
                a.keys().collect::<Vec<_>>(),
                b.keys().collect::<Vec<_>>(),
                "{path}"
            );
            for (k, v) in a {
                compare(v, &b[k], &format!("{path}.{k}"));
            }
        }
        (Array(a), Array(b)) => {
            assert_eq!(a.len(), b.len(), "{path}");
            for (i, (x, y)) in a.iter().zip(b).enumerate() {
                compare(x, y, &format!("{path}[{i}]"));
            }
        }
        _ => assert_eq!(got, want, "{path}"),
    }
}

#[test]
fn the_readme_example_scenario_builds_and_runs() {
    let readme =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../../README.md"))
            .unwrap();
    let start = readme
        .find("```toml\n")
        .expect("a TOML example in the README")
        + "```toml\n".len();
    let len = readme[start..].find("```").unwrap();
    let example = &readme[start..start + len];
    let run = Scenario::parse(example, "README.md", None)
        .unwrap_or_else(|e| panic!("{e}"))
        .build(&Overrides {
            duration: Some(5.0),
            ..Overrides::default()
        })
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(run.plan.agents().len(), 2);
    assert_eq!(
        run.plan.agents()[1]
            .torque_robot()
            .and_then(|r| r.torque_limit()),
        Some(5.0)
    );
    let mut none = |_: &Frame<'_>| -> Result<(), ObserverError> { Ok(()) };
    run.simulation().run(&mut none).unwrap();
}

/// `BASE` with both agents on the robot `[robots.b]` given by `fields`.
fn on_velocity_base(fields: &str) -> String {
    format!(
        "{}\n[robots.b]\n{fields}",
        BASE.replace("[[agents]]\n", "[[agents]]\nrobot = \"b\"\n")
    )
}

#[test]
fn velocity_bases_refuse_impossible_and_foreign_fields() {
    expect_error(
        &on_velocity_base("drive = \"velocity\"\ntau_v = -0.1\n"),
        25,
        "robots.b.tau_v",
        "must be ≥ 0",
    );
    expect_error(
        &on_velocity_base("drive = \"velocity\"\nv_max = 0.0\n"),
        25,
        "robots.b.v_max",
        "must be > 0",
    );
    expect_error(
        &on_velocity_base("drive = \"velocity\"\nmass = 1.0\n"),
        25,
        "robots.b.mass",
        "torque-driven robot's field",
    );
    expect_error(
        &on_velocity_base("preset = \"turtlebot3-burger\"\ntorque_limit = 1.0\n"),
        25,
        "robots.b.torque_limit",
        "torque-driven robot's field",
    );
    expect_error(
        &on_velocity_base("preset = \"agent1\"\ntau_omega = 0.1\n"),
        25,
        "robots.b.tau_omega",
        "velocity base's field",
    );
    // A lag the step cannot resolve (check_step): dt = 0.01 s.
    expect_error(
        &on_velocity_base("drive = \"velocity\"\ntau_v = 0.005\n"),
        25,
        "robots.b.tau_v",
        "shorter than the integration step",
    );
    expect_error(
        &on_velocity_base("drive = \"velocity\"\ntau_v = 0.0\na_max = 1.0\n"),
        26,
        "robots.b.a_max",
        "needs tau_v > 0",
    );
}

#[test]
fn the_law_must_suit_the_drive() {
    expect_error(
        &format!("{BASE}\n[control]\nlaw = \"kinematic\"\n"),
        22,
        "control.law",
        "is torque-driven",
    );
    expect_error(
        &format!(
            "{}\n[control]\nlaw = \"paper\"\n",
            on_velocity_base("drive = \"velocity\"\n")
        ),
        27,
        "control.law",
        "is a velocity base",
    );
    // A torque-driven follower needs its leader's v̇, which a base without a
    // speed lag does not have.
    let src = format!(
        "{}\n[robots.b]\ndrive = \"velocity\"\n",
        BASE.replacen("[[agents]]\n", "[[agents]]\nrobot = \"b\"\n", 1)
    );
    expect_error(&src, 19, "agents[2].leader", "acceleration is undefined");
    // With a lag, it has one; and the default law of a velocity base is kinematic.
    let run = build(&src.replace(
        "drive = \"velocity\"\n",
        "drive = \"velocity\"\ntau_v = 0.05\n",
    ))
    .unwrap();
    assert_eq!(run.plan.agents()[0].law(), echelon::control::Law::Kinematic);
    assert_eq!(run.plan.agents()[1].law(), echelon::control::Law::Paper);
}

/// A velocity scenario's trajectory has the velocity columns, a torque agent's
/// are NaN, and the summary counts saturated ticks for velocity agents only.
#[test]
fn velocity_runs_log_commands_and_saturation() {
    let dir = tempfile::tempdir().unwrap();
    let summary = run_into(dir.path(), "turtlebot-circle");
    let text = std::fs::read_to_string(dir.path().join(TRAJECTORY_FILE)).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some(output::TRAJECTORY_HEADER_VELOCITY));
    let (v_max, omega_max) = (0.22, 2.84);
    let mut saturated_rows = 0;
    for line in lines {
        let cells: Vec<f64> = line.split(',').map(|c| c.parse().unwrap()).collect();
        assert_eq!(cells.len(), 20, "{line}");
        assert!(cells[11..15].iter().all(|c| c.is_nan()), "{line}");
        // The state's and the applied command's speeds never leave the limits.
        for (v, w) in [(cells[5], cells[6]), (cells[17], cells[18])] {
            assert!(v.abs() <= v_max && w.abs() <= omega_max, "{line}");
        }
        if cells[19] == 1.0 {
            saturated_rows += 1;
            // Saturation keeps the commanded curvature.
            let (cmd, app) = ((cells[15], cells[16]), (cells[17], cells[18]));
            assert!(
                (cmd.0 * app.1 - cmd.1 * app.0).abs() <= 1e-12 * cmd.0.hypot(cmd.1),
                "{line}"
            );
        }
    }
    assert!(saturated_rows > 0);
    for a in &summary.agents {
        assert!(a.saturated_ticks.unwrap() > 0, "{}", a.name);
        assert!(a.final_error < 1e-3, "{}: {}", a.name, a.final_error);
    }
    let torque = run_into(dir.path(), "circle-pentagon");
    assert!(torque.agents.iter().all(|a| a.saturated_ticks.is_none()));
}

/// `[fleet.ros2]` (and an agent's `ros2`): names by ROS 2's rules, frames,
/// domain ids, timeouts, and one namespace per robot, each refused with its
/// place in the file.
#[test]
fn ros2_links_are_checked_where_they_are_written() {
    let fleet_error = |extra: &str, line: usize, field: &str, message: &str| {
        let src = format!("{BASE}{extra}");
        let err = Scenario::parse(&src, "test.toml", None)
            .unwrap()
            .fleet()
            .map(|_| ())
            .expect_err(extra);
        let text = err.to_string();
        assert_eq!(err.location.line, line, "{text}");
        assert_eq!(err.field, field, "{text}");
        assert!(err.message.contains(message), "{text}");
        assert!(
            !text.contains('\n') && text.starts_with(&format!("test.toml:{line}:")),
            "{text}"
        );
    };
    fleet_error(
        "[fleet.ros2]\nnamespace = \"/robot{k}/\"\n",
        21,
        "fleet.ros2.namespace",
        "ends with `/`",
    );
    fleet_error(
        "[fleet.ros2]\ncmd_vel = \"~/cmd_vel\"\n",
        21,
        "fleet.ros2.cmd_vel",
        "no `~`",
    );
    fleet_error(
        "[fleet.ros2]\nodom = \"1odom\"\n",
        21,
        "fleet.ros2.odom",
        "starts with a digit",
    );
    fleet_error(
        "[fleet.ros2]\nbase_frame = \"base link\"\n",
        21,
        "fleet.ros2.base_frame",
        "without spaces",
    );
    fleet_error(
        "[fleet.ros2]\ndomain_id = 300\n",
        21,
        "fleet.ros2.domain_id",
        "0 to 232",
    );
    fleet_error(
        "[fleet.ros2]\nodom_timeout = 0.0\n",
        21,
        "fleet.ros2.odom_timeout",
        "> 0",
    );
    fleet_error(
        "[fleet.ros2]\nnamespace = \"/bot\"\n",
        21,
        "fleet.ros2.namespace",
        "own namespace",
    );
    // An agent's own table over the file's: the error is at the agent's.
    let agent = BASE.replacen(
        "leader = 1\n",
        "leader = 1\nros2 = { namespace = \"/robot1\" }\n",
        1,
    );
    let err = Scenario::parse(&agent, "test.toml", None)
        .unwrap()
        .fleet()
        .unwrap_err();
    assert_eq!(
        (err.location.line, err.field.as_str()),
        (19, "agents[2].ros2.namespace"),
        "{err}"
    );

    // The defaults: `/robot{k}`, `cmd_vel`/`odom` in it, REP 105 frames.
    let ok = Scenario::parse(
        &format!("{BASE}[fleet.ros2]\ncmd_vel_type = \"twist\"\nkey_scheme = \"bridge\"\n"),
        "test.toml",
        None,
    )
    .unwrap()
    .fleet()
    .unwrap();
    let l = &ok.ros2[1];
    assert_eq!(
        (l.namespace.as_str(), l.cmd_vel.as_str(), l.odom.as_str()),
        ("/robot2", "/robot2/cmd_vel", "/robot2/odom")
    );
    assert_eq!(
        (l.base_frame.as_str(), l.odom_frame.as_str(), l.domain_id),
        ("base_link", "odom", 0)
    );
    assert_eq!(l.cmd_vel_type, echelon::scenario::schema::CmdVelType::Twist);
    assert_eq!(l.key_scheme, echelon::scenario::schema::KeyScheme::Bridge);
}

/// Values the field's own rules accept but no differential-drive robot would
/// have are refused with their plausible range (`scenario::PLAUSIBLE`); gains
/// that are only unusual are run with a warning at their place.
#[test]
fn absurd_values_are_refused_with_their_plausible_range() {
    expect_error(
        &format!("{BASE}\n[control]\nl = 1e9\n"),
        22,
        "control.l",
        "1e9 m is outside the plausible range 1e-4 to 10 m",
    );
    let robot = BASE.replacen("[[agents]]\n", "[[agents]]\nrobot = \"heavy\"\n", 1)
        + "\n[robots.heavy]\npreset = \"agent1\"\nmass = 1e30\n";
    expect_error(
        &robot,
        24,
        "robots.heavy.mass",
        "1e30 kg is outside the plausible range 0.05 to 5000 kg",
    );
    expect_errors_in(
        BASE,
        &[
            (
                "speed = 0.5",
                "speed = 1e5",
                7,
                "reference.circle.speed",
                "plausible range 0 to 100 m/s",
            ),
            (
                "x = -0.3, y = -1.5",
                "x = -0.3, y = -1e7",
                12,
                "agents[1].start.y",
                "plausible range -1e6 to 1e6 m",
            ),
            (
                "duration = 1.0",
                "duration = 1e7",
                3,
                "sim.duration",
                "plausible range 0 to 1e6 s",
            ),
        ],
    );
    // An agent's own table is named, not the file's.
    expect_error(
        &BASE.replacen("[[agents]]\n", "[[agents]]\ncontrol = { kz = 1e16 }\n", 1),
        12,
        "agents[1].control.kz",
        "plausible range 1e-15 to 1e15",
    );
    // A flag's value is refused as the flag.
    let err = Scenario::parse(BASE, "test.toml", None)
        .unwrap()
        .build(&Overrides {
            dt: Some(2.0),
            duration: Some(10.0),
            log_dt: Some(0.0),
            ..Overrides::default()
        })
        .unwrap_err();
    assert_eq!(
        err.to_string(),
        "command line: --dt: 2 s is outside the plausible range 1e-6 to 1 s"
    );
    // A step the default logging period is not a multiple of: the step is
    // named (the default is nowhere in the file).
    expect_error(
        &BASE.replace("dt = 0.01\n", "dt = 0.03\n"),
        4,
        "sim.dt",
        "default logging period log.dt = 0.01 s",
    );
    // A huge gain is runnable (a divergence is the run's to stop), with a warning.
    let run = build(&format!("{BASE}\n[control]\nke = 1e12\n")).unwrap();
    assert_eq!(
        run.warnings,
        [
            "test.toml:22:6: control.ke: 1e12 is outside the usual range 0.001 to 10000 (allowed; the run may be stiff or diverge)",
            "test.toml:22:6: control.ke: agent 1: K_e dt = 1e10 > 2: the step 0.01 s cannot follow the time scale 1/K_e = 1e-12 s and the run will oscillate and diverge (use dt < 2e-12 s)",
            "test.toml:22:6: control.ke: agent 2: K_e dt = 1e10 > 2: the step 0.01 s cannot follow the time scale 1/K_e = 1e-12 s and the run will oscillate and diverge (use dt < 2e-12 s)",
        ]
    );
    // A gain the step cannot follow, though usual.
    let run = build(&format!("{BASE}\n[control]\nkz = 1000.0\n")).unwrap();
    assert_eq!(run.warnings.len(), 2, "{:?}", run.warnings);
    assert!(
        run.warnings[0].starts_with("test.toml:22:6: control.kz: agent 1: K_z dt = 10 > 2:"),
        "{:?}",
        run.warnings
    );
    assert!(build(BASE).unwrap().warnings.is_empty());
    // Infinity keeps its meaning where a field allows it.
    let unlimited = on_velocity_base("drive = \"velocity\"\nv_max = inf\n");
    assert!(build(&unlimited).is_ok());
}

/// `[sim] bounds`: the divergence guard's bounds, each optional. A run
/// whose state leaves them stops there naming agent, time and quantity; bad
/// bounds are refused at their field.
#[test]
fn sim_bounds_set_the_divergence_guard() {
    let base = BASE.replace("[sim]\n", "[sim]\nbounds = { speed = 0.05 }\n");
    let run = build(&base).unwrap();
    let b = run.plan.config().bounds;
    assert_eq!((b.speed, b.turn_rate, b.distance), (0.05, 100.0, 1e6));
    let mut sim = run.simulation();
    let err = loop {
        if let Err(e) = sim.step() {
            break e;
        }
        assert!(!sim.is_done(), "no robot reached 0.05 m/s");
    };
    match &err {
        echelon::SimError::Diverged { breach, t, .. } => {
            assert_eq!(breach.quantity, "|v|");
            assert!(breach.value > 0.05 && *t > 0.0, "{err}");
        }
        other => panic!("{other}"),
    }
    assert!(err.to_string().contains("left its bound 0.05 m/s"), "{err}");
    let line = BASE.lines().position(|l| l == "[sim]").unwrap() + 2;
    expect_error(
        &BASE.replace("[sim]\n", "[sim]\nbounds = { turn_rate = -1.0 }\n"),
        line,
        "sim.bounds.turn_rate",
        "",
    );
}

/// `summary.json` is one type, written and read (issue house): read back
/// as [`output::RunSummary`] it is what the run returned (a torque
/// formation, a velocity one with `saturated_ticks`, the crossing with
/// `safety`), and written again it is the same bytes.
#[test]
fn the_summary_reads_back_as_the_type_it_was_written_from() {
    for name in ["circle-pentagon", "circle-pentagon-velocity", "crossing"] {
        let dir = tempfile::tempdir().unwrap();
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../scenarios")
            .join(format!("{name}.toml"));
        let scenario = Scenario::load(&path).unwrap();
        let overrides = Overrides {
            duration: Some(3.0),
            ..Overrides::default()
        };
        let written = common::run_to_dir(&scenario, &overrides, dir.path());
        let text = std::fs::read_to_string(dir.path().join(SUMMARY_FILE)).unwrap();
        let read: output::RunSummary = serde_json::from_str(&text).unwrap();
        assert_eq!(read, written, "{name}");
        assert_eq!(
            serde_json::to_string_pretty(&read).unwrap(),
            serde_json::to_string_pretty(&written).unwrap(),
            "{name}"
        );
        assert_eq!(read.safety.is_some(), name == "crossing", "{name}");
        if name.starts_with("circle") {
            assert_eq!(
                read.agents[0].saturated_ticks.is_some(),
                name.ends_with("velocity"),
                "{name}"
            );
        }
    }
}
