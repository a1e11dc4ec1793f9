//! A robot's odometry errors: the paper's additive `ζ` (Assumption 1,
//! eq. 23), Borenstein's systematic `E_d`, `E_b`, slip, tick quantization and
//! the noise of the measured speeds.

use crate::check;
use crate::error::ParamError;

/// How the paper's additive error `ζ` enters (`zeta_model = "wheels"` or
/// `"worst-case"` in a scenario).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Deserialize, serde::Serialize, schemars::JsonSchema)
)]
#[cfg_attr(feature = "serde", serde(rename_all = "kebab-case"))]
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
///
/// Built from [`ErrorModel::PERFECT`] by the `with_*` methods, each of which
/// refuses an impossible value, so an `ErrorModel` always holds a possible one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ErrorModel {
    zeta: f64,
    zeta_model: ZetaModel,
    wheel_diameter_ratio: f64,
    wheelbase_ratio: f64,
    slip: f64,
    ticks_per_rev: Option<u32>,
    speed_noise: f64,
    turn_rate_noise: f64,
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

    /// Only Borenstein's systematic errors ([`ErrorModel::with_systematic`]),
    /// everything else perfect.
    pub fn systematic(ed: f64, eb: f64) -> Result<ErrorModel, ParamError> {
        ErrorModel::PERFECT.with_systematic(ed, eb)
    }

    /// This model with the paper's additive error `ζ`, m per sample (eq. 23),
    /// entering as `zeta_model`; `ζ` must be finite.
    pub fn with_zeta(self, zeta: f64, zeta_model: ZetaModel) -> Result<ErrorModel, ParamError> {
        Ok(ErrorModel {
            zeta: check::finite("zeta", zeta)?,
            zeta_model,
            ..self
        })
    }

    /// This model with Borenstein's `E_d = D_R / D_L` (`ed`, the ratio of the
    /// actual wheel diameters, whose mean is the nominal one) and `E_b =
    /// b_actual / b_nominal` (`eb`): finite and > 0, 1 is perfect.
    pub fn with_systematic(self, ed: f64, eb: f64) -> Result<ErrorModel, ParamError> {
        let ratio = |field, v: f64| {
            check::finite(field, v)?;
            check::require(field, v, v > 0.0, "must be > 0 (1 is a perfect robot)")
        };
        Ok(ErrorModel {
            wheel_diameter_ratio: ratio("wheel_diameter_ratio", ed)?,
            wheelbase_ratio: ratio("wheelbase_ratio", eb)?,
            ..self
        })
    }

    /// This model with random slip: each wheel's measured displacement gets
    /// Gaussian noise of variance `slip · |Δ|`, m²/m (variance per metre
    /// travelled), ≥ 0.
    pub fn with_slip(self, slip: f64) -> Result<ErrorModel, ParamError> {
        Ok(ErrorModel {
            slip: check::non_negative("slip", slip)?,
            ..self
        })
    }

    /// This model with encoders of `ticks_per_rev` ticks per wheel
    /// revolution, ≥ 1 (`None`: ideal encoders).
    pub fn with_ticks_per_rev(self, ticks_per_rev: Option<u32>) -> Result<ErrorModel, ParamError> {
        if let Some(n) = ticks_per_rev {
            check::at_least_one("ticks_per_rev", n.into())?;
        }
        Ok(ErrorModel {
            ticks_per_rev,
            ..self
        })
    }

    /// This model with noisy speed measurements (Assumption 2: speeds are
    /// measured directly): the standard deviations of the measured linear
    /// speed, m/s, and angular speed, rad/s, ≥ 0 (0 is exact).
    pub fn with_speed_noise(
        self,
        speed_noise: f64,
        turn_rate_noise: f64,
    ) -> Result<ErrorModel, ParamError> {
        Ok(ErrorModel {
            speed_noise: check::non_negative("speed_noise", speed_noise)?,
            turn_rate_noise: check::non_negative("turn_rate_noise", turn_rate_noise)?,
            ..self
        })
    }

    /// The paper's additive error `ζ`, m per sample (eq. 23).
    #[inline]
    pub const fn zeta(&self) -> f64 {
        self.zeta
    }

    /// How `ζ` enters.
    #[inline]
    pub const fn zeta_model(&self) -> ZetaModel {
        self.zeta_model
    }

    /// Borenstein's `E_d = D_R / D_L`.
    #[inline]
    pub const fn wheel_diameter_ratio(&self) -> f64 {
        self.wheel_diameter_ratio
    }

    /// Borenstein's `E_b = b_actual / b_nominal`.
    #[inline]
    pub const fn wheelbase_ratio(&self) -> f64 {
        self.wheelbase_ratio
    }

    /// Slip variance per metre travelled, m²/m.
    #[inline]
    pub const fn slip(&self) -> f64 {
        self.slip
    }

    /// Encoder ticks per wheel revolution (`None`: ideal encoders).
    #[inline]
    pub const fn ticks_per_rev(&self) -> Option<u32> {
        self.ticks_per_rev
    }

    /// Standard deviation of the measured linear speed, m/s.
    #[inline]
    pub const fn speed_noise(&self) -> f64 {
        self.speed_noise
    }

    /// Standard deviation of the measured angular speed, rad/s.
    #[inline]
    pub const fn turn_rate_noise(&self) -> f64 {
        self.turn_rate_noise
    }

    /// Variance of each wheel's measured displacement in a sample in which
    /// the wheels (radius `r`) travelled `step` (right, left), m²: slip plus
    /// the quantization of the encoders (uniform over one tick) plus `ζ²`,
    /// plus a floor that keeps a filter from trusting odometry absolutely.
    pub fn wheel_variance(&self, r: f64, step: [f64; 2]) -> [f64; 2] {
        let floor = 1e-12;
        self.displacement_variance(r, step).map(|v| v + floor)
    }

    /// [`ErrorModel::wheel_variance`] without the floor: what the model
    /// itself says, 0 for a perfect odometer.
    pub fn displacement_variance(&self, r: f64, step: [f64; 2]) -> [f64; 2] {
        let tick = self.tick(r).powi(2) / 6.0;
        let zeta = self.zeta * self.zeta;
        step.map(|d| self.slip * d.abs() + tick + zeta)
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
        let e = ErrorModel::systematic(1.02, 1.0).unwrap();
        let (r, l) = e.wheel_radii(0.1);
        assert!((r / l - 1.02).abs() < 1e-15 && (0.5 * (r + l) - 0.1).abs() < 1e-15);
    }

    #[test]
    fn impossible_errors_are_refused() {
        let p = ErrorModel::PERFECT;
        let field = |e: Result<ErrorModel, ParamError>| e.unwrap_err().field;
        assert_eq!(field(p.with_systematic(1.0, 0.0)), "wheelbase_ratio");
        assert_eq!(
            field(p.with_systematic(f64::INFINITY, 1.0)),
            "wheel_diameter_ratio"
        );
        assert_eq!(field(p.with_slip(-1.0)), "slip");
        assert_eq!(field(p.with_zeta(f64::NAN, ZetaModel::Wheels)), "zeta");
        assert_eq!(field(p.with_ticks_per_rev(Some(0))), "ticks_per_rev");
        assert_eq!(field(p.with_speed_noise(0.0, -0.1)), "turn_rate_noise");
        // Each setter keeps what the others set.
        let m = p
            .with_slip(0.2)
            .unwrap()
            .with_systematic(1.01, 0.99)
            .unwrap();
        assert_eq!(
            (m.slip(), m.wheel_diameter_ratio(), m.wheelbase_ratio()),
            (0.2, 1.01, 0.99)
        );
    }
}
