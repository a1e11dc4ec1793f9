//! The run figures, as in the paper: `paths` (Figs. 8, 10, 12, 16, 17),
//! `errors` (Figs. 9, 11) and `signals` (Fig. 14).

use crate::figure::{Axis, Figure, Marker, Panel, Stroke, palette};
use crate::run::{Column, RunData};

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
    let col = |c: Column| move |i: usize| data.agents[i].get(c).to_vec();
    Figure::new(
        &format!(
            "{}: tracking error e (eq. 7, follower frame)",
            data.summary.scenario
        ),
        1000,
        720,
    )
    .with_panel(time_panel(
        data,
        Axis::new("e_x", "m"),
        col(Column::Ex),
        true,
    ))
    .with_panel(time_panel(
        data,
        Axis::new("e_y", "m"),
        col(Column::Ey),
        false,
    ))
}

/// v, ω, ‖e‖, ‖z‖ and the wheel torques against time (Fig. 14).
pub fn signals(data: &RunData) -> Figure {
    let col = |c: Column| move |i: usize| data.agents[i].get(c).to_vec();
    let z_norm = |i: usize| {
        let a = &data.agents[i];
        a.get(Column::Zx)
            .iter()
            .zip(a.get(Column::Zy))
            .map(|(x, y)| x.hypot(*y))
            .collect()
    };
    Figure::new(
        &format!("{}: speeds, errors and torques", data.summary.scenario),
        1200,
        1050,
    )
    .with_columns(2)
    .with_panel(time_panel(
        data,
        Axis::new("v", "m/s"),
        col(Column::V),
        true,
    ))
    .with_panel(time_panel(
        data,
        Axis::new("ω", "rad/s"),
        col(Column::Omega),
        false,
    ))
    .with_panel(time_panel(
        data,
        Axis::new("‖e‖", "m"),
        |i| data.agents[i].error_norm(),
        false,
    ))
    .with_panel(time_panel(data, Axis::new("‖z‖", "m/s"), z_norm, false))
    .with_panel(time_panel(
        data,
        Axis::new("τ_r", "N·m"),
        col(Column::TauR),
        false,
    ))
    .with_panel(time_panel(
        data,
        Axis::new("τ_l", "N·m"),
        col(Column::TauL),
        false,
    ))
}

/// The run figures with their file stems: `paths`, `errors`, `signals`, and
/// `drift` when agents dead-reckon.
pub fn run_figures(data: &RunData) -> Vec<(&'static str, Figure)> {
    let mut figures = vec![
        ("paths", paths(data)),
        ("errors", errors(data)),
        ("signals", signals(data)),
    ];
    if let Some(drift) = crate::odometry::drift(data) {
        figures.push(("drift", drift));
    }
    figures
}
