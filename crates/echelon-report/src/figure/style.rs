//! The figures' look: the colours (the palette), line strokes, marker shapes
//! and the embedded font that every figure shares.

use std::sync::Once;

use plotters::prelude::{IntoFont, RGBColor, ShapeStyle};
use plotters::style::{Color as _, FontStyle, TextStyle};

/// An sRGB colour.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Color(pub u8, pub u8, pub u8);

impl Color {
    /// `#RRGGBB`, as the SVG files and the report use it.
    pub fn hex(self) -> String {
        format!("#{:02X}{:02X}{:02X}", self.0, self.1, self.2)
    }

    pub(super) fn rgb(self) -> RGBColor {
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

impl Dash {
    /// `(dash, gap)` lengths in pixels; `None` for a solid line.
    pub(super) fn pattern(self) -> Option<(u32, u32)> {
        match self {
            Dash::Solid => None,
            Dash::Dashed => Some((9, 6)),
            Dash::Dotted => Some((2, 4)),
        }
    }
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

    pub(super) fn style(self) -> ShapeStyle {
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

const FONT_FAMILY: &str = "sans-serif";
const DEJAVU: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");

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

/// Text in the figures' font, `size` px high, in `color`.
pub(super) fn text(size: f64, color: Color) -> TextStyle<'static> {
    (FONT_FAMILY, size).into_font().color(&color.rgb())
}
