//! The run figures, as in the paper: `paths` (Figs. 8, 10, 12, 16, 17),
//! `errors` (Figs. 9, 11) and `signals` (Fig. 14; for velocity bases,
//! commanded against actual `v`, `ω` and saturation).

use crate::figure::{Axis, Dash, Figure, Marker, Panel, Stroke, palette};
use crate::run::{AgentTrack, Column, RunData, SpeedLimits, spans_where};

/// How many instants the `paths` figure shows the formation at.
pub const LINK_INSTANTS: usize = 5;

/// The logged instants (indices) at which `paths` draws the formation: evenly
/// spread over the run, the last one included, `t = 0` left to the start markers.
pub fn link_instants(data: &RunData) -> Vec<usize> {
    let n = data.times.len();
    if n < 2 {
        return Vec::new();
    }
    let mut ks: Vec<usize> = (1..=LINK_INSTANTS)
        .map(|j| ((j * (n - 1)) as f64 / LINK_INSTANTS as f64).round() as usize)
        .collect();
    ks.dedup();
    ks
}

fn times_label(data: &RunData, ks: &[usize]) -> String {
    let ts: Vec<String> = ks
        .iter()
        .map(|&k| format!("{:.1}", data.times[k]))
        .collect();
    format!("t = {} s", ts.join(", "))
}

/// Every agent's path, the reference, start poses (open triangles) and the
/// formation (poses and dotted leader–follower links) at [`link_instants`].
pub fn paths(data: &RunData) -> Figure {
    let mut panel = Panel::new(Axis::new("x", "m"), Axis::new("y", "m")).equal_aspect();
    if let Some(r) = data.reference.as_ref().filter(|_| data.uses_reference()) {
        panel.line(
            "reference",
            r.x.iter().copied().zip(r.y.iter().copied()).collect(),
            Stroke::reference(),
        );
    }
    for (i, a) in data.agents.iter().enumerate() {
        let xs = a.get(Column::X);
        let ys = a.get(Column::Y);
        panel.line(
            &a.name,
            xs.iter().copied().zip(ys.iter().copied()).collect(),
            Stroke::series(i),
        );
    }
    let ks = link_instants(data);
    let mut links = Vec::new();
    let mut ref_points = Vec::new();
    for &k in &ks {
        for i in 0..data.agents.len() {
            let a = &data.agents[i];
            let p = (a.get(Column::X)[k], a.get(Column::Y)[k]);
            if let Some(l) = data.leader_position(i, k) {
                links.push([p, l]);
            }
        }
        if let Some(r) = data.reference.as_ref().filter(|_| data.uses_reference()) {
            ref_points.push(((r.x[k], r.y[k]), Marker::Dot));
        }
    }
    if !links.is_empty() {
        panel.segments(
            &format!("leader links, {}", times_label(data, &ks)),
            links,
            Stroke::link(),
        );
    }
    if !ref_points.is_empty() {
        panel.markers("", ref_points, palette::MUTED);
    }
    for (i, a) in data.agents.iter().enumerate() {
        let (xs, ys, th) = (a.get(Column::X), a.get(Column::Y), a.get(Column::Theta));
        let mut at = vec![(
            (xs[0], ys[0]),
            Marker::Robot {
                heading: th[0],
                filled: false,
            },
        )];
        at.extend(ks.iter().map(|&k| {
            (
                (xs[k], ys[k]),
                Marker::Robot {
                    heading: th[k],
                    filled: true,
                },
            )
        }));
        panel.markers("", at, palette::series(i));
    }
    let title = format!(
        "{}: paths (open triangles: start poses; filled: formation at the link instants)",
        data.summary.scenario
    );
    // As tall as the paths need at 1000 px wide (equal scales), within reason.
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for a in &data.agents {
        for (&x, &y) in a.get(Column::X).iter().zip(a.get(Column::Y)) {
            if x.is_finite() && y.is_finite() {
                (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
            }
        }
    }
    let aspect = if x1 > x0 && y1 >= y0 {
        (y1 - y0) / (x1 - x0)
    } else {
        1.0
    };
    // Room for the legend: above wide paths, right of tall ones.
    let entries = data.agents.len().min(crate::figure::LEGEND_MAX) + 3;
    let legend_h = 19.0 * entries as f64;
    let (width, height) = if aspect < 0.6 {
        (
            1000,
            (900.0 * aspect * 1.05 + 130.0 + legend_h).clamp(560.0, 1000.0) as u32,
        )
    } else {
        let plot_h = 780.0;
        (
            ((plot_h / aspect) * 1.05 + 100.0 + 380.0).clamp(900.0, 1500.0) as u32,
            900,
        )
    };
    Figure::new(&title, width, height).with_panel(panel)
}

/// Every agent's column `c` against time.
fn column_panel(data: &RunData, y: Axis, c: Column, legend: bool) -> Panel {
    time_panel(data, y, |i| data.agents[i].get(c).to_vec(), legend)
}

fn time_panel(data: &RunData, y: Axis, series: impl Fn(usize) -> Vec<f64>, legend: bool) -> Panel {
    let mut panel = Panel::new(Axis::new("t", "s"), y);
    if !legend {
        panel = panel.without_legend();
    }
    for (i, a) in data.agents.iter().enumerate() {
        let values = series(i);
        panel.line(
            &a.name,
            data.times.iter().copied().zip(values).collect(),
            Stroke::series(i),
        );
    }
    panel
}

/// `e_x` and `e_y` of every agent against time (Figs. 9, 11).
pub fn errors(data: &RunData) -> Figure {
    Figure::new(
        &format!(
            "{}: tracking error e (eq. 7, follower frame)",
            data.summary.scenario
        ),
        1000,
        720,
    )
    .with_panel(column_panel(data, Axis::new("e_x", "m"), Column::Ex, true))
    .with_panel(column_panel(data, Axis::new("e_y", "m"), Column::Ey, false))
}

/// v, ω, ‖e‖, ‖z‖ and the wheel torques against time (Fig. 14).
///
/// A run with velocity bases ([`RunData::has_velocity_agents`]) gets
/// [`velocity_signals`] instead; a torque-only run gets the paper's figure.
pub fn signals(data: &RunData) -> Figure {
    if data.has_velocity_agents() {
        return velocity_signals(data);
    }
    let figure = Figure::new(
        &format!("{}: speeds, errors and torques", data.summary.scenario),
        1200,
        1050,
    )
    .with_columns(2)
    .with_panel(column_panel(data, Axis::new("v", "m/s"), Column::V, true))
    .with_panel(column_panel(
        data,
        Axis::new("ω", "rad/s"),
        Column::Omega,
        false,
    ))
    .with_panel(error_norm_panel(data))
    .with_panel(z_norm_panel(data));
    let [tau_r, tau_l] = torque_panels(data);
    figure.with_panel(tau_r).with_panel(tau_l)
}

fn error_norm_panel(data: &RunData) -> Panel {
    time_panel(
        data,
        Axis::new("‖e‖", "m"),
        |i| data.agents[i].error_norm(),
        false,
    )
}

fn z_norm_panel(data: &RunData) -> Panel {
    time_panel(
        data,
        Axis::new("‖z‖", "m/s"),
        |i| data.agents[i].norm(Column::Zx, Column::Zy),
        false,
    )
}

fn torque_panels(data: &RunData) -> [Panel; 2] {
    [
        column_panel(data, Axis::new("τ_r", "N·m"), Column::TauR, false),
        column_panel(data, Axis::new("τ_l", "N·m"), Column::TauL, false),
    ]
}

/// The legend entry for the commanded lines of [`velocity_signals`].
pub const COMMANDED_LABEL: &str = "commanded (dashed)";

/// Commanded against actual speed: every agent's actual `actual` solid, and a
/// velocity agent's command `commanded` dashed in the same colour, with the
/// bases' limits `±limit` as dotted lines (one pair per distinct finite limit).
fn command_panel(
    data: &RunData,
    y: Axis,
    (actual, commanded): (Column, Column),
    limit: fn(&SpeedLimits) -> f64,
    limit_name: &str,
    names: bool,
) -> Panel {
    let unit = y.unit.clone();
    let mut panel = Panel::new(Axis::new("t", "s"), y);
    let series = |a: &AgentTrack, c: Column| -> Vec<(f64, f64)> {
        data.times
            .iter()
            .copied()
            .zip(a.get(c).iter().copied())
            .collect()
    };
    for (i, a) in data.agents.iter().enumerate() {
        let label = if names { a.name.as_str() } else { "" };
        panel.line(label, series(a, actual), Stroke::series(i));
    }
    for (i, a) in data.agents.iter().enumerate() {
        if a.is_velocity() {
            panel.line(
                "",
                series(a, commanded),
                Stroke::series(i).dashed(Dash::Dashed),
            );
        }
    }
    // A legend line only (no points): what the dashes mean.
    panel.line(COMMANDED_LABEL, Vec::new(), Stroke::reference());
    let mut limits: Vec<f64> = Vec::new();
    for l in data.agents.iter().filter_map(|a| a.limits.as_ref()) {
        let m = limit(l);
        if m.is_finite() && !limits.contains(&m) {
            limits.push(m);
        }
    }
    let (t0, t1) = (
        data.times.first().copied().unwrap_or(0.0),
        data.times.last().copied().unwrap_or(0.0),
    );
    for m in limits {
        panel.segments(
            &format!("±{limit_name} = {m} {unit}"),
            vec![[(t0, m), (t1, m)], [(t0, -m), (t1, -m)]],
            Stroke::link(),
        );
    }
    panel
}

/// The maximal runs of saturated logged instants of agent `a`, as time spans:
/// instant `k` covers `[t_k, t_{k+1}]` (the last one, `[t_k, t_k]`).
pub fn saturated_spans(data: &RunData, a: &AgentTrack) -> Vec<(f64, f64)> {
    let sat = a.get(Column::Sat);
    spans_where(&data.times, sat.len(), |k| sat[k] == 1.0)
}

/// When the speed limits cut each velocity agent's command: a bar at the
/// agent's number over every saturated span ([`saturated_spans`]).
fn saturation_panel(data: &RunData) -> Panel {
    let n = data.agents.len();
    let spans: Vec<(usize, Vec<(f64, f64)>)> = (0..n)
        .filter(|&i| data.agents[i].is_velocity())
        .map(|i| (i, saturated_spans(data, &data.agents[i])))
        .collect();
    let title = if spans.iter().any(|(_, s)| !s.is_empty()) {
        "speed limits cutting the command (bars: saturated spans)"
    } else {
        "speed limits cutting the command: never"
    };
    let (t0, t1) = (
        data.times.first().copied().unwrap_or(0.0),
        data.times.last().copied().unwrap_or(1.0),
    );
    // The time axis of the other panels (their 5 % margin), and whole agent
    // numbers on the other axis.
    let margin = 0.05 * (t1 - t0).max(1e-9);
    let mut panel = Panel::new(
        Axis::new("t", "s").range(t0 - margin, t1 + margin),
        Axis::new("agent", "").range(0.0, n as f64 + 1.0).integer(),
    )
    .titled(title)
    .without_legend();
    for (i, spans) in spans {
        let y = (i + 1) as f64;
        panel.segments(
            "",
            spans.into_iter().map(|(a, b)| [(a, y), (b, y)]).collect(),
            Stroke {
                width: 8,
                ..Stroke::series(i)
            },
        );
    }
    panel
}

/// The signals of a run with velocity bases: commanded (dashed) against
/// actual (solid) `v` and `ω` with the bases' limits (dotted), ‖e‖, ‖z‖, the
/// wheel torques when some agents are torque-driven (a mixed run), and when
/// the speed limits cut each velocity agent's command.
pub fn velocity_signals(data: &RunData) -> Figure {
    let torque_agents = data.agents.iter().any(|a| !a.is_velocity());
    let mut figure = Figure::new(
        &format!(
            "{}: commanded and actual speeds, errors{} and saturation",
            data.summary.scenario,
            if torque_agents { ", torques" } else { "" }
        ),
        1200,
        if torque_agents { 1400 } else { 1050 },
    )
    .with_columns(2)
    .with_panel(command_panel(
        data,
        Axis::new("v", "m/s"),
        (Column::V, Column::VCmd),
        |l| l.v_max,
        "v_max",
        true,
    ))
    .with_panel(command_panel(
        data,
        Axis::new("ω", "rad/s"),
        (Column::Omega, Column::OmegaCmd),
        |l| l.omega_max,
        "ω_max",
        false,
    ))
    .with_panel(error_norm_panel(data))
    .with_panel(z_norm_panel(data));
    if torque_agents {
        let [tau_r, tau_l] = torque_panels(data);
        figure = figure.with_panel(tau_r).with_panel(tau_l);
    }
    figure.with_panel(saturation_panel(data))
}

/// The file stems of every run figure [`run_figures`] may draw.
pub const RUN_FIGURES: [&str; 5] = ["paths", "errors", "signals", "drift", "safety"];

/// The run figures with their file stems: `paths`, `errors`, `signals`,
/// `drift` when agents dead-reckon, and `safety` when a safety filter ran.
pub fn run_figures(data: &RunData) -> Vec<(&'static str, Figure)> {
    let mut figures = vec![
        ("paths", paths(data)),
        ("errors", errors(data)),
        ("signals", signals(data)),
    ];
    if let Some(drift) = crate::odometry::drift(data) {
        figures.push(("drift", drift));
    }
    if let Some(safety) = crate::safety::figure(data) {
        figures.push(("safety", safety));
    }
    figures
}
