//! Absolute position fixes: when they are taken, how noisy and late they
//! are, and how they correct the estimate.

use crate::check;
use crate::error::ParamError;

/// When absolute fixes are taken.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FixSchedule {
    /// Every `N` odometry samples (the paper's `N`).
    EverySamples(u64),
    /// Every `T` seconds (a whole number of odometry samples).
    Period(f64),
}

/// How a fix corrects the estimate (`fusion = "reset"` or `"ekf"` in a scenario).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Deserialize, serde::Serialize, schemars::JsonSchema)
)]
#[cfg_attr(feature = "serde", serde(rename_all = "kebab-case"))]
pub enum Fusion {
    /// Replace the estimate by the fix (the paper's "recalibration").
    #[default]
    Reset,
    /// Fuse odometry and fixes in an extended Kalman filter.
    Ekf,
}

/// Absolute position fixes (a motion-capture system, GNSS, a beacon…).
///
/// Built by [`FixSpec::new`] (exact, immediate fixes) and the `with_*`
/// methods, each of which refuses an impossible value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FixSpec {
    schedule: FixSchedule,
    position_noise: f64,
    heading_noise: Option<f64>,
    latency: f64,
    fusion: Fusion,
}

impl FixSpec {
    /// Exact fixes without latency, taken on `schedule` (at least every
    /// sample, or a finite period > 0) and used as `fusion` says.
    pub fn new(schedule: FixSchedule, fusion: Fusion) -> Result<FixSpec, ParamError> {
        match schedule {
            FixSchedule::EverySamples(n) => {
                check::at_least_one("every_steps", n)?;
            }
            FixSchedule::Period(p) => {
                check::positive("period", p)?;
            }
        }
        Ok(FixSpec {
            schedule,
            position_noise: 0.0,
            heading_noise: None,
            latency: 0.0,
            fusion,
        })
    }

    /// These fixes with noise: the standard deviation of each position
    /// coordinate, m, and of the heading, rad (`None`: fixes give no
    /// heading), finite and ≥ 0.
    pub fn with_noise(
        self,
        position_noise: f64,
        heading_noise: Option<f64>,
    ) -> Result<FixSpec, ParamError> {
        check::non_negative("position_noise", position_noise)?;
        if let Some(v) = heading_noise {
            check::non_negative("heading_noise", v)?;
        }
        Ok(FixSpec {
            position_noise,
            heading_noise,
            ..self
        })
    }

    /// These fixes arriving `latency` seconds after they are taken (finite, ≥ 0).
    pub fn with_latency(self, latency: f64) -> Result<FixSpec, ParamError> {
        Ok(FixSpec {
            latency: check::non_negative("latency", latency)?,
            ..self
        })
    }

    /// When.
    #[inline]
    pub const fn schedule(&self) -> FixSchedule {
        self.schedule
    }

    /// Standard deviation of each position coordinate, m.
    #[inline]
    pub const fn position_noise(&self) -> f64 {
        self.position_noise
    }

    /// Standard deviation of the heading, rad (`None`: fixes give no heading).
    #[inline]
    pub const fn heading_noise(&self) -> Option<f64> {
        self.heading_noise
    }

    /// Delay between taking a fix and the robot receiving it, s.
    #[inline]
    pub const fn latency(&self) -> f64 {
        self.latency
    }

    /// How the fix is used.
    #[inline]
    pub const fn fusion(&self) -> Fusion {
        self.fusion
    }

    /// Seconds between fixes, for odometry sampled every `sample_period`
    /// seconds (`every_steps` samples of it, or the `period` itself).
    pub fn interval(&self, sample_period: f64) -> f64 {
        match self.schedule {
            FixSchedule::Period(p) => p,
            FixSchedule::EverySamples(n) => n as f64 * sample_period,
        }
    }

    /// Odometry samples between fixes, for sampling every `period` seconds.
    pub fn samples_between(&self, period: f64) -> Result<u64, ParamError> {
        match self.schedule {
            FixSchedule::EverySamples(n) => check::at_least_one("every_steps", n),
            FixSchedule::Period(p) => {
                check::multiple_of("period", p, period, "the odometry period")
            }
        }
    }
}
