//! Odometry figures (paper section 6): a run's drift — true against estimated
//! paths, drift with its resets at fixes, the error the controller saw against
//! the true one — and a sweep's empirical ‖z‖, ‖e‖ against Theorem 2 (in the
//! form of each run's law: the paper's, or the kinematic law's, see
//! [`echelon::sweep`]).

use echelon::sweep::{Case, DriftCurve, Laws, Row};

use crate::figure::{Axis, Dash, Figure, Marker, Panel, Stroke, palette};
use crate::run::{Column, RunData};

/// The run's `drift` figure, if any agent dead-reckons.
pub fn drift(data: &RunData) -> Option<Figure> {
    let tracks: Vec<(usize, &crate::run::OdometryTrack)> = data
        .odometry
        .iter()
        .enumerate()
        .filter_map(|(i, t)| t.as_ref().map(|t| (i, t)))
        .collect();
    if tracks.is_empty() {
        return None;
    }
    let mut paths = Panel::new(Axis::new("x", "m"), Axis::new("y", "m"))
        .equal_aspect()
        .titled("true paths (solid) and what odometry believed (dashed); dots: fixes");
    let mut drift = Panel::new(Axis::new("t", "s"), Axis::new("‖p − p̂‖", "m"))
        .titled("odometry drift, reset by each fix")
        .without_legend();
    let mut errors = Panel::new(Axis::new("t", "s"), Axis::new("‖e‖", "m"))
        .titled("true ‖e‖ (solid) and the ‖ê‖ the controller saw (dashed)")
        .without_legend();
    for &(i, t) in &tracks {
        let a = &data.agents[i];
        let (xs, ys) = (a.get(Column::X), a.get(Column::Y));
        let stroke = Stroke::series(i);
        paths.line(
            &a.name,
            xs.iter().copied().zip(ys.iter().copied()).collect(),
            stroke,
        );
        paths.line(
            &format!("{} (estimate)", a.name),
            t.x.iter().copied().zip(t.y.iter().copied()).collect(),
            stroke.dashed(Dash::Dashed),
        );
        let fixes: Vec<((f64, f64), Marker)> = (0..t.fix.len())
            .filter(|&k| t.fix[k] > 0.0)
            .map(|k| ((xs[k], ys[k]), Marker::Dot))
            .collect();
        if !fixes.is_empty() {
            paths.markers("", fixes, palette::series(i));
        }
        let gap: Vec<(f64, f64)> = (0..data.times.len())
            .map(|k| (data.times[k], (xs[k] - t.x[k]).hypot(ys[k] - t.y[k])))
            .collect();
        drift.line(&a.name, gap, stroke);
        let e = a.error_norm();
        errors.line(&a.name, data.times.iter().copied().zip(e).collect(), stroke);
        let e_hat: Vec<(f64, f64)> = (0..data.times.len())
            .map(|k| (data.times[k], t.ex[k].hypot(t.ey[k])))
            .collect();
        errors.line(
            &format!("{} (believed)", a.name),
            e_hat,
            stroke.dashed(Dash::Dashed),
        );
    }
    Some(
        Figure::new(
            &format!(
                "{}: odometry drift (paper section 6)",
                data.summary.scenario
            ),
            1000,
            1300,
        )
        .with_panel(paths)
        .with_panel(drift)
        .with_panel(errors),
    )
}

/// A short label for an error model.
fn model_label(c: &Case) -> String {
    let mut parts = vec![format!("ζ = {:e} m", c.zeta)];
    if c.wheel_diameter_ratio != 1.0 {
        parts.push(format!("E_d = {}", c.wheel_diameter_ratio));
    }
    if c.wheelbase_ratio != 1.0 {
        parts.push(format!("E_b = {}", c.wheelbase_ratio));
    }
    if c.slip != 0.0 {
        parts.push(format!("slip {:e} m²/m", c.slip));
    }
    parts.join(", ")
}

/// The error models of a sweep, in grid order.
fn models(rows: &[Row]) -> Vec<Case> {
    let mut out: Vec<Case> = Vec::new();
    for r in rows {
        let m = r.case.error_model();
        if !out.contains(&m) {
            out.push(m);
        }
    }
    out
}

/// The laws of a set of rows (of those with a bound; of all if none has one):
/// one form when they agree, else [`Laws::Mixed`].
fn laws_of(rows: &[&Row]) -> Laws {
    let bounded: Vec<Laws> = rows
        .iter()
        .filter(|r| r.z_bound.is_some())
        .map(|r| r.laws)
        .collect();
    let laws = if bounded.is_empty() {
        rows.iter().map(|r| r.laws).collect()
    } else {
        bounded
    };
    match laws.first() {
        Some(&first) if laws.iter().all(|l| *l == first) => first,
        Some(_) => Laws::Mixed,
        None => Laws::Dynamic,
    }
}

/// The bound line's legend entry for an error model.
fn bound_label(laws: Laws, model: &str) -> String {
    match laws {
        Laws::Dynamic => format!("Theorem 2, {model}"),
        Laws::Kinematic => format!("Theorem 2 (kinematic law), {model}"),
        Laws::Mixed => format!("Theorem 2 (both laws), {model}"),
    }
}

/// One panel of a quantity against the fix interval `N`, log-log: every run as
/// a dot, and the theoretical bound as a dashed line per error model.
fn against_n(
    rows: &[Row],
    y: Axis,
    value: fn(&Row) -> f64,
    bound: fn(&Row) -> Option<f64>,
    title: &str,
) -> Panel {
    let mut panel =
        Panel::new(Axis::new("N (samples between fixes)", "").log(), y.log()).titled(title);
    for (i, m) in models(rows).iter().enumerate() {
        let of_model: Vec<&Row> = rows
            .iter()
            .filter(|r| r.case.fix_every > 0 && r.case.error_model() == *m)
            .collect();
        let dots: Vec<((f64, f64), Marker)> = of_model
            .iter()
            .filter(|r| value(r) > 0.0)
            .map(|r| ((r.case.fix_every as f64, value(r)), Marker::Dot))
            .collect();
        if dots.is_empty() {
            continue;
        }
        panel.markers(&model_label(m), dots, palette::series(i));
        let mut ns: Vec<u64> = of_model.iter().map(|r| r.case.fix_every).collect();
        ns.sort_unstable();
        ns.dedup();
        let line: Vec<(f64, f64)> = ns
            .iter()
            .filter_map(|&n| {
                of_model
                    .iter()
                    .filter(|r| r.case.fix_every == n)
                    .filter_map(|r| bound(r))
                    .reduce(f64::max)
                    .map(|b| (n as f64, b))
            })
            .collect();
        if line.len() >= 2 {
            panel.line(
                &bound_label(laws_of(&of_model), &model_label(m)),
                line,
                Stroke::series(i).dashed(Dash::Dashed),
            );
        }
    }
    panel
}

/// The sweep figure: empirical ultimate ‖z‖ and ‖e‖ against `N` with Theorem 2's
/// bounds, and drift without fixes against the paper's linear growth.
///
/// Each run's bound is in the form of its law ([`echelon::sweep`]'s module
/// docs): for the paper's law the ultimate bound on ‖z‖ and `‖z‖/K_e`; for the
/// kinematic law `√2 K_e N ζ` on ‖z‖ and its ultimate bound `√2 N ζ / γ` on ‖e‖.
pub fn sweep(name: &str, rows: &[Row], curves: &[DriftCurve]) -> Figure {
    let all: Vec<&Row> = rows.iter().collect();
    let (z_title, e_title) = match laws_of(&all) {
        Laws::Dynamic => (
            "true ‖z‖ of every run (dots) under Theorem 2's bound (dashed)",
            "true ‖e‖ of every run (dots) under the bound ‖z‖/K_e (dashed)",
        ),
        Laws::Kinematic => (
            "true ‖z‖ of every run (dots) under the kinematic law's bound √2 K_e N ζ (dashed)",
            "true ‖e‖ of every run (dots) under the kinematic law's ultimate bound √2 N ζ / γ (dashed)",
        ),
        Laws::Mixed => (
            "true ‖z‖ of every run (dots) under Theorem 2's bound for its law (dashed)",
            "true ‖e‖ of every run (dots) under ‖z‖/K_e (paper law) or √2 N ζ / γ (kinematic law) (dashed)",
        ),
    };
    let z = against_n(
        rows,
        Axis::new("ultimate max ‖z‖", "m/s"),
        |r| r.z_max,
        |r| r.z_bound,
        z_title,
    );
    let e = against_n(
        rows,
        Axis::new("ultimate max ‖e‖", "m"),
        |r| r.e_max,
        |r| r.e_bound,
        e_title,
    );
    let mut growth = Panel::new(Axis::new("t", "s"), Axis::new("‖p − p̂‖ without fixes", "m"))
        .titled("drift: actual (solid), the paper's √2 N ζ (dashed), linear from the first second (dotted)");
    let mut zetas_drawn: Vec<f64> = Vec::new();
    for (i, c) in curves.iter().enumerate() {
        let label = model_label(&c.case);
        let series = |v: &[f64]| c.times.iter().copied().zip(v.iter().copied()).collect();
        growth.line(&label, series(&c.drift), Stroke::series(i));
        // The paper's line depends on ζ only: once per ζ.
        if c.case.zeta > 0.0 && !zetas_drawn.contains(&c.case.zeta) {
            zetas_drawn.push(c.case.zeta);
            growth.line(
                &format!("paper: √2 N ζ, ζ = {:e} m", c.case.zeta),
                series(&c.paper),
                Stroke::reference(),
            );
        }
        if c.case.outside_assumption_1() {
            growth.line(
                &format!("linear from 1 s, {label}"),
                series(&c.early_slope),
                Stroke::series(i).dashed(Dash::Dotted),
            );
        }
    }
    Figure::new(
        &format!("{name}: how often a position fix is needed (Theorem 2)"),
        1000,
        1400,
    )
    .with_panel(z)
    .with_panel(e)
    .with_panel(growth)
}
