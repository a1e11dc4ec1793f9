//! The `safety` figure of a run with a barrier-certificate filter
//! (`echelon::safety`, `docs/safety.md`): how close the robots' points `L`
//! ahead came to each other and to the obstacles' edges against time, with
//! the `radius` they must keep, and when each robot's filter changed its
//! command, braked (QP infeasible) or broke a deadlock.

use crate::figure::{Axis, Dash, Figure, Marker, Panel, Stroke, palette};
use crate::run::{RunData, SafetyData, SafetyReport, spans_where};

/// At each logged instant, the smallest distance between two robots' points
/// `L` ahead, m (`None`: no safety filter, `L` unknown, or fewer than two robots).
pub fn min_distances(data: &RunData) -> Option<Vec<f64>> {
    let s = data.safety.as_ref()?;
    let n = data.agents.len();
    if n < 2 || s.l.len() != n {
        return None;
    }
    Some(
        (0..data.times.len())
            .map(|k| {
                let points: Vec<(f64, f64)> = (0..n).filter_map(|i| s.point(data, i, k)).collect();
                let mut best = f64::INFINITY;
                for i in 0..n {
                    for j in 0..i {
                        let d = (points[i].0 - points[j].0).hypot(points[i].1 - points[j].1);
                        best = best.min(d);
                    }
                }
                best
            })
            .collect(),
    )
}

/// Per obstacle, at each logged instant, the smallest distance from a
/// robot's point to the obstacle's edge, m (empty: no obstacles, or `L` unknown).
pub fn obstacle_clearances(data: &RunData) -> Vec<Vec<f64>> {
    let Some(s) = data.safety.as_ref() else {
        return Vec::new();
    };
    if s.l.len() != data.agents.len() {
        return Vec::new();
    }
    s.obstacles
        .iter()
        .map(|o| {
            (0..data.times.len())
                .map(|k| {
                    (0..data.agents.len())
                        .filter_map(|i| s.point(data, i, k))
                        .map(|(x, y)| (x - o.x()).hypot(y - o.y()) - o.r())
                        .fold(f64::INFINITY, f64::min)
                })
                .collect()
        })
        .collect()
}

/// What a filter did, for [`filter_spans`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Action {
    /// Changed the command (filtered or braked).
    Acted,
    /// Braked: the QP was infeasible.
    Braked,
    /// Broke a deadlock (its nominal turned).
    Deadlock,
}

/// The maximal runs of logged instants at which agent `i`'s filter did
/// `action`, as time spans (instant `k` covers `[t_k, t_{k+1}]`).
pub fn filter_spans(data: &RunData, s: &SafetyData, i: usize, action: Action) -> Vec<(f64, f64)> {
    let Some(Some(t)) = s.tracks.get(i) else {
        return Vec::new();
    };
    spans_where(&data.times, t.outcome.len(), |k| match action {
        Action::Acted => t.outcome[k] != 0,
        Action::Braked => t.outcome[k] == 2,
        Action::Deadlock => t.deadlock[k],
    })
}

/// The legend entries of the second panel.
pub const ACTED_LABEL: &str = "filter changed the command";
/// See [`ACTED_LABEL`].
pub const BRAKED_LABEL: &str = "braked (QP infeasible)";
/// See [`ACTED_LABEL`].
pub const DEADLOCK_LABEL: &str = "breaking a deadlock";

/// The top panel of [`figure`]: the closest pair and each obstacle's
/// clearance against time, the `radius`, and the closest approach over every
/// step, over `[t0, t1]`.
fn distances_panel(
    data: &RunData,
    s: &SafetyData,
    summary: &SafetyReport,
    (t0, t1): (f64, f64),
) -> Panel {
    let mut distances = Panel::new(Axis::new("t", "s"), Axis::new("distance", "m")).titled(
        "closest pair of robots' points L ahead, and each obstacle's closest point (edge clearance)",
    );
    if let Some(d) = min_distances(data) {
        distances.line(
            "closest pair",
            data.times.iter().copied().zip(d).collect(),
            Stroke {
                color: palette::INK,
                width: 2,
                dash: Dash::Solid,
            },
        );
    }
    for (o, c) in obstacle_clearances(data).into_iter().enumerate() {
        distances.line(
            &format!("obstacle {} clearance", o + 1),
            data.times.iter().copied().zip(c).collect(),
            Stroke::series(o),
        );
    }
    distances.segments(
        &format!("radius = {} m", s.radius),
        vec![[(t0, s.radius), (t1, s.radius)]],
        Stroke::reference(),
    );
    let summary = &summary.closest;
    let [a, b] = summary.min_distance_agents;
    let name = |k: usize| {
        data.agents
            .get(k.wrapping_sub(1))
            .map_or_else(|| format!("agent {k}"), |t| t.name.clone())
    };
    distances.markers(
        &format!(
            "closest over every step: {:.4} m at t = {} s ({}, {})",
            summary.min_distance,
            summary.min_distance_t,
            name(a),
            name(b)
        ),
        vec![((summary.min_distance_t, summary.min_distance), Marker::Dot)],
        palette::INK,
    );
    distances
}

/// The bottom panel of [`figure`]: per agent, bars where its filter changed
/// the command, braked or broke a deadlock, over `[t0, t1]`.
fn actions_panel(data: &RunData, s: &SafetyData, (t0, t1): (f64, f64)) -> Panel {
    let n = data.agents.len();
    let margin = 0.05 * (t1 - t0).max(1e-9);
    let mut actions = Panel::new(
        Axis::new("t", "s").range(t0 - margin, t1 + margin),
        Axis::new("agent", "").range(0.0, n as f64 + 1.0).integer(),
    )
    .titled("when each robot's filter acted (bars), braked (black) or broke a deadlock (grey)");
    let mut acted = Vec::new();
    let mut braked = Vec::new();
    let mut deadlock = Vec::new();
    for i in 0..n {
        let y = (i + 1) as f64;
        let bars = |action, dy: f64| -> Vec<[(f64, f64); 2]> {
            filter_spans(data, s, i, action)
                .into_iter()
                .map(|(a, b)| [(a, y + dy), (b, y + dy)])
                .collect()
        };
        acted.push((i, bars(Action::Acted, 0.0)));
        braked.extend(bars(Action::Braked, 0.3));
        deadlock.extend(bars(Action::Deadlock, -0.3));
    }
    for (i, bars) in acted {
        actions.segments(
            "",
            bars,
            Stroke {
                width: 8,
                ..Stroke::series(i)
            },
        );
    }
    // Legend entries with no segments: what the bars mean.
    actions.segments(
        ACTED_LABEL,
        Vec::new(),
        Stroke {
            width: 8,
            ..Stroke::series(0)
        },
    );
    actions.segments(
        BRAKED_LABEL,
        braked,
        Stroke {
            color: palette::INK,
            width: 4,
            dash: Dash::Solid,
        },
    );
    actions.segments(
        DEADLOCK_LABEL,
        deadlock,
        Stroke {
            color: palette::MUTED,
            width: 4,
            dash: Dash::Solid,
        },
    );
    actions
}

/// The `safety` figure, if the run had a safety filter.
///
/// Top: the smallest distance between two robots' points `L` ahead at every
/// logged instant ([`min_distances`]), the `radius` (dashed), the summary's
/// closest approach over every step (a dot), and per obstacle the smallest
/// clearance of a point from its edge ([`obstacle_clearances`]), which the
/// filter also keeps `≥ radius`. Bottom: per agent, bars where its filter
/// changed the command, braked, or broke a deadlock ([`filter_spans`]).
pub fn figure(data: &RunData) -> Option<Figure> {
    let s = data.safety.as_ref()?;
    let summary = data.summary.safety.as_ref()?;
    let (t0, t1) = (
        data.times.first().copied().unwrap_or(0.0),
        data.times.last().copied().unwrap_or(1.0),
    );
    let distances = distances_panel(data, s, summary, (t0, t1));
    let actions = actions_panel(data, s, (t0, t1));
    Some(
        Figure::new(
            &format!(
                "{}: safety filter (barrier certificates, docs/safety.md)",
                data.summary.scenario
            ),
            1000,
            900,
        )
        .with_panel(distances)
        .with_panel(actions),
    )
}
