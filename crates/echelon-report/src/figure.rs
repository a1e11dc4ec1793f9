//! A small figure builder with one consistent style: panels of lines, segments
//! and pose markers on x–y axes, written as SVG and PNG.
//!
//! Every echelon figure goes through here, so they all look alike: the same
//! palette (readable on white paper and, in SVG, on a dark page: the SVG carries
//! a `prefers-color-scheme: dark` style that swaps paper and ink), the same
//! embedded font (DejaVu Sans, so PNG text never depends on system fonts), axes
//! labelled with their units. Long series are thinned to what the pixels can
//! show (Ramer–Douglas–Peucker at a quarter pixel), so a 100 Hz log of a long
//! run draws as fast as a short one and looks the same.
//!
//! ```no_run
//! use echelon_report::figure::{Axis, Figure, Panel, Stroke};
//! let mut panel = Panel::new(Axis::new("t", "s"), Axis::new("‖e‖", "m"));
//! panel.line("agent 1", vec![(0.0, 1.0), (1.0, 0.5)], Stroke::series(0));
//! let figure = Figure::new("Tracking error", 900, 500).with_panel(panel);
//! figure.save(std::path::Path::new("out"), "errors").unwrap();
//! ```

use std::path::{Path, PathBuf};
use std::sync::Once;

use plotters::coord::Shift;
use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint, Ranged};
use plotters::coord::types::RangedCoordf64;
use plotters::element::{Circle, EmptyElement, PathElement, Polygon};
use plotters::prelude::{
    BitMapBackend, Cartesian2d, ChartBuilder, ChartContext, DashedLineSeries, DrawingArea,
    DrawingBackend, IntoDrawingArea, IntoFont, LineSeries, RGBColor, SVGBackend,
    SeriesLabelPosition, ShapeStyle,
};
use plotters::style::{Color as _, FontStyle, TextStyle};

use crate::ReportError;

/// An sRGB colour.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Color(pub u8, pub u8, pub u8);

impl Color {
    /// `#RRGGBB`, as the SVG files and the report use it.
    pub fn hex(self) -> String {
        format!("#{:02X}{:02X}{:02X}", self.0, self.1, self.2)
    }

    fn rgb(self) -> RGBColor {
        RGBColor(self.0, self.1, self.2)
    }
}

/// The colours every figure uses.
pub mod palette {
    use super::Color;

    /// Background (white paper; the SVG's dark style turns it near-black).
    pub const PAPER: Color = Color(0xFF, 0xFF, 0xFF);
    /// Text and axes.
    pub const INK: Color = Color(0x22, 0x22, 0x22);
    /// Secondary lines: references, formation links.
    pub const MUTED: Color = Color(0x6E, 0x6E, 0x6E);
    /// Grid lines.
    pub const GRID: Color = Color(0xDD, 0xDD, 0xDD);
    /// What `PAPER`, `INK`, `MUTED`, `GRID` become on a dark page.
    pub const DARK: [(Color, Color); 4] = [
        (PAPER, Color(0x16, 0x18, 0x1C)),
        (INK, Color(0xE8, 0xE8, 0xE8)),
        (MUTED, Color(0xA8, 0xA8, 0xA8)),
        (GRID, Color(0x3A, 0x3D, 0x44)),
    ];
    /// Series colours, in order (Okabe–Ito's colour-blind-safe set without
    /// black and yellow, plus three): mid-tones that read on white and on dark.
    pub const SERIES: [Color; 10] = [
        Color(0x00, 0x72, 0xB2),
        Color(0xD5, 0x5E, 0x00),
        Color(0x00, 0x9E, 0x73),
        Color(0xCC, 0x79, 0xA7),
        Color(0xE6, 0x9F, 0x00),
        Color(0x56, 0xB4, 0xE9),
        Color(0x99, 0x66, 0xCC),
        Color(0x8C, 0x8C, 0x3C),
        Color(0xC0, 0x39, 0x2B),
        Color(0x2E, 0x8B, 0x8B),
    ];

    /// The `i`-th series colour (cycling).
    pub fn series(i: usize) -> Color {
        SERIES[i % SERIES.len()]
    }
}

/// How a line is dashed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dash {
    /// Solid.
    Solid,
    /// Long dashes (references).
    Dashed,
    /// Short dots (formation links).
    Dotted,
}

/// A line's look.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stroke {
    /// Colour.
    pub color: Color,
    /// Width in pixels.
    pub width: u32,
    /// Dash pattern.
    pub dash: Dash,
}

impl Stroke {
    /// The `i`-th series' solid line.
    pub fn series(i: usize) -> Stroke {
        Stroke {
            color: palette::series(i),
            width: 2,
            dash: Dash::Solid,
        }
    }

    /// A reference or desired path: dashed, muted.
    pub fn reference() -> Stroke {
        Stroke {
            color: palette::MUTED,
            width: 2,
            dash: Dash::Dashed,
        }
    }

    /// A thin dotted link (leader–follower pairs).
    pub fn link() -> Stroke {
        Stroke {
            color: palette::MUTED,
            width: 1,
            dash: Dash::Dotted,
        }
    }

    /// The same stroke, dashed as given.
    pub fn dashed(self, dash: Dash) -> Stroke {
        Stroke { dash, ..self }
    }

    fn style(self) -> ShapeStyle {
        self.color.rgb().stroke_width(self.width)
    }
}

/// A marker shape, drawn in pixels (its size does not depend on the axes).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Marker {
    /// A robot: an isosceles triangle pointing along `heading` (rad, from +x,
    /// counter-clockwise, as in the world frame). Filled or outlined.
    Robot {
        /// Heading, rad.
        heading: f64,
        /// Filled (true) or outline.
        filled: bool,
    },
    /// A dot.
    Dot,
}

/// One axis: its quantity, its unit, and optionally a fixed range or a log scale.
#[derive(Debug, Clone, PartialEq)]
pub struct Axis {
    /// What is plotted (`t`, `‖e‖`, `τ_r`).
    pub quantity: String,
    /// Its unit (`s`, `m`, `N·m`); empty for a pure number.
    pub unit: String,
    /// Fixed range; `None` fits the data with a 5 % margin.
    pub range: Option<(f64, f64)>,
    /// Base-10 logarithmic scale (non-positive values are left out).
    pub log: bool,
    /// Ticks on whole numbers only (counts, agent numbers; linear axes).
    pub integer: bool,
}

impl Axis {
    /// A linear axis labelled `quantity [unit]`.
    pub fn new(quantity: &str, unit: &str) -> Axis {
        Axis {
            quantity: quantity.to_owned(),
            unit: unit.to_owned(),
            range: None,
            log: false,
            integer: false,
        }
    }

    /// With ticks on whole numbers only (a linear axis of counts or numbers).
    pub fn integer(mut self) -> Axis {
        self.integer = true;
        self
    }

    /// With a fixed range.
    pub fn range(mut self, lo: f64, hi: f64) -> Axis {
        self.range = Some((lo, hi));
        self
    }

    /// On a base-10 log scale.
    pub fn log(mut self) -> Axis {
        self.log = true;
        self
    }

    /// `quantity [unit]`.
    pub fn label(&self) -> String {
        if self.unit.is_empty() {
            self.quantity.clone()
        } else {
            format!("{} [{}]", self.quantity, self.unit)
        }
    }

    fn map(&self, v: f64) -> f64 {
        if self.log {
            if v > 0.0 { v.log10() } else { f64::NAN }
        } else {
            v
        }
    }
}

/// What a panel draws.
#[derive(Debug, Clone, PartialEq)]
pub enum Item {
    /// A polyline; non-finite points break it.
    Line {
        /// Legend entry (`None`: not in the legend).
        label: Option<String>,
        /// Points.
        points: Vec<(f64, f64)>,
        /// Look.
        stroke: Stroke,
    },
    /// Separate segments, all in one style (e.g. formation links).
    Segments {
        /// Legend entry.
        label: Option<String>,
        /// Segments.
        segments: Vec<[(f64, f64); 2]>,
        /// Look.
        stroke: Stroke,
    },
    /// Markers in one colour.
    Markers {
        /// Legend entry.
        label: Option<String>,
        /// Where, and which marker.
        at: Vec<((f64, f64), Marker)>,
        /// Colour.
        color: Color,
    },
}

/// One set of axes.
#[derive(Debug, Clone, PartialEq)]
pub struct Panel {
    /// Title above the panel.
    pub title: Option<String>,
    /// Horizontal axis.
    pub x: Axis,
    /// Vertical axis.
    pub y: Axis,
    /// Same metres per pixel on both axes (maps, paths).
    pub equal_aspect: bool,
    /// Draw a legend of the labelled items.
    pub legend: bool,
    /// The contents, drawn in order.
    pub items: Vec<Item>,
}

/// At most this many legend entries are listed; the rest are counted.
pub const LEGEND_MAX: usize = 12;

impl Panel {
    /// An empty panel with a legend.
    pub fn new(x: Axis, y: Axis) -> Panel {
        Panel {
            title: None,
            x,
            y,
            equal_aspect: false,
            legend: true,
            items: Vec::new(),
        }
    }

    /// With a title.
    pub fn titled(mut self, title: &str) -> Panel {
        self.title = Some(title.to_owned());
        self
    }

    /// With equal scales on both axes.
    pub fn equal_aspect(mut self) -> Panel {
        self.equal_aspect = true;
        self
    }

    /// Without a legend.
    pub fn without_legend(mut self) -> Panel {
        self.legend = false;
        self
    }

    /// Adds a line (an empty `label` keeps it out of the legend).
    pub fn line(&mut self, label: &str, points: Vec<(f64, f64)>, stroke: Stroke) -> &mut Panel {
        self.items.push(Item::Line {
            label: (!label.is_empty()).then(|| label.to_owned()),
            points,
            stroke,
        });
        self
    }

    /// Adds segments.
    pub fn segments(
        &mut self,
        label: &str,
        segments: Vec<[(f64, f64); 2]>,
        stroke: Stroke,
    ) -> &mut Panel {
        self.items.push(Item::Segments {
            label: (!label.is_empty()).then(|| label.to_owned()),
            segments,
            stroke,
        });
        self
    }

    /// Adds markers.
    pub fn markers(
        &mut self,
        label: &str,
        at: Vec<((f64, f64), Marker)>,
        color: Color,
    ) -> &mut Panel {
        self.items.push(Item::Markers {
            label: (!label.is_empty()).then(|| label.to_owned()),
            at,
            color,
        });
        self
    }

    /// Data bounds `(x0, x1, y0, y1)` in axis coordinates (log10 on log axes).
    fn bounds(&self) -> (f64, f64, f64, f64) {
        let mut b = (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        );
        let mut add = |(x, y): (f64, f64)| {
            let (x, y) = (self.x.map(x), self.y.map(y));
            if x.is_finite() && y.is_finite() {
                b = (b.0.min(x), b.1.max(x), b.2.min(y), b.3.max(y));
            }
        };
        for item in &self.items {
            match item {
                Item::Line { points, .. } => points.iter().copied().for_each(&mut add),
                Item::Segments { segments, .. } => {
                    segments.iter().flatten().copied().for_each(&mut add)
                }
                Item::Markers { at, .. } => at.iter().map(|(p, _)| *p).for_each(&mut add),
            }
        }
        b
    }

    /// The axis ranges for a plotting area of `w × h` pixels.
    fn ranges(&self, w: f64, h: f64) -> ((f64, f64), (f64, f64)) {
        let (x0, x1, y0, y1) = self.bounds();
        let fit = |lo: f64, hi: f64, fixed: Option<(f64, f64)>, axis: &Axis| {
            if let Some((a, b)) = fixed {
                return (axis.map(a), axis.map(b));
            }
            if !(lo.is_finite() && hi.is_finite()) {
                return (0.0, 1.0);
            }
            let span = hi - lo;
            if span <= 1e-12 * lo.abs().max(1.0) {
                let pad = if lo == 0.0 { 1.0 } else { 0.1 * lo.abs() };
                return (lo - pad, hi + pad);
            }
            (lo - 0.05 * span, hi + 0.05 * span)
        };
        let mut xr = fit(x0, x1, self.x.range, &self.x);
        let mut yr = fit(y0, y1, self.y.range, &self.y);
        if self.equal_aspect && w > 0.0 && h > 0.0 {
            // Widen the axis that has fewer units per pixel; the room gained
            // goes to the top (or right), where the legend prefers to sit.
            let (sx, sy) = ((xr.1 - xr.0) / w, (yr.1 - yr.0) / h);
            if sx > sy {
                yr.1 = yr.0 + sx * h;
            } else {
                xr.1 = xr.0 + sy * w;
            }
        }
        (xr, yr)
    }
}

/// A figure: a title over a grid of panels.
#[derive(Debug, Clone, PartialEq)]
pub struct Figure {
    /// Title over the whole figure.
    pub title: String,
    /// Width, px.
    pub width: u32,
    /// Height, px.
    pub height: u32,
    /// Panels per row (the rows follow).
    pub columns: usize,
    /// The panels, row by row.
    pub panels: Vec<Panel>,
}

/// The files [`Figure::save`] wrote.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Saved {
    /// `DIR/STEM.svg`.
    pub svg: PathBuf,
    /// `DIR/STEM.png`.
    pub png: PathBuf,
}

const FONT_FAMILY: &str = "sans-serif";
const DEJAVU: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");
const TITLE_PX: f64 = 22.0;
const TEXT_PX: f64 = 16.0;
const MARGIN: u32 = 12;
const X_LABEL_AREA: u32 = 46;
const Y_LABEL_AREA: u32 = 74;

/// Registers the embedded DejaVu Sans as the figures' font (once per process).
pub fn register_fonts() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        for style in [FontStyle::Normal, FontStyle::Bold] {
            // The bytes are a valid TTF, checked by the tests.
            let _ = plotters::style::register_font(FONT_FAMILY, style, DEJAVU);
        }
    });
}

fn text(size: f64, color: Color) -> TextStyle<'static> {
    (FONT_FAMILY, size).into_font().color(&color.rgb())
}

fn draw_err<E: std::error::Error + Send + Sync>(
    e: plotters::drawing::DrawingAreaErrorKind<E>,
) -> ReportError {
    ReportError::Draw(e.to_string())
}

/// Indices of the points Ramer–Douglas–Peucker keeps at tolerance `eps` (in the
/// points' own units); the first and last are always kept.
pub fn simplify(points: &[(f64, f64)], eps: f64) -> Vec<usize> {
    let n = points.len();
    if n <= 2 {
        return (0..n).collect();
    }
    let mut keep = vec![false; n];
    keep[0] = true;
    keep[n - 1] = true;
    let mut stack = vec![(0usize, n - 1)];
    while let Some((a, b)) = stack.pop() {
        if b <= a + 1 {
            continue;
        }
        let (ax, ay) = points[a];
        let (bx, by) = points[b];
        let (dx, dy) = (bx - ax, by - ay);
        let len = dx.hypot(dy);
        let mut worst = (0.0, a);
        for (i, &(px, py)) in points.iter().enumerate().take(b).skip(a + 1) {
            let d = if len > 0.0 {
                ((px - ax) * dy - (py - ay) * dx).abs() / len
            } else {
                (px - ax).hypot(py - ay)
            };
            if d > worst.0 {
                worst = (d, i);
            }
        }
        if worst.0 > eps {
            keep[worst.1] = true;
            stack.push((a, worst.1));
            stack.push((worst.1, b));
        }
    }
    (0..n).filter(|&i| keep[i]).collect()
}

/// An axis coordinate: plotters' `f64` mapping with the ticks we choose (see
/// [`ticks`]); labels come from our own formatters.
#[derive(Clone)]
struct Coord {
    inner: RangedCoordf64,
    ticks: Vec<f64>,
}

impl std::fmt::Debug for Coord {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Coord")
            .field("range", &self.inner.range())
            .field("ticks", &self.ticks)
            .finish()
    }
}

impl Coord {
    fn new(axis: &Axis, lo: f64, hi: f64, hint: usize) -> Coord {
        Coord {
            inner: RangedCoordf64::from(lo..hi),
            ticks: ticks(axis, lo, hi, hint),
        }
    }
}

impl Ranged for Coord {
    type FormatOption = DefaultFormatting;
    type ValueType = f64;

    fn range(&self) -> std::ops::Range<f64> {
        self.inner.range()
    }

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        self.inner.map(value, limit)
    }

    fn key_points<Hint: KeyPointHint>(&self, hint: Hint) -> Vec<f64> {
        if hint.weight().allow_light_points() {
            Vec::new()
        } else {
            self.ticks.clone()
        }
    }

    fn axis_pixel_range(&self, limit: (i32, i32)) -> std::ops::Range<i32> {
        self.inner.axis_pixel_range(limit)
    }
}

type Chart<'a, DB> = ChartContext<'a, DB, Cartesian2d<Coord, Coord>>;

/// Tick positions (in axis coordinates) for `lo..hi`: plotters' own choice on
/// a linear axis; 1, 2 and 5 × 10ᵏ on a log axis (whole decades only when they
/// are many, every mantissa when the range is under one 1-2-5 step).
fn ticks(axis: &Axis, lo: f64, hi: f64, hint: usize) -> Vec<f64> {
    if !axis.log && axis.integer {
        // Whole numbers, every `step`-th, at most `hint` of them.
        let (first, last) = (lo.ceil(), hi.floor());
        let step = ((last - first) / hint.max(1) as f64).ceil().max(1.0);
        let mut out = Vec::new();
        let mut v = first;
        while v <= last {
            out.push(v);
            v += step;
        }
        return out;
    }
    if !axis.log {
        return RangedCoordf64::from(lo..hi).key_points(hint);
    }
    let in_range = |v: f64| v >= lo - 1e-9 && v <= hi + 1e-9;
    let pick = |mantissas: &[f64]| -> Vec<f64> {
        let mut out = Vec::new();
        for k in (lo.floor() as i32)..=(hi.ceil() as i32) {
            for m in mantissas {
                let v = (m * 10f64.powi(k)).log10();
                if in_range(v) {
                    out.push(v);
                }
            }
        }
        out
    };
    let decades = pick(&[1.0]);
    if decades.len() > hint {
        let step = decades.len().div_ceil(hint);
        return decades.into_iter().step_by(step).collect();
    }
    let nice = pick(&[1.0, 2.0, 5.0]);
    if nice.len() >= 2 {
        return nice;
    }
    pick(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0])
}

impl Figure {
    /// An empty figure of `width × height` pixels, one panel per row.
    pub fn new(title: &str, width: u32, height: u32) -> Figure {
        Figure {
            title: title.to_owned(),
            width,
            height,
            columns: 1,
            panels: Vec::new(),
        }
    }

    /// With another panel.
    pub fn with_panel(mut self, panel: Panel) -> Figure {
        self.panels.push(panel);
        self
    }

    /// With `columns` panels per row.
    pub fn with_columns(mut self, columns: usize) -> Figure {
        self.columns = columns.max(1);
        self
    }

    /// The figure as an SVG document (with its dark-page style).
    pub fn svg(&self) -> Result<String, ReportError> {
        let mut out = String::new();
        {
            let root =
                SVGBackend::with_string(&mut out, (self.width, self.height)).into_drawing_area();
            self.draw(&root)?;
            root.present().map_err(draw_err)?;
        }
        Ok(with_dark_style(&out))
    }

    /// The figure as a PNG file's bytes.
    pub fn png(&self) -> Result<Vec<u8>, ReportError> {
        let (w, h) = (self.width, self.height);
        let mut rgb = vec![0u8; w as usize * h as usize * 3];
        {
            let root = BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
            self.draw(&root)?;
            root.present().map_err(draw_err)?;
        }
        let mut bytes = Vec::new();
        let mut encoder = png::Encoder::new(&mut bytes, w, h);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder
            .write_header()
            .map_err(|e| ReportError::Draw(e.to_string()))?;
        writer
            .write_image_data(&rgb)
            .map_err(|e| ReportError::Draw(e.to_string()))?;
        writer
            .finish()
            .map_err(|e| ReportError::Draw(e.to_string()))?;
        Ok(bytes)
    }

    /// Writes `dir/stem.svg` and `dir/stem.png`.
    pub fn save(&self, dir: &Path, stem: &str) -> Result<Saved, ReportError> {
        self.save_with_svg(dir, stem, &self.svg()?)
    }

    /// [`Figure::save`] with the figure's SVG already drawn ([`Figure::svg`]),
    /// for a caller that also keeps it.
    pub fn save_with_svg(&self, dir: &Path, stem: &str, svg: &str) -> Result<Saved, ReportError> {
        let saved = Saved {
            svg: dir.join(format!("{stem}.svg")),
            png: dir.join(format!("{stem}.png")),
        };
        crate::write_file(&saved.svg, svg.as_bytes())?;
        crate::write_file(&saved.png, &self.png()?)?;
        Ok(saved)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), ReportError>
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

/// Adds the `prefers-color-scheme: dark` style to a plotters SVG: paper, ink,
/// muted and grid colours are swapped for their dark-page counterparts (CSS
/// overrides SVG presentation attributes).
fn with_dark_style(svg: &str) -> String {
    let mut rules = String::new();
    for (light, dark) in palette::DARK {
        let (l, d) = (light.hex(), dark.hex());
        rules.push_str(&format!(
            "[fill=\"{l}\"]{{fill:{d}}}[stroke=\"{l}\"]{{stroke:{d}}}"
        ));
    }
    let style = format!("<style>@media (prefers-color-scheme: dark){{{rules}}}</style>\n");
    match svg.find('>') {
        Some(end) if svg.starts_with("<svg") => {
            let mut out = String::with_capacity(svg.len() + style.len());
            out.push_str(&svg[..=end]);
            out.push('\n');
            out.push_str(&style);
            out.push_str(&svg[end + 1..]);
            out
        }
        _ => svg.to_owned(),
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
        let label = match item {
            Item::Line { label, .. }
            | Item::Segments { label, .. }
            | Item::Markers { label, .. } => label.as_deref(),
        };
        let listed = label.filter(|_| {
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
        .filter_map(|i| match i {
            Item::Line { label, .. }
            | Item::Segments { label, .. }
            | Item::Markers { label, .. } => label.as_ref().map(|l| l.chars().count()),
        })
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
        let (x, y) = (panel.x.map(x), panel.y.map(y));
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

/// Short tick labels: `0.5`, `12`, `1e-3` (and `0` for rounding noise
/// such as `-6e-17`, which a tick at zero can come out as).
fn format_tick(v: f64) -> String {
    if v.abs() < 1e-12 {
        return "0".to_owned();
    }
    let a = v.abs();
    if !(1e-3..1e5).contains(&a) {
        return format!("{v:.0e}");
    }
    let s = format!("{v:.4}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" {
        "0".to_owned()
    } else {
        s.to_owned()
    }
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
    let map = |(x, y): (f64, f64)| (panel.x.map(x), panel.y.map(y));
    let legend_line = |stroke: Stroke| {
        let style = stroke.style();
        move |(x, y): (i32, i32)| PathElement::new(vec![(x, y), (x + 22, y)], style)
    };
    match item {
        Item::Line { points, stroke, .. } => {
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
                let anno = match stroke.dash {
                    Dash::Solid => chart
                        .draw_series(LineSeries::new(kept, stroke.style()))
                        .map_err(draw_err)?,
                    Dash::Dashed => chart
                        .draw_series(DashedLineSeries::new(kept, 9, 6, stroke.style()))
                        .map_err(draw_err)?,
                    Dash::Dotted => chart
                        .draw_series(DashedLineSeries::new(kept, 2, 4, stroke.style()))
                        .map_err(draw_err)?,
                };
                if first && let Some(l) = label {
                    anno.label(l).legend(legend_line(*stroke));
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
                    .legend(legend_line(*stroke));
            }
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
            let anno = match stroke.dash {
                Dash::Solid => chart
                    .draw_series(segs.into_iter().map(|s| PathElement::new(s, style)))
                    .map_err(draw_err)?,
                Dash::Dashed | Dash::Dotted => {
                    let (size, gap) = if stroke.dash == Dash::Dashed {
                        (9, 6)
                    } else {
                        (2, 4)
                    };
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
                let color = *color;
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
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn simplify_keeps_corners_and_drops_collinear_points() {
        let mut pts: Vec<(f64, f64)> = (0..=100).map(|i| (f64::from(i), 0.0)).collect();
        pts.extend((1..=100).map(|i| (100.0, f64::from(i))));
        let kept = simplify(&pts, 0.25);
        assert_eq!(kept, vec![0, 100, 200]);
    }

    #[test]
    fn simplify_stays_within_tolerance() {
        let pts: Vec<(f64, f64)> = (0..2000)
            .map(|i| {
                let t = f64::from(i) * 0.01;
                (t * 40.0, (t * 3.0).sin() * 100.0)
            })
            .collect();
        let kept = simplify(&pts, 0.25);
        assert!(kept.len() < pts.len() / 4, "{}", kept.len());
        // Every dropped point is within 0.25 of the kept polyline segment around it.
        for w in kept.windows(2) {
            let (a, b) = (pts[w[0]], pts[w[1]]);
            for p in &pts[w[0]..w[1]] {
                let (dx, dy) = (b.0 - a.0, b.1 - a.1);
                let d = ((p.0 - a.0) * dy - (p.1 - a.1) * dx).abs() / dx.hypot(dy);
                assert!(d <= 0.25 + 1e-12);
            }
        }
    }

    #[test]
    fn equal_aspect_gives_equal_units_per_pixel() {
        let mut p = Panel::new(Axis::new("x", "m"), Axis::new("y", "m")).equal_aspect();
        p.line("a", vec![(0.0, 0.0), (10.0, 1.0)], Stroke::series(0));
        let ((x0, x1), (y0, y1)) = p.ranges(800.0, 400.0);
        assert!(((x1 - x0) / 800.0 - (y1 - y0) / 400.0).abs() < 1e-12);
        assert!(x0 <= 0.0 && x1 >= 10.0 && y0 <= 0.0 && y1 >= 1.0);
    }

    #[test]
    fn log_axes_label_powers_of_ten_and_drop_non_positive_values() {
        let mut p = Panel::new(Axis::new("N", "").log(), Axis::new("‖z‖", "m/s").log());
        p.line(
            "bound",
            (0..=40)
                .map(|i| (10f64.powf(f64::from(i) / 10.0), 1e-3 * f64::from(i)))
                .collect(),
            Stroke::reference(),
        );
        let (x0, x1, y0, y1) = p.bounds();
        // i = 0 gives ‖z‖ = 0, left out on a log axis (so x starts at 10^0.1).
        assert!((x0 - 0.1).abs() < 1e-12 && x1 == 4.0, "{x0} {x1}");
        assert!((y0 - (-3.0)).abs() < 1e-12 && (y1 - 0.04f64.log10()).abs() < 1e-12);
        let svg = Figure::new("log", 600, 400).with_panel(p).svg().unwrap();
        let texts: Vec<&str> = svg
            .split("</text>")
            .filter_map(|t| t.rsplit('>').next())
            .map(str::trim)
            .collect();
        for want in ["1000", "10", "0.01", "‖z‖ [m/s]", "N"] {
            assert!(texts.contains(&want), "no `{want}` in {texts:?}");
        }
    }

    #[test]
    fn integer_axes_tick_whole_numbers_only() {
        let axis = Axis::new("agent", "").integer();
        assert_eq!(ticks(&axis, 0.0, 3.0, 7), [0.0, 1.0, 2.0, 3.0]);
        assert_eq!(ticks(&axis, 0.5, 4.5, 7), [1.0, 2.0, 3.0, 4.0]);
        let many = ticks(&axis, 0.0, 201.0, 7);
        assert!(
            many.len() <= 8 && many.iter().all(|t| t.fract() == 0.0),
            "{many:?}"
        );
    }

    #[test]
    fn ticks_are_short() {
        assert_eq!(format_tick(0.5), "0.5");
        assert_eq!(format_tick(12.0), "12");
        assert_eq!(format_tick(-0.00001), "-1e-5");
        assert_eq!(format_tick(-0.0), "0");
    }
}
