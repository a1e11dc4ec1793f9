//! A robot's odometry errors: the paper's additive `ζ` (Assumption 1,
//! eq. 23), Borenstein's systematic `E_d`, `E_b`, slip, tick quantization and
//! the noise of the measured speeds.

use crate::check;
use crate::error::ParamError;

/// How the paper's additive error `ζ` enters (`zeta_model = "wheels"` or
/// `"worst-case"` in a scenario).
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    Default,
    serde::Deserialize,
    serde::Serialize,
    schemars::JsonSchema,
)]
#[serde(rename_all = "kebab-case")]
pub enum ZetaModel {
    /// Assumption 1, eq. 23: each wheel's true displacement exceeds the measured
    /// one by `ζ` every sample, so `Δ = Δ̂ + ζ`, `Θ = Θ̂` (eq. 24): the heading
    /// stays exact and the position drifts by at most `ζ` per axis per sample.
    #[default]
    Wheels,
    /// The worst case of eq. 31: the true position exceeds the estimate by `ζ`
    /// on both world axes every sample (`x_N = x̂_N + Nζ`, `y_N = ŷ_N + Nζ`), the
    /// case Theorem 2 is written for.
    WorstCase,
}

/// The errors of one robot's odometry. All default to a perfect odometer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ErrorModel {
    /// The paper's additive error `ζ`, m per sample (eq. 23).
    pub zeta: f64,
    /// How `ζ` enters.
    pub zeta_model: ZetaModel,
    /// Borenstein's `E_d = D_R / D_L`, the ratio of the actual wheel diameters
    /// (their mean is the nominal one). 1 is perfect.
    pub wheel_diameter_ratio: f64,
    /// Borenstein's `E_b = b_actual / b_nominal`, the actual over the nominal
    /// wheelbase. 1 is perfect.
    pub wheelbase_ratio: f64,
    /// Random slip: each wheel's measured displacement gets Gaussian noise of
    /// variance `slip · |Δ|`, m²/m (variance per metre travelled).
    pub slip: f64,
    /// Encoder resolution, ticks per wheel revolution (`None`: ideal encoders).
    pub ticks_per_rev: Option<u32>,
    /// Standard deviation of the measured linear speed, m/s (Assumption 2: speeds
    /// are measured directly; 0 is exact).
    pub speed_noise: f64,
    /// Standard deviation of the measured angular speed, rad/s.
    pub turn_rate_noise: f64,
}

impl Default for ErrorModel {
    fn default() -> Self {
        ErrorModel::PERFECT
    }
}

impl ErrorModel {
    /// Perfect encoders and speed measurements.
    pub const PERFECT: ErrorModel = ErrorModel {
        zeta: 0.0,
        zeta_model: ZetaModel::Wheels,
        wheel_diameter_ratio: 1.0,
        wheelbase_ratio: 1.0,
        slip: 0.0,
        ticks_per_rev: None,
        speed_noise: 0.0,
        turn_rate_noise: 0.0,
    };

    /// Only Borenstein's systematic errors: the wheel diameter ratio `E_d`
    /// and the wheelbase ratio `E_b`, everything else perfect.
    pub const fn systematic(ed: f64, eb: f64) -> ErrorModel {
        ErrorModel {
            wheel_diameter_ratio: ed,
            wheelbase_ratio: eb,
            ..ErrorModel::PERFECT
        }
    }

    /// Refuses non-finite values, negative variances and ratios ≤ 0.
    pub fn validate(&self) -> Result<(), ParamError> {
        for (field, v) in [
            ("zeta", self.zeta),
            ("wheel_diameter_ratio", self.wheel_diameter_ratio),
            ("wheelbase_ratio", self.wheelbase_ratio),
            ("slip", self.slip),
            ("speed_noise", self.speed_noise),
            ("turn_rate_noise", self.turn_rate_noise),
        ] {
            check::finite(field, v)?;
        }
        for (field, v) in [
            ("wheel_diameter_ratio", self.wheel_diameter_ratio),
            ("wheelbase_ratio", self.wheelbase_ratio),
        ] {
            check::require(field, v, v > 0.0, "must be > 0 (1 is a perfect robot)")?;
        }
        for (field, v) in [
            ("slip", self.slip),
            ("speed_noise", self.speed_noise),
            ("turn_rate_noise", self.turn_rate_noise),
        ] {
            check::require(field, v, v >= 0.0, "must be ≥ 0")?;
        }
        if let Some(n) = self.ticks_per_rev {
            check::at_least_one("ticks_per_rev", n.into())?;
        }
        Ok(())
    }

    /// Variance of each wheel's measured displacement in a sample in which
    /// the wheels (radius `r`) travelled `step` (right, left), m²: slip plus
    /// the quantization of the encoders (uniform over one tick) plus `ζ²`,
    /// plus a floor that keeps a filter from trusting odometry absolutely.
    pub fn wheel_variance(&self, r: f64, step: [f64; 2]) -> [f64; 2] {
        let tick = self.tick(r).powi(2) / 6.0;
        let zeta = self.zeta * self.zeta;
        let floor = 1e-12;
        step.map(|d| self.slip * d.abs() + tick + zeta + floor)
    }

    /// One encoder tick of a wheel of radius `r`, m (0: ideal encoders).
    fn tick(&self, r: f64) -> f64 {
        self.ticks_per_rev
            .map_or(0.0, |n| std::f64::consts::TAU * r / f64::from(n))
    }

    /// Theorem 2's `ζ` for this model: a bound on the position error per
    /// axis of one sample in which the robot (wheels of radius `r`)
    /// travelled `step` m, under the theorem's Assumption 1 (the heading
    /// exact): the additive `ζ`, plus three standard deviations of the
    /// slip on the mean wheel displacement (`3 √(slip · step / 2)`), plus
    /// one encoder tick. The systematic `E_d`, `E_b` turn the heading and
    /// are outside Assumption 1; fixes that carry a heading correct them.
    pub fn zeta_per_sample(&self, r: f64, step: f64) -> f64 {
        let slip = if self.slip > 0.0 {
            3.0 * (self.slip * step.abs() / 2.0).sqrt()
        } else {
            0.0
        };
        self.zeta + slip + self.tick(r)
    }

    /// Actual right and left wheel radii for nominal radius `r` (Borenstein: the
    /// mean diameter is nominal, `D_R/D_L = E_d`).
    pub fn wheel_radii(&self, r: f64) -> (f64, f64) {
        let e = self.wheel_diameter_ratio;
        (r * 2.0 * e / (e + 1.0), r * 2.0 / (e + 1.0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wheel_radii_keep_the_mean_and_the_ratio() {
        let e = ErrorModel {
            wheel_diameter_ratio: 1.02,
            ..ErrorModel::PERFECT
        };
        let (r, l) = e.wheel_radii(0.1);
        assert!((r / l - 1.02).abs() < 1e-15 && (0.5 * (r + l) - 0.1).abs() < 1e-15);
    }

    #[test]
    fn invalid_error_models_are_refused() {
        let bad = ErrorModel {
            wheelbase_ratio: 0.0,
            ..ErrorModel::PERFECT
        };
        assert_eq!(bad.validate().unwrap_err().field, "wheelbase_ratio");
        let bad = ErrorModel {
            slip: -1.0,
            ..ErrorModel::PERFECT
        };
        assert_eq!(bad.validate().unwrap_err().field, "slip");
        let bad = ErrorModel {
            zeta: f64::NAN,
            ..ErrorModel::PERFECT
        };
        assert_eq!(bad.validate().unwrap_err().field, "zeta");
    }
}
