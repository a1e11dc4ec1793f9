//! Shared by the integration tests: runs written into temporary directories
//! and read back, and reading figures (their SVG texts, their lines).
#![allow(dead_code)]

use std::fmt::Write as _;
use std::path::Path;

use echelon::output;
use echelon::scenario::{Overrides, Scenario};
use echelon::sim::{Frame, ObserverError};
use echelon_report::RunData;
use echelon_report::figure::{Figure, Item, Panel};
use tempfile::TempDir;

/// Runs a scenario (TOML source) into `dir` with `overrides`.
pub(crate) fn run_source(source: &str, dir: &Path, overrides: &Overrides) {
    let scenario = Scenario::parse(source, "test.toml", None).unwrap();
    let mut run = scenario.build(overrides).unwrap();
    let mut none = |_: &Frame<'_>| -> Result<(), ObserverError> { Ok(()) };
    output::run_to_dir(&mut run, dir, &mut none).unwrap();
}

/// Overrides that shorten a run to `duration` seconds.
pub(crate) fn for_seconds(duration: f64) -> Overrides {
    Overrides {
        duration: Some(duration),
        ..Overrides::default()
    }
}

/// Runs a built-in scenario into `dir`.
pub(crate) fn run_builtin(name: &str, dir: &Path, overrides: &Overrides) {
    let src = echelon::scenario::builtin()
        .iter()
        .find(|(n, _)| *n == name)
        .unwrap()
        .1;
    run_source(src, dir, overrides);
}

/// A scenario (TOML source) run into a new temporary directory, read back.
pub(crate) fn load_source(source: &str, overrides: &Overrides) -> (TempDir, RunData) {
    let dir = tempfile::tempdir().unwrap();
    run_source(source, dir.path(), overrides);
    let data = RunData::load(dir.path()).unwrap();
    (dir, data)
}

/// A built-in scenario run into a new temporary directory, read back.
pub(crate) fn load_builtin(name: &str, overrides: &Overrides) -> (TempDir, RunData) {
    let dir = tempfile::tempdir().unwrap();
    run_builtin(name, dir.path(), overrides);
    let data = RunData::load(dir.path()).unwrap();
    (dir, data)
}

/// The texts of the SVG file at `path` (trimmed), which must be an SVG document.
pub(crate) fn svg_texts(path: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(path).unwrap();
    let doc = roxmltree::Document::parse(&text)
        .unwrap_or_else(|e| panic!("{} is not XML: {e}", path.display()));
    assert_eq!(doc.root_element().tag_name().name(), "svg");
    doc.descendants()
        .filter(|n| n.has_tag_name("text"))
        .filter_map(|n| n.text())
        .map(|t| t.trim().to_owned())
        .collect()
}

/// The points of `panel`'s line labelled `label`, if it has one.
pub(crate) fn labelled_line<'a>(panel: &'a Panel, label: &str) -> Option<&'a [(f64, f64)]> {
    panel.items.iter().find_map(|item| match item {
        Item::Line {
            label: Some(l),
            points,
            ..
        } if l == label => Some(points.as_slice()),
        _ => None,
    })
}

/// The points of the figure's first line labelled `label` (in any panel).
pub(crate) fn figure_line<'a>(figure: &'a Figure, label: &str) -> &'a [(f64, f64)] {
    figure
        .panels
        .iter()
        .find_map(|p| labelled_line(p, label))
        .unwrap_or_else(|| panic!("no line {label:?}"))
}

/// A formation of `n` robots (a multiple of 20) behind a 20 m circle: 20 lanes
/// following the reference, each with a column of followers, 70 s at 100 Hz.
pub(crate) fn many_agents(n: usize) -> String {
    let mut s = String::from(
        "name = \"swarm\"\ndescription = \"many robots in columns behind a circle\"\n\
         [sim]\nduration = 70.0\ndt = 0.01\n[log]\ndt = 0.01\n\
         [control]\nlycomp = \"exact\"\n\
         [reference.circle]\nspeed = 1.0\nturn_rate = 0.05\nstart = { x = 0.0, y = 0.0, theta = 0.0 }\n",
    );
    let lanes = 20;
    for i in 0..n {
        let (row, lane) = (i / lanes, i % lanes);
        let y = (lane as f64 - 9.5) * 0.6;
        let x = -1.0 - row as f64 * 0.9;
        let leader = if row == 0 {
            "\"reference\"".to_owned()
        } else {
            (i + 1 - lanes).to_string()
        };
        let offset = if row == 0 {
            format!("{{ x = 1.0, y = {} }}", -y)
        } else {
            "{ x = 0.85, y = 0.0 }".to_owned()
        };
        let _ = write!(
            s,
            "[[agents]]\nname = \"robot {}\"\nstart = {{ x = {x}, y = {}, theta = 0.0 }}\nleader = {leader}\noffset = {offset}\n",
            i + 1,
            y + 0.1
        );
    }
    s
}
