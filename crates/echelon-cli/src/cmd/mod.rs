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
