//! A panel: one set of axes and what it draws ([`Item`]s: lines, segments,
//! markers), and the axis ranges that fit its data.

use super::axis::Axis;
use super::style::{Color, Marker, Stroke};

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

impl Item {
    /// Its legend entry, if any.
    pub(super) fn label(&self) -> Option<&str> {
        match self {
            Item::Line { label, .. }
            | Item::Segments { label, .. }
            | Item::Markers { label, .. } => label.as_deref(),
        }
    }
}

/// A legend entry: `None` for an empty `label` (kept out of the legend).
fn legend_entry(label: &str) -> Option<String> {
    (!label.is_empty()).then(|| label.to_owned())
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
    /// A point in data units on the chart's axes (each axis's scale).
    pub(crate) fn map(&self, (x, y): (f64, f64)) -> (f64, f64) {
        (self.x.map(x), self.y.map(y))
    }

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
            label: legend_entry(label),
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
            label: legend_entry(label),
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
            label: legend_entry(label),
            at,
            color,
        });
        self
    }

    /// Data bounds `(x0, x1, y0, y1)` in axis coordinates (log10 on log axes).
    pub(super) fn bounds(&self) -> (f64, f64, f64, f64) {
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
    pub(super) fn ranges(&self, w: f64, h: f64) -> ((f64, f64), (f64, f64)) {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::figure::Figure;

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
}
