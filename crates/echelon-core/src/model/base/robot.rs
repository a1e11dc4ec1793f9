//! A velocity-controlled robot: its base and its wheels.

use super::*;

/// A velocity-controlled robot: its [`VelocityBase`] and the wheel geometry its
/// odometry needs (eq. 2). No mass or inertia: the base's own motor loops hide
/// them behind the lags.
///
/// Built through [`VelocityRobot::new`] (or a preset), which checks the wheels.
/// Serialises as its `base` and its wheels.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct VelocityRobot {
    pub(super) base: VelocityBase,
    /// How far the base may back up in one go, m (infinite: no limit):
    /// [`crate::model::base::Backup`].
    #[cfg_attr(feature = "serde", serde(skip_serializing_if = "f64_is_infinite"))]
    pub(super) reverse_limit: f64,
    pub(super) half_wheelbase: f64,
    pub(super) wheel_radius: f64,
}

impl VelocityRobot {
    /// The ideal base on Table I's wheels (agent 1: `r = 0.05 m`, `l = 0.15 m`):
    /// the paper's robots with their motor loops closed.
    pub const IDEAL: VelocityRobot = VelocityRobot {
        base: VelocityBase::IDEAL,
        reverse_limit: f64::INFINITY,
        half_wheelbase: crate::model::RobotParams::AGENT1.half_wheelbase(),
        wheel_radius: crate::model::RobotParams::AGENT1.wheel_radius(),
    };

    /// TurtleBot 3 Burger: `r = 0.033 m`, `l = 0.080 m` (`WHEEL_RADIUS`,
    /// `WHEEL_SEPARATION = 0.160` of `turtlebot3_node`'s burger parameters;
    /// the e-Manual's specifications agree).
    pub const TURTLEBOT3_BURGER: VelocityRobot = VelocityRobot {
        base: VelocityBase::TURTLEBOT3_BURGER,
        reverse_limit: f64::INFINITY,
        half_wheelbase: 0.080,
        wheel_radius: 0.033,
    };

    /// TurtleBot 4 (iRobot Create 3): `r = 0.036 m`, `l = 0.1175 m` (Create 3
    /// wheel diameter 72 mm, wheel separation 235 mm: iRobot's Create 3
    /// hardware overview; quoted, not re-measured).
    pub const TURTLEBOT4: VelocityRobot = VelocityRobot {
        base: VelocityBase::TURTLEBOT4,
        reverse_limit: CREATE3_BACKUP_LIMIT,
        half_wheelbase: 0.1175,
        wheel_radius: 0.036,
    };

    /// Clearpath Jackal: `r = 0.098 m`, `l = 0.1875 m` (`wheel_radius`,
    /// `wheel_separation = 0.375` of `jackal_control/config/control.yaml`).
    pub const JACKAL: VelocityRobot = VelocityRobot {
        base: VelocityBase::JACKAL,
        reverse_limit: f64::INFINITY,
        half_wheelbase: 0.1875,
        wheel_radius: 0.098,
    };

    /// The named presets: `ideal`, `turtlebot3-burger`, `turtlebot4`,
    /// `jackal` (each on the [`VelocityBase`] of that name).
    pub const PRESETS: [(&'static str, VelocityRobot); 4] = [
        ("ideal", Self::IDEAL),
        ("turtlebot3-burger", Self::TURTLEBOT3_BURGER),
        ("turtlebot4", Self::TURTLEBOT4),
        ("jackal", Self::JACKAL),
    ];

    /// A preset by name.
    pub fn preset(name: &str) -> Option<VelocityRobot> {
        crate::model::find_preset(&Self::PRESETS, name)
    }

    /// The robot on `base` (already checked: [`VelocityBase::new`]) with half
    /// wheel separation `l` (m) and wheel radius `r` (m), each a finite number
    /// `> 0`.
    pub fn new(
        base: VelocityBase,
        half_wheelbase: f64,
        wheel_radius: f64,
    ) -> Result<VelocityRobot, ParamError> {
        use crate::check::{finite, require};
        for (field, value) in [
            ("half_wheelbase", half_wheelbase),
            ("wheel_radius", wheel_radius),
        ] {
            require(field, finite(field, value)?, value > 0.0, "must be > 0")?;
        }
        Ok(VelocityRobot {
            base,
            reverse_limit: f64::INFINITY,
            half_wheelbase,
            wheel_radius,
        })
    }

    /// The same robot allowed to back up at most `limit` m in one go
    /// ([`Backup`]): a number `> 0`, infinite for no limit.
    pub fn with_reverse_limit(self, limit: f64) -> Result<VelocityRobot, ParamError> {
        if limit.is_nan() || limit <= 0.0 {
            return Err(ParamError::new(
                "reverse_limit",
                limit,
                "must be > 0 (m; leave it out for no limit)",
            ));
        }
        Ok(VelocityRobot {
            reverse_limit: limit,
            ..self
        })
    }

    /// How far it may back up in one go, m (infinite: no limit).
    #[inline]
    pub const fn reverse_limit(&self) -> f64 {
        self.reverse_limit
    }

    /// A fresh backup budget for it, nothing reversed yet (`None`: no
    /// `reverse_limit`): what its simulator and its fleet robot keep.
    pub fn backup(&self) -> Option<Backup> {
        self.reverse_limit
            .is_finite()
            .then(|| Backup::new(self.reverse_limit))
    }

    /// Lags and limits.
    #[inline]
    pub const fn base(&self) -> VelocityBase {
        self.base
    }

    /// `l`, half the wheel separation, m.
    #[inline]
    pub const fn half_wheelbase(&self) -> f64 {
        self.half_wheelbase
    }

    /// `r`, m.
    #[inline]
    pub const fn wheel_radius(&self) -> f64 {
        self.wheel_radius
    }
}

#[cfg(feature = "serde")]
fn f64_is_infinite(x: &f64) -> bool {
    x.is_infinite()
}
