//! One module per command.

pub(crate) mod bench;
pub(crate) mod bound;
pub(crate) mod fleet;
pub(crate) mod identify;
pub(crate) mod lycomp;
pub(crate) mod out;
pub(crate) mod plot;
pub(crate) mod progress;
pub(crate) mod run;
pub(crate) mod scenarios;
pub(crate) mod sweep;
pub(crate) mod umbmark;

/// A finite number, or a message saying why not.
pub(crate) fn parse_number(s: &str) -> Result<f64, String> {
    let v: f64 = s.parse().map_err(|_| format!("`{s}` is not a number"))?;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(format!("{s} is not a finite number"))
    }
}

/// A finite number > 0 (clap value parser).
pub(crate) fn positive(s: &str) -> Result<f64, String> {
    let v = parse_number(s)?;
    if v > 0.0 {
        Ok(v)
    } else {
        Err(format!("{s} must be > 0"))
    }
}

/// A finite number ≥ 0 (clap value parser).
pub(crate) fn non_negative(s: &str) -> Result<f64, String> {
    let v = parse_number(s)?;
    if v >= 0.0 {
        Ok(v)
    } else {
        Err(format!("{s} must be ≥ 0"))
    }
}

/// Longest real time a fleet process waits or runs, s (about 31 years): what
/// `std::time::Duration` holds with room to spare, and the fleet clock's own
/// longest nap.
pub(crate) const MAX_REAL_SECONDS: f64 = 1e9;

/// Slowest and fastest fleet clock, × real time: a fleet run's real length,
/// `--duration / --time-scale`, stays within [`MAX_REAL_SECONDS`] × 10⁶.
pub(crate) const TIME_SCALE_RANGE: (f64, f64) = (1e-3, 1e4);

/// A finite number `s` > 0 and ≤ [`MAX_REAL_SECONDS`] (clap value parser):
/// a timeout or a fleet duration, which the fleet turns into a
/// `std::time::Duration` (a larger value would not fit).
pub(crate) fn seconds(s: &str) -> Result<f64, String> {
    let v = positive(s)?;
    if v <= MAX_REAL_SECONDS {
        Ok(v)
    } else {
        Err(format!(
            "{s} s is more than {MAX_REAL_SECONDS:e} s (about 31 years)"
        ))
    }
}

/// A fleet time scale within [`TIME_SCALE_RANGE`] (clap value parser).
pub(crate) fn time_scale(s: &str) -> Result<f64, String> {
    let v = positive(s)?;
    let (lo, hi) = TIME_SCALE_RANGE;
    if (lo..=hi).contains(&v) {
        Ok(v)
    } else {
        Err(format!("{s} is outside {lo} to {hi} (× real time)"))
    }
}
