//! The rules every parameter is checked against, each written once. The
//! validating constructors ([`crate::RobotParams::new`],
//! [`crate::Gains::new`], [`crate::law::lycomp::Placement::new`],
//! [`crate::AgentSpec::new`], [`crate::SimConfig::new`], the references, the
//! odometry specs, …) are built from these; each returns a [`ParamError`]
//! naming the field, which the scenario builder attaches to its path in the file.

use std::borrow::Cow;

use crate::error::{ParamError, num};

/// `v` if `ok`, else an error saying `field = v` is refused because of `reason`.
pub fn require(
    field: &'static str,
    v: f64,
    ok: bool,
    reason: impl Into<Cow<'static, str>>,
) -> Result<f64, ParamError> {
    if ok {
        Ok(v)
    } else {
        Err(ParamError::new(field, v, reason))
    }
}

/// `v` if it is a finite number.
pub fn finite(field: &'static str, v: f64) -> Result<f64, ParamError> {
    require(field, v, v.is_finite(), "must be a finite number")
}

/// `v` if it is a finite number > 0.
pub fn positive(field: &'static str, v: f64) -> Result<f64, ParamError> {
    require(
        field,
        v,
        v.is_finite() && v > 0.0,
        "must be a finite number > 0",
    )
}

/// `v` if it is a finite number ≥ 0.
pub fn non_negative(field: &'static str, v: f64) -> Result<f64, ParamError> {
    require(
        field,
        v,
        v.is_finite() && v >= 0.0,
        "must be a finite number ≥ 0",
    )
}

/// `n` if it is at least 1 (a count of samples, runs, ticks).
pub fn at_least_one(field: &'static str, n: u64) -> Result<u64, ParamError> {
    if n >= 1 {
        Ok(n)
    } else {
        Err(ParamError::new(field, 0.0, "must be ≥ 1"))
    }
}

/// `period / dt` when `period` is a finite number > 0 and a whole multiple of
/// `dt` (to 1e-9 relative); `what` names `dt` in the error, which gives its
/// value in short form (`dt = 0.01 s`, `dt = 1e-300 s`).
pub fn multiple_of(
    field: &'static str,
    period: f64,
    dt: f64,
    what: &str,
) -> Result<u64, ParamError> {
    positive(field, period)?;
    crate::math::whole_ratio(period, dt).ok_or_else(|| {
        ParamError::new(
            field,
            period,
            format!("s is not a whole multiple of {what} = {} s", num(dt)),
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_rule_names_the_field_and_the_reason() {
        assert_eq!(positive("l", 0.05), Ok(0.05));
        let e = positive("l", 0.0).unwrap_err();
        assert_eq!((e.field, e.value), ("l", 0.0));
        assert_eq!(
            format!("{} {}", e.value, e.reason),
            "0 must be a finite number > 0"
        );
        assert!(finite("x", f64::NAN).is_err());
        assert!(finite("x", -1.0).is_ok());
        assert!(non_negative("slip", 0.0).is_ok());
        assert!(non_negative("slip", -1e-12).is_err());
        assert_eq!(at_least_one("runs", 0).unwrap_err().field, "runs");
        assert_eq!(multiple_of("period", 0.02, 0.01, "dt"), Ok(2));
        let e = multiple_of("period", 0.025, 0.01, "dt").unwrap_err();
        assert_eq!(
            format!("{} {}", e.value, e.reason),
            "0.025 s is not a whole multiple of dt = 0.01 s"
        );
        // A step far from 1 is in exponent form, not hundreds of digits.
        let e = multiple_of("period", 1e-299, 3e-300, "dt").unwrap_err();
        assert_eq!(e.reason, "s is not a whole multiple of dt = 3e-300 s");
        assert!(multiple_of("period", -0.02, 0.01, "dt").is_err());
    }
}
