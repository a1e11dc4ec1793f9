//! `report.html`: one self-contained page (no network: styles, script, data and
//! figures are inlined) with the scenario, the summary table, the figures and
//! an animated replay on a canvas.
//!
//! # What the replay embeds
//!
//! A JSON block, `<script type="application/json" id="echelon-data">`, holds:
//!
//! - `times`: the embedded instants, s, as JSON numbers (the same `f64` as in
//!   `trajectory.csv`);
//! - `rows`: for each embedded instant, its index among the logged instants of
//!   `trajectory.csv` (every `stride`-th, and always the last);
//! - `poses`: base64 of little-endian `float32` `[instant][agent][x, y, θ]`,
//!   each value the CSV's value rounded to the nearest `float32`;
//! - `reference`: the same for the virtual leader `[instant][x, y]` (or `null`);
//! - `agents`: names, leaders (0-based agent index, `-1` for the reference,
//!   `null` if unknown) and colours;
//! - `safety` (only for a run with a safety filter, [`ReplaySafety`]):
//!   `radius`, each agent's `L`, the obstacles `[x, y, r]` and, per embedded
//!   instant and agent, what its filter did. The replay then draws each
//!   robot's point `L` ahead with a disc of radius `radius/2` (two discs touch
//!   exactly when the points are `radius` apart, the filter's limit), each
//!   obstacle with a dashed ring at `r + radius/2` (a robot's disc touches it
//!   exactly when its point is `radius` from the edge), and highlights a
//!   robot while its filter acts. A run without one embeds, and draws, exactly
//!   what it did before.
//!
//! `stride` is 1 (every logged instant) unless the poses would exceed
//! [`MAX_POSE_VALUES`] floats; then every `stride`-th instant is kept, so
//! 200 agents over 70 s at 100 Hz embed ~33 instants per second (about 6 MB)
//! and the replay interpolates between them.

use std::fmt::Write as _;

use base64::Engine as _;
use serde::Serialize;

use echelon::formation::Leader;

use crate::figure::palette;
use crate::replay::STYLE;
use crate::run::{Column, RunData};

/// The report's file name.
pub const REPORT_FILE: &str = "report.html";

/// At most this many `float32` pose values are embedded (≈ 8 MB of base64).
pub const MAX_POSE_VALUES: usize = 1_500_000;

/// The recorded run's driver of the replay drawing ([`crate::replay`]).
const SCRIPT: &str = include_str!("../assets/replay.js");

/// The replay's script: the drawing (with the safety drawing when
/// `safety`), then [`SCRIPT`].
fn script(safety: bool) -> String {
    format!("{}{SCRIPT}", crate::replay::drawing(safety))
}

/// The embedded replay data (see the module doc).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ReplayData {
    /// Format tag.
    pub format: &'static str,
    /// Scenario name.
    pub scenario: String,
    /// Per agent.
    pub agents: Vec<ReplayAgent>,
    /// Every `stride`-th logged instant is embedded.
    pub stride: usize,
    /// Embedded instants, s.
    pub times: Vec<f64>,
    /// Index of each embedded instant among the logged ones.
    pub rows: Vec<usize>,
    /// Base64 little-endian `float32` `[instant][agent][x, y, θ]`.
    pub poses: String,
    /// Base64 little-endian `float32` `[instant][x, y]`, or `None`.
    pub reference: Option<String>,
    /// The safety filter (absent without one).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub safety: Option<ReplaySafety>,
}

/// The safety filter in [`ReplayData`].
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ReplaySafety {
    /// Smallest distance between two robots' points, m.
    pub radius: f64,
    /// Each agent's `L`, m.
    pub l: Vec<f64>,
    /// Obstacles, `[x, y, r]`, m.
    pub obstacles: Vec<[f64; 3]>,
    /// One digit per embedded instant per agent (`[instant][agent]`):
    /// outcome (0 nominal or no filter, 1 filtered, 2 braked) + 3 while
    /// breaking a deadlock.
    pub actions: String,
}

/// The safety part of the replay data (`None`: no filter, or `L` unknown).
fn replay_safety(data: &RunData, rows: &[usize]) -> Option<ReplaySafety> {
    let s = data.safety.as_ref()?;
    if s.l.len() != data.agents.len() {
        return None;
    }
    let mut actions = String::with_capacity(rows.len() * data.agents.len());
    for &k in rows {
        for t in &s.tracks {
            let a = t.as_ref().map_or(0, |t| {
                t.outcome[k].min(2) + if t.deadlock[k] { 3 } else { 0 }
            });
            actions.push(char::from(b'0' + a));
        }
    }
    Some(ReplaySafety {
        radius: s.radius,
        l: s.l.clone(),
        obstacles: s.obstacles.iter().map(|o| [o.x(), o.y(), o.r()]).collect(),
        actions,
    })
}

/// One agent in [`ReplayData`].
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ReplayAgent {
    /// Name.
    pub name: String,
    /// Leader: agent index (0-based), −1 for the reference, `None` if unknown.
    pub leader: Option<i64>,
    /// `#RRGGBB`.
    pub color: String,
}

/// The embedded instants: every `stride`-th logged one and the last.
pub fn embedded_rows(instants: usize, agents: usize) -> (usize, Vec<usize>) {
    if instants == 0 {
        return (1, Vec::new());
    }
    let per_instant = 3 * agents.max(1);
    let stride = (instants * per_instant).div_ceil(MAX_POSE_VALUES).max(1);
    let mut rows: Vec<usize> = (0..instants).step_by(stride).collect();
    if rows.last() != Some(&(instants - 1)) {
        rows.push(instants - 1);
    }
    (stride, rows)
}

fn base64_f32(values: impl Iterator<Item = f64>) -> String {
    let mut bytes = Vec::new();
    for v in values {
        bytes.extend_from_slice(&(v as f32).to_le_bytes());
    }
    base64::engine::general_purpose::STANDARD.encode(bytes)
}

/// The replay data of a run.
pub fn replay_data(data: &RunData) -> ReplayData {
    let (stride, rows) = embedded_rows(data.times.len(), data.agents.len());
    let poses = base64_f32(rows.iter().flat_map(|&k| {
        data.agents.iter().flat_map(move |a| {
            [
                a.get(Column::X)[k],
                a.get(Column::Y)[k],
                a.get(Column::Theta)[k],
            ]
        })
    }));
    let reference = data
        .reference
        .as_ref()
        .filter(|_| data.uses_reference())
        .map(|r| base64_f32(rows.iter().flat_map(|&k| [r.x[k], r.y[k]])));
    ReplayData {
        format: "echelon-replay-1",
        scenario: data.summary.scenario.clone(),
        agents: data
            .agents
            .iter()
            .enumerate()
            .map(|(i, a)| ReplayAgent {
                name: a.name.clone(),
                leader: a.leader.map(|l| match l {
                    Leader::Reference => -1,
                    Leader::Agent(j) => j as i64,
                }),
                color: crate::replay::agent_color(i),
            })
            .collect(),
        stride,
        times: rows.iter().map(|&k| data.times[k]).collect(),
        safety: replay_safety(data, &rows),
        rows,
        poses,
        reference,
    }
}

/// Escapes text for HTML.
pub fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

fn opt(v: Option<f64>, f: impl Fn(f64) -> String) -> String {
    v.filter(|x| x.is_finite())
        .map_or_else(|| "—".to_owned(), f)
}

/// Whether the summary has a velocity agent (its `saturated_ticks` column).
fn has_saturation(data: &RunData) -> bool {
    data.summary
        .agents
        .iter()
        .any(|a| a.saturated_ticks.is_some())
}

/// `n` of the run's `steps` as a count and a percentage: `6177 (20.6 %)`.
fn share(n: u64, steps: u64) -> String {
    format!("{n} ({:.1} %)", percent(n, steps))
}

/// `6177 of 30000 steps (20.6 %)`.
fn of_steps(n: u64, steps: u64) -> String {
    format!("{n} of {steps} steps ({:.1} %)", percent(n, steps))
}

fn percent(n: u64, steps: u64) -> f64 {
    100.0 * n as f64 / steps.max(1) as f64
}

fn summary_table(data: &RunData) -> String {
    let saturation = has_saturation(data);
    let mut t = String::from(
        "<table class=\"summary\"><thead><tr><th>agent</th><th>leader</th><th>offset (L<sub>Xoff</sub>, L<sub>Yoff</sub>)</th>\
         <th>final ‖e‖</th><th>RMS ‖e‖</th><th>peak |τ|</th><th>‖e‖ &lt; tolerance from</th>",
    );
    if saturation {
        t.push_str("<th>saturated steps</th>");
    }
    t.push_str("</tr></thead><tbody>\n");
    for (i, (a, r)) in data.agents.iter().zip(&data.summary.agents).enumerate() {
        let offset = a
            .offset
            .map_or_else(|| "tracking".to_owned(), |(x, y)| format!("({x} m, {y} m)"));
        // A velocity base has no wheel torques to show.
        let peak = finite(r.peak_torque).filter(|_| r.saturated_ticks.is_none());
        let _ = write!(
            t,
            "<tr><td><span class=\"swatch\" style=\"background:{}\"></span>{}</td><td>{}</td><td>{}</td>\
             <td>{}</td><td>{}</td><td>{}</td><td>{}</td>",
            palette::series(i).hex(),
            escape(&a.name),
            escape(&data.leader_name(i)),
            escape(&offset),
            opt(finite(r.final_error), |v| format!("{v:.2e} m")),
            opt(finite(r.rms_error), |v| format!("{v:.3} m")),
            opt(peak, |v| format!("{v:.2} N·m")),
            opt(r.settle_time, |v| format!("{v:.2} s")),
        );
        if saturation {
            let _ = write!(
                t,
                "<td>{}</td>",
                r.saturated_ticks
                    .map_or_else(|| "— (torque)".to_owned(), |n| share(n, data.summary.steps))
            );
        }
        t.push_str("</tr>\n");
    }
    t.push_str("</tbody></table>\n");
    t
}

/// `v` when finite (`summary.json` writes a value that is not as `null`,
/// read back as NaN).
fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

/// One sentence per velocity agent: how many steps its base's speed limits
/// cut the command (`summary.json`'s `saturated_ticks`), and what the signals
/// figure shows of it.
fn saturation_note(data: &RunData) -> Option<String> {
    let steps = data.summary.steps;
    let parts: Vec<String> = data
        .summary
        .agents
        .iter()
        .filter_map(|r| {
            r.saturated_ticks
                .map(|n| format!("{}: {}", escape(&r.name), of_steps(n, steps)))
        })
        .collect();
    if parts.is_empty() {
        return None;
    }
    Some(format!(
        "<p class=\"note\" id=\"saturation\">Velocity bases, steps at which the speed limits cut the kinematic law's command (v and ω scaled together, keeping the path's curvature): {}. \
         The signals figure draws each command dashed over the speed the base actually moved at (solid), the limits ±v<sub>max</sub>, ±ω<sub>max</sub> dotted, and bars where the command was cut.</p>",
        parts.join("; ")
    ))
}

/// What the replay draws of the safety filter, under its hint.
fn replay_safety_legend(data: &RunData) -> Option<String> {
    let s = data.safety.as_ref()?;
    replay_safety(data, &[])?;
    Some(format!(
        "<p class=\"hint\" id=\"safety-legend\">Safety filter: the circle around each robot's point L ahead has radius radius/2 = {} m, \
         so two circles touch exactly when two points are radius = {} m apart, the closest the filter allows. \
         Grey discs are obstacles; a robot's circle touches an obstacle's dashed ring (r + radius/2) exactly when its point is radius from the edge. \
         A filled circle: that robot's filter is changing its command; orange outline: braking (QP infeasible); dashed: breaking a deadlock.</p>\n",
        s.radius / 2.0,
        s.radius
    ))
}

fn metres(v: f64) -> String {
    if v.is_finite() {
        format!("{v} m")
    } else {
        "∞".to_owned()
    }
}

/// The safety section: the filter's settings and `summary.json`'s `safety`.
fn safety_section(data: &RunData) -> Option<String> {
    let report = data.summary.safety.as_ref()?;
    let r = &report.closest;
    let s = data.safety.as_ref()?;
    let name = |k: usize| {
        data.agents
            .get(k.wrapping_sub(1))
            .map_or_else(|| format!("agent {k}"), |a| a.name.clone())
    };
    let mut html = String::from("<section id=\"safety\">\n<h2>Safety</h2>\n");
    let _ = writeln!(
        html,
        "<p class=\"note\">Barrier-certificate filter (docs/safety.md) between the law and the base: radius = {} m between two robots' points L ahead and from an obstacle's edge; {} obstacle{}.</p>",
        r.radius,
        s.obstacles.len(),
        if s.obstacles.len() == 1 { "" } else { "s" }
    );
    let [a, b] = r.min_distance_agents;
    let _ = write!(
        html,
        "<p id=\"safety-closest\">Closest pair of points over every step: <strong>{:.4} m</strong> ({} and {}) at t = {} s",
        r.min_distance,
        escape(&name(a)),
        escape(&name(b)),
        r.min_distance_t
    );
    if let Some(c) = r.min_obstacle_clearance {
        let _ = write!(
            html,
            "; closest to an obstacle's edge: <strong>{c:.4} m</strong>"
        );
    }
    let _ = writeln!(
        html,
        ". Filters changed the command at {} controller samples, braked at {}, broke {} deadlock{}.</p>",
        report.active,
        report.infeasible,
        report.deadlock_breaks,
        if report.deadlock_breaks == 1 { "" } else { "s" }
    );
    html.push_str(
        "<table class=\"summary\"><thead><tr><th>agent</th><th>gain γ</th><th>range</th>\
         <th>command changed</th><th>braked</th><th>deadlock breaks</th></tr></thead><tbody>\n",
    );
    for a in &report.agents {
        let i = a.agent.wrapping_sub(1);
        let setting = s.settings.get(i).copied().flatten();
        let filters = s.tracks.get(i).is_some_and(Option::is_some) || setting.is_some();
        let (gain, range) = match (filters, setting) {
            (_, Some((g, range))) => (format!("{g} 1/s"), metres(range)),
            (true, None) => ("?".to_owned(), "?".to_owned()),
            (false, None) => ("— (no filter)".to_owned(), "—".to_owned()),
        };
        let _ = writeln!(
            html,
            "<tr><td><span class=\"swatch\" style=\"background:{}\"></span>{}</td><td>{gain}</td><td>{range}</td>\
             <td>{}</td><td>{}</td><td>{}</td></tr>",
            palette::series(i).hex(),
            escape(&name(a.agent)),
            a.active,
            a.infeasible,
            a.deadlock_breaks
        );
    }
    html.push_str("</tbody></table>\n");
    html.push_str(
        "<p class=\"note\">Counts are controller samples. The safety figure plots the closest pair at every logged instant against radius, each obstacle's clearance, and when each filter acted; the replay draws each robot's safety circle.</p>\n</section>\n",
    );
    Some(html)
}

/// The page's header: the scenario's name and description, the run's
/// size and timing, and whether it diverged.
fn write_header(html: &mut String, data: &RunData) {
    let s = &data.summary;
    let _ = writeln!(html, "<header><h1>{}</h1>", escape(&s.scenario));
    if let Some(d) = &data.description {
        let _ = writeln!(html, "<p class=\"description\">{}</p>", escape(d));
    }
    let controller = s.controller_period.map_or_else(
        || "continuous-time controller".to_owned(),
        |p| format!("controller sampled every {p} s (zero-order hold)"),
    );
    let _ = writeln!(
        html,
        "<p class=\"meta\">{} agent{} · {} s simulated at dt = {} s ({} RK4 steps) · {controller} · {} logged instants</p></header>",
        data.agents.len(),
        if data.agents.len() == 1 { "" } else { "s" },
        s.duration,
        s.dt,
        s.steps,
        data.times.len()
    );
    // A diverged run stopped early: say so before anything reads as a result.
    if let Some(d) = &s.diverged {
        let _ = writeln!(
            html,
            "<p class=\"diverged\" id=\"diverged\">This run diverged: {} (the logs, figures and replay stop at its last state within bounds)</p>",
            escape(&d.message)
        );
    }
}

/// The summary section: the agents' table, the tolerance, saturation and
/// the run's warnings.
fn write_summary(html: &mut String, data: &RunData) {
    let s = &data.summary;
    html.push_str("<section id=\"summary\">\n<h2>Summary</h2>\n");
    html.push_str(&summary_table(data));
    let _ = writeln!(
        html,
        "<p class=\"note\">‖e‖ (eq. 7) is the distance between where the leader should be, seen from the follower, and where it is; the tolerance is {} m.</p>",
        s.settle_tolerance
    );
    if let Some(note) = saturation_note(data) {
        html.push_str(&note);
        html.push('\n');
    }
    if !s.warnings.is_empty() {
        html.push_str("<ul class=\"warnings\">");
        for w in &s.warnings {
            let _ = write!(html, "<li>warning: {}</li>", escape(w));
        }
        html.push_str("</ul>\n");
    }
    html.push_str("</section>\n");
}

/// The whole page; `svgs` are the figures as `(stem, SVG document)`.
pub fn report(data: &RunData, svgs: &[(&str, String)]) -> String {
    let s = &data.summary;
    let title = format!("echelon — {}", s.scenario);
    let mut html = String::with_capacity(1 << 20);
    let _ = write!(
        html,
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n\
         <title>{}</title>\n<style>\n{STYLE}</style>\n</head>\n<body>\n<main>\n",
        escape(&title)
    );
    write_header(&mut html, data);
    html.push_str(
        "<section id=\"replay\">\n<h2>Replay</h2>\n<div class=\"controls\">\
         <button id=\"play\" type=\"button\" aria-label=\"play\">▶ Play</button>\
         <label>speed <select id=\"speed\">\
         <option value=\"0.25\">0.25×</option><option value=\"0.5\">0.5×</option>\
         <option value=\"1\" selected>1×</option><option value=\"2\">2×</option>\
         <option value=\"5\">5×</option><option value=\"10\">10×</option>\
         <option value=\"20\">20×</option><option value=\"50\">50×</option></select></label>\
         <input id=\"time\" type=\"range\" min=\"0\" max=\"10000\" value=\"0\" step=\"1\" aria-label=\"time\">\
         <output id=\"clock\">t = 0.00 s</output>\
         <button id=\"fit\" type=\"button\">Fit view</button>\
         <label><input id=\"trails\" type=\"checkbox\" checked> trails</label>\
         <label><input id=\"links\" type=\"checkbox\" checked> links</label>\
         <span class=\"frames\"><span id=\"frames\">0</span> frames drawn</span></div>\n\
         <canvas id=\"view\" width=\"960\" height=\"600\"></canvas>\n\
         <p class=\"hint\">Wheel or pinch: zoom · drag: pan · double-click: fit · space: play/pause · ←/→: step. \
         Triangles are the robots, dotted lines link each follower to its leader, the dashed line is the virtual leader's path.</p>\n",
    );
    if let Some(legend) = replay_safety_legend(data) {
        html.push_str(&legend);
    }
    html.push_str("</section>\n");
    write_summary(&mut html, data);
    if let Some(section) = safety_section(data) {
        html.push_str(&section);
    }
    html.push_str("<section id=\"figures\">\n<h2>Figures</h2>\n");
    for (stem, svg) in svgs {
        let _ = writeln!(
            html,
            "<figure id=\"fig-{stem}\">{}<figcaption>{stem}.svg / {stem}.png</figcaption></figure>",
            svg.trim()
        );
    }
    html.push_str("</section>\n");
    if let Some(text) = &data.scenario_text {
        let _ = writeln!(
            html,
            "<section id=\"scenario\">\n<h2>Scenario</h2>\n<details><summary>scenario.toml</summary><pre>{}</pre></details>\n</section>",
            escape(text)
        );
    }
    let json = serde_json::to_string(&replay_data(data))
        .unwrap_or_else(|_| "null".to_owned())
        // `<` only occurs inside JSON strings: escaped, no `</script>` or
        // `<!--` can end or confuse the data block.
        .replace('<', "\\u003c");
    let _ = write!(
        html,
        "</main>\n<script type=\"application/json\" id=\"echelon-data\">{json}</script>\n<script>\n{}</script>\n</body>\n</html>\n",
        script(replay_safety(data, &[]).is_some())
    );
    html
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_runs_embed_every_instant() {
        let (stride, rows) = embedded_rows(7001, 4);
        assert_eq!(stride, 1);
        assert_eq!(rows, (0..7001).collect::<Vec<_>>());
    }

    #[test]
    fn large_runs_are_thinned_to_the_budget_keeping_the_last_instant() {
        let (stride, rows) = embedded_rows(7001, 200);
        assert_eq!(stride, 3);
        assert_eq!(rows.last(), Some(&7000));
        assert!(rows.len() * 200 * 3 <= MAX_POSE_VALUES + 600);
        assert!(rows.windows(2).all(|w| w[1] - w[0] <= stride));
    }

    #[test]
    fn the_script_is_the_drawing_then_the_driver() {
        for safety in [false, true] {
            let s = script(safety);
            assert!(s.ends_with(SCRIPT));
            assert!(s.starts_with(&crate::replay::drawing(safety)));
            assert_eq!(s.contains("function drawSafety("), safety);
        }
    }

    #[test]
    fn escape_escapes() {
        assert_eq!(
            escape("<a href=\"x\">&'"),
            "&lt;a href=&quot;x&quot;&gt;&amp;&#39;"
        );
    }
}
