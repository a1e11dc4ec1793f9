//! Axes: what an axis shows ([`Axis`]: quantity, unit, range, log or integer
//! scale), where its ticks go and how tick labels read.

use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint, Ranged};
use plotters::coord::types::RangedCoordf64;

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

    pub(super) fn map(&self, v: f64) -> f64 {
        if self.log {
            if v > 0.0 { v.log10() } else { f64::NAN }
        } else {
            v
        }
    }
}

/// An axis coordinate: plotters' `f64` mapping with the ticks we choose (see
/// [`ticks`]); labels come from our own formatters.
#[derive(Clone)]
pub(super) struct Coord {
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
    pub(super) fn new(axis: &Axis, lo: f64, hi: f64, hint: usize) -> Coord {
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

/// Short tick labels: `0.5`, `12`, `1e-3` (and `0` for rounding noise
/// such as `-6e-17`, which a tick at zero can come out as).
pub(super) fn format_tick(v: f64) -> String {
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

#[cfg(test)]
mod tests {
    use super::*;

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
