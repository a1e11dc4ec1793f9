//! The filter's settings for one robot ([`SafetyConfig`], `[safety]`) and
//! their checks.

use crate::check;
use crate::error::ParamError;

/// The filter's settings for one robot (`[safety]`).
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub struct SafetyConfig {
    /// Smallest distance between two robots' points `L` ahead, and the
    /// clearance a point keeps from an obstacle's edge, m.
    pub radius: f64,
    /// `γ`, 1/s: `ḣ ≥ −γ h` (velocity bases without lag), `ḧ + (γ + p) ḣ + γ p h ≥ 0`
    /// (torques and velocity bases with lag; `p = max(γ, INNER_RATE)`).
    pub gain: f64,
    /// Neighbours whose point is farther than this are ignored, m (may be
    /// infinite).
    pub range: f64,
}

impl SafetyConfig {
    /// Refuses `radius`, `gain` that are not finite and `> 0`, and a `range`
    /// that is not `> radius` (it may be infinite).
    pub fn new(radius: f64, gain: f64, range: f64) -> Result<SafetyConfig, ParamError> {
        check::positive("radius", radius)?;
        check::positive("gain", gain)?;
        check::require(
            "range",
            range,
            range > radius,
            format!("must exceed radius = {radius} m (robots beyond it are not seen)"),
        )?;
        Ok(SafetyConfig {
            radius,
            gain,
            range,
        })
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use crate::safety::Obstacle;

    #[test]
    fn bad_settings_are_refused() {
        assert_eq!(
            SafetyConfig::new(0.0, 1.0, 1.0).unwrap_err().field,
            "radius"
        );
        assert_eq!(SafetyConfig::new(0.2, -1.0, 1.0).unwrap_err().field, "gain");
        assert_eq!(SafetyConfig::new(0.2, 1.0, 0.1).unwrap_err().field, "range");
        assert!(SafetyConfig::new(0.2, 1.0, f64::INFINITY).is_ok());
        assert_eq!(Obstacle::new(0.0, 0.0, 0.0).unwrap_err().field, "r");
    }
}
