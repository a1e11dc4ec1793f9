//! Drawing a figure with plotters, on any backend (SVG or bitmap): the title
//! and the grid of panels, each panel's mesh, its items (lines thinned to the
//! pixels, segments, robot markers) and its legend, placed where it hides the
//! fewest points.

use plotters::coord::Shift;
use plotters::element::{Circle, EmptyElement, PathElement, Polygon};
use plotters::prelude::{
    Cartesian2d, ChartBuilder, ChartContext, DashedLineSeries, DrawingArea, DrawingBackend,
    LineSeries, SeriesLabelPosition,
};
use plotters::style::Color as _;

use super::Figure;
use super::axis::{Coord, format_tick};
use super::panel::{Item, LEGEND_MAX, Panel};
use super::simplify::simplify;
use super::style::{Color, Marker, Stroke, palette, register_fonts, text};
use crate::ReportError;

const TITLE_PX: f64 = 22.0;
const TEXT_PX: f64 = 16.0;
const MARGIN: u32 = 12;
const X_LABEL_AREA: u32 = 46;
const Y_LABEL_AREA: u32 = 74;

pub(super) fn draw_err<E: std::error::Error + Send + Sync>(
    e: plotters::drawing::DrawingAreaErrorKind<E>,
) -> ReportError {
    ReportError::Draw(e.to_string())
}

type Chart<'a, DB> = ChartContext<'a, DB, Cartesian2d<Coord, Coord>>;

impl Figure {
    /// Draws the figure on `root`.
    pub(super) fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
    ) -> Result<(), ReportError>
    where
        DB::ErrorType: 'static,
    {
        register_fonts();
        root.fill(&palette::PAPER.rgb()).map_err(draw_err)?;
        let body = if self.title.is_empty() {
            root.clone()
        } else {
            root.titled(&self.title, text(TITLE_PX, palette::INK))
                .map_err(draw_err)?
        };
        let rows = self.panels.len().div_ceil(self.columns).max(1);
        let areas = body.split_evenly((rows, self.columns));
        for (panel, area) in self.panels.iter().zip(&areas) {
            draw_panel(panel, area)?;
        }
        Ok(())
    }
}

fn draw_panel<DB: DrawingBackend>(
    panel: &Panel,
    area: &DrawingArea<DB, Shift>,
) -> Result<(), ReportError>
where
    DB::ErrorType: 'static,
{
    let area = match &panel.title {
        Some(t) => area
            .titled(t, text(TEXT_PX + 1.0, palette::INK))
            .map_err(draw_err)?,
        None => area.clone(),
    };
    let (aw, ah) = area.dim_in_pixel();
    let plot_w = f64::from(aw.saturating_sub(2 * MARGIN + Y_LABEL_AREA)).max(1.0);
    let plot_h = f64::from(ah.saturating_sub(2 * MARGIN + X_LABEL_AREA)).max(1.0);
    let ((x0, x1), (y0, y1)) = panel.ranges(plot_w, plot_h);
    let mut chart = ChartBuilder::on(&area)
        .margin(MARGIN)
        .x_label_area_size(X_LABEL_AREA)
        .y_label_area_size(Y_LABEL_AREA)
        .build_cartesian_2d(
            Coord::new(&panel.x, x0, x1, 8),
            Coord::new(&panel.y, y0, y1, 7),
        )
        .map_err(draw_err)?;
    let log_label = |v: &f64| {
        // Never snapped to 0: on a log axis 1e-13 is a real tick.
        let x = 10f64.powf(*v);
        if (1e-3..1e5).contains(&x) {
            format_tick(x)
        } else {
            format!("{x:.0e}")
        }
    };
    let lin_label = |v: &f64| format_tick(*v);
    let x_fmt: &dyn Fn(&f64) -> String = if panel.x.log { &log_label } else { &lin_label };
    let y_fmt: &dyn Fn(&f64) -> String = if panel.y.log { &log_label } else { &lin_label };
    chart
        .configure_mesh()
        .x_desc(panel.x.label())
        .y_desc(panel.y.label())
        .x_label_formatter(x_fmt)
        .y_label_formatter(y_fmt)
        .x_labels(8)
        .y_labels(7)
        .axis_desc_style(text(TEXT_PX, palette::INK))
        .label_style(text(TEXT_PX - 2.0, palette::INK))
        .axis_style(palette::INK.rgb())
        .bold_line_style(palette::GRID.rgb())
        .light_line_style(palette::PAPER.rgb())
        .draw()
        .map_err(draw_err)?;
    // Points per pixel, to thin long series.
    let (px, py) = ((x1 - x0) / plot_w, (y1 - y0) / plot_h);
    let mut labelled = 0usize;
    let mut unlisted = 0usize;
    for item in &panel.items {
        let listed = item.label().filter(|_| {
            let ok = labelled < LEGEND_MAX;
            labelled += 1;
            if !ok {
                unlisted += 1;
            }
            ok && panel.legend
        });
        draw_item(&mut chart, panel, item, listed, (px, py))?;
    }
    if panel.legend && labelled > 0 {
        if unlisted > 0 {
            // A legend line only: "… and N more".
            chart
                .draw_series(std::iter::empty::<Circle<(f64, f64), u32>>())
                .map_err(draw_err)?
                .label(format!("… and {unlisted} more"))
                .legend(|(x, y)| EmptyElement::at((x, y)));
        }
        let entries = labelled.min(LEGEND_MAX) + usize::from(unlisted > 0);
        chart
            .configure_series_labels()
            .position(legend_corner(
                panel,
                ((x0, x1), (y0, y1)),
                (plot_w, plot_h),
                entries,
            ))
            .background_style(palette::PAPER.rgb().mix(0.85))
            .border_style(palette::GRID.rgb())
            .label_font(text(TEXT_PX - 2.0, palette::INK))
            .draw()
            .map_err(draw_err)?;
    }
    Ok(())
}

/// The corner of the plotting area whose legend-sized box covers the fewest
/// data points (upper right on ties).
fn legend_corner(
    panel: &Panel,
    ((x0, x1), (y0, y1)): ((f64, f64), (f64, f64)),
    (w, h): (f64, f64),
    entries: usize,
) -> SeriesLabelPosition {
    let longest = panel
        .items
        .iter()
        .filter_map(|i| i.label().map(|l| l.chars().count()))
        .max()
        .unwrap_or(8);
    // Legend box size in pixels, as plotters lays it out at this font size.
    let (bw, bh) = (
        (40.0 + 8.0 * longest as f64).min(w),
        (10.0 + 19.0 * entries as f64).min(h),
    );
    let corners = [
        SeriesLabelPosition::UpperRight,
        SeriesLabelPosition::UpperLeft,
        SeriesLabelPosition::LowerRight,
        SeriesLabelPosition::LowerLeft,
    ];
    let mut counts = [0usize; 4];
    let mut count = |(x, y): (f64, f64)| {
        let (x, y) = panel.map((x, y));
        if !(x.is_finite() && y.is_finite()) {
            return;
        }
        let px = (x - x0) / (x1 - x0) * w;
        let py = (y1 - y) / (y1 - y0) * h;
        let (right, left) = (px >= w - bw, px <= bw);
        let (top, bottom) = (py <= bh, py >= h - bh);
        for (c, hit) in
            counts
                .iter_mut()
                .zip([right && top, left && top, right && bottom, left && bottom])
        {
            *c += usize::from(hit);
        }
    };
    for item in &panel.items {
        match item {
            Item::Line { points, .. } => {
                let step = (points.len() / 4000).max(1);
                points.iter().step_by(step).copied().for_each(&mut count);
            }
            Item::Segments { segments, .. } => {
                segments.iter().flatten().copied().for_each(&mut count)
            }
            Item::Markers { at, .. } => at.iter().map(|(p, _)| *p).for_each(&mut count),
        }
    }
    let best = (0..4).min_by_key(|&i| counts[i]).unwrap_or(0);
    corners[best].clone()
}

fn robot_triangle(heading: f64, size: f64) -> Vec<(i32, i32)> {
    // Pixel y points down: rotate by −heading.
    let (s, c) = (-heading).sin_cos();
    [(1.0, 0.0), (-0.6, 0.55), (-0.6, -0.55)]
        .iter()
        .map(|&(x, y)| {
            let (x, y) = (x * size, -y * size);
            (
                (c * x - s * y).round() as i32,
                (s * x + c * y).round() as i32,
            )
        })
        .collect()
}

/// The legend's sample of a line drawn with `stroke`.
fn legend_line(stroke: Stroke) -> impl Fn((i32, i32)) -> PathElement<(i32, i32)> {
    let style = stroke.style();
    move |(x, y): (i32, i32)| PathElement::new(vec![(x, y), (x + 22, y)], style)
}

/// Draws a polyline of `points`, split at non-finite points, each run
/// thinned to a quarter pixel (`px`, `py`: a pixel in chart units).
fn draw_line<'a, DB: DrawingBackend + 'a>(
    chart: &mut Chart<'a, DB>,
    panel: &Panel,
    points: &[(f64, f64)],
    stroke: Stroke,
    label: Option<&str>,
    (px, py): (f64, f64),
) -> Result<(), ReportError>
where
    DB::ErrorType: 'static,
{
    let map = |p| panel.map(p);
    // Split at non-finite points, thin each run to a quarter pixel.
    let mapped: Vec<(f64, f64)> = points.iter().map(|&p| map(p)).collect();
    let mut runs: Vec<Vec<(f64, f64)>> = Vec::new();
    let mut run = Vec::new();
    for p in mapped {
        if p.0.is_finite() && p.1.is_finite() {
            run.push(p);
        } else if !run.is_empty() {
            runs.push(std::mem::take(&mut run));
        }
    }
    if !run.is_empty() {
        runs.push(run);
    }
    let mut first = true;
    for run in &runs {
        let scaled: Vec<(f64, f64)> = run.iter().map(|&(x, y)| (x / px, y / py)).collect();
        let kept: Vec<(f64, f64)> = simplify(&scaled, 0.25)
            .into_iter()
            .map(|i| run[i])
            .collect();
        let anno = match stroke.dash.pattern() {
            None => chart
                .draw_series(LineSeries::new(kept, stroke.style()))
                .map_err(draw_err)?,
            Some((size, gap)) => chart
                .draw_series(DashedLineSeries::new(kept, size, gap, stroke.style()))
                .map_err(draw_err)?,
        };
        if first && let Some(l) = label {
            anno.label(l).legend(legend_line(stroke));
        }
        first = false;
    }
    if runs.is_empty()
        && let Some(l) = label
    {
        chart
            .draw_series(std::iter::empty::<Circle<(f64, f64), u32>>())
            .map_err(draw_err)?
            .label(l)
            .legend(legend_line(stroke));
    }
    Ok(())
}

/// Draws the markers `at` in `color`: dots and robots (triangles at their
/// headings), the legend showing the panel's shape.
fn draw_markers<'a, DB: DrawingBackend + 'a>(
    chart: &mut Chart<'a, DB>,
    panel: &Panel,
    at: &[((f64, f64), Marker)],
    color: Color,
    label: Option<&str>,
) -> Result<(), ReportError>
where
    DB::ErrorType: 'static,
{
    let map = |p| panel.map(p);
    let rgb = color.rgb();
    let ink = palette::INK.rgb();
    let finite = |p: (f64, f64)| {
        let p = map(p);
        (p.0.is_finite() && p.1.is_finite()).then_some(p)
    };
    chart
        .draw_series(at.iter().filter_map(|&(p, marker)| {
            (marker == Marker::Dot)
                .then(|| finite(p))
                .flatten()
                .map(|p| Circle::new(p, 4, rgb.filled()))
        }))
        .map_err(draw_err)?;
    let anno = chart
        .draw_series(at.iter().filter_map(|&(p, marker)| {
            let Marker::Robot { heading, filled } = marker else {
                return None;
            };
            let tri = robot_triangle(heading, 9.0);
            let (fill, outline) = if filled {
                (rgb.filled(), ink.stroke_width(1))
            } else {
                (palette::PAPER.rgb().filled(), rgb.stroke_width(2))
            };
            let closed: Vec<(i32, i32)> = tri.iter().chain(tri.first()).copied().collect();
            Some(
                EmptyElement::at(finite(p)?)
                    + Polygon::new(tri, fill)
                    + PathElement::new(closed, outline),
            )
        }))
        .map_err(draw_err)?;
    if let Some(l) = label {
        // The legend shows the shape the panel draws: dots or robots.
        if at.iter().all(|(_, m)| *m == Marker::Dot) {
            anno.label(l).legend(move |(x, y)| {
                EmptyElement::at((x + 11, y)) + Circle::new((0, 0), 4, color.rgb().filled())
            });
        } else {
            anno.label(l).legend(move |(x, y)| {
                EmptyElement::at((x + 11, y))
                    + Polygon::new(robot_triangle(0.0, 8.0), color.rgb().filled())
            });
        }
    }
    Ok(())
}

fn draw_item<'a, DB: DrawingBackend + 'a>(
    chart: &mut Chart<'a, DB>,
    panel: &Panel,
    item: &Item,
    label: Option<&str>,
    (px, py): (f64, f64),
) -> Result<(), ReportError>
where
    DB::ErrorType: 'static,
{
    let map = |p| panel.map(p);
    match item {
        Item::Line { points, stroke, .. } => {
            draw_line(chart, panel, points, *stroke, label, (px, py))?;
        }
        Item::Segments {
            segments, stroke, ..
        } => {
            let style = stroke.style();
            let segs: Vec<Vec<(f64, f64)>> = segments
                .iter()
                .map(|[a, b]| vec![map(*a), map(*b)])
                .filter(|s| s.iter().all(|p| p.0.is_finite() && p.1.is_finite()))
                .collect();
            let anno = match stroke.dash.pattern() {
                None => chart
                    .draw_series(segs.into_iter().map(|s| PathElement::new(s, style)))
                    .map_err(draw_err)?,
                Some((size, gap)) => {
                    for s in segs {
                        chart
                            .draw_series(DashedLineSeries::new(s, size, gap, style))
                            .map_err(draw_err)?;
                    }
                    chart
                        .draw_series(std::iter::empty::<Circle<(f64, f64), u32>>())
                        .map_err(draw_err)?
                }
            };
            if let Some(l) = label {
                anno.label(l).legend(legend_line(*stroke));
            }
        }
        Item::Markers { at, color, .. } => {
            draw_markers(chart, panel, at, *color, label)?;
        }
    }
    Ok(())
}
