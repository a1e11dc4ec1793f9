//! The signals figure and the report of runs with velocity bases: commanded
//! (dashed) against actual (solid) `v`, `ω` with the bases' limits, the
//! saturated spans, and the saturated steps in the report's text, all checked
//! against what `trajectory.csv` and `summary.json` hold. A torque run's
//! figure stays the paper's Fig. 14.
#![allow(clippy::unwrap_used)]

mod common;

use std::path::Path;

use echelon::output::{SCENARIO_FILE, SUMMARY_FILE, TRAJECTORY_FILE, Table};
use echelon::sample::COLUMNS;
use echelon_report::figure::{Axis, Dash, Figure, Item, Panel, Stroke};
use echelon_report::html::REPORT_FILE;
use echelon_report::plots::{self, COMMANDED_LABEL};
use echelon_report::run::Column;
use echelon_report::{RunData, write_all};

/// One column of trajectory.csv for agent `agent` (from 1), by its header
/// name (`t`, `agent` and the [`Column`]s: the core's names).
fn csv_named(dir: &Path, agent: usize, name: &str) -> Vec<f64> {
    let path = dir.join(TRAJECTORY_FILE);
    let table = Table::read(&path).unwrap();
    let (a, c) = (
        table.column(COLUMNS[1], &path).unwrap(),
        table.column(name, &path).unwrap(),
    );
    table
        .rows
        .iter()
        .filter(|r| r[a] == agent as f64)
        .map(|r| r[c])
        .collect()
}

/// Column `c` of trajectory.csv for agent `agent` (from 1), by its name.
fn csv_column(dir: &Path, agent: usize, c: Column) -> Vec<f64> {
    csv_named(dir, agent, c.name())
}

/// The logged instants: trajectory.csv's `t` for agent `agent` (from 1).
fn csv_times(dir: &Path, agent: usize) -> Vec<f64> {
    csv_named(dir, agent, COLUMNS[0])
}

/// `(t, value)` of column `c` of trajectory.csv for agent `agent` (from 1).
fn csv_series(dir: &Path, agent: usize, c: Column) -> Vec<(f64, f64)> {
    csv_times(dir, agent)
        .into_iter()
        .zip(csv_column(dir, agent, c))
        .collect()
}

/// The quantities of the figure's panels (their y axes), in order.
fn quantities(figure: &Figure) -> Vec<&str> {
    figure
        .panels
        .iter()
        .map(|p| p.y.quantity.as_str())
        .collect()
}

fn panel<'a>(figure: &'a Figure, quantity: &str) -> &'a Panel {
    figure
        .panels
        .iter()
        .find(|p| p.y.quantity == quantity)
        .unwrap_or_else(|| panic!("no `{quantity}` panel"))
}

/// The points of the line drawn with `stroke` (exactly one).
fn line_with(panel: &Panel, stroke: Stroke) -> &[(f64, f64)] {
    let lines: Vec<&[(f64, f64)]> = panel
        .items
        .iter()
        .filter_map(|i| match i {
            Item::Line {
                points, stroke: s, ..
            } if *s == stroke && !points.is_empty() => Some(points.as_slice()),
            _ => None,
        })
        .collect();
    assert_eq!(
        lines.len(),
        1,
        "{} lines drawn with {stroke:?}",
        lines.len()
    );
    lines[0]
}

fn has_line_with(panel: &Panel, stroke: Stroke) -> bool {
    panel.items.iter().any(
        |i| matches!(i, Item::Line { points, stroke: s, .. } if *s == stroke && !points.is_empty()),
    )
}

/// Segments: pairs of points.
type Segments = Vec<[(f64, f64); 2]>;

/// The labelled segment items of a panel: `(label, segments)`.
fn labelled_segments(panel: &Panel) -> Vec<(String, Segments)> {
    panel
        .items
        .iter()
        .filter_map(|i| match i {
            Item::Segments {
                label: Some(l),
                segments,
                ..
            } => Some((l.clone(), segments.clone())),
            _ => None,
        })
        .collect()
}

/// The saturation panel's bars for agent `i` (0-based): `(t0, t1)` spans.
fn bars(figure: &Figure, i: usize) -> Vec<(f64, f64)> {
    let p = panel(figure, "agent");
    let y = (i + 1) as f64;
    p.items
        .iter()
        .filter_map(|item| match item {
            Item::Segments { segments, .. } => Some(segments),
            _ => None,
        })
        .flatten()
        .filter(|[a, b]| a.1 == y && b.1 == y)
        .map(|[a, b]| (a.0, b.0))
        .collect()
}

/// Checks that agent `i`'s bars cover exactly its saturated logged instants:
/// instant `k` is saturated iff some bar starts at or before `t_k` and ends
/// after it (or ends at it, for the last instant). Returns the saturated count.
fn assert_bars_match_sat(figure: &Figure, times: &[f64], sat: &[f64], i: usize) -> usize {
    let spans = bars(figure, i);
    let last = times.len() - 1;
    for (k, (&t, &s)) in times.iter().zip(sat).enumerate() {
        let covered = spans
            .iter()
            .any(|&(t0, t1)| t0 <= t && (t < t1 || (k == last && t == t1)));
        assert_eq!(covered, s == 1.0, "agent {}, t = {t}: sat = {s}", i + 1);
    }
    sat.iter().filter(|&&s| s == 1.0).count()
}

#[test]
fn a_velocity_runs_signals_show_command_against_actual_with_limits_and_saturation() {
    // TurtleBot 3 Burgers catching up from rest: the command exceeds the
    // 0.22 m/s limit for the first seconds.
    let (dir, data) = common::load_builtin("turtlebot-circle", &common::for_seconds(12.0));
    assert!(data.agents.iter().all(|a| a.is_velocity()));
    let figure = plots::signals(&data);
    assert!(figure.title.contains("commanded and actual speeds"));
    // No torque panels for velocity bases.
    assert_eq!(quantities(&figure), ["v", "ω", "‖e‖", "‖z‖", "agent"]);
    let times = csv_times(dir.path(), 1);
    let mut saturated_anywhere = 0;
    for i in 0..3 {
        let with_t = |c: &[f64]| -> Vec<(f64, f64)> {
            times.iter().copied().zip(c.iter().copied()).collect()
        };
        for (quantity, actual, commanded, limit) in [
            ("v", Column::V, Column::VCmd, 0.22),
            ("ω", Column::Omega, Column::OmegaCmd, 2.84),
        ] {
            let p = panel(&figure, quantity);
            let actual = csv_column(dir.path(), i + 1, actual);
            let commanded = csv_column(dir.path(), i + 1, commanded);
            // Actual solid, commanded dashed, in the agent's colour: the CSV's values.
            assert_eq!(line_with(p, Stroke::series(i)), with_t(&actual));
            assert_eq!(
                line_with(p, Stroke::series(i).dashed(Dash::Dashed)),
                with_t(&commanded)
            );
            // The base never exceeds its limit, and the limit lines are its.
            assert!(actual.iter().all(|x| x.abs() <= limit * (1.0 + 1e-12)));
            let unit = if quantity == "v" { "m/s" } else { "rad/s" };
            let name = if quantity == "v" { "v_max" } else { "ω_max" };
            let limits = labelled_segments(p);
            assert_eq!(limits.len(), 1, "{limits:?}");
            assert_eq!(limits[0].0, format!("±{name} = {limit} {unit}"));
            let (t0, t1) = (times[0], *times.last().unwrap());
            assert_eq!(
                limits[0].1,
                [[(t0, limit), (t1, limit)], [(t0, -limit), (t1, -limit)]]
            );
            assert!(common::labelled_line(p, COMMANDED_LABEL).is_some());
        }
        // The command is cut: it asks for more than the base gives.
        let v_cmd = csv_column(dir.path(), i + 1, Column::VCmd);
        let sat = csv_column(dir.path(), i + 1, Column::Sat);
        if v_cmd.iter().any(|v| v.abs() > 0.22) {
            assert!(sat.contains(&1.0));
        }
        saturated_anywhere += assert_bars_match_sat(&figure, &times, &sat, i);
        assert_eq!(data.agents[i].get(Column::Sat), sat.as_slice());
    }
    assert!(saturated_anywhere > 0, "the scenario saturates early");

    // The files and the report's text: saturated steps from summary.json.
    write_all(dir.path()).unwrap();
    let svg = std::fs::read_to_string(dir.path().join("signals.svg")).unwrap();
    for text in [
        "v [m/s]",
        "ω [rad/s]",
        COMMANDED_LABEL,
        "±v_max = 0.22 m/s",
        "±ω_max = 2.84 rad/s",
        "burger 3",
    ] {
        assert!(svg.contains(text), "signals.svg lacks {text}");
    }
    assert!(!svg.contains("τ_r"));
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join(SUMMARY_FILE)).unwrap()).unwrap();
    let steps = summary["steps"].as_u64().unwrap();
    let html = std::fs::read_to_string(dir.path().join(REPORT_FILE)).unwrap();
    assert!(html.contains("id=\"saturation\""));
    assert!(html.contains("<th>saturated steps</th>"));
    for a in summary["agents"].as_array().unwrap() {
        let n = a["saturated_ticks"].as_u64().unwrap();
        assert!(n > 0);
        let want = format!(
            "{}: {n} of {steps} steps ({:.1} %)",
            a["name"].as_str().unwrap(),
            100.0 * n as f64 / steps as f64
        );
        assert!(html.contains(&want), "report.html lacks `{want}`");
    }

    // Without scenario.toml the limits are unknown: no limit lines, the rest stays.
    std::fs::remove_file(dir.path().join(SCENARIO_FILE)).unwrap();
    let data = RunData::load(dir.path()).unwrap();
    let figure = plots::signals(&data);
    assert!(labelled_segments(panel(&figure, "v")).is_empty());
    assert!(has_line_with(
        panel(&figure, "v"),
        Stroke::series(0).dashed(Dash::Dashed)
    ));
}

/// An ideal base (circle-pentagon-velocity) is never saturated, and follows
/// its command exactly: the dashed and solid lines are the same numbers (after
/// `t = 0`, where the robots stand at their start speeds).
#[test]
fn an_ideal_base_follows_its_command_and_never_saturates() {
    let (_dir, data) = common::load_builtin("circle-pentagon-velocity", &common::for_seconds(3.0));
    let figure = plots::signals(&data);
    let v = panel(&figure, "v");
    for i in 0..4 {
        let actual = line_with(v, Stroke::series(i));
        let commanded = line_with(v, Stroke::series(i).dashed(Dash::Dashed));
        assert_eq!(actual[0].1, 0.0);
        for (a, c) in actual.iter().zip(commanded).skip(1) {
            assert!(
                (a.1 - c.1).abs() <= 1e-12 * c.1.abs().max(1.0),
                "{a:?} {c:?}"
            );
        }
        assert!(bars(&figure, i).is_empty());
    }
    // Unlimited: no limit lines; the saturation panel says "never".
    assert!(labelled_segments(v).is_empty());
    assert_eq!(
        panel(&figure, "agent").title.as_deref(),
        Some("speed limits cutting the command: never")
    );
}

const MIXED: &str = include_str!("fixtures/mixed.toml");

#[test]
fn a_mixed_run_shows_torques_for_the_torque_agent_and_commands_for_the_base() {
    let (dir, data) = common::load_source(MIXED, &echelon::scenario::Overrides::default());
    assert!(!data.agents[0].is_velocity() && data.agents[1].is_velocity());
    assert!(data.agents[0].limits.is_none());
    let figure = plots::signals(&data);
    assert_eq!(
        quantities(&figure),
        ["v", "ω", "‖e‖", "‖z‖", "τ_r", "τ_l", "agent"]
    );
    let times = csv_times(dir.path(), 1);
    let v = panel(&figure, "v");
    // The torque agent: its actual speed, no command.
    let v1 = csv_series(dir.path(), 1, Column::V);
    assert_eq!(line_with(v, Stroke::series(0)), v1);
    assert!(!has_line_with(v, Stroke::series(0).dashed(Dash::Dashed)));
    // The base: its command.
    let c2 = csv_series(dir.path(), 2, Column::VCmd);
    assert_eq!(line_with(v, Stroke::series(1).dashed(Dash::Dashed)), c2);
    // Torques: the torque agent's numbers; the base's are NaN (not drawn).
    let tau = panel(&figure, "τ_r");
    let t1 = csv_series(dir.path(), 1, Column::TauR);
    assert_eq!(line_with(tau, Stroke::series(0)), t1);
    assert!(bars(&figure, 0).is_empty(), "a torque agent has no bars");
    assert_bars_match_sat(&figure, &times, &csv_column(dir.path(), 2, Column::Sat), 1);
    write_all(dir.path()).unwrap();
    let html = std::fs::read_to_string(dir.path().join(REPORT_FILE)).unwrap();
    assert!(html.contains("— (torque)"));
    assert!(html.contains("burger: "));
}

/// A torque run's signals are the paper's Fig. 14, as before velocity bases:
/// the same title, size and six panels, each agent's column as a solid line.
#[test]
fn a_torque_runs_signals_figure_is_unchanged() {
    let (dir, data) = common::load_builtin("circle-pentagon", &common::for_seconds(4.0));
    assert!(!data.has_velocity_agents());
    let times = csv_times(dir.path(), 1);
    let panel_of =
        |quantity: &str, unit: &str, legend: bool, values: &dyn Fn(usize) -> Vec<f64>| {
            let mut p = Panel::new(Axis::new("t", "s"), Axis::new(quantity, unit));
            if !legend {
                p = p.without_legend();
            }
            for i in 0..4 {
                p.line(
                    &format!("agent {}", i + 1),
                    times.iter().copied().zip(values(i)).collect(),
                    Stroke::series(i),
                );
            }
            p
        };
    let path = dir.path();
    let col = |c: Column| move |i: usize| csv_column(path, i + 1, c);
    let norm = |x: Column, y: Column| {
        move |i: usize| {
            csv_column(path, i + 1, x)
                .iter()
                .zip(csv_column(path, i + 1, y))
                .map(|(a, b)| a.hypot(b))
                .collect()
        }
    };
    let want = Figure::new("circle-pentagon: speeds, errors and torques", 1200, 1050)
        .with_columns(2)
        .with_panel(panel_of("v", "m/s", true, &col(Column::V)))
        .with_panel(panel_of("ω", "rad/s", false, &col(Column::Omega)))
        .with_panel(panel_of("‖e‖", "m", false, &norm(Column::Ex, Column::Ey)))
        .with_panel(panel_of("‖z‖", "m/s", false, &norm(Column::Zx, Column::Zy)))
        .with_panel(panel_of("τ_r", "N·m", false, &col(Column::TauR)))
        .with_panel(panel_of("τ_l", "N·m", false, &col(Column::TauL)));
    assert_eq!(plots::signals(&data), want);
    // No saturation column or note in a torque run's report.
    write_all(dir.path()).unwrap();
    let html = std::fs::read_to_string(dir.path().join(REPORT_FILE)).unwrap();
    assert!(!html.contains("saturated steps") && !html.contains("id=\"saturation\""));
}
