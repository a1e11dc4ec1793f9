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
pub enum Fusion {
    /// Replace the estimate by the fix (the paper's "recalibration").
    #[default]
    Reset,
    /// Fuse odometry and fixes in an extended Kalman filter.
    Ekf,
}

/// Absolute position fixes (a motion-capture system, GNSS, a beacon…).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FixSpec {
    /// When.
    pub schedule: FixSchedule,
    /// Standard deviation of each position coordinate, m.
    pub position_noise: f64,
    /// Standard deviation of the heading, rad (`None`: fixes give no heading).
    pub heading_noise: Option<f64>,
    /// Delay between taking a fix and the robot receiving it, s.
    pub latency: f64,
    /// How the fix is used.
    pub fusion: Fusion,
}

impl FixSpec {
    /// Refuses an empty schedule and negative or non-finite noises and latency.
    pub fn validate(&self) -> Result<(), ParamError> {
        match self.schedule {
            FixSchedule::EverySamples(n) => {
                check::at_least_one("every_steps", n)?;
            }
            FixSchedule::Period(p) => {
                check::positive("period", p)?;
            }
        }
        check::non_negative("position_noise", self.position_noise)?;
        if let Some(v) = self.heading_noise {
            check::non_negative("heading_noise", v)?;
        }
        check::non_negative("latency", self.latency)?;
        Ok(())
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
            FixSchedule::Period(p) => check::multiple_of(
                "period",
                p,
                period,
                &format!("the odometry period {period} s"),
            ),
        }
    }
}
