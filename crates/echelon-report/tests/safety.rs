//! The `safety` figure, the report's safety section and the replay's safety
//! data, checked against the run's own files: `safety.csv` (each filtering
//! agent's distance to its nearest neighbour, per logged instant) and
//! `summary.json`'s `safety` (every step).
#![allow(clippy::unwrap_used)]

mod common;

use std::path::Path;

use echelon::output::{SAFETY_FILE, SAFETY_HEADER, Table};
use echelon::scenario::Overrides;
use echelon_report::safety::{self, Action};
use echelon_report::{html, write_all};

/// `safety.csv`, per logged instant: the smallest `min_distance` over the
/// agents, and per agent (1-based) its outcome column.
fn csv_closest(dir: &Path, agents: usize) -> (Vec<f64>, Vec<Vec<f64>>) {
    let path = dir.join(SAFETY_FILE);
    let table = Table::parse(&path, &std::fs::read_to_string(&path).unwrap()).unwrap();
    table.expect_header(&path, SAFETY_HEADER).unwrap();
    let mut closest: Vec<f64> = Vec::new();
    let mut outcomes = vec![Vec::new(); agents];
    let mut times: Vec<f64> = Vec::new();
    for row in &table.rows {
        if times.last() != Some(&row[0]) {
            times.push(row[0]);
            closest.push(f64::INFINITY);
        }
        let last = closest.len() - 1;
        closest[last] = closest[last].min(row[8]);
        outcomes[row[1] as usize - 1].push(row[2]);
    }
    (closest, outcomes)
}

#[test]
fn crossing_gets_a_safety_figure_whose_closest_pair_is_the_runs() {
    let (dir, data) = common::load_builtin("crossing", &Overrides::default());
    let n = data.agents.len();
    let summary = data.summary.safety.clone().unwrap();
    let s = data.safety.as_ref().unwrap();
    assert_eq!(s.l.len(), n);
    assert!(s.obstacles.is_empty());

    // Every agent filters in `crossing`: the smallest of their nearest-
    // neighbour distances in safety.csv is the closest pair at that instant.
    let (closest, outcomes) = csv_closest(dir.path(), n);
    let d = safety::min_distances(&data).unwrap();
    assert_eq!(d.len(), data.times.len());
    assert_eq!(closest.len(), d.len());
    for (k, (a, b)) in d.iter().zip(&closest).enumerate() {
        assert!((a - b).abs() <= 1e-12, "instant {k}: {a} against {b}");
    }
    // The summary watches every step, the figure the logged instants: its
    // minimum can only be larger, and by little (the closest approach is slow).
    let plotted = d.iter().copied().fold(f64::INFINITY, f64::min);
    assert!(plotted >= summary.closest.min_distance - 1e-12);
    assert!(
        plotted - summary.closest.min_distance < 5e-3,
        "{plotted} against {}",
        summary.closest.min_distance
    );
    assert!(summary.closest.min_distance >= summary.closest.radius - 1e-3);

    // The bars: agent i's "acted" spans cover exactly its logged instants
    // with a non-nominal outcome.
    for (i, out) in outcomes.iter().enumerate() {
        let spans = safety::filter_spans(&data, s, i, Action::Acted);
        let covered = |t: f64| spans.iter().any(|&(a, b)| a <= t && t <= b);
        for (k, o) in out.iter().enumerate() {
            if *o != 0.0 {
                assert!(
                    covered(data.times[k]),
                    "agent {} at {}",
                    i + 1,
                    data.times[k]
                );
            }
        }
        assert_eq!(spans.is_empty(), out.iter().all(|o| *o == 0.0));
    }

    let fig = safety::figure(&data).unwrap();
    let line = common::figure_line(&fig, "closest pair");
    assert_eq!(line.len(), d.len());
    assert!(line.iter().zip(&d).all(|(p, v)| p.1 == *v));

    let written = write_all(dir.path()).unwrap();
    let saved = written.figure("safety").unwrap();
    assert!(std::fs::metadata(&saved.svg).unwrap().len() > 1000);
    assert!(std::fs::metadata(&saved.png).unwrap().len() > 1000);
    let svg = std::fs::read_to_string(&saved.svg).unwrap();
    assert!(svg.contains(&format!("radius = {} m", summary.closest.radius)));
    assert!(svg.contains(safety::DEADLOCK_LABEL));

    // report.html: the section with the summary's numbers, and the replay's
    // safety data.
    let page = std::fs::read_to_string(&written.report).unwrap();
    let section = &page[page.find("<section id=\"safety\">").unwrap()..];
    let section = &section[..section.find("</section>").unwrap()];
    assert!(section.contains(&format!("radius = {} m", summary.closest.radius)));
    assert!(section.contains(&format!(
        "<strong>{:.4} m</strong>",
        summary.closest.min_distance
    )));
    assert!(section.contains(&format!("at t = {} s", summary.closest.min_distance_t)));
    assert!(section.contains(&format!(
        "changed the command at {} controller samples, braked at {}, broke {} deadlock",
        summary.active, summary.infeasible, summary.deadlock_breaks
    )));
    for a in &summary.agents {
        let row = format!(
            "<td>{}</td><td>{}</td><td>{}</td></tr>",
            a.active, a.infeasible, a.deadlock_breaks
        );
        assert!(section.contains(&row), "agent {}: {row}", a.agent);
    }
    assert!(page.contains("id=\"safety-legend\""));
    assert!(page.contains("function drawSafety("));
    let replay = html::replay_data(&data);
    let rs = replay.safety.unwrap();
    assert_eq!(rs.radius, summary.closest.radius);
    assert_eq!(rs.actions.len(), replay.rows.len() * n);
    for (j, &k) in replay.rows.iter().enumerate() {
        for (i, out) in outcomes.iter().enumerate() {
            let digit = rs.actions.as_bytes()[j * n + i] - b'0';
            assert_eq!(f64::from(digit % 3), out[k]);
        }
    }
}

#[test]
fn obstacle_clearance_is_plotted_per_obstacle() {
    let (_dir, data) = common::load_builtin("obstacle-slalom", &Overrides::default());
    let summary = data.summary.safety.clone().unwrap();
    let s = data.safety.as_ref().unwrap();
    assert!(!s.obstacles.is_empty());
    let clear = safety::obstacle_clearances(&data);
    assert_eq!(clear.len(), s.obstacles.len());
    let plotted = clear
        .iter()
        .flatten()
        .copied()
        .fold(f64::INFINITY, f64::min);
    let every_step = summary.closest.min_obstacle_clearance.unwrap();
    assert!(plotted >= every_step - 1e-12);
    assert!(
        plotted - every_step < 5e-3,
        "{plotted} against {every_step}"
    );
    let fig = safety::figure(&data).unwrap();
    for (o, c) in clear.iter().enumerate() {
        let line = common::figure_line(&fig, &format!("obstacle {} clearance", o + 1));
        assert!(line.iter().zip(c).all(|(p, v)| p.1 == *v));
    }
    let replay = html::replay_data(&data).safety.unwrap();
    assert_eq!(replay.obstacles.len(), s.obstacles.len());
}

#[test]
fn runs_without_a_safety_filter_have_no_safety_figure_section_or_replay_data() {
    let (dir, data) = common::load_builtin("experiment-circle", &common::for_seconds(1.0));
    assert!(data.safety.is_none() && data.summary.safety.is_none());
    assert!(safety::figure(&data).is_none());
    let written = write_all(dir.path()).unwrap();
    assert!(!dir.path().join("safety.svg").exists());
    assert!(written.figure("safety").is_none());
    let page = std::fs::read_to_string(&written.report).unwrap();
    assert!(!page.contains("id=\"safety"));
    assert!(!page.contains("drawSafety"));
    assert!(!page.contains("\"safety\":"));
}
