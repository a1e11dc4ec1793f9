//! The files `write_all` produces: they exist, parse, name the agents and the
//! units, and the report embeds exactly what trajectory.csv holds.
#![allow(clippy::unwrap_used)]

mod common;

use std::path::Path;

use base64::Engine as _;
use echelon::output::{TRAJECTORY_FILE, TRAJECTORY_HEADER};
use echelon::scenario::Overrides;
use echelon_report::html::{MAX_POSE_VALUES, REPORT_FILE};
use echelon_report::{ReportError, RunData, write_all};

/// Decodes a PNG; returns (width, height, number of distinct colours).
fn png_info(path: &Path) -> (u32, u32, usize) {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap();
    let px = info.color_type.samples();
    let mut colours: Vec<&[u8]> = buf[..info.buffer_size()].chunks(px).collect();
    colours.sort_unstable();
    colours.dedup();
    (info.width, info.height, colours.len())
}

#[test]
fn figures_exist_parse_and_name_agents_and_units() {
    let dir = tempfile::tempdir().unwrap();
    common::run_builtin("circle-pentagon", dir.path(), &Overrides::default());
    let written = write_all(dir.path()).unwrap();
    assert_eq!(written.figures.len(), 3);
    let units: [(&str, &[&str]); 3] = [
        ("paths", &["x [m]", "y [m]"]),
        ("errors", &["t [s]", "e_x [m]", "e_y [m]"]),
        (
            "signals",
            &[
                "t [s]",
                "v [m/s]",
                "ω [rad/s]",
                "‖e‖ [m]",
                "‖z‖ [m/s]",
                "τ_r [N·m]",
                "τ_l [N·m]",
            ],
        ),
    ];
    for (stem, labels) in units {
        let svg = dir.path().join(format!("{stem}.svg"));
        let texts = common::svg_texts(&svg);
        for label in labels.iter().copied() {
            assert!(
                texts.iter().any(|t| t == label),
                "{stem}: no `{label}` in {texts:?}"
            );
        }
        for agent in ["agent 1", "agent 2", "agent 3", "agent 4"] {
            assert!(
                texts.iter().any(|t| t == agent),
                "{stem}: no legend entry {agent}"
            );
        }
        let (w, h, colours) = png_info(&dir.path().join(format!("{stem}.png")));
        assert!(w >= 900 && h >= 600, "{stem}: {w}×{h}");
        // Text, axes, grid and four agents' colours (and their antialiasing).
        assert!(colours > 20, "{stem}.png looks blank: {colours} colours");
    }
    let paths = common::svg_texts(&dir.path().join("paths.svg"));
    assert!(paths.iter().any(|t| t == "reference"));
    assert!(
        paths
            .iter()
            .any(|t| t.starts_with("leader links, t = 12.6, 25.1"))
    );
}

/// The report's `echelon-data` JSON block.
fn embedded(html: &str) -> serde_json::Value {
    let open = "<script type=\"application/json\" id=\"echelon-data\">";
    let start = html.find(open).unwrap() + open.len();
    let end = start + html[start..].find("</script>").unwrap();
    serde_json::from_str(&html[start..end]).unwrap()
}

fn floats(b64: &str) -> Vec<f32> {
    base64::engine::general_purpose::STANDARD
        .decode(b64)
        .unwrap()
        .chunks(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}

/// trajectory.csv's rows as numbers, grouped per logged instant.
fn csv_instants(dir: &Path, agents: usize) -> Vec<Vec<Vec<f64>>> {
    let text = std::fs::read_to_string(dir.join(TRAJECTORY_FILE)).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some(TRAJECTORY_HEADER));
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|c| c.parse().unwrap()).collect())
        .collect();
    rows.chunks(agents).map(<[Vec<f64>]>::to_vec).collect()
}

/// Checks every embedded value against the CSV: times exactly, poses as the
/// CSV's values rounded to float32.
fn assert_embedded_equals_csv(dir: &Path, agents: usize) -> (usize, usize) {
    let html = std::fs::read_to_string(dir.join(REPORT_FILE)).unwrap();
    let data = embedded(&html);
    let instants = csv_instants(dir, agents);
    let times = data["times"].as_array().unwrap();
    let rows = data["rows"].as_array().unwrap();
    let poses = floats(data["poses"].as_str().unwrap());
    assert_eq!(times.len(), rows.len());
    assert_eq!(poses.len(), rows.len() * agents * 3);
    assert_eq!(data["agents"].as_array().unwrap().len(), agents);
    assert_eq!(
        rows.last().unwrap().as_u64().unwrap() as usize,
        instants.len() - 1
    );
    for (j, (t, k)) in times.iter().zip(rows).enumerate() {
        let k = k.as_u64().unwrap() as usize;
        let instant = &instants[k];
        for (i, row) in instant.iter().enumerate() {
            assert_eq!(row[0], t.as_f64().unwrap(), "time of embedded instant {j}");
            assert_eq!(row[1] as usize, i + 1);
            for (c, v) in [row[2], row[3], row[4]].iter().enumerate() {
                assert_eq!(
                    poses[(j * agents + i) * 3 + c],
                    *v as f32,
                    "instant {k}, agent {}, column {c}",
                    i + 1
                );
            }
        }
    }
    (rows.len(), instants.len())
}

#[test]
fn report_is_self_contained_and_embeds_the_csv() {
    let dir = tempfile::tempdir().unwrap();
    common::run_builtin("lemniscate-wedge", dir.path(), &Overrides::default());
    write_all(dir.path()).unwrap();
    let (embedded, logged) = assert_embedded_equals_csv(dir.path(), 4);
    assert_eq!(
        embedded, logged,
        "a 4-agent run embeds every logged instant"
    );
    let html = std::fs::read_to_string(dir.path().join(REPORT_FILE)).unwrap();
    // Nothing fetched: no external scripts, styles, images or fonts.
    for needle in [
        "<script src",
        "<link",
        "<img",
        "@import",
        "url(",
        "https://",
    ] {
        assert!(!html.contains(needle), "report.html contains `{needle}`");
    }
    // The only http:// is the SVG namespace.
    assert_eq!(
        html.matches("http://").count(),
        html.matches("http://www.w3.org/2000/svg").count()
    );
    for part in [
        "lemniscate-wedge",
        "<canvas id=\"view\"",
        "id=\"play\"",
        "id=\"fig-paths\"",
        "id=\"fig-errors\"",
        "id=\"fig-signals\"",
        "agent 4",
        "[reference.lemniscate]",
    ] {
        assert!(html.contains(part), "report.html lacks {part}");
    }
}

#[test]
fn two_hundred_agents_are_thinned_and_still_match_the_csv() {
    let dir = tempfile::tempdir().unwrap();
    common::run_source(&common::many_agents(200), dir.path(), &Overrides::default());
    write_all(dir.path()).unwrap();
    let (embedded, logged) = assert_embedded_equals_csv(dir.path(), 200);
    assert_eq!(logged, 7001);
    assert!(embedded * 200 * 3 <= MAX_POSE_VALUES + 600, "{embedded}");
    assert!(embedded >= logged / 3, "{embedded}");
    let size = std::fs::metadata(dir.path().join(REPORT_FILE))
        .unwrap()
        .len();
    assert!(size < 12_000_000, "report.html is {size} bytes");
    // The legend lists 12 entries (the reference and 11 robots) and counts the rest.
    let texts = common::svg_texts(&dir.path().join("paths.svg"));
    assert!(texts.iter().any(|t| t == "robot 11"));
    assert!(!texts.iter().any(|t| t == "robot 12"));
    assert!(texts.iter().any(|t| t == "… and 190 more"), "{texts:?}");
}

#[test]
fn same_run_gives_the_same_figures_and_report() {
    let dir = tempfile::tempdir().unwrap();
    common::run_builtin("nonfeasible", dir.path(), &Overrides::default());
    write_all(dir.path()).unwrap();
    let read = |f: &str| std::fs::read(dir.path().join(f)).unwrap();
    let first: Vec<Vec<u8>> = ["paths.svg", "paths.png", "signals.png", REPORT_FILE]
        .iter()
        .map(|f| read(f))
        .collect();
    write_all(dir.path()).unwrap();
    for (f, bytes) in ["paths.svg", "paths.png", "signals.png", REPORT_FILE]
        .iter()
        .zip(&first)
    {
        assert!(read(f) == *bytes, "{f} differs");
    }
}

#[test]
fn a_run_without_the_newer_files_still_plots() {
    // Runs written before reference.csv and scenario.toml existed.
    let dir = tempfile::tempdir().unwrap();
    common::run_builtin("circle-pentagon", dir.path(), &common::for_seconds(3.0));
    std::fs::remove_file(dir.path().join("reference.csv")).unwrap();
    std::fs::remove_file(dir.path().join("scenario.toml")).unwrap();
    let data = RunData::load(dir.path()).unwrap();
    assert!(data.reference.is_none() && data.agents[0].leader.is_none());
    write_all(dir.path()).unwrap();
    assert!(
        common::svg_texts(&dir.path().join("paths.svg"))
            .iter()
            .any(|t| t == "agent 3")
    );
}

#[test]
fn broken_run_directories_are_refused_with_the_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let missing = RunData::load(dir.path()).unwrap_err();
    assert!(matches!(missing, ReportError::Io { .. }), "{missing}");
    assert!(missing.to_string().contains("summary.json"));
    common::run_builtin("nonfeasible", dir.path(), &common::for_seconds(1.0));
    let csv = dir.path().join(TRAJECTORY_FILE);
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    lines[3] = lines[3].replacen(',', ",x", 2);
    std::fs::write(&csv, lines.join("\n")).unwrap();
    let err = RunData::load(dir.path()).unwrap_err().to_string();
    assert!(err.contains("trajectory.csv:4:"), "{err}");
    std::fs::write(&csv, "t,x\n0,1\n").unwrap();
    let err = RunData::load(dir.path()).unwrap_err().to_string();
    assert!(err.contains("expected the header"), "{err}");
    // Nothing was written next to the broken run.
    assert!(write_all(dir.path()).is_err());
    assert!(!dir.path().join(REPORT_FILE).exists());
    assert!(!dir.path().join("paths.svg").exists());
}

#[test]
fn names_cannot_break_the_page() {
    let name = "a</script><!--b & \"c\"";
    let src = echelon::scenario::builtin()
        .iter()
        .find(|(n, _)| *n == "nonfeasible")
        .unwrap()
        .1
        .replacen("[[agents]]", &format!("[[agents]]\nname = '{name}'"), 1);
    let src = if src.contains("name = \"robot\"") {
        src.replace("name = \"robot\"\n", "")
    } else {
        src
    };
    let dir = tempfile::tempdir().unwrap();
    common::run_source(&src, dir.path(), &common::for_seconds(1.0));
    write_all(dir.path()).unwrap();
    let html = std::fs::read_to_string(dir.path().join(REPORT_FILE)).unwrap();
    assert_eq!(embedded(&html)["agents"][0]["name"], name);
    // One data block, one script, and the name only escaped elsewhere.
    assert_eq!(html.matches("</script>").count(), 2);
    assert!(!html.contains("<!--b"));
    assert!(html.contains("a&lt;/script&gt;&lt;!--b &amp; &quot;c&quot;"));
}
