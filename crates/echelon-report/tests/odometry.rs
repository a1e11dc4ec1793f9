//! Odometry figures: a run's `drift` figure (only when agents dead-reckon) and
//! the sweep figure, parsed back with their names and units.
#![allow(clippy::unwrap_used)]

mod common;

use std::path::Path;

use echelon::odometry::ZetaModel;
use echelon::scenario::{Overrides, Scenario};
use echelon::sweep::{self, Grid, GridSpec};
use echelon_report::write_all;

/// The texts of the SVG at `path`, which show every one of `needles`.
fn svg_texts_showing(path: &Path, needles: &[&str]) -> Vec<String> {
    let texts = common::svg_texts(path);
    for needle in needles {
        assert!(
            texts.iter().any(|t| t == needle),
            "`{needle}` not in {texts:?}"
        );
    }
    texts
}

/// A one-seed sweep under the worst-case error `ζ = 1e-5 m` per sample over
/// the wheel diameter ratios and fix intervals given, with Theorem 2's `γ`
/// and the transient left out of the ultimate bound.
fn worst_case(
    wheel_diameter_ratio: Vec<f64>,
    fix_every: Vec<u64>,
    gamma: f64,
    transient: f64,
) -> Grid {
    Grid::new(GridSpec {
        zeta: vec![1e-5],
        zeta_model: ZetaModel::WorstCase,
        wheel_diameter_ratio,
        wheelbase_ratio: vec![1.0],
        slip: vec![0.0],
        fix_every,
        seeds: vec![0],
        gamma,
        transient,
    })
    .unwrap()
}

const DRIFTING: &str = include_str!("fixtures/drifting.toml");

#[test]
fn runs_with_odometry_get_a_drift_figure() {
    let (dir, data) = common::load_source(DRIFTING, &Overrides::default());
    assert!(data.odometry[0].is_some() && data.odometry[1].is_none());
    // Fixes every 3 s over 12 s: 4, counted in the fix column.
    let fixes: f64 = data.odometry[0].as_ref().unwrap().fix.iter().sum();
    assert_eq!(fixes, 4.0);
    let written = write_all(dir.path()).unwrap();
    let drift = written.figure("drift").unwrap();
    let texts = svg_texts_showing(
        &drift.svg,
        &[
            "scout",
            "scout (estimate)",
            "x [m]",
            "‖p − p̂‖ [m]",
            "t [s]",
            "‖e‖ [m]",
        ],
    );
    assert!(
        !texts.iter().any(|t| t.starts_with("perfect")),
        "only dead-reckoning agents"
    );
    assert!(drift.png.exists());
    let html = std::fs::read_to_string(&written.report).unwrap();
    assert!(html.contains("odometry drift"));
}

#[test]
fn runs_without_odometry_have_no_drift_figure() {
    let dir = tempfile::tempdir().unwrap();
    common::run_builtin("nonfeasible", dir.path(), &common::for_seconds(1.0));
    let written = write_all(dir.path()).unwrap();
    assert_eq!(written.figures.len(), 3);
    assert!(!dir.path().join("drift.svg").exists());
}

#[test]
fn the_sweep_figure_shows_runs_bounds_and_drift_growth() {
    let s = Scenario::builtin("fix-study").unwrap();
    let ov = common::for_seconds(6.0);
    let grid = worst_case(vec![1.0, 1.002], vec![10, 50, 100], 0.99, 3.0);
    let rows = sweep::run(&s, &ov, &grid, &|| {}).unwrap();
    let curves = sweep::drift_curves(&s, &ov, &grid, 100).unwrap();
    assert_eq!(curves.len(), 2, "one curve per error model");
    // The worst case drifts on the paper's line √2 N ζ, up to dead reckoning's
    // own error (each sample is taken as an exact arc: ~1e-9 m per sample here).
    let c = &curves[0];
    let last = c.times.len() - 1;
    assert!(
        (c.drift[last] - c.paper[last]).abs() < 1e-3 * c.paper[last],
        "{} vs {}",
        c.drift[last],
        c.paper[last]
    );
    // Systematic errors outgrow the linear extrapolation of their first second.
    let sys = &curves[1];
    let end = sys.times.len() - 1;
    assert!(
        sys.drift[end] > 2.0 * sys.early_slope[end],
        "{} vs {}",
        sys.drift[end],
        sys.early_slope[end]
    );
    let dir = tempfile::tempdir().unwrap();
    let saved = echelon_report::odometry::sweep("fix-study", &rows, &curves)
        .save(dir.path(), "sweep")
        .unwrap();
    let texts = svg_texts_showing(
        &saved.svg,
        &[
            "ultimate max ‖z‖ [m/s]",
            "ultimate max ‖e‖ [m]",
            "N (samples between fixes)",
            "Theorem 2, ζ = 1e-5 m",
            "ζ = 1e-5 m, E_d = 1.002",
            "t [s]",
        ],
    );
    // Log axes label 1-2-5 ticks, never fractional decades.
    assert!(
        texts.iter().any(|t| t == "50") && texts.iter().any(|t| t == "100"),
        "{texts:?}"
    );
    assert!(!texts.iter().any(|t| t.contains("31.62")), "{texts:?}");
}

/// The sweep figure of a velocity scenario overlays the kinematic law's bound:
/// `√2 K_e N ζ` on ‖z‖ and `√2 N ζ / γ` on ‖e‖, labelled and titled as such,
/// with every run's ‖e‖ under it.
#[test]
fn a_velocity_sweep_figure_overlays_the_kinematic_bound() {
    let s = Scenario::builtin("circle-pentagon-velocity").unwrap();
    let ov = common::for_seconds(14.0);
    let grid = worst_case(vec![1.0], vec![20, 100, 400], 0.9, 10.0);
    let rows = sweep::run(&s, &ov, &grid, &|| {}).unwrap();
    let curves = sweep::drift_curves(&s, &ov, &grid, 50).unwrap();
    let figure = echelon_report::odometry::sweep("circle-pentagon-velocity", &rows, &curves);
    let label = "Theorem 2 (kinematic law), ζ = 1e-5 m";
    let bound_line = |panel: usize| -> Vec<(f64, f64)> {
        common::labelled_line(&figure.panels[panel], label)
            .unwrap_or_else(|| panic!("no `{label}` line in panel {panel}"))
            .to_vec()
    };
    let sqrt2 = std::f64::consts::SQRT_2;
    let z_want: Vec<(f64, f64)> = [20.0, 100.0, 400.0]
        .iter()
        .map(|&n| (n, sqrt2 * 1.5 * n * 1e-5))
        .collect();
    let e_want: Vec<(f64, f64)> = [20.0, 100.0, 400.0]
        .iter()
        .map(|&n| (n, sqrt2 * n * 1e-5 / 0.9))
        .collect();
    for (got, want) in [(bound_line(0), z_want), (bound_line(1), e_want)] {
        assert_eq!(got.len(), want.len());
        for (g, w) in got.iter().zip(&want) {
            assert!(
                g.0 == w.0 && (g.1 - w.1).abs() <= 1e-15 * w.1,
                "{g:?} vs {w:?}"
            );
        }
    }
    for r in &rows {
        assert_eq!(r.laws, sweep::Laws::Kinematic);
        assert!(r.e_max < r.e_bound.unwrap(), "{r:?}");
    }
    let dir = tempfile::tempdir().unwrap();
    let saved = figure.save(dir.path(), "sweep").unwrap();
    let texts = svg_texts_showing(&saved.svg, &["ultimate max ‖e‖ [m]", label]);
    assert!(
        texts
            .iter()
            .any(|t| t.contains("kinematic law's ultimate bound √2 N ζ / γ")),
        "{texts:?}"
    );
}
