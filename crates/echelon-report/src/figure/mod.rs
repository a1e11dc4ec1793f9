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
//! This module holds the [`Figure`] (a title over a grid of panels) and its
//! output: SVG with the dark-page style, PNG, the files. The rest, one job a
//! file: `style` (colours, strokes, markers, the font), `axis` ([`Axis`], its
//! ticks and tick labels), `panel` ([`Panel`] and its [`Item`]s, the ranges
//! that fit them), `simplify` (thinning series) and `draw` (putting it all on
//! a plotters backend, legend placement included).
//!
//! ```no_run
//! use echelon_report::figure::{Axis, Figure, Panel, Stroke};
//! let mut panel = Panel::new(Axis::new("t", "s"), Axis::new("‖e‖", "m"));
//! panel.line("agent 1", vec![(0.0, 1.0), (1.0, 0.5)], Stroke::series(0));
//! let figure = Figure::new("Tracking error", 900, 500).with_panel(panel);
//! figure.save(std::path::Path::new("out"), "errors").unwrap();
//! ```

mod axis;
mod draw;
mod panel;
mod simplify;
mod style;

use std::path::{Path, PathBuf};

use plotters::prelude::{BitMapBackend, IntoDrawingArea, SVGBackend};

pub use axis::Axis;
pub use panel::{Item, LEGEND_MAX, Panel};
pub use simplify::simplify;
pub use style::{Color, Dash, Marker, Stroke, palette, register_fonts};

use crate::ReportError;
use draw::draw_err;

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
